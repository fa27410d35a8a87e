"""Placing a colour checker by hand: four clicks on the canvas, when the detector cannot find the chart.

:class:`CornerPlacement` takes the canvas's picks (its eyedropper mode) for four clicks, prompting in the status
bar for each corner in :data:`engine.checker`'s order, and hands the corners on; Esc or another tool cancels.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QObject, Qt, Signal
from PySide6.QtGui import QKeySequence, QShortcut

#: The outer corners of the chart's patch area, in the order :func:`engine.checker.checker_from_corners` takes.
CORNERS = ("dark skin (top left)", "bluish green (top right)", "black (bottom right)", "white (bottom left)")


class CornerPlacement(QObject):
    """Four clicks on ``canvas`` become a chart's corners (camera pixels).

    Parameters
    ----------
    canvas : app.qt.canvas.Canvas
    status : callable
        ``status(text)`` shows a prompt (the status bar).

    Signals
    -------
    placed(object)
        ``(4, 2)`` float64 ``(x, y)`` corners, once the fourth is clicked.
    """

    placed = Signal(object)

    def __init__(self, canvas, status):
        super().__init__(canvas)
        self.canvas, self.status = canvas, status
        self.corners: list[tuple[float, float]] | None = None  # None: not placing
        self._escape = QShortcut(QKeySequence(Qt.Key.Key_Escape), canvas.window(), self.cancel)
        self._escape.setEnabled(False)

    @property
    def active(self) -> bool:
        return self.corners is not None

    def start(self) -> None:
        """Ask for the first corner; the canvas's clicks are picks until the fourth."""
        self.corners = []
        self.canvas.set_picking(True)
        self._escape.setEnabled(True)
        self._prompt()

    def pick(self, x: float, y: float) -> None:
        """A click at camera pixel ``(x, y)``."""
        if self.corners is None:
            return
        self.corners.append((float(x), float(y)))
        if len(self.corners) < len(CORNERS):
            self._prompt()
            return
        corners = np.array(self.corners, np.float64)
        self._stop()
        self.placed.emit(corners)

    def cancel(self) -> None:
        """Esc: stop placing (nothing measured)."""
        if self.corners is not None:
            self._stop()
            self.status("Placing the colour checker's corners was cancelled")

    def _stop(self) -> None:
        self.corners = None
        self._escape.setEnabled(False)
        self.canvas.set_picking(False)

    def _prompt(self) -> None:
        n = len(self.corners)
        self.status(f"Colour checker: click the outer corner of its {CORNERS[n]} patch ({n + 1} of 4; Esc cancels)")
