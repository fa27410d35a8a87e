"""The calibration wizard, driven page by page on the virtual rig (24×24, ideal, offscreen)."""

from __future__ import annotations

import os

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

import threading  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from PySide6.QtCore import Qt  # noqa: E402
from PySide6.QtWidgets import QWizard  # noqa: E402

import app.qt.calibration_wizard as wizard_module  # noqa: E402
import devices  # noqa: E402
from app.qt.calibration_wizard import CalibrationWizard  # noqa: E402
from devices.qtscreen import identify_pattern  # noqa: E402
from devices.registry import Availability  # noqa: E402
from engine.acquire import calibration_budget  # noqa: E402
from engine.calibrate import Calibration, PixelStatus, projector_lit  # noqa: E402
from engine.errors import InputError  # noqa: E402
from engine.session import Session  # noqa: E402
from engine.workflow import load_calibration, run_calibration, save_calibration  # noqa: E402

RES = 24
TIMEOUT_MS = 30_000


@pytest.fixture
def make_wizard(qtbot, tmp_path, virtual_cache):
    """Factory: a wizard on virtual:cornell, ideal, RES×RES, session folder in tmp_path."""
    made = []

    def make(**kw):
        kw.setdefault("rig_name", "virtual:cornell")
        kw.setdefault("rig_options", {"cache_dir": str(virtual_cache)})
        kw.setdefault("session_path", tmp_path / "session")
        kw.setdefault("live_interval_ms", 20)
        w = CalibrationWizard(**kw)
        w.rig_page.ideal.setChecked(True)
        w.rig_page.res_h.setValue(RES)
        w.rig_page.res_w.setValue(RES)
        qtbot.addWidget(w)
        w.show()
        made.append(w)
        return w

    yield make
    for w in made:
        if w.isVisible():
            w.reject()  # cancels jobs, closes the rig it opened


def _to_calibration_page(w: CalibrationWizard, qtbot) -> None:
    w.next()
    assert w.currentId() == w.PAGE_PROJECTOR
    w.next()  # opens the rig (threaded: moves on by itself when done)
    qtbot.waitUntil(lambda: w.currentId() == w.PAGE_EXPOSURE, timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: w.exposure_page.live.frames >= 1, timeout=TIMEOUT_MS)
    w.next()
    assert w.currentId() == w.PAGE_CALIBRATE


def _snapshot(session_path) -> dict[str, str]:
    return {c.name: (c.sha256, c.time, c.index) for c in Session.open(session_path).captures}


def test_rig_page_greys_out_unavailable_rigs_with_their_reason(make_wizard, monkeypatch):
    monkeypatch.setattr(devices, "available", lambda: [
        Availability("virtual:cornell", True, "simulated rig"),
        Availability("gphoto2", False, "cannot import: No module named 'gphoto2'"),
    ])
    w = make_wizard()
    items = [w.rig_page.rigs.item(i) for i in range(w.rig_page.rigs.count())]
    assert [bool(i.flags() & Qt.ItemFlag.ItemIsEnabled) for i in items] == [True, False]
    assert "No module named 'gphoto2'" in items[1].text() and "gphoto2" in items[1].toolTip()
    assert w.rig_page.rig_name.text() == "virtual:cornell" and w.rig_page.virtual.isEnabled()
    assert w.rig_page.options() == {"ideal": True, "projector": "coaxial", "resolution": (RES, RES)}

    w.rig_page.rig_name.setText("nosuch:0")  # a hardware-like backend: screens, no virtual options
    assert not w.rig_page.virtual.isEnabled() and w.rig_page.options() == {}
    w.next()
    assert not w.projector_page.screens.isHidden() and w.projector_page.screens.count() >= 1
    assert w.projector_page.options()["projector"].startswith("qtscreen:")
    w.next()  # opening fails: the engine's message is shown and the wizard stays
    assert w.currentId() == w.PAGE_PROJECTOR and w.rig is None
    assert "unknown rig backend 'nosuch'" in w.projector_page.status.text()


