"""Names and paths inside a session folder: nothing is read or written outside it.

Every name the session gives a file (captures, masks, calibration arrays, cache entries) obeys
:data:`NAME`; every path read from the manifest goes through :func:`inside`, which refuses
absolute paths, ``..`` and symlinks leading out of the folder.
"""

from __future__ import annotations

import os
import re
from pathlib import Path, PurePosixPath, PureWindowsPath

from engine.errors import InputError, SessionError

__all__ = ["FOLDERS", "MANIFEST", "NAME", "check_name", "inside", "writable"]

MANIFEST = "manifest.json"
#: The sub-folders every session has.
FOLDERS = ("captures", "masks", "calibration", "cache")
#: A file name the session writes: letters, digits, ``._-``, starting with a letter or digit.
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,127}")


def check_name(kind: str, name) -> str:
    """Return ``name`` if it is a valid session file name, else raise InputError naming ``kind``."""
    if not isinstance(name, str) or not NAME.fullmatch(name):
        raise InputError(
            f"{kind} name must be 1-128 characters of letters, digits, '.', '_', '-' starting with a "
            f"letter or digit, got {name!r}"
        )
    return name


def inside(root: Path, path: Path, rel, where: str) -> Path:
    """Return ``path / rel`` if ``rel`` is a safe relative path that stays inside ``root``.

    Parameters
    ----------
    root : Path
        The session folder with symlinks resolved.
    path : Path
        The session folder as given.
    rel : str
        A path from the manifest, relative to the folder.
    where : str
        What the path belongs to, for the message.

    Raises
    ------
    SessionError
        ``rel`` is not a string, absolute, contains ``..``, or leads outside through a symlink.
    """
    if not isinstance(rel, str) or not rel:
        raise SessionError(f"{where}: path {rel!r} in the manifest must be a non-empty relative path")
    posix, windows = PurePosixPath(rel), PureWindowsPath(rel)
    if posix.is_absolute() or windows.is_absolute() or windows.drive or "\\" in rel or rel.startswith("~"):
        raise SessionError(f"{where}: path {rel!r} is absolute; session paths must be relative to the folder")
    if ".." in posix.parts:
        raise SessionError(f"{where}: path {rel!r} leads outside the session folder ('..')")
    full = path / posix
    real = Path(os.path.realpath(full))
    if real != root and root not in real.parents:
        raise SessionError(f"{where}: path {rel!r} leads outside the session folder (symlink to {real})")
    return full


def writable(root: Path, path: Path, rel: str, *, folder: bool = False) -> Path:
    """Return ``path / rel``, creating the folder(s) needed, refusing anything outside the session."""
    target = path / rel
    directory = target if folder else target.parent
    rel_dir = str(PurePosixPath(rel)) if folder else str(PurePosixPath(rel).parent)
    inside(root, path, rel_dir, rel)  # before mkdir: never create anything outside
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SessionError(f"cannot create {directory}: {exc}") from exc
    inside(root, path, rel_dir, rel)
    return target
