"""Preparing a target for re-emission: its direct image D and the pixels that can take it.

D (Sec. 3.3) is measured with high-frequency patterns lit only inside the target's
projector footprint (Nayar et al. 2006): the direct part ``L⁺ − L⁻`` of the captures minus
the projector-black reference. Because the correspondence says which projector pixel lights
each camera pixel, ``L⁺`` and ``L⁻`` are means over the captures where that pixel's whole
3×3 projector neighbourhood was lit (unlit) rather than the max (min) over all captures:
unbiased under noise, which the max/min is not (it overestimates D by about 2σ), and immune
to projector blur at square edges. Next to a concave corner the global light follows the
pattern (the corner returns the light of the pixel's own lit square) and that D is too high:
the part of it that D from every capture does not share, beyond what it is over the rest of the
target, is taken out where the pixel sees its own projector pixel alone (:func:`_pattern_bias`).
Target pixels the Gray code could not decode (concave corners, grazing angles) get their
projector pixel from their decoded neighbours (:func:`engine.calibrate.fill_correspondence`).
Pixels where D is still near zero (shadowed, unlit) cannot be re-emitted: they are removed from
the target and reported.

A target may be a soft mask (coverage 0–1, :mod:`engine.edge`): only its solid pixels
(coverage 1) whose projector pixel lights nothing else are re-emitted; its edge pixels are
recolored from both sides' interaction shares when decomposing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.acquire.recorder import Recorder
from engine.calibrate import (
    Calibration,
    Correspondence,
    PixelStatus,
    fill_correspondence,
    high_frequency_patterns,
    projector_footprint,
    projector_spread,
    spread_patterns,
)
from engine.calibrate.warp import SPREAD_CAPTURES
from engine.checks import check_mask
from engine.decompose import Decomposition, decompose
from engine.denoise import denoise_components
from engine.edge import blend_edges, check_coverage, is_soft
from engine.edge import stand_in as stand_in_weights
from engine.errors import InputError
from engine.fill import fill_unreachable
from engine.trust import TrustedDecomposition, each_order, prepare_trust

#: An edge pixel's measured D counts when it is at least this fraction of its brightest solid
#: neighbour's: the high-frequency patterns' global light alone gives up to 12 % next to a concave
#: corner, where a co-axial projector puts no direct light on the edge pixels (ideal supersampled
#: Cornell box, 48²); a posed projector's light on them is 15–65 % there.
EDGE_DIRECT_FLOOR = 0.15


@dataclass(frozen=True, eq=False)
class PreparedTarget:
    """A target ready for re-emission.

    Attributes
    ----------
    mask : (H, W) bool
        The emittable target: painted, decoded and with a usable D in every channel.
    unreachable : (H, W) bool
        Painted pixels that cannot be re-emitted (no correspondence, or D below the floor).
    direct : (H, W, 3) float32
        D per unit of linear projector light, per primary (zero off the target).
    correspondence : Correspondence
        The rig's correspondence with the target's undecoded pixels filled in.
    filled : int
        Target pixels whose projector pixel was interpolated from their neighbours.
    direct_matrix : (H, W, 3, 3) float32 or None
        Per pixel, camera channel c's direct radiance per unit of projector primary k
        (``[..., c, k]``): colour crosstalk and albedo together. Measured when D is measured
        per primary; lets one RGB emission replace three single-primary ones.
    direct_variance : (H, W, 3) float32 or None
        Variance of D from the camera noise of the captures it was measured from (None when
        the camera's noise is unknown). D's error is the same in every re-emission. The bias
        left next to concave corners (:func:`_pattern_bias`) is not in it: counted as variance
        there (its estimate, σ/D correlated 0.89 with D's real error) it made the noise-aware
        recolor choose lower orders for the whole target (grazing wall, ideal rig 48², κ =
        (2, 0.125, 8): 6.43 → 8.33 %).
    coverage : (H, W) float32 or None
        The soft mask the target was painted with (None: a hard mask). Its solid pixels are
        ``mask | unreachable``; its edge pixels (0 < coverage < 1) are blended when decomposing.
    spread : (H, W, 3, 3) float32 or None
        How each emitted pixel's direct light divides among the projector pixels round its own
        (:func:`engine.calibrate.projector_spread`, renormalised over the projector pixels D
        was measured with): what the emission's direct light is completed with. Edge pixels too.
    edge_direct : (H, W, 3) float32 or None
        D of a soft mask's edge pixels (their target strip, lit by the emitted projector pixels
        alone): a posed projector's emitted pixels also light the strip, and that direct light,
        which Eq. 9 at an edge pixel does not hold, is taken out of every re-emission.
    """

    mask: np.ndarray
    unreachable: np.ndarray
    direct: np.ndarray
    correspondence: Correspondence
    filled: int = 0
    direct_matrix: np.ndarray | None = None
    direct_variance: np.ndarray | None = None
    coverage: np.ndarray | None = None
    spread: np.ndarray | None = None
    edge_direct: np.ndarray | None = None

    def decompose(self, observations, *, unreached_light: bool = True, fill_radius: int = 3,
                  edge_radius: int = 1, covariance=None, constraint: str = "ordered",
                  denoise: int = 0) -> Decomposition:
        """Decompose on the emittable pixels, then estimate the unreachable and edge ones near them.

        :func:`engine.decompose.decompose` on :attr:`mask` (weighted by ``covariance`` when
        given), then :func:`engine.fill.fill_unreachable` with the painted target
        (``mask | unreachable``): unreachable pixels within ``fill_radius`` pixels of
        emittable ones get their neighbours' interaction shares (0 leaves every one of them
        out); then, with ``denoise`` > 0, noise reduction of that radius in pixels
        (:func:`engine.denoise.denoise_components`, guided by the photograph); then, for a
        soft mask, :func:`engine.edge.blend_edges` recolors its edge pixels from both sides'
        shares within ``edge_radius`` pixels, with the neighbour's shares fitted along the edge
        over ``denoise`` pixels (its ``along``).

        Notes
        -----
        Noise reduction comes before the edge blend, for two reasons: the blend extrapolates
        each edge pixel's target part from two target pixels (which multiplies their noise),
        so it should read denoised components; and a blended edge pixel packs its target part
        and its neighbour's into one set of components that recoloring weighs differently
        (``κ^{m+2}`` and ``κ^{m+1}``), which a filter run afterwards mixes with the outside
        pixels' own. On the path-traced Cornell box (``mitsuba:cornell``, 64², 1024 spp, the
        right wall refined into a soft mask, κ = (2, 0.125, 8), order 4, radius 4) the edge
        pixels' error is 7.9 % this way, against 19.1 % filtering the blended decomposition
        and 12.0 % without noise reduction. The guided filter reads an edge pixel's neighbours
        in a square; its noise is reduced further along the edge, a curve, where the neighbour's
        shares vary slowly: 6.5 % with that (the wall with its edge 3.57 → 3.19 %, 1.69 → 1.51× its
        interior, on one acquisition).
        """
        photograph = np.asarray(observations)[0]
        d = decompose(observations, self.mask, unreached_light=unreached_light, covariance=covariance,
                      constraint=constraint)
        d = fill_unreachable(d, self.mask | self.unreachable, photograph, radius=fill_radius)[0]
        if denoise:
            d = denoise_components(d, photograph, radius=denoise)
        if self.coverage is not None:
            d = blend_edges(d, self.coverage, photograph, radius=edge_radius, along=denoise, smoothed=bool(denoise))[0]
        return d

    def stand_in(self) -> np.ndarray | None:
        """(H, W) float32: how much more each emitted pixel emits for the edge next to it, or None.

        :func:`engine.edge.stand_in` of a soft mask's edge pixels (their target part cannot be
        re-emitted); None for a hard mask. Painted pixels the projector cannot reach are not
        stood in for: they are where the correspondence is unreliable (concave corners, where
        interreflections corrupt the Gray code), and raising the light next to them amplifies
        whatever the projector pixels there really light (measured on the 40² supersampled
        Cornell box, before shared decodes were refilled, :func:`_drop_shared`: a column of
        them made the observations 15–20 % wrong on the wall beside it).
        """
        if self.coverage is None:
            return None
        cov = np.where(self.coverage < 1, self.coverage, 0).astype(np.float32)
        return stand_in_weights(cov, self.mask)

    def trust(self, observations, covariance, *, unreached_light: bool = True, fill_radius: int = 3,
              edge_radius: int = 1, lamps: bool = True, should_stop=None) -> TrustedDecomposition:
        """The observations ready for noise-aware recoloring (:mod:`engine.trust`).

        Unconstrained weighted decompositions of every order up to the observations' (the
        first k observations are an order-k acquisition), unreachable pixels filled and, for a
        soft mask, edge pixels blended from both sides as in :meth:`decompose`, shares smoothed
        by :func:`engine.trust.prepare_trust` (``lamps``: False when ``observations[0]`` is not
        a photograph but the scene under a re-emission).
        """
        obs = np.asarray(observations)
        orders = (fill_unreachable(d, self.mask | self.unreachable, obs[0], radius=fill_radius)[0]
                  for d in each_order(obs, self.mask, covariance, unreached_light=unreached_light))
        if self.coverage is not None:
            orders = (blend_edges(d, self.coverage, obs[0], radius=edge_radius)[0] for d in orders)
        return prepare_trust(orders, obs[0], lamps=lamps, should_stop=should_stop)  # one order in memory at a time

    def report(self) -> str:
        """One line for logs and dialogs."""
        painted = int(self.mask.sum() + self.unreachable.sum())
        bad = int(self.unreachable.sum())
        filled = f" ({self.filled} undecoded pixels interpolated from their neighbours)" if self.filled else ""
        if self.coverage is not None:
            n_edge = int(((self.coverage > 0) & (self.coverage < 1)).sum())
            # how many of them can be split is known once decomposed (engine.workflow.estimated_report)
            filled += f"; {n_edge} edge pixels are partly target (recolored from both sides where they can be split)"
        if not bad:
            return f"all {painted} target pixels can be re-emitted{filled}"
        return (
            f"{bad} of {painted} target pixels ({bad / max(painted, 1):.1%}) cannot be re-emitted "
            f"(the projector does not reach them: shadowed or not decoded) and are not measured{filled}"
        )


def prepare_target(
    recorder: Recorder,
    calibration: Calibration,
    target,
    base: np.ndarray,
    *,
    name: str = "target",
    per_channel: bool = True,
    period: int = 8,
    shifts: int = 2,
    floor: float = 0.02,
    consistency: float = 0.7,
    margin: int = 0,
    spread: bool = True,
    pattern_bias: bool = True,
) -> PreparedTarget:
    """Measure D on a painted target and drop the pixels the projector cannot re-emit.

    Parameters
    ----------
    recorder : Recorder
    calibration : Calibration
    target : (H, W) bool, or (H, W) float coverage in [0, 1]
        The painted target, in camera pixels: a hard mask, or a soft mask whose solid
        pixels (coverage 1) are re-emitted and whose edge pixels are blended
        (:mod:`engine.edge`).
    base : (H, W, 3) float32
        Capture with the projector at black (removed from every pattern capture).
    name : str
        Prefix of the capture names (distinguishes targets of a cascade).
    per_channel : bool
        Measure D on each projector primary separately (3× the captures): needed for
        per-channel emission when the primaries leak into other camera channels, and gives
        the per-pixel 3×3 ``direct_matrix`` that corrects crosstalk in RGB emission.
    period, shifts : int
        High-frequency pattern parameters, see :func:`engine.calibrate.high_frequency_patterns`.
    floor : float
        Pixels whose D is below ``floor`` times the target's median D (in any channel) are
        unreachable.
    consistency : float
        A pixel whose D (from the captures its projector pixel lit and left unlit, according
        to the correspondence) is below this fraction of its correspondence-free
        ``max − min`` has a wrong correspondence (lit and unlit captures got mixed) and is
        unreachable. Noise biases ``max − min`` up by about 2σ, hence the margin.
    margin : int
        Projector pixels this close to one decoded by a non-solid camera pixel are not
        emitted either (the projector footprint must be wholly on the target: use the
        projector's blur radius when it is defocused). Edge pixels the Gray code could not
        decode claim no projector pixel.
    spread : bool
        Also measure how the target's camera pixels straddle projector pixels (8 more captures,
        :func:`engine.calibrate.spread_patterns`): :attr:`PreparedTarget.spread`, and a soft
        mask's edge pixels' D (:attr:`PreparedTarget.edge_direct`), which complete each
        re-emission's direct light where a posed projector's pixels do not line up with the
        camera's. False when only D is wanted (or to measure what they are worth).
    pattern_bias : bool
        Take the checkerboards' own global light, which concave corners return, out of D
        (:func:`_pattern_bias`). Measured on the ideal rig at 48²: D's relative error on the
        checker scene's grazing wall 0.545 → 0.256 % rms (max 5.0 → 2.2 %), the noise-aware
        recolor of the whole image with κ = (2, 0.125, 8), order 4, 6.43 → 4.47 % (exact D: 2.39 %);
        on the Cornell box's wall (true coverage, 4×4 supersampled) 0.77 → 0.47 % rms,
        noise-aware 0.36 → 0.28 % (exact D: 0.25 %); on the frontal panel D stays within 0.01 %.
        Only on the pixels that see their own projector pixel alone, as the spread captures
        measure them (so never with ``spread`` False): a posed projector's other pixels straddle
        projector pixels, and D from every capture split by their own one is not D (the offset
        wedge's soft-mask recolor, 24², 4× supersampled: 11.2 % corrected everywhere, 1.43 % so,
        1.48 % uncorrected). False: the previous estimate.

    Returns
    -------
    PreparedTarget

    Raises
    ------
    InputError
        The target is empty, or no pixel of it can be re-emitted.
    """
    coverage = None
    if np.asarray(target).dtype.kind == "f":
        coverage = check_coverage("target", target, calibration.camera_resolution)
        target = coverage >= 1.0
        if not is_soft(coverage):
            coverage = None
    target = check_mask("target", target, calibration.camera_resolution)
    if not target.any():
        raise InputError("target is empty (no pixel wholly on it): paint the surface to recolor first")
    if int(margin) < 0:
        raise InputError(f"margin must be >= 0 projector pixels, got {margin!r}")
    corr, filled = fill_correspondence(_drop_shared(calibration.correspondence, target, int(margin)), target)
    painted_valid = target & corr.valid & ~_conflicts(corr, target, margin=int(margin))
    if not painted_valid.any():
        raise InputError(
            "no pixel of the target has a projector correspondence: the projector does not reach it "
            "(check the Gray-code coverage map)"
        )
    footprint = projector_footprint(corr, target=painted_valid)
    patterns = high_frequency_patterns(calibration.projector_resolution, mask_projector=footprint, period=period,
                                       shifts=shifts)
    # a soft mask's edge pixels are measured too (not emitted): the light a posed projector's
    # emitted pixels put on their target strip is taken out of each re-emission (Emitter.shortfall)
    edge_px = np.zeros_like(target)
    if coverage is not None and spread:
        corr, edge_px = _edge_decodes(corr, target, coverage > 0)
    measured = painted_valid | edge_px
    lit_full, unlit_full, lit_own = _neighbourhood_states(patterns, corr, measured, footprint)
    groups = [(c,) for c in range(3)] if per_channel else [(0, 1, 2)]
    # matrix[..., c, g]: camera channel c's direct light per unit of primary group g
    matrix = np.zeros(base.shape + (len(groups),), np.float32)
    n_plus = lit_full.sum(axis=0)[:, :, None]
    n_minus = unlit_full.sum(axis=0)[:, :, None]
    n_on = lit_own.sum(axis=0)[:, :, None]
    n_off = len(patterns) - n_on
    ok = measured[:, :, None] & (n_plus > 0) & (n_minus > 0)
    brightest = np.full(base.shape, -np.inf)  # correspondence-free max - min, to check it
    darkest = np.full(base.shape, np.inf)
    variance = np.zeros(base.shape, np.float64)  # of D: lit and unlit means, base cancels
    excess = np.zeros(base.shape, np.float64)  # D minus D from every capture (_pattern_bias)
    excess_var = np.zeros(base.shape, np.float64)
    known = True
    for g, channels in enumerate(groups):
        label = "rgb"[channels[0]] if per_channel else "rgb"
        plus = np.zeros(base.shape, np.float64)
        minus = np.zeros_like(plus)
        var_plus = np.zeros_like(plus)
        var_minus = np.zeros_like(plus)
        sq_plus = np.zeros_like(plus)
        sq_minus = np.zeros_like(plus)
        on = np.zeros_like(plus)  # every capture, split by the pixel's own projector pixel alone
        off = np.zeros_like(plus)
        var_excess = np.zeros_like(plus)
        hi = np.full(base.shape, -np.inf)
        lo = np.full(base.shape, np.inf)
        for i, pattern in enumerate(patterns):
            shown = np.zeros_like(pattern)
            shown[..., channels] = pattern[..., channels]
            if calibration.response is not None:
                shown = calibration.response.linearize(shown)
            cap = recorder.capture(f"{name}-direct-{label}-{i:02d}", shown, meta={"kind": "direct"})
            light = cap - base
            plus += np.where(lit_full[i][:, :, None], light, 0)
            minus += np.where(unlit_full[i][:, :, None], light, 0)
            sq_plus += np.where(lit_full[i][:, :, None], np.square(light, dtype=np.float64), 0)
            sq_minus += np.where(unlit_full[i][:, :, None], np.square(light, dtype=np.float64), 0)
            on += np.where(lit_own[i][:, :, None], light, 0)
            off += np.where(lit_own[i][:, :, None], 0, light)
            if recorder.last_variance is None:
                known = False
            else:
                var_plus += np.where(lit_full[i][:, :, None], recorder.last_variance, 0)
                var_minus += np.where(unlit_full[i][:, :, None], recorder.last_variance, 0)
                # the capture's weight in D minus D from every capture (the full ones are among them)
                w = (np.where(lit_full[i][:, :, None], 1 / np.maximum(n_plus, 1), 0)
                     - np.where(unlit_full[i][:, :, None], 1 / np.maximum(n_minus, 1), 0)
                     - np.where(lit_own[i][:, :, None], 1 / np.maximum(n_on, 1), -1 / np.maximum(n_off, 1)))
                var_excess += w * w * recorder.last_variance
            np.maximum(hi, light, out=hi)
            np.minimum(lo, light, out=lo)
        matrix[..., g] = np.where(ok, plus / np.maximum(n_plus, 1) - minus / np.maximum(n_minus, 1), 0)
        every = on / np.maximum(n_on, 1) - off / np.maximum(n_off, 1)  # D from every capture
        for c in channels:
            excess[..., c] = np.where(ok, matrix[..., g] - every, 0)[..., c]
            excess_var[..., c] = var_excess[..., c]
        for c in channels:
            brightest[..., c], darkest[..., c] = hi[..., c], lo[..., c]
            variance[..., c] = np.maximum(
                (var_plus / np.maximum(n_plus, 1) ** 2 + var_minus / np.maximum(n_minus, 1) ** 2)[..., c],
                (_spread(plus, sq_plus, n_plus) + _spread(minus, sq_minus, n_minus))[..., c])
    direct = np.stack([matrix[..., c, c] for c in range(3)], -1) if per_channel else matrix[..., 0]
    # a wrong correspondence mixes lit and unlit captures: its D falls far below max - min
    consistent = (direct >= consistency * (brightest - darkest)).all(axis=-1)
    med = np.median(direct[painted_valid], axis=0)
    strong = (direct >= floor * np.maximum(med, 1e-30)).all(axis=-1) & (direct > 0).all(axis=-1)
    usable = painted_valid & consistent & strong
    if not usable.any():
        raise InputError("the projector's direct light on the target is too weak to measure everywhere on it")
    edge_direct = None
    if edge_px.any():  # D of the edge pixels' target strip, where it passes its noise and the patterns' bias
        import cv2

        sigma = np.sqrt(variance) if known else 0.0
        solid_d = np.where(usable[:, :, None], direct, 0).astype(np.float32)
        neighbour_d = cv2.dilate(solid_d, np.ones((3, 3), np.uint8))  # the brightest solid neighbour's D
        real = (direct > 2 * sigma) & (direct > EDGE_DIRECT_FLOOR * neighbour_d)
        edge_direct = np.where(edge_px[:, :, None] & real, direct, 0).astype(np.float32)
    weights = None
    if spread:
        lit_direct = np.where(usable[:, :, None], direct, 0).astype(np.float32)
        if edge_direct is not None:
            lit_direct += edge_direct
        weights = _measure_spread(recorder, calibration, corr, usable | edge_px, lit_direct, footprint, base, name)
        if pattern_bias:  # the checkerboards' own global light, which concave corners return (see _pattern_bias)
            # only where the pixel sees its own projector pixel alone: what D from every capture assumes
            bias = _pattern_bias(excess, excess_var if known else None, direct, usable & (weights[..., 1, 1] >= 1))
            direct = direct - bias
            if per_channel:
                for c in range(3):
                    matrix[..., c, c] -= bias[..., c]
    direct = np.where(usable[:, :, None], direct, 0).astype(np.float32)
    direct_matrix = np.where(usable[:, :, None, None], matrix, 0).astype(np.float32) if per_channel else None
    direct_variance = np.where(usable[:, :, None], variance, 0).astype(np.float32) if known else None
    return PreparedTarget(usable, target & ~usable, direct, corr, int((filled & usable).sum()), direct_matrix,
                          direct_variance, coverage, weights, edge_direct)


def _edge_decodes(corr: Correspondence, target: np.ndarray, painted: np.ndarray) -> tuple[Correspondence, np.ndarray]:
    """The correspondence with the edge pixels' (``painted & ~target``) decodes repaired, and those decoded.

    A mixed pixel often does not decode (under a posed projector its stripes are mixed too): it
    gets the target's local plane (:func:`engine.calibrate.fill_correspondence`). Only the edge
    pixels change; they are measured, never emitted. (The unpainted pixels next to the target
    are not measured: at a concave corner the patterns' global light there passes any floor
    that keeps a posed projector's spill.)
    """
    edge_px = painted & ~target
    filled, _ = fill_correspondence(corr, painted)
    x = np.where(edge_px, filled.x, corr.x).astype(np.int32)
    y = np.where(edge_px, filled.y, corr.y).astype(np.int32)
    status = np.where(edge_px, filled.status, corr.status).astype(corr.status.dtype)
    out = Correspondence(x, y, status, corr.projector_resolution)
    return out, edge_px & out.valid


def _measure_spread(recorder: Recorder, calibration: Calibration, corr: Correspondence, usable, direct, footprint,
                    base, name: str) -> np.ndarray:
    """Capture :func:`engine.calibrate.spread_patterns` and read :func:`engine.calibrate.projector_spread`."""
    lights, variances = [], []
    for i, pattern in enumerate(spread_patterns(footprint)):
        shown = pattern if calibration.response is None else calibration.response.linearize(pattern)
        lights.append(recorder.capture(f"{name}-spread-{i}", shown, meta={"kind": "spread"}) - base)
        variances.append(recorder.last_variance)
    known = all(v is not None for v in variances)
    return projector_spread(corr, usable, direct, lights, footprint=footprint, variance=variances if known else None)


def _drop_shared(corr: Correspondence, target: np.ndarray, margin: int) -> Correspondence:
    """The correspondence without the target's decodes that a non-target pixel shares (:func:`_conflicts`).

    At a concave corner interreflections shift a target pixel's Gray code onto the projector
    pixel of the neighbouring surface's edge pixel. Kept, such a decode also steers the plane
    fit that fills its undecoded neighbours (measured on the 40² supersampled Cornell box: a
    solid pixel next to the corner was filled one projector pixel short, so its re-emission lit
    the pixel beside it). Dropped, it is filled from its neighbours like an undecoded pixel;
    :func:`_conflicts` still refuses it when the filled projector pixel is shared too.

    Only when each projector pixel is at most one camera pixel: a coarser projector's pixels
    straddle the target's edge and are shared by right decodes, which refilled from their
    neighbours re-emit where the pixel does not look (realistic rig, 128² camera, 64²
    projector, Fig. 10 with hard masks: 7.2 % dropped against 4.3 % kept).
    """
    hp, wp = corr.projector_resolution
    if hp < target.shape[0] or wp < target.shape[1]:
        return corr
    shared = _conflicts(corr, target, margin=margin) & corr.valid
    if not shared.any():
        return corr
    status = np.where(shared, np.uint8(PixelStatus.LOW_CONTRAST), corr.status).astype(corr.status.dtype)
    return Correspondence(np.where(shared, -1, corr.x).astype(corr.x.dtype),
                          np.where(shared, -1, corr.y).astype(corr.y.dtype), status, corr.projector_resolution)


def _conflicts(corr: Correspondence, target: np.ndarray, *, distance: float = 0.0, margin: int = 0) -> np.ndarray:
    """Target pixels whose projector pixel is also decoded by a non-target pixel.

    Emitting on such a projector pixel also lights the other surface — and strongly, since
    ``I / D`` is large where the target is grazing and the other surface is often frontal —
    or the target pixel's decode is wrong (targets are where interreflections, which corrupt
    Gray code, are strong). Either way it cannot be re-emitted safely. ``distance`` tolerates
    claims by non-target pixels that close in the camera image (0: none); ``margin`` also
    refuses projector pixels within that many projector pixels of a claimed one. Measured on the
    offset-projector Cornell box (64×64, ideal): relative error 1870 % without the repairs of
    the correspondence, 46 % with outlier rejection and a 2-pixel tolerance, 4.7 % with none.
    """
    hp, wp = corr.projector_resolution
    other = corr.valid & ~target
    owner_u = np.full((hp, wp), -1e9)
    owner_v = np.full((hp, wp), -1e9)
    vs, us = np.nonzero(other)
    owner_u[corr.y[vs, us], corr.x[vs, us]] = us
    owner_v[corr.y[vs, us], corr.x[vs, us]] = vs
    mine = corr.valid & target
    vt, ut = np.nonzero(mine)
    du = owner_u[corr.y[vt, ut], corr.x[vt, ut]] - ut
    dv = owner_v[corr.y[vt, ut], corr.x[vt, ut]] - vt
    out = np.zeros_like(target)
    out[vt, ut] = np.hypot(du, dv) > distance
    out[vt, ut] &= owner_u[corr.y[vt, ut], corr.x[vt, ut]] > -1e8
    if margin > 0:
        import cv2

        claimed = (owner_u > -1e8).astype(np.uint8)
        near = cv2.dilate(claimed, np.ones((2 * margin + 1,) * 2, np.uint8)) > 0
        out[vt, ut] |= near[corr.y[vt, ut], corr.x[vt, ut]]
    return out


def _neighbourhood_states(
    patterns, corr: Correspondence, mask: np.ndarray, footprint: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per pattern and camera pixel: was the pixel's 3×3 projector neighbourhood all lit / all unlit? Its own pixel lit?

    Neighbours outside the target's footprint are never lit; they do not prevent "all lit"
    (otherwise the target's edge pixels would never count as lit).
    """
    import cv2

    kernel = np.ones((3, 3), np.uint8)
    ys, xs = np.nonzero(mask)
    px, py = corr.x[ys, xs], corr.y[ys, xs]
    lit = np.zeros((len(patterns),) + mask.shape, bool)
    unlit = np.zeros_like(lit)
    own = np.zeros_like(lit)
    for i, pattern in enumerate(patterns):
        on = (pattern[..., 0] > 0.5).astype(np.uint8)
        own[i, ys, xs] = on[py, px] > 0
        lit[i, ys, xs] = cv2.erode(on | ~footprint, kernel, borderType=cv2.BORDER_REPLICATE)[py, px] > 0
        unlit[i, ys, xs] = cv2.dilate(on, kernel, borderType=cv2.BORDER_REPLICATE)[py, px] == 0
    return lit, unlit, own


