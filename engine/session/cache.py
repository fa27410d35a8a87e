"""The disposable cache: named arrays in ``cache/<key>.npz``; anything unreadable counts as missing.

Entries are plain uncompressed npz archives written atomically and read without pickle. A
corrupt or unsafe entry is deleted on read and reported as absent, so the caller recomputes.
"""

from __future__ import annotations

import errno
import os
import zipfile
from pathlib import Path

import numpy as np

from engine import imageio
from engine.errors import InputError
from engine.session.arrays import check_storable
from engine.session.paths import check_name

__all__ = ["check_entry", "read_entry", "write_entry"]


def check_entry(arrays) -> dict[str, np.ndarray]:
    """Return ``{name: ndarray}`` if every name is a session name and every array storable, else InputError."""
    if not isinstance(arrays, dict) or not arrays:
        raise InputError(f"arrays must be a non-empty dict {{name: array}}, got {arrays!r:.80}")
    return {check_name("cache array", name): check_storable(f"cache array {name!r}", array)
            for name, array in arrays.items()}


def write_entry(file: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write ``arrays`` (checked by :func:`check_entry`) to ``file`` atomically; OSError if it failed."""

    written = []

    def writer(temp: Path) -> None:
        with open(temp, "wb") as raw:
            with zipfile.ZipFile(raw, "w", compression=zipfile.ZIP_STORED) as zf:
                for name, array in arrays.items():
                    with zf.open(f"{name}.npy", "w", force_zip64=True) as fh:
                        np.lib.format.write_array(fh, array, allow_pickle=False)
            written.append(raw.tell())

    def verify(temp: Path) -> None:  # a full disk may truncate silently: the size must be what was written
        if os.path.getsize(temp) != written[-1]:
            raise OSError(errno.EIO, f"the cache entry written is {os.path.getsize(temp)} bytes, not {written[-1]}")

    imageio.atomic_write(file, writer, verify=verify)


def read_entry(file: Path) -> dict[str, np.ndarray] | None:
    """The arrays in ``file``, or None (and the file deleted) if it cannot be read safely."""
    try:
        with open(file, "rb") as fh:
            loaded = np.load(fh, allow_pickle=False)
            if not isinstance(loaded, np.lib.npyio.NpzFile):
                raise ValueError("not an npz archive")
            with loaded as npz:
                return {name: npz[name] for name in npz.files}
    except Exception:  # a disposable cache: any failure to read it means "recompute"
        try:
            os.unlink(file)
        except OSError:
            pass
        return None
