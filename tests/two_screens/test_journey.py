"""A lab tech's journey on the loopback bench through the real MainWindow, threaded as in the app:
Rig ▸ Calibrate opens the wizard (both screens listed with their sizes, the projector window on
HDMI-1, live view, calibration), then the acquisition panel measures a painted target and the
result recolours like the scene's ground truth."""

from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import QSettings
from PySide6.QtWidgets import QMessageBox, QWizard

from app.model.document import Document
from app.qt.calibration_wizard import CalibrationWizard
from app.qt.main_window import MainWindow
from engine.acquire.predict import relative_error
from engine.recolor import recolor
from tests.two_screens.bench import SCENE, TARGET

TIMEOUT_MS = 240_000
KAPPA = np.array([1.5, 0.8, 1.2])


@pytest.fixture
def dialogs(monkeypatch) -> list:
    """Message boxes shown (recorded instead of blocking the test)."""
    shown = []
    for kind in ("critical", "warning", "information", "question"):
        monkeypatch.setattr(QMessageBox, kind, staticmethod(
            lambda parent, title, text, *a, kind=kind, **k: shown.append((kind, title, text))
            or QMessageBox.StandardButton.Ok))
    return shown


@pytest.fixture
def window(qtbot, tmp_path, monkeypatch, cache, dialogs):
    monkeypatch.setenv("XDG_CACHE_HOME", str(cache))  # the rig's default set-up cache
    w = MainWindow(synchronous=False, settings=QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat))
    w.resize(1200, 800)
    w.show()
    qtbot.waitExposed(w)
    yield w
    if w.doc is not None:
        w.doc.mark_saved()
    rig = w.rig
    w.close()
    if rig is not None:
        rig.close()


def test_calibrate_and_acquire_on_the_loopback_bench(window, qtbot, tmp_path, dialogs):
    window.calibrate()
    wizard = window.findChild(CalibrationWizard)
    wizard.rig_page.rig_name.setText(f"loopback:{SCENE}")
    wizard.rig_page.session_path.setText(str(tmp_path / "session"))
    wizard.next()
    assert wizard.currentId() == wizard.PAGE_PROJECTOR
    screens = wizard.projector_page.screens
    assert [screens.item(i).text() for i in range(screens.count())] == [
        "qtscreen:0 — Built-in display 1920x1080",
        "qtscreen:1 — HDMI-1 1024x768",
    ]
    assert wizard.projector_page.options() == {"projector": "qtscreen:1"}  # not the primary
    wizard.next()  # opens the bench: the projector window on HDMI-1, the hot folder, the bench camera
    qtbot.waitUntil(lambda: wizard.currentId() == wizard.PAGE_EXPOSURE, timeout=TIMEOUT_MS)
    rig = wizard.rig
    assert rig.name == f"loopback:{SCENE}" and rig.projector.screen_name == "HDMI-1"
    assert rig.projector.window.isFullScreen() and rig.projector.window.screen().name() == "HDMI-1"
    qtbot.waitUntil(lambda: wizard.exposure_page.live.frames >= 1, timeout=TIMEOUT_MS)  # files from a worker
    wizard.next()
    with qtbot.waitSignal(wizard.calibrated, timeout=TIMEOUT_MS) as calibrated:
        wizard.calibration_page.start.click()
    assert calibrated.args[0].correspondence.valid.mean() > 0.7
    qtbot.waitUntil(wizard.calibration_page.isComplete, timeout=TIMEOUT_MS)
    wizard.next()
    wizard.next()
    with qtbot.waitSignal(wizard.finished_session, timeout=TIMEOUT_MS):
        wizard.button(QWizard.WizardButton.FinishButton).click()
    assert window.rig is rig and not rig.closed and window.session is not None

    # paint the target on the camera's picture under projector white, then acquire it
    doc = Document(window.session.load_capture("cal-white").image)
    doc.add_target(TARGET, rig.targets[TARGET])
    window.set_document(doc, window.session, rig=rig)
    window.acquire()
    panel = window.rigs.panel  # the acquisition dock's panel (RigControl keeps the rig, the wizard and the dock)
    with qtbot.waitSignals([panel.acquired], raising=False, timeout=TIMEOUT_MS, check_params_cbs=None) as done:
        assert panel.start() is not None
        qtbot.waitUntil(lambda: panel.result is not None or bool(dialogs), timeout=TIMEOUT_MS)
    assert dialogs == [] and done.signal_triggered
    assert doc.acquisition is not None
    truth = rig.truth.recolor([(rig.targets[TARGET], KAPPA)])
    surfaces = ~rig.truth.emitters()
    assert relative_error(recolor(doc.acquisition.decomposition, KAPPA), truth, surfaces) < 0.05
    assert not rig.bench.errors
