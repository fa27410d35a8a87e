"""The automation contract: every action and interactive widget has a stable objectName, and
docs/ui.md lists exactly those names."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from PySide6.QtWidgets import (
    QAbstractButton,
    QAbstractItemView,
    QAbstractSlider,
    QAbstractSpinBox,
    QComboBox,
    QDockWidget,
    QLineEdit,
    QMenu,
    QScrollBar,
    QToolBar,
    QWidget,
    QWizard,
    QWizardPage,
)

import devices
from app.model.document import Document
from app.qt.canvas import Canvas
from engine.session import Session
from engine.workflow import run_calibration
from tests.app.qt.user import User

UI_MD = Path(__file__).resolve().parents[3] / "docs" / "ui.md"
INTERACTIVE = (QAbstractButton, QAbstractSlider, QAbstractSpinBox, QComboBox, QLineEdit, QAbstractItemView, QDockWidget,
               QWizardPage, QToolBar, Canvas)


def _documented() -> set[str]:
    """Names in docs/ui.md's tables, headings and the wizard's button line."""
    names = set()
    for line in UI_MD.read_text().splitlines():
        if line.startswith(("|", "#", "Buttons:")):
            names |= set(re.findall(r"`([a-z][a-z0-9_]*)`", line))
    return names


def _internal(w: QWidget) -> bool:
    """Parts Qt makes inside a control (a spin box's line edit, a combo box's list, scroll bars)."""
    if w.objectName().startswith("qt_") or isinstance(w, QScrollBar):
        return True
    parent = w.parentWidget()
    while parent is not None:
        if isinstance(parent, (QAbstractSpinBox, QComboBox)) or parent.objectName().startswith("qt_"):
            return True
        parent = parent.parentWidget()
    return False


@pytest.fixture
def everything(make_window, qtbot, tmp_path):
    """The main window with a rig, the acquisition dock and the calibration wizard open."""
    rig = devices.open_rig("virtual:cornell", ideal=True, resolution=(24, 24), cache_dir=False)
    session = Session.create(tmp_path / "s", rig_name=rig.identity, camera_resolution=rig.camera.resolution,
                             projector_resolution=rig.projector.resolution)
    run_calibration(rig, session)
    doc = Document(np.asarray(rig.truth.photograph(), np.float32))
    doc.add_target("wall", rig.targets["right_wall"])
    window = make_window(doc, session, rig=rig)
    user = User(qtbot, window)
    user.trigger("acquire")
    user.trigger("calibrate")
    return window, window.findChild(QWizard, "calibration_wizard")


def test_every_action_and_control_is_named_and_documented(everything):
    window, wizard = everything
    documented = _documented()
    actions = {a.objectName() for a in window.actions()}
    assert "" not in actions, [a.text() for a in window.actions() if not a.objectName()]
    menus = {a.menu().objectName() for a in window.menuBar().actions()} | {window.recent_menu.objectName()}
    widgets = [w for w in window.findChildren(QWidget) if isinstance(w, INTERACTIVE) and not _internal(w)]
    unnamed = [f"{type(w).__name__} {getattr(w, 'text', lambda: '')()!r}" for w in widgets if not w.objectName()]
    assert unnamed == []
    named = actions | menus | {w.objectName() for w in widgets} | {window.objectName(), wizard.objectName()}
    assert named - documented == set(), "named in the app but not in docs/ui.md"
    progress_parts = {f"{p}_{part}" for p in ("job_progress", "acquire_progress", "calibrate_progress",
                                                "open_rig_progress") for part in ("message", "bar")}
    empty_window = {"placeholder"}  # shown only while no document is open
    app_names = named | progress_parts | empty_window | {w.objectName() for w in window.findChildren(QWidget)}
    assert documented - app_names == set(), "in docs/ui.md but not in the app"
    assert all(isinstance(m, QMenu) for m in (window.findChild(QMenu, n) for n in menus))
