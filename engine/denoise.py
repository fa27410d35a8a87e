"""Denoising interaction components by their low-pass nature (paper Sec. 6, Discussion).

Light that reached a pixel after interacting with the target is diffuse interreflection:
spatially smooth, except where the surface's albedo or the geometry changes — and those edges
are visible in the photograph. Noise, by contrast, is white, and recoloring multiplies the
noise of component i by κ^{i+1}. Filtering the interreflection components with an
edge-preserving guided filter (He et al. 2013) whose guide is the photograph removes noise
and keeps texture and surface boundaries. Inside and outside the target are filtered
separately. What the filter takes from a component is given back to the term that is not
filtered (R^0 L_d inside, L̄_d outside), so ``recolor(·, κ = 1)`` is unchanged.
"""

from __future__ import annotations

import cv2
import numpy as np

from engine._checks import check_float_image
from engine.decompose import Decomposition
from engine.errors import InputError


def denoise_components(decomposition: Decomposition, photograph, *, radius: int = 4, eps: float = 1e-3) -> Decomposition:
    """Return a decomposition whose interreflection components are guided-filtered.

    Parameters
    ----------
    decomposition : Decomposition
    photograph : (H, W, C) float, linear radiance
        The guide (``observations[0]``); its log is used so edges count by contrast.
    radius : int
        Filter radius in pixels.
    eps : float
        Guided-filter regulariser on the log guide's variance: edges with log-contrast well
        above ``sqrt(eps)`` are kept.

    Returns
    -------
    Decomposition
        Inside components 1..K-1 and outside interaction components filtered; inside
        component 0 and the unreached light absorb the difference, so the per-pixel sum
        (the photograph's fit, κ = 1) is unchanged. Without unreached light the first
        outside component absorbs it instead and is not filtered.

    Notes
    -----
    Measured on the realistic virtual Cornell box (128×128, κ = (2, 0.125, 8), 16 frames):
    relative error 7.5 % → 4.1 % at 3rd order and 12.3 % → 6.6 % at 4th order.
    """
    if not isinstance(decomposition, Decomposition):
        raise InputError(f"decomposition must be an engine.decompose.Decomposition, got {type(decomposition).__name__}")
    k, h, w, c = decomposition.components.shape
    photo = check_float_image("photograph", photograph, ndim=3)
    if photo.shape != (h, w, c):
        raise InputError(f"photograph must have the decomposition's shape {(h, w, c)}, got {photo.shape}")
    if int(radius) < 1 or not np.isfinite(eps) or eps <= 0:
        raise InputError(f"radius must be >= 1 and eps > 0, got radius={radius!r}, eps={eps!r}")
    target = decomposition.target
    inside = target[:, :, None]
    comps = decomposition.components.astype(np.float32, copy=True)
    unreached = decomposition.unreached.astype(np.float32, copy=True)
    guide = np.log(np.maximum(photo, 1e-6 * max(float(photo.max()), 1e-30))).astype(np.float32)
    first_outside = 0 if decomposition.unreached_light else 1
    for i in range(k):
        regions = []
        if i >= 1:
            regions.append(target)
        if i >= first_outside and i < decomposition.outside_order:
            regions.append(~target)
        if not regions:
            continue
        smoothed = comps[i].copy()
        for region in regions:
            smoothed = np.where(region[:, :, None], _filter_region(comps[i], guide, region, int(radius), float(eps)), smoothed)
        delta = smoothed - comps[i]
        comps[i] = smoothed
        comps[0] -= np.where(inside, delta, 0)  # inside: R^0 L_d absorbs the change
        if decomposition.unreached_light:
            unreached -= np.where(inside, 0, delta)
        elif i > 0:
            comps[0] -= np.where(inside, 0, delta)
    dtype = decomposition.components.dtype
    return Decomposition(
        comps.astype(dtype), unreached.astype(dtype), decomposition.target, decomposition.constraint,
        decomposition.unreached_light, decomposition.residual,
    )


def _filter_region(component: np.ndarray, guide: np.ndarray, region: np.ndarray, radius: int, eps: float) -> np.ndarray:
    """Guided filter of each channel, normalised so pixels outside ``region`` do not leak in."""
    w = region.astype(np.float32)
    out = np.empty(component.shape, np.float32)
    for ch in range(component.shape[-1]):
        g = guide[..., ch] * w
        num = cv2.ximgproc.guidedFilter(g, component[..., ch].astype(np.float32) * w, radius, eps)
        den = cv2.ximgproc.guidedFilter(g, w, radius, eps)
        out[..., ch] = np.where(den > 1e-3, num / np.maximum(den, 1e-3), component[..., ch])
    return out
