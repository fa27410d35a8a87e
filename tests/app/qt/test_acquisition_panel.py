"""The acquisition panel on calibrated virtual rigs (24×24, ideal, offscreen)."""

from __future__ import annotations

import os

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

import shutil  # noqa: E402
import threading  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from PySide6.QtWidgets import QMessageBox  # noqa: E402

import devices  # noqa: E402
from app.qt.acquisition_panel import AcquisitionPanel, unreachable_target_pixels  # noqa: E402
from engine.acquire import CaptureSettings  # noqa: E402
from engine.acquire.target import pattern_budget  # noqa: E402
from engine.calibrate import PixelStatus  # noqa: E402
from engine.session import Session  # noqa: E402
from engine.session.edit import mask_digest, mask_name  # noqa: E402
from engine.workflow import load_calibration, load_decomposition, run_calibration  # noqa: E402

RES = 24
TIMEOUT_MS = 30_000


def _calibrated(tmp_path_factory, virtual_cache, scene: str, projector: str):
    rig = devices.open_rig(f"virtual:{scene}", ideal=True, resolution=(RES, RES), projector=projector,
                           cache_dir=str(virtual_cache))
    path = tmp_path_factory.mktemp(scene) / "calibrated"
    session = Session.create(path, rig_name=rig.identity, camera_resolution=rig.camera.resolution,
                             projector_resolution=rig.projector.resolution)
    run_calibration(rig, session)
    return rig, path


@pytest.fixture(scope="module")
def cornell(tmp_path_factory, virtual_cache):
    """(rig, folder of a calibrated session): co-axial Cornell box."""
    rig, path = _calibrated(tmp_path_factory, virtual_cache, "cornell", "coaxial")
    yield rig, path
    rig.close()


@pytest.fixture
def fresh(cornell, tmp_path):
    """(rig, a private copy of the calibrated session)."""
    rig, template = cornell
    shutil.copytree(template, tmp_path / "s")
    return rig, Session.open(tmp_path / "s")


@pytest.fixture
def dialogs(monkeypatch):
    """Every QMessageBox the panel opens, recorded instead of shown (a modal box hangs CI)."""
    shown = []
    for kind in ("warning", "critical", "information"):
        monkeypatch.setattr(QMessageBox, kind,
                            lambda *args, _k=kind: shown.append((_k, *args[1:])) or QMessageBox.StandardButton.Ok)
    return shown


@pytest.fixture
def make_panel(qtbot):
    """Factory: a shown panel; pytest-qt closes it after the test (closing cancels a run)."""

    def make(*args, **kw):
        panel = AcquisitionPanel(*args, **kw)
        qtbot.addWidget(panel)
        panel.show()
        return panel

    return make


def _expected_captures(order: int, targets: int = 1) -> int:
    """Camera shots of an uninterrupted single-target acquisition (per-channel emission).

    The first re-emission sends the photograph, which has no negative part: 3 captures; later
    ones may split their negative noise off (at most ``captures_per_step``), so beyond order 2
    this is an upper bound.
    """
    later = order**targets - 2
    return 1 + targets * pattern_budget(True, spread=True) + 3 + max(later, 0) * CaptureSettings().captures_per_step()


def _acq(session) -> dict[str, str]:
    return {c.name: (c.sha256, c.time, c.index)
            for c in Session.open(session.path).captures if c.name.startswith("acq-")}


