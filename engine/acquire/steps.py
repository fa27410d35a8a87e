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
from engine.acquire.noise import Noise
from engine.acquire.recorder import Recorder
from engine.acquire.target import PreparedTarget
from engine.calibrate import projector_to_camera_map, warp_to_projector
from engine.noise import quantization_variance


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
        ``split`` by default: a re-emitted difference is mostly interreflection, often smaller
        than the camera noise, and clamping its negative half to zero biases every later
        observation (measured on the realistic Cornell box, 16 frames: +2 % and +3.5 % in
        the blue 3rd and 4th observations, which left the noise-aware recolor at 72 % error
        instead of 2.6 %); splitting costs a capture only where negatives occur.
    complete_direct : bool
        Add to each re-emission's capture the direct light the target's camera pixels were
        meant to get and did not, because one projector pixel lights several of them with one
        value (:meth:`engine.acquire.emission.Emitter.shortfall`). False only to measure what
        it is worth (the behaviour before it existed).
    stand_in : bool
        Let the emitted pixels next to a target's edge (and next to painted pixels the
        projector cannot reach) also emit the light of the target part there, which cannot be
        re-emitted (:func:`engine.edge.stand_in`, :attr:`PreparedTarget.stand_in`). False only
        to measure what it is worth (the behaviour before it existed).
    spread : bool
        Measure how the target's pixels straddle projector pixels and the direct light the
        emitted pixels put on a soft mask's edge pixels, and complete each re-emission's direct
        light with both (:func:`engine.calibrate.projector_spread`, 8 more captures a target):
        what a posed projector needs. False only to measure what it is worth (the behaviour
        before it existed).
    """

    per_channel: bool = True
    differences: bool = True
    tau: float = 1.0
    negative: str = Negative.SPLIT
    complete_direct: bool = True
    stand_in: bool = True
    spread: bool = True

    def to_dict(self) -> dict:
        """JSON form, stored in the session (the switches that are on by default only when off)."""
        out = {"per_channel": self.per_channel, "differences": self.differences, "tau": self.tau,
               "negative": str(self.negative)}
        for name in ("complete_direct", "stand_in", "spread"):
            if not getattr(self, name):
                out[name] = False
        return out

    @classmethod
    def from_dict(cls, values: dict) -> CaptureSettings:
        """The settings :meth:`to_dict` stored."""
        return cls(per_channel=values["per_channel"], differences=values["differences"], tau=values["tau"],
                   negative=values["negative"], complete_direct=values.get("complete_direct", True),
                   stand_in=values.get("stand_in", True), spread=values.get("spread", True))

    def captures_per_step(self) -> int:
        """Captures one re-emission costs at most, but for a soft mask's stand-in: where its raised
        light passes τ each capture may take one more (:class:`engine.acquire.emission.Emitter`)."""
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
    covariance : (K(K+1)/2, H, W, 3) float32 or None
        Covariance of the observations' noise per pixel and channel, packed
        (:func:`engine.noise.unpack_covariance`): the camera noise of every capture carried
        through re-emission, base removal and differences (:mod:`engine.acquire.noise`).
        None when the camera's noise is unknown (a calibration without a noise measurement,
        on a backend that does not report it).
    """

    observations: np.ndarray
    target: PreparedTarget
    base: np.ndarray
    clamped: int = 0
    log: list = field(default_factory=list)
    covariance: np.ndarray | None = None

    @property
    def images(self) -> int:
        """Photographs taken for the observations (the paper's image count, D excluded)."""
        return sum(len(e["captures"]) for e in self.log)


@dataclass(frozen=True, eq=False)
class Reemission:
    """What one re-emission produced.

    Attributes
    ----------
    light : (H, W, 3) float32
        ``T`` applied to ``wanted`` (Eq. 5), base light removed, scaling undone; the target's
        direct term completed where a projector pixel lit several camera pixels with their
        mean (:meth:`Emitter.shortfall`).
    names : list of str
        The captures taken.
    clamped : int
        Target pixel-channels whose negative wanted light was emitted as zero.
    noise : Noise or None
        The light's noise (None when the camera's noise is unknown).
    """

    light: np.ndarray
    names: list
    clamped: int
    noise: Noise | None = None


@dataclass(frozen=True, eq=False)
class EmittedNoise:
    """The noise that the light a re-emission shows already carries.

    Attributes
    ----------
    wanted : Noise
        Noise of the wanted radiance (made of earlier captures).
    base : Noise
        Noise of the base light removed from every capture.
    direct : (str, (H, W, 3) float32) or None
        Name of the target's D-error source and D's relative standard deviation.
    """

    wanted: Noise
    base: Noise
    direct: tuple | None = None


