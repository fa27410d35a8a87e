"""The on-disk session: one folder holding everything an edit was measured and decided from.

Layout (all paths relative to the session folder)::

    manifest.json        schema version, rig, calibration, masks, state (acquisition plan,
                         status and result, the saved edit), capture log
    captures/<name>.exr  one float EXR per capture, written once, read-only, never rewritten
    masks/<name>.png     target masks, 8-bit grey PNG (0 / 255)
    calibration/<group>/<name>.exr | .npy
                         calibration arrays (EXR for finite float32 images, .npy for the rest)
    cache/<key>.npz      disposable results (decompositions); corrupt entries count as missing
    quarantine/          unreadable capture files set aside (never deleted)
    session.lock         the advisory lock; names its holder while held

Guarantees:

- every write is atomic (temporary file in the same folder, then rename), and the manifest is
  rewritten after each capture, so a process killed at any moment leaves the previous
  manifest intact and loses at most the capture being written — which is kept on disk: a
  capture file not listed in the manifest is an *orphan*, reported by :attr:`Session.orphans`
  and adopted by :meth:`Session.recover_orphans` (each capture file carries its own record);
- captures are created with mode 0o444 through a hard link that cannot replace an existing
  file, and are never opened for writing again;
- every file is read back and compared with what was written before it gets its name, so a
  write a full disk truncated never becomes part of the session; a full disk raises
  :class:`engine.errors.DiskFull` saying how much space is needed and that a rerun resumes;
  unreadable orphans are moved to ``quarantine/`` and taken again;
- every write holds the session's advisory lock (:mod:`~engine.session.lock`) and re-reads the
  manifest another writer committed; a second writer is told who holds the lock;
- :meth:`Session.open` refuses a missing or corrupt manifest, an unknown or newer schema
  version, a field that does not fit the schema (:mod:`engine.session.schema`, naming the
  field's path), a listed capture that is missing, corrupt or another capture's file (each
  carries its own record), and any path that is absolute or leads outside the folder (``..``
  or a symlink), changing nothing on disk; on success it only removes the temporary files of
  killed writes, when no one writes the session. It never unpickles
  (``np.load(allow_pickle=False)``) or executes anything from the folder.

The package: :mod:`~engine.session.folder` (the :class:`Session` front door),
:mod:`~engine.session.schema` and :mod:`~engine.session.spec` (the manifest schema),
:mod:`~engine.session.opening` (the checks on open), :mod:`~engine.session.paths` (names and
safe paths), :mod:`~engine.session.records` and :mod:`~engine.session.captures` (capture
records and files), :mod:`~engine.session.arrays` (calibration arrays),
:mod:`~engine.session.cache` (the disposable cache), :mod:`~engine.session.lock` (the
advisory lock), :mod:`~engine.session.space` (full disks), :mod:`~engine.session.edit` (the
saved edit), :mod:`~engine.session.jsonio` (plain JSON in and out).
"""

from engine.session.folder import Session
from engine.session.records import CaptureRecord, LoadedCapture, pattern_hash
from engine.session.schema import SCHEMA_VERSION

__all__ = ["SCHEMA_VERSION", "CaptureRecord", "LoadedCapture", "Session", "pattern_hash"]
