"""A person at the keyboard and mouse: drives the real widgets, found by objectName (docs/ui.md).

Journey and regression tests go through :class:`User` only: actions are triggered as the menu
would, buttons are clicked, lists and sliders are operated with the mouse and the keyboard,
text is typed. No private method is called to set state a person could not set.

Every test runs under pytest-qt's exception capture: an exception escaping a Qt slot (or a
psygnal callback called from one) fails the test (``test_an_exception_escaping_a_slot_fails``).
"""

from __future__ import annotations

from PySide6.QtCore import QEvent, QPoint, QPointF, Qt
from PySide6.QtGui import QAction, QKeyEvent
from PySide6.QtWidgets import (
    QAbstractButton,
    QAbstractItemView,
    QAbstractSpinBox,
    QApplication,
    QLineEdit,
    QListWidget,
    QSlider,
    QStyle,
    QStyleOptionSlider,
    QWidget,
)

TIMEOUT_MS = 60_000


class User:
    """Operates ``window`` (a MainWindow or any top-level widget) through ``qtbot``."""

    def __init__(self, qtbot, window: QWidget):
        self.qtbot = qtbot
        self.window = window

    # ------------------------------------------------------------------ finding
    def find(self, name: str, cls=QWidget, root: QWidget | None = None):
        """The one visible-or-not widget called ``name`` under ``root`` (default the window)."""
        root = root or self.window
        found = root.findChildren(cls, name)
        assert len(found) == 1, f"expected one {cls.__name__} named {name!r} under {root.objectName()!r}, got {found}"
        return found[0]

    def action(self, name: str) -> QAction:
        return self.find(name, QAction)

    # ------------------------------------------------------------------ acting
    def trigger(self, name: str) -> None:
        """Choose a menu item (or press its shortcut): it must be enabled, as for a person."""
        act = self.action(name)
        assert act.isEnabled(), f"{name!r} ({act.text()!r}) is disabled: {act.toolTip() or act.statusTip()}"
        act.trigger()

    def click(self, target, root: QWidget | None = None) -> None:
        """Click a button (by name or widget); it must be visible and enabled."""
        w = self.find(target, QAbstractButton, root) if isinstance(target, str) else target
        assert w.isVisible() and w.isEnabled(), f"{w.objectName()!r} cannot be clicked (hidden or disabled)"
        self.qtbot.mouseClick(w, Qt.MouseButton.LeftButton, pos=w.rect().center())

    def type_into(self, target, text: str, root: QWidget | None = None, *, enter: bool = True) -> None:
        """Click into a spin box or line edit, replace its text, press Enter."""
        w = self.find(target, QWidget, root) if isinstance(target, str) else target
        edit = w.lineEdit() if isinstance(w, QAbstractSpinBox) else w
        assert w.isVisible() and w.isEnabled(), f"{w.objectName()!r} cannot be typed into"
        self.qtbot.mouseClick(edit, Qt.MouseButton.LeftButton, pos=edit.rect().center())
        self.qtbot.keyClick(edit, Qt.Key.Key_A, Qt.KeyboardModifier.ControlModifier)
        self.type_text(edit, text)
        if enter:
            self.qtbot.keyClick(edit, Qt.Key.Key_Return)

    def type_text(self, widget: QWidget, text: str) -> None:
        """Type ``text`` into ``widget`` key by key (characters beyond ASCII as a keyboard layout sends them)."""
        for ch in text:
            if ch.isascii():
                self.qtbot.keyClicks(widget, ch)
            else:  # QTest only knows ASCII keys: a key event carrying the character, as from a compose key
                for kind in (QEvent.Type.KeyPress, QEvent.Type.KeyRelease):
                    QApplication.sendEvent(widget, QKeyEvent(kind, 0, Qt.KeyboardModifier.NoModifier, ch))

    def press(self, key, modifiers=Qt.KeyboardModifier.NoModifier) -> None:
        """A key press where the keyboard focus is (as a person presses a shortcut), in the active window."""
        if not self.window.isActiveWindow():  # e.g. after a dialog closed: a person clicks the window first
            self.window.activateWindow()
            self.qtbot.waitUntil(self.window.isActiveWindow, timeout=5000)
        target = QApplication.focusWidget() or self.window
        self.qtbot.keyClick(target, key, modifiers)

    # ------------------------------------------------------------------ lists
    def row_point(self, lst: QListWidget, row: int) -> QPoint:
        item = lst.item(row)
        assert item is not None, f"{lst.objectName()!r} has no row {row} ({lst.count()} rows)"
        lst.scrollToItem(item)
        return lst.visualItemRect(item).center()

    def select_row(self, lst: QListWidget, row: int) -> None:
        self.qtbot.mouseClick(lst.viewport(), Qt.MouseButton.LeftButton, pos=self.row_point(lst, row))

    def toggle_row(self, lst: QListWidget, row: int) -> None:
        """Select a row and press Space: its check box flips."""
        self.select_row(lst, row)
        self.qtbot.keyClick(lst, Qt.Key.Key_Space)

    def rename_row(self, lst: QListWidget, row: int, text: str) -> None:
        """Double-click a row, type the new text, press Enter."""
        self.double_click(lst.viewport(), self.row_point(lst, row))
        editor = lst.viewport().findChild(QLineEdit) or lst.findChild(QLineEdit)
        assert editor is not None and editor.isVisible(), "double-clicking the row opened no editor"
        self.qtbot.keyClick(editor, Qt.Key.Key_A, Qt.KeyboardModifier.ControlModifier)
        self.type_text(editor, text)
        self.qtbot.keyClick(editor, Qt.Key.Key_Return)  # the view commits on its next event-loop turn
        self.qtbot.waitUntil(lambda: lst.state() != QAbstractItemView.State.EditingState, timeout=5000)

    def double_click(self, widget: QWidget, pos: QPoint) -> None:
        """Press, release, then the second press that makes it a double click (QTest sends only that one)."""
        self.qtbot.mouseClick(widget, Qt.MouseButton.LeftButton, pos=pos)
        self.qtbot.mouseDClick(widget, Qt.MouseButton.LeftButton, pos=pos)

    def rows(self, lst: QListWidget) -> list[str]:
        return [lst.item(i).text() for i in range(lst.count())]

    # ------------------------------------------------------------------ sliders and the canvas
    def drag_slider(self, slider: QSlider, values) -> None:
        """Grab the slider's handle with the mouse and drag it through ``values`` (slider units)."""
        assert slider.isVisible() and slider.isEnabled(), f"{slider.objectName()!r} cannot be dragged"
        opt = QStyleOptionSlider()
        slider.initStyleOption(opt)
        style = slider.style()
        handle = style.subControlRect(QStyle.ComplexControl.CC_Slider, opt, QStyle.SubControl.SC_SliderHandle, slider)
        groove = style.subControlRect(QStyle.ComplexControl.CC_Slider, opt, QStyle.SubControl.SC_SliderGroove, slider)
        span = groove.width() - handle.width()
        grab = handle.center() - handle.topLeft()

        def at(value) -> QPoint:
            x = style.sliderPositionFromValue(slider.minimum(), slider.maximum(), int(value), span)
            return QPoint(groove.x() + x + grab.x(), handle.center().y())

        start = handle.center()
        self.qtbot.mousePress(slider, Qt.MouseButton.LeftButton, pos=start)
        last = start
        for v in values:
            last = at(v)
            self.qtbot.mouseMove(slider, last)
        self.qtbot.mouseRelease(slider, Qt.MouseButton.LeftButton, pos=last)

    def canvas_point(self, canvas, x: float, y: float) -> QPoint:
        """Widget position of camera pixel coordinates (x, y) on the canvas as shown now."""
        p = canvas.to_widget(QPointF(x, y))
        return QPoint(round(p.x()), round(p.y()))

    def drag_on_canvas(self, canvas, points, *, button=Qt.MouseButton.LeftButton,
                       modifiers=Qt.KeyboardModifier.NoModifier) -> None:
        """Press at the first camera-pixel point, move through the rest, release at the last."""
        pts = [self.canvas_point(canvas, x, y) for x, y in points]
        self.qtbot.mousePress(canvas, button, modifiers, pts[0])
        for p in pts[1:]:
            self.qtbot.mouseMove(canvas, p)
        self.qtbot.mouseRelease(canvas, button, modifiers, pts[-1])

    def click_on_canvas(self, canvas, x: float, y: float, *, button=Qt.MouseButton.LeftButton) -> None:
        """Click at camera pixel coordinates (x, y) (the eyedropper, a polygon vertex)."""
        self.qtbot.mouseClick(canvas, button, pos=self.canvas_point(canvas, x, y))

    def wait_until(self, condition, timeout_ms: int = TIMEOUT_MS) -> None:
        self.qtbot.waitUntil(condition, timeout=timeout_ms)