def reemit(recorder: Recorder, emitter: Emitter, wanted: np.ndarray, base: np.ndarray, *, name: str,
           noise: EmittedNoise | None = None) -> Reemission:
    """Emit ``wanted`` direct radiance on the target and return the light it causes.

    With ``noise`` (and a camera whose noise is known), the light's noise is tracked: each
    capture's own, minus the base's, over the scale; the wanted radiance's noise reflected
    straight back on the target (divided among the camera pixels that share a projector
    pixel); the pattern's rounding to the projector's ``bit_depth``; and D's error, which
    scales the emitted light by ``D / D̂`` (Sec. 3.3).
    """
    emissions, clamped = emitter.emissions(wanted)
    captures, names, variances = [], [], []
    for em in emissions:
        cname = f"{name}-{em.name}"
        meta = {"kind": "reemission", "channels": list(em.channels), "scale": em.scale, "sign": em.sign}
        captures.append(recorder.capture(cname, em.pattern, meta=meta))
        variances.append(recorder.last_variance)
        names.append(cname)
    light = Emitter.combine(emissions, captures, base)
    short = Emitter.shortfall(emissions)
    if short is not None:
        light = light + short
    if noise is None or any(v is None for v in variances):
        return Reemission(light, names, clamped)
    tracked = _reemission_noise(recorder, emitter, wanted, emissions, names, variances, noise)
    return Reemission(light, names, clamped, tracked)


def _reemission_noise(recorder, emitter: Emitter, wanted, emissions, names, variances, noise: EmittedNoise) -> Noise:
    target = emitter.target
    t3 = target[:, :, None]
    corr = emitter.correspondence
    bits = int(getattr(recorder.rig.projector, "bit_depth", 8))
    shared = projector_to_camera_map(corr, target=target).count  # camera pixels per projector pixel
    ys, xs = np.nonzero(target & corr.valid)
    count = np.ones(target.shape, np.float32)
    count[ys, xs] = np.maximum(shared[corr.y[ys, xs], corr.x[ys, xs]], 1)
    shown = t3 & np.ones(3, bool)  # where the wanted light is shown (clamped negatives are not)
    if emitter.negative == Negative.CLAMP:
        shown = shown & (emitter.light(wanted) > 0)
    # a projector pixel seen by n camera pixels q' shows Σ wanted / Σ D over them
    # (Emitter._warp), so pixel q gets back the fraction D_q / Σ D of its own noise, and as
    # much of its neighbours' variance, independent of its own — unless the direct light is
    # completed (Emitter.shortfall): then its own wanted light, noise and all, comes back whole
    def back(image):  # camera image → per projector pixel mean over the pixels seeing it → camera
        proj = warp_to_projector(image, corr, target=target)
        out_ = np.zeros(target.shape + (3,), np.float32)
        out_[ys, xs] = proj[corr.y[ys, xs], corr.x[ys, xs]]
        return out_

    n3 = count[:, :, None]
    if emitter.complete_direct:  # Emitter.shortfall gives each pixel its own wanted direct light back
        share = np.where(shown, 1.0, 0.0)
    elif emitter.per_channel or emitter.direct_matrix is None:
        d = np.where(t3, emitter.direct, 0.0).astype(np.float32)
        block = back(d) * n3
        share = np.where(shown & (block > 0), d / np.where(block > 0, block, 1.0), 0.0)
    else:  # the pattern is the plain mean of the camera pixels' light
        share = np.where(shown, 1.0 / n3, 0.0)
    out = noise.wanted * share
    wanted_var = noise.wanted.variance()
    if wanted_var is not None and not emitter.complete_direct and bool(np.any(count > 1)):
        others = np.maximum(back(np.where(t3, wanted_var, 0.0).astype(np.float32)) * n3 - wanted_var, 0.0)
        out = out + Noise.fresh(np.sqrt(others) * share, "shared")
    for em, cname, var in zip(emissions, names, variances, strict=True):
        chans = np.zeros(3, np.float32)
        chans[list(em.channels)] = 1.0
        factor = np.float32(em.sign / em.scale) * chans
        out = out + Noise.source(cname, np.sqrt(var) * factor) - noise.base * factor
        q = quantization_variance(em.pattern, emitter.response, bits)  # projector pixels, linear light
        q_cam = np.zeros(target.shape + (3,), np.float32)
        q_cam[ys, xs] = q[corr.y[ys, xs], corr.x[ys, xs]]
        out = out + Noise.source(f"q:{cname}", emitter.direct * np.sqrt(q_cam) * np.float32(1.0 / em.scale) * chans)
    if noise.direct is not None:
        source, relative = noise.direct
        out = out - Noise.source(source, np.where(shown, np.asarray(wanted, np.float32) * relative, 0))
    return out
