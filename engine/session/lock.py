"""One advisory lock per session folder: two writers never interleave, and the second is told who writes.

The lock is the file ``session.lock`` in the folder, held with ``flock``: the kernel releases it
when the holder exits, however it exits, so a lock left behind by a killed process is stale
and simply taken over (its file still names the dead holder until then). While the lock is
held, the file names its holder — pid, host, command and since when — and a second writer
that cannot get it within a few seconds is refused with those words.

Within one process the lock is shared: every :class:`~engine.session.Session` object of the
same folder and every thread hold it through one counted holder, so the app's worker and its
window cooperate instead of refusing each other; :func:`thread_lock` serialises their manifest
updates.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import socket
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path

from engine.errors import SessionError

__all__ = ["LOCK_FILE", "WAIT_SECONDS", "describe_holder", "hold", "thread_lock"]

LOCK_FILE = "session.lock"
#: How long a writer waits for another process to let go before it is refused.
WAIT_SECONDS = 3.0
_POLL = 0.02


class _Holder:
    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.count = 0


_REGISTRY = threading.Lock()
_HELD: dict[tuple[int, int], _Holder] = {}
_ACQUIRING: dict[tuple[int, int], threading.Lock] = {}
_THREAD_LOCKS: dict[tuple[int, int], threading.RLock] = {}


def _key(folder: Path) -> tuple[int, int]:
    st = os.stat(folder)
    return st.st_dev, st.st_ino


def thread_lock(folder: Path) -> threading.RLock:
    """The lock every thread of this process takes around a change of ``folder``'s manifest."""
    key = _key(folder)
    with _REGISTRY:
        return _THREAD_LOCKS.setdefault(key, threading.RLock())


def _command() -> str:
    argv = sys.argv or ["python"]
    return " ".join([Path(argv[0]).name, *argv[1:2]])


def describe_holder(folder: Path) -> str:
    """Who the lock file says holds (or last held) ``folder``'s lock, in words."""
    try:
        info = json.loads((Path(folder) / LOCK_FILE).read_text(encoding="utf-8"))
        return (f"{info['command']} (pid {info['pid']} on {info['host']}, since {info['since']})"
                if isinstance(info, dict) else "another process")
    except (OSError, ValueError, KeyError, TypeError):
        return "another process"


@contextmanager
def hold(folder, purpose: str | None = None, *, wait: float | None = None, idle: bool = False) -> Iterator[None]:
    """Hold ``folder``'s lock for the block (re-entrant within the process).

    Parameters
    ----------
    folder : str or Path
        A session folder.
    purpose : str, optional
        What the holder is doing, recorded in the lock file (default: the command line).
    wait : float, optional
        Seconds to wait for another process to release it (default :data:`WAIT_SECONDS`).
    idle : bool
        Only if no one writes the folder, this process included (to clean up after killed
        writes without touching a live write's files).

    Raises
    ------
    SessionError
        Another process holds the lock (the message names it: command, pid, host, since),
        with ``idle`` this process does, or the lock file cannot be created (a read-only
        folder) or locked (a file system without locks).
    """
    folder = Path(folder)
    key = _key(folder)
    _acquire(folder, key, purpose or _command(), WAIT_SECONDS if wait is None else wait, idle)
    try:
        yield
    finally:
        _release(key)


def _acquire(folder: Path, key: tuple[int, int], purpose: str, wait: float, idle: bool) -> None:
    with _REGISTRY:
        gate = _ACQUIRING.setdefault(key, threading.Lock())
    with gate:  # one thread of this process acquires a folder at a time; the others count on it
        with _REGISTRY:
            holder = _HELD.get(key)
            if holder is not None:
                if idle:
                    raise SessionError(f"session {folder} is being written by this process")
                holder.count += 1
                return
        try:
            fd = os.open(folder / LOCK_FILE, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        except OSError as exc:
            raise SessionError(f"cannot take the lock of session {folder} ({exc.strerror or exc}): it is read-only or "
                               "unreachable; nothing was written") from None
        deadline = time.monotonic() + max(0.0, wait)
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() >= deadline:
                    os.close(fd)
                    raise SessionError(f"session {folder} is being written by {describe_holder(folder)}; wait until "
                                       "it has finished, then run again (nothing was written)") from None
                time.sleep(_POLL)
            except OSError as exc:
                os.close(fd)
                if exc.errno in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL):
                    raise SessionError(f"the file system of {folder} cannot lock files ({exc.strerror}); copy the "
                                       "session to a local disk to write it") from None
                raise SessionError(f"cannot take the lock of session {folder}: {exc}") from None
        info = {"pid": os.getpid(), "host": socket.gethostname(), "command": purpose,
                "since": datetime.now(UTC).isoformat(timespec="seconds")}
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, json.dumps(info).encode(), 0)
        except OSError:
            pass  # the holder's name is a courtesy to the next writer; the lock itself is held
        holder = _Holder(fd)
        holder.count = 1
        with _REGISTRY:
            _HELD[key] = holder


def _release(key: tuple[int, int]) -> None:
    with _REGISTRY:
        holder = _HELD[key]
        holder.count -= 1
        if holder.count:
            return
        del _HELD[key]
    try:
        os.ftruncate(holder.fd, 0)
    except OSError:
        pass
    fcntl.flock(holder.fd, fcntl.LOCK_UN)
    os.close(holder.fd)
