"""Target pixels the projector cannot re-emit, estimated from their reachable neighbours.

Acquisition leaves out painted target pixels whose projector pixel is unknown, shared with
another surface or too dim to measure (:func:`engine.acquire.prepare_target`): they have no
interaction components of their own and, recolored as if they were not target, keep their
old colour — speckles on a wall, a rim along a corner. On a diffuse surface the *share* of
its light that bounced i times off the target, ``R^i L_d / I``, varies smoothly (it is a
property of the illumination, not of the texture), so a hole pixel takes its neighbours'
shares times its own photograph value: its texture is kept, κ = 1 still returns the
photograph exactly, and recoloring scales it with the rest of the surface.
"""

from __future__ import annotations

import cv2
import numpy as np

from engine._checks import check_float_image, check_mask
from engine.decompose import Decomposition
from engine.errors import InputError


def fill_unreachable(decomposition: Decomposition, painted, photograph, *, radius: int = 3) -> tuple[Decomposition, np.ndarray]:
    """Give painted-but-unreachable pixels inside components estimated from their neighbours.

    Parameters
    ----------
    decomposition : Decomposition
        Decomposed on the reachable part of the target (its ``target``).
    painted : (H, W) bool
        The target as painted (``decomposition.target`` is a subset of it).
    photograph : (H, W, C) float
        ``observations[0]``: the light each hole pixel's shares are applied to.
    radius : int
        Only holes with reachable target pixels within this many pixels (a square window)
        are filled; farther ones (large shadows) stay out, as before.

    Returns
    -------
    decomposition : Decomposition
        ``target`` grown by the filled pixels, where the components are
        ``photograph × (mean share of the reachable neighbours)`` (shares renormalised to sum
        to 1) and the unreached light is zero; elsewhere unchanged.
    filled : (H, W) bool
        The pixels filled.

    Raises
    ------
    InputError
        Shapes that do not match, a painted mask that does not contain the decomposition's
        target, or a negative radius.
    """
    if not isinstance(decomposition, Decomposition):
        raise InputError(f"decomposition must be an engine.decompose.Decomposition, got {type(decomposition).__name__}")
    k, h, w, c = decomposition.components.shape
    painted = check_mask("painted", painted, (h, w))
    photo = check_float_image("photograph", photograph, ndim=3)
    if photo.shape != (h, w, c):
        raise InputError(f"photograph must have the decomposition's shape {(h, w, c)}, got {photo.shape}")
    if int(radius) < 0:
        raise InputError(f"radius must be >= 0 pixels, got {radius!r}")
    reach = decomposition.target
    if (reach & ~painted).any():
        raise InputError("painted must contain the decomposition's target (the reachable part of what was painted)")
    holes = painted & ~reach
    if not holes.any() or not reach.any() or int(radius) == 0:
        return decomposition, np.zeros((h, w), bool)
    comps = decomposition.components.astype(np.float32)
    light = photo.astype(np.float32)
    valid = reach & (light > 0).all(axis=-1)
    weight = valid.astype(np.float32)
    size = (2 * int(radius) + 1,) * 2
    count = cv2.boxFilter(weight, -1, size, normalize=False, borderType=cv2.BORDER_CONSTANT)
    filled = holes & (count > 0.5)
    if not filled.any():
        return decomposition, filled
    shares = np.empty((k, h, w, c), np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        for i in range(k):
            ratio = np.where(valid[:, :, None], comps[i] / np.where(valid[:, :, None], light, 1), 0).astype(np.float32)
            shares[i] = cv2.boxFilter(ratio, -1, size, normalize=False, borderType=cv2.BORDER_CONSTANT)
    total = shares.sum(axis=0)
    filled &= (total > 0).all(axis=-1)
    sel = filled[:, :, None]
    out = comps.copy()
    for i in range(k):
        out[i] = np.where(sel, light * shares[i] / np.where(sel, total, 1), out[i])
    unreached = np.where(filled[:, :, None], 0, decomposition.unreached).astype(decomposition.unreached.dtype)
    residual = decomposition.residual
    if residual is not None:
        residual = np.where(filled, 0, residual).astype(residual.dtype)
    result = Decomposition(out.astype(decomposition.components.dtype), unreached, reach | filled,
                           decomposition.constraint, decomposition.unreached_light, residual)
    return result, filled
