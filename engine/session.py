"""The on-disk session: one folder holding everything an edit was measured and decided from.

Layout (all paths relative to the session folder)::

    manifest.json        schema version, rig, calibration, masks, state (targets, κ, order,
                         acquisition plan/progress, the app's edits), capture log
    captures/<name>.exr  one float EXR per capture, written once, read-only, never rewritten
    masks/<name>.png     target masks, 8-bit grey PNG (0 / 255)
    calibration/<group>/<name>.exr | .npy
                         calibration arrays (EXR for finite float32 images, .npy for the rest)
    cache/<key>.npz      disposable results (decompositions); corrupt entries count as missing

Guarantees:

- every write is atomic (temporary file in the same folder, then rename), and the manifest is
  rewritten after each capture, so a process killed at any moment leaves the previous
  manifest intact and loses at most the capture being written — which is kept on disk: a
  capture file not listed in the manifest is an *orphan*, reported by :attr:`Session.orphans`
  and adopted by :meth:`Session.recover_orphans` (each capture file carries its own record);
- captures are created with mode 0o444 through a hard link that cannot replace an existing
  file, and are never opened for writing again;
- :meth:`Session.open` only reads: it refuses a missing or corrupt manifest, an unknown or newer
  schema version, a listed capture that is missing or corrupt, and any path that is absolute or
  leads outside the folder (``..`` or a symlink), changing nothing on disk; it never unpickles
  (``np.load(allow_pickle=False)``) or executes anything from the folder.
"""

from __future__ import annotations

import copy
import hashlib
import json
import os
import re
import shutil
import threading
import zipfile
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Any

import numpy as np

from engine import imageio
from engine.checks import check_float_image, check_mask, check_order, check_resolution
from engine.errors import InputError, SessionError

__all__ = ["SCHEMA_VERSION", "CaptureRecord", "LoadedCapture", "Session", "pattern_hash"]

#: The manifest schema this version writes and reads. Newer manifests are refused.
SCHEMA_VERSION = 1

_FORMAT = "albedit-session"
_MANIFEST = "manifest.json"
_FOLDERS = ("captures", "masks", "calibration", "cache")
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,127}")
_SHA256 = re.compile(r"[0-9a-f]{64}")
_MAX_MANIFEST_BYTES = 64 * 1024 * 1024
_SATURATED_CHANNEL = "saturated"


# ----------------------------------------------------------------------------- records


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
        :meth:`Session.add_frame`.
    shape : (int, int, int)
        ``(H, W, 3)``.
    has_saturated : bool
        Whether a saturation mask is stored with the image.
    sha256 : str
        Checksum of the file's bytes, verified by :meth:`Session.read_capture`.
    size : int
        File size in bytes, verified by :meth:`Session.open`.
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


# ----------------------------------------------------------------------------- helpers


def _check_name(kind: str, name) -> str:
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise InputError(
            f"{kind} name must be 1-128 characters of letters, digits, '.', '_', '-' starting with a "
            f"letter or digit, got {name!r}"
        )
    return name


def _json_default(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (tuple, set, frozenset)):
        return list(value)
    raise TypeError(f"{type(value).__name__} is not JSON-serialisable")


def _to_json(name: str, value) -> Any:
    """Return ``value`` as plain JSON data (numpy arrays become lists), or raise InputError."""
    try:
        return json.loads(json.dumps(value, default=_json_default, allow_nan=False))
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be JSON-serialisable (finite numbers, strings, lists, dicts): {exc}") from exc


def _refuse_constant(name: str):
    raise ValueError(f"non-standard JSON constant {name}")


