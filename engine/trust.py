"""Noise-aware recoloring: how much of each interaction component to trust (paper Sec. 6, Discussion).

Recoloring multiplies the noise of component i by κ^{i+1}, and the high components of a
real camera's decomposition are mostly noise (the transport matrix's condition number
grows ~13× per order, so even float32 rounding ruins them by the 7th). Three facts make a
better estimate possible.

- Interreflections are low-pass: a pixel's *share* of light that interacted j times with the
  target, ``s_j = u_j / I`` (``I`` the photograph), varies smoothly even across texture,
  while the noise is white with a known variance (``Decomposition.covariance``).
- The components decay, ``u_{j+1} ≈ ρ u_j`` with ρ the target's decay ratio, so a component
  too noisy to measure can be predicted from the one before it.
- An order-K acquisition holds every lower order's observations (its first k), and a lower
  order's components are far less noisy.

:func:`prepare_trust` smooths every share of every order's decomposition with the box radius
that minimises its locally averaged SURE (Stein's unbiased estimate of the mean squared
error, bias included), on and off the target separately (a soft mask's blended edge pixels,
and a lamp or highlight in view, :func:`bright_pixels`, on their own). :func:`recolor_trusted`
writes the recolored pixel as ``I (a + Σ_j β_j s̃_j)`` for each decomposition order — its
measured shares, the truncated tail beyond it put back with ρ — and, per region and channel,
goes on to the next order only while the squared bias it removes exceeds the variance it
adds, both estimated from the data, and is smaller than the bias the order before removed (a
convergent series' corrections shrink). The result carries its predicted standard deviation.
κ = 1 returns the photograph exactly.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import cached_property
from math import comb

import cv2
import numpy as np

from engine.checks import check_float_image, check_kappa
from engine.decompose import Decomposition, decompose
from engine.errors import InputError
from engine.noise import packed_index
from engine.progress import Progress, ShouldStop, checkpoint, report

#: Box radii a share may be smoothed with (0: the pixel alone).
RADII = (0, 1, 2, 4, 8, 16)
#: Half-size of the window over which SURE is averaged to choose a radius (pixels).
WINDOW = 16
#: Half-size of the window over which the remaining truncation bias is mapped for σ (pixels).
BIAS_WINDOW = 8
#: A decay ratio is used when the tail it predicts is known to within 1 / this of itself (:func:`_tail_ratio`).
SIGNIFICANT = 3.0
#: Pixels darker than this fraction of their region's median brightness weigh as if that
#: bright when a region's relative errors are summed to choose an order (an unlit
#: background would decide otherwise).
DARK = 0.1
#: Non-target pixels brighter than this many times the median non-target pixel (mean over channels) are a light
#: source or a highlight in view (:func:`bright_pixels`): their shares are smoothed, and their orders chosen, apart.
BRIGHT = 8.0
#: A share's variance beyond this (σ a thousand times the pixel's own light) means "unknown".
UNKNOWN = 1e6
#: No share's variance is taken below this fraction of its region's median (σ 1000× below it):
#: a rounding-level variance would otherwise overflow the weights and decide its whole window.
PRECISE = 1e-6
#: A smoothed share is moved onto the ordering constraint (``0 ≤ s_j ≤ s_{j-1} ≤ 1``) only where it
#: violates it by at most this many of its standard deviations: noise. A larger violation is the
#: truncated tail the solved share holds (the last unknowns of an unconstrained decomposition
#: absorb it, :func:`_aliasing`), true and not a constraint's to remove: clipping it was a bias no
#: variance accounted for (ideal Cornell box 128², κ = (2, 0.125, 8): 0.16 % at captured order 5
#: against 0.09 % at order 4, the green share of order 5 off the target clipped by 0.27 % rms).
ORDERING_NOISE = 2.0
#: Largest decay ratio (and κ·ratio) used to extrapolate: the series must converge.
MAX_RATIO = 0.95


@dataclass(frozen=True, eq=False)
class TrustLevel:
    """One decomposition order's interaction shares, smoothed, with their covariance.

    Attributes
    ----------
    shares : (K-1, H, W, C) float32
        Smoothed ``s̃_j`` for j = 1..K-1: on the target ``R^j L_d / I``, off it
        ``C R^{j-1} L_d / I``.
    share_covariance : (K(K-1)/2, H, W, C) float32
        Packed covariance of the smoothed shares (:func:`engine.noise.packed_index` over
        K-1 shares), smoothing bias included on the diagonal.
    photograph_share_covariance : (K-1, H, W, C) float32
        ``Cov(I, s̃_j)``.
    sums : (2, K, C) float64
        The target's components summed over its pixels (row 0) and the sums' standard
        deviations (row 1): how fast the interactions decay.
    """

    shares: np.ndarray
    share_covariance: np.ndarray
    photograph_share_covariance: np.ndarray
    sums: np.ndarray

    @property
    def order(self) -> int:
        """K of the decomposition."""
        return int(self.shares.shape[0]) + 1


@dataclass(frozen=True, eq=False)
class TrustedDecomposition:
    """Decompositions of the observations at every order, their shares smoothed (κ-independent).

    Attributes
    ----------
    photograph : (H, W, C) float32
        ``I``, the light every share is a fraction of (``observations[0]``).
    photograph_variance : (H, W, C) float32
    levels : tuple of TrustLevel
        One per decomposition order, increasing.
    target : (H, W) bool
    unreached_light : bool
    lamps : bool
        Whether :func:`bright_pixels` of the photograph (a lamp, a highlight) were smoothed apart;
        then they also choose their orders apart (:attr:`regions`).
    """

    photograph: np.ndarray
    photograph_variance: np.ndarray
    levels: tuple
    target: np.ndarray
    unreached_light: bool = True
    lamps: bool = False

    @property
    def order(self) -> int:
        """The highest order decomposed (1: the photograph only)."""
        return max((lv.order for lv in self.levels), default=1)

    @cached_property
    def regions(self) -> tuple:
        """``(name, pixels, on the target)`` of each region :func:`recolor_trusted` chooses orders for (those with
        pixels): ``"target"``, ``"elsewhere"`` and, with :attr:`lamps`, ``"bright"`` (:func:`bright_pixels`)."""
        shine = _apart(self.photograph, self.target, self.lamps)
        named = (("target", self.target, True), ("elsewhere", ~self.target & ~shine, False), ("bright", shine, False))
        return tuple(r for r in named if r[1].any())

    @cached_property
    def gathered(self) -> dict:
        """What :func:`recolor_trusted` reads per region and channel, gathered once (it is κ-independent).

        ``{(region, channel): (photograph, its variance, relative weights, [(shares, their full
        covariance, Cov(I, share)) per level])}`` over the region's pixels: the photograph's
        terms float64, the levels' float32 (about 1.2× the levels' own size). Gathering the
        region's pixels was most of a recolor's cost; kept, a recolor at 512² takes 0.41 s
        instead of 0.99 s (bench/trusted.py's data), with identical results.
        """
        out = {}
        unpacked = [_unpack_shares(lv.share_covariance, lv.order - 1) for lv in self.levels]
        for name, region, _ in self.regions:
            for ch in range(self.photograph.shape[2]):
                photo = self.photograph[region, ch].astype(np.float64)
                photo_var = self.photograph_variance[region, ch].astype(np.float64)
                # relative errors, so a lamp does not decide; pixels far darker than the region's
                # mean (an unlit background) would decide instead: their weight is capped
                rel = 1.0 / np.maximum(photo**2, (DARK * max(float(np.median(np.abs(photo))), 1e-30)) ** 2)
                per_level = [(np.ascontiguousarray(lv.shares[:, region, ch]),
                              np.ascontiguousarray(cov[:, :, region, ch]),
                              np.ascontiguousarray(lv.photograph_share_covariance[:, region, ch]))
                             for lv, cov in zip(self.levels, unpacked, strict=True)]
                out[(name, ch)] = (photo, photo_var, rel, per_level)
        return out

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Named plain arrays (no pickle), e.g. for a session's cache; :meth:`from_arrays` reads them back.

        Examples
        --------
        >>> t = TrustedDecomposition(np.ones((1, 2, 3), np.float32), np.zeros((1, 2, 3), np.float32), (),
        ...                          np.array([[True, False]]))
        >>> back = TrustedDecomposition.from_arrays(t.to_arrays())
        >>> back.order, bool(np.array_equal(back.target, t.target)), back.unreached_light
        (1, True, True)
        """
        arrays = {"photograph": self.photograph, "photograph_variance": self.photograph_variance,
                  "target": self.target, "flags": np.array([self.unreached_light, self.lamps], bool),
                  "orders": np.array([lv.order for lv in self.levels], np.int64)}
        for lv in self.levels:
            arrays.update({f"shares{lv.order}": lv.shares, f"share_covariance{lv.order}": lv.share_covariance,
                           f"photograph_share_covariance{lv.order}": lv.photograph_share_covariance,
                           f"sums{lv.order}": lv.sums})
        return arrays

    @classmethod
    def from_arrays(cls, arrays) -> TrustedDecomposition:
        """Inverse of :meth:`to_arrays`.

        Raises
        ------
        InputError
            A missing array, or arrays whose shapes do not fit together.
        """
        try:
            photo = np.asarray(arrays["photograph"], np.float32)
            target = np.asarray(arrays["target"], bool)
            levels = []
            for k in (int(v) for v in np.asarray(arrays["orders"]).ravel()):
                n = k - 1
                lv = TrustLevel(np.asarray(arrays[f"shares{k}"], np.float32),
                                np.asarray(arrays[f"share_covariance{k}"], np.float32),
                                np.asarray(arrays[f"photograph_share_covariance{k}"], np.float32),
                                np.asarray(arrays[f"sums{k}"], np.float64))
                if (lv.shares.shape != (n,) + photo.shape or lv.photograph_share_covariance.shape != lv.shares.shape
                        or lv.share_covariance.shape != (n * (n + 1) // 2,) + photo.shape
                        or lv.sums.shape != (2, k, photo.shape[2])):
                    raise InputError(f"the arrays of order {k} do not fit a {photo.shape} photograph")
                levels.append(lv)
            variance = np.asarray(arrays["photograph_variance"], np.float32)
            if photo.ndim != 3 or variance.shape != photo.shape or target.shape != photo.shape[:2]:
                raise InputError(f"photograph {photo.shape}, its variance {variance.shape} and target {target.shape} "
                                 "do not fit together")
            flags = np.asarray(arrays["flags"], bool).ravel()
            return cls(photo, variance, tuple(levels), target, bool(flags[0]), bool(flags[1:2].any()))
        except KeyError as exc:
            raise InputError(f"a noise-aware decomposition needs the array {exc.args[0]!r}") from None


@dataclass(frozen=True, eq=False)
class TrustedRecolor:
    """A noise-aware recolor and what it predicts about itself.

    Attributes
    ----------
    image : (H, W, C) float32
        The recolored image.
    sigma : (H, W, C) float32
        Predicted standard deviation of its error: noise, smoothing bias and the truncation
        bias that remains.
    orders : dict
        Per region (``"target"``, ``"elsewhere"``, ``"bright"`` if any:
        :attr:`TrustedDecomposition.regions`), per channel: ``(K, J)`` — the order of
        the decomposition used and how many of its components are measured, beyond which the
        tail is extrapolated (``J = K``: every order's candidate uses all its components);
        ``(1, 1)`` is the photograph times κ.
    """

    image: np.ndarray
    sigma: np.ndarray
    orders: dict = field(default_factory=dict)


def decompose_orders(observations, target, covariance, *, unreached_light: bool = True) -> list[Decomposition]:
    """Unconstrained GLS decompositions of the first k observations, for k = 2..K.

    Parameters
    ----------
    observations : (K, H, W, C) float
    target : (H, W) bool
    covariance : (K(K+1)/2, H, W, C) float
        The observations' packed noise covariance (``Acquisition.covariance``).
    unreached_light : bool

    Returns
    -------
    list of Decomposition
        Orders 2..K, each with its covariance (empty for K = 1). :func:`each_order` gives
        them one at a time (what :func:`prepare_trust` needs: one order in memory at once).
    """
    return list(each_order(observations, target, covariance, unreached_light=unreached_light))


def each_order(observations, target, covariance, *, unreached_light: bool = True) -> Iterator[Decomposition]:
    """:func:`decompose_orders` one order at a time, lowest first (arguments checked on the first call).

    Each order's covariance is the leading block of the observations' packed one, taken
    plane by plane (no full ``(K, K, H, W, C)`` copy).
    """
    obs = check_float_image("observations", observations, ndim=4)
    cov = check_float_image("covariance", covariance, ndim=4)
    k = obs.shape[0]
    if cov.shape[0] != k * (k + 1) // 2 or cov.shape[1:] != obs.shape[1:]:
        raise InputError(f"covariance must have shape {(k * (k + 1) // 2,) + obs.shape[1:]} for {k} observations, "
                         f"got {cov.shape}")

    def orders() -> Iterator[Decomposition]:
        for n in range(2, k + 1):
            leading = cov if n == k else cov[[packed_index(i, j, k) for i in range(n) for j in range(i, n)]]
            yield decompose(obs[:n], target, constraint="none", unreached_light=unreached_light, covariance=leading)

    return orders()


def prepare_trust(decompositions, photograph, *, radii=RADII, window: int = WINDOW, lamps: bool = True,
                  progress: Progress | None = None, should_stop: ShouldStop | None = None) -> TrustedDecomposition:
    """Smooth the interaction shares of decompositions where their noise allows (once; κ comes later).

    Parameters
    ----------
    decompositions : Decomposition or sequence of Decomposition
        Unconstrained (``constraint="none"``) with ``covariance``, all of one target and
        shape; typically :func:`decompose_orders` of the observations. The ordering
        constraint is imposed later on the smoothed shares, where noise no longer turns it
        into a bias, and only as far as their noise explains a violation
        (:data:`ORDERING_NOISE`).
    photograph : (H, W, C) float
        ``observations[0]``: κ = 1 returns it bit for bit.
    radii : sequence of int
        Box radii to choose from, 0 (no smoothing) first.
    window : int
        Half-size of the window SURE is averaged over to choose a radius.
    lamps : bool
        Smooth the shares of non-target pixels far brighter than the rest apart, and choose their
        orders apart (:func:`bright_pixels`: a lamp, a highlight). False where ``photograph`` is
        not one: a cascade's earlier target decomposed under the re-emission on a later one, whose
        brightest pixels are that later target's, lit by the projector (smoothed apart there, Fig.
        10 with soft masks went from 1.52 % to 1.58 % over three seeds, up to 1.83 % on one; with
        their orders apart too, 1.80 % on seed 1).
    progress, should_stop
        See :mod:`engine.progress`; checked per order, region and channel.

    Returns
    -------
    TrustedDecomposition

    Raises
    ------
    InputError
        A decomposition without covariance or with a constraint, decompositions of different
        targets or shapes, a photograph of another shape, bad radii or window.

    Notes
    -----
    For a box of radius r with inverse-variance weights ``w``, ``s̃ = Σ w s / Σ w`` has
    variance ``1 / Σ w`` and its own pixel's weight ``ω = w_x / Σ w``; SURE,
    ``(s̃ − s)² − v (1 − 2 ω)``, is an unbiased estimate of its mean squared error. Averaged
    over a window it picks, pixel by pixel, large radii on smooth walls and small ones at
    corners and edges; what it averages to is kept as the smoothed share's error. The
    covariance of two smoothed shares scales their raw correlation by ``√(N_small / N_large)``
    of the two windows' effective sizes. Measured on the realistic Cornell box (128², 16
    frames, 3 seeds): 94–95 % of pixels within ±2σ.
    """
    if isinstance(decompositions, Decomposition):
        decompositions = [decompositions]
    photo = check_float_image("photograph", photograph, ndim=3).astype(np.float32)
    radii = tuple(int(r) for r in radii)
    if not radii or radii[0] != 0 or any(b <= a for a, b in zip(radii[:-1], radii[1:], strict=False)):
        raise InputError(f"radii must increase from 0, got {radii!r}")
    if int(window) < 1:
        raise InputError(f"window must be >= 1 pixel, got {window!r}")
    if isinstance(decompositions, (list, tuple)):  # given at once: any order; else one at a time, increasing
        for i, d in enumerate(decompositions):
            _check_decomposition(i, d)
        decompositions = sorted(decompositions, key=lambda d: d.order)
    first = None  # (shape, target, unreached light) of the first decomposition: not the arrays, dropped after use
    levels: list[TrustLevel] = []
    total = len(decompositions) if isinstance(decompositions, list) else None
    for i, d in enumerate(decompositions):
        _check_decomposition(i, d)
        first = (d.target.copy(), d.unreached_light) if first is None else first
        if d.shape != photo.shape or not np.array_equal(d.target, first[0]):
            raise InputError(f"decompositions[{i}] must share the photograph's shape {photo.shape} and the first "
                             "decomposition's target")
        if d.unreached_light != first[1]:
            raise InputError("the decompositions must agree on unreached light")
        if d.order < 2:
            continue
        if levels and d.order <= levels[-1].order:
            raise InputError(f"decompositions[{i}] has order {d.order} after order {levels[-1].order}: give them "
                             "as a list, or one at a time with increasing orders")
        checkpoint(should_stop, "noise-aware recoloring")
        if total is not None:
            report(progress, i, total, f"smoothing the interaction shares of order {d.order}")
        if not levels:
            # every decomposition has the first one's target
            shine = _apart(photo, d.target, lamps)
        levels.append(_level(d, shine, radii, int(window), should_stop))
        if len(levels) == 1:
            assert d.covariance is not None  # _check_decomposition
            photo_var = _photograph_variance(d.covariance)
        del d  # the next order's arrays replace this one's
    if not levels or first is None:
        return TrustedDecomposition(photo, np.zeros_like(photo), (), np.zeros(photo.shape[:2], bool))
    if total is not None:
        report(progress, total, total, "interaction shares smoothed")
    return TrustedDecomposition(photo, photo_var, tuple(levels), first[0], first[1], bool(lamps))


def _check_decomposition(i: int, d) -> None:
    """What :func:`prepare_trust` needs of a decomposition: a covariance, no constraint."""
    if not isinstance(d, Decomposition):
        raise InputError(f"decompositions[{i}] must be an engine.decompose.Decomposition, got {type(d).__name__}")
    if d.covariance is None:
        raise InputError(f"decompositions[{i}] carries no covariance: decompose with covariance= (the "
                         "acquisition's Acquisition.covariance) to recolor with noise awareness")
    if d.constraint != "none":
        raise InputError(f"decompositions[{i}] was decomposed with constraint={d.constraint!r}; noise-aware "
                         "recoloring needs unbiased components (constraint='none')")


def _photograph_variance(packed: np.ndarray) -> np.ndarray:
    """``Var(I)`` of the photograph ``I = Σ u_j``: every entry of the unknowns' covariance summed (float32)."""
    k = int(round((np.sqrt(8 * packed.shape[0] + 1) - 1) / 2))
    total = np.zeros(packed.shape[1:], np.float64)
    for a in range(k):
        for b in range(k):
            total += packed[packed_index(a, b, k)]
    return total.astype(np.float32)


def recolor_trusted(trusted: TrustedDecomposition, kappa) -> TrustedRecolor:
    """Recolor with the orders, per region and channel, that minimise the predicted error.

    Parameters
    ----------
    trusted : TrustedDecomposition
    kappa : float or (C,) array_like
        Non-negative albedo scale of the target.

    Returns
    -------
    TrustedRecolor
        ``image`` (exactly the photograph for κ = 1), ``sigma`` and the orders used.

    Raises
    ------
    InputError
        Not a TrustedDecomposition, a bad κ, or a κ so large the result leaves float32's range.

    Notes
    -----
    The recolor is ``Σ_i w_i u_i`` (Eq. 3–4: ``w_i = κ^{i+1}`` on the target, ``κ^i`` off it
    with ``u_0 = L̄_d``) ``= I (a + Σ_j b_j s_j)``, ``a = w_0``, ``b_j = w_j − a``. Candidate
    K uses order K's measured shares, the last of which absorbs the truncated tail; the tail
    is put back with the decay ratio ρ of the target's components, summed to infinity
    (:func:`_coefficients`, which also covers the orders never captured). Candidates form a
    chain of decreasing bias — the photograph alone, then orders 2, 3, … — followed while each
    step pays, ``G = Σ (Δy² − |ΔVar|) > Σ ΔVar`` over the region: the squared bias it removes
    against the variance it adds (pixels weighted by ``1/I²``, relative errors, so a lamp does
    not decide), and removes less than the step before (``G`` smaller): the corrections of a
    convergent series shrink, so a step that changes the result more than the one before
    measures the new components' error, not bias. That second test is what the first misses on
    noise-free data, where a smoothed share's systematic error (D's bias: spatially smooth, so
    smoothing does not average it) can be 3–10× its predicted σ: without it a higher captured
    order came out worse (ideal Cornell box 128², κ = (2, 0.125, 8): 0.0394 % at order 5,
    0.0453 % at 8; now 0.0381 % from order 6 on). The first step that does not pay ends the
    chain. Lower orders' components are far less noisy, so capturing more orders does not blow
    the result up as it does the plain recolor's. ``sigma`` adds to the chosen candidate's
    variance the bias it leaves against the next candidate, mapped locally.
    """
    if not isinstance(trusted, TrustedDecomposition):
        raise InputError(f"trusted must be a TrustedDecomposition (from prepare_trust), got {type(trusted).__name__}")
    h, w, c = trusted.photograph.shape
    kap = check_kappa(kappa, c)
    image = np.zeros((h, w, c), np.float64)
    sigma = np.zeros((h, w, c), np.float64)
    orders = {"target": [(1, 1)] * c, "elsewhere": [(1, 1)] * c}
    gathered = trusted.gathered
    for name, region, inside in trusted.regions:
        orders[name] = [(1, 1)] * c
        for ch in range(c):
            photo, photo_var, rel, per_level = gathered[(name, ch)]
            weights = _weights(kap[ch], inside, trusted.order)
            a = weights[0]
            # the chain of candidates, bias decreasing: the photograph times a, then each order K with
            # its truncated tail put back
            best, best_y, best_var = (1, 1), photo * a, a * a * photo_var
            extra = None
            rho = _tail_ratio(trusted.levels, ch, kap[ch])
            removed = np.inf  # the bias the last step removed: a convergent series' corrections shrink
            for lv, (s, cs, ps) in zip(trusted.levels, per_level, strict=True):
                k = lv.order
                beta = _coefficients(weights[:k] - a, rho, kap[ch], inside)
                y1, var1 = _candidate(beta, a, s, cs, ps, photo, photo_var)
                step = (y1 - best_y) ** 2 - np.abs(var1 - best_var)
                gain = float(np.sum(step * rel))
                if gain <= float(np.sum((var1 - best_var) * rel)) or gain >= removed:
                    # the first order that does not pay ends the chain; what it would have
                    # removed is the bias the chosen one leaves
                    extra = _local_mean(np.maximum(step, 0), region, BIAS_WINDOW)
                    break
                best, best_y, best_var, removed = (k, k), y1, var1, gain
            extra = np.zeros_like(best_y) if extra is None else extra
            if kap[ch] == 1.0:  # every candidate is the photograph: return it bit for bit
                best_y = trusted.photograph[region, ch].astype(np.float64)
            image[region, ch] = best_y
            sigma[region, ch] = np.sqrt(np.maximum(best_var + extra, 0))
            orders[name][ch] = best
    top = float(np.finfo(np.float32).max)
    if not (np.isfinite(image).all() and np.isfinite(sigma).all() and np.abs(image).max(initial=0.0) <= top
            and sigma.max(initial=0.0) <= top):
        raise InputError(
            f"recoloring with kappa {kap.tolist()} at order {trusted.order} gives values that are not finite: "
            f"κ^{trusted.order} multiplies the last interaction component beyond float32's range (or the data hold "
            "non-finite values); use a smaller kappa")
    return TrustedRecolor(image.astype(np.float32), sigma.astype(np.float32), orders)


def recolor_noise_aware(observations, target, covariance, kappa, *, unreached_light: bool = True) -> TrustedRecolor:
    """:func:`decompose_orders`, :func:`prepare_trust`, :func:`recolor_trusted` in one call.

    Prepare once (:func:`prepare_trust`) to recolor with many κ.
    """
    obs = check_float_image("observations", observations, ndim=4)
    orders = each_order(obs, target, covariance, unreached_light=unreached_light)
    return recolor_trusted(prepare_trust(orders, obs[0]), kappa)


# --- helpers -----------------------------------------------------------------------------------
def _level(d: Decomposition, shine: np.ndarray, radii, window: int, should_stop) -> TrustLevel:
    """Smooth one decomposition's shares in each region (target, elsewhere, the bright pixels ``shine``, blended
    edge pixels) and channel.

    Works one channel at a time from the packed float32 covariance (float64 planes of one
    channel, not the whole unpacked covariance): bench/trusted.py measures its time and peak
    memory beside the former whole-array version.
    """
    k, h, w, c = d.components.shape
    n = k - 1
    assert d.covariance is not None  # prepare_trust refuses decompositions without one
    packed = d.covariance
    shares = np.zeros((n, h, w, c), np.float32)
    share_cov = np.zeros((n * (n + 1) // 2, h, w, c), np.float32)
    photo_share = np.zeros((n, h, w, c), np.float32)
    # a soft mask's blended edge pixels hold the target part's light (its direct light too) beside the neighbour's:
    # their shares are smoothed among themselves only, and never read by the neighbour's
    # a lamp's shares are its light's, not the wall's beside it: the pixels bright_pixels finds are smoothed apart
    regions = [d.target, d.unblended_outside & ~shine, d.unblended_outside & shine] + (
        [] if d.blended is None else [d.blended & ~d.target])
    for ch in range(c):
        def cov(a: int, b: int, ch=ch) -> np.ndarray:
            return packed[packed_index(a, b, k), ..., ch].astype(np.float64)

        unknowns = _unknowns(d, ch)
        light = unknowns.sum(axis=0)
        photo_var = np.zeros((h, w))
        photo_cov = np.zeros((k, h, w))  # Cov(I, u_j)
        for a in range(k):
            for b in range(k):
                entry = cov(a, b)
                photo_var += entry
                photo_cov[b] += entry
        for region in regions:
            if not region.any():
                continue
            checkpoint(should_stop, "noise-aware recoloring")
            # pixels with no light carry no share: they take their neighbours' smoothed shares
            lit = region & (light > 1e-6 * max(float(np.max(np.where(region, light, 0))), 1e-300))
            denom = np.where(lit, light, 1.0)
            est: list[np.ndarray] = []
            var: list[np.ndarray] = []
            neff: list[np.ndarray] = []
            for j in range(1, k):
                s = np.where(lit, unknowns[j] / denom, 0.0)
                v = np.where(lit, np.minimum(cov(j, j) / denom**2, UNKNOWN), np.inf)
                e_, v_, n_ = _smooth(s, v, lit, radii, window)
                # the ordering constraint on the smoothed shares (a share of the photograph's light lies in
                # [0, 1] and none exceeds the share of one interaction fewer), where noise explains the violation
                # (a zero mean squared error is _smooth's "unknown": anything is noise there)
                clipped = np.clip(e_, 0.0, est[-1] if est else 1.0)
                noise = np.where(v_ > 0, ORDERING_NOISE * np.sqrt(v_), np.inf)
                est.append(np.where(np.abs(clipped - e_) <= noise, clipped, e_))
                var.append(np.minimum(v_, UNKNOWN))
                neff.append(n_)
            for i in range(n):
                shares[i, ..., ch] = np.where(region, est[i], shares[i, ..., ch])
                bound = np.sqrt(np.maximum(photo_var, 0) * var[i])  # Cauchy–Schwarz
                photo_share[i, ..., ch] = np.where(lit, np.clip(photo_cov[i + 1] / denom / neff[i], -bound, bound),
                                                   photo_share[i, ..., ch])
                for j in range(i, n):
                    if i == j:
                        cij = var[i]
                    else:
                        raw = np.clip(cov(i + 1, j + 1) / np.sqrt(np.maximum(
                            cov(i + 1, i + 1) * cov(j + 1, j + 1), 1e-300)), -1.0, 1.0)
                        small, large = np.minimum(neff[i], neff[j]), np.maximum(neff[i], neff[j])
                        cij = raw * np.sqrt(var[i] * var[j] * small / large)
                    p = packed_index(i, j, n)
                    share_cov[p, ..., ch] = np.where(region, cij, share_cov[p, ..., ch])
    return TrustLevel(shares, share_cov, photo_share, _target_sums(d))


def bright_pixels(photograph, target) -> np.ndarray:
    """(H, W) bool: non-target pixels far brighter than the rest — a lamp or a highlight in view.

    Brighter (mean over channels) than :data:`BRIGHT` times the median lit non-target pixel.
    Interaction shares are smooth over reflecting surfaces, even across their texture, but a
    light source's share is its emission's, near 0: smoothed with the surfaces around it, it
    took theirs, which the recolor then multiplied by ``κ^i`` on the lamp's own light (realistic
    Cornell box, 64², 16 frames, κ = (2, 0.125, 8): the lamp's raw blue share 0.001 ± 0.014, its
    smoothed one 0.0074; the lamp 3.4 % off the truth where the photograph is 0.28 % off, and the
    whole image 3.41 % against the naive recolor's 2.46 %). Smoothed apart: the lamp 0.86 %, the
    whole image 1.08 %, the surfaces 5.45 → 5.28 %; its orders chosen apart too (the chain of
    orders for all non-target pixels is weighted so that a lamp does not decide, and at 4 frames
    its noise times κ^i left it 7 % off): the lamp 0.54 % (at 48² with 4 frames 1.07 %, the photograph
    1.08 %; the whole image 1.30 % against the naive recolor's 2.81 %). Not where the photograph is the scene
    under a re-emission (:func:`prepare_trust`'s ``lamps``).

    Examples
    --------
    >>> photo = np.ones((1, 4, 3), np.float32); photo[0, 3] = 50
    >>> bright_pixels(photo, np.array([[True, False, False, False]])).tolist()
    [[False, False, False, True]]
    """
    outside = ~np.asarray(target, bool)
    return _brighter(photograph, outside, outside)


def _brighter(photograph, candidates: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """(H, W) bool: ``candidates`` brighter (mean over channels) than :data:`BRIGHT` times the median lit
    pixel of ``reference`` (none when ``reference`` has no lit pixel)."""
    level = np.asarray(photograph, np.float64).mean(axis=-1)
    lit = reference & (level > 0)
    if not lit.any():
        return np.zeros(level.shape, bool)
    return candidates & (level > 0) & (level > BRIGHT * float(np.median(level[lit])))


def lamp_caution(name: str, photograph, mask) -> str:
    """A warning when the target painted as ``mask`` holds a light source, or ``""``.

    A lamp's light is its own emission: scaling its albedo by κ leaves that light as it is, but the
    method counts everything leaving a target pixel as reflected (the photograph is the first
    interaction component's sum) and would scale the lamp's light by κ, on the lamp and on every
    surface it lights. Target pixels (any coverage) brighter than :data:`BRIGHT` times the median lit
    pixel outside the target — what :func:`bright_pixels` calls a lamp or a highlight — are counted;
    the caution is given from 4 pixels or 1 % of the target on.

    Parameters
    ----------
    name : str
        The target's display name.
    photograph : (H, W, 3) float
        Linear radiance.
    mask : (H, W) bool or float coverage

    Returns
    -------
    str
        One line naming the target and how many of its pixels are that bright.

    Examples
    --------
    >>> photo = np.ones((8, 8, 3), np.float32); photo[:2, :3] = 50
    >>> lamp = np.zeros((8, 8), bool); lamp[:3, :3] = True
    >>> lamp_caution("shade", photo, lamp)[:48]
    "6 of 9 pixels of 'shade' are over 8× the scene's"
    >>> lamp_caution("wall", photo, ~lamp)
    ''
    """
    painted = np.asarray(mask) > 0
    bright = _brighter(photograph, painted, ~painted)
    n, total = int(bright.sum()), int(painted.sum())
    if n < max(4, 0.01 * total):
        return ""
    return (f"{n} of {total} pixels of {name!r} are over {BRIGHT:g}× the scene's median brightness: a light source "
            "or a highlight, whose own light κ would scale (a lamp's light does not change with its albedo); "
            "erase them from the target")


def _apart(photograph: np.ndarray, target: np.ndarray, lamps: bool) -> np.ndarray:
    """(H, W) bool: the pixels smoothed and chosen for apart — :func:`bright_pixels` with ``lamps``, else none."""
    return bright_pixels(photograph, target) if lamps else np.zeros(np.shape(target), bool)


def _unknowns(d: Decomposition, ch: int) -> np.ndarray:
    """(K, H, W) float64: the solver's unknowns of channel ``ch``, in the covariance's order (see
    Decomposition.covariance)."""
    k = d.order
    comps = d.components[..., ch]
    outside = np.concatenate([d.unreached[None, ..., ch], comps[: k - 1]]) if d.unreached_light else comps
    return np.where(d.target[None], comps, outside).astype(np.float64)


def _weights(kappa: float, inside: bool, count: int) -> np.ndarray:
    """``w_i`` of the unknowns: ``κ^{i+1}`` on the target, ``κ^i`` off it (u_0 = L̄_d)."""
    powers = np.arange(count) + (1 if inside else 0)
    return kappa ** powers.astype(np.float64)


def _target_sums(d: Decomposition) -> np.ndarray:
    """``Σ u_j`` over the target per channel and its standard deviation (pixels independent)."""
    sums, cov = d.target_sums  # on the target the unknowns are R^j L_d
    assert cov is not None  # prepare_trust refuses decompositions without one
    return np.stack([sums, np.sqrt(np.maximum(np.einsum("jjc->jc", cov), 0))])


def _tail_ratio(levels, ch: int, kappa: float) -> float:
    """The target's decay ratio ρ for channel ``ch``: ``Σ u_q / Σ u_{q-1}``.

    The last components of a decomposition absorb the truncated tail (:func:`_aliasing`), so
    the pair is read in the lowest order where it is not the last one (order q + 2); q = 2
    when the tail it predicts is known well enough, else q = 1; with only order 2 its aliased
    ratio is all there is. The same value then serves every order above, so capturing more
    orders only adds candidates. 0 when no pair qualifies: no tail.

    Known well enough: the tail ``Σ_m (κρ)^m`` is steep in ρ (``d ln tail / d ln ρ =
    1 / (1 − κρ)``), so the ratio's relative standard deviation times that must be at most
    1 / :data:`SIGNIFICANT`. Both sums being :data:`SIGNIFICANT` σ above 0 was not enough: on
    the realistic Cornell box (128², 16 frames, κ_B = 8, camera-noise seed 2) the blue
    component-2 sum read 0.126 ± 0.040 where the noise-free rig's is 0.022, ρ = 0.096
    against ~0.02, κρ = 0.77, and the tail multiplied the recolor's blue by up to 3 (whole image 6.7 %).
    """
    by_order = {lv.order: lv for lv in levels}
    choices = [(q, by_order.get(q + 2)) for q in (2, 1)]
    if 2 in by_order and 3 not in by_order:
        choices.append((1, by_order[2]))
    cap = MAX_RATIO / max(kappa, 1e-12)
    for q, lv in choices:
        if lv is None:
            continue
        sums, sds = lv.sums[0, q - 1:q + 1, ch], lv.sums[1, q - 1:q + 1, ch]
        if not np.all(sums > 0):
            continue
        rho = min(float(np.clip(sums[1] / sums[0], 0.0, MAX_RATIO)), cap)
        spread = float(np.hypot(*(sds / sums))) / (1.0 - kappa * rho)  # the tail's relative standard deviation
        if SIGNIFICANT * spread <= 1.0:
            return rho
    return 0.0


def _aliasing(order: int, rho: float, inside: bool) -> np.ndarray:
    """``g``: how a geometric tail ``u_{K-1+m} = u_{K-1} ρ^m`` beyond the order leaks into the solution.

    Solving the order-K system on observations that hold the tail gives ``û = u + u_{K-1} g``
    with ``g = A⁻¹ t``, ``t_r = Σ_{m≥1} ρ^m binom(n + m + r, r)`` for the last unknown's
    interaction index n (Eq. 6 / Eq. 9).

    Examples
    --------
    >>> g = _aliasing(2, 0.5, True)          # R^2, R^3, ... halve each time
    >>> round(float(g.sum()), 6)             # the photograph holds the whole tail: ρ / (1 − ρ)
    1.0
    """
    from engine.figurate import outside_matrix, transport_matrix

    a = transport_matrix(order) if inside else outside_matrix(order)
    last = order - 1 if inside else order - 2
    t = np.zeros(order)
    if rho <= 0:
        return t
    for r in range(order):
        if rho < 0.5:  # terms fall fast: sum them
            total, m = 0.0, 1
            while True:
                term = comb(last + m + r, r) * rho**m
                total += term
                if term < 1e-17 * total or m > 4000:
                    break
                m += 1
            t[r] = total
        else:  # Σ_{p≥0} binom(p + r, r) ρ^p = (1 − ρ)^-(r+1), minus the first last+1 terms, over ρ^last
            head = sum(comb(p + r, r) * rho**p for p in range(last + 1))
            t[r] = ((1 - rho) ** -(r + 1) - head) / rho**last
    return np.linalg.solve(a, t)


def _coefficients(b: np.ndarray, rho: float, kappa: float, inside: bool) -> np.ndarray:
    """``β`` over the K-1 shares of an order-K decomposition, its truncated tail put back.

    ``Σ_i w_i u_i`` of the true components plus the tail ``Σ_{m≥1} w_{K-1+m} u_{K-1} ρ^m``
    equals ``Σ_i w_i û_i + û_{K-1} (T − b·g) / (1 + g_{K-1})`` in terms of the solved (tail-
    holding) unknowns ``û`` (:func:`_aliasing`), with ``T = Σ_{m≥1} b_{K-1+m} ρ^m``; the
    photograph's weight cancels (``Σ g = ρ / (1 − ρ)``).
    """
    k = b.size
    beta = b[1:].astype(np.float64).copy()
    if rho > 0:
        e = 1 if inside else 0
        a = kappa**e
        tail = kappa ** (k - 1 + e) * (kappa * rho) / (1 - kappa * rho) - a * rho / (1 - rho)
        g = _aliasing(k, rho, inside)
        beta[-1] += (tail - float(b @ g)) / (1 + g[-1])
    return beta


def _candidate(beta, a, shares, cov, photo_cov, photo, photo_var):
    """Recolored values and their variance for one candidate (pixels as columns)."""
    val = a + beta @ shares
    var = (val**2 * photo_var + photo**2 * np.einsum("i,ijn,j->n", beta, cov, beta)
           + 2 * val * photo * (beta @ photo_cov))
    return photo * val, np.maximum(var, 0)


def _unpack_shares(packed: np.ndarray, n: int) -> np.ndarray:
    full = np.empty((n, n) + packed.shape[1:], packed.dtype)
    for i in range(n):
        for j in range(i, n):
            full[i, j] = full[j, i] = packed[packed_index(i, j, n)]
    return full


def _box(x: np.ndarray, r: int) -> np.ndarray:
    """Sum over a (2r+1)² window, zero outside the image."""
    return cv2.boxFilter(np.asarray(x, np.float64), cv2.CV_64F, (2 * r + 1, 2 * r + 1), normalize=False,
                         borderType=cv2.BORDER_CONSTANT)


def _local_mean(values: np.ndarray, region: np.ndarray, r: int) -> np.ndarray:
    """Mean of ``values`` (given on the region's pixels) over each region pixel's window."""
    full = np.zeros(region.shape)
    full[region] = values
    return (_box(full, r) / np.maximum(_box(region, r), 1e-12))[region]


def _correlation(s: np.ndarray, u: np.ndarray, ok: np.ndarray) -> float:
    """How much a box average's variance exceeds the white-noise ``1 / Σ w``: ``Σ_lag ρ(lag)`` over the 3×3 lags.

    The noise of re-emitted light is shared by the camera pixels that one projector pixel
    lights (a projector coarser than the camera), so neighbouring shares' errors correlate.
    Measured on the whitened residuals ``(s − s̄) √w`` (``s̄`` the radius-4 box mean), clipped
    to [1, 9] (white noise: 1; errors shared by whole 3×3 blocks: 9).
    """
    if int(ok.sum()) < 16:
        return 1.0
    total = np.where(ok, _box(u, 4), 1.0)
    z = np.where(ok, (s - _box(u * s, 4) / np.maximum(total, 1e-300)) * np.sqrt(u), 0.0)
    energy = float(np.sum(z * z))
    if energy <= 0:
        return 1.0
    lagged = 0.0
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = z[dy:, max(dx, 0):z.shape[1] + min(dx, 0)]
        b = z[:z.shape[0] - dy, max(-dx, 0):z.shape[1] - max(dx, 0)]
        lagged += float(np.sum(a * b))
    return float(np.clip(1.0 + 2.0 * lagged / energy, 1.0, 9.0))


def _smooth(s: np.ndarray, v: np.ndarray, lit: np.ndarray, radii, window: int):
    """SURE-chosen inverse-variance box smoothing of one share over the pixels ``lit``.

    Returns the smoothed share, its mean squared error (variance and bias) and the chosen
    window's effective number of pixels (for the covariances between shares).
    """
    s = np.asarray(s, np.float64)
    v = np.asarray(v, np.float64)
    ok = lit & np.isfinite(v) & (v > 0)
    if ok.any():  # a pixel fitted exactly (a rounding-level variance) is not infinitely precise
        v = np.where(ok, np.maximum(v, PRECISE * float(np.median(v[ok]))), v)
    vv = np.where(ok, v, 0.0)
    u = np.where(ok, 1.0 / np.where(ok, v, 1.0), 0.0)
    s0 = np.where(ok, s, 0.0)
    spread = _correlation(s0, u, ok)
    weight = _box(u, window)  # precision in the window: noisy pixels count less
    weighed = weight > 1e-9 * max(float(weight.max()), 1e-300)  # (box sums leave rounding residue where empty)
    weight = np.where(weighed, weight, 1.0)
    best_score = best_est = best_mse = best_var = None
    for r in radii:
        if r == 0:
            est, var, self_weight = s0, np.where(ok, v, np.inf), ok.astype(np.float64)
        else:
            total = _box(u, r)
            seen = total > 1e-9 * max(float(total.max()), 1e-300)
            total = np.where(seen, total, 1.0)
            est = np.where(seen, _box(u * s0, r) / total, 0.0)
            var = np.where(seen, spread / total, np.inf)
            self_weight = np.minimum(spread * u / total, 1.0)  # Cov(est, s) / Var(s), neighbours' share included
        sure = np.where(ok, (est - s0) ** 2 - vv * (1 - 2 * self_weight), 0.0)
        score = np.where(weighed, _box(u * sure, window) / weight, 0.0)
        mse = np.maximum(score, var)
        if best_score is None:
            best_score, best_est, best_var, best_mse = score, est, var, mse
        else:
            assert best_est is not None and best_var is not None and best_mse is not None  # set with best_score
            better = score < best_score
            best_score = np.where(better, score, best_score)
            best_est = np.where(better, est, best_est)
            best_var = np.where(better, var, best_var)
            best_mse = np.where(better, mse, best_mse)
    # prepare_trust checks that radii is not empty (it starts at 0): the loop ran at least once
    assert best_est is not None and best_var is not None and best_mse is not None
    # pixels without a share of their own take the widest window's estimate of their neighbours
    best_est = np.where(ok, best_est, est)
    best_var = np.where(ok, best_var, var)
    best_mse = np.where(ok, best_mse, np.maximum(score, var))
    finite = np.isfinite(best_var)
    neff = np.where(ok & finite, 1.0 / np.maximum(u * np.where(finite, best_var, 1.0), 1e-300), 1.0)
    return best_est, np.where(np.isfinite(best_mse), best_mse, 0.0), np.maximum(neff, 1.0)
