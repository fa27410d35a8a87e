"""A session keeps its colour facts: the colour checker's measurement and each target's D."""

from __future__ import annotations

import numpy as np
import pytest

import devices
from engine.albedo import AlbedoScale
from engine.checker import PATCHES, Checker
from engine.errors import InputError, SessionError
from engine.session import Session
from engine.session.colour import COLOUR_GROUP, CheckerRecord, direct_array
from engine.session.edit import mask_digest
from engine.workflow import (
    RELATIVE,
    cached_decomposition,
    load_decomposition,
    run_calibration,
    run_capture,
    run_checker,
    saved_checker,
    saved_edit,
    target_albedo,
    target_colour,
    target_direct,
)
from engine.workflow import capture as capture_module

CAMERA = (6, 8)


def _record(shape=CAMERA) -> CheckerRecord:
    rng = np.random.default_rng(0)
    residual = rng.normal(0, 0.01, (PATCHES, 3))
    residual[3] = np.nan
    used = np.ones(PATCHES, bool)
    used[3] = False
    patch_direct = rng.uniform(0.1, 1.0, (PATCHES, 3))
    patch_direct[3] = np.nan
    scale = AlbedoScale(np.array([2.0, 3.0, 4.0]), residual=residual, used=used, plane=np.array([1.0, 0.01, -0.02]))
    checker = Checker(np.array([[0.5, 0.5], [6.5, 0.5], [6.5, 4.5], [0.5, 4.5]]), shape, "manual")
    return CheckerRecord(checker, "checker-0123abcd", "Nikon 5100 (NPL)", "D65", scale, patch_direct)


def _session(path) -> Session:
    return Session.create(path, rig_name="virtual:checker", camera_resolution=CAMERA, projector_resolution=CAMERA)


def test_a_checker_measurement_round_trips_through_the_session(tmp_path):
    session = _session(tmp_path / "s")
    assert saved_checker(session) is None
    record = _record()
    session.update(colour={"version": 1, "checker": record.to_json()})
    back = saved_checker(Session.open(tmp_path / "s"))
    np.testing.assert_array_equal(back.checker.corners, record.checker.corners)
    assert back.checker.shape == CAMERA and back.checker.source == "manual" and back.captures == record.captures
    np.testing.assert_array_equal(back.scale.scale, record.scale.scale)
    np.testing.assert_array_equal(back.scale.plane, record.scale.plane)
    np.testing.assert_array_equal(back.scale.used, record.scale.used)
    np.testing.assert_array_equal(back.scale.residual, record.scale.residual)  # NaN (not measured) kept
    np.testing.assert_array_equal(back.patch_direct, record.patch_direct)
    assert back.report() == record.report() and "23 of 24" in back.report()


@pytest.mark.parametrize("field, value, path", [
    ("corners", [[0, 0], [1, 0], [1, 1]], "state.colour.checker.corners"),
    ("scale", [2.0, -3.0, 4.0], "state.colour.checker.scale[1]"),
    ("used", [True] * 23, "state.colour.checker.used"),
    ("source", "guessed", "state.colour.checker.source"),
    ("captures", "../outside", "state.colour.checker.captures"),
    ("residual", [["0.1", 0.0, 0.0]] * 24, "state.colour.checker.residual[0][0]"),
])
def test_a_malformed_checker_measurement_is_refused_naming_the_field(tmp_path, field, value, path):
    session = _session(tmp_path / "s")
    data = _record().to_json()
    data[field] = value
    with pytest.raises(InputError, match=path.replace("[", r"\[").replace("]", r"\]")):
        session.update(colour={"version": 1, "checker": data})
    assert "colour" not in Session.open(tmp_path / "s").state  # nothing written


def test_corners_outside_the_camera_image_are_refused_on_reading(tmp_path):
    session = _session(tmp_path / "s")
    data = _record().to_json()
    data["corners"][2] = [40.0, 4.5]
    session.update(colour={"version": 1, "checker": data})
    with pytest.raises(SessionError, match="corners .* outside the 8×6 camera image"):
        saved_checker(Session.open(tmp_path / "s"))


def test_recalibrating_keeps_the_colour_arrays(tmp_path):
    session = _session(tmp_path / "s")
    name = direct_array(mask_digest(np.eye(6, 8, dtype=bool)))
    d = np.ones((*CAMERA, 3), np.float32)
    session.write_array(COLOUR_GROUP, name, d)
    session.write_calibration({"v": 1}, {"rig": {"lut": np.arange(3.0)}}, keep=(COLOUR_GROUP,))
    session.write_calibration({"v": 2}, {"rig": {"lut": np.arange(4.0)}}, keep=(COLOUR_GROUP,))
    reopened = Session.open(tmp_path / "s")
    np.testing.assert_array_equal(reopened.read_array(COLOUR_GROUP, name), d)
    data, arrays = reopened.read_calibration(groups=("rig",))
    assert data == {"v": 2} and list(arrays) == ["rig"] and arrays["rig"]["lut"].size == 4
    assert reopened.read_calibration(groups=())[1] == {}


