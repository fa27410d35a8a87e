"""The :class:`Session` front door: create, open, and every read and write of a session folder.

What each part of the folder holds and how it is checked lives in the sibling modules:
:mod:`~engine.session.schema` (the manifest), :mod:`~engine.session.paths` (names, safe
paths), :mod:`~engine.session.records` (capture records), :mod:`~engine.session.arrays`
(calibration arrays), :mod:`~engine.session.cache` (the disposable cache) and
:mod:`~engine.session.edit` (the saved edit). This file is longer than most because it is the
one front door: every public method of a session, each with its documentation, delegating
the work to those modules.
"""

from __future__ import annotations

import copy
import errno
import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path, PurePosixPath

import numpy as np

from engine import imageio
from engine.checks import check_float_image, check_mask, check_order, check_resolution
from engine.errors import DiskFull, InputError, SessionError
from engine.session import arrays as _arrays
from engine.session import cache as _cache
from engine.session import captures as _captures
from engine.session import lock as _lock
from engine.session.jsonio import dumps, to_json
from engine.session.opening import check_folder, is_skeleton, read_manifest, remove_temporaries
from engine.session.paths import FOLDERS, MANIFEST, check_name, inside, writable
from engine.session.records import CaptureRecord, LoadedCapture, now, record
from engine.session.schema import FINGERPRINT, FORMAT, SCHEMA_VERSION, validate_manifest, validate_state
from engine.session.space import write_failed
from engine.session.spec import Invalid

__all__ = ["Session"]

_CONSTRUCT = object()