def test_panel_acquires_a_target_with_thumbnails_pause_and_resume(fresh, make_panel, qtbot, dialogs, monkeypatch):
    rig, session = fresh
    # the worker's second camera shot waits until the test has seen the pause: no race with the worker
    shots, go = [], threading.Event()
    capture = rig.camera.capture

    def gated_capture():
        shots.append(threading.current_thread().name)
        if len(shots) == 2:
            go.wait(TIMEOUT_MS / 1000)
        return capture()

    monkeypatch.setattr(rig.camera, "capture", gated_capture)
    # and the test sees when the worker parks at the pause (it may do so before its second shot)
    from app.qt.worker import Job

    parked, should_stop = threading.Event(), Job.should_stop

    def watched(job):
        if job.is_paused:
            parked.set()
        return should_stop(job)

    monkeypatch.setattr(Job, "should_stop", watched)
    panel = make_panel(rig, session, [("right_wall", rig.targets["right_wall"])])
    panel.order.setValue(2)
    assert panel.start_button.text() == "Start" and not panel.threshold.isEnabled()
    assert "right_wall" in panel.targets_label.text()
    panel.thumbnail_added.connect(lambda name: panel.pause_button.setChecked(True))
    started = []
    panel.started.connect(started.append)
    panel.start_button.click()
    qtbot.waitUntil(lambda: bool(started) and started[0].is_paused, timeout=TIMEOUT_MS)
    assert panel.pause_button.text() == "Resume" and not panel.start_button.isEnabled()
    assert not panel.order.isEnabled()  # settings are locked while a run holds the rig
    # the worker is held either in its second shot (by the gate) or at the pause before it; a loaded
    # machine may take a while to get it to either place
    qtbot.waitUntil(lambda: len(shots) == 2 or parked.is_set(), timeout=TIMEOUT_MS)
    go.set()
    qtbot.waitUntil(lambda: len(_acq(session)) == len(shots), timeout=TIMEOUT_MS)
    held = len(_acq(session))
    qtbot.wait(200)
    assert held in (1, 2) and len(_acq(session)) == held and len(shots) == held and started[0].is_paused
    panel.thumbnail_added.disconnect()
    with qtbot.waitSignal(panel.acquired, timeout=TIMEOUT_MS) as blocker:
        panel.pause_button.setChecked(False)
    result = blocker.args[0]
    assert threading.main_thread().name not in shots  # every shot on the worker

    assert result.images == 2 and result.acquisition.observations.shape == (2, RES, RES, 3)
    names = list(_acq(session))
    assert len(names) == _expected_captures(2)
    qtbot.waitUntil(lambda: panel.thumbnails.count() == len(names), timeout=TIMEOUT_MS)
    assert panel.thumbnails.names() == names  # every capture, in arrival order
    icon = panel.thumbnails.item(0).icon()
    assert not icon.isNull() and max(icon.availableSizes()[0].width(), icon.availableSizes()[0].height()) <= 72
    d = load_decomposition(Session.open(session.path))
    assert d.order == 2
    np.testing.assert_array_equal(d.target, result.targets[-1][1].mask)
    shots = len(names)  # the bar and the summary count the same camera shots
    assert f"Captured 2 observation images (0 predicted) in {shots} camera shots" in panel.status.text()
    assert panel.eta.bar.format() == f"{shots} / {shots} camera shots" and "right_wall: all" in panel.status.text()
    assert dialogs == [] and not panel.busy and panel.start_button.isEnabled()


def test_cancel_then_resume_after_a_restart_reuses_the_captures(fresh, make_panel, qtbot, dialogs):
    rig, session = fresh
    target = [("right_wall", rig.targets["right_wall"])]
    first = make_panel(rig, session, target, synchronous=True)
    first.order.setValue(3)
    first.started.connect(lambda job: job.progress.connect(lambda s, t, m: s >= 10 and job.cancel()))
    with qtbot.waitSignal(first.cancelled):
        first.start_button.click()
    kept = _acq(session)
    assert 10 <= len(kept) < _expected_captures(3)
    assert "taken so far stay in the session" in first.status.text() and first.start_button.text() == "Resume"
    assert first.result is None and dialogs == []

    # a restart: a new panel on the same session finds the interrupted plan and restores it
    second = make_panel(rig, Session.open(session.path), target, synchronous=True)
    assert second.order.value() == 3 and second.start_button.text() == "Resume"
    assert "interrupted acquisition of right_wall" in second.status.text()
    second.order.setValue(4)  # another plan would overwrite the kept one: refused, nothing written
    second.start_button.click()
    assert dialogs[-1][0] == "warning" and "different acquisition plan" in dialogs[-1][2]
    assert _acq(session) == kept
    second.order.setValue(3)
    with qtbot.waitSignal(second.acquired, timeout=TIMEOUT_MS) as blocker:
        second.start_button.click()
    final = _acq(session)
    assert len(kept) < len(final) <= _expected_captures(3)
    assert {n: final[n] for n in kept} == kept  # reused, never retaken
    assert blocker.args[0].images == 3 and load_decomposition(Session.open(session.path)).order == 3
    qtbot.waitUntil(lambda: second.thumbnails.count() == len(final), timeout=TIMEOUT_MS)


