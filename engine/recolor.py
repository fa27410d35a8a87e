"""Recoloring: the κ-weighted sum of interaction components (paper Eq. 3 and 4).

Inside the target ``I' = Σ_i κ^{i+1} R^i L_d``; outside ``Ī' = L̄_d + Σ_i κ^{i+1} C R^i L_d``.
Because a :class:`~engine.decompose.Decomposition` packs both families into one array with
the same weights, one Horner pass over it recolors every pixel. For fixed κ the result is
linear in the components, so area-averaging the components first and recoloring after gives
exactly the area average of the full-resolution result: that is the live preview.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from engine.checks import check_kappa
from engine.decompose import Decomposition
from engine.errors import InputError
from engine.noise import packed_index

#: Elements per Horner tile: small enough for the accumulator to stay in cache.
_TILE = 3 * (1 << 15)
_THREADS = max(1, min(4, os.cpu_count() or 1))


def recolor(decomposition: Decomposition, kappa) -> np.ndarray:
    """Recolor the photograph with the target's albedo scaled by ``kappa``.

    Parameters
    ----------
    decomposition : Decomposition
    kappa : float or (C,) array_like
        Non-negative albedo scale of the target, one value or one per channel.

    Returns
    -------
    (H, W, C) float32
        The recolored image in the photograph's linear units. ``kappa = 1`` reproduces the
        photograph up to the decomposition's fit residual.

    Notes
    -----
    Evaluated in Horner form, ``κ(c_0 + κ(c_1 + … κ c_{K-1}))`` plus ``L̄_d`` (Eq. 3-4), tile
    by tile on a few threads so the accumulator stays in cache.

    Examples
    --------
    >>> comps = np.array([[[[1.0]]], [[[0.5]]]], np.float32)  # c_0 = 1, c_1 = 0.5 at one pixel
    >>> d = Decomposition(comps, np.zeros((1, 1, 1), np.float32), np.ones((1, 1), bool))
    >>> float(recolor(d, 2.0)[0, 0, 0])                     # 2·1 + 4·0.5
    4.0
    """
    if not isinstance(decomposition, Decomposition):
        raise InputError(f"decomposition must be an engine.decompose.Decomposition, got {type(decomposition).__name__}")
    k, h, w, c = decomposition.components.shape
    kap = check_kappa(kappa, c)
    comps = decomposition.components.reshape(k, -1)
    unreached = decomposition.unreached.reshape(-1)
    out = np.empty(h * w * c, np.float32)
    tile = _TILE - _TILE % c
    weights = np.tile(kap.astype(np.float32), tile // c)
    overflowed = []

    def run(start: int) -> None:
        stop = min(start + tile, out.size)
        wt = weights[: stop - start]
        acc = out[start:stop]
        with np.errstate(over="ignore", invalid="ignore"):  # checked below, while the tile is in cache
            np.multiply(comps[k - 1, start:stop], wt, out=acc)
            for i in range(k - 2, -1, -1):
                acc += comps[i, start:stop]
                acc *= wt
            acc += unreached[start:stop]
        if not np.isfinite(acc).all():
            overflowed.append(start)

    starts = range(0, out.size, tile)
    if _THREADS > 1 and len(starts) > 1:
        with ThreadPoolExecutor(_THREADS) as pool:
            list(pool.map(run, starts))
    else:
        for s in starts:
            run(s)
    if overflowed:
        raise InputError(
            f"recoloring with kappa {kap.tolist()} at order {k} gives values that are not finite: κ^{k} multiplies "
            "the last interaction component beyond float32's range (or the decomposition holds non-finite "
            "values); use a smaller kappa")
    return out.reshape(h, w, c)


def recolor_variance(decomposition: Decomposition, kappa) -> np.ndarray:
    """Variance of :func:`recolor`'s result, from the decomposition's covariance.

    Parameters
    ----------
    decomposition : Decomposition
        Decomposed with ``covariance=`` (the observations' noise).
    kappa : float or (C,) array_like

    Returns
    -------
    (H, W, C) float32
        ``wᵀ Σ w`` per pixel-channel, ``w_i = κ^{i+1}`` for the target's unknowns
        (Eq. 3) and ``κ^i`` for ``(L̄_d, C R^0 L_d, …)`` off it (Eq. 4): how the noise of
        component i is multiplied by ``κ^{i+1}``.

    Raises
    ------
    InputError
        The decomposition carries no covariance.

    Examples
    --------
    >>> cov = np.array([1.0, 0.0, 4.0], np.float32).reshape(3, 1, 1, 1)  # Var c0 = 1, Var c1 = 4
    >>> d = Decomposition(np.zeros((2, 1, 1, 1), np.float32), np.zeros((1, 1, 1), np.float32),
    ...                   np.ones((1, 1), bool), covariance=cov)
    >>> float(recolor_variance(d, 2.0)[0, 0, 0])          # 2² · 1 + 4² · 4
    68.0
    """
    if not isinstance(decomposition, Decomposition):
        raise InputError(f"decomposition must be an engine.decompose.Decomposition, got {type(decomposition).__name__}")
    if decomposition.covariance is None:
        raise InputError("the decomposition carries no covariance: decompose with covariance= to predict its noise")
    k, h, w, c = decomposition.components.shape
    kap = check_kappa(kappa, c)
    powers = np.arange(k, dtype=np.float64)[:, None]
    inside = kap[None, :] ** (powers + 1)
    outside = kap[None, :] ** powers if decomposition.unreached_light else inside
    weights = np.where(decomposition.target[None, :, :, None], inside[:, None, None, :], outside[:, None, None, :])
    out = np.zeros((h, w, c), np.float64)
    for i in range(k):
        for j in range(k):
            out += weights[i] * weights[j] * decomposition.covariance[packed_index(i, j, k)]
    return out.astype(np.float32)


@dataclass(frozen=True, eq=False)
class PreviewPack:
    """A reduced-resolution copy of a decomposition, ready for fast recoloring.

    Attributes
    ----------
    decomposition : Decomposition
        Area-averaged components at the preview size (target mask: pixels more than half
        covered by the full-resolution target).
    scale : tuple of float
        Full-resolution pixels per preview pixel, ``(sy, sx)``.
    """

    decomposition: Decomposition
    scale: tuple[float, float]

    @property
    def shape(self) -> tuple[int, int]:
        """``(h, w)`` of the preview."""
        return self.decomposition.components.shape[1:3]


def prepare_preview(decomposition: Decomposition, shape: tuple[int, int]) -> PreviewPack:
    """Area-average a decomposition down to at most ``shape`` for the live preview.

    Parameters
    ----------
    decomposition : Decomposition
    shape : (h, w)
        Largest preview size wanted (e.g. the view's size in device pixels). The aspect
        ratio is kept; a decomposition already smaller is used at full resolution.

    Returns
    -------
    PreviewPack
        ``recolor_preview(pack, κ)`` equals the area average of ``recolor(decomposition, κ)``;
        with a covariance, ``recolor_variance(pack.decomposition, κ)`` is the mean of the
        full-resolution pixels' predicted variance (exactly, in blocks wholly on or off the target).
    """
    if not isinstance(decomposition, Decomposition):
        raise InputError(f"decomposition must be an engine.decompose.Decomposition, got {type(decomposition).__name__}")
    try:
        max_h, max_w = (int(v) for v in shape)
    except (TypeError, ValueError):
        raise InputError(f"shape must be (h, w), got {shape!r}") from None
    if max_h < 1 or max_w < 1:
        raise InputError(f"shape must be positive, got {shape!r}")
    k, h, w, c = decomposition.components.shape
    factor = max(1, int(np.ceil(max(h / max_h, w / max_w))))
    if factor == 1:
        return PreviewPack(decomposition, (1.0, 1.0))
    comps = area_average(decomposition.components, factor, axes=(1, 2))
    unreached = area_average(decomposition.unreached, factor)
    target = area_average(decomposition.target.astype(np.float32), factor) > 0.5
    cov = None if decomposition.covariance is None else area_average(decomposition.covariance, factor, axes=(1, 2))
    small = Decomposition(
        comps, unreached, target, decomposition.constraint, decomposition.unreached_light, None, cov
    )
    return PreviewPack(small, (h / target.shape[0], w / target.shape[1]))


def recolor_preview(pack: PreviewPack, kappa) -> np.ndarray:
    """Recolor a :class:`PreviewPack`; same maths as :func:`recolor` on the small copy."""
    return recolor(pack.decomposition, kappa)


def area_average(array: np.ndarray, factor: int, *, axes: tuple[int, int] = (0, 1)) -> np.ndarray:
    """Mean over ``factor``×``factor`` blocks of two consecutive axes; edge blocks average what they hold.

    The preview's reduction: recoloring is linear in the components, so recoloring the
    area-averaged components equals area-averaging the recolored image. Computed as ``factor``
    strided additions per axis (no padded copy of the input), ~20× faster than a padded
    reshape-and-sum on an 8-megapixel K = 4 stack.

    Examples
    --------
    >>> area_average(np.arange(6, dtype=np.float32).reshape(2, 3, 1), 2)[..., 0]
    array([[2. , 3.5]], dtype=float32)
    """
    array = np.asarray(array)
    if factor == 1:
        return array.astype(np.float32, copy=False)
    for axis in axes:
        n = array.shape[axis]
        blocks = -(-n // factor)
        shape = list(array.shape)
        shape[axis] = blocks
        total = np.zeros(shape, np.float32)
        for offset in range(factor):
            part = array[(slice(None),) * axis + (slice(offset, None, factor),)]
            total[(slice(None),) * axis + (slice(0, part.shape[axis]),)] += part
        counts = np.minimum(n - np.arange(blocks) * factor, factor).astype(np.float32)
        total /= counts.reshape((-1,) + (1,) * (array.ndim - axis - 1))
        array = total
    return array
