"""J2, the lab tech: with a document open, Rig ▸ Calibrate → auto exposure → identify → calibrate →
Finish → Rig ▸ Acquire on a target painted in that document → progress, pause, resume, cancel,
resume → recolor → Save → Export (noise-aware, against the truth). Then the same after File ▸ Open of
another session, and File ▸ Open of the first again: its edit exports the same pixels.

Threaded, as in the app (jobs and the live view on workers), on the ideal virtual rig at 32²;
the user pauses and cancels when a capture's thumbnail arrives, so nothing depends on timing.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QCheckBox, QComboBox, QFileDialog, QMessageBox, QPushButton, QSlider, QWizard
from scipy.ndimage import binary_erosion

import devices
from app.model import files
from app.model.document import Document
from app.qt.panels import kappa_to_ticks
from devices.qtscreen import identify_pattern
from engine import imageio
from engine.acquire.predict import relative_error
from engine.recolor import recolor
from tests.app.qt.user import TIMEOUT_MS, User

RES = 32


def open_room(make_window, qtbot, tmp_path):
    """A threaded window with the ideal Cornell box's photograph (an EXR) opened in it, as File ▸ Open does.

    Returns the window, its :class:`User`, the photograph and the right and left walls' masks.
    """
    with devices.open_rig("virtual:cornell", ideal=True, resolution=(RES, RES)) as rig:
        photo, wall, left = rig.truth.photograph(), rig.targets["right_wall"], rig.targets["left_wall"]
    imageio.write_image(tmp_path / "room.exr", photo)
    window = make_window(synchronous=False)
    user = User(qtbot, window)
    window.open_path(tmp_path / "room.exr")
    qtbot.waitUntil(lambda: window.doc is not None and window.job is None, timeout=TIMEOUT_MS)
    return window, user, photo, wall, left


def paint_wall(user: User, window, wall) -> None:
    """A brush stroke down the middle of the wall (its tallest column, two pixels in)."""
    user.click("target_add")
    user.type_into("brush_size", "2")
    inner = binary_erosion(wall, iterations=2)
    column = int(np.argmax(inner.sum(axis=0)))
    ys = np.flatnonzero(inner[:, column])
    user.drag_on_canvas(window.canvas, [(column + 0.5, ys.min() + 0.5), (column + 0.5, ys.max() + 0.5)])


def calibrate(window, qtbot, *, identify: bool, rig: str | None = None, resolution: int | None = None) -> str:
    """Rig ▸ Calibrate through the wizard's pages, as a lab tech clicks them (typing ``rig``, an ideal
    virtual one of ``resolution``², when given); the summary page's text."""
    User(qtbot, window).trigger("calibrate")
    wizard = window.findChild(QWizard, "calibration_wizard")
    w = User(qtbot, wizard)
    if rig is not None:
        w.type_into("wizard_rig_name", rig, enter=False)
        if not w.find("wizard_ideal", QCheckBox).isChecked():
            w.click("wizard_ideal")
        for side in ("wizard_res_h", "wizard_res_w"):
            w.type_into(side, str(resolution), enter=False)
    w.click("wizard_next")
    w.click("wizard_next")  # opens the rig (a worker builds the virtual set-up), then moves on
    qtbot.waitUntil(lambda: wizard.currentId() == wizard.PAGE_EXPOSURE, timeout=TIMEOUT_MS)
    page = wizard.exposure_page
    qtbot.waitUntil(lambda: page.live.frames >= 1, timeout=TIMEOUT_MS)
    w.click("wizard_auto_exposure")
    qtbot.waitUntil(lambda: page.auto is None and page.auto_button.isEnabled(), timeout=TIMEOUT_MS)
    assert "does not clip" in page.report.text()  # the ideal camera: settled at once
    if identify:
        level = w.find("wizard_projector_level", QComboBox)
        w.qtbot.mouseClick(level, Qt.MouseButton.LeftButton)
        w.qtbot.keyClick(level.view(), Qt.Key.Key_End)
        w.qtbot.keyClick(level.view(), Qt.Key.Key_Return)
        assert level.currentIndex() == 2  # identify: grid and centre cross on the scene
        rig = wizard.rig
        hp, wp = rig.projector.resolution
        qtbot.waitUntil(lambda: np.array_equal(rig.projector._input, identify_pattern(
            (hp, wp), label=f"{rig.name}  {wp}x{hp}")), timeout=TIMEOUT_MS)
    w.click("wizard_next")
    with qtbot.waitSignal(wizard.calibrated, timeout=TIMEOUT_MS):
        w.click("calibrate_start")
    qtbot.waitUntil(wizard.calibration_page.isComplete, timeout=TIMEOUT_MS)
    w.click("wizard_next")
    assert wizard.currentId() == wizard.PAGE_RESULTS
    w.click("wizard_next")
    summary = wizard.summary_page.text.toPlainText()
    w.click("wizard_finish")
    return summary