def test_wizard_opens_the_path_traced_rig_like_the_virtual_one(make_wizard, qtbot, tmp_path):
    pytest.importorskip("mitsuba", reason="the mitsuba extra is not installed: pip install 'albedit[mitsuba]'")
    w = make_wizard(rig_name="mitsuba:cornell",
                    rig_options={"cache_dir": str(tmp_path / "mi"), "spp": 4, "ambient_spp": 8, "coverage_passes": 4})
    assert w.rig_page.virtual.isEnabled()
    assert w.rig_page.options() == {"ideal": True, "projector": "coaxial", "resolution": (RES, RES)}
    w.next()
    assert w.currentId() == w.PAGE_PROJECTOR and w.projector_page.screens.isHidden()
    w.next()  # opens the rig on a worker: loading Mitsuba and rendering take longer than the virtual rig
    qtbot.waitUntil(lambda: w.currentId() == w.PAGE_EXPOSURE, timeout=4 * TIMEOUT_MS)
    qtbot.waitUntil(lambda: w.exposure_page.live.frames >= 1, timeout=4 * TIMEOUT_MS)
    assert w.rig.name == "mitsuba:cornell" and w.rig.camera.resolution == (RES, RES)


def test_wizard_calibrates_into_a_session_on_workers(make_wizard, qtbot, tmp_path):
    w = make_wizard()
    w.next()
    assert "simulates its projector" in w.projector_page.note.text()
    w.next()
    qtbot.waitUntil(lambda: w.currentId() == w.PAGE_EXPOSURE, timeout=TIMEOUT_MS)
    rig = w.rig
    assert rig.name == "virtual:cornell" and rig.camera.resolution == (RES, RES)
    page = w.exposure_page
    qtbot.waitUntil(lambda: page.live.frames >= 2, timeout=TIMEOUT_MS)
    assert page.grabbed_on and page.grabbed_on != threading.main_thread().name  # grabbed on a worker
    assert "does not clip" in page.report.text() and page.live.saturated_fraction == 0.0  # the ideal camera
    page.exposure.setValue(page.exposure.value() / 2)  # the worker applies it to the camera
    qtbot.waitUntil(lambda: np.isclose(rig.camera.exposure * 1000, page.exposure.value(), rtol=1e-3),
                    timeout=TIMEOUT_MS)
    w.next()
    cal_page = w.calibration_page
    assert cal_page.start.text() == "Start"
    with qtbot.waitSignal(w.calibrated, timeout=TIMEOUT_MS) as blocker:
        cal_page.start.click()
    calibration = blocker.args[0]
    qtbot.waitUntil(cal_page.isComplete, timeout=TIMEOUT_MS)
    budget = calibration_budget((RES, RES))
    assert cal_page.eta.bar.value() == budget and f"{budget} / {budget}" in cal_page.eta.bar.format()

    w.next()
    assert w.currentId() == w.PAGE_RESULTS
    coverage = w.results_page.coverage
    counts = calibration.correspondence.counts()
    assert {p.name.lower(): n for p, n in coverage.counts.items()} == counts
    assert counts["decoded"] > 0.9 * RES * RES
    assert coverage.legend_lines()[0].startswith(f"decoded: {counts['decoded']} (")
    np.testing.assert_array_equal(w.results_page.response.measured, calibration.response.raw_table)
    assert calibration.correspondence.summary() in w.results_page.coverage_text.text()

    session_path = tmp_path / "session"
    loaded = load_calibration(Session.open(session_path))
    assert loaded.rig_name == "virtual:cornell" and loaded.camera_resolution == (RES, RES)
    np.testing.assert_array_equal(loaded.correspondence.status, calibration.correspondence.status)
    names = [c.name for c in Session.open(session_path).captures]
    assert len(names) == len(set(names)) == budget

    w.next()
    assert w.currentId() == w.PAGE_SUMMARY
    assert "Nothing to fix" in w.summary_page.text.toPlainText()
    with qtbot.waitSignal(w.finished_session, timeout=TIMEOUT_MS) as done:
        w.button(QWizard.WizardButton.FinishButton).click()
    assert done.args[0].path == w.result_session.path and w.result_session.path.resolve() == session_path.resolve()
    assert rig.closed and w.rig is None  # the wizard opened it, keep_rig=False: closed on Finish


