"""The headless workflow shared by the CLI and the app: calibrate, capture, decompose, export.

Each step reads and writes a :class:`engine.session.Session`, so it can be interrupted and
resumed, and re-run offline from the session alone (a ``replay:`` rig serves its captures).
Nothing here imports Qt or ``devices``: callers open the rig.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from engine.acquire import Adaptive, CaptureSettings, Recorder, acquire_cascade, calibrate_rig
from engine.acquire.cascade import CascadeResult
from engine.calibrate import Calibration
from engine.decompose import Decomposition
from engine.errors import SessionError
from engine.progress import Progress, ShouldStop
from engine.session import Session

_CALIBRATION_GROUP = "rig"


def open_session_for_rig(path, rig) -> Session:
    """Open the session at ``path`` (adopting orphan captures) or create one for ``rig``.

    Raises
    ------
    SessionError
        ``path`` is a session of another rig or resolution, or cannot be created.
    """
    path = Path(path)
    if (path / "manifest.json").exists():
        session = Session.open(path)
        session.recover_orphans()
        theirs = (session.rig_name, tuple(session.camera_resolution), tuple(session.projector_resolution))
        ours = (rig.identity, tuple(rig.camera.resolution), tuple(rig.projector.resolution))
        if theirs != ours:
            raise SessionError(
                f"session {path} belongs to rig {theirs[0]!r} (camera {theirs[1]}, projector {theirs[2]}), "
                f"not to {ours[0]!r} (camera {ours[1]}, projector {ours[2]}); choose a new session folder"
            )
        return session
    return Session.create(
        path,
        rig_name=rig.identity,
        camera_resolution=tuple(rig.camera.resolution),
        projector_resolution=tuple(rig.projector.resolution),
        metadata={"projector_bit_depth": int(getattr(rig.projector, "bit_depth", 8))},
    )


def save_calibration(session: Session, calibration: Calibration) -> None:
    """Store a calibration in a session (JSON + lossless arrays)."""
    meta, arrays = calibration.to_dict()
    session.write_calibration(meta, {_CALIBRATION_GROUP: arrays})


def load_calibration(session: Session) -> Calibration:
    """Read the session's calibration; SessionError if it has none."""
    meta, arrays = session.read_calibration()
    if not meta:
        raise SessionError(f"session {session.path} has no calibration: run `albedit calibrate` on it first")
    return Calibration.from_dict(meta, arrays.get(_CALIBRATION_GROUP, {}))


def run_calibration(
    rig,
    session: Session,
    *,
    levels: int = 17,
    crosstalk: bool = False,
    progress: Progress | None = None,
    should_stop: ShouldStop | None = None,
) -> Calibration:
    """Calibrate ``rig`` into ``session`` (resumable); see :func:`engine.acquire.calibrate_rig`."""
    recorder = Recorder(rig, session, progress=progress, should_stop=should_stop)
    calibration = calibrate_rig(recorder, rig_name=session.rig_name, levels=levels, crosstalk=crosstalk)
    save_calibration(session, calibration)
    return calibration


def capture_plan(
    targets, order, *, fixed_kappa=(), settings: CaptureSettings = CaptureSettings(),
    adaptive: Adaptive | None = None, photograph_pattern: bool = False,
) -> dict:
    """The JSON plan :func:`run_capture` stores, and compares with a session's before a run.

    Two runs with equal plans take the same captures (a rerun resumes); anything that changes
    the emitted patterns — targets (names and painted pixels), order, fixed κ, settings —
    changes the plan.
    """
    return {
        "targets": [name for name, _ in targets],
        "masks": [hashlib.sha256(np.packbits(np.asarray(m, bool)).tobytes()).hexdigest()[:16] for _, m in targets],
        "order": order if order == "auto" else int(order),
        "fixed_kappa": [np.broadcast_to(np.asarray(k, float), (3,)).tolist() for k in fixed_kappa],
        "settings": settings.to_dict(),
        "adaptive": None if adaptive is None else adaptive.to_dict(),
        "photograph_pattern": bool(photograph_pattern),
    }


