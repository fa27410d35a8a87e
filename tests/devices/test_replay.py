"""Tests of devices.replay: a recorded session served back pattern by pattern."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from devices import open_rig
from devices.base import Frame
from devices.replay import probe
from engine.errors import DeviceError, InputError
from engine.session import Session, pattern_hash

CAMERA = (5, 7)
PROJECTOR = (3, 4)


def _pattern(i: int) -> np.ndarray:
    return np.random.default_rng(10 + i).uniform(0.0, 1.0, (*PROJECTOR, 3)).astype(np.float32)


def _image(i: int) -> np.ndarray:
    return np.random.default_rng(20 + i).uniform(0.0, 2.0, (*CAMERA, 3)).astype(np.float32)


@pytest.fixture
def recording(tmp_path) -> Path:
    """Three patterns, each captured once, with distinct exposures and saturation masks."""
    session = Session.create(tmp_path / "rec", rig_name="virtual:cornell", camera_resolution=CAMERA,
                             projector_resolution=PROJECTOR, metadata={"projector_bit_depth": 10})
    for i in range(3):
        saturated = np.zeros(CAMERA, bool)
        saturated[i, i] = True
        frame = Frame(_image(i), exposure=0.01 * (i + 1), gain=1.0 + i, black_level=64.0,
                      saturated=saturated, metadata={"shot": i})
        session.add_frame(f"p{i}", frame, pattern_id=pattern_hash(_pattern(i)))
    session.write_mask("wall", np.eye(*CAMERA, dtype=bool))
    return tmp_path / "rec"


def test_replay_serves_the_capture_recorded_for_each_pattern(recording):
    with open_rig(f"replay:{recording}") as rig:
        assert rig.name == f"replay:{recording}"
        assert rig.camera.resolution == CAMERA and rig.projector.resolution == PROJECTOR
        assert rig.projector.bit_depth == 10
        np.testing.assert_array_equal(rig.targets["wall"], np.eye(*CAMERA, dtype=bool))
        for i in (2, 0, 1):  # any order
            rig.projector.show(_pattern(i).copy())
            frame = rig.camera.capture()
            np.testing.assert_array_equal(frame.image, _image(i))
            assert frame.image.dtype == np.float32
            assert (frame.exposure, frame.gain, frame.black_level) == (0.01 * (i + 1), 1.0 + i, 64.0)
            assert np.argwhere(frame.saturated).tolist() == [[i, i]]
            assert frame.metadata["shot"] == i
            assert frame.metadata["replay"]["capture"] == f"p{i}"


def test_frames_are_copies(recording):
    rig = open_rig(f"replay:{recording}")
    rig.projector.show(_pattern(0))
    first = rig.camera.capture()
    first.image[:] = -1.0
    first.saturated[:] = True
    first.metadata["shot"] = 99
    second = rig.camera.capture()
    np.testing.assert_array_equal(second.image, _image(0))
    assert second.saturated.sum() == 1 and second.metadata["shot"] == 0


def test_unknown_pattern_and_nothing_shown_are_device_errors(recording):
    rig = open_rig(f"replay:{recording}")
    with pytest.raises(DeviceError, match="nothing has been shown"):
        rig.camera.capture()
    unknown = _pattern(7)
    rig.projector.show(unknown)
    with pytest.raises(DeviceError,
                       match=f"pattern {pattern_hash(unknown)} was never recorded: .*has no capture for it"):
        rig.camera.capture()
    with pytest.raises(InputError, match=r"image must have shape \(3, 4, 3\)"):
        rig.projector.show(np.zeros((4, 3, 3), np.float32))
    with pytest.raises(InputError, match="in \\[0, 1\\]"):
        rig.projector.show(np.full((*PROJECTOR, 3), 1.5, np.float32))


def test_repeated_patterns_are_served_in_order_and_exposure_selects(tmp_path):
    session = Session.create(tmp_path / "s", rig_name="gphoto2", camera_resolution=CAMERA,
                             projector_resolution=PROJECTOR)
    black = pattern_hash(np.zeros((*PROJECTOR, 3), np.float32))
    session.add_capture("dark-start", _image(0), pattern_id=black, meta={"exposure": 0.1})
    session.add_capture("dark-long", _image(1), pattern_id=black, meta={"exposure": 0.4})
    session.add_capture("dark-end", _image(2), pattern_id=black, meta={"exposure": 0.1})
    rig = open_rig(f"replay:{tmp_path / 's'}")
    assert rig.camera.exposure == 0.1  # the first capture's, until set
    rig.blank()
    served = [rig.camera.capture().metadata["replay"]["capture"] for _ in range(4)]
    assert served == ["dark-start", "dark-long", "dark-end", "dark-end"]
    rig.camera.exposure = 0.1
    replayed = [rig.camera.capture().metadata["replay"]["capture"] for _ in range(3)]
    assert replayed == ["dark-start", "dark-end", "dark-end"]
    rig.camera.exposure = 0.4
    np.testing.assert_array_equal(rig.camera.capture().image, _image(1))
    rig.camera.exposure = 0.2
    with pytest.raises(DeviceError, match=r"only at exposures \[0\.1, 0\.4\], not at 0\.2 s"):
        rig.camera.capture()


def test_open_errors_and_probe(tmp_path, recording):
    with pytest.raises(InputError, match="replay needs a session folder"):
        open_rig("replay:")
    with pytest.raises(DeviceError, match="cannot replay .*no session folder at"):
        open_rig(f"replay:{tmp_path / 'missing'}")
    (recording / "manifest.json").write_text("{")
    with pytest.raises(DeviceError, match="cannot replay .*not valid JSON"):
        open_rig(f"replay:{recording}")
    with pytest.raises(InputError, match="takes no options"):
        open_rig(f"replay:{recording}", ideal=True)
    assert [str(a) for a in probe()] == ["replay:PATH: available — give a session folder"]
