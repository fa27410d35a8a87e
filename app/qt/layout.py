"""Window geometry that fits the screen it is on (small laptops, 2× scaled displays)."""

from __future__ import annotations

from PySide6.QtCore import QEvent, QObject, Qt
from PySide6.QtGui import QGuiApplication
from PySide6.QtWidgets import QAbstractSpinBox, QApplication, QComboBox, QScrollArea, QWidget

#: Room the window manager takes around a window (title bar and bottom border; side borders), logical pixels.
FRAME = 40
SIDES = 16


def fit_to_screen(widget: QWidget, preferred: tuple[int, int]) -> None:
    """Resize ``widget`` to ``preferred`` (w, h) or the available area of its screen if smaller, inside it."""
    screen = widget.screen() or QGuiApplication.primaryScreen()
    if screen is None:
        widget.resize(*preferred)
        return
    area = screen.availableGeometry()
    w, h = min(preferred[0], area.width() - SIDES), min(preferred[1], area.height() - FRAME)
    widget.resize(w, h)
    widget.move(area.x() + (area.width() - w) // 2, area.y() + max((area.height() - FRAME - h) // 2, 0))


def scrolling(widget: QWidget, name: str) -> QScrollArea:
    """``widget`` in a scroll area (docks scroll on small screens instead of cutting their controls)."""
    area = QScrollArea(objectName=name)
    area.setWidgetResizable(True)
    area.setFrameShape(QScrollArea.Shape.NoFrame)
    area.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
    area.setWidget(widget)
    guard = _WheelScrolls(area)
    for control in (*widget.findChildren(QComboBox), *widget.findChildren(QAbstractSpinBox)):
        control.setFocusPolicy(Qt.FocusPolicy.StrongFocus)  # a wheel passing over does not focus it
        control.installEventFilter(guard)
    # wide enough for the controls and the vertical scroll bar (without it, the bar covered their right edge)
    area.setMinimumWidth(widget.minimumSizeHint().width() + area.verticalScrollBar().sizeHint().width())
    return area


class _WheelScrolls(QObject):
    """The wheel over a combo box or spin box of a scrolling dock scrolls the dock, unless the control has the
    focus (clicked first): scrolling past the acquisition dock's controls changed its policy and its order."""

    def __init__(self, area: QScrollArea):
        super().__init__(area)
        self.area = area

    def eventFilter(self, obj, event) -> bool:  # noqa: N802 (Qt name)
        if event.type() == QEvent.Type.Wheel and not obj.hasFocus():
            QApplication.sendEvent(self.area.verticalScrollBar(), event)
            return True
        return False
