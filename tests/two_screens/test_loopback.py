"""The loopback bench on the "desk" layout: ``albedit calibrate`` and ``albedit capture`` through the
real projector window on HDMI-1 and the real hot-folder camera, compared with the same scene on
the virtual rig, and the faults a bench has (a frame that never arrives, a half-written file, a
file for the wrong pattern, the projector window closed mid-run)."""

from __future__ import annotations

import hashlib
import re

import numpy as np
import pytest

import devices
from app.main import main
from devices import loopback
from engine.acquire.predict import relative_error
from engine.recolor import recolor
from engine.session import Session
from engine.workflow import load_calibration, load_decomposition

SCENE, TARGET, ORDER = "cornell", "right_wall", 3
CAMERA, PROJECTOR = (48, 64), (768, 1024)
KAPPA = np.array([1.5, 0.8, 1.2])


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """One virtual set-up of the scene for every rig here (built once, ~10 s)."""
    return tmp_path_factory.mktemp("virtual-cache")


def _add_options(monkeypatch, cache) -> dict:
    """Options the command line cannot give, added to ``devices.open_rig`` per backend."""
    extra = {"loopback": {"cache_dir": cache}, "virtual": {"cache_dir": cache, "projector_resolution": PROJECTOR}}
    real = devices.open_rig
    monkeypatch.setattr(devices, "open_rig", lambda name, **options: real(name, **options, **extra.get(name.partition(":")[0], {})))
    return extra


@pytest.fixture
def rig_options(monkeypatch, cache):
    return _add_options(monkeypatch, cache)


def _cli(capsys, *argv) -> tuple[int, list[str]]:
    status = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return status, [line.split("\r")[-1] for line in err.strip().splitlines()]


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
    with devices.open_rig(f"virtual:{SCENE}", resolution=CAMERA, projector_resolution=PROJECTOR, cache_dir=cache) as virtual:
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
    _add_options(mp, cache)
    out = {}
    try:
        for rig, options in ((f"loopback:{SCENE}", []), (f"virtual:{SCENE}", ["--resolution", "48x64"])):
            session = tmp_path_factory.mktemp(rig.partition(":")[0]) / "session"
            cal = main(["calibrate", str(session), "--rig", rig, *options])
            cap = main(["capture", str(session), "--rig", rig, *options, "--target", TARGET, "--order", str(ORDER)])
            out[rig.partition(":")[0]] = (cal, cap, Session.open(session))
    finally:
        mp.undo()
    with real(f"virtual:{SCENE}", resolution=CAMERA, projector_resolution=PROJECTOR, cache_dir=cache) as virtual:
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
    np.testing.assert_allclose(ours.black_frame[surfaces], theirs.black_frame[surfaces], atol=2e-3)


def test_recolouring_matches_the_virtual_rig_within_the_noise(runs):
    truth, surfaces = runs["truth"], runs["surfaces"]
    ours, theirs = (load_decomposition(runs[rig][2]) for rig in ("loopback", "virtual"))
    err_ours, err_theirs = (relative_error(recolor(d, KAPPA), truth, surfaces) for d in (ours, theirs))
    assert err_ours < 0.05 and err_theirs < 0.05, (err_ours, err_theirs)
    assert err_ours == pytest.approx(err_theirs, abs=0.01), (err_ours, err_theirs)  # noise: 2-3 %


@pytest.mark.parametrize(
    "fault, options, message",
    [
        ("drop", {"timeout": 1.0}, r"albedit calibrate: error: no new image arrived in hot folder '.*' within 1 s after running \["),
        ("partial", {"timeout": 3.0, "quiet": 0.3}, r"albedit calibrate: error: hot-folder file 'IMG_0003.tif' \(\d+ bytes, unchanged for 0.\d s\) cannot be read: "),
        ("twice", {}, r"albedit calibrate: error: hot folder '.*' received 'IMG_0003b.tif' before the camera was triggered: a frame taken for an earlier pattern"),
        ("close", {}, r"albedit calibrate: error: the projector window on 'HDMI-1' was closed \(by the user or the window manager\) while the rig was open"),
    ],
)
def test_bench_faults_end_in_one_plain_line_and_the_run_resumes(tmp_path, capsys, rig_options, fault, options, message):
    session = tmp_path / "session"
    rig_options["loopback"].update(options, faults={3: fault})
    status, lines = _cli(capsys, "calibrate", session, "--rig", f"loopback:{SCENE}")
    # the error follows the unfinished progress bar on its line (app.cli.ProgressBar is not ended on errors)
    assert status == 1 and re.search(message, lines[-1]), lines
    kept = Session.open(session).captures
    assert [c.name for c in kept][:2] == ["cal-black", "cal-white"]  # nothing taken is lost
    del rig_options["loopback"]["faults"]
    status, lines = _cli(capsys, "calibrate", session, "--rig", f"loopback:{SCENE}")
    assert status == 0 and any(line.startswith(f"calibrated loopback:{SCENE} into") for line in lines), lines
