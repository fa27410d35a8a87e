"""Defects a new user's walk of the real window found (2026-12-03), each through the real window."""

from __future__ import annotations

import numpy as np

from app.model.document import Document
from engine.decompose import Decomposition, observe
from tests.app.qt.user import User


def test_a_kappa_typed_beyond_the_range_is_said_not_dropped(make_window, qtbot):
    """Typing 40 into a κ box read as 4 (the box's maximum dropped the last keystroke) without a word."""
    doc = Document(np.full((12, 16, 3), 0.2, np.float32))
    wall = doc.add_target("wall", np.eye(12, 16, dtype=bool))
    window = make_window(doc)
    user = User(qtbot, window)
    user.click("kappa_link")  # one channel alone
    user.type_into("kappa_R_value", "3")
    user.type_into("kappa_R_value", "40")
    np.testing.assert_allclose(wall.kappa, (3.0, 1.0, 1.0))  # refused, as an impossible albedo is
    assert window.statusBar().currentMessage() == "κ R is at most 16 (Albedit's range): 40 was not applied"
    assert user.find("kappa_R_value").value() == 3.0


def test_a_kappa_past_the_sliders_end_is_said(make_window, qtbot):
    """A measured limit beyond the slider's 16 lets a κ be typed (or asked for by a colour) past its end: the
    slider sat pinned at its end while the box read 17.7, and nothing said why."""
    rng = np.random.default_rng(3)
    target = np.zeros((12, 16), bool)
    target[3:9, 4:12] = True
    decay = (0.01 ** np.arange(3))[:, None, None, None].astype(np.float32)  # a wall that returns 1 % of its light
    inside = rng.uniform(0.5, 1.0, (1, 12, 16, 3)).astype(np.float32) * decay
    d = Decomposition.from_components(inside, inside[:2] * 0.5, np.full((12, 16, 3), 0.3, np.float32), target)
    doc = Document(observe(d)[0])
    wall = doc.add_target("wall", target)
    doc.set_acquisition([wall.uid], d)
    window = make_window(doc)
    user = User(qtbot, window)
    user.click("kappa_link")
    high = window.colour_panel.kappa_high(wall.uid)
    assert high is not None and high[0] > 17.7  # the measured limit
    user.type_into("kappa_R_value", "17.7")
    np.testing.assert_allclose(wall.kappa, (17.7, 1.0, 1.0))
    message = window.statusBar().currentMessage()
    assert message.startswith("κ R = 17.7 is past the slider's end (16): its box shows it, and takes values up to ")


def _wheel(widget, steps: int) -> None:
    """The mouse wheel turned ``steps`` notches over the middle of ``widget`` (negative: towards the user)."""
    from PySide6.QtCore import QPoint, QPointF, Qt
    from PySide6.QtGui import QWheelEvent
    from PySide6.QtWidgets import QApplication

    pos = QPointF(widget.rect().center())
    event = QWheelEvent(pos, QPointF(widget.mapToGlobal(pos.toPoint())), QPoint(0, 0), QPoint(0, 120 * steps),
                        Qt.MouseButton.NoButton, Qt.KeyboardModifier.NoModifier, Qt.ScrollPhase.NoScrollPhase, False)
    QApplication.sendEvent(widget, event)


def test_the_wheel_over_a_docks_control_scrolls_the_dock(make_window, acquired_doc, qtbot):
    """Scrolling down the acquisition dock changed its combo boxes (Adaptive became span) on the way."""
    from PySide6.QtCore import Qt
    from PySide6.QtWidgets import QScrollArea

    window = make_window(acquired_doc)
    window.resize(1000, 420)  # the Albedo dock scrolls
    user = User(qtbot, window)
    area = user.find("albedo_scroll", QScrollArea)
    qtbot.waitUntil(lambda: area.verticalScrollBar().maximum() > 0)
    radius = user.find("noise_radius")
    before, bar = radius.value(), area.verticalScrollBar()
    bar.setValue(0)
    _wheel(radius, -1)
    assert radius.value() == before and bar.value() > 0  # the dock scrolled, the radius stayed
    qtbot.mouseClick(radius.lineEdit(), Qt.MouseButton.LeftButton)
    qtbot.waitUntil(radius.hasFocus)
    _wheel(radius, 1)
    assert radius.value() == before + 1  # a control the user clicked into takes the wheel


def test_ctrl_equals_zooms_in_as_ctrl_plus_does(make_window, acquired_doc, qtbot):
    """On most keyboards + is Shift+=: Ctrl+= did nothing."""
    from PySide6.QtCore import Qt

    window = make_window(acquired_doc)
    user = User(qtbot, window)
    before = window.canvas.zoom
    user.press(Qt.Key.Key_Equal, Qt.KeyboardModifier.ControlModifier)
    assert window.canvas.zoom > before


def test_an_export_name_of_another_format_says_the_extension_it_got(make_window, acquired_doc, qtbot, tmp_path,
                                                                    monkeypatch):
    """'test.jpg' with the EXR filter wrote test.jpg.exr without a word."""
    from PySide6.QtWidgets import QFileDialog

    from app.qt.file_control import EXPORT_FILTERS

    exr = next(f for f, (ext, _) in EXPORT_FILTERS.items() if ext == ".exr")
    monkeypatch.setattr(QFileDialog, "getSaveFileName", staticmethod(lambda *a, **k: (str(tmp_path / "test.jpg"), exr)))
    window = make_window(acquired_doc)
    User(qtbot, window).trigger("export")
    qtbot.waitUntil(lambda: window.job is None and (tmp_path / "test.jpg.exr").exists())
    assert window.statusBar().currentMessage() == (f"Exported {tmp_path / 'test.jpg.exr'} (.jpg is not an export "
                                                   "format: .exr was added)")


def test_the_acquisition_dock_opens_with_start_in_view_on_a_small_screen(make_window, qtbot):
    """On a 1024×700 window the dock opened scrolled to its top, Start below the fold."""
    import devices

    with devices.open_rig("virtual:cornell", ideal=True, resolution=(24, 24)) as rig:
        doc = Document(rig.truth.photograph())
        doc.add_target("wall", rig.targets["right_wall"])
        window = make_window(doc, rig=rig)
        window.resize(1024, 700)
        user = User(qtbot, window)
        user.trigger("acquire")
        start = user.find("acquire_start")
        qtbot.waitUntil(lambda: start.isVisible() and not start.visibleRegion().isEmpty())
        window.rigs.shutdown()
