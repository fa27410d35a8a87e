"""The GenICam backend against a scripted stand-in of ``harvesters.core`` (every exchange must be used).

The stand-in is checked against the real harvesters and genicam when installed
(:func:`test_standin_matches_harvesters`); tests/devices/test_harvesters_library.py drives the real
library with genicam's simulated GenTL producer.
"""

from __future__ import annotations

import sys
import threading
import time
import types

import numpy as np
import pytest

import devices
from devices.harvesters_camera import open_camera, probe, to_rgb
from engine.errors import DeviceError, InputError
from tests.standins import check_standin, stands_in_for

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
            assert (name, args) == (want, tuple(want_args)), \
                f"exchange {self.used}: got {name}{args}, expected {want}{tuple(want_args)}"
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


class _Node:
    def __init__(self, script, name, value):
        self._script, self._name, self._value = script, name, value

    @property
    def value(self):
        return self._value

    @value.setter
    def value(self, v):
        self._script("set", self._name, v)
        self._value = v


@stands_in_for("genicam.genapi:IEnumeration", attributes=("value", "symbolics"))
class EnumNode(_Node):
    def __init__(self, script, name, value, symbolics=()):
        super().__init__(script, name, value)
        self.symbolics = list(symbolics)


@stands_in_for("genicam.genapi:IInteger", attributes=("value",))
class IntNode(_Node):
    pass


@stands_in_for("genicam.genapi:IFloat", attributes=("value", "min", "max"))
class FloatNode(_Node):
    def __init__(self, script, name, value, lo, hi):
        super().__init__(script, name, value)
        self.min, self.max = lo, hi


@stands_in_for("harvesters.core:Component2DImage", attributes=("data", "data_format", "width", "height"))
class Component:
    def __init__(self, data, data_format, width, height):
        self.data, self.data_format, self.width, self.height = data, data_format, width, height


@stands_in_for("harvesters.core:PayloadImage", attributes=("components",))
class Payload:
    def __init__(self, components):
        self.components = components


@stands_in_for("harvesters.core:Buffer", attributes=("payload",))
class Buffer:
    def __init__(self, script, data, fmt, w, h):
        self.payload = Payload([Component(data, fmt, w, h)])
        self._script = script

    def queue(self):
        self._script("queue")


@stands_in_for("harvesters.core:RemoteDevice", attributes=("node_map",))
class RemoteDevice:
    def __init__(self, node_map):
        self.node_map = node_map


@stands_in_for("harvesters.core:ImageAcquirer", attributes=("remote_device",))
class ImageAcquirer:
    script: Script
    node_map: object

    def __init__(self):
        self.remote_device = RemoteDevice(self.node_map)

    def start(self):
        self.script("start")

    def stop(self):
        self.script("stop")

    def try_fetch(self, *, timeout):
        time.sleep(min(timeout, 0.01))  # a producer waits for a buffer
        return self.script("try_fetch")

    def destroy(self):
        self.script("destroy")


@stands_in_for("harvesters.core:ParameterSet", constructed=True)
class ParameterSet:
    def __init__(self, parameter_dict=None):
        self.parameters = dict(parameter_dict or {})


@stands_in_for("harvesters.core:ParameterKey")
class ParameterKey:
    LOGGER = 0


@stands_in_for("harvesters.core:Harvester", attributes=("device_info_list",), constructed=True)
class Harvester:
    script: Script
    acquirer: type
    device_info_list: list

    def __init__(self, *, config=None):
        self.config = config

    def add_file(self, file_path, check_existence=False, check_validity=False):
        self.script("add_file", file_path, check_existence, check_validity)

    def update(self):
        self.script("update")

    def create(self, search_key=None):
        self.script("create", search_key)
        return self.acquirer()

    def reset(self):
        self.script("reset")


