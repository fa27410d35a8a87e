"""The installed Qt binding must not leak references to interpreter singletons.

PySide6 6.12.0 (abi3) on CPython 3.11 drops a reference to None on every void Qt call and
to True on every Signal.emit; the interpreter aborts after a few thousand of them (minutes of
painting). pyproject.toml excludes it; this test fails if such a binding is installed.
"""

import sys

from PySide6.QtCore import QObject, Signal


class _Emitter(QObject):
    changed = Signal(int)


def test_void_calls_and_emits_keep_none_and_true_alive():
    obj = _Emitter()
    obj.changed.connect(lambda value: None)
    none_before, true_before = sys.getrefcount(None), sys.getrefcount(True)
    for _ in range(2000):
        obj.setObjectName("probe")  # returns None
        obj.changed.emit(1)  # returns True
    assert sys.getrefcount(None) >= none_before - 50
    assert sys.getrefcount(True) >= true_before - 50
