"""Words for people: counts and lists of names in messages (never a Python repr)."""

from __future__ import annotations

__all__ = ["counted", "listed"]


def counted(n: int, noun: str) -> str:
    """``n`` and ``noun``, plural unless ``n`` is 1.

    Examples
    --------
    >>> counted(1, "capture"), counted(3, "capture"), counted(0, "camera shot")
    ('1 capture', '3 captures', '0 camera shots')
    """
    return f"{n} {noun}" + ("" if n == 1 else "s")


def listed(names) -> str:
    """Names quoted and joined for a sentence.

    Examples
    --------
    >>> listed(["floor", "target 1"])
    "'floor', 'target 1'"
    """
    return ", ".join(repr(str(n)) for n in names)
