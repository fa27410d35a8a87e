"""A reopened session of the open simulated rig gets the scene's ground truth, lit as its photograph was;
another rig, another lighting or another photograph gets none, and says why."""

from __future__ import annotations

import numpy as np
import pytest

import devices
from app.model.scene_truth import scene_truth
from engine.acquire.predict import relative_error
from engine.session import Session
from engine.workflow import run_calibration, run_capture

RES = (20, 20)


@pytest.fixture(scope="module")
def acquired(tmp_path_factory):
    """A session of the ideal Cornell box whose photograph was taken under a 60 % flood: (rig options, path)."""
    path = tmp_path_factory.mktemp("truth") / "s"
    with devices.open_rig("virtual:cornell", ideal=True, resolution=RES) as rig:
        session = Session.create(path, rig_name=rig.identity, camera_resolution=rig.camera.resolution,
                                 projector_resolution=rig.projector.resolution, fingerprint=rig.fingerprint)
        run_calibration(rig, session)
        flood = np.full((*rig.projector.resolution, 3), 0.6, np.float32)
        run_capture(rig, session, [("wall", rig.targets["right_wall"])], 2, photograph_pattern=flood)
    return path


def test_the_truth_is_the_scene_lit_as_the_photograph_was(acquired):
    session = Session.open(acquired)
    photo = session.read_capture("acq-photograph")
    with devices.open_rig("virtual:cornell", ideal=True, resolution=RES) as rig:
        truth, why = scene_truth(rig, session, photo)
        assert why == "" and truth.pattern is not None
        np.testing.assert_allclose(truth.photograph(), photo, rtol=1e-4, atol=1e-6)
        wall = rig.targets["right_wall"]
        expected = rig.truth.recolor([(wall, 0.5)], pattern=truth.pattern)
        np.testing.assert_array_equal(truth.recolor([(wall, 0.5)]), expected)
        assert relative_error(expected, rig.truth.recolor([(wall, 0.5)])) > 0.1  # the flood matters


def test_another_rig_lighting_or_photograph_gets_no_truth(acquired):
    session = Session.open(acquired)
    photo = session.read_capture("acq-photograph")
    with devices.open_rig("virtual:cornell", ideal=True, resolution=(16, 16)) as small:
        assert scene_truth(small, session, photo)[1].startswith("the open rig, virtual:cornell, is not the one")
    with devices.open_rig("virtual:cornell", ideal=True, resolution=RES) as rig:
        truth, why = scene_truth(rig, session, 2.0 * photo)  # not what the scene gives under that light
        assert truth is None and "differs from this photograph by" in why
        assert scene_truth(None, session, photo) == (None, "only a simulated rig's scene has a ground truth")
        assert scene_truth(rig, None, photo)[0] is None