def _sha256_file(path: Path) -> tuple[str, int]:
    digest = hashlib.sha256()
    size = 0
    with open(path, "rb") as fh:
        while chunk := fh.read(1 << 22):
            digest.update(chunk)
            size += len(chunk)
    return digest.hexdigest(), size


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def _is_int(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _write_npy(array: np.ndarray):
    def writer(temp: Path) -> None:
        with open(temp, "wb") as fh:
            np.save(fh, array, allow_pickle=False)

    return writer


# ----------------------------------------------------------------------------- the session


class Session:
    """An Albedit session folder (see the module docstring for the layout and guarantees).

    Create one with :meth:`create`, open one with :meth:`open`; don't call the constructor.
    Methods are thread-safe (one lock around every manifest change). Two processes must not
    write the same session at once.

    Attributes
    ----------
    path : Path
        The session folder.
    orphans : tuple of str
        Capture files found on disk but not in the manifest (relative paths), e.g. from a
        process killed between writing a capture and updating the manifest. They are never
        deleted; :meth:`recover_orphans` adopts them.
    """

    def __init__(self, path: Path, manifest: dict, orphans: list[str], *, _token=None):
        if _token is not _CONSTRUCT:
            raise TypeError("use Session.create(path, ...) or Session.open(path)")
        self.path = path
        self._root = Path(os.path.realpath(path))
        self._manifest = manifest
        self._orphans = list(orphans)
        self._lock = threading.RLock()

    # ------------------------------------------------------------------ create / open

    @classmethod
    def create(
        cls,
        path,
        *,
        rig_name: str,
        camera_resolution: tuple[int, int],
        projector_resolution: tuple[int, int],
        metadata: dict | None = None,
    ) -> Session:
        """Create a new, empty session folder.

        Parameters
        ----------
        path : str or Path
            A folder that does not exist yet (it is created) or is empty.
        rig_name : str
            The rig's name, e.g. ``"virtual:cornell"`` or ``"gphoto2"``.
        camera_resolution, projector_resolution : (int, int)
            ``(H, W)`` of the camera and ``(Hp, Wp)`` of the projector. Every capture must be
            ``(H, W, 3)``.
        metadata : dict, optional
            JSON facts about the session (operator, scene, projector bit depth, ...).

        Returns
        -------
        Session

        Raises
        ------
        SessionError
            ``path`` is a file, already a session, or a non-empty folder.
        InputError
            Bad rig name, resolution or metadata.

        Examples
        --------
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     s = Session.create(Path(d) / "s", rig_name="virtual:cornell",
        ...                        camera_resolution=(4, 6), projector_resolution=(8, 8))
        ...     print(s.camera_resolution, sorted(p.name for p in s.path.iterdir()))
        (4, 6) ['cache', 'calibration', 'captures', 'manifest.json', 'masks']
        """
        path = Path(path)
        if not isinstance(rig_name, str) or not rig_name:
            raise InputError(f"rig_name must be a non-empty string, got {rig_name!r}")
        camera = check_resolution("camera_resolution", camera_resolution)
        projector = check_resolution("projector_resolution", projector_resolution)
        metadata = _to_json("metadata", {} if metadata is None else metadata)
        if not isinstance(metadata, dict):
            raise InputError(f"metadata must be a dict, got {type(metadata).__name__}")
        if path.exists() or path.is_symlink():
            if not path.is_dir():
                raise SessionError(f"cannot create a session at {path}: it exists and is not a folder")
            if (path / _MANIFEST).exists():
                raise SessionError(f"{path} is already a session; use Session.open")
            if any(path.iterdir()):
                raise SessionError(f"cannot create a session in {path}: the folder is not empty")
        try:
            path.mkdir(parents=True, exist_ok=True)
            for folder in _FOLDERS:
                (path / folder).mkdir(exist_ok=True)
        except OSError as exc:
            raise SessionError(f"cannot create session folder {path}: {exc}") from exc
        manifest = {
            "format": _FORMAT,
            "schema_version": SCHEMA_VERSION,
            "created": _now(),
            "rig": {
                "name": rig_name,
                "camera_resolution": list(camera),
                "projector_resolution": list(projector),
            },
            "metadata": metadata,
            "state": {},
            "masks": {},
            "calibration": {"data": {}, "arrays": {}},
            "captures": [],
        }
        session = cls(path, manifest, [], _token=_CONSTRUCT)
        session._commit(manifest)
        return session

    @classmethod
    def open(cls, path, *, verify: bool = False) -> Session:
        """Open an existing session, checking it without changing anything on disk.

        Parameters
        ----------
        path : str or Path
            The session folder.
        verify : bool, keyword-only
            Also checksum every capture file (reads all of them; default checks each listed
            capture's existence, size and image header only).

        Returns
        -------
        Session

        Raises
        ------
        SessionError
            The folder or ``manifest.json`` is missing; the manifest is not valid JSON, not an
            Albedit manifest, of an unknown or newer schema version, or malformed; a listed
            capture is missing, of the wrong size or unreadable (or, with ``verify``, its
            checksum differs); a path in the manifest is absolute or leads outside the folder
            (``..``, or a symlink whose target is outside). The message names the file.
        """
        path = Path(path)
        if not path.is_dir():
            raise SessionError(f"no session folder at {path}")
        root = Path(os.path.realpath(path))
        manifest_path = path / _MANIFEST
        if not manifest_path.exists() and not manifest_path.is_symlink():
            raise SessionError(f"{path} is not a session: {_MANIFEST} is missing")
        _inside(root, path, _MANIFEST, "the manifest")
        if not manifest_path.is_file():
            raise SessionError(f"{manifest_path} is not a regular file")
        if manifest_path.stat().st_size > _MAX_MANIFEST_BYTES:
            raise SessionError(f"{manifest_path} is larger than {_MAX_MANIFEST_BYTES} bytes; refusing to load it")
        try:
            text = manifest_path.read_bytes().decode("utf-8")
            manifest = json.loads(text, parse_constant=_refuse_constant)
        except (ValueError, UnicodeDecodeError, RecursionError) as exc:
            raise SessionError(f"{manifest_path} is corrupt (not valid JSON): {exc}") from exc
        except OSError as exc:
            raise SessionError(f"cannot read {manifest_path}: {exc}") from exc
        _validate_manifest(manifest, manifest_path)
        for folder in _FOLDERS:
            if (path / folder).exists() or (path / folder).is_symlink():
                _inside(root, path, folder, f"the {folder} folder")
        camera = tuple(manifest["rig"]["camera_resolution"])
        referenced = set()
        for i, entry in enumerate(manifest["captures"]):
            where = f"capture {entry['name']!r} (captures[{i}])"
            file = _inside(root, path, entry["file"], where)
            referenced.add(PurePosixPath(entry["file"]).as_posix())
            _check_capture_file(file, entry, camera, where, verify=verify)
        for name, entry in manifest["masks"].items():
            _inside(root, path, entry["file"], f"mask {name!r}")
        for key, entry in manifest["calibration"]["arrays"].items():
            _inside(root, path, entry["file"], f"calibration array {key!r}")
        orphans = []
        captures_dir = path / "captures"
        if captures_dir.is_dir():
            for child in sorted(captures_dir.iterdir()):
                rel = f"captures/{child.name}"
                if child.name.startswith(".") or rel in referenced or child.is_dir():
                    continue  # temporary files of interrupted writes are ignored
                orphans.append(rel)
        return cls(path, manifest, orphans, _token=_CONSTRUCT)

    # ------------------------------------------------------------------ properties

    @property
    def rig_name(self) -> str:
        """The rig the session was recorded with."""
        return self._manifest["rig"]["name"]

    @property
    def camera_resolution(self) -> tuple[int, int]:
        """Camera ``(H, W)``; every capture is ``(H, W, 3)``."""
        return tuple(self._manifest["rig"]["camera_resolution"])

    @property
    def projector_resolution(self) -> tuple[int, int]:
        """Projector ``(Hp, Wp)``."""
        return tuple(self._manifest["rig"]["projector_resolution"])

    @property
    def metadata(self) -> dict:
        """A copy of the metadata given to :meth:`create`."""
        return copy.deepcopy(self._manifest["metadata"])

    @property
    def orphans(self) -> tuple[str, ...]:
        """Capture files on disk that the manifest does not list (see the class docstring)."""
        return tuple(self._orphans)

    @property
    def captures(self) -> tuple[CaptureRecord, ...]:
        """The capture log, oldest first."""
        with self._lock:
            return tuple(_record(e, i) for i, e in enumerate(self._manifest["captures"]))

    @property
    def state(self) -> dict:
        """A copy of the free JSON state: targets, kappa, order, acquisition progress, edits."""
        with self._lock:
            return copy.deepcopy(self._manifest["state"])

    @property
    def masks(self) -> tuple[str, ...]:
        """Names of the stored masks."""
        with self._lock:
            return tuple(self._manifest["masks"])

    def __repr__(self) -> str:
        return f"Session({str(self.path)!r}, rig={self.rig_name!r}, captures={len(self._manifest['captures'])})"

    # ------------------------------------------------------------------ captures

    def has_capture(self, name: str) -> bool:
        """Whether the log has a capture called ``name``."""
        with self._lock:
            return any(e["name"] == name for e in self._manifest["captures"])

    def capture_record(self, name: str) -> CaptureRecord:
        """The log entry of capture ``name``; SessionError if there is none."""
        with self._lock:
            for i, entry in enumerate(self._manifest["captures"]):
                if entry["name"] == name:
                    return _record(entry, i)
        raise SessionError(f"session {self.path} has no capture named {name!r}")

    def find_by_pattern(self, pattern_id: str) -> list[CaptureRecord]:
        """Every capture taken under pattern ``pattern_id``, oldest first (empty if none)."""
        with self._lock:
            return [_record(e, i) for i, e in enumerate(self._manifest["captures"]) if e["pattern_id"] == pattern_id]

    def add_capture(
        self,
        name: str,
        image: np.ndarray,
        *,
        pattern_id: str,
        meta: dict | None = None,
        saturated: np.ndarray | None = None,
    ) -> CaptureRecord:
        """Store a capture the moment it arrives, then log it in the manifest.

        The image is written to ``captures/<name>.exr`` (float32, read-only, carrying its own
        record in the ``albedit:capture`` attribute), then the manifest is rewritten
        atomically. If the process dies between the two, the file is an orphan that
        :meth:`recover_orphans` adopts on the next run.

        Parameters
        ----------
        name : str
            Unique capture name (letters, digits, ``._-``).
        image : (H, W, 3) float
            Linear radiance at the camera resolution, finite. Stored as float32.
        pattern_id : str, keyword-only
            :func:`pattern_hash` of the projector pattern shown.
        meta : dict, optional, keyword-only
            JSON metadata (exposure, gain, black_level, metadata, ...).
        saturated : (H, W) bool, optional, keyword-only
            Saturation mask, stored as an extra ``saturated`` channel of the EXR.

        Returns
        -------
        CaptureRecord

        Raises
        ------
        SessionError
            ``name`` is already logged, or a file of that name is already on disk (an orphan),
            or the disk write failed. Nothing existing is changed.
        InputError
            Bad name, image, pattern_id, meta or mask.
        """
        _check_name("capture", name)
        image = check_float_image("image", image, ndim=3)
        h, w = self.camera_resolution
        if image.shape != (h, w, 3):
            raise InputError(f"image must have shape {(h, w, 3)} (camera resolution, RGB), got {image.shape}")
        if not isinstance(pattern_id, str) or not pattern_id or len(pattern_id) > 256:
            raise InputError(f"pattern_id must be a non-empty string of at most 256 characters, got {pattern_id!r}")
        meta = _to_json("meta", {} if meta is None else meta)
        if not isinstance(meta, dict):
            raise InputError(f"meta must be a dict, got {type(meta).__name__}")
        if saturated is not None:
            saturated = check_mask("saturated", saturated, (h, w))
        with self._lock:
            if self.has_capture(name):
                raise SessionError(
                    f"session {self.path} already has a capture named {name!r}; captures are written once and never replaced"
                )
            rel = f"captures/{name}.exr"
            file = self.path / rel
            index = len(self._manifest["captures"])
            entry = {
                "name": name,
                "file": rel,
                "pattern_id": pattern_id,
                "meta": meta,
                "shape": [h, w, 3],
                "saturated": saturated is not None,
                "time": _now(),
            }
            pixels = image.astype(np.float32, copy=False)
            channels = ("R", "G", "B")
            if saturated is not None:
                pixels = np.concatenate([pixels, saturated[..., None].astype(np.float32)], axis=2)
                channels += (_SATURATED_CHANNEL,)
            try:
                imageio.write_image(
                    file,
                    pixels,
                    dtype="float",
                    metadata={"capture": {**entry, "index": index}},
                    channel_names=channels,
                    mode=0o444,
                    exclusive=True,
                )
            except FileExistsError:
                raise SessionError(
                    f"{file} already exists but is not in the manifest (an orphan from an interrupted run?); "
                    "it is never overwritten: call recover_orphans() or use another name"
                ) from None
            except InputError as exc:
                raise SessionError(f"cannot store capture {name!r}: {exc}") from exc
            entry["sha256"], entry["bytes"] = _sha256_file(file)
            new = copy.deepcopy(self._manifest)
            new["captures"].append(entry)
            try:
                self._commit(new)
            except SessionError as exc:
                self._orphans.append(rel)
                raise SessionError(
                    f"capture {name!r} was written to {file} but the manifest could not be updated ({exc}); "
                    "the file is kept and recover_orphans() adopts it"
                ) from exc
            return _record(entry, index)

    def add_frame(self, name: str, frame, *, pattern_id: str, meta: dict | None = None) -> CaptureRecord:
        """Store a ``devices.base.Frame`` (or anything with the same attributes) as a capture.

        ``meta`` gets ``exposure``, ``gain``, ``black_level`` and ``metadata`` from the frame
        (explicit ``meta`` keys win); the frame's saturation mask is stored with the image.
        See :meth:`add_capture`.
        """
        full = {
            "exposure": float(frame.exposure),
            "gain": float(frame.gain),
            "black_level": float(frame.black_level),
            "metadata": frame.metadata,
            **(meta or {}),
        }
        saturated = getattr(frame, "saturated", None)
        return self.add_capture(name, frame.image, pattern_id=pattern_id, meta=full, saturated=saturated)

    def load_capture(self, name: str) -> LoadedCapture:
        """Read a capture back with its record and saturation mask, checking its checksum.

        Raises
        ------
        SessionError
            No such capture; its file is missing, outside the folder, altered (checksum
            differs) or unreadable. The message names the file.
        """
        record = self.capture_record(name)
        file = _inside(self._root, self.path, record.file, f"capture {name!r}")
        if not file.is_file():
            raise SessionError(f"capture {name!r}: file {file} is missing")
        try:
            digest, _ = _sha256_file(file)
        except OSError as exc:
            raise SessionError(f"capture {name!r}: cannot read {file}: {exc}") from exc
        if digest != record.sha256:
            raise SessionError(f"capture {name!r}: {file} is corrupt (its checksum differs from the manifest's)")
        try:
            pixels = imageio.read_image(file, srgb=False)
        except InputError as exc:
            raise SessionError(f"capture {name!r}: {file} is unreadable: {exc}") from exc
        h, w, _ = record.shape
        expected = 4 if record.has_saturated else 3
        if pixels.shape != (h, w, expected) or not np.all(np.isfinite(pixels)):
            raise SessionError(f"capture {name!r}: {file} is corrupt (shape {pixels.shape} or non-finite values)")
        image = np.ascontiguousarray(pixels[..., :3])
        saturated = pixels[..., 3] > 0.5 if record.has_saturated else np.zeros((h, w), bool)
        return LoadedCapture(record, image, saturated)

    def read_capture(self, name: str) -> np.ndarray:
        """Read capture ``name`` as ``(H, W, 3) float32`` (see :meth:`load_capture`)."""
        return self.load_capture(name).image

    def recover_orphans(self) -> list[CaptureRecord]:
        """Adopt orphan capture files into the log, using the record each file carries.

        An orphan is adopted if it is a readable capture of this session's resolution whose
        embedded record names it and whose name is not already logged. Others stay in
        :attr:`orphans` (nothing is ever deleted).

        Returns
        -------
        list of CaptureRecord
            The adopted captures, in their original capture order.
        """
        with self._lock:
            found = []
            for rel in self._orphans:
                entry = self._orphan_entry(rel)
                if entry is not None:
                    found.append((entry.pop("index", 0), rel, entry))
            if not found:
                return []
            found.sort(key=lambda item: (item[0], item[2]["time"], item[2]["name"]))
            new = copy.deepcopy(self._manifest)
            start = len(new["captures"])
            for _, _, entry in found:
                new["captures"].append(entry)
            self._commit(new)
            adopted = {rel for _, rel, _ in found}
            self._orphans = [rel for rel in self._orphans if rel not in adopted]
            return [_record(e, start + i) for i, (_, _, e) in enumerate(found)]

    def _orphan_entry(self, rel: str) -> dict | None:
        try:
            file = _inside(self._root, self.path, rel, "orphan")
            record = imageio.read_metadata(file).get("capture")
            if not isinstance(record, dict):
                return None
            entry = {k: record.get(k) for k in ("name", "file", "pattern_id", "meta", "shape", "saturated", "time")}
            entry["index"] = record.get("index", 0) if _is_int(record.get("index")) else 0
            if entry["file"] != rel or self.has_capture(entry["name"]):
                return None
            pixels = imageio.read_image(file, srgb=False)
        except (SessionError, InputError):
            return None
        h, w = self.camera_resolution
        expected = (h, w, 4 if entry["saturated"] else 3)
        if pixels.shape != expected or not np.all(np.isfinite(pixels)):
            return None
        entry["sha256"], entry["bytes"] = _sha256_file(file)
        try:
            _validate_capture_entry(entry, "orphan", (h, w))
        except SessionError:
            return None
        return entry

    # ------------------------------------------------------------------ state

    def update(self, **fields) -> dict:
        """Merge ``fields`` into the JSON state and persist it atomically.

        Conventional keys: ``targets`` (target names → mask names or properties), ``kappa``,
        ``order`` (checked to be a positive integer), ``acquisition`` (plan and progress),
        ``edits``. A value of ``None`` removes the key. numpy arrays and scalars become lists
        and numbers.

        Returns
        -------
        dict
            A copy of the new state.

        Raises
        ------
        InputError
            A value is not JSON-serialisable (or ``order`` is not a positive integer).
        SessionError
            The manifest could not be written (the state on disk is unchanged).
        """
        if fields.get("order") is not None:
            fields["order"] = check_order(fields["order"])
        values = _to_json("state", fields)
        with self._lock:
            new = copy.deepcopy(self._manifest)
            for key, value in values.items():
                if value is None:
                    new["state"].pop(key, None)
                else:
                    new["state"][key] = value
            self._commit(new)
            return copy.deepcopy(new["state"])

    # ------------------------------------------------------------------ masks

    def write_mask(self, name: str, mask: np.ndarray) -> None:
        """Store (or replace) a target mask as ``masks/<name>.png``.

        Parameters
        ----------
        name : str
            Mask name.
        mask : (H, W) bool
            Camera pixels.
        """
        _check_name("mask", name)
        mask = check_mask("mask", mask, self.camera_resolution)
        rel = f"masks/{name}.png"
        with self._lock:
            file = self._writable(rel)
            try:
                imageio.write_image(file, mask.astype(np.uint8) * np.uint8(255))
            except InputError as exc:
                raise SessionError(f"cannot store mask {name!r}: {exc}") from exc
            new = copy.deepcopy(self._manifest)
            new["masks"][name] = {"file": rel, "shape": list(mask.shape)}
            self._commit(new)

    def read_mask(self, name: str) -> np.ndarray:
        """Read mask ``name`` as ``(H, W) bool``; SessionError if unknown, missing or corrupt."""
        with self._lock:
            entry = self._manifest["masks"].get(name)
        if entry is None:
            raise SessionError(f"session {self.path} has no mask named {name!r}")
        file = _inside(self._root, self.path, entry["file"], f"mask {name!r}")
        try:
            pixels = imageio.read_image(file, srgb=False)
        except InputError as exc:
            raise SessionError(f"mask {name!r}: {exc}") from exc
        if pixels.shape != (*entry["shape"], 1):
            raise SessionError(f"mask {name!r}: {file} has shape {pixels.shape}, expected {tuple(entry['shape'])}")
        return pixels[..., 0] > 0.5

    # ------------------------------------------------------------------ calibration

    def write_array(self, group: str, name: str, array: np.ndarray) -> None:
        """Store (or replace) a calibration array as ``calibration/<group>/<name>.exr`` or ``.npy``.

        Finite float32 images ``(H, W)`` or ``(H, W, C≤4)`` go to EXR (viewable in any image
        tool); everything else (integers, bools, float64, NaN-marked maps, other shapes) to
        ``.npy`` written without pickle. Both read back exactly.

        Raises
        ------
        InputError
            Bad names, or an object array (which would need pickle).
        """
        self._write_arrays({group: {name: array}}, data=None, replace=False)

    def read_array(self, group: str, name: str) -> np.ndarray:
        """Read a calibration array back (same dtype and shape as written).

        Raises
        ------
        SessionError
            Unknown array, or its file is missing, outside the folder or corrupt.
        """
        key = f"{group}/{name}"
        with self._lock:
            entry = self._manifest["calibration"]["arrays"].get(key)
        if entry is None:
            raise SessionError(f"session {self.path} has no calibration array {key!r}")
        file = _inside(self._root, self.path, entry["file"], f"calibration array {key!r}")
        shape, dtype = tuple(entry["shape"]), np.dtype(entry["dtype"])
        try:
            if file.suffix == ".npy":
                array = np.load(file, allow_pickle=False)
            else:
                array = imageio.read_image(file, srgb=False)
                if array.size == int(np.prod(shape)):
                    array = array.reshape(shape)
        except (InputError, OSError, ValueError, EOFError) as exc:
            raise SessionError(f"calibration array {key!r}: cannot read {file}: {exc}") from exc
        if array.shape != shape or array.dtype != dtype:
            raise SessionError(
                f"calibration array {key!r}: {file} holds {array.dtype}{array.shape}, the manifest says {dtype}{shape}"
            )
        return array

    def write_calibration(self, data: dict, arrays: dict[str, dict[str, np.ndarray]] | None = None) -> None:
        """Replace the whole calibration: JSON ``data`` and arrays ``{group: {name: array}}``.

        Arrays of a previous calibration not in ``arrays`` are dropped (their files deleted
        after the manifest is updated). Array files are written first, the manifest once at the end.
        """
        data = _to_json("calibration data", data)
        if not isinstance(data, dict):
            raise InputError(f"calibration data must be a dict, got {type(data).__name__}")
        self._write_arrays(arrays or {}, data=data, replace=True)

    def read_calibration(self) -> tuple[dict, dict[str, dict[str, np.ndarray]]]:
        """Return ``(data, arrays)`` as given to :meth:`write_calibration` (and :meth:`write_array`)."""
        with self._lock:
            data = copy.deepcopy(self._manifest["calibration"]["data"])
            keys = list(self._manifest["calibration"]["arrays"])
        arrays: dict[str, dict[str, np.ndarray]] = {}
        for key in keys:
            group, name = key.split("/", 1)
            arrays.setdefault(group, {})[name] = self.read_array(group, name)
        return data, arrays

    def _write_arrays(self, arrays, *, data, replace: bool) -> None:
        if not isinstance(arrays, dict):
            raise InputError(f"arrays must be a dict {{group: {{name: array}}}}, got {type(arrays).__name__}")
        prepared = []
        for group, members in arrays.items():
            _check_name("calibration group", group)
            if not isinstance(members, dict):
                raise InputError(f"arrays[{group!r}] must be a dict {{name: array}}, got {type(members).__name__}")
            for name, array in members.items():
                _check_name("calibration array", name)
                array = np.asarray(array)
                if array.dtype.hasobject or array.dtype.kind not in "biufc":
                    raise InputError(
                        f"calibration array {group}/{name} has dtype {array.dtype}; only numeric and bool arrays are stored"
                    )
                as_image = (
                    array.dtype == np.float32
                    and array.size > 0
                    and (array.ndim == 2 or (array.ndim == 3 and 1 <= array.shape[2] <= 4))
                    and bool(np.all(np.isfinite(array)))
                )
                rel = f"calibration/{group}/{name}.{'exr' if as_image else 'npy'}"
                prepared.append((f"{group}/{name}", rel, array, as_image))
        with self._lock:
            written = {}
            for key, rel, array, as_image in prepared:
                group = key.split("/", 1)[0]
                folder = self._writable(f"calibration/{group}", folder=True)
                file = folder / Path(rel).name
                try:
                    if as_image:
                        imageio.write_image(file, array, dtype="float")
                    else:
                        imageio.atomic_write(file, _write_npy(array))
                except (InputError, OSError) as exc:
                    raise SessionError(f"cannot store calibration array {key!r}: {exc}") from exc
                written[key] = {"file": rel, "shape": list(array.shape), "dtype": array.dtype.str}
            new = copy.deepcopy(self._manifest)
            before = {e["file"] for e in new["calibration"]["arrays"].values()}
            if replace:
                new["calibration"]["arrays"] = written
            else:
                new["calibration"]["arrays"].update(written)
            if data is not None:
                new["calibration"]["data"] = data
            self._commit(new)
            # files no longer referenced (dropped arrays, or an array that moved between .npy and .exr)
            for rel in before - {e["file"] for e in new["calibration"]["arrays"].values()}:
                try:
                    os.unlink(_inside(self._root, self.path, rel, "old calibration array"))
                except (OSError, SessionError):
                    pass

    # ------------------------------------------------------------------ cache

    def cache_put(self, key: str, arrays: dict[str, np.ndarray]) -> None:
        """Store disposable arrays (e.g. a decomposition) as ``cache/<key>.npz``, replacing any old entry.

        Raises
        ------
        InputError
            Bad key or array names, or an object array (which would need pickle).
        """
        _check_name("cache key", key)
        if not isinstance(arrays, dict) or not arrays:
            raise InputError(f"arrays must be a non-empty dict {{name: array}}, got {arrays!r:.80}")
        clean = {}
        for name, array in arrays.items():
            _check_name("cache array", name)
            array = np.asarray(array)
            if array.dtype.hasobject or array.dtype.kind not in "biufc":
                raise InputError(f"cache array {name!r} has dtype {array.dtype}; only numeric and bool arrays are stored")
            clean[name] = array

        def writer(temp: Path) -> None:
            with zipfile.ZipFile(temp, "w", compression=zipfile.ZIP_STORED) as zf:
                for name, array in clean.items():
                    with zf.open(f"{name}.npy", "w", force_zip64=True) as fh:
                        np.lib.format.write_array(fh, array, allow_pickle=False)

        with self._lock:
            folder = self._writable("cache", folder=True)
            try:
                imageio.atomic_write(folder / f"{key}.npz", writer)
            except OSError as exc:
                raise SessionError(f"cannot write cache entry {key!r}: {exc}") from exc

    def cache_get(self, key: str) -> dict[str, np.ndarray] | None:
        """Return the arrays stored under ``key``, or None if absent.

        A corrupt or unsafe entry (unreadable, not an npz, needing pickle, a symlink leading
        outside the folder) counts as missing and is deleted.
        """
        _check_name("cache key", key)
        file = self.path / "cache" / f"{key}.npz"
        if not file.exists() and not file.is_symlink():
            return None
        try:
            _inside(self._root, self.path, f"cache/{key}.npz", "cache entry")
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

    def cache_keys(self) -> list[str]:
        """Keys of the cache entries present, sorted."""
        folder = self.path / "cache"
        if not folder.is_dir() or folder.is_symlink():
            return []
        return sorted(p.stem for p in folder.glob("*.npz") if p.is_file() and not p.is_symlink())

    def cache_discard(self, key: str) -> None:
        """Delete the cache entry ``key`` if there is one."""
        _check_name("cache key", key)
        with self._lock:
            try:
                (self.path / "cache" / f"{key}.npz").unlink()
            except FileNotFoundError:
                pass

    def cache_clear(self) -> None:
        """Delete every cache entry."""
        folder = self.path / "cache"
        if not folder.is_dir() or folder.is_symlink():
            return
        for child in folder.iterdir():
            if child.is_file() or child.is_symlink():
                child.unlink()
            elif child.is_dir():
                shutil.rmtree(child)

    # ------------------------------------------------------------------ internals

    def _writable(self, rel: str, *, folder: bool = False) -> Path:
        """Return ``path/rel``, creating the folder(s) needed, refusing anything outside the session."""
        target = self.path / rel
        directory = target if folder else target.parent
        rel_dir = str(PurePosixPath(rel)) if folder else str(PurePosixPath(rel).parent)
        _inside(self._root, self.path, rel_dir, rel)  # before mkdir: never create anything outside
        try:
            directory.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise SessionError(f"cannot create {directory}: {exc}") from exc
        _inside(self._root, self.path, rel_dir, rel)
        return target

    def _commit(self, manifest: dict) -> None:
        """Write ``manifest`` atomically, then make it the in-memory state."""
        text = json.dumps(manifest, indent=1, ensure_ascii=False, allow_nan=False) + "\n"
        try:
            imageio.atomic_write(self.path / _MANIFEST, lambda temp: temp.write_text(text, encoding="utf-8"))
        except OSError as exc:
            raise SessionError(f"cannot write {self.path / _MANIFEST}: {exc}; the previous manifest is intact") from exc
        self._manifest = manifest


_CONSTRUCT = object()


# ----------------------------------------------------------------------------- validation


def _inside(root: Path, path: Path, rel, where: str) -> Path:
    """Return ``path / rel`` if ``rel`` is a safe relative path that stays inside ``root``."""
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


def _check_capture_file(file: Path, entry: dict, camera, where: str, *, verify: bool) -> None:
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
        raise SessionError(
            f"{where}: {file} is {info.height}x{info.width}x{info.channels}, expected {camera[0]}x{camera[1]}x{channels}"
        )
    if verify and _sha256_file(file)[0] != entry["sha256"]:
        raise SessionError(f"{where}: {file} is corrupt (its checksum differs from the manifest's)")


def _validate_capture_entry(entry, where: str, camera) -> None:
    def bad(field, expected):
        raise SessionError(f"{where}: {field} must be {expected}, got {entry.get(field)!r:.80}")

    if not isinstance(entry, dict):
        raise SessionError(f"{where} must be an object")
    if not isinstance(entry.get("name"), str) or not _NAME.fullmatch(entry["name"]):
        bad("name", "a capture name")
    if not isinstance(entry.get("file"), str):
        bad("file", "a relative path")
    if not isinstance(entry.get("pattern_id"), str) or not entry["pattern_id"]:
        bad("pattern_id", "a non-empty string")
    if not isinstance(entry.get("meta"), dict):
        bad("meta", "an object")
    shape = entry.get("shape")
    if not isinstance(shape, list) or len(shape) != 3 or shape != [*camera, 3]:
        bad("shape", f"[{camera[0]}, {camera[1]}, 3] (the camera resolution)")
    if not isinstance(entry.get("saturated"), bool):
        bad("saturated", "true or false")
    if not isinstance(entry.get("sha256"), str) or not _SHA256.fullmatch(entry["sha256"]):
        bad("sha256", "64 hexadecimal digits")
    if not _is_int(entry.get("bytes")) or entry["bytes"] < 0:
        bad("bytes", "a file size")
    if not isinstance(entry.get("time"), str):
        bad("time", "an ISO time string")


def _validate_manifest(manifest, where: Path) -> None:
    """Check the manifest's structure; SessionError naming the first problem."""
    if not isinstance(manifest, dict):
        raise SessionError(f"{where} is corrupt: expected a JSON object, got {type(manifest).__name__}")
    if manifest.get("format") != _FORMAT:
        raise SessionError(f"{where} is not an Albedit session manifest (format {manifest.get('format')!r})")
    version = manifest.get("schema_version")
    if not _is_int(version):
        raise SessionError(f"{where}: schema_version must be an integer, got {version!r}")
    if version > SCHEMA_VERSION:
        raise SessionError(
            f"{where} has schema_version {version}, newer than this Albedit reads ({SCHEMA_VERSION}); upgrade Albedit"
        )
    if version != SCHEMA_VERSION:
        raise SessionError(f"{where} has unknown schema_version {version} (this Albedit reads {SCHEMA_VERSION})")
    rig = manifest.get("rig")
    if not isinstance(rig, dict) or not isinstance(rig.get("name"), str):
        raise SessionError(f"{where}: 'rig' must be an object with a 'name'")
    for key in ("camera_resolution", "projector_resolution"):
        value = rig.get(key)
        if not isinstance(value, list) or len(value) != 2 or not all(_is_int(v) and v > 0 for v in value):
            raise SessionError(f"{where}: rig.{key} must be [height, width], got {value!r}")
    for key in ("metadata", "state", "masks"):
        if not isinstance(manifest.get(key), dict):
            raise SessionError(f"{where}: {key!r} must be an object")
    calibration = manifest.get("calibration")
    if (
        not isinstance(calibration, dict)
        or not isinstance(calibration.get("data"), dict)
        or not isinstance(calibration.get("arrays"), dict)
    ):
        raise SessionError(f"{where}: 'calibration' must be an object with 'data' and 'arrays' objects")
    for key, entry in calibration["arrays"].items():
        parts = key.split("/")
        ok = len(parts) == 2 and all(_NAME.fullmatch(p) for p in parts) and isinstance(entry, dict)
        if ok:
            try:
                ok = (
                    isinstance(entry.get("file"), str)
                    and isinstance(entry.get("shape"), list)
                    and all(_is_int(v) and v >= 0 for v in entry["shape"])
                    and np.dtype(entry.get("dtype")).kind in "biufc"
                )
            except TypeError:
                ok = False
        if not ok:
            raise SessionError(f"{where}: calibration array {key!r} has a malformed entry {entry!r:.120}")
    for name, entry in manifest["masks"].items():
        if (
            not _NAME.fullmatch(name)
            or not isinstance(entry, dict)
            or not isinstance(entry.get("file"), str)
            or not isinstance(entry.get("shape"), list)
            or len(entry["shape"]) != 2
            or not all(_is_int(v) for v in entry["shape"])
        ):
            raise SessionError(f"{where}: mask {name!r} has a malformed entry {entry!r:.120}")
    captures = manifest.get("captures")
    if not isinstance(captures, list):
        raise SessionError(f"{where}: 'captures' must be a list")
    camera = tuple(rig["camera_resolution"])
    names = set()
    for i, entry in enumerate(captures):
        _validate_capture_entry(entry, f"{where}: captures[{i}]", camera)
        if entry["name"] in names:
            raise SessionError(f"{where}: captures[{i}] repeats the name {entry['name']!r}")
        names.add(entry["name"])


def _record(entry: dict, index: int) -> CaptureRecord:
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