def test_refuses_without_a_calibration(cornell, make_panel, tmp_path, dialogs):
    rig, _ = cornell
    bare = Session.create(tmp_path / "bare", rig_name=rig.identity, camera_resolution=rig.camera.resolution,
                          projector_resolution=rig.projector.resolution)
    panel = make_panel(rig, bare, [("right_wall", rig.targets["right_wall"])], synchronous=True)
    refused = []
    panel.refused.connect(refused.append)
    assert panel.start() is None
    assert "has no calibration" in refused[0] and "Calibrate the rig" in refused[0]
    assert dialogs == [("warning", "Cannot start the acquisition", refused[0])]
    assert not Session.open(bare.path).captures and not panel.busy


@pytest.fixture(scope="module")
def wedge_offset(tmp_path_factory, virtual_cache):
    """The wedge seen with the offset projector: the top rows are in the projector's shadow."""
    rig, path = _calibrated(tmp_path_factory, virtual_cache, "wedge", "offset")
    yield rig, path
    rig.close()


def test_refuses_a_target_the_projector_cannot_reach(wedge_offset, make_panel, dialogs):
    rig, path = wedge_offset
    session = Session.open(path)
    calibration = load_calibration(session)
    shadow = calibration.correspondence.status == PixelStatus.UNLIT
    assert shadow.any()  # the scene has a projector shadow at this pose
    painted = shadow & ~rig.targets["left"]
    panel = make_panel(rig, session, [("left", rig.targets["left"]), ("backdrop", painted)], [(1.5, 1.0, 1.0)],
                       synchronous=True)
    assert not unreachable_target_pixels(calibration, rig.targets["left"]).any()
    assert unreachable_target_pixels(calibration, painted).sum() == painted.sum()
    refused = []
    panel.refused.connect(refused.append)
    panel.start_button.click()
    n = int(painted.sum())
    assert refused == [f"Target 'backdrop': {n} of {n} painted pixels cannot be reached by the projector "
                       f"({n} unlit). Erase them from the target (the calibration's coverage map shows where "
                       "the projector reaches), or move the projector and recalibrate."]
    assert dialogs[-1][2] == refused[0] and "backdrop" in panel.status.text()
    assert not [c for c in Session.open(path).captures if c.name.startswith("acq-")]


def test_settings_reach_the_engine(fresh, make_panel):
    rig, session = fresh
    panel = make_panel(rig, session, [("right_wall", rig.targets["right_wall"])])
    assert panel.adaptive() is None and panel.capture_settings().per_channel
    assert panel.flood.value() == 0 and panel.photograph_pattern() is None  # the Cornell box has its lamp
    panel.policy.setCurrentIndex(1)
    panel.threshold.setValue(2.5)
    panel.emission.setCurrentIndex(1)
    assert panel.threshold.isEnabled()
    assert panel.adaptive().to_dict() == {"policy": "linear", "threshold": 0.025, "noise_band": True}
    assert panel.capture_settings().per_channel is False
    panel.set_targets([("a", rig.targets["left_wall"]), ("b", rig.targets["right_wall"])])
    assert "needs the fixed κ of the first 1, got 0" in panel.check_ready()
    panel.set_targets([("a", rig.targets["left_wall"]), ("b", rig.targets["right_wall"])], [0.5])
    assert panel.check_ready() == "" and "κ fixed 0.5, 0.5, 0.5" in panel.targets_label.text()


