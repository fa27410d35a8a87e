"""Capture records: the log entry of each capture, and the pattern hash that finds it again."""

from __future__ import annotations

import copy
import hashlib
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from engine.errors import InputError

__all__ = ["CaptureRecord", "LoadedCapture", "now", "pattern_hash", "record", "sha256_file"]

def pattern_hash(pattern: np.ndarray) -> str:
    """A stable content hash of a projector pattern, to find the capture taken under it.

    Parameters
    ----------
    pattern : (Hp, Wp, 3) float
        The image given to ``Projector.show``. It is hashed as float32 (so a float64 copy of
        the same pattern hashes the same), with ``-0.0`` counted as ``0.0``, together with its
        shape.

    Returns
    -------
    str
        64 hexadecimal digits (SHA-256).

    Raises
    ------
    InputError
        ``pattern`` is not a finite float array.

    Examples
    --------
    >>> a = np.zeros((2, 3, 3), np.float32)
    >>> pattern_hash(a) == pattern_hash(a.astype(np.float64)) == pattern_hash(-a)
    True
    >>> pattern_hash(a) == pattern_hash(a.reshape(3, 2, 3))
    False
    """
    array = np.asarray(pattern)
    if array.dtype.kind != "f":
        raise InputError(f"pattern must be a float array (projector values in [0, 1]), got dtype {array.dtype}")
    array = np.ascontiguousarray(array, dtype=np.float32) + np.float32(0.0)
    if not np.all(np.isfinite(array)):
        raise InputError("pattern contains non-finite values (NaN or inf)")
    digest = hashlib.sha256(f"albedit-pattern:float32:{array.shape}:".encode())
    digest.update(array.tobytes())
    return digest.hexdigest()


@dataclass(frozen=True)
class CaptureRecord:
    """One entry of the capture log.

    Attributes
    ----------
    name : str
        Unique capture name (also the file stem).
    file : str
        Path relative to the session folder, ``"captures/<name>.exr"``.
    pattern_id : str
        :func:`pattern_hash` of the projector pattern shown (or any stable id the caller chose).
    meta : dict
        JSON metadata given at capture time; by convention ``exposure`` (s), ``gain``,
        ``black_level`` and ``metadata`` (the Frame's metadata), as written by
        :meth:`engine.session.Session.add_frame`.
    shape : (int, int, int)
        ``(H, W, 3)``.
    has_saturated : bool
        Whether a saturation mask is stored with the image.
    sha256 : str
        Checksum of the file's bytes, verified by :meth:`engine.session.Session.read_capture`.
    size : int
        File size in bytes, verified by :meth:`engine.session.Session.open`.
    time : str
        ISO 8601 UTC time the capture was stored.
    index : int
        Position in the log (0 = first).
    """

    name: str
    file: str
    pattern_id: str
    meta: dict
    shape: tuple[int, int, int]
    has_saturated: bool
    sha256: str
    size: int
    time: str
    index: int


@dataclass(frozen=True)
class LoadedCapture:
    """A capture read back: its record, image ``(H, W, 3) float32`` and saturation mask ``(H, W) bool``."""

    record: CaptureRecord
    image: np.ndarray
    saturated: np.ndarray


def record(entry: dict, index: int) -> CaptureRecord:
    """The :class:`CaptureRecord` of a manifest entry (a copy: the manifest stays untouched)."""
    return CaptureRecord(
        name=entry["name"],
        file=entry["file"],
        pattern_id=entry["pattern_id"],
        meta=copy.deepcopy(entry["meta"]),
        shape=tuple(entry["shape"]),
        has_saturated=entry["saturated"],
        sha256=entry["sha256"],
        size=entry["bytes"],
        time=entry["time"],
        index=index,
    )


def sha256_file(path: Path) -> tuple[str, int]:
    """``(hex digest, size in bytes)`` of a file's content."""
    digest = hashlib.sha256()
    size = 0
    with open(path, "rb") as fh:
        while chunk := fh.read(1 << 22):
            digest.update(chunk)
            size += len(chunk)
    return digest.hexdigest(), size


def now() -> str:
    """The current UTC time, ISO 8601 to the second."""
    return datetime.now(UTC).isoformat(timespec="seconds")
