"""The direct image D of a target: Nayar et al. (2006) high-frequency separation.

Shifted checkerboards light half of the target's projector footprint at a time. Each pixel's
brightest capture ``L⁺`` has its direct light plus half the global light, its darkest ``L⁻``
only the half global light (plus the projector's black level ``b``), so
``L_d = (L⁺ − L⁻) / (1 − b)`` and ``L_g = 2 (L⁻ − b L⁺) / (1 − b²)``. The paper (Sec. 3.3)
models the direct outgoing radiance under projector pattern ``L`` as ``D(x) L(x)`` and
estimates ``D`` as this direct image.

References
----------
S. K. Nayar, G. Krishnan, M. D. Grossberg, R. Raskar, "Fast separation of direct and global
components of a scene using high frequency illumination", ACM TOG 25(3), 2006.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.calibrate._common import Patterns
from engine.checks import check_image, check_images, check_mask, check_resolution, float_dtype
from engine.errors import InputError

__all__ = ["DirectImage", "direct_image", "high_frequency_patterns"]


def high_frequency_patterns(
    projector_resolution,
    *,
    mask_projector=None,
    period: int = 8,
    shifts: int = 2,
) -> Patterns:
    """Return shifted checkerboards, restricted to the target's projector footprint.

    Parameters
    ----------
    projector_resolution : (Hp, Wp)
    mask_projector : (Hp, Wp) bool, optional
        Projector pixels to light (the target's footprint, see
        :func:`engine.calibrate.projector_footprint`); black elsewhere. Default: all.
    period : int
        Checkerboard period in projector pixels (two squares of ``period / 2``); even, ≥ 4.
        Small enough that the global light cannot resolve it, large enough that projector
        blur leaves the square centres fully lit.
    shifts : int
        Shifts per square side along each axis (1 … period / 2). The sequence has
        ``2 · shifts²`` patterns: offsets ``o_i = round(i · s / shifts)``, i in 0 … shifts − 1,
        ``s = period / 2``; x offsets ``o_i`` and ``o_i + s`` (the complements), y offsets ``o_i``.

    Returns
    -------
    Patterns
        Lazy sequence of float32 ``(Hp, Wp, 3)`` images with values 0 and 1 (no linearisation
        needed). Every footprint pixel is lit in exactly half of them and unlit in the other
        half; with ``shifts ≥ 2`` and squares ≥ 3 pixels, each pixel is at least once lit with
        its whole 3×3 neighbourhood lit, and at least once unlit with it unlit.

    Examples
    --------
    >>> seq = high_frequency_patterns((2, 4), period=4, shifts=1)
    >>> len(seq), seq[0][..., 0].astype(int).tolist(), seq[1][..., 0].astype(int).tolist()
    (2, [[1, 1, 0, 0], [1, 1, 0, 0]], [[0, 0, 1, 1], [0, 0, 1, 1]])
    """
    hp, wp = check_resolution("projector_resolution", projector_resolution)
    if isinstance(period, bool) or not isinstance(period, (int, np.integer)) or period < 4 or period % 2:
        raise InputError(f"period must be an even integer ≥ 4 (projector pixels), got {period!r}")
    side = period // 2
    if isinstance(shifts, bool) or not isinstance(shifts, (int, np.integer)) or not 1 <= shifts <= side:
        raise InputError(f"shifts must be an integer in 1..{side} (period / 2), got {shifts!r}")
    mask = None
    if mask_projector is not None:
        mask = np.asarray(mask_projector)
        if mask.dtype != np.bool_ or mask.shape != (hp, wp):
            raise InputError(
                f"mask_projector must be a boolean (Hp, Wp) = {(hp, wp)} mask of projector pixels, "
                f"got dtype {mask.dtype} shape {mask.shape}"
            )
        if not mask.any():
            raise InputError("mask_projector lights no projector pixel; the target's footprint is empty")
    oy = [round(i * side / shifts) for i in range(shifts)]
    ox = oy + [o + side for o in oy]  # the second half are the complements
    combos = [(dx, dy) for dy in oy for dx in ox]
    names = [f"checker period {period} shift x{dx} y{dy}" for dx, dy in combos]
    yy, xx = np.ogrid[:hp, :wp]

    def render(i: int) -> np.ndarray:
        dx, dy = combos[i]
        lit = (((xx + dx) // side + (yy + dy) // side) % 2) == 0
        if mask is not None:
            lit = lit & mask
        out = np.empty((hp, wp, 3), np.float32)
        out[...] = lit[..., None]
        return out

    return Patterns(render, names, (hp, wp))


@dataclass(frozen=True, eq=False)
class DirectImage:
    """Direct/global separation of a target lit by the projector.

    Attributes
    ----------
    direct : (H, W, 3) float32 (float64 for float64 captures)
        ``L_d``: direct radiance under full projector white, projector-off light excluded.
        The paper's D: direct outgoing radiance per unit projector light (Sec. 3.3).
    global_light : (H, W, 3), same dtype
        ``L_g``: light that reached the pixel after other bounces (of the lit area only).
    black_fraction : (3,) float64
        The ``b`` used.
    """

    direct: np.ndarray
    global_light: np.ndarray
    black_fraction: np.ndarray

    @property
    def per_input(self) -> np.ndarray:
        """(H, W, 3): ``(1 − b) L_d = L⁺ − L⁻``, direct light per unit *linearised* input.

        Use this D when the projector shows ``response.linearize(v)`` and the capture with the
        projector at black is subtracted (the acquisition's reference): the direct light then
        changes by ``(1 − b) L_d · v``.
        """
        return self.direct * (1 - self.black_fraction).astype(self.direct.dtype)


def direct_image(captures, *, black_fraction=0.0, ambient=None, target=None) -> DirectImage:
    """Separate direct and global light from captures of :func:`high_frequency_patterns`.

    Parameters
    ----------
    captures : (N, H, W, 3) float or a sequence of N (H, W, 3) float, linear radiance
        One capture per pattern (any order); reduced one at a time, never stacked.
    black_fraction : float or (3,) float
        ``b``, light of an unlit projector pixel relative to a lit one, per camera channel:
        ``ProjectorResponse.black_level``. In [0, 1).
    ambient : (H, W, 3) float, optional
        Capture with the projector off (or covered), subtracted first. None: a dark room.
    target : (H, W) bool, optional
        Camera pixels of the target; outputs are 0 elsewhere.

    Returns
    -------
    DirectImage
        ``direct = (L⁺ − L⁻) / (1 − b)`` and ``global_light = 2 (L⁻ − b L⁺) / (1 − b²)``
        with ``L⁺``/``L⁻`` the per-pixel, per-channel max/min over the captures.

    Raises
    ------
    InputError
        Fewer than 2 captures, mismatched shapes, non-finite values, ``b`` outside [0, 1).

    Notes
    -----
    Nayar et al. 2006, Sec. 3–4, with half the pixels lit (α = ½). Computed in float32 (float64
    if the captures are). The max is biased upward by noise; more shifts average less but
    resolve blur better. The global part only contains light from the lit footprint; light
    from unlit pixels at the black level adds ``2 c / (1 + b)`` to it, nothing to the direct.

    Examples
    --------
    >>> lit = np.full((1, 1, 3), 0.6 + 0.5 * 0.2, np.float32)  # L_d = 0.6, L_g = 0.2, b = 0
    >>> unlit = np.full((1, 1, 3), 0.5 * 0.2, np.float32)
    >>> d = direct_image(np.stack([lit, unlit]))
    >>> round(float(d.direct[0, 0, 0]), 4), round(float(d.global_light[0, 0, 0]), 4)
    (0.6, 0.2)
    """
    caps = check_images("captures", captures, min_count=2)
    dtype = float_dtype(*caps)
    b = np.asarray(black_fraction, dtype=np.float64)
    if b.ndim == 0:
        b = np.full(3, float(b))
    if b.shape != (3,) or not np.all(np.isfinite(b)) or np.any(b < 0) or np.any(b >= 1):
        raise InputError(
            "black_fraction must be a scalar or (3,) in [0, 1) (projector black / white), "
            f"got {np.asarray(black_fraction).tolist()}"
        )
    hi = caps[0].astype(dtype)  # running max/min: one capture in memory at a time
    lo = hi.copy()
    for c in caps[1:]:
        np.maximum(hi, c, out=hi)
        np.minimum(lo, c, out=lo)
    if ambient is not None:
        amb = check_image("ambient", ambient, caps[0].shape).astype(dtype)
        hi -= amb
        lo -= amb
    bb = b.astype(dtype)
    direct = (hi - lo) / (1 - bb)
    glob = 2 * (lo - bb * hi) / (1 - bb * bb)
    if target is not None:
        sel = check_mask("target", target, caps[0].shape[:2])
        direct[~sel] = 0
        glob[~sel] = 0
    return DirectImage(direct.astype(dtype, copy=False), glob.astype(dtype, copy=False), b)