def test_leave_out_trims_only_the_unreachable_pixels(wedge_offset, make_panel, qtbot, tmp_path, dialogs):
    rig, template = wedge_offset
    shutil.copytree(template, tmp_path / "s")
    session = Session.open(tmp_path / "s")
    calibration = load_calibration(session)
    shadow = calibration.correspondence.status == PixelStatus.UNLIT
    painted = rig.targets["left"] | shadow  # painted over the edge into the projector's shadow
    bad = unreachable_target_pixels(calibration, painted)
    assert bad.any() and not bad.all()
    panel = make_panel(rig, session, [("left", painted)])
    panel.order.setValue(2)
    assert "cannot be reached by the projector" in panel.check_ready()
    panel.leave_out.setChecked(True)
    assert panel.check_ready() == ""
    with qtbot.waitSignal(panel.acquired, timeout=TIMEOUT_MS):
        panel.start_button.click()
    stored = mask_name("left", mask_digest(painted & ~bad))
    np.testing.assert_array_equal(Session.open(session.path).read_mask(stored), painted & ~bad)
    assert f"{int(bad.sum())} pixels of 'left' the projector cannot reach were left out" in panel.status.text()
    assert dialogs == []


def test_a_scene_lit_by_the_projector_is_photographed_under_its_flood(wedge_offset, make_panel, qtbot, tmp_path,
                                                                       dialogs):
    """The wedge has no light but the projector's: the app photographed it under projector black (a dark
    photograph with nothing to recolor); the panel now floods it as its scene says, and a resumed plan keeps its own
    flood."""
    rig, template = wedge_offset
    shutil.copytree(template, tmp_path / "s")
    session = Session.open(tmp_path / "s")
    panel = make_panel(rig, session, [("right", rig.targets["right"])])
    assert panel.flood.value() == 100.0 and panel.flood.isEnabled()  # the scene's natural light
    panel.order.setValue(2)
    panel.flood.setValue(60.0)
    with qtbot.waitSignal(panel.acquired, timeout=TIMEOUT_MS) as blocker:
        panel.start_button.click()
    assert dialogs == []
    stored = Session.open(session.path)
    assert stored.state["plan"]["photograph_pattern"]
    np.testing.assert_allclose(stored.read_array("acquisition", "photograph_pattern"), 0.6)
    photo = blocker.args[0].acquisition.observations[0]
    lit = rig.targets["right"]
    np.testing.assert_allclose(photo[lit].mean(), rig.truth.photograph(pattern=np.full(
        (*rig.projector.resolution, 3), 0.6, np.float32))[lit].mean(), rtol=0.02)
    again = make_panel(rig, stored, [("right", rig.targets["right"])])
    assert again.flood.value() == 60.0  # the plan's flood, not the scene's
    shutil.copytree(template, tmp_path / "t")
    again.set_session(Session.open(tmp_path / "t"))  # no plan: the scene's light again, not the last plan's
    assert again.flood.value() == 100.0


def test_progress_shows_count_and_time_left(qtbot):
    from app.qt.worker import JobProgress

    now = [100.0]
    eta = JobProgress("p", unit="images", clock=lambda: now[0])
    qtbot.addWidget(eta)
    eta.update_progress(4, 10, "captured cal-003")
    assert eta.seconds_left is None and eta.bar.format() == "4 / 10 images"
    eta.update_progress(4, 10, "capturing cal-004")
    now[0] += 6.0
    eta.update_progress(7, 10, "capturing cal-007")  # 3 captures in 6 s: 2 s each, 3 to go
    assert eta.seconds_left == pytest.approx(6.0) and "about 6 s left" in eta.label.text()
    assert eta.label.toolTip() == eta.label.text()  # cut short in a narrow status bar: hover reads it whole
    assert eta.bar.value() == 7 and eta.bar.maximum() == 10
    for step in range(8, 17):  # instant steps at the start (a resumed run) leave the window
        now[0] += 1.0
        eta.update_progress(step, 20, "capturing")
    assert eta.seconds_left == pytest.approx(4.0)  # 1 s per step, 4 to go
