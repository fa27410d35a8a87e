"""Capturing a cascade into a session: every check before the first capture, then the capture itself."""

from __future__ import annotations

from dataclasses import dataclass, fields
from enum import StrEnum

import numpy as np

from engine.acquire import CAPTURE_PREFIX, Adaptive, CaptureSettings, Recorder, acquire_cascade
from engine.acquire.cascade import CascadeResult
from engine.calibrate import Calibration, fill_correspondence
from engine.checks import check_kappa, check_mask
from engine.decompose import Decomposition
from engine.edge import REACH, check_coverage, is_soft, solid, unblended
from engine.errors import InputError, SessionError
from engine.figurate import MAX_ORDER
from engine.progress import Progress, ShouldStop
from engine.session import Session
from engine.session.edit import check_target_name, mask_digest, mask_name
from engine.text import listed
from engine.workflow.calibration import ACQUISITION_GROUP, PHOTOGRAPH_PATTERN, check_rig, load_calibration
from engine.workflow.colour import store_directs
from engine.workflow.decomposition import decomposition_key

__all__ = [
    "MAX_FRAMES", "CaptureResult", "Preflight", "Unreachable", "capture_plan", "check_frames", "check_targets",
    "estimated_report", "preflight", "run_capture", "solid_part",
]

#: Frames averaged per capture, at most (noise falls as 1/sqrt(frames); beyond this it is hours).
MAX_FRAMES = 256


def capture_plan(
    targets, order, *, fixed_kappa=(), settings: CaptureSettings | None = None,
    adaptive: Adaptive | None = None, photograph_pattern: bool = False,
) -> dict:
    """The JSON plan :func:`run_capture` stores, and compares with a session's before a run.

    Two runs with equal plans take the same captures (a rerun resumes); anything that changes
    the emitted patterns — targets (names and painted pixels), order, fixed κ, settings —
    changes the plan.
    """
    return {
        "targets": [name for name, _ in targets],
        "masks": [mask_digest(m) for _, m in targets],
        "order": order if order == "auto" else int(order),
        "fixed_kappa": [np.broadcast_to(np.asarray(k, float), (3,)).tolist() for k in fixed_kappa],
        "settings": (settings or CaptureSettings()).to_dict(),
        "adaptive": None if adaptive is None else adaptive.to_dict(),
        "photograph_pattern": bool(photograph_pattern),
    }


class Unreachable(StrEnum):
    """What :func:`preflight` does with painted pixels the projector cannot reach.

    ``estimate`` keeps them in the target (acquisition estimates those near measured pixels
    from their neighbours and reports the rest); ``refuse`` refuses the target; ``leave_out``
    removes them from the target first (they keep their colour).
    """

    ESTIMATE = "estimate"
    REFUSE = "refuse"
    LEAVE_OUT = "leave_out"


@dataclass(frozen=True, eq=False)
class Preflight:
    """Everything a capture was checked to need (see :func:`preflight`).

    Attributes
    ----------
    calibration : Calibration
    targets : list of (str, (H, W) bool or float32 coverage)
        The targets to capture (with ``leave_out``, without their unreachable pixels); soft
        masks stay soft, a float mask of 0 and 1 only becomes boolean.
    left_out : dict of str to int
        Pixels left out per target name (``leave_out`` only).
    plan : dict
        :func:`capture_plan` of these targets and settings.
    """

    calibration: Calibration
    targets: list
    left_out: dict
    plan: dict


