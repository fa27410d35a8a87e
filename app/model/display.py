"""Display conversions for the canvas: linear radiance to packed 32-bit screen pixels.

The live preview converts a screen-sized float image per slider event, so the conversion is
one compiled pass (numba) that applies the exposure, looks the sRGB curve up in the same
65536-entry table as :func:`engine.imageio.to_display` (bit-identical results) and packs
``0xFFRRGGBB`` words that a ``QImage.Format_RGB32`` wraps without a copy.

Clipping to [0, 1] happens here and only here, for display (see :func:`engine.imageio.to_display`).
False-colour maps (difference and error views) are here too.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from itertools import pairwise

import numba
import numpy as np

from engine.checks import check_float_image
from engine.errors import InputError
from engine.imageio import srgb_encode

_LUT = np.round(srgb_encode(np.arange(65536, dtype=np.float64) / 65535.0) * 255.0).astype(np.uint8)


@numba.njit(cache=True, nogil=True, inline="always")
def _pack_row(idx, lut, dst, w):  # pragma: no cover - compiled
    """One row of 0xFFRRGGBB words from 16-bit sRGB table indices (R, G, B interleaved)."""
    for j in range(w):
        r = np.uint32(lut[idx[3 * j]])
        g = np.uint32(lut[idx[3 * j + 1]])
        b = np.uint32(lut[idx[3 * j + 2]])
        dst[j] = np.uint32(0xFF000000) | (r << np.uint32(16)) | (g << np.uint32(8)) | b


@numba.njit(cache=True, nogil=True)
def _pack_srgb(image, scale, lut, out):  # pragma: no cover - compiled
    h, w = out.shape
    n3 = 3 * w
    idx = np.empty(n3, np.int32)
    lo, hi, half = np.float32(0.0), np.float32(65535.0), np.float32(0.5)
    for i in range(h):
        src = image[i].reshape(n3)
        for x in range(n3):
            # 16-bit table index of x·scale, clipped, rounded half to even like np.rint:
            # v + 0.5 is exact in float32 below 2**23, and a tie is an integer v + 0.5
            v = min(max(src[x] * scale, lo), hi) + half
            t = np.int32(v)
            idx[x] = t - ((t & 1) & np.int32(np.float32(t) == v))
        _pack_row(idx, lut, out[i], w)


def to_rgb32(image: np.ndarray, *, exposure: float = 0.0, out: np.ndarray | None = None) -> np.ndarray:
    """Pack linear radiance into ``0xFFRRGGBB`` words through exposure and the sRGB curve.

    Parameters
    ----------
    image : (H, W, 3) float32
        Linear radiance.
    exposure : float
        Stops: the image is multiplied by ``2**exposure`` first.
    out : (H, W) uint32, optional
        Destination (reused between frames to avoid allocations).

    Returns
    -------
    (H, W) uint32
        Same 8-bit values as ``engine.imageio.to_display(image, exposure=exposure)``.

    Examples
    --------
    >>> hex(int(to_rgb32(np.array([[[1.0, 0.18, 0.0]]], np.float32))[0, 0]))
    '0xffff7600'
    """
    if not isinstance(image, np.ndarray) or image.ndim != 3 or image.shape[2] != 3 or image.dtype.kind != "f":
        raise InputError(f"image must be a (H, W, 3) float array, got {getattr(image, 'shape', None)} "
                         f"{getattr(image, 'dtype', type(image).__name__)}")
    if not np.isfinite(exposure):
        raise InputError(f"exposure must be a finite number of stops, got {exposure!r}")
    h, w = image.shape[:2]
    if out is None:
        out = np.empty((h, w), np.uint32)
    elif out.shape != (h, w) or out.dtype != np.uint32 or not out.flags.c_contiguous:
        raise InputError(f"out must be ({h}, {w}) uint32, got {out.shape} {out.dtype}")
    img = np.ascontiguousarray(image, dtype=np.float32)
    _pack_srgb(img, np.float32(2.0**exposure * 65535.0), _LUT, out)
    return out


@numba.njit(cache=True, nogil=True)
def _recolor_rows(comps, unreached, weights, scale, lut, out, r0, r1):  # pragma: no cover - compiled
    k, _, w, _ = comps.shape
    n3 = 3 * w
    acc = np.empty(n3, np.float32)
    idx = np.empty(n3, np.int32)
    wt = np.empty(n3, np.float32)
    for x in range(n3):
        wt[x] = weights[x % 3]
    lo, hi, half = np.float32(0.0), np.float32(65535.0), np.float32(0.5)
    for i in range(r0, r1):
        # engine.recolor's Horner order, in float32: κ(c_0 + κ(c_1 + … κ c_{K-1})) + L̄_d;
        # contiguous row loops, so they vectorise
        top = comps[k - 1, i].reshape(n3)
        for x in range(n3):
            acc[x] = top[x] * wt[x]
        for n in range(k - 2, -1, -1):
            row = comps[n, i].reshape(n3)
            for x in range(n3):
                acc[x] = (acc[x] + row[x]) * wt[x]
        unr = unreached[i].reshape(n3)
        for x in range(n3):  # to_rgb32's table index (see _pack_srgb)
            v = min(max((acc[x] + unr[x]) * scale, lo), hi) + half
            t = np.int32(v)
            idx[x] = t - ((t & 1) & np.int32(np.float32(t) == v))
        _pack_row(idx, lut, out[i], w)


_POOL: ThreadPoolExecutor | None = None
_THREADS = max(1, min(2, os.cpu_count() or 1))


def recolor_rgb32(decomposition, kappa, *, exposure: float = 0.0) -> np.ndarray:
    """Recolor and convert for display in one pass: the live preview's hot path.

    Same float32 arithmetic, in the same order, as :func:`engine.recolor.recolor` followed by
    :func:`to_rgb32` — the result is bit-identical — but without the float image in between,
    on row bands in a few threads (the kernel releases the GIL).

    Parameters
    ----------
    decomposition : engine.decompose.Decomposition
        Usually a :class:`engine.recolor.PreviewPack`'s small copy; float32, 3 channels.
    kappa : float or (3,)
    exposure : float
        Display exposure in stops.

    Returns
    -------
    (H, W) uint32
        ``0xFFRRGGBB`` words.
    """
    from engine.checks import check_kappa

    comps = np.ascontiguousarray(decomposition.components, dtype=np.float32)
    unreached = np.ascontiguousarray(decomposition.unreached, dtype=np.float32)
    if comps.ndim != 4 or comps.shape[3] != 3:
        raise InputError(f"decomposition components must be (K, H, W, 3), got {comps.shape}")
    if not np.isfinite(exposure):
        raise InputError(f"exposure must be a finite number of stops, got {exposure!r}")
    weights = check_kappa(kappa, 3).astype(np.float32)
    h, w = comps.shape[1:3]
    out = np.empty((h, w), np.uint32)
    scale = np.float32(2.0**exposure * 65535.0)
    bands = np.linspace(0, h, _THREADS + 1).astype(int)
    if _THREADS == 1 or h < 64:
        _recolor_rows(comps, unreached, weights, scale, _LUT, out, 0, h)
        return out
    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(_THREADS, thread_name_prefix="albedit-display")
    jobs = [_POOL.submit(_recolor_rows, comps, unreached, weights, scale, _LUT, out, int(a), int(b))
            for a, b in pairwise(bands)]
    for j in jobs:
        j.result()
    return out


def rgb32_to_rgb(words: np.ndarray) -> np.ndarray:
    """Unpack ``0xFFRRGGBB`` words to (H, W, 3) uint8 (tests, PNG export of a view)."""
    w = np.asarray(words, np.uint32)
    return np.stack([(w >> 16) & 255, (w >> 8) & 255, w & 255], axis=-1).astype(np.uint8)


def rgb_to_rgb32(rgb: np.ndarray) -> np.ndarray:
    """Pack (H, W, 3) uint8 into ``0xFFRRGGBB`` words."""
    c = np.asarray(rgb, np.uint32)
    return (np.uint32(0xFF000000) | (c[..., 0] << 16) | (c[..., 1] << 8) | c[..., 2]).astype(np.uint32)


def _ramp(anchors) -> np.ndarray:
    a = np.asarray(anchors, np.float64)
    x = np.linspace(0.0, 1.0, len(a))
    t = np.linspace(0.0, 1.0, 256)
    return np.stack([np.interp(t, x, a[:, c]) for c in range(3)], axis=-1).round().astype(np.uint8)


#: Sequential map for magnitudes (black → purple → orange → pale yellow, inferno-like).
MAGNITUDE_MAP = _ramp([(0, 0, 4), (40, 11, 84), (101, 21, 110), (159, 42, 99), (212, 72, 66),
                       (245, 125, 21), (250, 193, 39), (252, 255, 164)])
#: Diverging map for signed differences: blue (darker) ← black (equal) → orange (brighter).
SIGNED_MAP = _ramp([(120, 200, 255), (40, 110, 230), (15, 35, 90), (0, 0, 0), (95, 35, 10),
                    (235, 110, 30), (255, 215, 120)])

#: Rec. 709 luminance weights of linear RGB.
LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)


def false_colour(values: np.ndarray, lo: float, hi: float, cmap: np.ndarray) -> np.ndarray:
    """Map scalar values linearly from [lo, hi] onto a 256-entry colour map, as RGB32 words.

    Values outside [lo, hi] take the end colours (display only).

    Examples
    --------
    >>> rgb32_to_rgb(false_colour(np.array([[0.0, 1.0]]), 0.0, 1.0, MAGNITUDE_MAP))[0].tolist()
    [[0, 0, 4], [252, 255, 164]]
    """
    v = np.asarray(values, np.float32)
    if not hi > lo:
        raise InputError(f"false-colour range must have hi > lo, got [{lo}, {hi}]")
    idx = np.clip((v - np.float32(lo)) * np.float32(255.0 / (hi - lo)), 0.0, 255.0)
    np.rint(idx, out=idx)
    return rgb_to_rgb32(cmap[idx.astype(np.uint8)])


def robust_max(values: np.ndarray, *, percentile: float = 99.5) -> float:
    """A scale for false colour: the ``percentile`` of |values| (never 0).

    Examples
    --------
    >>> robust_max(np.array([0.0, 0.0]))
    1e-06
    """
    a = np.abs(np.asarray(values, np.float32)).ravel()
    if a.size > 1_000_000:  # a strided sample is plenty for a display scale
        a = a[:: a.size // 1_000_000 + 1]
    s = float(np.percentile(a, percentile)) if a.size else 0.0
    return s if s > 0 else 1e-6


def luminance(image: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance (H, W) float32 of linear RGB (H, W, 3)."""
    img = check_float_image("image", image, ndim=3)
    return img.astype(np.float32, copy=False) @ LUMA
