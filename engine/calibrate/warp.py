"""Warps between camera and projector pixels through a :class:`Correspondence`.

Re-emission (paper Sec. 3.3) shows ``(I_{r-1} ∩ A) / D`` from the projector: a camera-space
image turned into the projector image that lights each target point with the wanted value.
The camera→projector map is the correspondence itself (``x``, ``y`` per camera pixel);
its inverse is many-to-one, so projector pixels average the camera pixels that see them.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from engine.calibrate._common import wh
from engine.calibrate.graycode import Correspondence
from engine.checks import check_mask, check_resolution
from engine.errors import InputError

__all__ = [
    "ProjectorMap",
    "estimate_hole_radius",
    "projector_footprint",
    "projector_spread",
    "projector_to_camera_map",
    "spread_patterns",
    "warp_to_camera",
    "warp_to_projector",
]


def _check_correspondence(correspondence, projector_resolution=None) -> Correspondence:
    if not isinstance(correspondence, Correspondence):
        raise InputError(
            f"correspondence must be an engine.calibrate.Correspondence (from decode_gray_code), "
            f"got {type(correspondence).__name__}"
        )
    if projector_resolution is not None:
        res = check_resolution("projector_resolution", projector_resolution)
        if res != correspondence.projector_resolution:
            raise InputError(
                f"projector_resolution is {wh(res)} but the correspondence was decoded for a "
                f"{wh(correspondence.projector_resolution)} projector"
            )
    return correspondence


def _sources(correspondence: Correspondence, target) -> np.ndarray:
    """(H, W) bool: camera pixels that take part (decoded, and in the target if given)."""
    use = correspondence.valid
    if target is not None:
        use = use & check_mask("target", target, correspondence.camera_resolution)
    return use


@dataclass(frozen=True, eq=False)
class ProjectorMap:
    """The projector→camera map: mean camera position of each projector pixel.

    Attributes
    ----------
    u, v : (Hp, Wp) float32
        Mean camera column and row of the camera pixels that see each projector pixel; NaN
        where none does.
    count : (Hp, Wp) int32
        How many camera pixels see each projector pixel (0 = not seen).
    """

    u: np.ndarray
    v: np.ndarray
    count: np.ndarray


def projector_to_camera_map(correspondence: Correspondence, *, target=None) -> ProjectorMap:
    """Invert a correspondence: for every projector pixel, the camera pixels that see it.

    Parameters
    ----------
    correspondence : Correspondence
        Camera→projector map from :func:`decode_gray_code`.
    target : (H, W) bool, optional
        Use only these camera pixels.

    Returns
    -------
    ProjectorMap
        Averaged camera coordinates (many camera pixels can see one projector pixel).

    Examples
    --------
    >>> c = Correspondence.from_maps(np.array([[0, 0, 1]]), np.zeros((1, 3), int), np.ones((1, 3), bool), (1, 2))
    >>> m = projector_to_camera_map(c)
    >>> m.u.tolist(), m.count.tolist()
    ([[0.5, 2.0]], [[2, 1]])
    """
    corr = _check_correspondence(correspondence)
    use = _sources(corr, target)
    hp, wp = corr.projector_resolution
    idx = (corr.y[use].astype(np.int64) * wp + corr.x[use]).ravel()
    vv, uu = np.nonzero(use)
    count = np.bincount(idx, minlength=hp * wp)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = (np.bincount(idx, weights=uu, minlength=hp * wp) / count).astype(np.float32)
        v = (np.bincount(idx, weights=vv, minlength=hp * wp) / count).astype(np.float32)
    return ProjectorMap(u.reshape(hp, wp), v.reshape(hp, wp), count.reshape(hp, wp).astype(np.int32))


def estimate_hole_radius(correspondence: Correspondence, *, target=None) -> int:
    """Radius (projector pixels) of the gaps between projector pixels hit by the camera.

    A camera coarser than the projector leaves projector pixels that no camera pixel sees;
    their spacing is estimated from neighbouring camera pixels (90th percentile of the
    projector-space step), and half of it, rounded up, closes the gaps.

    Examples
    --------
    >>> estimate_hole_radius(Correspondence.identity((4, 4)))
    1
    """
    corr = _check_correspondence(correspondence)
    use = _sources(corr, target)
    x, y = corr.x.astype(np.float32), corr.y.astype(np.float32)
    step_parts = []
    for axis in (0, 1):
        a = [slice(None)] * 2
        b = [slice(None)] * 2
        a[axis], b[axis] = slice(1, None), slice(None, -1)
        both = use[tuple(a)] & use[tuple(b)]
        d = np.maximum(np.abs(x[tuple(a)] - x[tuple(b)]), np.abs(y[tuple(a)] - y[tuple(b)]))
        step_parts.append(d[both])
    steps = np.concatenate(step_parts)
    if steps.size == 0:
        return 1
    return max(1, int(np.ceil(np.percentile(steps, 90) / 2)))


def projector_footprint(correspondence: Correspondence, *, target=None, radius: int | None = None) -> np.ndarray:
    """Projector pixels that light the target: pixels seen by the camera, gaps closed.

    Parameters
    ----------
    correspondence : Correspondence
    target : (H, W) bool, optional
        Camera pixels of the target; default all decoded pixels.
    radius : int, optional
        Closing radius in projector pixels; default :func:`estimate_hole_radius`. Gaps narrower than
        ``2 · radius`` between seen projector pixels are part of the footprint.

    Returns
    -------
    (Hp, Wp) bool
        Use as ``mask_projector`` of :func:`high_frequency_patterns`.

    Examples
    --------
    >>> c = Correspondence.from_maps(np.array([[0, 2]]), np.zeros((1, 2), int), np.ones((1, 2), bool), (1, 5))
    >>> projector_footprint(c).astype(int).tolist()
    [[1, 1, 1, 0, 0]]
    """
    corr = _check_correspondence(correspondence)
    hit = projector_to_camera_map(corr, target=target).count > 0
    r = estimate_hole_radius(corr, target=target) if radius is None else _check_radius(radius)
    return hit | (_close(hit, r) & ~_lights_elsewhere(corr, target))


#: Captures :func:`spread_patterns` takes (two complementary pairs per axis).
SPREAD_CAPTURES = 8


def spread_patterns(footprint) -> list[np.ndarray]:
    """Eight white stripe patterns that measure how camera pixels straddle projector pixels.

    Parameters
    ----------
    footprint : (Hp, Wp) bool
        Projector pixels that light the target (:func:`projector_footprint`); black elsewhere.

    Returns
    -------
    list of (Hp, Wp, 3) float32
        Per axis (columns, then rows), two complementary pairs of stripes: pixels of even index
        and their complement, pixels of index ``≡ 1, 2 (mod 4)`` and their complement. Read
        the captures back with :func:`projector_spread`.

    Examples
    --------
    >>> p = spread_patterns(np.ones((1, 4), bool))
    >>> [q[0, :, 0].tolist() for q in p[:4]]
    [[1.0, 0.0, 1.0, 0.0], [0.0, 1.0, 0.0, 1.0], [0.0, 1.0, 1.0, 0.0], [1.0, 0.0, 0.0, 1.0]]
    """
    fp = np.asarray(footprint, bool)
    if fp.ndim != 2:
        raise InputError(f"footprint must be an (Hp, Wp) projector mask, got shape {fp.shape}")
    rows, cols = np.indices(fp.shape)
    out = []
    for index in (cols, rows):
        for lit in (index % 2 == 0, (index % 4 == 1) | (index % 4 == 2)):
            for part in (lit, ~lit):
                out.append(np.repeat((part & fp)[:, :, None], 3, axis=2).astype(np.float32))
    return out


#: A measured share of a camera pixel's direct light below this is taken as none: the global light of two
#: complementary one-pixel stripes is not quite the same, and makes up to 7.3 % on co-axial rigs, where every
#: share is 0 or 1 (ideal supersampled Cornell box, 128², hard mask; 6.8 % on the realistic rig).
SPREAD_FLOOR = 0.1


def projector_spread(correspondence: Correspondence, pixels, direct, lights, *, footprint=None,
                     variance=None) -> np.ndarray:
    """How each camera pixel's direct light divides among the 3×3 projector pixels round its own.

    A camera pixel decodes one projector pixel (the one its centre falls in), but its footprint,
    seen from a posed projector, straddles up to four: the light it receives is a weighted mean
    of theirs, not its own projector pixel's alone.

    Parameters
    ----------
    correspondence : Correspondence
    pixels : (H, W) bool
        Camera pixels to give weights (decoded ones only).
    direct : (H, W, C) float
        Their direct light under the footprint wholly lit, per camera channel (D, with the
        footprint's projector pixels alone lit, as :func:`spread_patterns` light them).
    lights : sequence of 8 (H, W, C) float
        Captures of :func:`spread_patterns`, the projector-black light removed.
    footprint : (Hp, Wp) bool, optional
        The projector pixels the patterns lit: weights on others are dropped.
    variance : sequence of 8 (H, W, C) float, optional
        The captures' noise variance: a share within two standard deviations of zero is none.

    Returns
    -------
    (H, W, 3, 3) float32
        ``[y, x, 1 + dy, 1 + dx]``: the fraction of pixel (y, x)'s direct light from projector
        pixel ``(py + dy, px + dx)``, ``(py, px)`` its decode; each pixel's sum is 1. Pixels
        without weights (not decoded, no direct light) have all of it on ``(py, px)``.

    Notes
    -----
    Along each axis a pixel of decode ``p`` takes shares ``l, o, r`` of its light from ``p − 1,
    p, p + 1``. A pair of complementary patterns lights the sets ``S`` and ``S̄``; their
    captures differ by ``D (2 m − 1)``, ``m`` the share from ``S`` (the global light of two
    complementary one-pixel stripes is the same: it cannot resolve them). Even indices give
    ``o`` (or ``1 − o`` for an odd ``p``); indices ``≡ 1, 2 (mod 4)`` give one of ``l``, ``r``
    (which one depends on ``p mod 4``), and the third is the rest. Shares below
    :data:`SPREAD_FLOOR` (or within noise) count as none; the two axes' shares multiply (the
    footprint is taken as separable), dropped off the footprint, and sum to 1. A co-axial
    projector (of the camera's resolution, or coarser by an integer) gives each pixel its own
    projector pixel alone.

    Examples
    --------
    >>> c = Correspondence.identity((4, 4))
    >>> fp = np.ones((4, 4), bool)
    >>> d = np.ones((4, 4, 1), np.float32)
    >>> caps = [q[:, :, :1] for q in spread_patterns(fp)]   # each camera pixel sees its own projector pixel
    >>> float(projector_spread(c, np.ones((4, 4), bool), d, caps)[1, 2, 1, 1])
    1.0
    """
    corr = _check_correspondence(correspondence)
    pixels = check_mask("pixels", pixels, corr.camera_resolution)
    d = np.asarray(direct, np.float64)
    if d.shape[:2] != corr.camera_resolution or len(lights) != SPREAD_CAPTURES:
        raise InputError(f"direct must be {corr.camera_resolution} (+ channels) and lights {SPREAD_CAPTURES} "
                         f"captures of spread_patterns, got {d.shape} and {len(lights)}")
    h, w = corr.camera_resolution
    out = np.zeros((h, w, 3, 3), np.float32)
    out[..., 1, 1] = 1.0
    total = d.reshape(h, w, -1).sum(-1)
    ys, xs = np.nonzero(pixels & corr.valid & (total > 0))
    if not len(ys):
        return out
    dsum = total[ys, xs]

    def share(i):  # fraction of the light from the first pattern of pair i, and its standard deviation
        diff = (np.asarray(lights[2 * i], np.float64) - np.asarray(lights[2 * i + 1], np.float64))[ys, xs]
        m = 0.5 * (1.0 + diff.reshape(len(ys), -1).sum(-1) / dsum)
        if variance is None:
            return m, np.zeros(len(ys))
        var = (np.asarray(variance[2 * i], np.float64) + np.asarray(variance[2 * i + 1], np.float64))[ys, xs]
        return m, 0.5 * np.sqrt(var.reshape(len(ys), -1).sum(-1)) / dsum

    axes = []
    for a, p in enumerate((corr.x[ys, xs], corr.y[ys, xs])):
        (even, s_even), (mid, s_mid) = share(2 * a), share(2 * a + 1)
        own = np.where(p % 2 == 0, even, 1.0 - even)
        k = p % 4
        right = np.where(k == 0, mid, np.where(k == 1, mid - own, 0.0))
        left = np.where(k == 3, mid, np.where(k == 2, mid - own, 0.0))
        right = np.where((k == 2) | (k == 3), 1.0 - own - left, right)
        left = np.where((k == 0) | (k == 1), 1.0 - own - right, left)
        noise = 2.0 * np.hypot(s_even, s_mid)
        shares = np.stack([left, own, right], -1)
        shares[(shares < SPREAD_FLOOR) | (shares < noise[:, None])] = 0.0
        shares[:, 1] = np.where(shares.sum(-1) > 0, shares[:, 1], 1.0)
        axes.append(shares / shares.sum(-1, keepdims=True))
    weights = axes[1][:, :, None] * axes[0][:, None, :]  # [n, 1 + dy, 1 + dx]
    if footprint is not None:
        fp = np.asarray(footprint, bool)
        if fp.shape != corr.projector_resolution:
            raise InputError(f"footprint must have the projector's shape {corr.projector_resolution}, got {fp.shape}")
        hp, wp = fp.shape
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                qy, qx = corr.y[ys, xs] + dy, corr.x[ys, xs] + dx
                on = (qy >= 0) & (qy < hp) & (qx >= 0) & (qx < wp)
                on &= fp[np.clip(qy, 0, hp - 1), np.clip(qx, 0, wp - 1)]
                weights[:, dy + 1, dx + 1] *= on
    norm = weights.sum((1, 2))
    keep = norm > 0
    out[ys[keep], xs[keep]] = (weights[keep] / norm[keep, None, None]).astype(np.float32)
    return out


def _lights_elsewhere(corr: Correspondence, target) -> np.ndarray:
    """(Hp, Wp) bool: projector pixels decoded by a camera pixel outside ``target``.

    Such a pixel is known to light another surface: filling a hole of the target's footprint
    with it would spill the target's (often strong, ``I / D`` on a grazing surface) light there.
    """
    hp, wp = corr.projector_resolution
    if target is None:
        return np.zeros((hp, wp), bool)
    other = corr.valid & ~check_mask("target", target, corr.camera_resolution)
    out = np.zeros((hp, wp), bool)
    out[corr.y[other], corr.x[other]] = True
    return out


def _check_radius(radius) -> int:
    if isinstance(radius, bool) or not isinstance(radius, (int, np.integer)) or radius < 0:
        raise InputError(f"hole_radius must be an integer ≥ 0 (projector pixels), got {radius!r}")
    return int(radius)


def _close(hit: np.ndarray, r: int) -> np.ndarray:
    if r == 0:
        return hit.copy()
    k = cv2.getStructuringElement(cv2.MORPH_RECT, (2 * r + 1, 2 * r + 1))
    # Pad so the closing neither grows nor shrinks the footprint at the image border.
    padded = cv2.copyMakeBorder(hit.view(np.uint8), r, r, r, r, cv2.BORDER_REPLICATE)
    closed = cv2.morphologyEx(padded, cv2.MORPH_CLOSE, k)
    return closed[r:-r, r:-r].astype(bool)


def warp_to_projector(
    camera_image,
    correspondence: Correspondence,
    projector_resolution=None,
    *,
    target=None,
    fill_holes: bool = True,
    hole_radius: int | None = None,
) -> np.ndarray:
    """Turn a camera-space image into the projector image that re-emits it.

    Parameters
    ----------
    camera_image : (H, W, C) or (H, W) float
        Values per camera pixel (e.g. ``I / D`` on the target), any sign, not clipped.
    correspondence : Correspondence
        Camera→projector map from :func:`decode_gray_code`.
    projector_resolution : (Hp, Wp), optional
        Checked against the correspondence's when given.
    target : (H, W) bool, optional
        Camera pixels to re-emit; default every decoded pixel. Other pixels are ignored.
    fill_holes : bool
        Give projector pixels inside the target's footprint that no camera pixel sees the
        average of their seen neighbours (within ``hole_radius``). Pixels outside the
        footprint stay 0.
    hole_radius : int, optional
        Default :func:`estimate_hole_radius` of the correspondence.

    Returns
    -------
    (Hp, Wp, C) or (Hp, Wp) float32
        Projector image; the average of the camera pixels that see each projector pixel, 0
        where nothing is to be emitted. Not clipped and not linearised: scale, then pass
        through :meth:`ProjectorResponse.linearize`.

    Notes
    -----
    Camera pixels that are not decoded cannot be re-emitted; find them with
    ``correspondence.missing(target)`` and report them.

    Examples
    --------
    >>> c = Correspondence.from_maps(np.array([[0, 0, 2]]), np.zeros((1, 3), int), np.ones((1, 3), bool), (1, 4))
    >>> warp_to_projector(np.array([[1.0, 3.0, 5.0]], np.float32), c).tolist()
    [[2.0, 3.5, 5.0, 0.0]]
    """
    corr = _check_correspondence(correspondence, projector_resolution)
    img = np.asarray(camera_image)
    if img.dtype.kind != "f":
        raise InputError(f"camera_image must be a floating-point image, got dtype {img.dtype}")
    if img.shape[:2] != corr.camera_resolution or img.ndim not in (2, 3):
        raise InputError(
            f"camera_image must have shape {corr.camera_resolution} or {corr.camera_resolution + ('C',)} "
            f"(the correspondence's camera), got {img.shape}"
        )
    if not np.all(np.isfinite(img)):
        raise InputError("camera_image contains NaN or inf; expected finite values")
    plane = img.ndim == 2
    img3 = img[..., None] if plane else img
    use = _sources(corr, target)
    hp, wp = corr.projector_resolution
    idx = (corr.y[use].astype(np.int64) * wp + corr.x[use]).ravel()
    count = np.bincount(idx, minlength=hp * wp).reshape(hp, wp)
    hit = count > 0
    vals = img3[use]
    out = np.zeros((hp, wp, img3.shape[2]), np.float32)
    with np.errstate(invalid="ignore", divide="ignore"):
        for c in range(img3.shape[2]):
            s = np.bincount(idx, weights=vals[:, c], minlength=hp * wp).reshape(hp, wp)
            out[..., c] = np.where(hit, s / count, 0.0)
    if fill_holes and hit.any():
        r = estimate_hole_radius(corr, target=target) if hole_radius is None else _check_radius(hole_radius)
        holes = _close(hit, r) & ~hit & ~_lights_elsewhere(corr, target)
        if r > 0 and holes.any():
            size = (2 * r + 1, 2 * r + 1)
            w = cv2.boxFilter(hit.astype(np.float32), -1, size, normalize=False, borderType=cv2.BORDER_CONSTANT)
            for c in range(out.shape[2]):
                total = cv2.boxFilter(out[..., c], -1, size, normalize=False, borderType=cv2.BORDER_CONSTANT)
                out[..., c][holes] = total[holes] / w[holes]  # w > 0: every closed pixel is within r of a hit
    return out[..., 0] if plane else out


def warp_to_camera(projector_image, correspondence: Correspondence, *, fill: float = 0.0) -> np.ndarray:
    """Sample a projector-space image at every camera pixel's projector pixel.

    Parameters
    ----------
    projector_image : (Hp, Wp, C) or (Hp, Wp) float
    correspondence : Correspondence
    fill : float
        Value for camera pixels without a projector pixel.

    Returns
    -------
    (H, W, C) or (H, W) float32
        What each camera pixel's surface point receives from the projector.

    Examples
    --------
    >>> c = Correspondence.from_maps(np.array([[1, 0]]), np.zeros((1, 2), int), np.array([[True, False]]), (1, 2))
    >>> warp_to_camera(np.array([[7.0, 9.0]]), c, fill=-1).tolist()
    [[9.0, -1.0]]
    """
    corr = _check_correspondence(correspondence)
    img = np.asarray(projector_image)
    if img.dtype.kind != "f":
        raise InputError(f"projector_image must be a floating-point image, got dtype {img.dtype}")
    if img.shape[:2] != corr.projector_resolution or img.ndim not in (2, 3):
        raise InputError(
            f"projector_image must have shape {corr.projector_resolution}[+ (C,)] (the correspondence's "
            f"projector), got {img.shape}"
        )
    ok = corr.valid
    out = img[np.where(ok, corr.y, 0), np.where(ok, corr.x, 0)].astype(np.float32)
    out[~ok] = np.float32(fill)
    return out
