"""Single-target acquisition (paper Sec. 3.3 with the dynamic-range steps of Sec. 6).

The photograph ``I_0``, then K-1 captures, each emitting the previous observation on the
target divided by D: ``L_r = (I_{r-1} ∩ A) / D``, so that ``I_r = T I_{r-1}`` (Eq. 5). With
``differences`` (Sec. 6, Eq. 12-14) the r-th emission is ``(I_{r-1} − I_{r-2}) ∩ A / D``
for r ≥ 2 and ``I_r = I_{r-1} + T(I_{r-1} − I_{r-2})``: the bright direct term is not
re-emitted, which leaves the projector's range to the interreflections.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from engine._checks import check_order
from engine.acquire.emission import Emitter, Negative
from engine.acquire.recorder import Recorder
from engine.acquire.target import PreparedTarget, pattern_budget, prepare_target
from engine.calibrate import Calibration
from engine.figurate import MAX_ORDER
from engine.errors import InputError


@dataclass(frozen=True)
class CaptureSettings:
    """How re-emission patterns are made (the same for every target of a plan).

    Attributes
    ----------
    per_channel : bool
        Emit each channel on its own primary (3 captures a step; the paper's choice).
    differences : bool
        Re-emit ``I_{r-1} − I_{r-2}`` instead of ``I_{r-1}`` from the second step on.
    tau : float
        Largest linear light fraction emitted (Sec. 6 step 1).
    negative : {"clamp", "split"}
        Handling of negative wanted light (noise), see :class:`engine.acquire.emission.Negative`.
    """

    per_channel: bool = True
    differences: bool = True
    tau: float = 1.0
    negative: str = Negative.CLAMP

    def to_dict(self) -> dict:
        """JSON form, stored in the session."""
        return {"per_channel": self.per_channel, "differences": self.differences, "tau": self.tau, "negative": str(self.negative)}

    def captures_per_step(self) -> int:
        """Captures one re-emission costs."""
        return (3 if self.per_channel else 1) * (2 if self.negative == Negative.SPLIT else 1)


@dataclass(frozen=True, eq=False)
class Acquisition:
    """What one target's acquisition produced.

    Attributes
    ----------
    observations : (K, H, W, 3) float32
        ``observations[0]`` the photograph; ``[r]`` the r-th re-emission with the
        photograph's light removed — the input of :func:`engine.decompose.decompose`.
    target : PreparedTarget
        The emittable mask, the unreachable pixels and D.
    base : (H, W, 3) float32
        The light removed from every re-emission capture (projector at black).
    clamped : int
        Target pixel-channels whose negative wanted light was emitted as zero.
    log : list of dict
        One entry per observation: ``{"index", "source": "photograph" | "captured" | "predicted", "captures": [...]}``.
    """

    observations: np.ndarray
    target: PreparedTarget
    base: np.ndarray
    clamped: int = 0
    log: list = field(default_factory=list)

    @property
    def images(self) -> int:
        """Photographs taken for the observations (the paper's image count, D excluded)."""
        return sum(len(e["captures"]) for e in self.log)


def reemit(recorder: Recorder, emitter: Emitter, wanted: np.ndarray, base: np.ndarray, *, name: str) -> tuple[np.ndarray, list[str], int]:
    """Emit ``wanted`` direct radiance on the target and return the light it causes.

    Returns
    -------
    light : (H, W, 3) float32
        ``T`` applied to ``wanted`` (Eq. 5), base light removed, scaling undone.
    names : list of str
        The captures taken.
    clamped : int
    """
    emissions, clamped = emitter.emissions(wanted)
    captures, names = [], []
    for em in emissions:
        cname = f"{name}-{em.name}"
        meta = {"kind": "reemission", "channels": list(em.channels), "scale": em.scale, "sign": em.sign}
        captures.append(recorder.capture(cname, em.pattern, meta=meta))
        names.append(cname)
    return Emitter.combine(emissions, captures, base), names, clamped


def acquire_single(
    recorder: Recorder,
    calibration: Calibration,
    target,
    order: int,
    *,
    settings: CaptureSettings = CaptureSettings(),
    photograph_pattern: np.ndarray | None = None,
    prepared: PreparedTarget | None = None,
    name: str = "target",
) -> Acquisition:
    """Capture the observations of one target (Sec. 3.3).

    Parameters
    ----------
    recorder : Recorder
        The rig, session, progress and cancellation.
    calibration : Calibration
        Of this rig (checked).
    target : (H, W) bool
        The painted target in camera pixels.
    order : int
        K: the photograph plus K-1 re-emissions.
    settings : CaptureSettings
    photograph_pattern : (Hp, Wp, 3) float32, optional
        What the projector shows for the photograph (e.g. a flood, the paper's Fig. 7-8
        lighting); default black. When given, re-emissions are shown without it and a
        projector-black capture is the light removed.
    prepared : PreparedTarget, optional
        D and the emittable mask from an earlier :func:`prepare_target` of the same target
        on the same rig (cascades re-use it); measured now when None.
    name : str
        Capture-name prefix.

    Returns
    -------
    Acquisition

    Raises
    ------
    InputError
        Bad order, a calibration of another rig, a target the projector cannot reach.
    Cancelled
        Stopped on request; captures so far are in the session and a rerun resumes.

    Notes
    -----
    Costs 1 photograph (+1 black if ``photograph_pattern``), ``pattern_budget`` captures for
    D, and ``K-1`` re-emissions of ``settings.captures_per_step()`` captures each.
    """
    k = check_order(order)
    if k > MAX_ORDER:
        raise InputError(f"order must be at most {MAX_ORDER}, got {k}")
    rig = recorder.rig
    calibration.check_compatible(getattr(rig, "name", calibration.rig_name), tuple(rig.camera.resolution), tuple(rig.projector.resolution))
    d_cost = 0 if prepared is not None else pattern_budget(settings.per_channel)
    recorder.planned = recorder.count + 1 + (photograph_pattern is not None) + d_cost + (k - 1) * settings.captures_per_step()
    photo_pattern = recorder.black() if photograph_pattern is None else np.asarray(photograph_pattern, np.float32)
    photograph = recorder.capture(f"{name}-photograph", photo_pattern, meta={"kind": "photograph"})
    base = photograph if photograph_pattern is None else recorder.capture(f"{name}-black", recorder.black(), meta={"kind": "black"})
    if prepared is None:
        prepared = prepare_target(recorder, calibration, target, base, name=name, per_channel=settings.per_channel)
    emitter = Emitter(calibration.correspondence, prepared.direct, prepared.mask, calibration.response, settings.per_channel, settings.tau, settings.negative)
    obs = [photograph]
    log = [{"index": 0, "source": "photograph", "captures": [f"{name}-photograph"]}]
    clamped = 0
    for r in range(1, k):
        step_diff = settings.differences and r >= 2
        wanted = obs[r - 1] - obs[r - 2] if step_diff else obs[r - 1]
        light, names, n_clamped = reemit(recorder, emitter, wanted, base, name=f"{name}-r{r}")
        obs.append(light + obs[r - 1] if step_diff else light)
        clamped += n_clamped
        log.append({"index": r, "source": "captured", "captures": names, "clamped": n_clamped})
    return Acquisition(np.stack(obs).astype(np.float32), prepared, base, clamped, log)
