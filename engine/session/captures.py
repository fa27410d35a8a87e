"""Capture files: one float EXR per capture, carrying its own record, checked every time it is read.

A capture file holds R, G, B (and a ``saturated`` channel when the frame had clipped pixels)
and, in its ``albedit:capture`` attribute, the record it was logged with (name, file, pattern,
meta, shape, time, index), so a file whose manifest update was lost can be adopted again.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from engine import imageio
from engine.errors import InputError, SessionError
from engine.session.records import CaptureRecord, LoadedCapture, sha256_file

__all__ = ["SATURATED_CHANNEL", "check_file", "inspect_orphan", "read", "size_bound", "write"]

#: Name of the extra EXR channel holding a capture's saturation mask.
SATURATED_CHANNEL = "saturated"
_ENTRY_KEYS = ("name", "file", "pattern_id", "meta", "shape", "saturated", "time")


def size_bound(shape: tuple[int, ...], saturated: bool) -> int:
    """Bytes a capture of ``(H, W, 3)`` pixels takes at most on disk (float32, uncompressed, plus its header)."""
    h, w = shape[:2]
    return h * w * (4 if saturated else 3) * 4 + 64 * 1024


def write(file: Path, image: np.ndarray, saturated: np.ndarray | None, embedded: dict) -> tuple[str, int]:
    """Write a capture file once (read-only, never replacing a file); returns ``(sha256, size)``.

    Raises
    ------
    FileExistsError
        A file of that name is already there (nothing written).
    InputError
        The write failed (nothing left under ``file``).
    """
    pixels = image.astype(np.float32, copy=False)
    channels: tuple[str, ...] = ("R", "G", "B")
    if saturated is not None:
        pixels = np.concatenate([pixels, saturated[..., None].astype(np.float32)], axis=2)
        channels += (SATURATED_CHANNEL,)
    imageio.write_image(file, pixels, dtype="float", metadata={"capture": embedded}, channel_names=channels,
                        mode=0o444, exclusive=True)
    return sha256_file(file)


def read(file: Path, rec: CaptureRecord) -> LoadedCapture:
    """Read a capture back, checking its checksum, shape and values.

    Raises
    ------
    SessionError
        Missing, altered (checksum differs), unreadable, or of the wrong shape or with
        non-finite values; the message names the capture and the file.
    """
    name = rec.name
    if not file.is_file():
        raise SessionError(f"capture {name!r}: file {file} is missing")
    try:
        digest, _ = sha256_file(file)
    except OSError as exc:
        raise SessionError(f"capture {name!r}: cannot read {file}: {exc}") from exc
    if digest != rec.sha256:
        raise SessionError(f"capture {name!r}: {file} is corrupt (its checksum differs from the manifest's)")
    try:
        pixels = imageio.read_image(file, srgb=False)
    except InputError as exc:
        raise SessionError(f"capture {name!r}: {file} is unreadable: {exc}") from exc
    h, w, _ = rec.shape
    expected = 4 if rec.has_saturated else 3
    if pixels.shape != (h, w, expected) or not np.all(np.isfinite(pixels)):
        raise SessionError(f"capture {name!r}: {file} is corrupt (shape {pixels.shape} or non-finite values)")
    _check_identity(file, {"name": rec.name, "file": rec.file, "pattern_id": rec.pattern_id}, f"capture {name!r}")
    image = np.ascontiguousarray(pixels[..., :3])
    saturated = pixels[..., 3] > 0.5 if rec.has_saturated else np.zeros((h, w), bool)
    return LoadedCapture(rec, image, saturated)


def check_file(file: Path, entry: dict, camera, where: str, *, verify: bool) -> None:
    """The quick check on open: the file exists with the logged size and a header of the right shape.

    With ``verify`` its checksum is compared too. SessionError naming ``where`` otherwise.
    """
    if not file.is_file():
        raise SessionError(f"{where}: file {file} is missing")
    size = file.stat().st_size
    if size != entry["bytes"]:
        raise SessionError(f"{where}: {file} is corrupt ({size} bytes, the manifest says {entry['bytes']})")
    try:
        info = imageio.image_info(file)
    except InputError as exc:
        raise SessionError(f"{where}: {file} is corrupt: {exc}") from exc
    channels = 4 if entry["saturated"] else 3
    if (info.height, info.width, info.channels) != (*camera, channels):
        raise SessionError(f"{where}: {file} is {info.height}x{info.width}x{info.channels}, "
                           f"expected {camera[0]}x{camera[1]}x{channels}")
    if verify and sha256_file(file)[0] != entry["sha256"]:
        raise SessionError(f"{where}: {file} is corrupt (its checksum differs from the manifest's)")
    _check_identity(file, entry, where)


def _check_identity(file: Path, entry: dict, where: str) -> None:
    """SessionError unless the record the file carries names the same capture and pattern as the manifest.

    Catches files swapped or copied over one another together with their manifest entries
    (size and checksum then agree): each file knows which capture it is.
    """
    try:
        embedded = imageio.read_metadata(file).get("capture")
    except InputError as exc:
        raise SessionError(f"{where}: {file} is corrupt: {exc}") from exc
    if not isinstance(embedded, dict):
        raise SessionError(f"{where}: {file} carries no capture record; it is not a capture this session wrote")
    for key in ("name", "file", "pattern_id"):
        if embedded.get(key) != entry[key]:
            raise SessionError(
                f"{where}: {file} holds the capture recorded as {embedded.get('name')!r} "
                f"(its {key} is {embedded.get(key)!r:.80}, the manifest says {entry[key]!r:.80}): the capture files "
                "were swapped or replaced; restore them, or recapture into a new session")


def inspect_orphan(file: Path, rel: str, camera) -> tuple[dict | None, str | None]:
    """What an orphan file is: ``(entry, None)`` for an adoptable capture, ``(None, why)`` for an unreadable one.

    ``entry`` is the manifest entry the file carries, with its checksum and its original
    position as ``"index"``. A readable file that is not a capture of this session naming
    itself ``rel`` (another program's image) gives ``(None, None)``: it is left alone.
    """
    try:
        embedded = imageio.read_metadata(file).get("capture")
    except InputError as exc:
        return None, str(exc)
    if not isinstance(embedded, dict) or embedded.get("file") != rel:
        try:
            imageio.image_info(file)
        except InputError as exc:
            return None, str(exc)
        return None, None
    entry = {k: embedded.get(k) for k in _ENTRY_KEYS}
    index = embedded.get("index", 0)
    entry["index"] = index if isinstance(index, int) and not isinstance(index, bool) else 0
    try:
        pixels = imageio.read_image(file, srgb=False)
    except InputError as exc:
        return None, str(exc)
    expected = (*camera, 4 if entry["saturated"] else 3)
    if pixels.shape != expected:
        return None, f"its pixels are {pixels.shape}, a capture of this session is {expected}"
    entry["sha256"], entry["bytes"] = sha256_file(file)
    return entry, None
