"""Undo history without Qt: commands with ``redo()``/``undo()`` and a stack of them.

The editing model (:mod:`app.model.document`) pushes every edit here. The desktop app swaps in
:class:`app.qt.undo.QtHistory`, the same interface over a ``QUndoStack`` (menus, shortcuts,
clean state), so the model never imports Qt and its tests need no widgets.

A command may be pushed *already applied* (a brush drag paints while the mouse moves and is
recorded once, on release): ``push(cmd, applied=True)`` skips the first ``redo()``.
"""

from __future__ import annotations

from typing import Protocol

from psygnal import Signal


class Command(Protocol):
    """One undoable edit. ``text`` is shown in the Edit menu ("Undo Paint 'wall'")."""

    text: str

    def redo(self) -> None: ...

    def undo(self) -> None: ...


class History:
    """A linear undo stack with a clean mark, like ``QUndoStack`` but Qt-free.

    Examples
    --------
    >>> class Add:
    ...     text = "add"
    ...     def __init__(self, box): self.box = box
    ...     def redo(self): self.box.append(1)
    ...     def undo(self): self.box.pop()
    >>> box = []
    >>> h = History()
    >>> h.push(Add(box)); h.push(Add(box)); box
    [1, 1]
    >>> h.undo(); box, h.can_redo()
    ([1], True)
    >>> h.is_clean()
    False
    """

    #: emitted after every push, undo, redo and clean-mark change
    changed = Signal()

    def __init__(self) -> None:
        self._commands: list[Command] = []
        self._index = 0  # number of applied commands
        self._clean: int | None = 0

    def push(self, command: Command, *, applied: bool = False) -> None:
        """Record ``command``; run its ``redo()`` unless ``applied``. Drops the redo tail."""
        if not applied:
            command.redo()
        del self._commands[self._index :]
        if self._clean is not None and self._clean > self._index:
            self._clean = None  # the clean state was in the dropped tail: unreachable now
        self._commands.append(command)
        self._index += 1
        self.changed.emit()

    def undo(self) -> None:
        """Undo the last applied command (no-op when there is none)."""
        if self._index == 0:
            return
        self._index -= 1
        self._commands[self._index].undo()
        self.changed.emit()

    def redo(self) -> None:
        """Redo the next undone command (no-op when there is none)."""
        if self._index == len(self._commands):
            return
        self._commands[self._index].redo()
        self._index += 1
        self.changed.emit()

    def can_undo(self) -> bool:
        return self._index > 0

    def can_redo(self) -> bool:
        return self._index < len(self._commands)

    def undo_text(self) -> str:
        return self._commands[self._index - 1].text if self.can_undo() else ""

    def redo_text(self) -> str:
        return self._commands[self._index].text if self.can_redo() else ""

    def count(self) -> int:
        """Number of commands on the stack (applied and undone)."""
        return len(self._commands)

    def set_clean(self) -> None:
        """Mark the current state as saved."""
        self._clean = self._index
        self.changed.emit()

    def is_clean(self) -> bool:
        """True when the state equals the last saved one."""
        return self._clean == self._index

    def clear(self) -> None:
        """Forget every command; the current state becomes clean."""
        self._commands.clear()
        self._index = 0
        self._clean = 0
        self.changed.emit()
