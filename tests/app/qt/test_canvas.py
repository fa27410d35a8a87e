"""The canvas with real Qt mouse events: painting, pan, zoom, split divider, undo shortcuts."""

from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import QPoint, QPointF, Qt

from app.model.display import recolor_rgb32
from app.model.document import Document
from app.model.painting import Tool
from tests.app.model.test_painting import _capsule_reference

ZOOM, OFFSET = 2.0, 10.0


@pytest.fixture
def window(make_window, qtbot):
    doc = Document(np.full((40, 60, 3), 0.25, np.float32))
    doc.add_target("a")
    doc.mark_saved()
    w = make_window(doc)
    qtbot.wait(1)  # let the initial fit happen first
    w.canvas._set_zoom(ZOOM, QPointF(OFFSET, OFFSET))
    w.canvas._fitted = False
    return w


def _widget(x, y) -> QPoint:
    """Widget position of image coordinates (x, y)."""
    return QPoint(int(x * ZOOM + OFFSET), int(y * ZOOM + OFFSET))


def test_mouse_drag_on_the_canvas_paints_the_expected_mask(window, qtbot):
    c = window.canvas
    window.painter.set_size(6)
    qtbot.mousePress(c, Qt.MouseButton.LeftButton, pos=_widget(5, 5))
    qtbot.mouseMove(c, _widget(15, 5))
    qtbot.mouseMove(c, _widget(25, 20))
    qtbot.mouseRelease(c, Qt.MouseButton.LeftButton, pos=_widget(25, 20))
    expected = _capsule_reference((5, 5), (5, 5), 3) | _capsule_reference((5, 5), (15, 5), 3)
    expected |= _capsule_reference((15, 5), (25, 20), 3) | _capsule_reference((25, 20), (25, 20), 3)
    mask = window.doc.target(window.doc.current).mask
    np.testing.assert_array_equal(mask, expected)
    assert window.doc.is_dirty() and window.isWindowModified()


def test_undo_and_redo_shortcuts_restore_exactly(window, qtbot):
    c = window.canvas
    mask = window.doc.target(window.doc.current).mask
    window.painter.set_size(4)
    for y in (5, 15):
        qtbot.mousePress(c, Qt.MouseButton.LeftButton, pos=_widget(5, y))
        qtbot.mouseMove(c, _widget(30, y))
        qtbot.mouseRelease(c, Qt.MouseButton.LeftButton, pos=_widget(30, y))
        if y == 5:
            after_first = mask.copy()
    after_both = mask.copy()
    assert window.undo_group.activeStack().count() == 2
    qtbot.keyClick(c, Qt.Key.Key_Z, Qt.KeyboardModifier.ControlModifier)
    np.testing.assert_array_equal(mask, after_first)
    qtbot.keyClick(c, Qt.Key.Key_Z, Qt.KeyboardModifier.ControlModifier)
    assert not mask.any() and not window.doc.is_dirty()
    qtbot.keyClick(c, Qt.Key.Key_Z, Qt.KeyboardModifier.ControlModifier | Qt.KeyboardModifier.ShiftModifier)
    window.act_redo.trigger()
    np.testing.assert_array_equal(mask, after_both)


def test_middle_button_and_space_pan_without_painting(window, qtbot):
    c = window.canvas
    mask = window.doc.target(window.doc.current).mask
    qtbot.mousePress(c, Qt.MouseButton.MiddleButton, pos=_widget(10, 10))
    qtbot.mouseMove(c, _widget(20, 15))
    qtbot.mouseRelease(c, Qt.MouseButton.MiddleButton, pos=_widget(20, 15))
    assert c.offset == QPointF(OFFSET + 20, OFFSET + 10)
    qtbot.keyPress(c, Qt.Key.Key_Space)
    qtbot.mousePress(c, Qt.MouseButton.LeftButton, pos=QPoint(100, 100))
    qtbot.mouseMove(c, QPoint(90, 100))
    qtbot.mouseRelease(c, Qt.MouseButton.LeftButton, pos=QPoint(90, 100))
    qtbot.keyRelease(c, Qt.Key.Key_Space)
    assert c.offset == QPointF(OFFSET + 10, OFFSET + 10)
    assert not mask.any()


def test_wheel_zooms_around_the_cursor_and_fit(window, qtbot):
    c = window.canvas
    anchor = QPointF(200, 150)
    before = c.to_image(anchor)
    c.zoom_by(1.25**2, anchor)
    assert c.zoom == pytest.approx(ZOOM * 1.5625)
    after = c.to_image(anchor)
    assert (after.x(), after.y()) == pytest.approx((before.x(), before.y()))
    window.act_zoom_100.trigger()
    assert c.zoom == 1.0
    window.act_fit.trigger()
    assert c.zoom == pytest.approx(min(c.width() / 60, c.height() / 40))