def check_targets(targets, shape: tuple[int, int], *, unreachable: np.ndarray | None = None) -> None:
    """Check targets in cascade order before any acquisition; InputError naming the first problem.

    Parameters
    ----------
    targets : sequence of (str, (H, W) bool or float coverage)
        Hard masks, or soft masks (coverage in [0, 1], :mod:`engine.edge`) whose solid
        pixels are re-emitted and whose edge pixels are recolored from both sides.
    shape : (H, W)
        The camera resolution.
    unreachable : (H, W) bool, optional
        Camera pixels the projector cannot reach; a target covering any is refused.

    Raises
    ------
    InputError
        No target, a name a user could not have typed or used twice, a mask of another shape,
        an empty target (a soft one: no pixel wholly on it), overlapping targets (soft ones:
        coverages summing past 1), or unreachable pixels.
    """
    if not targets:
        raise InputError("no target to acquire: add a target and paint it first")
    names, total = [], np.zeros(shape, np.float64)
    for name, mask in targets:
        check_target_name(name)
        if name in names:
            raise InputError(f"target names must be unique, {name!r} is used twice")
        names.append(name)
        mask = np.asarray(mask)
        if mask.shape != tuple(shape):
            raise InputError(f"target {name!r} is {mask.shape[1]}×{mask.shape[0]} pixels but the camera is "
                             f"{shape[1]}×{shape[0]}")
        if mask.dtype.kind == "f":
            mask = check_coverage(f"target {name!r}", mask, shape)
            if mask.any() and not solid(mask).any():
                raise InputError(f"target {name!r} has no pixel wholly on it (coverage 1): paint its inside too")
        else:
            mask = check_mask(f"target {name!r}", mask, shape)
        if not mask.any():
            raise InputError(f"target {name!r} is empty: paint it before acquiring")
        total += mask
    if (total > 1 + 1e-6).any():
        raise InputError("targets overlap: a pixel may belong to one target only (soft masks: coverages may not "
                         "sum past 1)")
    if unreachable is not None:
        conflicts = {n: int(np.count_nonzero(solid_part(m) & unreachable)) for n, m in targets}
        listed = ", ".join(f"{n!r}: {c} px" for n, c in conflicts.items() if c)
        if listed:
            raise InputError(f"targets cover pixels the projector cannot reach ({listed}); their light cannot be "
                             "re-emitted. Erase them (shown hatched) before acquiring.")


def _as_mask(mask) -> np.ndarray:
    """A checked target mask as ``(H, W) bool``, or float32 coverage when it is soft."""
    arr = np.asarray(mask)
    if arr.dtype.kind == "f":
        return arr.astype(np.float32) if is_soft(arr) else solid(arr)
    return arr.astype(bool)


def solid_part(mask) -> np.ndarray:
    """(H, W) bool: the pixels of a hard or soft mask that are wholly target (the ones re-emitted).

    Examples
    --------
    >>> solid_part(np.array([[0.0, 0.5, 1.0]], np.float32)).tolist(), solid_part(np.array([[True]])).tolist()
    ([[False, False, True]], [[True]])
    """
    arr = np.asarray(mask)
    return solid(arr) if arr.dtype.kind == "f" else arr.astype(bool)


def check_frames(frames) -> int:
    """Frames averaged per capture: an integer in 1..:data:`MAX_FRAMES`, else InputError."""
    if isinstance(frames, bool) or not isinstance(frames, (int, np.integer)) or not 1 <= frames <= MAX_FRAMES:
        raise InputError(f"frames (averaged per capture) must be an integer in 1..{MAX_FRAMES}, got {frames!r}")
    return int(frames)


