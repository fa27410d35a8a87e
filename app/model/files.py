"""Documents on disk: open and save sessions with their edits, export images. Qt-free.

A document saved by the app lives in a session folder (:mod:`engine.session`). Its edit is
the engine's saved edit (:mod:`engine.session.edit`, read by :func:`engine.workflow.saved_edit`,
which also reads what older versions wrote): the targets with their display names, masks, κ
and overlay colours, the acquired cascade, its decomposition's cache key and its noise reduction.

Masks are stored under names derived from each target's name and pixels
(:func:`engine.session.edit.mask_name`) and the decomposition in the session cache under the
acquisition's key (its noise-reduced version, if any, under
:func:`engine.workflow.denoised_key`), all *before* the state is rewritten, so a save that
fails half way leaves the previous save intact ("nothing lost").

Which capture is the photograph: :func:`engine.workflow.photograph_name`. A mask named
``"unreachable"`` marks camera pixels the projector cannot light; without one, they are taken
from the session's calibration (:func:`unlit_pixels`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from app.model.document import Document
from engine import imageio
from engine.errors import InputError, SessionError
from engine.progress import checkpoint, report
from engine.recolor import recolor
from engine.session import Session
from engine.session.edit import METADATA_KEY, Edit, EditAcquisition, EditTarget, export_metadata, mask_digest, mask_name
from engine.trust import recolor_trusted
from engine.workflow import (
    cached_decomposition,
    denoised_key,
    interrupted_edit,
    load_calibration,
    load_decomposition,
    load_trusted,
    photograph_name,
    save_edit,
    saved_edit,
)

PHOTOGRAPH = "photograph"
UNREACHABLE = "unreachable"
#: How an exported image was recolored (its metadata's ``recolor``).
NOISE_AWARE, PLAIN = "noise-aware", "plain"

class NeedsClipping(InputError):
    """An integer export would have to clip values outside [0, 1]; exporting again with ``clip=True`` allows it.

    Attributes
    ----------
    values : int
        How many values fall outside [0, 1].
    """

    def __init__(self, message: str, *, values: int) -> None:
        super().__init__(message)
        self.values = values


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
    if image.ndim == 2:
        image = image[..., None]
    if image.ndim != 3 or image.shape[2] not in (1, 2, 3, 4):
        raise InputError(f"{path}: a grey or RGB image is needed, got shape {image.shape}")
    if image.shape[2] < 3:  # grey (and alpha): the same light in every channel
        image = np.repeat(image[..., :1], 3, axis=2)
    doc = Document(np.ascontiguousarray(image[..., :3]), history=history, source=str(path))
    return doc, None, []


def unlit_pixels(calibration) -> np.ndarray:
    """Camera pixels the projector does not light at all (shadow, outside its frame).

    Pixels whose Gray code merely had low contrast are not included: acquisition
    interpolates their correspondence from the neighbours (``engine.acquire.prepare_target``).
    """
    from engine.calibrate.graycode import PixelStatus

    status = np.asarray(calibration.correspondence.status)
    return (status == PixelStatus.UNLIT) | (status == PixelStatus.OUT_OF_RANGE)


def _calibrated_unreachable(session: Session) -> np.ndarray | None:
    try:
        return unlit_pixels(load_calibration(session))
    except SessionError:
        return None  # no (usable) calibration: nothing is known to be unreachable


def _document_from_session(session: Session, *, history=None) -> tuple[Document, list[str]]:
    edit = saved_edit(session) or interrupted_edit(session)  # an unsaved, unfinished acquisition: resumable
    photo = session.read_capture(photograph_name(session, edit))
    unreachable = session.read_mask(UNREACHABLE) if UNREACHABLE in session.masks else _calibrated_unreachable(session)
    source = session.metadata.get("source")  # a session made from a document records where its photograph came from
    doc = Document(photo, unreachable=unreachable, history=history,
                   source=source if isinstance(source, str) else session.rig_name)
    warnings: list[str] = []
    for t in () if edit is None else edit.targets:
        try:
            target = doc.add_target(t.name, session.read_mask(t.mask), kappa=t.kappa)
            if t.colour is not None:
                target.colour = t.colour
            if not t.included:
                doc.set_included(target.uid, False)
        except (InputError, SessionError) as exc:
            warnings.append(f"target {t.name!r} could not be restored: {exc}")
    if edit is not None and edit.acquisition is not None:
        try:
            warnings += _restore_acquisition(doc, session, edit)
        except (InputError, SessionError) as exc:
            warnings.append(f"the acquisition could not be restored ({exc}); acquire again to recolor")
    for t in doc.targets:
        if edit is not None and t.name == edit.current:
            doc.set_current(t.uid)
    doc.history.clear()
    doc.mark_saved()
    return doc, warnings


def _restore_acquisition(doc: Document, session: Session, edit: Edit) -> list[str]:
    """Set the saved acquisition (and its noise reduction) on ``doc``; returns warnings."""
    acq = edit.acquisition
    notes: list[str] = []
    d = load_decomposition(session, acq.decomposition, notes=notes)
    doc.set_acquisition([doc.by_name(n).uid for n in acq.cascade], d, key=acq.decomposition,
                        noise_aware=acq.noise_aware)
    if acq.denoise <= 0:
        return notes
    filtered = cached_decomposition(session, denoised_key(acq.decomposition, acq.denoise), notes)
    try:
        if filtered is None:
            raise SessionError("its filtered decomposition is missing from the session cache")
        doc.set_noise_reduction(acq.denoise, filtered)
    except (InputError, SessionError) as exc:
        notes.append(f"noise reduction (radius {acq.denoise}) could not be restored ({exc}); apply it again")
    return notes


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


def document_edit(document: Document, *, photograph: str | None = None) -> Edit:
    """The document's edit in the engine's schema (:class:`engine.session.edit.Edit`).

    Raises
    ------
    InputError
        A target name no user could type (line breaks, tabs).
    """
    acq = document.acquisition
    return Edit(
        targets=tuple(EditTarget(t.name, mask_name(t.name, mask_digest(t.acquired_mask())),
                                 tuple(float(k) for k in t.kappa), tuple(int(c) for c in t.colour), t.included)
                      for t in document.targets),
        acquisition=None if acq is None else EditAcquisition(
            tuple(document.target(u).name for u in acq.cascade),
            # the earlier targets' κ at acquisition (they shaped the emitted light); the free one's as edited
            tuple(tuple(float(k) for k in kap) for kap in (*acq.kappas[:-1], document.target(acq.cascade[-1]).kappa)),
            acq.key, int(acq.denoise), bool(acq.noise_aware)),
        current=document.target(document.current).name if document.current != -1 else None,
        photograph=photograph,
    )


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
    InputError
        A target name no user could type (line breaks, tabs).
    """
    if tuple(session.camera_resolution) != tuple(document.shape):
        raise SessionError(f"session {session.path} is {session.camera_resolution}, the document {document.shape}")
    edit = document_edit(document, photograph=photograph_name(session, saved_edit(session)))
    existing = set(session.masks)
    for t, saved in zip(document.targets, edit.targets, strict=True):
        if saved.mask not in existing:
            session.write_mask(saved.mask, t.acquired_mask())
            existing.add(saved.mask)
    acq = document.acquisition
    present = set(session.cache_keys())
    if acq is not None:
        cached = {acq.key: acq.raw}
        if acq.denoise:
            cached[denoised_key(acq.key, acq.denoise)] = acq.decomposition
        for key, decomposition in cached.items():
            if key not in present:
                session.cache_put(key, decomposition.to_arrays())
    save_edit(session, edit)
    if acq is not None:  # noise-reduced copies of other radii are no longer referenced (and are big)
        keep = denoised_key(acq.key, acq.denoise) if acq.denoise else None
        for key in present:
            if key.startswith(f"{acq.key}-denoise") and key != keep:
                session.cache_discard(key)
    if mark_saved:
        document.mark_saved()