def run_capture(
    rig,
    session: Session,
    targets: list[tuple[str, np.ndarray]],
    order: int,
    *,
    fixed_kappa=(),
    settings: CaptureSettings = CaptureSettings(),
    adaptive: Adaptive | None = None,
    photograph_pattern: np.ndarray | None = None,
    frames: int = 1,
    progress: Progress | None = None,
    should_stop: ShouldStop | None = None,
    on_capture=None,
) -> CascadeResult:
    """Capture a cascade (or one target) into ``session`` and cache its decomposition.

    ``frames`` captures are averaged per pattern (noise ∝ 1/sqrt(frames)).
    The plan (targets in order, order, fixed κ, settings) is written to the session's state
    before the first capture, masks to ``masks/``; re-running with the same session resumes.
    The last target's decomposition is cached under ``cache/``, weighted by the
    observations' noise and with its covariance when the camera's noise is known
    (:func:`engine.recolor.recolor_variance` then predicts a recolor's σ).

    Returns
    -------
    engine.acquire.CascadeResult
    """
    calibration = load_calibration(session)
    plan = capture_plan(
        targets, order, fixed_kappa=fixed_kappa, settings=settings, adaptive=adaptive,
        photograph_pattern=photograph_pattern is not None,
    )
    previous = session.state.get("plan")
    if previous is not None and previous != plan:
        raise SessionError(
            f"session {session.path} already holds a different acquisition plan ({_describe(previous)}); "
            "use a new session folder for a new plan"
        )
    for name, mask in targets:  # only once the plan is known to be this session's
        session.write_mask(name, np.asarray(mask, bool))
    session.update(plan=plan, status="capturing")
    recorder = Recorder(rig, session, progress=progress, should_stop=should_stop, on_capture=on_capture, frames=frames)
    result = acquire_cascade(
        recorder,
        calibration,
        targets,
        order,
        fixed_kappa=fixed_kappa,
        settings=settings,
        adaptive=adaptive,
        photograph_pattern=photograph_pattern,
    )
    last = result.targets[-1][1]
    session.write_mask(f"{targets[-1][0]}-emittable", last.mask)
    d = last.decompose(result.acquisition.observations, covariance=result.acquisition.covariance)
    cache_decomposition(session, d)
    session.update(
        status="captured",
        result={
            "images": result.images,
            "predicted": result.predicted,
            "captures": result.captures,
            "clamped": result.acquisition.clamped,
            "unreachable": {name: int(p.unreachable.sum()) for name, p in result.targets},
            "estimated": int((d.target & ~last.mask).sum()),
            "log": result.log,
        },
    )
    return result


def plan_key(session: Session) -> str:
    """Cache key of the session's current plan (changes when the plan does)."""
    blob = json.dumps(session.state.get("plan"), sort_keys=True).encode()
    return "decomposition-" + hashlib.sha256(blob).hexdigest()[:16]


def cache_decomposition(session: Session, d: Decomposition) -> None:
    """Store a decomposition in the session's disposable cache."""
    session.cache_put(
        plan_key(session),
        {
            "components": d.components,
            "unreached": d.unreached,
            "target": d.target,
            "residual": d.residual,
            "flags": np.array([d.unreached_light], bool),
            "constraint": np.frombuffer(d.constraint.encode().ljust(16), np.uint8),
            **({} if d.covariance is None else {"covariance": d.covariance}),
        },
    )


def load_decomposition(session: Session, *, rig=None) -> Decomposition:
    """The session's decomposition: from the cache, else recomputed from its captures.

    Parameters
    ----------
    session : Session
    rig : object, optional
        A rig to recompute with when the cache is gone (normally ``replay:`` of the same
        session, which serves every capture back without hardware).

    Raises
    ------
    SessionError
        No acquisition in the session, or no cache and no rig to recompute with.
    """
    cached = session.cache_get(plan_key(session))
    if cached is not None:
        return Decomposition(
            cached["components"],
            cached["unreached"],
            cached["target"].astype(bool),
            bytes(cached["constraint"]).decode().strip(),
            bool(cached["flags"][0]),
            cached["residual"],
            cached.get("covariance"),
        )
    plan = session.state.get("plan")
    if plan is None:
        raise SessionError(f"session {session.path} has no acquisition: run `albedit capture` first")
    if rig is None:
        raise SessionError(f"session {session.path} has no cached decomposition; recompute it with a replay rig")
    targets = [(name, session.read_mask(name)) for name in plan["targets"]]
    s = plan["settings"]
    settings = CaptureSettings(per_channel=s["per_channel"], differences=s["differences"], tau=s["tau"], negative=s["negative"])
    adaptive = None if plan["adaptive"] is None else Adaptive(**plan["adaptive"])
    result = acquire_cascade(
        Recorder(rig, session), load_calibration(session), targets, plan["order"],
        fixed_kappa=plan["fixed_kappa"], settings=settings, adaptive=adaptive,
    )
    d = result.targets[-1][1].decompose(result.acquisition.observations, covariance=result.acquisition.covariance)
    cache_decomposition(session, d)
    return d


def estimated_report(session: Session) -> str:
    """One line on the unreachable target pixels the last capture estimated (empty if none)."""
    result = session.state.get("result") or {}
    n = int(result.get("estimated", 0))
    if not n:
        return ""
    last = (session.state.get("plan") or {}).get("targets", [None])[-1]  # only the last target is filled
    left = int((result.get("unreachable") or {}).get(last, n))
    return (f"{n} unreachable target pixels were given the interaction shares of reachable neighbours "
            f"(engine.fill); {max(left - n, 0)} farther from any keep their colour")


def _describe(plan: dict) -> str:
    return f"targets {plan.get('targets')}, order {plan.get('order')}"
