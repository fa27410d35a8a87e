"""The Calibration bundle: JSON + arrays round trip, compatibility checks, validation."""

from __future__ import annotations

import json

import numpy as np
import pytest

from engine.calibrate import Calibration, Correspondence, Crosstalk, ProjectorResponse
from engine.errors import InputError


def make(cam=(48, 64), proj=(30, 40), crosstalk=True):
    rng = np.random.default_rng(0)
    valid = rng.random(cam) > 0.2
    x = rng.integers(0, proj[1], cam)
    y = rng.integers(0, proj[0], cam)
    lv = np.linspace(0, 1, 9)
    resp = ProjectorResponse(lv, np.stack([lv**g for g in (2.2, 2.0, 2.4)], 1), [0.01, 0.02, 0.03])
    return Calibration(
        rig_name="virtual:cornell",
        camera_resolution=cam,
        projector_resolution=proj,
        black_frame=rng.random(cam + (3,)).astype(np.float32),
        response=resp,
        correspondence=Correspondence.from_maps(x, y, valid, proj),
        crosstalk=Crosstalk(np.array([[0.9, 0.1, 0], [0.05, 0.9, 0.05], [0, 0.1, 0.9]])) if crosstalk else None,
        metadata={"exposure": 0.02, "note": "test"},
    )


@pytest.mark.parametrize("crosstalk", [True, False])
def test_round_trip_through_json_and_arrays(crosstalk):
    cal = make(crosstalk=crosstalk)
    meta, arrays = cal.to_dict()
    text = json.dumps(meta)  # JSON-serialisable, no arrays inside
    assert len(text) < 10_000
    back = Calibration.from_dict(json.loads(text), {k: a.copy() for k, a in arrays.items()})
    assert back.rig_name == cal.rig_name and back.metadata == cal.metadata
    assert back.camera_resolution == (48, 64) and back.projector_resolution == (30, 40)
    np.testing.assert_array_equal(back.black_frame, cal.black_frame)
    np.testing.assert_array_equal(back.correspondence.x, cal.correspondence.x)
    np.testing.assert_array_equal(back.correspondence.status, cal.correspondence.status)
    v = np.linspace(0, 1, 7)[:, None].repeat(3, 1)
    np.testing.assert_array_equal(back.response.linearize(v), cal.response.linearize(v))
    if crosstalk:
        np.testing.assert_array_equal(back.crosstalk.matrix, cal.crosstalk.matrix)
    else:
        assert back.crosstalk is None
    assert {k: a.dtype for k, a in arrays.items()} == {
        "black_frame": np.float32,
        "correspondence_x": np.int32,
        "correspondence_y": np.int32,
        "correspondence_status": np.uint8,
    }


def test_check_compatible_names_the_reason():
    cal = make(cam=(512, 512), proj=(30, 40))
    cal.check_compatible("virtual:cornell", (512, 512), (30, 40))
    with pytest.raises(InputError, match="calibration was made for camera 512×512, this rig's camera is 640×480"):
        cal.check_compatible("virtual:cornell", (480, 640), (30, 40))
    with pytest.raises(InputError, match="made for projector 40×30, this rig's projector is 1024×768"):
        cal.check_compatible("virtual:cornell", (512, 512), (768, 1024))
    with pytest.raises(InputError, match="made for rig 'virtual:cornell', this rig is 'gphoto2'"):
        cal.check_compatible("gphoto2", (512, 512), (30, 40))


def test_from_dict_refuses_bad_data():
    meta, arrays = make().to_dict()
    with pytest.raises(InputError, match="version 99 is not supported"):
        Calibration.from_dict({**meta, "version": 99}, arrays)
    with pytest.raises(InputError, match="not an Albedit calibration"):
        Calibration.from_dict({"kind": "other"}, arrays)
    with pytest.raises(InputError, match="missing 'black_frame'"):
        Calibration.from_dict(meta, {k: a for k, a in arrays.items() if k != "black_frame"})
    with pytest.raises(InputError, match=r"arrays\['correspondence_x'\] must be int32"):
        Calibration.from_dict(meta, {**arrays, "correspondence_x": arrays["correspondence_x"].astype(np.float64)})
    with pytest.raises(InputError, match="must be float32 of shape"):
        Calibration.from_dict(meta, {**arrays, "black_frame": arrays["black_frame"][:10]})
    with pytest.raises(InputError, match="missing 'rig_name'"):
        Calibration.from_dict({k: v for k, v in meta.items() if k != "rig_name"}, arrays)
    bad_x = arrays["correspondence_x"].copy()
    bad_x[0, 0] = 10_000
    status = arrays["correspondence_status"].copy()
    status[0, 0] = 0
    with pytest.raises(InputError, match="inside the 40×30 projector"):
        Calibration.from_dict(meta, {**arrays, "correspondence_x": bad_x, "correspondence_status": status})


def test_constructor_validates_consistency():
    cal = make()
    with pytest.raises(InputError, match="correspondence maps a 64×48 camera"):
        Calibration("r", (10, 10), cal.projector_resolution, np.zeros((10, 10, 3), np.float32), cal.response,
                    cal.correspondence)
    with pytest.raises(InputError, match="black_frame must have shape"):
        Calibration("r", cal.camera_resolution, cal.projector_resolution, np.zeros((4, 4, 3), np.float32),
                    cal.response, cal.correspondence)
    with pytest.raises(InputError, match="rig_name must be a non-empty string"):
        Calibration("", cal.camera_resolution, cal.projector_resolution, cal.black_frame, cal.response,
                    cal.correspondence)
    assert not cal.black_frame.flags.writeable