# ----------------------------------------------------------------------------- export


def edit_metadata(document: Document) -> dict:
    """The edit as exported files carry it: ``{METADATA_KEY: engine.session.edit.export_metadata(...)}``."""
    d = document.decomposition
    return {
        METADATA_KEY: export_metadata(
            document_edit(document), source=document.source,
            pixels={t.name: int(np.count_nonzero(t.mask)) for t in document.targets},
            order=None if d is None else d.order, constraint=None if d is None else d.constraint,
            recolor=None if d is None else (NOISE_AWARE if document.trusted is not None else PLAIN),
        )
    }


def recolored_image(document: Document) -> np.ndarray:
    """The full-resolution recolored image the document shows at rest and exports: noise-aware when its data is
    ready (:func:`engine.trust.recolor_trusted`), else plain (:func:`engine.recolor.recolor`)."""
    if document.trusted is not None:
        return recolor_trusted(document.trusted, document.recolor_kappa()).image
    return recolor(document.decomposition, document.recolor_kappa())


def prepare_trusted(document: Document, session: Session | None, *, progress=None, should_stop=None) -> str:
    """Give ``document`` the noise-aware data of its acquisition if it asks for it (:func:`load_trusted`).

    For the command line (the app prepares it as a job). Returns "" or the one line saying why
    the acquisition is recolored plainly (no session, no noise model, a capture missing).
    """
    acq = document.acquisition
    if acq is None or not document.needs_trusted():
        return ""
    if session is None:
        problem = "the noise-aware recolor needs the acquisition's session (its captures and their noise)"
        document.set_trusted(acq.key, None, problem)
        return problem
    try:
        document.set_trusted(acq.key, load_trusted(session, acq.key, progress=progress, should_stop=should_stop))
        return ""
    except SessionError as exc:  # NoNoiseModel, or a capture missing: plain, and say why
        document.set_trusted(acq.key, None, str(exc))
        return str(exc)


def export_image(document: Document, path, *, dtype: str | None = None, exposure: float = 0.0,
                 clip: bool = False, progress=None, should_stop=None) -> Path:
    """Write the full-resolution recolored image (:func:`recolored_image`), with the edit in the file's metadata.

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
        Nothing acquired, unsupported format or dtype.
    NeedsClipping
        Values out of range for uint16 without ``clip`` (an :class:`InputError` too).
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
    image = recolored_image(document)
    checkpoint(should_stop, "export")
    report(progress, 1, 3, "converting")
    if ext == ".png":
        pixels = imageio.to_display(image, exposure=exposure)
        meta[METADATA_KEY]["display"] = {"exposure": float(exposure), "transfer": "sRGB", "clipped": True}
    elif dtype == "uint16":
        pixels = image * np.float32(2.0**exposure)
        over = int(np.count_nonzero((pixels > 1.0) | (pixels < 0.0)))
        if over and not clip:
            raise NeedsClipping(
                f"{over} values fall outside [0, 1] after an exposure of {exposure:+g} stops and a 16-bit TIFF "
                "cannot hold them: lower the exposure, export float, or allow clipping", values=over)
        pixels = np.clip(pixels, 0.0, 1.0)
        meta[METADATA_KEY]["linear"] = {"exposure": float(exposure), "clipped_values": over}
    else:
        pixels = image
        meta[METADATA_KEY]["linear"] = {"exposure": 0.0}
    checkpoint(should_stop, "export")
    report(progress, 2, 3, f"writing {path.name}")
    imageio.write_image(path, pixels, dtype=dtype, metadata=meta)
    report(progress, 3, 3, "exported")
    return path

