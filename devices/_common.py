"""Small helpers shared by the device backends: bounded device calls, option checks, cache keys.

Vendor libraries block inside C calls that no Python timeout can interrupt. :func:`call_with_timeout`
runs such a call on a daemon thread and gives up waiting after a deadline, so the caller gets a
:class:`~engine.errors.DeviceError` instead of a hang. The abandoned call keeps running; a backend
must refuse further calls until it finishes (see :class:`Watchdog`).
"""

from __future__ import annotations

import hashlib
import os
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from engine.errors import DeviceError, InputError


class DeviceTimeout(DeviceError):
    """A device call did not return within its deadline (the call may still be running)."""


class Watchdog:
    """Runs device calls with a deadline and remembers a call that never came back.

    Parameters
    ----------
    device : str
        Plain name of the device, used in messages ("camera", "Canon EOS 80D").

    Notes
    -----
    After a timeout the abandoned call is still inside the vendor library; running another call
    on the same handle could corrupt its state, so every later call raises until the abandoned
    one returns (then :attr:`recovered` is True once, so the backend can reset its session).

    Examples
    --------
    >>> dog = Watchdog("camera")
    >>> dog.call(lambda x: x + 1, 41, timeout=1.0, what="add")
    42
    """

    def __init__(self, device: str):
        self.device = device
        self._hung: threading.Thread | None = None
        self._hung_what = ""
        self.recovered = False

    def check(self) -> None:
        """Raise if an earlier call is still stuck in the device library."""
        if self._hung is None:
            return
        if self._hung.is_alive():
            raise DeviceError(
                f"the {self.device} has not answered an earlier {self._hung_what} yet; "
                "unplug and reconnect it (or switch it off and on), then open the rig again"
            )
        self._hung = None
        self.recovered = True

    def call(self, fn: Callable[..., Any], *args: Any, timeout: float, what: str) -> Any:
        """Call ``fn(*args)`` and return its result, or raise DeviceError after ``timeout`` s.

        Exceptions raised by ``fn`` propagate unchanged (the backend maps vendor errors).
        """
        self.check()
        box: dict[str, Any] = {}
        done = threading.Event()

        def run() -> None:
            try:
                box["value"] = fn(*args)
            except BaseException as exc:  # handed to the caller below
                box["error"] = exc
            finally:
                done.set()

        worker = threading.Thread(target=run, daemon=True, name=f"albedit-{what}")
        worker.start()
        if not done.wait(timeout):
            self._hung, self._hung_what = worker, what
            raise DeviceTimeout(
                f"the {self.device} did not finish {what} within {timeout:g} s; "
                "check the cable and that the device is switched on and not asleep"
            )
        if "error" in box:
            raise box["error"]
        return box.get("value")


def call_with_timeout(fn: Callable[..., Any], *args: Any, timeout: float, what: str, device: str = "device") -> Any:
    """Call ``fn(*args)`` on a daemon thread; raise DeviceError if it takes longer than ``timeout`` s.

    A one-shot :class:`Watchdog`; use a Watchdog per device when calls share a handle.

    Examples
    --------
    >>> call_with_timeout(sum, [1, 2], timeout=1.0, what="adding")
    3
    """
    return Watchdog(device).call(fn, *args, timeout=timeout, what=what)


def cache_folder(option, default: Callable[[], Any]):
    """A simulated rig's ``cache_dir`` option: a path, None (``default()``) or False (no cache)."""
    if option is None:
        return default()
    if option is False:
        return None
    if not isinstance(option, (str, os.PathLike)):
        raise InputError(f"cache_dir must be a path, None or False, got {option!r}")
    return option


def source_digest(package: Path) -> str:
    """Digest of the Python source of one package folder, for keying caches of what that code computes.

    A cache keyed by a hand-bumped version number is read by any code that carries the same
    number, including code restored by a revert after the number moved on; a cache keyed by the
    source itself is read only by the code that wrote it. Any edit (a docstring too) costs one
    rebuild, which is what a cache is for.

    Parameters
    ----------
    package : Path
        Folder whose ``*.py`` files (not sub-folders) make up the computation.

    Returns
    -------
    str
        16 hex digits.

    Examples
    --------
    >>> len(source_digest(Path(__file__).parent))
    16
    """
    digest = hashlib.sha256()
    for path in sorted(Path(package).glob("*.py")):
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()[:16]