@pytest.fixture(scope="module")
def checker_session(tmp_path_factory):
    """virtual:checker (ideal, 96²): calibrated, the panel captured at order 2, then the chart measured."""
    tmp = tmp_path_factory.mktemp("colour")
    with devices.open_rig("virtual:checker", ideal=True, resolution=(96, 96), cache_dir=tmp / "cache") as rig:
        session = Session.create(tmp / "s", rig_name=rig.identity, camera_resolution=rig.camera.resolution,
                                 projector_resolution=rig.projector.resolution)
        run_calibration(rig, session)
        panel = rig.targets["panel"]
        result = run_capture(rig, session, [("panel", panel)], 2)
        before = len(session.captures)
        record = run_checker(rig, session)
        truth = rig.truth.albedo()[panel].mean(axis=0).astype(np.float64)
        yield tmp / "s", rig, panel, result, record, truth, before


def test_the_panels_absolute_albedo_comes_from_the_session_alone(checker_session):
    path, _, panel, result, record, truth, _ = checker_session
    session = Session.open(path)
    stored = saved_checker(session)
    assert stored.checker.source == "detected" and stored.scale.rms_residual < 0.02, stored.report()
    np.testing.assert_allclose(stored.scale.scale, record.scale.scale)
    np.testing.assert_allclose(target_albedo(session, panel), truth, rtol=0.02)
    np.testing.assert_array_equal(target_direct(session, panel), result.targets[0][1].direct)
    colour = target_colour(session, load_decomposition(session), panel)
    np.testing.assert_allclose(colour.albedo, truth, rtol=0.02)
    assert colour.relative == ""


def test_the_checker_keeps_the_saved_edits_decomposition(checker_session):
    """The chart's captures change the session's capture list: the edit was saved first, so its
    decomposition is still found in the cache (not recomputed)."""
    path, _, _, result, _, _, _ = checker_session
    session = Session.open(path)
    edit = saved_edit(session)
    assert edit.acquisition.decomposition == result.key
    assert cached_decomposition(session, result.key) is not None


def test_measuring_again_with_the_same_corners_resumes_without_captures(checker_session):
    path, rig, _, _, record, _, _ = checker_session
    session = Session.open(path)
    count = len(session.captures)
    again = run_checker(rig, session, corners=record.checker.corners)
    assert len(session.captures) == count
    np.testing.assert_allclose(again.scale.scale, record.scale.scale)
    assert again.checker.source == "manual"


def test_without_a_checker_albedo_is_relative_and_says_how_to_fix_it(tmp_path):
    with devices.open_rig("virtual:checker", ideal=True, resolution=(48, 48), cache_dir=tmp_path / "cache") as rig:
        session = Session.create(tmp_path / "s", rig_name=rig.identity, camera_resolution=rig.camera.resolution,
                                 projector_resolution=rig.projector.resolution)
        run_calibration(rig, session)
        panel = rig.targets["panel"]
        run_capture(rig, session, [("panel", panel)], 2)
    with pytest.raises(InputError, match="albedo is relative: no colour checker .*albedit checker"):
        target_albedo(session, panel)
    colour = target_colour(session, load_decomposition(session), panel)
    assert colour.albedo is None and colour.relative == RELATIVE


def test_an_older_session_without_d_gets_it_from_its_own_captures(tmp_path, monkeypatch):
    monkeypatch.setattr(capture_module, "store_directs", lambda session, prepared: None)
    with devices.open_rig("virtual:checker", ideal=True, resolution=(48, 48), cache_dir=tmp_path / "cache") as rig:
        session = Session.create(tmp_path / "s", rig_name=rig.identity, camera_resolution=rig.camera.resolution,
                                 projector_resolution=rig.projector.resolution)
        run_calibration(rig, session)
        panel = rig.targets["panel"]
        result = run_capture(rig, session, [("panel", panel)], 2)
    name = direct_array(mask_digest(panel))
    with pytest.raises(SessionError):
        session.read_array(COLOUR_GROUP, name)
    session = Session.open(tmp_path / "s")  # no rig from here on
    np.testing.assert_array_equal(target_direct(session, panel), result.targets[0][1].direct)
    np.testing.assert_array_equal(session.read_array(COLOUR_GROUP, name), result.targets[0][1].direct)  # kept now
    assert target_direct(session, ~panel) is None  # never measured
