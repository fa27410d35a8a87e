"""The steps every capture plan is made of: settings, one re-emission, the result record.

A re-emission shows ``(I ∩ A) / D`` so that the target's direct outgoing radiance equals
``I`` and the capture, base light removed, is ``T I`` (Sec. 3.3, Eq. 5). With
``differences`` (Sec. 6, Eq. 12-14) plans re-emit ``I_{r-1} − I_{r-2}`` from the second step
on and add ``I_{r-1}`` back: the bright direct term is not re-emitted, which leaves the
projector's range to the interreflections.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from engine.acquire.emission import Emitter, Negative
from engine.acquire.recorder import Recorder
from engine.acquire.target import PreparedTarget


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
    complete_direct : bool
        Add to each re-emission's capture the direct light the target's camera pixels were
        meant to get and did not, because one projector pixel lights several of them with one
        value (:meth:`engine.acquire.emission.Emitter.shortfall`). False only to measure what
        it is worth (the behaviour before it existed).
    """

    per_channel: bool = True
    differences: bool = True
    tau: float = 1.0
    negative: str = Negative.CLAMP
    complete_direct: bool = True

    def to_dict(self) -> dict:
        """JSON form, stored in the session (``complete_direct`` only when off: older plans stay equal)."""
        out = {"per_channel": self.per_channel, "differences": self.differences, "tau": self.tau,
               "negative": str(self.negative)}
        return out if self.complete_direct else out | {"complete_direct": False}

    @classmethod
    def from_dict(cls, values: dict) -> CaptureSettings:
        """The settings :meth:`to_dict` stored."""
        return cls(per_channel=values["per_channel"], differences=values["differences"], tau=values["tau"],
                   negative=values["negative"], complete_direct=values.get("complete_direct", True))

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
        ``T`` applied to ``wanted`` (Eq. 5), base light removed, scaling undone; the target's
        direct term completed where a projector pixel lit several camera pixels with their
        mean (:meth:`Emitter.shortfall`).
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
    light = Emitter.combine(emissions, captures, base)
    short = Emitter.shortfall(emissions)
    return (light if short is None else light + short), names, clamped
