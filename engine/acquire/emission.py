"""Turning wanted direct radiance on the target into projector patterns (Sec. 3.3 and 6).

To make the direct outgoing radiance of target pixel x equal ``I(x)``, the projector must
show ``I(x) / D(x)`` at the projector pixel that lights x (Sec. 3.3). Two steps of Sec. 6
widen the dynamic range: the pattern is scaled by ``τ / max`` before it is shown and the
capture divided by the same factor afterwards, and successive re-emissions send differences
``I_r − I_{r-1}`` (Eq. 12-14). Each channel is emitted on its own projector primary by
default (the paper's choice, immune to colour crosstalk).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from engine.calibrate import Correspondence, ProjectorResponse, warp_to_projector
from engine.errors import InputError

#: The stand-in's raised light beyond τ gets a capture of its own when its peak passes this
#: fraction of τ (below it, what is cut is lost in the projector's quantisation anyway).
OVER_MIN = 0.01


class Negative(StrEnum):
    """What to do with negative wanted radiance (noise in re-emitted differences).

    ``clamp``: emit zero there and count the pixels. ``split``: emit the positive and the
    negative parts as two patterns and subtract the captures (transport is linear).
    """

    CLAMP = "clamp"
    SPLIT = "split"


@dataclass(frozen=True)
class Emission:
    """One projector pattern to show, and how to read its capture back.

    Attributes
    ----------
    pattern : (Hp, Wp, 3) float32
        Projector input in [0, 1], through the inverse response.
    channels : tuple of int
        Camera channels this capture measures (one for per-channel emission).
    scale : float
        The ``τ / max`` factor applied: divide the capture by it.
    sign : int
        +1, or -1 for the negative part of a split emission.
    name : str
        Suffix naming the capture within its step (``"r"``, ``"g-neg"``, ``"rgb"``).
    shortfall : (H, W, 3) float32 or None
        Direct radiance the pattern was meant to put on the target's camera pixels minus
        what it puts there (before ``scale`` is undone), see :meth:`Emitter.shortfall`;
        the stand-in's extra direct light (:attr:`Emitter.stand_in`) is part of it.
    """

    pattern: np.ndarray
    channels: tuple[int, ...]
    scale: float
    sign: int
    name: str
    shortfall: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class Emitter:
    """How to re-emit camera-space radiance onto one target.

    Parameters
    ----------
    correspondence : Correspondence
        Camera→projector pixels of the rig.
    direct : (H, W, 3) float32
        D: direct outgoing radiance per unit of linear projector light (Sec. 3.3), measured
        per projector primary when ``per_channel``.
    target : (H, W) bool
        The emittable target (D usable, correspondence decoded).
    response : ProjectorResponse or None
        Maps linear light fractions to projector input; None for a linear projector.
    per_channel : bool
        Emit each channel on its own primary (3 captures a step) or all at once (1 capture).
    tau : float
        Largest linear light fraction emitted (Sec. 6, step 1), in (0, 1].
    negative : {"clamp", "split"}
    direct_matrix : (H, W, 3, 3) float32, optional
        Per-pixel direct response of each camera channel to each primary. With
        ``per_channel=False`` the RGB pattern solves ``direct_matrix @ light = wanted`` per
        pixel: colour crosstalk corrected, one capture per re-emission.
    complete_direct : bool
        Record each emission's :attr:`Emission.shortfall` (:meth:`shortfall`), so that the
        capture can be completed with the direct light the projector could not give.
    stand_in : (H, W) float32, optional
        ``b ≥ 0`` per target pixel (:func:`engine.edge.stand_in`): emit ``(1 + b)`` times the
        light there, so that the pixels next to a target's edge also send the interreflections
        of the edge's target part, which cannot be re-emitted. The extra direct light ``b I``
        is always taken out again through :attr:`Emission.shortfall`. The pattern's scale
        ``τ / max`` is that of the light without it: dimming the whole pattern to make room for
        the raised light cost more against the camera noise than it gained (realistic Cornell
        box at 64², κ = (2, 0.125, 8): 7.42 % error over the surfaces that way, 5.75 % with the
        raised light cut at τ, 6.88 % without the stand-in). What passes τ is not cut either:
        it is emitted in one more capture (named ``…-over``), scaled up to the full range, when
        its peak is above ``OVER_MIN`` τ. Cutting it lost the stand-in where it matters most —
        a concave corner is where the target is brightest — and left the edge pixels'
        observations 11 % off the whole target's (ideal supersampled Cornell box, 128²; 0.5 %
        with the extra capture, whose camera noise the larger scale divides).
    spread : (H, W, 3, 3) float32, optional
        How each camera pixel's direct light divides among the 3×3 projector pixels round its
        own (:func:`engine.calibrate.projector_spread`); None: all from its own. The direct
        light a pattern gives (:meth:`shortfall`) is their weighted mean: a posed projector's
        pixels straddle the camera's, so a pixel also receives what its neighbours wanted.
    edge_direct : (H, W, 3) float32, optional
        D of pixels that are not emitted but that emitted projector pixels light (a soft mask's
        edge pixels under a posed projector, :attr:`engine.acquire.PreparedTarget.edge_direct`):
        the direct light each pattern puts there is known and taken out of the capture with the
        shortfall, so that they hold what Eq. 9 says of a target point left out of the
        re-emission.
    """

    correspondence: Correspondence
    direct: np.ndarray
    target: np.ndarray
    response: ProjectorResponse | None = None
    per_channel: bool = True
    tau: float = 1.0
    negative: str = Negative.CLAMP
    direct_matrix: np.ndarray | None = None
    complete_direct: bool = True
    stand_in: np.ndarray | None = None
    spread: np.ndarray | None = None
    edge_direct: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not 0.0 < float(self.tau) <= 1.0:
            raise InputError(f"tau must be in (0, 1] (a fraction of the projector's range), got {self.tau}")
        Negative(self.negative)

    def emissions(self, wanted: np.ndarray) -> tuple[list[Emission], int]:
        """Projector patterns that make the target's direct radiance equal ``wanted``.

        Parameters
        ----------
        wanted : (H, W, 3) float
            Camera-space radiance wanted on the target (ignored elsewhere).

        Returns
        -------
        emissions : list of Emission
            Empty channels (all zero) are skipped: their capture would be pure noise.
        clamped : int
            Number of target pixel-channels whose negative value was emitted as zero.
        """
        t = self.target[:, :, None]
        light = self.light(wanted)  # linear projector light per primary, camera space
        boost = None if self.stand_in is None else (1.0 + np.where(self.target, self.stand_in, 0))[:, :, None]
        clamped = int(np.count_nonzero((light < 0) & t))
        if self.negative == Negative.SPLIT:
            parts = [(np.maximum(light, 0), 1, ""), (np.maximum(-light, 0), -1, "-neg")]
            clamped = 0
        else:
            parts = [(np.maximum(light, 0), 1, "")]
        groups = [((c,), "rgb"[c]) for c in range(3)] if self.per_channel else [((0, 1, 2), "rgb")]
        out = []
        for part, sign, suffix in parts:
            for channels, label in groups:
                plane = np.zeros_like(part)
                plane[..., channels] = part[..., channels]
                peak = float(plane.max())
                if peak <= 0:
                    continue
                # the stand-in raises the light next to the edge but not the scale (a lower scale
                # would dim the whole pattern against the camera noise): what passes τ (where the
                # edge is brightest) goes into a capture of its own, and the shortfall takes the
                # raised direct light out of both
                scale = self.tau / peak
                proj = self._warp(plane * scale if boost is None else plane * boost * scale)
                over = np.maximum(proj - self.tau, 0.0) if boost is not None else None
                proj = np.clip(proj, 0.0, self.tau)  # hole filling may overshoot by rounding only
                short = None
                if self.complete_direct or boost is not None:
                    short = self._direct(plane * scale, channels) - self._direct(self._lit(proj), channels)
                    if boost is not None and not self.complete_direct:  # the stand-in's extra direct light only
                        short = np.where((boost > 1) & t, short, 0).astype(np.float32)
                short = self._off_target(proj, channels, short)
                out.append(self._emission(proj, channels, scale, sign, label + suffix, short))
                if over is not None and float(over.max()) > OVER_MIN * self.tau:
                    grow = self.tau / float(over.max())  # shown at full range: its capture's noise shrinks by it
                    over = over * grow
                    extra = -self._direct(self._lit(over), channels)  # all of it is the stand-in's direct light
                    extra = self._off_target(over, channels, extra)
                    out.append(self._emission(over, channels, scale * grow, sign, label + suffix + "-over", extra))
        return out, clamped

    def _emission(self, proj, channels, scale, sign, name, short) -> Emission:
        """An :class:`Emission` of linear projector light ``proj`` (through the projector's response)."""
        if self.response is not None:
            proj = self.response.linearize(proj)
        return Emission(proj.astype(np.float32), channels, scale, sign, name, short)

    def _off_target(self, proj: np.ndarray, channels: tuple[int, ...], short):
        """``short`` minus the direct light pattern ``proj`` puts on :attr:`edge_direct`'s pixels."""
        if self.edge_direct is None:
            return short
        where = (self.edge_direct > 0).any(axis=-1) & self.correspondence.valid & ~self.target
        lit = self._lit(proj, where)
        extra = np.zeros(self.target.shape + (3,), np.float32)
        extra[..., channels] = (self.edge_direct * lit)[..., channels]
        return -extra if short is None else (short - extra).astype(np.float32)

    def _lit(self, projector_light: np.ndarray, pixels: np.ndarray | None = None) -> np.ndarray:
        """(H, W, 3): the linear light each target camera pixel (or each of ``pixels``) receives, 0 elsewhere.

        Its own projector pixel's, or with :attr:`spread` the weighted mean of the 3×3 round it.
        """
        corr, t = self.correspondence, (self.target if pixels is None else pixels)
        lit = np.zeros(t.shape + (3,), np.float32)
        if self.spread is None:
            lit[t] = projector_light[corr.y[t], corr.x[t]]
            return lit
        hp, wp = projector_light.shape[:2]
        ys, xs = corr.y[t], corr.x[t]
        weights = self.spread[t]
        acc = np.zeros((len(ys), projector_light.shape[2]), np.float64)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                wgt = weights[:, dy + 1, dx + 1]
                if not wgt.any():
                    continue
                acc += wgt[:, None] * projector_light[np.clip(ys + dy, 0, hp - 1), np.clip(xs + dx, 0, wp - 1)]
        lit[t] = acc
        return lit

    def _direct(self, light: np.ndarray, channels: tuple[int, ...]) -> np.ndarray:
        """Direct radiance of the target's camera pixels lit by ``light`` (H, W, 3; primaries ``channels``)."""
        t = self.target
        out = np.zeros(t.shape + (3,), np.float32)
        if self.per_channel or self.direct_matrix is None:
            out[..., channels] = np.where(t[:, :, None], self.direct * light, 0)[..., channels]
        else:
            out[t] = np.einsum("nck,nk->nc", self.direct_matrix[t], light[t])
        return out

    @staticmethod
    def shortfall(emissions: list[Emission]) -> np.ndarray | None:
        """Direct radiance the emissions meant to put on the target and did not, scaling undone.

        A projector pixel lights every camera pixel that sees it with one value, the mean of
        their ``wanted / D``, when the camera has more pixels than the projector. The direct
        term of each such camera pixel is then ``D(x) L(p(x))``, not the ``wanted(x)`` Eq. 6
        assumes: the difference is zero on average over the projector pixel, but it holds the
        camera noise of ``wanted`` that the mean removed, which Eq. 6 expects to see again
        (re-emitted noise cancels between successive observations). Both terms are known, so
        adding the difference to the capture restores the direct term (up to the error of
        D). The interreflections the difference would have caused are not restored: it
        averages to zero over each projector pixel, so they are small. Clamped negative light
        is not part of it (the rest of the scene did not receive it either). Where the light
        was raised to stand in for an edge (:attr:`Emitter.stand_in`) it is negative: the
        extra direct light, ``b · wanted``, is known and taken out again.

        Returns
        -------
        (H, W, 3) float32 or None
            ``Σ sign · shortfall / scale``; None when there are no emissions.
        """
        out = None
        for em in emissions:
            if em.shortfall is not None:
                part = (em.sign / em.scale) * em.shortfall
                out = part if out is None else out + part
        return out

    def _warp(self, light: np.ndarray) -> np.ndarray:
        """Camera-space projector light to the projector pattern.

        Where several camera pixels see one projector pixel (a projector coarser than the
        camera), the pattern is ``Σ D·light / Σ D`` over them: the direct light they receive
        together is what they want together. (The plain mean of ``light = wanted / D`` would
        not conserve it where D varies inside the footprint, a bias every re-emission repeats.)
        """
        if not self.per_channel and self.direct_matrix is not None:
            return warp_to_projector(light, self.correspondence, target=self.target)
        d = np.where(self.target[:, :, None], self.direct, 0.0).astype(np.float32)
        num = warp_to_projector(light * d, self.correspondence, target=self.target)
        den = warp_to_projector(d, self.correspondence, target=self.target)
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0).astype(np.float32)

    def light(self, wanted: np.ndarray) -> np.ndarray:
        """Projector light (per primary, camera pixels) whose direct reflection is ``wanted``."""
        t = self.target[:, :, None]
        if self.per_channel or self.direct_matrix is None:
            d = np.where(t, self.direct, 1.0)
            return np.where(t, wanted / d, 0.0).astype(np.float32)
        light = np.zeros(wanted.shape, np.float32)
        m = self.direct_matrix[self.target].astype(np.float64)
        light[self.target] = np.linalg.solve(m, np.asarray(wanted, np.float64)[self.target][..., None])[..., 0]
        return light

    @staticmethod
    def combine(emissions: list[Emission], captures: list[np.ndarray], base: np.ndarray) -> np.ndarray:
        """Undo scaling, signs and channel splitting: the radiance the wanted emission causes.

        Parameters
        ----------
        emissions : list of Emission
        captures : list of (H, W, 3) float
            One capture per emission.
        base : (H, W, 3) float
            The light present without emission (removed from every capture).
        """
        out = np.zeros(base.shape, np.float32)
        for em, cap in zip(emissions, captures, strict=True):
            ch = list(em.channels)
            out[..., ch] += (em.sign / em.scale) * (cap[..., ch] - base[..., ch])
        return out
