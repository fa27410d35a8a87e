"""A target's edge: soft masks, and recoloring the pixels that see the target only in part.

A camera pixel on a target's boundary averages two surfaces: a fraction α of its footprint
(its *coverage*) is target, the rest is the neighbour. The paper's method cannot measure such
a pixel — the projector pixel that lights it also lights the neighbour, so re-emitting
``(I ∩ A) / D`` there sends the target's light onto the other surface — and recoloring it as
target or as non-target leaves a seam along every edge. Here the target is a *soft mask*:

* pixels with coverage 1 (*solid*) are the target the projector re-emits (where the
  projector footprint is wholly on it, :func:`engine.acquire.prepare_target`);
* pixels with 0 < α < 1 (*edge*) are not re-emitted; their light is split into the target's
  part and the neighbour's, each recolored with the interaction shares of its own side,
  estimated from nearby solid and nearby outside pixels (as :mod:`engine.fill` does for
  unreachable pixels): :func:`blend_edges`;
* a soft mask comes from a feathered brush, or from the artist's hard mask refined along the
  photograph's edges (:func:`refine_mask`: the compositing equation ``I = α A + (1 − α) B``
  solved per pixel with the two sides' colours sampled nearby).

κ = 1 returns the photograph exactly on edge pixels: their shares sum to 1 on both sides.
"""

from __future__ import annotations

import cv2
import numpy as np

from engine._checks import check_float_image, check_mask
from engine.decompose import Decomposition
from engine.errors import InputError

# Coverages within this distance of 0 or 1 are snapped there (8-bit masks, filter ripple).
SNAP = 1.0 / 64.0


def check_coverage(name: str, coverage, shape: tuple[int, int]) -> np.ndarray:
    """A soft mask as float32 in [0, 1] (a boolean mask becomes 0/1).

    Raises
    ------
    InputError
        Wrong shape, non-finite values or values outside [0, 1].

    Examples
    --------
    >>> check_coverage("m", np.array([[True, False]]), (1, 2)).tolist()
    [[1.0, 0.0]]
    """
    arr = np.asarray(coverage)
    if arr.dtype == np.bool_:
        arr = arr.astype(np.float32)
    if arr.dtype.kind != "f":
        raise InputError(f"{name} must be a boolean mask or float coverage in [0, 1], got dtype {arr.dtype}")
    if arr.shape != tuple(shape):
        raise InputError(f"{name} must have shape {tuple(shape)} (camera pixels), got {arr.shape}")
    if not np.all(np.isfinite(arr)) or arr.min(initial=0) < 0 or arr.max(initial=0) > 1:
        raise InputError(f"{name} coverage must be finite and in [0, 1], got min {np.nanmin(arr):g}, max {np.nanmax(arr):g}")
    return arr.astype(np.float32)


def is_soft(mask) -> bool:
    """Whether ``mask`` is a soft mask with some fractional coverage (not 0/1 only)."""
    arr = np.asarray(mask)
    return arr.dtype.kind == "f" and bool(((arr > 0) & (arr < 1)).any())