def _pattern_bias(excess, excess_var, direct, usable) -> np.ndarray:
    """(H, W, 3): the part of D that is the checkerboards' own global light, to take out of D.

    D (the captures whose pixel's 3×3 projector neighbourhood is all lit, minus those where
    it is all unlit) assumes the global light does not follow the pattern (Nayar et al. 2006).
    Next to a concave corner it does: the corner returns the light of the pixel's own lit
    square, so D is too high (up to 5–6 %, ideal rig 48²: the checker scene's grazing wall and
    the Cornell box's wall beside its edge). D from every capture, split by the pixel's own
    projector pixel alone (``excess = D − D_every``), correlates its neighbourhood with its
    own state less and sees less of that light; over a flat wall ``excess / D`` is the same
    everywhere (projector blur, the residual global light at the checkerboard's frequency):
    the median over ``usable`` (the pixels that see their own projector pixel alone), per
    channel. What stands out of it beyond twice its noise
    (``excess_var``; every pixel without it) is the bias: its regression on D's real error
    has slope 1.01 on the grazing wall and 1.03 on the Cornell wall, correlation 0.87 / 0.82.
    D moves by at most a tenth (the largest bias measured is 6.4 %): where the estimate says more
    the pixel is unreliable anyway (path-traced Cornell box 48², 512 spp, the wall's mask refined
    from the photograph: a few pixels by the corner 36 % off, which half of D left to move made 54 %).
    """
    rel = np.where(usable[:, :, None], excess / np.where(direct > 0, direct, 1), 0)
    med = np.array([np.median(rel[usable, c]) for c in range(rel.shape[-1])])
    dev = (rel - med) * direct
    if excess_var is not None:
        dev = np.where(np.abs(dev) > 2 * np.sqrt(excess_var), dev, 0)
    dev = np.clip(dev, -0.1 * np.abs(direct), 0.1 * np.abs(direct))
    return np.where(usable[:, :, None], dev, 0)


def pattern_budget(per_channel: bool, *, shifts: int = 2, spread: bool = False) -> int:
    """Number of captures :func:`prepare_target` takes (``spread``: with its spread captures)."""
    return (3 if per_channel else 1) * 2 * shifts * shifts + (SPREAD_CAPTURES if spread else 0)


def _spread(total: np.ndarray, squares: np.ndarray, count: np.ndarray) -> np.ndarray:
    """Squared standard error of a mean from its samples' sum and sum of squares (0 below 2 samples).

    D is the mean of the lit captures minus that of the unlit ones, and the global light under
    each pattern is not quite the same (its own pattern's interreflections): the captures'
    spread bounds that error even where the camera has no noise (the ideal rig: D's error
    ~3e-4 relative in red, while its captures' noise predicts 1e-6).

    Examples
    --------
    >>> float(_spread(np.array([6.0]), np.array([14.0]), np.array([3]))[0])   # 1, 2, 3: s² = 1, over 3
    0.3333333333333333
    """
    n = np.asarray(count, np.float64)
    mean = total / np.maximum(n, 1)
    sample = np.maximum(squares - n * mean * mean, 0) / np.maximum(n - 1, 1)
    return np.where(n > 1, sample / np.maximum(n, 1), 0.0)
