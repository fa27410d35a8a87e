"""The progress and cancellation conventions shared by all long engine and device work.

Long functions take ``progress(step, total, message)`` and ``should_stop()`` keyword
arguments; both may be ``None``. :func:`report` and :func:`checkpoint` are the only places
that call them.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from engine.errors import Cancelled


class Progress(Protocol):
    """``progress(step, total, message)``: ``step`` of ``total`` units are done."""

    def __call__(self, step: int, total: int, message: str, /) -> None: ...


ShouldStop = Callable[[], bool]


def report(progress: Progress | None, step: int, total: int, message: str) -> None:
    """Call ``progress`` if there is one."""
    if progress is not None:
        progress(step, total, message)


def checkpoint(should_stop: ShouldStop | None, what: str = "work") -> None:
    """Raise :class:`Cancelled` if ``should_stop()`` says so.

    Call between units of work, never in the middle of writing a file.
    """
    if should_stop is not None and should_stop():
        raise Cancelled(f"{what} cancelled on request")
