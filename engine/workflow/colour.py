"""A session's colour facts: measuring its colour checker, each target's D, and absolute albedo.

Absolute albedo needs a reference lit like the target: here a ColorChecker measured with the
same Nayar patterns as the targets (:func:`run_checker`). The session keeps the measurement
and every target's D (:mod:`engine.session.colour`), so any later command, or the app, can
turn a target's D into its albedo (:func:`target_colour`) without the rig.
"""

from __future__ import annotations

import numpy as np

from engine.acquire import CAPTURE_PREFIX, Recorder, measure_checker, prepare_target
from engine.acquire.target import pattern_budget
from engine.calibrate import fill_correspondence
from engine.checker import ILLUMINANT, SENSITIVITIES, Checker, NoChart, checker_from_corners, detect_checker
from engine.checks import check_mask
from engine.decompose import Decomposition
from engine.errors import InputError, SessionError
from engine.progress import Progress, ShouldStop
from engine.session import Session
from engine.session.colour import COLOUR_GROUP, COLOUR_VERSION, CheckerRecord, direct_array
from engine.session.edit import mask_digest
from engine.target_colour import TargetColour
from engine.workflow.calibration import check_rig, load_calibration
from engine.workflow.decomposition import _OfflineRig
from engine.workflow.edit import save_edit, saved_edit

__all__ = ["RELATIVE", "run_checker", "saved_checker", "store_directs", "target_albedo", "target_colour",
           "target_direct"]

#: Why a session without a checker gives relative colours only.
RELATIVE = ("albedo is relative: no colour checker calibrated this session (measure one in the target's plane "
            "with `albedit checker SESSION`, or the Albedo panel's Checker button)")


def saved_checker(session: Session) -> CheckerRecord | None:
    """The colour checker that calibrated ``session``, or None.

    Raises
    ------
    SessionError
        The stored measurement does not fit the schema (the message names the field).
    """
    colour = session.state.get("colour")
    if colour is None or colour.get("checker") is None:
        return None
    try:
        return CheckerRecord.from_json(colour["checker"], session.camera_resolution)
    except InputError as exc:
        raise SessionError(f"session {session.path}: {exc}") from None


def run_checker(rig, session: Session, *, corners=None, frames: int = 1, sensitivities: str = SENSITIVITIES,
                progress: Progress | None = None, should_stop: ShouldStop | None = None) -> CheckerRecord:
    """Find (or place) a ColorChecker in the scene, measure its D and store the fit in ``session``.

    Parameters
    ----------
    rig : RigLike
        The rig the session was calibrated with.
    session : Session
        Calibrated; captures may already be in it (the saved edit keeps its decomposition).
    corners : (4, 2) float, optional
        The chart's patch-area corners ``(x, y)`` in camera pixels (dark skin, bluish green,
        black, white); default: detected in a frame with the projector black, or, if that
        finds nothing, white.
    frames : int
        Frames averaged per capture.
    sensitivities : str
        The camera's spectral sensitivities in colour-science
        (:func:`engine.checker.reference_reflectances`; default: the virtual rig's).
    progress, should_stop
        :mod:`engine.progress` conventions.

    Returns
    -------
    CheckerRecord
        As stored under ``state["colour"]``.

    Raises
    ------
    SessionError
        No calibration in the session.
    InputError
        Another rig; no chart found (place its corners by hand); corners outside the image or
        not convex; fewer than 6 patches measured.

    Notes
    -----
    The chart's captures are named after its pixels (``checker-<digest>``), so a rerun with
    the same corners resumes and other corners take new captures. A session whose capture
    finished without a saved edit gets its edit saved first: the chart's captures would
    otherwise change the cache key its decomposition is found under.
    """
    placed = None if corners is None else checker_from_corners(corners, session.camera_resolution)
    with session.writing("measuring the colour checker"):
        calibration = load_calibration(session)
        check_rig(calibration, rig)
        edit = session.state.get("edit")
        if not (isinstance(edit, dict) and "version" in edit) and (derived := saved_edit(session)) is not None:
            save_edit(session, derived)
        recorder = Recorder(rig, session, progress=progress, should_stop=should_stop, frames=frames)
        recorder.planned = recorder.count + 2 + pattern_budget(True)
        base = recorder.capture("checker-black", recorder.black(), meta={"kind": "black"})
        checker = placed or _detect(recorder, base)
        prefix = f"checker-{mask_digest(checker.mask())[:8]}"
        chart = measure_checker(recorder, calibration, checker, base, name=prefix, sensitivities=sensitivities)
        record = CheckerRecord(checker, prefix, sensitivities, ILLUMINANT, chart.scale, chart.patch_direct)
        session.update(colour={"version": COLOUR_VERSION, "checker": record.to_json()})
        return record