def test_cancel_then_resume_and_restart_reuse_every_capture(make_wizard, qtbot, tmp_path):
    session_path = tmp_path / "session"
    budget = calibration_budget((RES, RES))
    stops = [12, 25]

    def cancel_at_next_stop(job):
        at = stops.pop(0)
        job.progress.connect(lambda step, total, message: step >= at and job.cancel())

    first = make_wizard(synchronous=True)
    _to_calibration_page(first, qtbot)
    page = first.calibration_page
    first.job_started.connect(cancel_at_next_stop)
    cancelled = []
    first.job_started.connect(lambda job: job.cancelled.connect(cancelled.append))

    page.start.click()  # cancelled after 12 captures
    kept = _snapshot(session_path)
    assert len(cancelled) == 1 and first.calibration is None and 12 <= len(kept) < budget
    assert "kept in the session" in page.status.text() and page.start.text() == "Resume"
    assert not page.isComplete()

    page.start.click()  # resumes, then cancelled again after 25
    again = _snapshot(session_path)
    assert len(cancelled) == 2 and 25 <= len(again) < budget
    assert {n: again[n] for n in kept} == kept  # the first captures were reused, not retaken
    first.reject()  # "quit": the rig is closed, the session keeps its captures

    second = make_wizard(synchronous=True)  # a restart on the same folder
    _to_calibration_page(second, qtbot)
    page = second.calibration_page
    assert page.start.text() == "Resume" and f"{len(again)} already in the session" in page.info.text()
    with qtbot.waitSignal(second.calibrated, timeout=TIMEOUT_MS):
        page.start.click()
    final = _snapshot(session_path)
    assert len(final) == budget and {n: final[n] for n in again} == again
    assert load_calibration(Session.open(session_path)).correspondence.valid.sum() > 0.9 * RES * RES


@pytest.fixture(scope="module")
def donor_session(tmp_path_factory, virtual_cache):
    """A session of the same rig, calibrated by the engine (the calibration to reuse)."""
    path = tmp_path_factory.mktemp("donor") / "calibrated"
    with devices.open_rig("virtual:cornell", ideal=True, resolution=(RES, RES), projector="coaxial",
                          cache_dir=str(virtual_cache)) as rig:
        session = Session.create(path, rig_name=rig.identity, camera_resolution=rig.camera.resolution,
                                 projector_resolution=rig.projector.resolution)
        run_calibration(rig, session)
    return path


def test_reuse_calibration_of_another_session_checks_the_rig(make_wizard, qtbot, tmp_path, donor_session):
    donor = load_calibration(Session.open(donor_session))
    meta, arrays = donor.to_dict()
    foreign = Session.create(tmp_path / "foreign", rig_name="virtual:wedge", camera_resolution=(RES, RES),
                             projector_resolution=(RES, RES))
    save_calibration(foreign, Calibration.from_dict(dict(meta, rig_name="virtual:wedge"), arrays))

    w = make_wizard(synchronous=True)
    _to_calibration_page(w, qtbot)
    page = w.calibration_page
    page.mode_reuse.setChecked(True)
    assert page.reuse_box.isEnabled() and not page.start.isEnabled()
    page.reuse_path.setText(str(foreign.path))
    page.use.click()
    assert ("Refused: calibration was made for rig 'virtual:wedge', this rig is 'virtual:cornell'; recalibrate"
            in page.status.text())
    assert w.calibration is None and not page.isComplete() and not w.session.read_calibration()[0]

    page.reuse_path.setText(str(donor_session))
    with qtbot.waitSignal(w.calibrated):
        page.use.click()
    assert page.isComplete() and "Using the calibration of" in page.status.text()
    copied = load_calibration(Session.open(tmp_path / "session"))
    np.testing.assert_array_equal(copied.correspondence.x, donor.correspondence.x)
    assert not Session.open(tmp_path / "session").captures  # reused, nothing captured
    w.next()
    assert w.currentId() == w.PAGE_RESULTS
    assert w.results_page.coverage.counts[PixelStatus.DECODED] == int(donor.correspondence.valid.sum())


def test_failure_is_shown_verbatim_with_a_fix_on_the_summary(make_wizard, qtbot, monkeypatch):
    message = ("the camera saw no change between projector black and white: is the projector on, "
               "pointed at the scene, and the camera's exposure long enough?")

    def broken(*args, **kwargs):
        raise InputError(message)

    monkeypatch.setattr(wizard_module, "run_calibration", broken)
    w = make_wizard(synchronous=True)
    _to_calibration_page(w, qtbot)
    page = w.calibration_page
    finished = []
    w.finished_session.connect(finished.append)
    page.start.click()
    assert isinstance(w.failure, InputError) and w.calibration is None
    assert message in page.status.text()
    assert page.isComplete() and page.start.isEnabled()  # Start again retries; Next explains
    w.next()
    assert w.currentId() == w.PAGE_SUMMARY  # no results page without a calibration
    text = w.summary_page.text.toPlainText()
    assert message in text and "press Start again" in text and "No calibration" in text
    w.button(QWizard.WizardButton.FinishButton).click()
    assert finished == [] and w.result_session is None


