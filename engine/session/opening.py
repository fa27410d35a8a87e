"""What :meth:`engine.session.Session.open` checks before it trusts a folder.

The manifest is read with a size limit and strict JSON, then validated against the schema;
every path it names must stay inside the folder and be the path the session would have
written; every listed capture must be on disk with its logged size and header. Capture files
the manifest does not list are reported as orphans.
"""

from __future__ import annotations

from pathlib import Path

from engine.errors import SessionError
from engine.imageio import is_temp_name
from engine.session import captures as _captures
from engine.session.jsonio import loads
from engine.session.lock import LOCK_FILE
from engine.session.paths import FOLDERS, MANIFEST, inside
from engine.session.schema import validate_manifest
from engine.session.spec import Invalid

__all__ = ["MAX_MANIFEST_BYTES", "check_folder", "is_skeleton", "read_manifest", "remove_temporaries"]

MAX_MANIFEST_BYTES = 64 * 1024 * 1024


def read_manifest(root: Path, path: Path) -> dict:
    """Read and validate ``path/manifest.json``.

    Raises
    ------
    SessionError
        Missing, a symlink out of the folder, too large, not strict JSON, or a field that does
        not fit the schema; the message names the file and the field's path.
    """
    manifest_path = path / MANIFEST
    if not manifest_path.exists() and not manifest_path.is_symlink():
        raise SessionError(f"{path} is not a session: {MANIFEST} is missing")
    inside(root, path, MANIFEST, "the manifest")
    if not manifest_path.is_file():
        raise SessionError(f"{manifest_path} is not a regular file")
    if manifest_path.stat().st_size > MAX_MANIFEST_BYTES:
        raise SessionError(f"{manifest_path} is larger than {MAX_MANIFEST_BYTES} bytes; refusing to load it")
    try:
        manifest = loads(manifest_path.read_bytes().decode("utf-8"))
    except (ValueError, UnicodeDecodeError, RecursionError) as exc:
        raise SessionError(f"{manifest_path} is corrupt (not valid JSON): {exc}") from exc
    except OSError as exc:
        raise SessionError(f"cannot read {manifest_path}: {exc}") from exc
    try:
        validate_manifest(manifest)
    except Invalid as exc:
        raise SessionError(f"{manifest_path}: {exc}") from None
    return manifest


def check_folder(root: Path, path: Path, manifest: dict, *, verify: bool) -> list[str]:
    """Check every path and capture file the manifest names; return the orphan captures.

    Raises
    ------
    SessionError
        A path leads outside the folder or is not the one the session writes for that entry,
        or a listed capture is missing, of another size or header (or checksum, with
        ``verify``).
    """
    for folder in FOLDERS:
        if (path / folder).exists() or (path / folder).is_symlink():
            inside(root, path, folder, f"the {folder} folder")
    camera = tuple(manifest["rig"]["camera_resolution"])
    referenced = set()
    for i, entry in enumerate(manifest["captures"]):
        where = f"capture {entry['name']!r} (captures[{i}])"
        file = inside(root, path, entry["file"], where)
        _expect(where, entry["file"], f"captures/{entry['name']}.exr")
        referenced.add(entry["file"])
        _captures.check_file(file, entry, camera, where, verify=verify)
    for name, entry in manifest["masks"].items():
        inside(root, path, entry["file"], f"mask {name!r}")
        _expect(f"mask {name!r}", entry["file"], f"masks/{name}.png")
    for key, entry in manifest["calibration"]["arrays"].items():
        inside(root, path, entry["file"], f"calibration array {key!r}")
        _expect(f"calibration array {key!r}", entry["file"], f"calibration/{key}.exr", f"calibration/{key}.npy")
    orphans = []
    captures_dir = path / "captures"
    if captures_dir.is_dir():
        for child in sorted(captures_dir.iterdir()):
            rel = f"captures/{child.name}"
            if child.name.startswith(".") or rel in referenced or child.is_dir():
                continue  # temporary files of interrupted writes are not captures
            orphans.append(rel)
    return orphans


def _expect(where: str, rel: str, *allowed: str) -> None:
    if rel not in allowed:
        raise SessionError(f"{where}: its file must be {' or '.join(map(repr, allowed))}, the manifest says {rel!r}")


def is_skeleton(path: Path) -> bool:
    """Whether ``path`` holds nothing but what an interrupted :meth:`Session.create` leaves.

    That is: empty sub-folders of a session, its lock file and temporary files of a manifest
    write that never finished. Anything else (a photograph, a capture, another program's
    files) makes it a folder that is not ours to fill.
    """
    for child in path.iterdir():
        if child.is_symlink():
            return False
        if child.name in FOLDERS and child.is_dir():
            if any(child.iterdir()):
                return False
        elif not (child.is_file() and (child.name == LOCK_FILE or is_temp_name(child.name))):
            return False
    return True


def remove_temporaries(path: Path) -> list[str]:
    """Delete the temporary files killed writes left in the session folder; returns their relative paths.

    Only names :func:`engine.imageio.atomic_write` gives its temporary files are touched, in
    the folder, its sub-folders and the calibration groups (never through a symlink). Call it
    with the session's lock held, so no live write's temporary file is taken.
    """
    folders = [path] + [path / f for f in FOLDERS]
    calibration = path / "calibration"
    if calibration.is_dir() and not calibration.is_symlink():
        folders += [g for g in calibration.iterdir() if g.is_dir() and not g.is_symlink()]
    removed = []
    for folder in folders:
        if not folder.is_dir() or folder.is_symlink():
            continue
        for child in folder.iterdir():
            if is_temp_name(child.name) and child.is_file() and not child.is_symlink():
                try:
                    child.unlink()
                except OSError:
                    continue
                removed.append(child.relative_to(path).as_posix())
    return sorted(removed)
