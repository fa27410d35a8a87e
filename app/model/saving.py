"""Where a document is saved and acquired: its session, or a new session folder. Qt-free.

Saving itself (what a session holds of an edit) is :mod:`app.model.files`; this module decides
*where*: Save writes into the document's session, Save As makes a new session folder — a copy
of the current session (its captures and calibration stay with the edit) or, for a plain
photograph, a new session holding the photograph. :func:`branch_session` starts a new session
folder for a new acquisition plan when the document's session holds another one (a session
holds one plan; the old one is never changed).
"""

from __future__ import annotations

import shutil
from pathlib import Path

from app.model import files
from app.model.document import Document
from engine.errors import InputError
from engine.session import Session
from engine.workflow import adopt_calibration, load_calibration, open_session_for_rig, photograph_name


def save_into(document: Document, session: Session) -> Session:
    """Write the edit into ``session`` (call with editing suspended; mark the document saved after)."""
    files.save_document(document, session, mark_saved=False)
    return session


def save_as(document: Document, path, *, source: Session | None = None,
            projector_resolution: tuple[int, int] | None = None) -> Session:
    """Save the edit into a new session folder ``path`` and return that session.

    Parameters
    ----------
    document : Document
    path : str or Path
        A folder that does not exist yet, or an empty one.
    source : Session, optional
        The document's current session: copied first (captures, calibration, cache), never modified.
    projector_resolution : (Hp, Wp), optional
        For a new session of a plain photograph (default: the camera resolution).

    Raises
    ------
    InputError
        ``path`` exists and is not empty, or is inside ``source``.
    """
    path = Path(path)
    if path.exists() and any(path.iterdir()):
        raise InputError(f"{path} exists and is not empty: choose a new folder name")
    if source is None:
        return files.create_session(path, document, projector_resolution=projector_resolution, mark_saved=False)
    src = Path(source.path).resolve()
    if path.resolve().is_relative_to(src):
        raise InputError(f"{path} is inside the session {src}: choose a folder outside it")
    shutil.copytree(src, path, dirs_exist_ok=True)
    target = Session.open(path)
    files.save_document(document, target, mark_saved=False)
    return target


def branch_session(source: Session, path, rig, *, calibration=None) -> Session:
    """A new session folder ``path`` for acquiring another plan with ``rig``, from ``source``.

    The calibration is ``calibration`` (one made since, e.g. by the wizard) or ``source``'s; the
    photograph capture is copied when ``source`` was taken by this rig set-up (the acquisition
    then reuses it instead of retaking it). ``source`` is never modified.

    Raises
    ------
    InputError
        ``path`` exists and is not empty.
    SessionError, InputError
        The calibration does not fit ``rig`` (from :func:`engine.workflow.preflight` later), or a write failed.
    """
    path = Path(path)
    if path.exists() and any(path.iterdir()):
        raise InputError(f"{path} exists and is not empty: choose a new folder name")
    new = open_session_for_rig(path, rig)
    adopt_calibration(new, calibration if calibration is not None else load_calibration(source))
    same_setup = (tuple(source.camera_resolution) == tuple(new.camera_resolution)
                  and source.rig_name == new.rig_name and source.fingerprint == new.fingerprint)
    if same_setup and source.captures:
        name = photograph_name(source)
        record, loaded = source.capture_record(name), source.load_capture(name)
        new.add_capture(name, loaded.image, pattern_id=record.pattern_id, meta=record.meta, saturated=loaded.saturated)
    return new