def test_session_of_another_rig_is_refused(make_wizard, qtbot, tmp_path):
    Session.create(tmp_path / "other", rig_name="virtual:wedge", camera_resolution=(RES, RES),
                   projector_resolution=(RES, RES))
    w = make_wizard(synchronous=True, session_path=tmp_path / "other")
    w.next()
    w.next()
    assert w.currentId() == w.PAGE_PROJECTOR and w.rig is not None and w.session is None
    assert "belongs to rig 'virtual:wedge'" in w.projector_page.status.text()
    assert "choose a new session folder" in w.projector_page.status.text()


def test_auto_exposure_and_identify_on_the_exposure_page(make_wizard, qtbot):
    w = make_wizard()
    w.rig_page.ideal.setChecked(False)  # the realistic camera clips; the ideal one never does
    w.next()
    w.next()
    qtbot.waitUntil(lambda: w.currentId() == w.PAGE_EXPOSURE, timeout=TIMEOUT_MS)
    page, rig = w.exposure_page, w.rig
    page.level.setCurrentIndex(2)  # identify: the grid with its centre cross goes to the projector
    qtbot.waitUntil(lambda: page.live.frames >= 1 and page._shown == "identify", timeout=TIMEOUT_MS)
    hp, wp = rig.projector.resolution
    np.testing.assert_array_equal(rig.projector._input, identify_pattern((hp, wp), label=f"{rig.name}  {wp}x{hp}"))
    page.exposure.setValue(0.01)  # 0.01 ms: far too dark
    page.auto_button.click()  # a black frame first (the lamp), then steps under white
    assert page.level.currentIndex() == 1 and not page.auto_button.isEnabled()
    qtbot.waitUntil(lambda: page.auto is None, timeout=TIMEOUT_MS)
    assert "settled" in page.report.text() and page.auto_button.isEnabled() and page.level.currentIndex() == 0
    assert page.controller.frames <= 3  # the frames say where the camera clips: one jump, then settled
    qtbot.waitUntil(lambda: np.isclose(rig.camera.exposure * 1000, page.exposure.value(), rtol=1e-3),
                    timeout=TIMEOUT_MS)
    white = rig.camera.capture()
    rig.projector.show(np.zeros(rig.projector.resolution + (3,), np.float32))
    lit = projector_lit(white.image, rig.camera.capture().image)
    assert white.saturated[lit].mean() <= 0.005 and lit.mean() > 0.8
    # the bright end of the projector-lit pixels sits near 0.8 of full scale; the lamp may clip
    m = rig.camera.model
    clip_electrons = min(m.full_well, (m.white_level - m.black_level) * m.electrons_per_dn)
    clip = clip_electrons / (m.electrons_per_radiance * white.exposure)
    assert 0.8 / 1.26 <= np.percentile(white.image.max(axis=-1)[lit], 99.5) / clip <= 0.8 * 1.26
    assert white.saturated[~lit].any()  # the lamp is not projector light: it may clip


def test_auto_exposure_settles_at_once_on_a_camera_that_does_not_clip(make_wizard, qtbot):
    """Defect 6: on the ideal camera Auto ran the exposure up to an hour and reported "ok" over white."""
    w = make_wizard()
    w.next()
    w.next()
    qtbot.waitUntil(lambda: w.currentId() == w.PAGE_EXPOSURE, timeout=TIMEOUT_MS)
    page = w.exposure_page
    before = page.exposure.value()
    page.auto_button.click()
    qtbot.waitUntil(lambda: page.auto is None, timeout=TIMEOUT_MS)
    assert page.controller.frames == 1 and page.exposure.value() == before
    assert "does not clip" in page.report.text() and np.isclose(w.rig.camera.exposure * 1000, before)
    # the picture is the same at any exposure: a long one does not turn it white
    image = page.live._image
    page.exposure.setValue(before * 64)
    frames = page.live.frames
    qtbot.waitUntil(lambda: page.live.frames > frames + 1, timeout=TIMEOUT_MS)
    assert page.live._image == image


def test_live_view_runs_again_after_back_and_enter_does_not_leave_the_page(make_wizard, qtbot):
    """Defect 7: the live view froze after Next → Back; Enter in the exposure box went to the next page."""
    from tests.app.qt.user import User

    w = make_wizard()
    user = User(qtbot, w)
    w.next()
    w.next()
    qtbot.waitUntil(lambda: w.currentId() == w.PAGE_EXPOSURE, timeout=TIMEOUT_MS)
    page = w.exposure_page
    qtbot.waitUntil(lambda: page.live.frames >= 1, timeout=TIMEOUT_MS)
    user.type_into("wizard_exposure", "12.5")  # typed, then Enter
    assert w.currentId() == w.PAGE_EXPOSURE and page.exposure.value() == 12.5
    qtbot.waitUntil(lambda: np.isclose(w.rig.camera.exposure, 0.0125), timeout=TIMEOUT_MS)
    user.click("wizard_next")
    assert w.currentId() == w.PAGE_CALIBRATE
    user.click("wizard_back")
    frames = page.live.frames
    qtbot.waitUntil(lambda: page.live.frames >= frames + 2, timeout=TIMEOUT_MS)  # live again


