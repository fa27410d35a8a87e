"""Helpers shared by the wizard's pages: rich-text messages, what to do about a failure, Enter keys."""

from __future__ import annotations

import html

from PySide6.QtCore import QEvent, QObject, Qt
from PySide6.QtWidgets import QAbstractSpinBox, QLineEdit

from engine.errors import DeviceError, InputError, SessionError

RED = "#c0392b"
#: Backends whose projector is simulated or recorded: no screen to choose, opened on a worker.
NO_SCREEN_BACKENDS = ("virtual", "mitsuba", "replay")
#: Rigs that simulate their scene: they take the "Virtual rig" options and report set-up progress.
SIMULATED = ("virtual:", "mitsuba:")


def esc(text: str) -> str:
    """Escape text for a rich-text label (quotes stay readable)."""
    return html.escape(text, quote=False)


def red(text: str) -> str:
    return f"<span style='color:{RED}'>{esc(text)}</span>"


def error_text(exc: BaseException) -> str:
    return str(exc) or type(exc).__name__


def fix_for(exc: BaseException) -> str:
    """What to do about a failure, beyond the engine's own words."""
    if isinstance(exc, SessionError):
        return "Go back to the first page and choose a new session folder."
    if isinstance(exc, DeviceError):
        return "Check the cables and power, then go back to the first page to open the rig again."
    if isinstance(exc, InputError):
        return "Fix what the message says, then press Start again: captures already taken are reused."
    return "This is unexpected: the message above and the session folder help a bug report."


class EnterCommits(QObject):
    """Event filter: Enter in a spin box or line edit commits its value instead of pressing Next."""

    def eventFilter(self, obj, event) -> bool:  # noqa: N802 (Qt name)
        if event.type() == QEvent.Type.KeyPress and event.key() in (Qt.Key.Key_Return, Qt.Key.Key_Enter):
            spin = obj if isinstance(obj, QAbstractSpinBox) else obj.parent()
            if isinstance(spin, QAbstractSpinBox):  # the spin box, or the line edit inside it
                spin.interpretText()
                spin.editingFinished.emit()
                return True
            if isinstance(obj, QLineEdit):
                obj.editingFinished.emit()
                return True
        return False
