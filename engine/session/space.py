"""What a failed write tells the user: on a full disk, how much space is needed and that a rerun resumes."""

from __future__ import annotations

import errno
import shutil
from pathlib import Path

from engine.errors import DiskFull, SessionError

__all__ = ["free_bytes", "megabytes", "write_failed"]

_FULL = (errno.ENOSPC, errno.EDQUOT)


def free_bytes(folder: Path) -> int:
    """Bytes free on the disk holding ``folder`` (0 if it cannot be asked)."""
    try:
        return int(shutil.disk_usage(folder).free)
    except OSError:
        return 0


def megabytes(n: int) -> str:
    """``n`` bytes in megabytes, for messages.

    Examples
    --------
    >>> megabytes(3_500_000), megabytes(1000)
    ('3.5 MB', '0.001 MB')
    """
    return f"{n / 1e6:.3g} MB"


def _is_full(exc: BaseException | None) -> bool:
    while exc is not None:
        if isinstance(exc, OSError) and exc.errno in _FULL:
            return True
        exc = exc.__cause__ or exc.__context__
    return False


def write_failed(folder: Path, what: str, exc: BaseException, needed: int, kept: str) -> SessionError:
    """The error for a write of ``what`` (``needed`` bytes) into session ``folder`` that failed with ``exc``.

    A full disk (``ENOSPC``, or less free space than the write needed) gives :class:`DiskFull`
    saying how much space is free and needed and that running the same command again resumes;
    anything else a :class:`SessionError` with the system's words. ``kept`` says what is safe.
    """
    free = free_bytes(folder)
    if _is_full(exc) or free < needed:
        return DiskFull(
            f"cannot write {what} in {folder}: the disk is full ({megabytes(free)} free, this write needs about "
            f"{megabytes(needed)}); free some space and run the same command again: {kept}, and it resumes where "
            "it stopped", free=free, needed=needed)
    return SessionError(f"cannot write {what} in {folder}: {exc}; {kept}")