def test_the_main_window_wizard_starts_from_the_document_and_remembers(make_window, qtbot, tmp_path, monkeypatch):
    """Defect 5: the wizard ignored the open document, showed a repr, left empty folders behind."""
    from PySide6.QtWidgets import QWizard

    from app.model.document import Document
    from tests.app.qt.user import User

    window = make_window(Document(np.full((RES, RES + 8, 3), 0.2, np.float32)))
    user = User(qtbot, window)
    monkeypatch.setattr(CalibrationWizard, "default_session_path", lambda self: tmp_path / "new-session")
    user.trigger("calibrate")
    w = window.findChild(QWizard, "calibration_wizard")
    assert (w.rig_page.res_h.value(), w.rig_page.res_w.value()) == (RES, RES + 8)  # the document's resolution
    w.rig_page.res_w.setValue(RES)
    w.rig_page.ideal.setChecked(True)
    w.next()
    w.next()
    qtbot.waitUntil(lambda: w.currentId() == w.PAGE_EXPOSURE, timeout=TIMEOUT_MS)
    assert (tmp_path / "new-session" / "manifest.json").exists()
    w.reject()  # nothing captured: the folder it made goes
    assert not (tmp_path / "new-session").exists() and window.rig is None
    qtbot.waitUntil(lambda: window.findChild(QWizard, "calibration_wizard") is None)  # closed wizards are deleted

    user.trigger("calibrate")
    w = window.findChild(QWizard, "calibration_wizard")
    assert w.rig_page.res_w.value() == RES + 8  # the document's resolution again
    assert w.rig_page.size_note.text() == ""  # the photograph's own size: nothing to warn about
    _to_calibration_page(w, qtbot)
    with qtbot.waitSignal(w.calibrated, timeout=TIMEOUT_MS):
        w.calibration_page.start.click()
    qtbot.waitUntil(w.calibration_page.isComplete, timeout=TIMEOUT_MS)
    w.next()
    w.next()
    w.button(QWizard.WizardButton.FinishButton).click()
    qtbot.waitUntil(lambda: window.findChild(QWizard, "calibration_wizard") is None)
    assert window.rig is not None and window.rig.camera.resolution == (RES, RES + 8)  # kept open for acquiring
    assert window.session is not None and load_calibration(window.session) is not None
    assert window.act_close_rig.isEnabled() and window.act_acquire.isEnabled()
    assert window.settings.value("wizard/res_w") in (RES + 8, str(RES + 8))  # remembered

    user.trigger("calibrate")  # now the open rig: named in words, no Python repr
    w = window.findChild(QWizard, "calibration_wizard")
    assert w.rig_page.given.text() == (f"Using the rig that is open: virtual:cornell — camera {RES + 8}×{RES}, "
                                       f"projector {RES + 8}×{RES}.")
    assert w.rig_page.rigs.isHidden() and w.rig_page.rigs_label.isHidden()
    w.reject()
    assert window.rig is not None  # the wizard never closes a rig it was given


@pytest.mark.parametrize(
    "name, words",
    [
        ("gphoto2", "opening the camera failed: no camera found: check that it is connected by USB"),
        ("harvesters:/no/such/maker.cti", "no GenTL producer file at '/no/such/maker.cti'"),
        ("opencv:97", "no camera at index 97 (not attached, or in use by another program)"),
    ],
)
def test_a_camera_that_cannot_open_is_shown_in_the_engines_words(make_wizard, name, words):
    """The real libraries' failures with no device reach the wizard as one plain message."""
    if name == "gphoto2":
        from devices.gphoto2_camera import list_cameras
        from engine.errors import DeviceError

        try:
            attached = list_cameras()
        except DeviceError:  # python-gphoto2 not installed: the wizard says so instead
            attached, words = [], "python-gphoto2 is not installed"
        if attached:
            pytest.skip("a camera is connected to this machine")
    w = make_wizard()
    w.rig_page.rig_name.setText(name)
    w.next()
    w.next()  # opening fails: the wizard stays on the projector page with the message
    assert w.currentId() == w.PAGE_PROJECTOR and w.rig is None
    assert words in w.projector_page.status.text()