def _detect(recorder: Recorder, base: np.ndarray) -> Checker:
    try:
        return detect_checker(base)
    except InputError as first:
        white = recorder.capture("checker-white", np.ones_like(recorder.black()), meta={"kind": "white"})
        try:
            return detect_checker(white)
        except InputError as second:  # "not found" rather than "black": a scene lit by the projector alone
            raise (first if isinstance(first, NoChart) else second) from None


def store_directs(session: Session, prepared) -> None:
    """Keep each measured target's D in ``session`` (:func:`engine.session.colour.direct_array`).

    Parameters
    ----------
    session : Session
    prepared : sequence of (str, PreparedTarget)
        The targets as :func:`engine.acquire.acquire_cascade` measured them.
    """
    for _, p in prepared:
        session.write_array(COLOUR_GROUP, direct_array(mask_digest(p.mask | p.unreachable)), p.direct)


def target_direct(session: Session, mask) -> np.ndarray | None:
    """The D measured on the painted pixels ``mask``, or None if it never was.

    A session captured before D was kept gets it recomputed from its own captures (no rig
    needed; its spread captures too, where it holds them: they decide where D's corner bias is
    taken out, :func:`engine.acquire.prepare_target`) and stored, when it can be written.

    Parameters
    ----------
    session : Session
    mask : (H, W) bool
        The painted target, as acquired.

    Returns
    -------
    (H, W, 3) float32 or None
    """
    mask = check_mask("mask", mask, session.camera_resolution)
    digest = mask_digest(mask)
    try:
        return session.read_array(COLOUR_GROUP, direct_array(digest))
    except SessionError:
        pass
    plan = session.state.get("plan")
    if plan is None or session.state.get("status") != "captured" or digest not in plan["masks"]:
        return None
    name = plan["targets"][plan["masks"].index(digest)]
    base = session.read_capture(f"{CAPTURE_PREFIX}-{'black' if plan['photograph_pattern'] else 'photograph'}")
    recorder = Recorder(_OfflineRig.of(session), session)
    stem = f"{CAPTURE_PREFIX}-{name}"  # with its spread captures, which say where D's corner bias is taken out
    direct = prepare_target(recorder, load_calibration(session), mask, base, name=stem,
                            spread=session.has_capture(f"{stem}-spread-0")).direct
    try:
        session.write_array(COLOUR_GROUP, direct_array(digest), direct)
    except (OSError, SessionError):
        pass  # a read-only session: computed again next time
    return direct


def target_albedo(session: Session, mask, direct: np.ndarray | None = None) -> np.ndarray:
    """The absolute albedo of the target painted as ``mask``, from the session's colour checker.

    Parameters
    ----------
    session : Session
    mask : (H, W) bool
        The painted target.
    direct : (H, W, 3) float, optional
        Its D (default :func:`target_direct`).

    Returns
    -------
    (3,) float64

    Raises
    ------
    InputError
        No checker calibrated the session (:data:`RELATIVE`), or the target's D was never measured.
    """
    record = saved_checker(session)
    if record is None:
        raise InputError(RELATIVE)
    mask = check_mask("mask", mask, session.camera_resolution)
    d = target_direct(session, mask) if direct is None else direct
    if d is None:
        raise InputError("the target's direct image D was not measured (it is measured when the target is "
                         "acquired): albedo is relative")
    corr, _ = fill_correspondence(load_calibration(session).correspondence, mask)
    xy = np.stack([corr.x, corr.y], axis=-1).astype(np.float64)
    return record.scale.albedo(d, mask, xy)


def target_colour(session: Session, decomposition: Decomposition, mask) -> TargetColour:
    """Everything the session knows of the colour of the target painted as ``mask``.

    Parameters
    ----------
    session : Session
    decomposition : Decomposition
        The target's decomposition (the free target of the saved edit).
    mask : (H, W) bool
        The painted target, as acquired.

    Returns
    -------
    TargetColour
        With its D when measured, and its absolute albedo when a checker calibrated the session
        (else the reason it is relative).
    """
    direct = target_direct(session, mask)
    try:
        albedo, relative = target_albedo(session, mask, direct), ""
    except InputError as exc:
        albedo, relative = None, str(exc)
    return TargetColour(decomposition, direct=direct, albedo=albedo, relative=relative)