class Session:
    """An Albedit session folder (see :mod:`engine.session` for the layout and guarantees).

    Create one with :meth:`create`, open one with :meth:`open`; don't call the constructor.
    Every write holds the session's advisory lock (:mod:`engine.session.lock`) and re-reads
    the manifest if another writer changed it, so no update is lost; :meth:`writing` holds the
    lock across a whole run. Methods are thread-safe.

    Attributes
    ----------
    path : Path
        The session folder.
    orphans : tuple of str
        Capture files found on disk but not in the manifest (relative paths), e.g. from a
        process killed between writing a capture and updating the manifest. They are never
        deleted; :meth:`recover_orphans` adopts them.
    quarantined : list of (str, str, str)
        Unreadable orphans :meth:`recover_orphans` moved aside: (where it was, where it is
        now under ``quarantine/``, why it is unreadable).
    removed : list of str
        Temporary files of killed writes that :meth:`open` deleted.
    """

    def __init__(self, path: Path, manifest: dict, orphans: list[str], *, _token=None):
        if _token is not _CONSTRUCT:
            raise TypeError("use Session.create(path, ...) or Session.open(path)")
        self.path = path
        self._root = Path(os.path.realpath(path))
        self._manifest = manifest
        self._signature = _signature(self.path)
        self._orphans = list(orphans)
        self._lock = _lock.thread_lock(self._root)
        self.quarantined: list[tuple[str, str, str]] = []
        self.removed: list[str] = []

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
        fingerprint: dict | None = None,
    ) -> Session:
        """Create a new, empty session folder.

        Parameters
        ----------
        path : str or Path
            A folder that does not exist yet (it is created), is empty, or holds only the empty
            skeleton of an interrupted :meth:`create`.
        rig_name : str
            The rig's name, e.g. ``"virtual:cornell"`` or ``"gphoto2"``.
        camera_resolution, projector_resolution : (int, int)
            ``(H, W)`` of the camera and ``(Hp, Wp)`` of the projector. Every capture must be
            ``(H, W, 3)``.
        metadata : dict, optional
            JSON facts about the session (operator, scene, projector bit depth, ...).
        fingerprint : dict, optional
            What the rig's calibration depends on (:attr:`engine.rig.RigLike.fingerprint`):
            strings, numbers, booleans and lists of them.

        Returns
        -------
        Session

        Raises
        ------
        SessionError
            ``path`` is a file, already a session, or a folder holding anything but the empty
            skeleton an interrupted :meth:`create` leaves (which is completed).
        InputError
            Bad rig name, resolution or metadata.

        Examples
        --------
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     s = Session.create(Path(d) / "s", rig_name="virtual:cornell",
        ...                        camera_resolution=(4, 6), projector_resolution=(8, 8))
        ...     print(s.camera_resolution, sorted(p.name for p in s.path.iterdir()))
        (4, 6) ['cache', 'calibration', 'captures', 'manifest.json', 'masks', 'session.lock']
        """
        path = Path(path)
        if not isinstance(rig_name, str) or not rig_name:
            raise InputError(f"rig_name must be a non-empty string, got {rig_name!r}")
        camera = check_resolution("camera_resolution", camera_resolution)
        projector = check_resolution("projector_resolution", projector_resolution)
        metadata = to_json("metadata", {} if metadata is None else metadata)
        if not isinstance(metadata, dict):
            raise InputError(f"metadata must be a dict, got {type(metadata).__name__}")
        if fingerprint is not None:
            fingerprint = to_json("fingerprint", fingerprint)
            try:
                FINGERPRINT.check(fingerprint, "fingerprint")
            except Invalid as exc:
                raise InputError(str(exc)) from None
        if path.exists() or path.is_symlink():
            if not path.is_dir():
                raise SessionError(f"cannot create a session at {path}: it exists and is not a folder")
            if (path / MANIFEST).exists():
                raise SessionError(f"{path} is already a session; use Session.open")
            if not is_skeleton(path):
                raise SessionError(f"cannot create a session in {path}: the folder is not empty")
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise SessionError(f"cannot create session folder {path}: {exc}") from exc
        with _lock.hold(path, "creating the session"):
            if (path / MANIFEST).exists() or not is_skeleton(path):  # another process was quicker
                raise SessionError(f"cannot create a session in {path}: another process has just created one there")
            remove_temporaries(path)
            try:
                for folder in FOLDERS:
                    (path / folder).mkdir(exist_ok=True)
            except OSError as exc:
                raise SessionError(f"cannot create session folder {path}: {exc}") from exc
            session = cls(path, _new_manifest(rig_name, camera, projector, metadata, fingerprint), [],
                          _token=_CONSTRUCT)
            session._commit(session._manifest)
        return session

    @classmethod
    def open(cls, path, *, verify: bool = False) -> Session:
        """Open an existing session, checking it; only temporary files of killed writes are removed.

        Those are removed only when no one writes the session (see :attr:`removed`); a
        refusal changes nothing on disk.

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
            Albedit manifest, of an unknown or newer schema version, or a field does not fit the
            schema (:mod:`engine.session.schema`: the message names the field's path); a listed
            capture is missing, of the wrong size or unreadable (or, with ``verify``, its
            checksum differs); a path in the manifest is absolute or leads outside the folder
            (``..``, or a symlink whose target is outside). The message names the file.
        """
        path = Path(path)
        if not path.is_dir():
            raise SessionError(f"no session folder at {path}")
        root = Path(os.path.realpath(path))
        manifest = read_manifest(root, path)
        orphans = check_folder(root, path, manifest, verify=verify)
        session = cls(path, manifest, orphans, _token=_CONSTRUCT)
        session.removed = session._remove_temporaries()
        return session

    def _remove_temporaries(self) -> list[str]:
        """Delete the temporary files of killed writes, unless another process is writing (its are live)."""
        try:
            with _lock.hold(self._root, "removing temporary files", wait=0, idle=True):
                return remove_temporaries(self.path)
        except SessionError:  # a writer is at work, or the folder is read-only: leave them
            return []

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
    def fingerprint(self) -> dict | None:
        """What the rig's calibration depends on, as recorded at :meth:`create` (None for older sessions)."""
        return copy.deepcopy(self._manifest["rig"].get("fingerprint"))

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
            return tuple(record(e, i) for i, e in enumerate(self._manifest["captures"]))

    @property
    def state(self) -> dict:
        """A copy of the JSON state: the plan, its status and result, the saved edit, and free keys."""
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
                    return record(entry, i)
        raise SessionError(f"session {self.path} has no capture named {name!r}")

    def find_by_pattern(self, pattern_id: str) -> list[CaptureRecord]:
        """Every capture taken under pattern ``pattern_id``, oldest first (empty if none)."""
        with self._lock:
            return [record(e, i) for i, e in enumerate(self._manifest["captures"]) if e["pattern_id"] == pattern_id]

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
            :func:`engine.session.pattern_hash` of the projector pattern shown.
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
        check_name("capture", name)
        image = check_float_image("image", image, ndim=3)
        h, w = self.camera_resolution
        if image.shape != (h, w, 3):
            raise InputError(f"image must have shape {(h, w, 3)} (camera resolution, RGB), got {image.shape}")
        if not isinstance(pattern_id, str) or not pattern_id or len(pattern_id) > 256:
            raise InputError(f"pattern_id must be a non-empty string of at most 256 characters, got {pattern_id!r}")
        meta = to_json("meta", {} if meta is None else meta)
        if not isinstance(meta, dict):
            raise InputError(f"meta must be a dict, got {type(meta).__name__}")
        if saturated is not None:
            saturated = check_mask("saturated", saturated, (h, w))
        with self._writing():
            if self.has_capture(name):
                raise SessionError(f"session {self.path} already has a capture named {name!r}; "
                                   "captures are written once and never replaced")
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
                "time": now(),
            }
            try:
                entry["sha256"], entry["bytes"] = _captures.write(file, image, saturated, {**entry, "index": index})
            except FileExistsError:
                raise SessionError(
                    f"{file} already exists but is not in the manifest (an orphan from an interrupted run?); "
                    "it is never overwritten: call recover_orphans() or use another name"
                ) from None
            except InputError as exc:
                needed = _captures.size_bound(image.shape, saturated is not None)
                raise self._write_failed(f"capture {name!r}", exc, needed,
                                         "the captures finished before it are kept") from exc
            new = copy.deepcopy(self._manifest)
            new["captures"].append(entry)
            try:
                self._commit(new)
            except DiskFull as exc:
                self._orphans.append(rel)
                raise DiskFull(f"{exc} (capture {name!r} is complete on disk: the rerun adopts it)",
                               free=exc.free, needed=exc.needed) from exc
            except SessionError as exc:
                self._orphans.append(rel)
                raise SessionError(
                    f"capture {name!r} was written to {file} but the manifest could not be updated ({exc}); "
                    "the file is kept and recover_orphans() adopts it"
                ) from exc
            return record(entry, index)

    def add_frame(self, name: str, frame, *, pattern_id: str, meta: dict | None = None) -> CaptureRecord:
        """Store an :class:`engine.rig.Frame` (or anything with the same attributes) as a capture.

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
        rec = self.capture_record(name)
        return _captures.read(inside(self._root, self.path, rec.file, f"capture {name!r}"), rec)

    def read_capture(self, name: str) -> np.ndarray:
        """Read capture ``name`` as ``(H, W, 3) float32`` (see :meth:`load_capture`)."""
        return self.load_capture(name).image

    def recover_orphans(self) -> list[CaptureRecord]:
        """Adopt orphan capture files into the log, using the record each file carries.

        An orphan is adopted if it is a readable capture of this session's resolution whose
        embedded record names it and whose name is not already logged. An orphan that cannot
        be read (a write a full disk truncated) is moved to ``quarantine/`` — listed in
        :attr:`quarantined` — so the capture of that name is taken again. Other files (another
        program's images) stay in :attr:`orphans`; nothing is ever deleted.

        Returns
        -------
        list of CaptureRecord
            The adopted captures, in their original capture order.
        """
        with self._writing():
            found, kept = [], []
            for rel in self._orphans:
                entry, unreadable = self._inspect_orphan(rel)
                if entry is not None:
                    found.append((entry.pop("index", 0), rel, entry))
                elif unreadable is not None:
                    self._quarantine(rel, unreadable)
                else:
                    kept.append(rel)
            self._orphans = kept
            if not found:
                return []
            found.sort(key=lambda item: (item[0], item[2]["time"], item[2]["name"]))
            new = copy.deepcopy(self._manifest)
            start = len(new["captures"])
            for _, _, entry in found:
                new["captures"].append(entry)
            try:
                self._commit(new)
            except SessionError:
                self._orphans += [rel for _, rel, _ in found]
                raise
            return [record(e, start + i) for i, (_, _, e) in enumerate(found)]

    def _inspect_orphan(self, rel: str) -> tuple[dict | None, str | None]:
        try:
            file = inside(self._root, self.path, rel, "orphan")
        except SessionError:
            return None, None  # a symlink leading out: never read, never moved
        entry, unreadable = _captures.inspect_orphan(file, rel, self.camera_resolution)
        if entry is None or self.has_capture(entry["name"]):
            return None, unreadable
        candidate = copy.deepcopy(self._manifest)
        candidate["captures"].append({k: v for k, v in entry.items() if k != "index"})
        try:
            validate_manifest(candidate)
        except Invalid as exc:
            return None, f"its record does not fit the manifest ({exc})"
        return entry, None

    def _quarantine(self, rel: str, why: str) -> None:
        """Move an unreadable orphan to ``quarantine/`` (never deleted) and remember it in :attr:`quarantined`."""
        folder = writable(self._root, self.path, "quarantine", folder=True)
        name = PurePosixPath(rel).name
        target, n = folder / name, 1
        while target.exists():
            target, n = folder / f"{name}.{n}", n + 1
        try:
            os.rename(self.path / rel, target)
        except OSError as exc:
            raise SessionError(f"cannot move the unreadable {rel} aside into quarantine/: {exc}") from exc
        self.quarantined.append((rel, target.relative_to(self.path).as_posix(), why))

    # ------------------------------------------------------------------ state

    def update(self, **fields) -> dict:
        """Merge ``fields`` into the JSON state and persist it atomically.

        Known keys are checked against the schema (:data:`engine.session.schema.STATE`):
        ``plan``, ``status``, ``result``, ``edit`` (:mod:`engine.session.edit`), ``order``
        (a positive integer); other keys are free JSON. A value of ``None`` removes the key.
        numpy arrays and scalars become lists and numbers.

        Returns
        -------
        dict
            A copy of the new state.

        Raises
        ------
        InputError
            A value is not JSON-serialisable or does not fit the schema (the message names the
            field's path, e.g. ``state.plan.order``).
        SessionError
            The manifest could not be written (the state on disk is unchanged).
        """
        if fields.get("order") is not None:
            fields["order"] = check_order(fields["order"])
        values = to_json("state", fields)
        with self._writing():
            new = copy.deepcopy(self._manifest)
            for key, value in values.items():
                if value is None:
                    new["state"].pop(key, None)
                else:
                    new["state"][key] = value
            try:
                validate_state(new["state"])
            except Invalid as exc:
                raise InputError(str(exc)) from None
            self._commit(new)
            return copy.deepcopy(new["state"])

    # ------------------------------------------------------------------ masks

    def write_mask(self, name: str, mask: np.ndarray) -> None:
        """Store (or replace) a target mask as ``masks/<name>.png``.

        Parameters
        ----------
        name : str
            Mask name (a session file name; :func:`engine.session.edit.mask_name` derives one
            from a target's display name).
        mask : (H, W) bool
            Camera pixels.
        """
        check_name("mask", name)
        mask = check_mask("mask", mask, self.camera_resolution)
        rel = f"masks/{name}.png"
        with self._writing():
            file = writable(self._root, self.path, rel)
            try:
                imageio.write_image(file, mask.astype(np.uint8) * np.uint8(255))
            except InputError as exc:
                raise self._write_failed(f"mask {name!r}", exc, mask.size, "the session is as it was") from exc
            new = copy.deepcopy(self._manifest)
            new["masks"][name] = {"file": rel, "shape": list(mask.shape)}
            self._commit(new)

    def read_mask(self, name: str) -> np.ndarray:
        """Read mask ``name`` as ``(H, W) bool``; SessionError if unknown, missing or corrupt."""
        with self._lock:
            entry = self._manifest["masks"].get(name)
        if entry is None:
            raise SessionError(f"session {self.path} has no mask named {name!r}")
        file = inside(self._root, self.path, entry["file"], f"mask {name!r}")
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
        file = inside(self._root, self.path, entry["file"], f"calibration array {key!r}")
        try:
            return _arrays.read_array(file, tuple(entry["shape"]), np.dtype(entry["dtype"]))
        except (InputError, OSError, ValueError, EOFError) as exc:
            raise SessionError(f"calibration array {key!r}: cannot read {file}: {exc}") from exc

    def write_calibration(self, data: dict, arrays: dict[str, dict[str, np.ndarray]] | None = None, *,
                          keep: tuple[str, ...] = ()) -> None:
        """Replace the whole calibration: JSON ``data`` and arrays ``{group: {name: array}}``.

        Arrays of a previous calibration not in ``arrays`` are dropped (their files deleted
        after the manifest is updated), except those of the groups in ``keep`` (measurements
        of the scene stored beside the calibration, such as :mod:`engine.session.colour`'s).
        Array files are written first, the manifest once at the end.
        """
        data = to_json("calibration data", data)
        if not isinstance(data, dict):
            raise InputError(f"calibration data must be a dict, got {type(data).__name__}")
        self._write_arrays(arrays or {}, data=data, replace=True, keep=tuple(keep))

    def read_calibration(self, *, groups: tuple[str, ...] | None = None) -> tuple[dict, dict[str, dict[str, np.ndarray]]]:
        """Return ``(data, arrays)`` as given to :meth:`write_calibration` (and :meth:`write_array`).

        ``groups`` limits the arrays read to those groups (``()``: the JSON data alone).
        """
        with self._lock:
            data = copy.deepcopy(self._manifest["calibration"]["data"])
            keys = list(self._manifest["calibration"]["arrays"])
        arrays: dict[str, dict[str, np.ndarray]] = {}
        for key in keys:
            group, name = key.split("/", 1)
            if groups is not None and group not in groups:
                continue
            arrays.setdefault(group, {})[name] = self.read_array(group, name)
        return data, arrays

    def _write_arrays(self, arrays, *, data, replace: bool, keep: tuple[str, ...] = ()) -> None:
        if not isinstance(arrays, dict):
            raise InputError(f"arrays must be a dict {{group: {{name: array}}}}, got {type(arrays).__name__}")
        prepared = []
        for group, members in arrays.items():
            check_name("calibration group", group)
            if not isinstance(members, dict):
                raise InputError(f"arrays[{group!r}] must be a dict {{name: array}}, got {type(members).__name__}")
            for name, array in members.items():
                check_name("calibration array", name)
                array = _arrays.check_storable(f"calibration array {group}/{name}", array)
                prepared.append((group, name, array, f"calibration/{group}/{name}{_arrays.suffix_for(array)}"))
        with self._writing():
            written = {}
            for group, name, array, rel in prepared:
                folder = writable(self._root, self.path, f"calibration/{group}", folder=True)
                try:
                    _arrays.write_array(folder / Path(rel).name, array)
                except (InputError, OSError) as exc:
                    raise self._write_failed(f"calibration array {group}/{name}", exc, array.nbytes,
                                             "the captures are kept") from exc
                written[f"{group}/{name}"] = {"file": rel, "shape": list(array.shape), "dtype": array.dtype.str}
            new = copy.deepcopy(self._manifest)
            before = {e["file"] for e in new["calibration"]["arrays"].values()}
            if replace:
                new["calibration"]["arrays"] = {key: entry for key, entry in new["calibration"]["arrays"].items()
                                                if key.split("/", 1)[0] in keep} | written
            else:
                new["calibration"]["arrays"].update(written)
            if data is not None:
                new["calibration"]["data"] = data
            self._commit(new)
            # files no longer referenced (dropped arrays, or an array that moved between .npy and .exr)
            for rel in before - {e["file"] for e in new["calibration"]["arrays"].values()}:
                try:
                    os.unlink(inside(self._root, self.path, rel, "old calibration array"))
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
        check_name("cache key", key)
        clean = _cache.check_entry(arrays)
        with self._writing():
            folder = writable(self._root, self.path, "cache", folder=True)
            try:
                _cache.write_entry(folder / f"{key}.npz", clean)
            except OSError as exc:
                raise self._write_failed(f"cache entry {key!r}", exc, sum(a.nbytes for a in clean.values()),
                                         "the captures are kept") from exc

    def cache_get(self, key: str) -> dict[str, np.ndarray] | None:
        """Return the arrays stored under ``key``, or None if absent.

        A corrupt or unsafe entry (unreadable, not an npz, needing pickle, a symlink leading
        outside the folder) counts as missing and is deleted.
        """
        check_name("cache key", key)
        file = self.path / "cache" / f"{key}.npz"
        if not file.exists() and not file.is_symlink():
            return None
        try:
            inside(self._root, self.path, f"cache/{key}.npz", "cache entry")
        except SessionError:
            file.unlink()
            return None
        return _cache.read_entry(file)

    def cache_keys(self) -> list[str]:
        """Keys of the cache entries present, sorted."""
        folder = self.path / "cache"
        if not folder.is_dir() or folder.is_symlink():
            return []
        return sorted(p.stem for p in folder.glob("*.npz") if p.is_file() and not p.is_symlink())

    def cache_discard(self, key: str) -> None:
        """Delete the cache entry ``key`` if there is one."""
        check_name("cache key", key)
        with self._writing():
            try:
                (self.path / "cache" / f"{key}.npz").unlink()
            except FileNotFoundError:
                pass

    def cache_clear(self) -> None:
        """Delete every cache entry."""
        folder = self.path / "cache"
        if not folder.is_dir() or folder.is_symlink():
            return
        with self._writing():
            for child in folder.iterdir():
                if child.is_file() or child.is_symlink():
                    child.unlink()
                elif child.is_dir():
                    shutil.rmtree(child)

    # ------------------------------------------------------------------ internals

    @contextmanager
    def writing(self, purpose: str | None = None) -> Iterator[Session]:
        """Hold the session's advisory lock for a whole run of writes (e.g. a calibration or a capture).

        Every write takes the lock on its own; holding it across a run keeps other processes
        from writing in between (a second ``albedit capture`` is refused, naming this one).
        Re-entrant, and shared by every thread and Session object of this process.

        Parameters
        ----------
        purpose : str, optional
            What is being done, shown to a refused writer (default: the command line).

        Raises
        ------
        SessionError
            Another process holds the lock, or the folder is read-only (see :mod:`engine.session.lock`).
        """
        with _lock.hold(self._root, purpose):
            with self._lock:
                self._refresh()
            yield self

    @contextmanager
    def _writing(self) -> Iterator[None]:
        """The lock of one change: held, the manifest re-read if another writer changed it."""
        with _lock.hold(self._root), self._lock:
            self._refresh()
            yield

    def _refresh(self) -> None:
        """Read the manifest again if it changed on disk since this object last read or wrote it."""
        signature = _signature(self.path)
        if signature != self._signature:
            self._manifest = read_manifest(self._root, self.path)
            self._signature = signature

    def _commit(self, manifest: dict) -> None:
        """Write ``manifest`` atomically (read back before it replaces the old one), then make it the state."""
        text = dumps(manifest)

        def verify(temp: Path) -> None:
            if temp.read_text(encoding="utf-8") != text:
                raise OSError(errno.EIO, "the manifest written does not read back")

        try:
            imageio.atomic_write(self.path / MANIFEST, lambda temp: temp.write_text(text, encoding="utf-8"),
                                 verify=verify)
        except OSError as exc:
            raise self._write_failed(MANIFEST, exc, len(text.encode()),
                                     "the previous manifest is intact") from exc
        self._manifest = manifest
        self._signature = _signature(self.path)

    def _write_failed(self, what: str, exc: BaseException, needed: int, kept: str) -> SessionError:
        """The error of a failed write: a full disk says how much space is needed and that a rerun resumes."""
        return write_failed(self.path, what, exc, needed, kept)


def _signature(path: Path) -> tuple[int, int, int] | None:
    try:
        st = os.stat(Path(path) / MANIFEST)
    except OSError:
        return None
    return st.st_ino, st.st_mtime_ns, st.st_size


def _new_manifest(rig_name: str, camera, projector, metadata: dict, fingerprint: dict | None) -> dict:
    rig = {"name": rig_name, "camera_resolution": list(camera), "projector_resolution": list(projector)}
    if fingerprint is not None:
        rig["fingerprint"] = fingerprint
    return {
        "format": FORMAT,
        "schema_version": SCHEMA_VERSION,
        "created": now(),
        "rig": rig,
        "metadata": metadata,
        "state": {},
        "masks": {},
        "calibration": {"data": {}, "arrays": {}},
        "captures": [],
    }
