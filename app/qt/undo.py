"""The model's undo history on a ``QUndoStack`` (Edit menu, Ctrl+Z / Ctrl+Shift+Z, clean state).

:class:`QtHistory` has the interface of :class:`app.model.history.History`; each model command is
wrapped in a ``QUndoCommand`` that calls its ``redo``/``undo``. Commands pushed as already
applied (a brush drag) skip the first ``redo`` that ``QUndoStack.push`` performs.
"""

from __future__ import annotations

from psygnal import Signal
from PySide6.QtGui import QUndoCommand, QUndoStack
from shiboken6 import isValid

from app.model.history import Command


class _QtCommand(QUndoCommand):
    def __init__(self, command: Command, applied: bool):
        super().__init__(command.text)
        self.command = command
        self._skip = applied

    def redo(self) -> None:
        if self._skip:
            self._skip = False
            return
        self.command.redo()

    def undo(self) -> None:
        self.command.undo()


class QtHistory:
    """Adapter: the :class:`app.model.history.History` interface over a ``QUndoStack``."""

    changed = Signal()

    def __init__(self, stack: QUndoStack | None = None):
        self.stack = stack if stack is not None else QUndoStack()
        self.stack.indexChanged.connect(self._on_stack_changed)
        self.stack.cleanChanged.connect(self._on_stack_changed)

    def _on_stack_changed(self, *_args) -> None:
        if isValid(self.stack):  # a QUndoStack being destroyed clears itself and signals
            self.changed.emit()

    def push(self, command: Command, *, applied: bool = False) -> None:
        self.stack.push(_QtCommand(command, applied))

    def undo(self) -> None:
        self.stack.undo()

    def redo(self) -> None:
        self.stack.redo()

    def can_undo(self) -> bool:
        return self.stack.canUndo()

    def can_redo(self) -> bool:
        return self.stack.canRedo()

    def undo_text(self) -> str:
        return self.stack.undoText()

    def redo_text(self) -> str:
        return self.stack.redoText()

    def count(self) -> int:
        return self.stack.count()

    def set_clean(self) -> None:
        self.stack.setClean()
        self.changed.emit()

    def is_clean(self) -> bool:
        return self.stack.isClean() if isValid(self.stack) else True

    def clear(self) -> None:
        self.stack.clear()
        self.changed.emit()