def preflight(
    rig,
    session: Session,
    targets,
    order,
    *,
    fixed_kappa=(),
    settings: CaptureSettings | None = None,
    adaptive: Adaptive | None = None,
    photograph_pattern: np.ndarray | None = None,
    frames: int = 1,
    unreachable: Unreachable | str = Unreachable.ESTIMATE,
) -> Preflight:
    """Check everything :func:`run_capture` needs, before the first capture; nothing is written.

    Parameters are those of :func:`run_capture`; ``unreachable`` says what to do with painted
    pixels the projector cannot reach (:class:`Unreachable`).

    Returns
    -------
    Preflight

    Raises
    ------
    SessionError
        The session has no calibration, or holds a different acquisition plan.
    InputError
        The calibration was made with another rig; bad targets (see :func:`check_targets`),
        order, fixed κ, frames, adaptive threshold or photograph pattern; unreachable target
        pixels with ``refuse``. The message says what was wrong and the fix.
    """
    unreachable = Unreachable(unreachable)
    calibration = load_calibration(session)
    check_rig(calibration, rig)
    targets = [(str(name), mask) for name, mask in targets]
    check_targets(targets, calibration.camera_resolution)
    targets = [(name, _as_mask(mask)) for name, mask in targets]
    if order != "auto" and (isinstance(order, bool) or not isinstance(order, (int, np.integer))
                            or not 1 <= order <= MAX_ORDER):
        raise InputError(f"order must be an integer in 1..{MAX_ORDER} or 'auto', got {order!r}")
    if order == "auto" and (len(targets) != 1 or (adaptive is not None and adaptive.policy != "brute")):
        raise InputError("order 'auto' chooses the order of one target with brute-force capture: give one target "
                         "and no adaptive policy")
    if len(fixed_kappa) != len(targets) - 1:
        raise InputError(f"a cascade of {len(targets)} targets needs the fixed κ of the first {len(targets) - 1}, "
                         f"got {len(fixed_kappa)}")
    for i, kappa in enumerate(fixed_kappa):
        check_kappa(kappa, 3, name=f"fixed κ of target {targets[i][0]!r}")
    check_frames(frames)
    if adaptive is not None and not (np.isfinite(adaptive.threshold) and 0 < adaptive.threshold <= 1):
        raise InputError(f"the adaptive threshold must be a relative error in (0, 1], got {adaptive.threshold!r}")
    if photograph_pattern is not None:
        pattern = np.asarray(photograph_pattern)
        hp, wp = calibration.projector_resolution
        if pattern.shape != (hp, wp, 3) or pattern.dtype.kind != "f" or not np.all(np.isfinite(pattern)) or \
                pattern.min() < 0 or pattern.max() > 1:
            raise InputError(f"the photograph's projector pattern must be ({hp}, {wp}, 3) floats in [0, 1]")
    left_out = {}
    if unreachable is not Unreachable.ESTIMATE:
        kept = []
        for name, mask in targets:
            hard = solid_part(mask)
            bad = hard & ~fill_correspondence(calibration.correspondence, hard)[0].valid
            if bad.any() and (unreachable is Unreachable.REFUSE or bad.sum() == hard.sum()):
                counts = calibration.correspondence.counts(bad)
                why = ", ".join(f"{n} {k.replace('_', ' ')}" for k, n in counts.items() if n and k != "decoded")
                raise InputError(
                    f"Target {name!r}: {int(bad.sum())} of {int(hard.sum())} painted pixels cannot be reached by the "
                    f"projector ({why}). Erase them from the target (the calibration's coverage map shows where the "
                    "projector reaches), or move the projector and recalibrate.")
            if bad.any():
                left_out[name] = int(bad.sum())
            kept.append((name, np.where(bad, 0, mask).astype(mask.dtype) if mask.dtype.kind == "f" else mask & ~bad))
        targets = kept
    plan = capture_plan(targets, order, fixed_kappa=fixed_kappa, settings=settings, adaptive=adaptive,
                        photograph_pattern=photograph_pattern is not None)
    previous = session.state.get("plan")
    if previous is not None and previous != plan:
        raise SessionError(
            f"this session already holds a different acquisition plan (targets {listed(previous.get('targets', ()))}, "
            f"order {previous.get('order')}): set the same controls to resume it, or acquire into a new session folder"
        )
    return Preflight(calibration, targets, left_out, plan)


# ----------------------------------------------------------------------------- capture


@dataclass(frozen=True, eq=False)
class CaptureResult(CascadeResult):
    """What :func:`run_capture` produced: the cascade, the last target's decomposition and cache key, and
    ``shots``, the camera shots the session holds for the acquisition (the direct image D's included)."""

    decomposition: Decomposition | None = None
    key: str = ""
    shots: int = 0


def run_capture(
    rig,
    session: Session,
    targets: list[tuple[str, np.ndarray]],
    order: int,
    *,
    fixed_kappa=(),
    settings: CaptureSettings | None = None,
    adaptive: Adaptive | None = None,
    photograph_pattern: np.ndarray | None = None,
    frames: int = 1,
    unreachable: Unreachable | str = Unreachable.ESTIMATE,
    progress: Progress | None = None,
    should_stop: ShouldStop | None = None,
    on_capture=None,
) -> CaptureResult:
    """Capture a cascade (or one target) into ``session`` and cache its decomposition.

    Everything is checked first (:func:`preflight`). ``frames`` captures are averaged per
    pattern (noise ∝ 1/sqrt(frames)). The plan (targets in order, order, fixed κ, settings) is
    written to the session's state before the first capture, masks to ``masks/`` under
    :func:`engine.session.edit.mask_name`; re-running with the same session resumes. The last
    target's decomposition is cached under :func:`decomposition_key`, weighted by the
    observations' noise and with its covariance when the camera's noise is known
    (:func:`engine.recolor.recolor_variance` then predicts a recolor's σ), and every target's D
    is kept (:mod:`engine.session.colour`: absolute albedo with a colour checker).

    Returns
    -------
    CaptureResult
        The :class:`engine.acquire.CascadeResult` with the decomposition and its cache key.
    """
    settings = settings or CaptureSettings()
    with session.writing("capturing"):
        return _capture(rig, session, targets, order, fixed_kappa=fixed_kappa, settings=settings, adaptive=adaptive,
                        photograph_pattern=photograph_pattern, frames=frames, unreachable=unreachable,
                        progress=progress, should_stop=should_stop, on_capture=on_capture)


