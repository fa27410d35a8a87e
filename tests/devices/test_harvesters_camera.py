"""The GenICam backend against a scripted stand-in of ``harvesters.core`` (every exchange must be used)."""

from __future__ import annotations

import sys
import threading
import time
import types

import numpy as np
import pytest

import devices
from devices.harvesters_camera import open_camera, open_rig, probe, to_rgb
from engine.errors import DeviceError, InputError

H, W = 6, 8


REPEAT = "repeat"


class Script:
    """Expected exchanges in order: (name, args, result[, REPEAT]); an exception result is raised.

    A REPEAT step matches one or more times in a row (a polling loop).
    """

    def __init__(self, steps):
        self.steps, self.used, self.hits, self.lock = list(steps), 0, 0, threading.Lock()

    def __call__(self, name, *args):
        with self.lock:
            step = self.steps[self.used] if self.used < len(self.steps) else None
            if step is not None and len(step) == 4 and self.hits and (name, args) != (step[0], tuple(step[1])):
                self.used, self.hits = self.used + 1, 0  # the repeated exchange is over
            assert self.used < len(self.steps), f"unexpected {name}{args}: script exhausted"
            want, want_args, result, *repeat = self.steps[self.used]
            assert (name, args) == (want, tuple(want_args)), f"exchange {self.used}: got {name}{args}, expected {want}{tuple(want_args)}"
            if repeat:
                self.hits += 1
            else:
                self.used += 1
        if isinstance(result, BaseException):
            raise result
        return result

    def finished(self):
        used = self.used + (1 if self.hits else 0)
        assert used == len(self.steps), f"unused scripted exchanges: {self.steps[used:]}"


class Node:
    def __init__(self, script, name, value, *, lo=None, hi=None, symbolics=()):
        self._script, self._name, self._value = script, name, value
        self.min, self.max, self.symbolics = lo, hi, list(symbolics)

    @property
    def value(self):
        return self._value

    @value.setter
    def value(self, v):
        self._script("set", self._name, v)
        self._value = v


class Buffer:
    def __init__(self, script, data, fmt, w, h):
        comp = types.SimpleNamespace(data=data, data_format=fmt, width=w, height=h)
        self.payload = types.SimpleNamespace(components=[comp])
        self._script = script

    def queue(self):
        self._script("queue")


def install(monkeypatch, script, nodes, devices_found=("cam0",)):
    """Put a fake ``harvesters.core`` in sys.modules: Harvester and ImageAcquirer call the script."""
    node_map = types.SimpleNamespace(**nodes)

    class ImageAcquirer:
        remote_device = types.SimpleNamespace(node_map=node_map)

        def start(self):
            script("start")

        def stop(self):
            script("stop")

        def try_fetch(self, *, timeout):
            time.sleep(min(timeout, 0.01))  # a producer waits for a buffer
            return script("try_fetch")

        def destroy(self):
            script("destroy")

    class Harvester:
        device_info_list = list(devices_found)

        def add_file(self, path):
            script("add_file", path)

        def update(self):
            script("update")

        def create(self, key):
            script("create", key)
            return ImageAcquirer()

        def reset(self):
            script("reset")

    core = types.ModuleType("harvesters.core")
    core.Harvester = Harvester
    package = types.ModuleType("harvesters")
    package.core = core
    monkeypatch.setitem(sys.modules, "harvesters", package)
    monkeypatch.setitem(sys.modules, "harvesters.core", core)


def nodes_for(script, *, formats=("Mono8", "Mono12", "BayerRG12")):
    return {
        "ExposureAuto": Node(script, "ExposureAuto", "Continuous"),
        "GainAuto": Node(script, "GainAuto", "Continuous"),
        "PixelFormat": Node(script, "PixelFormat", "Mono8", symbolics=formats),
        "Width": Node(script, "Width", W),
        "Height": Node(script, "Height", H),
        "ExposureTime": Node(script, "ExposureTime", 10000.0, lo=20.0, hi=1e6),
        "Gain": Node(script, "Gain", 0.0, lo=0.0, hi=24.0),
    }


OPENING = [
    ("add_file", ("/x.cti",), None),
    ("update", (), None),
    ("create", ({"serial_number": "S1"},), None),
    ("set", ("ExposureAuto", "Off"), None),
    ("set", ("GainAuto", "Off"), None),
    ("set", ("PixelFormat", "Mono12"), None),  # the deepest linear format offered
    ("set", ("ExposureTime", 2000.0), None),
    ("set", ("Gain", pytest.approx(20 * np.log10(2.0))), None),
]


@pytest.fixture
def cti(tmp_path):
    path = tmp_path / "x.cti"
    path.write_bytes(b"producer")
    return path


def opening(cti):
    return [(n, (str(cti),), r) if n == "add_file" else (n, a, r) for n, a, r in OPENING]