def solid(coverage: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels wholly on the target (coverage 1)."""
    return np.asarray(coverage) >= 1.0


def edge(coverage: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels partly on the target (0 < coverage < 1)."""
    c = np.asarray(coverage)
    return (c > 0) & (c < 1)


def refine_mask(mask, photograph, *, radius: int = 3, band: int = 1, contrast: float = 0.05) -> np.ndarray:
    """Refine a hard target mask into coverage along the photograph's edges.

    Parameters
    ----------
    mask : (H, W) bool
        The target as painted (a pixel counts when most of it is target).
    photograph : (H, W, C) float, linear radiance
        A mixed pixel's colour lies between its two surfaces' colours.
    radius : int
        Window radius (pixels) of the two sides' colour estimates.
    band : int
        Only pixels within ``band`` pixels of the mask's boundary are refined; farther ones
        keep 0 or 1.
    contrast : float
        Pixels whose two side colours differ by less than this fraction of their brightness
        cannot be unmixed and keep their painted value.

    Returns
    -------
    (H, W) float32
        Coverage in [0, 1], snapped to exactly 0 or 1 within :data:`SNAP`.

    Notes
    -----
    A pixel mixing two surfaces sees ``I = α A + (1 − α) B`` (the compositing equation; in
    linear radiance it is exact). ``A`` and ``B`` are the mean colours of the painted pixels
    and of the unpainted pixels in the window that are not on the boundary, and
    ``α = ⟨I − B, A − B⟩ / |A − B|²`` is its least-squares solution over the channels: the
    closed-form alpha of the colour-line model (Levin et al. 2008) with the two colours
    sampled locally instead of solved for globally. Exact for flat colours; smooth shading
    biases it by the shading's change across the window.

    Examples
    --------
    >>> img = np.zeros((6, 8, 3), np.float32); img[:, 4:] = 1; img[:, 3] = 0.25
    >>> m = np.zeros((6, 8), bool); m[:, 4:] = True
    >>> refine_mask(m, img)[2, 2:6].tolist()
    [0.0, 0.25, 1.0, 1.0]
    """
    mask = check_mask("mask", mask, np.asarray(mask).shape[:2])
    photo = check_float_image("photograph", photograph, ndim=3)
    if photo.shape[:2] != mask.shape:
        raise InputError(f"photograph must have the mask's shape {mask.shape} (+ channels), got {photo.shape}")
    if int(radius) < 1 or int(band) < 1 or not np.isfinite(contrast) or contrast < 0:
        raise InputError(f"radius and band must be >= 1 and contrast >= 0, got radius={radius!r}, band={band!r}, "
                         f"contrast={contrast!r}")
    m8 = mask.astype(np.uint8)
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    sure_in = cv2.erode(m8, cross, borderType=cv2.BORDER_REPLICATE) > 0
    sure_out = cv2.erode(1 - m8, cross, borderType=cv2.BORDER_REPLICATE) > 0
    kernel = np.ones((2 * int(band) + 1,) * 2, np.uint8)
    near = cv2.dilate(m8, kernel) > cv2.erode(m8, kernel)
    out = mask.astype(np.float32)
    if not near.any():
        return out
    size = (2 * int(radius) + 1,) * 2
    img = np.ascontiguousarray(photo, np.float32)

    def mean(sel):
        n = cv2.boxFilter(sel.astype(np.float32), -1, size, normalize=False, borderType=cv2.BORDER_CONSTANT)
        tot = cv2.boxFilter(np.where(sel[:, :, None], img, 0).astype(np.float32), -1, size, normalize=False,
                            borderType=cv2.BORDER_CONSTANT)
        if tot.ndim == 2:
            tot = tot[:, :, None]
        return tot / np.maximum(n, 1)[:, :, None], n > 0.5

    a, has_a = mean(sure_in)
    b, has_b = mean(sure_out)
    diff = a - b
    d2 = (diff * diff).sum(axis=-1)
    scale = np.maximum((a * a).sum(axis=-1), (b * b).sum(axis=-1))
    ok = near & has_a & has_b & (d2 > contrast**2 * scale) & (d2 > 0)
    alpha = ((img - b) * diff).sum(axis=-1) / np.where(ok, d2, 1.0)
    out[ok] = np.clip(alpha[ok], 0.0, 1.0)
    out[out < SNAP] = 0.0
    out[out > 1.0 - SNAP] = 1.0
    return out


def blend_edges(decomposition: Decomposition, coverage, photograph, *, radius: int = 3) -> tuple[Decomposition, np.ndarray]:
    """Recolor edge pixels as the coverage-weighted mix of the target's side and the neighbour's.

    Parameters
    ----------
    decomposition : Decomposition
        Of the solid target (its ``target`` holds solid pixels only; edge pixels were
        decomposed as non-target).
    coverage : (H, W) float in [0, 1]
        The soft mask.
    photograph : (H, W, C) float
        ``observations[0]``.
    radius : int
        Shares and side radiances come from pixels within this many pixels (square window).

    Returns
    -------
    decomposition : Decomposition
        Edge pixels with components ``I · (w s_A + (1 − w) s_N)`` and unreached light
        ``I (1 − w) s_N,0``; ``target`` unchanged.
    blended : (H, W) bool
        The edge pixels changed (those with target and outside pixels in their window).

    Notes
    -----
    ``s_A`` are the mean interaction shares ``R^i L_d / I`` of the solid target pixels in
    the window, ``s_N`` the mean shares ``(L̄_d, C R^i L_d) / I`` of the outside pixels
    (coverage 0), each renormalised to sum to 1. The pixel's light ``I = α I_A + (1 − α) I_N``
    is split with the two sides' mean radiances ``Ī_A``, ``Ī_N`` in the window:
    ``w = α Ī_A / (α Ī_A + (1 − α) Ī_N)`` per channel. Recoloring then gives
    ``I (w Σ κ^{i+1} s_A,i + (1 − w)(s_N,0 + Σ κ^{i+1} s_N,i+1))`` — Eq. 3 on the target's part
    and Eq. 4 on the neighbour's — and exactly ``I`` at κ = 1.
    """
    if not isinstance(decomposition, Decomposition):
        raise InputError(f"decomposition must be an engine.decompose.Decomposition, got {type(decomposition).__name__}")
    k, h, w, c = decomposition.components.shape
    cov = check_coverage("coverage", coverage, (h, w))
    photo = check_float_image("photograph", photograph, ndim=3)
    if photo.shape != (h, w, c):
        raise InputError(f"photograph must have the decomposition's shape {(h, w, c)}, got {photo.shape}")
    if int(radius) < 1:
        raise InputError(f"radius must be >= 1 pixel, got {radius!r}")
    mixed = edge(cov) & ~decomposition.target
    none = np.zeros((h, w), bool)
    if not mixed.any():
        return decomposition, none
    r = int(radius)
    ys, xs = np.nonzero(mixed)
    rows = slice(max(ys.min() - r, 0), min(ys.max() + r + 1, h))
    cols = slice(max(xs.min() - r, 0), min(xs.max() + r + 1, w))
    light = photo[rows, cols].astype(np.float32)
    positive = (light > 0).all(axis=-1)
    inside = decomposition.target[rows, cols] & positive
    outside = (cov[rows, cols] <= 0) & ~decomposition.target[rows, cols] & positive
    size = (2 * r + 1,) * 2

    def box(x):
        return cv2.boxFilter(np.ascontiguousarray(x, np.float32), -1, size, normalize=False, borderType=cv2.BORDER_CONSTANT)

    n_in, n_out = box(inside), box(outside)
    sel = mixed[rows, cols] & (n_in > 0.5) & (n_out > 0.5)
    if not sel.any():
        return decomposition, none
    vy, vx = np.nonzero(sel)
    safe = np.where(positive[:, :, None], light, 1.0)
    comps = decomposition.components[:, rows, cols]
    # shares of each side, summed over the window: index 0 = unreached light, 1.. = components
    s_in = np.empty((k + 1, len(vy), c), np.float32)
    s_out = np.empty_like(s_in)
    for j in range(k + 1):
        part = decomposition.unreached[rows, cols] if j == 0 else comps[j - 1]
        ratio = (part / safe).astype(np.float32)
        s_in[j] = box(np.where(inside[:, :, None], ratio, 0))[vy, vx]
        s_out[j] = box(np.where(outside[:, :, None], ratio, 0))[vy, vx]
    s_in /= np.maximum(s_in.sum(axis=0), 1e-30)
    s_out /= np.maximum(s_out.sum(axis=0), 1e-30)
    i_in = box(np.where(inside[:, :, None], light, 0))[vy, vx] / n_in[vy, vx, None]
    i_out = box(np.where(outside[:, :, None], light, 0))[vy, vx] / n_out[vy, vx, None]
    alpha = cov[rows, cols][vy, vx][:, None]
    num = alpha * i_in
    wgt = num / np.maximum(num + (1 - alpha) * i_out, 1e-30)
    shares = wgt[None] * s_in + (1 - wgt[None]) * s_out
    pixel = light[vy, vx]
    fy, fx = vy + rows.start, vx + cols.start
    components = decomposition.components.copy()
    unreached = decomposition.unreached.copy()
    components[:, fy, fx] = (pixel[None] * shares[1:]).astype(components.dtype)
    unreached[fy, fx] = (pixel * shares[0]).astype(unreached.dtype)
    residual = decomposition.residual
    if residual is not None:
        residual = residual.copy()
        residual[fy, fx] = 0
    blended = none.copy()
    blended[fy, fx] = True
    return Decomposition(components, unreached, decomposition.target, decomposition.constraint,
                         decomposition.unreached_light, residual), blended