def test_the_lab_tech_calibrates_and_acquires(make_window, qtbot, tmp_path, monkeypatch, dialogs):
    window, user, photo, wall, left = open_room(make_window, qtbot, tmp_path)

    assert "Nothing to fix" in calibrate(window, qtbot, identify=True)
    assert window.rig is not None and window.session is not None
    paint_wall(user, window, wall)
    doc = window.doc
    target = doc.target(doc.current)

    user.trigger("acquire")
    panel = window.rigs.panel
    pause = user.find("acquire_progress_pause", QPushButton)
    cancel = user.find("acquire_progress_cancel", QPushButton)
    jobs = []
    panel.started.connect(jobs.append)
    arrivals = []

    def on_thumbnail(name):  # the user watches the captures arrive, and reacts
        arrivals.append(name)
        if len(arrivals) == 1:
            user.click(pause)

    panel.thumbnail_added.connect(on_thumbnail)
    user.click("acquire_start")
    qtbot.waitUntil(lambda: bool(jobs) and jobs[0].is_paused, timeout=TIMEOUT_MS)
    assert pause.text() == "Resume" and not user.find("acquire_start").isEnabled()
    qtbot.waitUntil(lambda: panel.eta.bar.maximum() > 0, timeout=TIMEOUT_MS)  # progress with a count
    held = panel.thumbnails.count()
    qtbot.wait(300)
    assert panel.thumbnails.count() <= held + 1 and jobs[0].is_paused  # at most the capture in flight

    def cancel_soon(name):  # two captures after resuming, the user cancels
        arrivals.append(name)
        if len(arrivals) == 3:
            user.click(cancel)

    panel.thumbnail_added.disconnect(on_thumbnail)
    panel.thumbnail_added.connect(cancel_soon)
    user.click(pause)  # Resume
    qtbot.waitUntil(lambda: not panel.busy, timeout=TIMEOUT_MS)
    assert "Cancelled" in user.find("acquire_status").text() and doc.acquisition is None
    kept = {c.name: c.sha256 for c in window.session.captures if c.name.startswith("acq-")}
    assert len(kept) >= 3 and user.find("acquire_start").text() == "Resume"

    panel.thumbnail_added.disconnect(cancel_soon)
    with qtbot.waitSignal(panel.acquired, timeout=TIMEOUT_MS):
        user.click("acquire_start")  # resume: the captures taken so far are reused, not retaken
    assert doc.acquisition is not None and doc.acquisition.cascade == (target.uid,)
    after = {c.name: c.sha256 for c in window.session.captures}
    assert {n: after[n] for n in kept} == kept and len(after) > len(kept)
    qtbot.waitUntil(lambda: window.job is None and panel.eta.bar.value() == panel.eta.bar.maximum(),
                    timeout=TIMEOUT_MS)

    # recolor: drag κ (linked) and the preview follows the measured interreflections
    user.drag_slider(user.find("kappa_G", QSlider), [kappa_to_ticks(0.5), kappa_to_ticks(0.25)])
    kappa = target.kappa.copy()
    np.testing.assert_allclose(kappa, 0.25, rtol=0.02)
    with devices.open_rig("virtual:cornell", ideal=True, resolution=(RES, RES)) as check:
        truth, surfaces = check.truth.recolor([(target.mask, kappa)]), ~check.truth.emitters()
    assert relative_error(recolor(doc.decomposition, kappa), truth, surfaces) < 0.01
    qtbot.waitUntil(lambda: window.preview.frame is not None and window.preview.frame.request.kappa == tuple(kappa),
                    timeout=TIMEOUT_MS)
    # the noise-aware recolor is prepared after the acquisition (a job in the status bar): wait for it to end
    qtbot.waitUntil(lambda: window.job is None and doc.trusted is not None, timeout=TIMEOUT_MS)

    # File ▸ Save into the calibrated session, File ▸ Export: the noise-aware recolor, true to the scene
    first = window.session.path
    user.trigger("save")
    qtbot.waitUntil(lambda: window.job is None and not doc.is_dirty(), timeout=TIMEOUT_MS)
    exported = _export(user, window, qtbot, monkeypatch, tmp_path / "first.exr")
    assert relative_error(exported, truth, surfaces) < 0.01

    # the same after File ▸ Open of another session: the open rig stays, calibrate again, acquire
    other = Document(photo, source="another photograph")
    t = other.add_target("left wall", left & binary_erosion(left, iterations=1))
    other.set_kappa(t.uid, (0.5, 1.0, 2.0))
    files.create_session(tmp_path / "other", other)
    monkeypatch.setattr(QFileDialog, "getExistingDirectory", staticmethod(lambda *a, **k: str(tmp_path / "other")))
    dialogs.answers = [QMessageBox.StandardButton.Discard]  # the unsaved first edit: not the point here
    user.trigger("open")
    qtbot.waitUntil(lambda: window.doc is not doc and window.job is None, timeout=TIMEOUT_MS)
    assert window.rig is not None and not window.rig.closed  # opening a document keeps the rig
    assert panel.session is window.session and [n for n, _ in panel.targets] == ["left wall"]
    assert "Nothing to fix" in calibrate(window, qtbot, identify=False)  # the wizard starts from the open rig
    assert window.session.read_calibration()[0]  # the session took the new calibration
    with qtbot.waitSignal(panel.acquired, timeout=TIMEOUT_MS):
        user.click("acquire_start")
    second = window.doc
    assert second.acquisition is not None and [second.target(u).name for u in second.acquisition.cascade] == [
        "left wall"]
    with devices.open_rig("virtual:cornell", ideal=True, resolution=(RES, RES)) as check:
        truth = check.truth.recolor([(second.by_name("left wall").mask, np.array([0.5, 1.0, 2.0]))])
    assert relative_error(recolor(second.decomposition, second.recolor_kappa()), truth, surfaces) < 0.01

    # File ▸ Open the first session again (the second edit is discarded): its edit and recolor come back whole
    monkeypatch.setattr(QFileDialog, "getExistingDirectory", staticmethod(lambda *a, **k: str(first)))
    dialogs.answers = [QMessageBox.StandardButton.Discard]
    user.trigger("open")
    qtbot.waitUntil(lambda: window.doc is not second and window.job is None, timeout=TIMEOUT_MS)
    reopened = window.doc
    assert reopened.acquisition is not None and reopened.acquisition.noise_aware
    np.testing.assert_allclose(reopened.by_name(target.name).kappa, kappa)
    np.testing.assert_array_equal(_export(user, window, qtbot, monkeypatch, tmp_path / "again.exr"), exported)
    assert dialogs.texts("critical") == []


def _export(user: User, window, qtbot, monkeypatch, path) -> np.ndarray:
    """File ▸ Export to ``path`` (a linear EXR, noise-aware): the pixels written."""
    monkeypatch.setattr(QFileDialog, "getSaveFileName", staticmethod(lambda *a, **k: (str(path), "")))
    user.trigger("export")
    qtbot.waitUntil(lambda: window.job is None and path.exists(), timeout=TIMEOUT_MS)
    assert imageio.read_metadata(path)["edit"]["recolor"] == "noise-aware"
    return imageio.read_image(path)
