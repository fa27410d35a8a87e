"""Colour estimates and κ from colours against the virtual rig's truth (ideal rig)."""

import json

import numpy as np
import pytest

import devices
from devices.virtual.scene import SCENE_DIR
from engine.acquire import Recorder, measure_checker, prepare_target, projector_xy
from engine.albedo import reference_scale
from engine.checker import detect_checker, reference_reflectances
from engine.colour import direct_colour, kappa_for_albedo
from engine.session import Session
from engine.workflow import load_decomposition, run_calibration, run_capture


def _calibrated(rig, path):
    session = Session.create(path, rig_name=rig.name, camera_resolution=rig.camera.resolution,
                             projector_resolution=rig.projector.resolution)
    calibration = run_calibration(rig, session)
    recorder = Recorder(rig, session)
    photograph = recorder.capture("photograph", recorder.black(), meta={"kind": "photograph"})
    return session, calibration, recorder, photograph


@pytest.mark.parametrize("projector", ["coaxial", "offset"])
def test_checker_gives_the_panels_absolute_albedo_within_2_percent(tmp_path, projector):
    """The panel beside the chart, in its plane; the offset projector lights that plane
    unevenly (the fit models it)."""
    with devices.open_rig("virtual:checker", ideal=True, resolution=(96, 96), projector=projector,
                          cache_dir=tmp_path / "cache") as rig:
        _, calibration, recorder, photograph = _calibrated(rig, tmp_path / "s")
        chart = measure_checker(recorder, calibration, detect_checker(photograph), photograph)
        assert chart.scale.used.all() and np.abs(chart.scale.residual).max() < 0.02, chart.report()
        truth = rig.truth.albedo()
        panel = rig.targets["panel"]
        d = prepare_target(recorder, calibration, panel, photograph, name="panel")
        albedo = chart.scale.albedo(d.direct, d.mask, projector_xy(d))
        np.testing.assert_allclose(albedo, truth[panel].mean(axis=0), rtol=0.02)
        # a wall out of the chart's plane, grazed by the projector from farther away, gets less
        # light per unit albedo than the model says: its chromaticity is right, its albedo not
        wall = rig.targets["right_wall"]
        w = prepare_target(recorder, calibration, wall, photograph, name="wall")
        seen, true = chart.scale.albedo(w.direct, w.mask, projector_xy(w)), truth[wall].mean(axis=0)
        np.testing.assert_allclose(seen / seen.sum(), true / true.sum(), rtol=0.02)
        assert seen[0] / true[0] < 0.8


@pytest.fixture
def cornell_with_card(tmp_path):
    """virtual:cornell with a white card of known reflectance laid over the right wall."""
    scene = json.loads((SCENE_DIR / "cornell.json").read_text())
    card = reference_reflectances()[18]  # the chart's white patch: a known reflectance
    for surface in scene["surfaces"]:
        if surface["name"] == "right_wall":
            surface["albedo"] = card.tolist()
    path = tmp_path / "cornell_card.json"
    path.write_text(json.dumps(scene))
    return path, card


def test_kappa_from_the_papers_colour_alone_is_the_papers_kappa(tmp_path, cornell_with_card):
    """'Make the right wall (0.2, 0.1, 0.8)': κ = (2, 0.125, 8) (Fig. 6) within 2 %, with
    the wall's albedo measured against a card laid over it (the paper's Fig. 7 procedure)."""
    card_scene, card = cornell_with_card
    options = dict(ideal=True, resolution=(64, 64), cache_dir=tmp_path / "cache")
    with devices.open_rig(f"virtual:{card_scene}", **options) as rig:
        _, calibration, recorder, photograph = _calibrated(rig, tmp_path / "card")
        wall = rig.targets["right_wall"]
        reference = prepare_target(recorder, calibration, wall, photograph, name="card")
    scale = reference_scale(reference.direct, card, reference.mask)
    with devices.open_rig("virtual:cornell", **options) as rig:
        session = Session.create(tmp_path / "s", rig_name=rig.name, camera_resolution=rig.camera.resolution,
                                 projector_resolution=rig.projector.resolution)
        run_calibration(rig, session)
        result = run_capture(rig, session, [("right_wall", wall)], 4)
        prepared = result.targets[0][1]
        kappa = kappa_for_albedo(scale.albedo(prepared.direct, prepared.mask), [0.2, 0.1, 0.8])
        np.testing.assert_allclose(kappa, [2.0, 0.125, 8.0], rtol=0.02)
        # without a reference only the colour is known: white-balanced by D it is the albedo's
        colour = direct_colour(load_decomposition(session), direct=prepared.direct)
        true = np.array([0.1, 0.8, 0.1])
        np.testing.assert_allclose(colour / colour.sum(), true / true.sum(), rtol=0.02)
