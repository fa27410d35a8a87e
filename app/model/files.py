"""Documents on disk: open and save sessions with their edits, export images. Qt-free.

A document saved by the app lives in a session folder (:mod:`engine.session`). Its edit is
kept in the session's JSON state under ``"edits"``::

    {"version": 1, "photograph": "<capture name>",
     "targets": [{"name": ..., "mask": "<mask name>", "kappa": [r, g, b], "colour": [r, g, b]}, ...],
     "current": "<target name>",
     "acquisition": {"key": ..., "cascade": [names], "kappas": [[...]], "masks": [mask names],
                     "constraint": ..., "unreached_light": ..., "denoise": radius}}

Masks are stored under content-addressed names (``edit-<sha>``) and the decomposition in the
session cache under the acquisition's key (its noise-reduced version, if any, under
``<key>-denoise<radius>``), all *before* the state is rewritten, so a save
that fails half way leaves the previous save intact ("nothing lost").

Which capture is the photograph: ``edits.photograph``, else ``state["photograph"]``, else a
capture named ``"photograph"``, else the last capture whose metadata says ``kind:
"photograph"`` (what ``engine.workflow.run_capture`` writes), else the first capture. A mask
named ``"unreachable"`` marks camera pixels the projector cannot light; without one, they are
taken from the session's calibration (:func:`unreachable_pixels`).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from app.model.document import Document
from engine import imageio
from engine.decompose import Decomposition
from engine.errors import InputError, SessionError
from engine.progress import checkpoint, report
from engine.recolor import recolor
from engine.session import Session

EDITS_VERSION = 1
PHOTOGRAPH = "photograph"
UNREACHABLE = "unreachable"

#: Export choices: extension → allowed dtypes (first is the default).
EXPORT_FORMATS = {
    ".exr": ("half", "float"),
    ".tif": ("uint16", "float"),
    ".tiff": ("uint16", "float"),
    ".png": ("uint8",),
}


# ----------------------------------------------------------------------------- opening


def open_document(path, *, history=None) -> tuple[Document, Session | None, list[str]]:
    """Open a session folder or a single image as a document.

    Parameters
    ----------
    path : str or Path
        A session folder (restores targets, κ and acquisition) or an image file (EXR, TIFF,
        PNG, JPEG, camera RAW; linear radiance is assumed as :func:`engine.imageio.read_image` says).
    history : History-like, optional
        Undo stack for the new document.

    Returns
    -------
    document, session (None for an image), warnings (things that could not be restored)

    Raises
    ------
    SessionError, InputError
        Unreadable session or image; the message names the file.
    """
    path = Path(path)
    if path.is_dir():
        session = Session.open(path)
        doc, warnings = _document_from_session(session, history=history)
        return doc, session, warnings
    image = imageio.read_image(path)
    if image.ndim != 3 or image.shape[2] < 3:
        raise InputError(f"{path}: an RGB image is needed, got shape {image.shape}")
    doc = Document(np.ascontiguousarray(image[..., :3]), history=history, source=str(path))
    return doc, None, []


def unreachable_pixels(calibration) -> np.ndarray:
    """Camera pixels the projector does not light at all (shadow, outside its frame).

    Pixels whose Gray code merely had low contrast are not included: acquisition
    interpolates their correspondence from the neighbours (``engine.acquire.prepare_target``).
    """
    from engine.calibrate.graycode import PixelStatus

    status = np.asarray(calibration.correspondence.status)
    return (status == PixelStatus.UNLIT) | (status == PixelStatus.OUT_OF_RANGE)


def _calibrated_unreachable(session: Session) -> np.ndarray | None:
    from engine.workflow import load_calibration

    try:
        return unreachable_pixels(load_calibration(session))
    except (SessionError, InputError, KeyError, ValueError):
        return None  # no (usable) calibration: nothing is known to be unreachable


def _photograph_name(session: Session, edits: dict) -> str:
    records = session.captures
    names = [c.name for c in records]
    if not names:
        raise SessionError(f"session {session.path} has no capture: there is no photograph to edit")
    for candidate in (edits.get("photograph"), session.state.get("photograph"), PHOTOGRAPH):
        if isinstance(candidate, str) and candidate in names:
            return candidate
    kinds = [c.name for c in records if isinstance(c.meta, dict) and c.meta.get("kind") == "photograph"]
    return kinds[-1] if kinds else names[0]


def _document_from_session(session: Session, *, history=None) -> tuple[Document, list[str]]:
    state = session.state
    edits = state.get("edits") if isinstance(state.get("edits"), dict) else {}
    photo = session.read_capture(_photograph_name(session, edits))
    unreachable = session.read_mask(UNREACHABLE) if UNREACHABLE in session.masks else _calibrated_unreachable(session)
    doc = Document(photo, unreachable=unreachable, history=history, source=session.rig_name)
    warnings: list[str] = []
    version = edits.get("version", EDITS_VERSION)
    if version > EDITS_VERSION:
        raise SessionError(f"{session.path}: edits version {version} is newer than this app ({EDITS_VERSION})")
    for entry in edits.get("targets", []):
        try:
            mask = session.read_mask(entry["mask"])
            t = doc.add_target(str(entry["name"]), mask, kappa=entry.get("kappa", 1.0))
            if "colour" in entry:
                t.colour = tuple(int(c) for c in entry["colour"])[:3]
        except (KeyError, TypeError, InputError, SessionError) as exc:
            warnings.append(f"target {entry.get('name', '?')!r} could not be restored: {exc}")
    acq = edits.get("acquisition")
    plan = state.get("plan")
    if isinstance(acq, dict):
        try:
            warnings += _restore_acquisition(doc, session, acq)
        except (KeyError, TypeError, ValueError, InputError, SessionError) as exc:
            warnings.append(f"the acquisition could not be restored ({exc}); acquire again to recolor")
    elif not edits and isinstance(plan, dict) and state.get("status") == "captured":
        try:
            _restore_plan(doc, session, plan)
        except (KeyError, TypeError, ValueError, InputError, SessionError) as exc:
            warnings.append(f"the captured plan could not be restored ({exc})")
    current = edits.get("current")
    for t in doc.targets:
        if t.name == current:
            doc.set_current(t.uid)
    doc.history.clear()
    doc.mark_saved()
    return doc, warnings


def _decomposition_from_cache(session: Session, key: str, acq: dict | None = None) -> Decomposition:
    arrays = session.cache_get(key)
    if arrays is None:
        raise SessionError(f"its decomposition {key!r} is missing from the session cache")
    if "flags" in arrays:  # the layout engine.workflow.cache_decomposition writes
        constraint = bytes(arrays["constraint"]).decode().strip()
        unreached_light = bool(arrays["flags"][0])
    else:
        constraint = str((acq or {}).get("constraint", "ordered"))
        unreached_light = bool((acq or {}).get("unreached_light", True))
    return Decomposition(arrays["components"], arrays["unreached"], arrays["target"].astype(bool),
                         constraint, unreached_light, arrays.get("residual"))


def _restore_acquisition(doc: Document, session: Session, acq: dict) -> list[str]:
    """Set the saved acquisition (and its noise reduction) on ``doc``; returns warnings."""
    key = str(acq["key"])
    d = _decomposition_from_cache(session, key, acq)
    cascade = [doc.by_name(n).uid for n in acq["cascade"]]
    doc.set_acquisition(cascade, d, key=key)
    radius = int(acq.get("denoise", 0))
    if radius <= 0:
        return []
    try:
        doc.set_noise_reduction(radius, _decomposition_from_cache(session, _denoised_key(key, radius), acq))
    except (KeyError, TypeError, ValueError, InputError, SessionError) as exc:
        return [f"noise reduction (radius {radius}) could not be restored ({exc}); apply it again"]
    return []


def _denoised_key(key: str, radius: int) -> str:
    return f"{key}-denoise{radius}"


def _restore_plan(doc: Document, session: Session, plan: dict) -> None:
    """A session captured by ``albedit capture`` (engine.workflow): its targets, fixed κ, decomposition."""
    from engine.workflow import plan_key

    names = [str(n) for n in plan["targets"]]
    fixed = list(plan.get("fixed_kappa", []))
    for i, name in enumerate(names):
        kappa = fixed[i] if i < len(fixed) else 1.0
        doc.add_target(name, session.read_mask(name), kappa=kappa)
    key = plan_key(session)
    d = _decomposition_from_cache(session, key)
    doc.set_acquisition([doc.by_name(n).uid for n in names], d, key=key)


# ----------------------------------------------------------------------------- saving


def create_session(path, document: Document, *, rig_name: str | None = None,
                   projector_resolution: tuple[int, int] | None = None, mark_saved: bool = True) -> Session:
    """Make a new session folder holding the document's photograph, then save the edit into it.

    Parameters
    ----------
    path : str or Path
        A folder that does not exist yet, or an empty one.
    document : Document
    rig_name : str, optional
        Default: the document's source (e.g. ``"virtual:cornell"``), else ``"image"``.
    projector_resolution : (Hp, Wp), optional
        Default: the camera resolution (unknown for a plain image).
    """
    session = Session.create(
        path,
        rig_name=rig_name or (document.source if ":" in document.source else "image"),
        camera_resolution=document.shape,
        projector_resolution=projector_resolution or document.shape,
        metadata={"source": document.source},
    )
    session.add_capture(PHOTOGRAPH, document.photograph, pattern_id="photograph", meta={"source": document.source})
    if document.unreachable is not None:
        session.write_mask(UNREACHABLE, document.unreachable)
    save_document(document, session, mark_saved=mark_saved)
    return session


def save_document(document: Document, session: Session, *, mark_saved: bool = True) -> None:
    """Write the edit (targets, masks, κ, acquisition) into ``session`` and mark the document saved.

    Call it where the document is edited (the UI thread), or with ``mark_saved=False`` from a
    worker while editing is suspended, then call ``document.mark_saved()`` back on the UI thread.

    Masks and the decomposition are written first under new names, the state last (one
    atomic manifest update): if anything fails, the previous save is still complete.

    Raises
    ------
    SessionError
        A write failed (the document stays marked unsaved).
    """
    if tuple(session.camera_resolution) != tuple(document.shape):
        raise SessionError(f"session {session.path} is {session.camera_resolution}, the document {document.shape}")
    existing = set(session.masks)
    targets = []
    for t in document.targets:
        name = _mask_name(t.mask)
        if name not in existing:
            session.write_mask(name, t.mask)
            existing.add(name)
        targets.append({"name": t.name, "mask": name, "kappa": [float(k) for k in t.kappa],
                        "colour": [int(c) for c in t.colour]})
    edits = {
        "version": EDITS_VERSION,
        "photograph": _photograph_name(session, session.state.get("edits") or {}),
        "targets": targets,
        "current": document.target(document.current).name if document.current != -1 else None,
    }
    acq = document.acquisition
    if acq is not None:
        d = acq.raw
        cached = {acq.key: d}
        if acq.denoise:
            cached[_denoised_key(acq.key, acq.denoise)] = acq.decomposition
        present = set(session.cache_keys())
        for key, decomposition in cached.items():
            if key not in present:
                session.cache_put(key, _cache_arrays(decomposition))
        edits["acquisition"] = {
            "key": acq.key,
            "cascade": [document.target(u).name for u in acq.cascade],
            "kappas": [[float(k) for k in kap] for kap in acq.kappas],
            "constraint": str(d.constraint),
            "unreached_light": bool(d.unreached_light),
            "denoise": int(acq.denoise),
        }
    session.update(edits=edits)
    if acq is not None:  # noise-reduced copies of other radii are no longer referenced (and are big)
        keep = _denoised_key(acq.key, acq.denoise) if acq.denoise else None
        for key in present:
            if key.startswith(f"{acq.key}-denoise") and key != keep:
                session.cache_discard(key)
    if mark_saved:
        document.mark_saved()


def _cache_arrays(d: Decomposition) -> dict:
    """The cache layout of engine.workflow.cache_decomposition, so either side can read it."""
    arrays = {
        "components": d.components,
        "unreached": d.unreached,
        "target": d.target,
        "flags": np.array([d.unreached_light], bool),
        "constraint": np.frombuffer(str(d.constraint).encode().ljust(16), np.uint8),
    }
    if d.residual is not None:
        arrays["residual"] = d.residual
    return arrays


def _mask_name(mask: np.ndarray) -> str:
    digest = hashlib.sha256(np.packbits(mask).tobytes() + str(mask.shape).encode()).hexdigest()
    return f"edit-{digest[:16]}"


# ----------------------------------------------------------------------------- export


def edit_metadata(document: Document) -> dict:
    """The edit as JSON-able metadata: targets (name, κ, pixels, cascade position), order, source."""
    acq = document.acquisition
    cascade = [] if acq is None else [document.target(u).name for u in acq.cascade]
    d = document.decomposition
    return {
        "edit": {
            "source": document.source,
            "targets": [
                {"name": t.name, "kappa": [float(k) for k in t.kappa], "pixels": int(np.count_nonzero(t.mask)),
                 "cascade_position": i + 1, "acquired": t.name in cascade}
                for i, t in enumerate(document.targets)
            ],
            "cascade": cascade,
            "kappa": [float(k) for k in document.recolor_kappa()],
            "order": None if d is None else int(d.order),
            "constraint": None if d is None else str(d.constraint),
            "denoise": 0 if acq is None else int(acq.denoise),
        }
    }


def export_image(document: Document, path, *, dtype: str | None = None, exposure: float = 0.0,
                 clip: bool = False, progress=None, should_stop=None) -> Path:
    """Write the full-resolution recolored image, with the edit in the file's metadata.

    Parameters
    ----------
    document : Document
        Must hold an acquisition (a decomposition to recolor).
    path : str or Path
        ``.exr`` (half or float, linear), ``.tif`` (uint16 linear or float), ``.png``
        (8-bit sRGB through the exposure, for sharing).
    dtype : str, optional
        See :data:`EXPORT_FORMATS`; default the first for the extension.
    exposure : float
        Stops applied before writing integer files (uint16 TIFF, PNG); float files stay in
        the photograph's linear units.
    clip : bool
        Allow a uint16 TIFF to clip values above 1 after exposure (counted in the metadata).
        Without it such an export is refused.
    progress, should_stop
        :mod:`engine.progress` conventions.

    Returns
    -------
    Path

    Raises
    ------
    InputError
        Nothing acquired, unsupported format/dtype, values out of range for uint16.
    Cancelled
        Stopped before the write started (nothing written).
    """
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in EXPORT_FORMATS:
        raise InputError(f"{path}: export as one of {sorted(EXPORT_FORMATS)}, got {path.suffix!r}")
    dtype = dtype or EXPORT_FORMATS[ext][0]
    if dtype not in EXPORT_FORMATS[ext]:
        raise InputError(f"{path}: dtype for {ext} must be one of {list(EXPORT_FORMATS[ext])}, got {dtype!r}")
    if document.decomposition is None:
        raise InputError("nothing to export yet: acquire the targets first (the recolored image needs a decomposition)")
    if not np.isfinite(exposure):
        raise InputError(f"exposure must be finite, got {exposure!r}")
    meta = edit_metadata(document)
    report(progress, 0, 3, "recoloring at full resolution")
    image = recolor(document.decomposition, document.recolor_kappa())
    checkpoint(should_stop, "export")
    report(progress, 1, 3, "converting")
    if ext == ".png":
        pixels = imageio.to_display(image, exposure=exposure)
        meta["edit"]["display"] = {"exposure": float(exposure), "transfer": "sRGB", "clipped": True}
    elif dtype == "uint16":
        pixels = image * np.float32(2.0**exposure)
        over = int(np.count_nonzero((pixels > 1.0) | (pixels < 0.0)))
        if over and not clip:
            raise InputError(
                f"{over} values fall outside [0, 1] after an exposure of {exposure:+g} stops and a 16-bit TIFF "
                "cannot hold them: lower the exposure, export float, or allow clipping"
            )
        pixels = np.clip(pixels, 0.0, 1.0)
        meta["edit"]["linear"] = {"exposure": float(exposure), "clipped_values": over}
    else:
        pixels = image
        meta["edit"]["linear"] = {"exposure": 0.0}
    checkpoint(should_stop, "export")
    report(progress, 2, 3, f"writing {path.name}")
    imageio.write_image(path, pixels, dtype=dtype, metadata=meta)
    report(progress, 3, 3, "exported")
    return path