@pytest.mark.parametrize(
    "standin",
    [EnumNode, IntNode, FloatNode, Component, Payload, Buffer, RemoteDevice, ImageAcquirer, ParameterSet, ParameterKey,
     Harvester],
    ids=lambda c: c.__name__,
)
def test_standin_matches_harvesters(standin):
    pytest.importorskip("harvesters.core")
    assert check_standin(standin) == []


def install(monkeypatch, script, nodes, devices_found=("cam0",)):
    """Put a fake ``harvesters.core`` in sys.modules: Harvester and ImageAcquirer call the script."""
    acquirer = type("ImageAcquirer", (ImageAcquirer,), {"script": script, "node_map": types.SimpleNamespace(**nodes)})
    harvester = type("Harvester", (Harvester,),
                     {"script": script, "acquirer": acquirer, "device_info_list": list(devices_found)})
    core = types.ModuleType("harvesters.core")
    core.Harvester, core.ParameterSet, core.ParameterKey = harvester, ParameterSet, ParameterKey
    package = types.ModuleType("harvesters")
    package.core = core
    monkeypatch.setitem(sys.modules, "harvesters", package)
    monkeypatch.setitem(sys.modules, "harvesters.core", core)


def nodes_for(script, *, formats=("Mono8", "Mono12", "BayerRG12")):
    return {
        "ExposureAuto": EnumNode(script, "ExposureAuto", "Continuous", ("Off", "Continuous")),
        "GainAuto": EnumNode(script, "GainAuto", "Continuous", ("Off", "Continuous")),
        "PixelFormat": EnumNode(script, "PixelFormat", "Mono8", formats),
        "Width": IntNode(script, "Width", W),
        "Height": IntNode(script, "Height", H),
        "ExposureTime": FloatNode(script, "ExposureTime", 10000.0, 20.0, 1e6),
        "Gain": FloatNode(script, "Gain", 0.0, 0.0, 24.0),
    }


OPENING = [
    ("add_file", ("/x.cti", True, True), None),
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
    return [(n, (str(cti), True, True), r) if n == "add_file" else (n, a, r) for n, a, r in OPENING]


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
        + [("start", (), None), ("try_fetch", (), None, REPEAT), ("stop", (), None), ("destroy", (), None),
           ("reset", (), None)]
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
    with pytest.raises(InputError, match="pixel_format 'RGB8' is not offered by this camera; "
                                         "valid choices: Mono8, Mono12, BayerRG12"):
        open_camera(cti, serial="S1", pixel_format="RGB8")
    script.finished()
    script = Script(opening(cti)[:6] + [("destroy", (), None), ("reset", (), None)])
    install(monkeypatch, script, nodes_for(script))
    with pytest.raises(InputError, match=r"exposure 5 s is outside the camera's range 2e-05 .. 1 s"):
        open_camera(cti, serial="S1", exposure=5.0)
    script.finished()


def test_no_camera_and_producer_errors(monkeypatch, cti, tmp_path):
    script = Script([("add_file", (str(cti), True, True), None), ("update", (), None), ("reset", (), None)])
    install(monkeypatch, script, nodes_for(script), devices_found=())
    with pytest.raises(DeviceError, match="no GenICam camera found through x.cti"):
        open_camera(cti)
    script.finished()
    script = Script([("add_file", (str(cti), True, True), OSError("x.cti: file too short")), ("reset", (), None)])
    install(monkeypatch, script, nodes_for(script))
    with pytest.raises(DeviceError, match="loading the GenTL producer failed: x.cti: file too short"):
        open_camera(cti)
    script.finished()
    with pytest.raises(DeviceError, match="no GenTL producer file"):
        open_camera(tmp_path / "missing.cti")
    with pytest.raises(InputError, match="needs the GenTL producer"):
        devices.open_rig("harvesters")


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


def test_probe_without_the_library(without_modules):
    without_modules("harvesters", "genicam")
    (entry,) = probe()
    assert not entry.ok and "pip install 'albedit[harvesters]'" in entry.reason
    assert any(a.name.startswith("harvesters:") for a in devices.available())
