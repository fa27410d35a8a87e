"""Child process of the J5 journey (tests/app/qt/test_journey_screens.py): does everything fit this screen?

Run as ``python -m tests.app.qt.screen_fit OUT.json`` under a Qt platform configured for one
screen (``QT_QPA_PLATFORM=offscreen:configfile=…``, optionally ``QT_SCALE_FACTOR``). It opens
the main window on a small acquired document with a virtual rig, shows the acquisition dock
(Rig ▸ Acquire) and walks the calibration wizard's pages (Rig ▸ Calibrate), and writes the
problems it finds as JSON: windows larger than the screen's available area, controls a person
cannot reach (not on screen even after scrolling their dock), text cut off.
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from PySide6.QtCore import QPoint, QRect, QSettings
from PySide6.QtWidgets import (
    QApplication,
    QCheckBox,
    QLabel,
    QPushButton,
    QRadioButton,
    QScrollArea,
    QWidget,
    QWizard,
)

#: Controls that must be reachable in the main window (docs/ui.md names).
MAIN_CONTROLS = ("canvas", "targets_list", "target_add", "target_remove", "kappa_R", "kappa_G", "kappa_B",
                 "kappa_R_value", "kappa_G_value", "kappa_B_value", "kappa_link", "kappa_reset", "noise_radius",
                 "noise_apply", "status", "acquire_start", "acquire_progress_pause", "acquire_progress_cancel",
                 "brush_size", "fill_tolerance", "refine_edge_button", "view_recolored_button", "view_error_button",
                 "view_noise_button", "display_exposure", "fit_button", "zoom_100_button")
WIZARD_CONTROLS = ("wizard_next", "wizard_back", "wizard_cancel")
LAST_PAGE_CONTROLS = ("wizard_finish", "wizard_cancel")


def _window_rect(w: QWidget) -> QRect:
    top = w.window()
    return QRect(w.mapTo(top, QPoint(0, 0)), w.size())


def reachable(w: QWidget) -> bool:
    """On screen inside its window once its scroll area (if any) has scrolled to it."""
    parent = w.parentWidget()
    while parent is not None:
        if isinstance(parent, QScrollArea) and parent.widget() is not None and parent.widget().isAncestorOf(w):
            parent.ensureWidgetVisible(w, 0, 0)
            QApplication.processEvents()
        parent = parent.parentWidget()
    return w.isVisible() and not w.visibleRegion().isEmpty() and w.window().rect().contains(_window_rect(w))


def cut_off(root: QWidget) -> list[str]:
    """Visible labels and buttons narrower than their text."""
    out = []
    for w in root.findChildren(QWidget):
        if not w.isVisible() or w.visibleRegion().isEmpty():
            continue
        if isinstance(w, QLabel) and not w.wordWrap() and w.text() and w.pixmap().isNull():
            need = w.fontMetrics().horizontalAdvance(w.text()) if "<" not in w.text() else w.minimumSizeHint().width()
            if w.width() + 1 < need:
                out.append(f"label {w.text()[:60]!r} is {w.width()} px wide, needs {need}")
        elif isinstance(w, (QPushButton, QCheckBox, QRadioButton)) and w.text():
            need = w.minimumSizeHint().width()
            if w.width() + 1 < need:
                out.append(f"{type(w).__name__} {w.text()!r} is {w.width()} px wide, needs {need}")
    return out


def check_window(window: QWidget, names, what: str) -> list[str]:
    problems = []
    area = window.screen().availableGeometry()
    if not area.contains(window.frameGeometry()):
        problems.append(f"{what}: {window.frameGeometry().getRect()} does not fit the screen's {area.getRect()}")
    for name in names:
        found = [w for w in window.findChildren(QWidget, name) if w.isVisibleTo(window)]
        if not found:
            problems.append(f"{what}: no visible {name!r}")
        elif not reachable(found[0]):
            problems.append(f"{what}: {name!r} cannot be reached (off screen)")
    return problems + [f"{what}: {p}" for p in cut_off(window)]


def main(out: str) -> int:
    app = QApplication(["albedit"])
    import devices
    from app.model.document import Document
    from app.qt.main_window import MainWindow
    from engine.session import Session
    from engine.workflow import run_calibration

    tmp = Path(tempfile.mkdtemp())
    settings = QSettings(str(tmp / "settings.ini"), QSettings.Format.IniFormat)
    rig = devices.open_rig("virtual:cornell", ideal=True, resolution=(24, 24), cache_dir=False)
    session = Session.create(tmp / "s", rig_name=rig.identity, camera_resolution=rig.camera.resolution,
                             projector_resolution=rig.projector.resolution)
    run_calibration(rig, session)
    doc = Document(np.asarray(rig.truth.photograph(), np.float32), source=rig.name)
    doc.add_target("right_wall", rig.targets["right_wall"])
    doc.mark_saved()
    window = MainWindow(doc, session, rig=rig, synchronous=True, settings=settings)
    window.show()
    app.processEvents()
    window.act_acquire.trigger()
    app.processEvents()
    screen = window.screen()
    problems = check_window(window, MAIN_CONTROLS, "main window")
    window.act_calibrate.trigger()
    app.processEvents()
    wizard = window.findChild(QWizard, "calibration_wizard")
    for page in range(6):
        app.processEvents()
        controls = WIZARD_CONTROLS[:1] if page == 0 else LAST_PAGE_CONTROLS if page == 5 else WIZARD_CONTROLS
        problems += check_window(wizard, controls, f"wizard page {page + 1}")
        if page == 3:  # calibrate into the wizard's session, then on to the results
            wizard.calibration_page.start.click()
        if page < 5:
            wizard.next()
    wizard.reject()
    geometry = {"screen": screen.geometry().getRect(), "available": screen.availableGeometry().getRect(),
                "dpr": screen.devicePixelRatio(), "window": window.frameGeometry().getRect()}
    Path(out).write_text(json.dumps({"problems": problems, "geometry": geometry}))
    for w in QApplication.topLevelWidgets():
        if isinstance(w, MainWindow):
            w.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
