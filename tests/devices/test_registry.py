"""The registry: camera backends paired with any registered projector backend."""

from __future__ import annotations

import sys
import types

import numpy as np
import pytest

import devices
from devices import registry
from devices.registry import Availability
from engine.errors import InputError


class WallProjector:
    """A projector backend's projector that records what it was opened with."""

    resolution, bit_depth = (4, 6), 8

    def __init__(self, arg, options):
        self.arg, self.options, self.callbacks, self.shown = arg, options, [], 0

    def add_shown_callback(self, callback):
        self.callbacks.append(callback)

    def show(self, image):
        self.shown += 1
        for callback in self.callbacks:
            callback()

    def idle(self, seconds):
        pass


@pytest.fixture
def wall(monkeypatch):
    """A projector backend registered by one line, as a new module would be."""
    module = types.ModuleType("wall_projector")
    module.open_projector = lambda arg, **options: WallProjector(arg, options)
    module.probe = lambda: [Availability("wall:left", True, "the left wall")]
    module.default_problem = lambda: ""
    monkeypatch.setitem(sys.modules, "wall_projector", module)
    monkeypatch.setitem(registry._PROJECTORS, "wall", "wall_projector")
    return module


def test_a_projector_backend_is_chosen_by_name_with_its_options(wall, tmp_path):
    name = f"hotfolder:{tmp_path}"
    rig = devices.open_rig(name, projector="wall:left", settle=0.2, projector_timeout=3.0, resolution=(2, 3))
    assert isinstance(rig.projector, WallProjector) and rig.camera.resolution == (2, 3)
    assert rig.projector.arg == "left" and rig.projector.options == {"settle": 0.2, "timeout": 3.0}
    assert rig.camera._sleep == rig.projector.idle  # the camera waits through the projector
    assert Availability("wall:left", True, "the left wall") in devices.available_projectors()
    rig.close()


def test_the_camera_drops_queued_frames_after_each_projector_change(wall, tmp_path):
    import cv2

    for i in range(4):
        cv2.imwrite(str(tmp_path / f"f_{i:04d}.png"), np.full((2, 3, 3), 10 * (i + 1), np.uint8))
    rig = devices.open_rig(f"opencv:{tmp_path / 'f_%04d.png'}", projector="wall", response="linear", discard=1)
    assert rig.projector.arg is None  # the backend's default projector
    assert rig.camera.capture_codes()[0, 0, 0] == 10
    rig.projector.show(np.zeros((4, 6, 3), np.float32))
    assert rig.camera.capture_codes()[0, 0, 0] == 30  # one queued frame dropped
    rig.close()


def test_projector_errors(tmp_path):
    with pytest.raises(InputError, match=r"unknown projector backend 'vga'; expected one of \['qtscreen'\]"):
        devices.open_rig(f"hotfolder:{tmp_path}", projector="vga:1")
    given = WallProjector(None, {})
    with pytest.raises(InputError, match=r"projector options \['settle'\] only apply to a projector opened by name"):
        registry.open_projector(given, settle=0.1)
    assert registry.open_projector(given) is given
    with pytest.raises(InputError, match=r"unknown rig backend 'scanner'"):
        devices.open_rig("scanner:1")


def test_screens_are_listed_as_projectors_not_as_rigs():
    assert [a.name for a in devices.available_projectors()] == ["qtscreen:0"]  # one offscreen test screen
    assert not any(a.name.startswith("qtscreen") for a in devices.available())