def _capture(rig, session: Session, targets, order, *, fixed_kappa, settings, adaptive, photograph_pattern, frames,
             unreachable, progress, should_stop, on_capture) -> CaptureResult:
    checked = preflight(rig, session, targets, order, fixed_kappa=fixed_kappa, settings=settings, adaptive=adaptive,
                        photograph_pattern=photograph_pattern, frames=frames, unreachable=unreachable)
    targets, plan = checked.targets, checked.plan
    for (name, mask), digest in zip(targets, plan["masks"], strict=True):
        session.write_mask(mask_name(name, digest), mask)
    if photograph_pattern is not None:  # the replay needs it to find (and check) the photograph
        session.write_array(ACQUISITION_GROUP, PHOTOGRAPH_PATTERN, np.asarray(photograph_pattern, np.float32))
    session.update(plan=plan, status="capturing")
    recorder = Recorder(rig, session, progress=progress, should_stop=should_stop, on_capture=on_capture, frames=frames)
    result = acquire_cascade(recorder, checked.calibration, targets, order, fixed_kappa=fixed_kappa,
                             settings=settings, adaptive=adaptive, photograph_pattern=photograph_pattern)
    last = result.targets[-1][1]
    session.write_mask(mask_name(f"{targets[-1][0]} emittable", mask_digest(last.mask)), last.mask)
    store_directs(session, result.targets)
    d = last.decompose(result.acquisition.observations, covariance=result.acquisition.covariance)
    session.update(
        status="captured",
        result={
            "images": result.images,
            "predicted": result.predicted,
            "captures": result.captures,
            "clamped": result.acquisition.clamped,
            "unreachable": {name: int(p.unreachable.sum()) for name, p in result.targets},
            "estimated": int((d.target & ~last.mask).sum()),
            "unblended": 0 if last.coverage is None else int(unblended(d, last.coverage).sum()),
            "log": result.log,
        },
    )
    key = decomposition_key(session)
    session.cache_put(key, d.to_arrays())
    shots = sum(c.name.startswith(f"{CAPTURE_PREFIX}-") for c in session.captures)
    return CaptureResult(**{f.name: getattr(result, f.name) for f in fields(CascadeResult)}, decomposition=d, key=key,
                         shots=max(shots, result.captures))


def estimated_report(session: Session) -> str:
    """One line on the target pixels the last capture estimated or left out (empty if none).

    The unreachable target pixels given their neighbours' shares (:func:`engine.fill.fill_unreachable`)
    and those too far for that; the edge pixels of a soft mask that could not be split between
    the target and its neighbour (:func:`engine.edge.unblended`), which recolor as the neighbour.
    """
    result = session.state.get("result") or {}
    lines = []
    if n := int(result.get("estimated", 0)):
        last = (session.state.get("plan") or {}).get("targets", [None])[-1]  # only the last target is filled
        left = int((result.get("unreachable") or {}).get(last, n))
        lines.append(f"{n} unreachable target pixels were given the interaction shares of reachable neighbours "
                     f"(engine.fill); {max(left - n, 0)} farther from any keep their colour")
    if m := int(result.get("unblended", 0)):
        # decomposed with blend_edges' default radius of 1 pixel: its widest window reaches REACH pixels
        lines.append(f"{m} edge pixels (partly target) have no wholly-target or no outside pixel within {REACH} "
                     "pixels to split them by and recolor as not target: paint the target up to them, or harden the "
                     "edge there")
    return "; ".join(lines)