def test_capture_is_linear_with_black_level_exposure_and_gain(monkeypatch, cti):
    codes = np.arange(H * W, dtype=np.uint16) * 50
    codes[0] = 4095  # clipped
    script = Script([])
    buffer = Buffer(script, codes, "Mono12", W, H)
    script.steps = opening(cti) + [
        ("start", (), None),
        ("try_fetch", (), None),  # incomplete or not there yet: try again
        ("try_fetch", (), buffer),
        ("queue", (), None),  # the buffer goes back to the producer
        ("stop", (), None),
        ("destroy", (), None),
        ("reset", (), None),
    ]
    install(monkeypatch, script, nodes_for(script))
    cam = open_camera(cti, serial="S1", exposure=0.002, gain=2.0, black_level=95.0)
    assert cam.resolution == (H, W) and cam.pixel_format == "Mono12"
    assert cam.exposure == pytest.approx(0.002) and cam.gain == pytest.approx(2.0)
    frame = cam.capture()
    expected = (codes.reshape(H, W).astype(np.float64) - 95.0) / (4095 - 95.0) / (0.002 * 2.0)
    np.testing.assert_allclose(frame.image[..., 1], expected, rtol=1e-6)
    assert np.array_equal(frame.image[..., 0], frame.image[..., 2])
    assert frame.saturated[0, 0] and frame.saturated.sum() == 1
    assert frame.metadata["pixel_format"] == "Mono12" and frame.exposure == pytest.approx(0.002)
    cam.close()
    cam.close()  # idempotent: destroy and reset once
    script.finished()


def test_no_frame_in_time_is_a_device_error_and_acquisition_stops(monkeypatch, cti):
    script = Script(
        opening(cti)[:6]
        + [("start", (), None), ("try_fetch", (), None, REPEAT), ("stop", (), None), ("destroy", (), None), ("reset", (), None)]
    )
    install(monkeypatch, script, nodes_for(script))
    cam = open_camera(cti, serial="S1", timeout=0.3)
    with pytest.raises(DeviceError, match="no complete frame from the camera within 0.3 s"):
        cam.capture()
    assert script.steps[script.used][0] == "destroy"  # acquisition was stopped
    cam.close()
    script.finished()


def test_bad_options_list_the_choices(monkeypatch, cti):
    script = Script(opening(cti)[:5] + [("destroy", (), None), ("reset", (), None)])
    install(monkeypatch, script, nodes_for(script))
    with pytest.raises(InputError, match="pixel_format 'RGB8' is not offered by this camera; valid choices: Mono8, Mono12, BayerRG12"):
        open_camera(cti, serial="S1", pixel_format="RGB8")
    script.finished()
    script = Script(opening(cti)[:6] + [("destroy", (), None), ("reset", (), None)])
    install(monkeypatch, script, nodes_for(script))
    with pytest.raises(InputError, match=r"exposure 5 s is outside the camera's range 2e-05 .. 1 s"):
        open_camera(cti, serial="S1", exposure=5.0)
    script.finished()


def test_no_camera_and_producer_errors(monkeypatch, cti, tmp_path):
    script = Script([("add_file", (str(cti),), None), ("update", (), None), ("reset", (), None)])
    install(monkeypatch, script, nodes_for(script), devices_found=())
    with pytest.raises(DeviceError, match="no GenICam camera found through x.cti"):
        open_camera(cti)
    script.finished()
    script = Script([("add_file", (str(cti),), RuntimeError("GenTL: invalid producer")), ("reset", (), None)])
    install(monkeypatch, script, nodes_for(script))
    with pytest.raises(DeviceError, match="loading the GenTL producer failed: GenTL: invalid producer"):
        open_camera(cti)
    script.finished()
    with pytest.raises(DeviceError, match="no GenTL producer file"):
        open_camera(tmp_path / "missing.cti")
    with pytest.raises(InputError, match="needs the GenTL producer"):
        open_rig("")


def test_bayer_patterns_demosaic_to_the_right_colour():
    # a pure red scene seen through each GenICam Bayer pattern
    for pattern, red_at in {"RG": (0, 0), "GR": (0, 1), "GB": (1, 0), "BG": (1, 1)}.items():
        mosaic = np.zeros((8, 8), np.uint16)
        mosaic[red_at[0] :: 2, red_at[1] :: 2] = 1000
        rgb, clipped, top = to_rgb(mosaic.ravel(), f"Bayer{pattern}12", 8, 8)
        assert top == 4095 and not clipped.any()
        assert rgb[4, 4].tolist() == [1000.0, 0.0, 0.0], pattern
    with pytest.raises(DeviceError, match="unsupported pixel format 'YUV422_8'"):
        to_rgb(np.zeros(4, np.uint8), "YUV422_8", 2, 2)


def test_probe_without_the_library(monkeypatch):
    monkeypatch.setitem(sys.modules, "harvesters", None)  # as if not installed
    import importlib.util

    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None)
    (entry,) = probe()
    assert not entry.ok and "pip install 'albedit[harvesters]'" in entry.reason
    assert any(a.name.startswith("harvesters:") for a in devices.available())
