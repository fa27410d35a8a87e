"""Guard against a PySide6 reference-count bug that kills the process on Python < 3.12.

With the PySide6 6.12.0 wheel (``cp310-abi3``) on CPython 3.11, every call of a Qt method that
returns nothing drops one reference to ``None`` and every ``Signal.emit()`` drops one to
``True`` (measured: ``widget.update()`` ×1000 → ``sys.getrefcount(None)`` falls by 1000). On
3.12+ these objects are immortal (PEP 683) and nothing happens; on 3.11 the count reaches
zero after some tens of thousands of calls — a few minutes of painting — and CPython aborts
with "Fatal Python error: none_dealloc" (or "bool_dealloc").

:func:`install` checks for the leak with a few harmless calls and, only if it is there, gives
``None``, ``True`` and ``False`` the same effectively-infinite reference count that 3.12's
immortal objects have. The real fix is a PySide6 build without the bug or Python ≥ 3.12.
"""

from __future__ import annotations

import ctypes
import sys

_BIG = 1 << 40  # ~1e12 leaked references before anything could happen
_installed = False


def leaks() -> bool:
    """True when void Qt calls drop references to ``None`` in this interpreter."""
    if sys.version_info >= (3, 12):
        return False
    from PySide6.QtCore import QObject

    probe = QObject()
    before = sys.getrefcount(None)
    for _ in range(64):
        probe.setObjectName("probe")
    return sys.getrefcount(None) <= before - 64


def install() -> bool:
    """Make ``None``, ``True`` and ``False`` effectively immortal if PySide leaks them.

    Returns True when the guard was (or already is) installed.

    Examples
    --------
    >>> install() in (True, False)
    True
    """
    global _installed
    if _installed:
        return True
    if not leaks():
        return False
    for obj in (None, True, False):
        ctypes.c_ssize_t.from_address(id(obj)).value += _BIG  # ob_refcnt is the first field
    _installed = True
    return True
