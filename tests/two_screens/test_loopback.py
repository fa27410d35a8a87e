"""The loopback bench on the "desk" layout: ``albedit calibrate`` and ``albedit capture`` through the
real projector window on HDMI-1 and the real hot-folder camera, compared with the same scene on
the virtual rig (faults: test_loopback_faults.py)."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

import devices
from app.main import main
from devices import loopback
from engine.acquire.predict import relative_error
from engine.recolor import recolor
from engine.session import Session
from engine.workflow import load_calibration, load_decomposition
from tests.two_screens.bench import CAMERA, ORDER, PROJECTOR, SCENE, TARGET, add_rig_options

KAPPA = np.array([1.5, 0.8, 1.2])


def test_the_bench_camera_photographs_exactly_what_the_screen_shows(cache):
    with devices.open_rig(f"loopback:{SCENE}", cache_dir=cache) as rig:
        assert rig.projector.screen_name == "HDMI-1" and rig.projector.resolution == PROJECTOR
        assert type(rig.camera).__name__ == "HotFolderCamera" and rig.camera.resolution == CAMERA
        pattern = np.random.default_rng(1).uniform(0, 1, (*PROJECTOR, 3)).astype(np.float32)
        rig.projector.show(pattern)
        frame = rig.camera.capture()
        (shot,) = rig.bench.shots
        assert shot["screen"] == hashlib.sha1(rig.projector.last_shown.tobytes()).hexdigest()
        assert frame.metadata["file"] == shot["file"] == "IMG_0001.tif" and frame.metadata["stored"] == "uint16"
        truth = rig.truth.photograph(pattern=pattern)
        lit = truth.mean(axis=2) > 0.05
        assert np.median(frame.image[lit] / truth[lit]) == pytest.approx(1.0, abs=0.01)  # the virtual rig's units


@pytest.mark.parametrize("file_format, tolerance", [("tiff", 1.2e-5), ("dng", 1e-6), ("exr", 1e-6)])
def test_each_file_format_carries_the_sensors_values(cache, file_format, tolerance):
    """The same exposure through a file and straight from the virtual rig's sensor (same noise seed)."""
    pattern = np.full((*PROJECTOR, 3), 0.5, np.float32)
    with devices.open_rig(f"loopback:{SCENE}", cache_dir=cache, file_format=file_format) as rig:
        rig.projector.show(pattern)
        frame = rig.camera.capture()
    scene = f"virtual:{SCENE}"
    with devices.open_rig(scene, resolution=CAMERA, projector_resolution=PROJECTOR, supersample=1,
                          cache_dir=cache) as virtual:
        virtual.camera.model, virtual.camera.exposure = loopback._sensor(virtual)
        virtual.projector.show(pattern)
        direct = virtual.camera.capture()
    above_black = direct.image > 0  # files hold no value below the black level (a RAW converter clips there)
    assert frame.exposure == pytest.approx(direct.exposure)
    np.testing.assert_allclose(frame.image[above_black], direct.image[above_black], atol=tolerance)
    if file_format != "exr":  # float files carry no clipping level
        np.testing.assert_array_equal(frame.saturated, direct.saturated)
        assert direct.saturated.any()  # the lamp


@pytest.fixture(scope="module")
def runs(tmp_path_factory, cache):
    """``albedit calibrate`` then ``albedit capture`` on the loopback bench and on the virtual rig."""
    real = devices.open_rig
    mp = pytest.MonkeyPatch()
    add_rig_options(mp, cache)
    out = {}
    try:
        for rig, options in ((f"loopback:{SCENE}", []), (f"virtual:{SCENE}", ["--resolution", "48x64"])):
            session = tmp_path_factory.mktemp(rig.partition(":")[0]) / "session"
            cal = main(["calibrate", str(session), "--rig", rig, *options])
            cap = main(["capture", str(session), "--rig", rig, *options, "--target", TARGET, "--order", str(ORDER)])
            out[rig.partition(":")[0]] = (cal, cap, Session.open(session))
    finally:
        mp.undo()
    with real(f"virtual:{SCENE}", resolution=CAMERA, projector_resolution=PROJECTOR, supersample=1,
              cache_dir=cache) as virtual:
        mask = virtual.targets[TARGET]
        out["truth"] = virtual.truth.recolor([(mask, KAPPA)])
        out["correspondence"] = virtual.truth.correspondence()
        out["surfaces"] = ~virtual.truth.emitters()  # the lamp: clipped in a fixed-exposure camera's files
    return out


def test_calibrate_and_capture_run_on_the_bench(runs):
    for rig in ("loopback", "virtual"):
        cal, cap, session = runs[rig]
        assert (cal, cap) == (0, 0), rig
        assert session.rig_name == f"{rig}:{SCENE}" and tuple(session.projector_resolution) == PROJECTOR


def test_calibration_matches_the_virtual_rig(runs):
    ours, theirs = (load_calibration(runs[rig][2]) for rig in ("loopback", "virtual"))
    a, b = ours.correspondence, theirs.correspondence
    assert a.valid.mean() > 0.7 and (a.valid == b.valid).mean() > 0.99  # cornell at 48x64: 28 % unlit
    both = a.valid & b.valid
    assert (a.x[both] == b.x[both]).mean() > 0.99 and (a.y[both] == b.y[both]).mean() > 0.99  # projector pixels
    xy, lit = runs["correspondence"]
    near = both & lit
    off = np.maximum(np.abs(a.x[near] - xy[near][:, 0]), np.abs(a.y[near] - xy[near][:, 1]))
    assert (off <= 1).mean() > 0.95  # edge pixels straddle two surfaces
    surfaces = runs["surfaces"]  # the virtual rig brackets the lamp, a hot-folder camera cannot
    # the same light, independent noise: the virtual rig seeds each frame from its capture's identity,
    # which the bench camera behind a hot folder cannot know
    difference = ours.black_frame[surfaces] - theirs.black_frame[surfaces]
    assert abs(float(difference.mean())) < 5e-4 and float(np.abs(difference).max()) < 5e-2


def test_recolouring_matches_the_virtual_rig_within_the_noise(runs):
    truth, surfaces = runs["truth"], runs["surfaces"]
    ours, theirs = (load_decomposition(runs[rig][2]) for rig in ("loopback", "virtual"))
    err_ours, err_theirs = (relative_error(recolor(d, KAPPA), truth, surfaces) for d in (ours, theirs))
    assert err_ours < 0.05 and err_theirs < 0.05, (err_ours, err_theirs)
    assert err_ours == pytest.approx(err_theirs, abs=0.01), (err_ours, err_theirs)  # noise: 2-3 %