def test_brush_size_keys_polygon_enter_and_cursor_readout(window, qtbot):
    c = window.canvas
    window.painter.set_size(10)
    qtbot.keyClick(c, Qt.Key.Key_BracketRight)
    assert window.painter.size == 12.5 and window.size_spin.value() == 12
    qtbot.keyClick(c, Qt.Key.Key_P)
    assert window.painter.tool == Tool.POLYGON
    for x, y in ((2, 2), (20, 2), (20, 12)):
        qtbot.mouseClick(c, Qt.MouseButton.LeftButton, pos=_widget(x, y))
    qtbot.keyClick(c, Qt.Key.Key_Return)
    mask = window.doc.target(window.doc.current).mask
    assert mask[3, 18] and not mask[11, 3]
    qtbot.mouseMove(c, _widget(18.5, 3.5))
    assert window.readout.text().startswith("x    18  y     3") and "naive recolor: R 0.25" in window.readout.text()
    assert "[a]" in window.readout.text()
    # κ changes and the mouse stays: the readout reads the new preview (it kept the old value until the mouse moved)
    window.doc.set_kappa(window.doc.current, (2.0, 2.0, 2.0))
    qtbot.waitUntil(lambda: "naive recolor: R 0.5 " in window.readout.text(), timeout=5000)
    assert window.readout.isVisible()
    c.cursor_moved.emit(None)  # the mouse leaves the image: the readout gives its room to the status messages
    assert not window.readout.isVisible()
    window.statusBar().showMessage("Acquired 'a' in 12 camera shots", 10)  # a message clipped or expired
    assert window.statusBar().toolTip() == "Last message: Acquired 'a' in 12 camera shots"


def test_split_divider_drags(make_window, acquired_doc, qtbot):
    w = make_window(acquired_doc)
    w.set_view("split")
    c = w.canvas
    rect = c.image_rect()
    x = int(rect.left() + rect.width() * 0.5)
    y = int(rect.center().y())
    mask = acquired_doc.by_name("wall").mask.copy()
    qtbot.mousePress(c, Qt.MouseButton.LeftButton, pos=QPoint(x, y))
    qtbot.mouseMove(c, QPoint(int(rect.left() + rect.width() * 0.8), y))
    qtbot.mouseRelease(c, Qt.MouseButton.LeftButton, pos=QPoint(int(rect.left() + rect.width() * 0.8), y))
    assert c.split == pytest.approx(0.8, abs=0.02)
    np.testing.assert_array_equal(acquired_doc.by_name("wall").mask, mask)
    assert c.grab().width() > 0


def test_zoomed_in_past_the_preview_the_visible_region_sharpens_to_export_pixels(make_window, acquired_doc, qtbot):
    w = make_window(acquired_doc)
    c, preview = w.canvas, w.preview
    preview.max_shape = (12, 16)  # a 4× smaller preview, as a 24 MP photograph on a 1080p screen
    preview.rebuild()
    assert preview.renderer.factor == 4
    c.zoom_to(32.0, QPointF(0, 0))
    region = c.visible_region()
    assert c.detail is not None and c.detail.region == region and region[1] - region[0] < 48
    wall = acquired_doc.by_name("wall")
    kappa = wall.kappa
    full = recolor_rgb32(acquired_doc.decomposition, kappa)
    c.show_overlays = False  # compare the picture itself, without target outlines and tints
    image = c.grab().toImage()
    for y, x in [(region[0] + 3, region[2] + 5), (region[1] - 2, region[3] - 3)]:
        centre = c.to_widget(QPointF(x + 0.5, y + 0.5))
        assert image.pixel(int(centre.x()), int(centre.y())) & 0xFFFFFF == int(full[y, x]) & 0xFFFFFF
    # a new κ: the old detail no longer belongs on screen; the new one follows
    old = c.detail
    acquired_doc.set_kappa(wall.uid, (2.0, 0.5, 0.5))
    assert c.detail is not old and c.detail.request.kappa == (2.0, 0.5, 0.5)
    c.set_detail(old)  # a late detail of an earlier request is ignored
    assert c.detail is not old
    # back to fit on a large preview: nothing to sharpen
    preview.max_shape = (1080, 1920)
    preview.rebuild()
    assert not preview.wants_detail()


def test_the_first_stroke_on_a_photograph_without_targets_starts_one(make_window, qtbot):
    """Opening a photograph and painting on it warned 'add or select a target before painting' and painted
    nothing; the first stroke now starts 'target 1', shown in the Targets panel and in the Albedo panel."""
    from PySide6.QtWidgets import QListWidget

    from tests.app.qt.user import User

    doc = Document(np.full((40, 60, 3), 0.25, np.float32))
    doc.mark_saved()
    w = make_window(doc)
    user = User(qtbot, w)
    w.set_tool(Tool.BRUSH)
    user.drag_on_canvas(w.canvas, [(10, 10), (20, 12)])
    assert user.rows(user.find("targets_list", QListWidget)) == ["target 1"]
    assert doc.targets[0].mask[11, 15] and doc.current == doc.targets[0].uid
    assert w.albedo_panel.findChild(object, "kappa_R_value").isEnabled()
