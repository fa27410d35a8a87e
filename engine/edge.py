"""A target's edge: soft masks, and recoloring the pixels that see the target only in part.

A camera pixel on a target's boundary averages two surfaces: a fraction α of its footprint
(its *coverage*) is target, the rest is the neighbour. The paper's method cannot measure such
a pixel — the projector pixel that lights it also lights the neighbour, so re-emitting
``(I ∩ A) / D`` there sends the target's light onto the other surface — and recoloring it as
target or as non-target leaves a seam along every edge. Here the target is a *soft mask*:

* pixels with coverage 1 (*solid*) are the target the projector re-emits (where the
  projector footprint is wholly on it, :func:`engine.acquire.prepare_target`);
* pixels with 0 < α < 1 (*edge*) are not re-emitted; their light — measured by the
  re-emissions around it, the target's part one interaction late — is split into the target's
  part (the target's components extrapolated to the strip of it in the pixel, or, beside a
  textured target, the pixel's light less the neighbour's by radiance) and the
  neighbour's (the rest): :func:`blend_edges`; under noise, the neighbour's interaction shares
  are fitted along the edge, where they vary slowly (its ``along``);
* the emitted pixels next to the edge also emit the edge's target part (:func:`stand_in`), so
  that the observations hold about the interreflections of the whole target Eq. 6 assumes;
* a soft mask comes from the rig's true coverage, or from the artist's hard mask refined along the
  photograph's edges (:func:`refine_mask`: the compositing equation ``I = α A + (1 − α) B``
  solved per pixel with the two sides' colours extrapolated from nearby pixels).

κ = 1 returns the photograph exactly on edge pixels.
"""

from __future__ import annotations

import cv2
import numpy as np

from engine.checks import check_float_image, check_mask
from engine.decompose import Decomposition
from engine.errors import InputError

#: Outside pixels whose mean radiance is at most this fraction of an edge pixel's own, in every channel,
#: are a void (no surface): :func:`blend_edges` then takes all of the pixel's light as the target's.
VOID = 1e-3

#: The target's texture beside an edge pixel (:func:`_texture`) up to which :func:`blend_edges` takes the pixel's
#: target part from the strip (the solid pixels extrapolated), and from which it takes the radiance split's,
#: linearly between.
TEXTURE = (0.03, 0.06)
#: The same for the spread of the strip's extrapolations along the 8 directions over their mean (:func:`_strip`).
SPREAD = (0.2, 0.4)
#: Edge pixels with no solid or no outside pixel within ``radius`` try a window this many times wider.
REACH = 3
#: The 8 directions :func:`refine_mask` samples each side's colour along.
DIRECTIONS = ((0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1))
#: Steps along a direction read for a linear extrapolation, the nearest two first (:func:`_steps`).
PAIRS = ((1, 2), (2, 3), (1, 3))
#: How much worse (relative squared residual of the compositing equation) a pair of side colours may explain a
#: pixel than the best pair and still count in :func:`refine_mask`'s coverage: ``e``-fold less per this much.
RESIDUAL = 1e-3
#: Boundary pixels :func:`refine_mask` unmixes at a time (64 colour pairs each: ~13 MB an array).
CHUNK = 1 << 13


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
        raise InputError(
            f"{name} coverage must be finite and in [0, 1], got min {np.nanmin(arr):g}, max {np.nanmax(arr):g}"
        )
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


def stand_in(coverage, emitted, *, radius: int = 2) -> np.ndarray:
    """How much more each emitted pixel re-emits, to stand in for the target it borders that cannot be.

    Parameters
    ----------
    coverage : (H, W) float in [0, 1]
        The soft mask (a hard mask as 0/1): how much of each pixel is target.
    emitted : (H, W) bool
        The pixels the projector re-emits (solid, reachable).
    radius : int
        Target pixels not emitted hand their coverage to emitted pixels within this many
        pixels (a square window); farther ones (a large shadow) are not stood in for.

    Returns
    -------
    (H, W) float32
        ``b ≥ 0`` on emitted pixels, 0 elsewhere: emitting ``(1 + b) I / D`` there instead of
        ``I / D`` sends into the scene, from next to the edge, about the light the edge's target
        part would have sent.

    Notes
    -----
    Eq. 6 holds when the *whole* target re-emits its light; the target's part of an edge
    pixel (and a painted pixel the projector cannot reach) re-emits nothing, so every
    observation lacks the interreflections its light would have caused — most at the solid
    pixels next to it, which makes their observations inconsistent with Eq. 6. A strip of
    target next to an emitted pixel has about that pixel's radiance and form factors, so its
    share ``c_q`` (coverage not emitted) of pixel q is given to the nearest emitted pixels s
    (those of the first ring round q that has any) in proportion to ``1 / |s − q|²``:
    ``b(s) = Σ_q c_q |s − q|⁻² / Σ_{s'} |s' − q|⁻²``. The
    extra direct light this puts on s is known (``b I``) and taken out of the capture
    (:meth:`engine.acquire.emission.Emitter.shortfall`); what stays is the strip's
    interreflections, displaced by a pixel or two. The emitter does not dim the whole pattern to
    make room for the raised light (which costs signal against
    the camera noise); what passes the peak is emitted in a capture of its own
    (:class:`engine.acquire.emission.Emitter`).

    Examples
    --------
    >>> cov = np.array([[1, 1, 0.5, 0]], np.float32)
    >>> stand_in(cov, cov >= 1).tolist()
    [[0.0, 0.5, 0.0, 0.0]]
    """
    emitted = np.asarray(emitted, bool)
    cov = check_coverage("coverage", coverage, emitted.shape)
    if int(radius) < 1:
        raise InputError(f"radius must be >= 1 pixel, got {radius!r}")
    missing = np.where(emitted, 0.0, cov).astype(np.float32)
    out = np.zeros(cov.shape, np.float32)
    for r in range(1, int(radius) + 1):  # the nearest ring of emitted pixels takes it
        yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
        dist2 = (yy * yy + xx * xx).astype(np.float32)
        kernel = np.where(dist2 > 0, 1.0 / np.maximum(dist2, 1.0), 0.0).astype(np.float32)
        norm = cv2.filter2D(emitted.astype(np.float32), -1, kernel, borderType=cv2.BORDER_CONSTANT)
        given = norm > 1e-6
        per_weight = np.where(given, missing / np.where(given, norm, 1.0), 0.0).astype(np.float32)
        out += cv2.filter2D(per_weight, -1, kernel, borderType=cv2.BORDER_CONSTANT)
        missing = np.where(given, 0.0, missing).astype(np.float32)
    return np.where(emitted, out, 0.0).astype(np.float32)


def unblended(decomposition: Decomposition, coverage) -> np.ndarray:
    """(H, W) bool: the edge pixels :func:`blend_edges` left as non-target.

    Edge pixels (0 < coverage < 1) neither decomposed as target nor blended: no wholly-target
    pixel within ``3 radius`` pixels (a stray feathered stroke, a feather wider than the
    blend's window), or a window inside the frame with wholly-target pixels but no outside one.
    Recoloring scales them as the neighbour (Eq. 4), so callers report them.

    Examples
    --------
    >>> from engine.decompose import Decomposition
    >>> d = Decomposition(np.zeros((1, 1, 3, 1), np.float32), np.zeros((1, 3, 1), np.float32),
    ...                   np.array([[True, False, False]]))
    >>> unblended(d, np.array([[1, 0.5, 0.5]], np.float32)).tolist()
    [[False, True, True]]
    """
    if not isinstance(decomposition, Decomposition):
        raise InputError(f"decomposition must be an engine.decompose.Decomposition, got {type(decomposition).__name__}")
    cov = check_coverage("coverage", coverage, decomposition.shape[:2])
    left = edge(cov) & ~decomposition.target
    return left if decomposition.blended is None else left & ~decomposition.blended


def refine_mask(mask, photograph, *, contrast: float = 0.05, snap: float = 0.1, claimed=None) -> np.ndarray:
    """Refine a hard target mask into coverage along the photograph's edges.

    Parameters
    ----------
    mask : (H, W) bool
        The target as painted (a pixel counts when most of it is target).
    photograph : (H, W, C) float, linear radiance
        A mixed pixel's colour lies between its two surfaces' colours.
    contrast : float
        Pixels whose two side colours differ by less than this fraction of their brightness
        cannot be unmixed and keep their painted value.
    snap : float
        Coverages within ``snap`` of 0 or 1 become exactly 0 or 1 (a pixel that is almost
        all target is re-emitted; shading gradients at concave corners look like a little
        mixing).
    claimed : (H, W) float in [0, 1] or bool, optional
        How much of each pixel other targets already cover (their coverages summed). The
        result never exceeds ``1 − claimed``: two touching targets refined one after the
        other share their boundary pixels instead of both claiming them (a cascade refuses
        coverages that sum past 1).

    Returns
    -------
    (H, W) float32
        Coverage in [0, 1]; only pixels on the mask's boundary (either side) change, and
        pixels others claim.

    Notes
    -----
    A pixel mixing two surfaces sees ``I = α A + (1 − α) B`` (the compositing equation; in
    linear radiance it is exact), and ``α = ⟨I − B, A − B⟩ / |A − B|²`` is its least-squares
    solution over the channels: the closed-form alpha of the colour-line model (Levin et al.
    2008) with the two colours sampled locally instead of solved for globally. Each side offers
    a colour along each of the 8 directions ``d``: the linear extrapolation to the pixel of the
    nearest two of ``p + d, p + 2d, p + 3d`` on that side and not on the boundary (e.g.
    ``2 I(p + d) − I(p + 2d)``; extrapolating rather than averaging removes most of the bias of
    shading gradients, which interreflections make steep at concave corners). Every pair of an
    inside and an outside colour gives an α; the pair whose compositing residual
    ``|I − α A − (1 − α) B|²`` (relative to ``max(|A|², |B|²)``) is least explains the pixel
    best, and α is the mean over pairs weighted by ``exp(−(r − r_min) / RESIDUAL)``. A
    direction that crosses a texture's edge, a third surface at a corner or an occluder
    extrapolates a colour the pixel does not hold and drops out, where the former mean over
    directions kept it. Measured against the rigs' true coverage (sum over pixels of the
    squared coverage error, before → after): ideal supersampled ``virtual:textured`` 128²
    1.30 → 0.25, ``virtual:cornell`` right wall 128² 0.99 → 0.03, with camera noise (one
    frame) 1.15 → 0.19; path-traced ``mitsuba:cornell`` 64² at 1024 spp 1.11 → 0.38,
    ``mitsuba:textured`` 48² 1.65 → 0.22. Exact for flat or linearly shaded colours.

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
    if not np.isfinite(contrast) or contrast < 0 or not np.isfinite(snap) or not 0 <= snap < 0.5:
        raise InputError(f"contrast must be >= 0 and snap in [0, 0.5), got contrast={contrast!r}, snap={snap!r}")
    room = None
    if claimed is not None:
        room = 1.0 - check_coverage("claimed", claimed, mask.shape)
    m8 = mask.astype(np.uint8)
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    sure_in = cv2.erode(m8, cross, borderType=cv2.BORDER_REPLICATE) > 0
    sure_out = cv2.erode(1 - m8, cross, borderType=cv2.BORDER_REPLICATE) > 0
    square = np.ones((3, 3), np.uint8)
    near = cv2.dilate(m8, square) > cv2.erode(m8, square)
    out = mask.astype(np.float32)
    if not near.any():
        return out if room is None else np.minimum(out, room)
    ys, xs = np.nonzero(near)
    for start in range(0, ys.size, CHUNK):  # the pairs' arrays are 64 per pixel: bounded memory
        y, x = ys[start:start + CHUNK], xs[start:start + CHUNK]
        alpha, ok = _unmix(photo, sure_in, sure_out, y, x, contrast)
        out[y[ok], x[ok]] = alpha[ok]
    out[out <= snap] = 0.0
    out[out >= 1.0 - snap] = 1.0
    return out if room is None else np.minimum(out, room)


def _unmix(img: np.ndarray, sure_in: np.ndarray, sure_out: np.ndarray, ys: np.ndarray, xs: np.ndarray,
           contrast: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`refine_mask`'s coverage at pixels ``(ys, xs)`` of the photograph ``img``, and where it has one.

    Every pair of an inside and an outside colour (:func:`_side_colours`) whose colours differ by more than
    ``contrast`` gives its least-squares α; the pairs are weighted by how well they explain the pixel.
    """
    pixel = img[ys, xs].astype(np.float64)
    a, has_a = _side_colours(img, sure_in, ys, xs)
    b, has_b = _side_colours(img, sure_out, ys, xs)
    diff = a[:, None] - b[None]  # (8, 8, N, C)
    d2 = (diff * diff).sum(axis=-1)
    scale = np.maximum((a * a).sum(axis=-1)[:, None], (b * b).sum(axis=-1)[None])
    good = has_a[:, None] & has_b[None] & (d2 > contrast**2 * scale) & (d2 > 0)
    alpha = np.clip(((pixel - b[None]) * diff).sum(axis=-1) / np.where(good, d2, 1.0), 0.0, 1.0)
    miss = pixel - b[None] - alpha[..., None] * diff
    residual = np.where(good, (miss * miss).sum(axis=-1) / np.where(good, scale, 1.0), np.inf)
    ok = good.any(axis=(0, 1))
    best = np.where(ok, residual.min(axis=(0, 1)), 0.0)
    weight = np.exp(-(residual - best) / RESIDUAL)  # 0 for the pairs that are not good (an infinite residual)
    return (weight * alpha).sum(axis=(0, 1)) / np.where(ok, weight.sum(axis=(0, 1)), 1.0), ok


def _steps(region: np.ndarray, ys: np.ndarray, xs: np.ndarray, d: tuple[int, int]) -> dict:
    """The pixels 1, 2 and 3 steps from ``(ys, xs)`` along ``d``: ``{i: (rows, columns, on region)}``.

    Off the frame counts as off the region (rows and columns clipped into it).
    """
    h, w = region.shape
    out = {}
    for i in (1, 2, 3):
        py, px = ys + i * d[0], xs + i * d[1]
        inside = (py >= 0) & (py < h) & (px >= 0) & (px < w)
        py, px = np.clip(py, 0, h - 1), np.clip(px, 0, w - 1)
        out[i] = (py, px, inside & region[py, px])
    return out


def _side_colours(img: np.ndarray, sure: np.ndarray, ys: np.ndarray, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One side's colour at pixels ``(ys, xs)`` along each of the 8 directions (:func:`refine_mask`).

    ``img`` is the photograph, ``sure`` the side's pixels not on the boundary.
    Along a direction ``d``: the linear extrapolation of the nearest two of ``p + d, p + 2d,
    p + 3d`` on the side; a pixel with no such pair along any direction (the frame's edge, a
    sliver one pixel wide) takes instead the nearest one along each direction.

    Returns
    -------
    (8, N, C) float64, (8, N) bool
        The colours, and which directions have one.
    """
    colours, found = np.zeros((8, ys.size, img.shape[-1])), np.zeros((8, ys.size), bool)
    along = []
    for k, d in enumerate(DIRECTIONS):
        at = _steps(sure, ys, xs, d)
        on = {i: q[2] for i, q in at.items()}
        val = {i: img[q[0], q[1]].astype(np.float64) for i, q in at.items()}
        along.append((on, val))
        for i, j in PAIRS:
            take = on[i] & on[j] & ~found[k]
            colours[k, take] = val[i][take] + (val[i][take] - val[j][take]) * (i / (j - i))
            found[k] |= take
    alone = ~found.any(axis=0)
    for k, (on, val) in enumerate(along):
        for i in (1, 2, 3):  # the nearest one along d
            take = alone & on[i] & ~found[k]
            colours[k, take] = val[i][take]
            found[k] |= take
    return colours, found


def blend_edges(
    decomposition: Decomposition, coverage, photograph, *, radius: int = 1, along: int = 0, smoothed: bool = False
) -> tuple[Decomposition, np.ndarray]:
    """Recolor edge pixels: their target part as target, their neighbour's part as non-target.

    Parameters
    ----------
    decomposition : Decomposition
        Of the solid target (its ``target`` holds solid pixels only; edge pixels were not
        re-emitted and were decomposed as non-target, Eq. 9).
    coverage : (H, W) float in [0, 1]
        The soft mask.
    photograph : (H, W, C) float
        ``observations[0]``.
    radius : int
        Edge pixels with solid and outside pixels within this many pixels (square window)
        are blended; where the target does not line up with one, the neighbour's interaction
        shares and both sides' radiances come from that window (1 = the 8 neighbours, the
        least biased near concave corners, where shares change fast).
    along : int
        Noise reduction along the edge: the neighbour's interaction shares of each blended
        pixel are fitted to the blended pixels within this many pixels (square window)
        whose edge faces the same way (least squares, below); 0 (the default) leaves every
        pixel's own.
    smoothed : bool
        Whether the edge pixels' decomposition was noise-reduced with the pixels around them
        (:meth:`engine.acquire.PreparedTarget.decompose` filters before the blend): each then
        mixes the neighbour's light and shares into its ``F``, which the radiance split's target
        part would take whole, so edge pixels keep the strip wherever it exists (below).

    Returns
    -------
    decomposition : Decomposition
        Edge pixels re-packed so that recoloring scales their target part as target
        (Eq. 3) and their neighbour's part as non-target (Eq. 4), and marked in its
        ``blended``; ``target`` unchanged.
    blended : (H, W) bool
        The edge pixels changed: those with solid and outside pixels in their window, and those
        whose window the frame cuts off before any outside pixel (below). The edge pixels left
        as non-target, for callers to report, are :func:`unblended`: no solid pixel within
        ``3 radius`` pixels (or K = 1).

    Notes
    -----
    A target point that is not re-emitted is measured exactly, shifted by one interaction:
    re-emitting ``I_{r-1}`` on the rest of the target gives it
    ``Σ_n binom(n+r-1, r) R^n L_d`` (Eq. 6 without the emitted direct term), which is Eq. 9
    with ``L̄_d = R^0 L_d`` and ``C R^m L_d = R^{m+1} L_d``. So an edge pixel's non-target
    decomposition ``F = (L̄_d, C R^0 L_d, …)`` is the sum of its target part's components
    (shifted) and its neighbour's, and only the split is unknown. The target part is
    ``α R^i L_d`` of the strip of target the pixel holds, ``R^i L_d`` extrapolated linearly
    from the decomposed target pixels beyond the edge (Eq. 9 there, two in a line along each
    of the 8 directions, averaged) to the strip's centre, ``(1 − α) / 2`` pixel from the
    pixel's centre towards the target; the neighbour's part is the rest of ``F`` (the target
    part is clipped to ``[0, F]``). Interreflections make those components steepest at a
    concave corner, where edges often are: on the ideal supersampled Cornell box (128²,
    κ = (2, 0.125, 8)) the wall with its edge is at 1.48× its interior this way, against 7.0×
    taking the neighbour's part from the shares of the outside pixels around (the radiance
    split, below), which change as fast there but are not measured as well (the outside
    pixels' observations miss the edge strip's re-emission, which the stand-in only sends from
    a pixel away). But a linear extrapolation misses a *textured* target's own albedo in the
    strip (a checker's jump across the two pixels it reads, or in the strip itself) by tens of
    percent, and it multiplies the noise of the two pixels it reads; the radiance split reads
    the neighbour instead. So each edge pixel takes ``(1 − s)`` of the strip's target part and
    ``s`` of the split's, ``s`` the larger of two ramps: the target's texture around the pixel,
    :func:`_texture` ``τ`` (what a quadratic trend leaves of the photograph of the target
    pixels within 2 pixels), from 0 at ``τ`` = :data:`TEXTURE` [0] = 0.03 to 1 at 0.06; and how
    far the strip's directions disagree (the spread of its 8 extrapolations over their mean:
    noise, or a texture the quadratic follows), from 0 at :data:`SPREAD` [0] = 0.2 to 1 at 0.4.
    Shading is smooth over a few pixels: beside the ideal Cornell box's wall ``τ ≤ 0.034``
    (48², 0.013 at 128²) and the spread ≤ 0.17 with true coverage, so its edge pixels keep the
    strip (one pixel of 25 has ``s > 0`` at 48²); beside Fig. 12's checker wall (48²) ``τ`` has
    a median of 0.07 and 33 of its 48 edge pixels take the split wholly. With true coverage,
    κ = (2, 0.125, 1.2), edge pixels (those with coverage < 1 or next to them): the ideal
    supersampled textured wall (``virtual:textured``) 2.60 → 1.42 % at 48², 2.40 → 1.18 % at 64²,
    1.56 → 0.99 % at 128² (the split alone 1.75, 1.29, 1.06 %), the wall with its edge from
    8.9× to 4.9× its interior at 48²; path-traced at 512 spp (``mitsuba:textured``, 48², against
    the mean of 4 truth renders) 6.38 → 4.36 % (the split alone 3.44 %). The ideal Cornell box
    does not change (48², 64², 128², true or refined coverage, κ = (0.5, 1.2, 0.8) and
    (2, 0.125, 8): edge pixels within 0.1 %), nor the path-traced one (48², 512 spp; 64², 1024
    spp). With ``smoothed`` (noise reduction before the blend) the split is not taken: the
    filter, which reduces the edge pixels' noise by smoothing them with the pixels around them
    (path-traced Cornell box, 64², 1024 spp, κ = (2, 0.125, 8), radius 3: edge pixels 11.6 →
    6.4 %), mixes the neighbour's shares into ``F``, and the split's target part took them whole
    (at 48², radius 4: the ideal textured wall 3.22 → 3.92 %, the ideal Cornell box's refined mask
    11.2 → 13.6 %; the path-traced box at 32², 32 spp, 13.4 → 29.8 %). Where no
    two target pixels line up with the edge pixel, the neighbour's part is ``(1 − w) I s_N``,
    with ``s_N`` the mean shares ``(L̄_d, C R^i L_d) / I`` of the lit outside pixels
    (coverage 0) in the window, renormalised to sum to 1, and ``w`` the target's share of
    the pixel's light from the coverage and the two sides' mean radiances ``Ī_A``, ``Ī_N``
    (dark outside pixels count: against the void, ``w = 1``):
    ``w = α Ī_A / (α Ī_A + (1 − α) Ī_N)`` per channel; the target part is the rest of ``F``
    (clipped at 0). ``F`` is first scaled to sum to ``I``, so κ = 1 gives ``I`` exactly.
    Against a void — the outside pixels around hold no light, their mean radiance at most
    :data:`VOID` (10⁻³) of the pixel's own in every channel — ``w = 1`` is exact and the target
    part is the whole ``F``: the strip's extrapolation would miss a textured target's own
    albedo by tens of percent and recolor the difference as neighbour light the void does not
    have. An edge pixel whose window (at ``3 radius``) holds solid pixels but no outside pixel
    because the frame cuts it off borders what lies beyond the frame, which the camera never
    saw: its whole ``F`` is the target part too (before, such a pixel was left as non-target).
    On the path-traced textured wall at 512 spp (true coverage, κ = (2, 0.125, 1.2), Fig. 12) the 7 edge
    pixels against the void go from 82 % to 2.3 % error (the pixel at the frame's border from
    216 % to 1 %), all edge pixels from 16.8 to 7.5 %, the wall from 5.0 to 2.9 %; the ideal
    Cornell box, whose edges have lit neighbours, does not change.
    With ``along``, the neighbour's part keeps its total but takes the shares
    ``s_j = Σ_q T(q) part_j(q) / Σ_q T(q)²`` of the blended pixels q near it along the edge
    (``T`` the neighbour part's light; :func:`_along_edge`): its noise is the noisiest
    observations' (an edge pixel is not re-emitted), multiplied by ``κ^{m+1}``.
    Recoloring multiplies the target part's ``L̄_d`` by κ and its ``C R^m L_d`` by
    ``κ^{m+2}`` (Eq. 3), the neighbour's as Eq. 4. The target part's K-th interaction
    (beyond the K-1 outside components) is not represented.
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
    if isinstance(along, bool) or not isinstance(along, (int, np.integer)) or along < 0:
        raise InputError(f"along must be a whole number of pixels >= 0, got {along!r}")
    todo = edge(cov) & ~decomposition.target
    blended = np.zeros((h, w), bool)
    # edge pixels with no solid or no outside pixel that close (slivers) try a wider window; those whose
    # widest window the frame cuts off before any outside pixel border what lies beyond it (``beyond``)
    wide = REACH * int(radius)
    for r, beyond in ((int(radius), False), (wide, False), (wide, True)):
        if not (todo & ~blended).any() or k < 2:
            break
        decomposition, done = _blend(decomposition, cov, photo, r, todo & ~blended, int(along), beyond,
                                     bool(smoothed))
        blended |= done
    return decomposition, blended


def _blend(
    decomposition: Decomposition, cov, photo, r: int, mixed, along: int, beyond: bool, smoothed: bool
) -> tuple[Decomposition, np.ndarray]:
    """:func:`blend_edges` of the pixels ``mixed`` with a ``(2r+1)²`` window.

    With ``beyond``, only the pixels whose window holds solid pixels, no outside pixel, and is cut
    off by the frame, each taken as bordering a void beyond the frame.
    """
    k, h, w, c = decomposition.components.shape
    none = np.zeros((h, w), bool)
    ys, xs = np.nonzero(mixed)
    rows = slice(max(ys.min() - r, 0), min(ys.max() + r + 1, h))
    cols = slice(max(xs.min() - r, 0), min(xs.max() + r + 1, w))
    light = photo[rows, cols].astype(np.float32)
    positive = (light > 0).all(axis=-1)
    inside = decomposition.target[rows, cols] & positive
    # the neighbour's radiance counts dark pixels too (a target against the void has none);
    # its shares need light to be measured
    around = (cov[rows, cols] <= 0) & ~decomposition.target[rows, cols]
    outside = around & positive
    size = (2 * r + 1,) * 2

    def box(x):
        return cv2.boxFilter(
            np.ascontiguousarray(x, np.float32), -1, size, normalize=False, borderType=cv2.BORDER_CONSTANT
        )

    n_in, n_around = box(inside), box(around)
    if beyond:
        yy, xx = np.mgrid[rows, cols]
        cut = (yy < r) | (yy >= h - r) | (xx < r) | (xx >= w - r)  # the window reaches past the frame
        sel = mixed[rows, cols] & (n_in > 0.5) & (n_around < 0.5) & cut
    else:
        sel = mixed[rows, cols] & (n_in > 0.5) & (n_around > 0.5)
    if not sel.any():
        return decomposition, none
    vy, vx = np.nonzero(sel)
    safe = np.where(positive[:, :, None], light, 1.0)
    unreached = decomposition.unreached[rows, cols]
    comps = decomposition.components[:, rows, cols]
    # the neighbour's shares: index 0 = unreached light, 1.. = C R^i L_d
    s_out = np.empty((k, len(vy), c), np.float32)
    for j in range(k):
        part = unreached if j == 0 else comps[j - 1]
        s_out[j] = box(np.where(outside[:, :, None], part / safe, 0))[vy, vx]
    s_out /= np.maximum(s_out.sum(axis=0), 1e-30)
    i_in = box(np.where(inside[:, :, None], light, 0))[vy, vx] / n_in[vy, vx, None]
    i_out = box(np.where(around[:, :, None], light, 0))[vy, vx] / np.maximum(n_around[vy, vx, None], 1)
    alpha = np.broadcast_to(cov[rows, cols][vy, vx][:, None], i_in.shape)
    # the two sides' light is non-negative; where neither has any, the coverage alone decides
    num = alpha * np.maximum(i_in, 0)
    den = num + (1 - alpha) * np.maximum(i_out, 0)
    wgt = np.divide(num, den, out=alpha.astype(np.float64), where=den > 0)
    pixel = light[vy, vx]
    own = np.concatenate([unreached[None, vy, vx], comps[: k - 1, vy, vx]]).astype(np.float64)
    # F sums to I: rescaled where both are light, else the difference goes to the unreached light.
    # (A pixel lit only by re-emitted differences or noise may hold no light or negative light:
    # under a cascade's emission on a later target an earlier target's edge is mostly dark;
    # a floored division there once turned F into ~1e22 and its shares swamped the image.)
    total = own.sum(axis=0)
    fits = (total > 0) & (pixel > 0)
    own *= np.where(fits, pixel / np.where(fits, total, 1.0), 1.0)[None]
    own[0] += np.where(fits, 0.0, pixel - total)
    target_part = np.maximum(own - (1 - wgt)[None] * pixel[None] * s_out, 0)
    fy, fx = vy + rows.start, vx + cols.start
    lit = decomposition.target & (photo > 0).all(axis=-1)
    strip, found, spread = _strip(decomposition.components, lit, cov, fy, fx)
    # against a void (the outside pixels around hold no light, or the frame cuts them off) all the
    # pixel's light is the target's: its whole F, exactly, not the strip's extrapolation
    void = np.full(len(vy), bool(beyond)) | ((pixel > 0) & (np.abs(i_out) <= VOID * pixel)).all(axis=-1)
    # where the target reaches the edge in a line, its part is the strip's own components (never more
    # than the pixel holds, so that the neighbour's part stays non-negative and κ = 1 gives I) where the
    # target is smooth and the strip's directions agree; the split's where it is textured or they do not
    if smoothed:  # F mixes the neighbour's shares: the split's target part would take them whole
        split = np.zeros((1, len(vy), 1))
    else:
        texture = _texture(photo, decomposition.target, fy, fx)
        split = np.maximum(_ramp(texture, TEXTURE), _ramp(spread, SPREAD))[None, :, None]
    strip = np.clip(strip, 0, np.maximum(own, 0))
    strip_at = found & ~void
    target_part[:, strip_at] = ((1 - split) * strip + split * target_part)[:, strip_at]
    target_part[:, void] = own[:, void]
    other = own - target_part
    if along:
        other = _along_edge(other, cov, fy, fx, along)
    packed = np.zeros((k, len(vy), c))
    packed[0] = target_part[0]  # the target part's direct light: κ^1
    for m in range(k - 1):
        packed[m + 1] += target_part[m + 1]  # its m+1-th interaction: κ^{m+2}
        packed[m] += other[m + 1]  # the neighbour's C R^m L_d: κ^{m+1}
    components = decomposition.components.copy()
    new_unreached = decomposition.unreached.copy()
    components[:, fy, fx] = packed.astype(components.dtype)
    new_unreached[fy, fx] = other[0].astype(new_unreached.dtype)
    residual = decomposition.residual
    if residual is not None:
        residual = residual.copy()
        residual[fy, fx] = 0
    blended = none.copy()
    blended[fy, fx] = True
    return Decomposition(
        components,
        new_unreached,
        decomposition.target,
        decomposition.constraint,
        decomposition.unreached_light,
        residual,
        decomposition.covariance,  # an edge pixel keeps its unknowns' variance: its light is only re-divided
        blended if decomposition.blended is None else decomposition.blended | blended,
        decomposition.observed,
    ), blended


def _strip(components, inside, cov, ys, xs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The target part of edge pixels ``(ys, xs)``: ``α`` times the target's components extrapolated to the strip.

    Parameters
    ----------
    components : (K, H, W, C) float
        The decomposition's components (the target's ``R^i L_d`` on ``inside``).
    inside : (H, W) bool
        Decomposed target pixels that can be extrapolated from (lit).
    cov : (H, W) float
        Coverage.
    ys, xs : (N,) int
        The edge pixels.

    Returns
    -------
    part : (K, N, C) float64
        ``α c̃_i`` with ``c̃_i`` the mean over the 8 directions ``d`` of the linear extrapolation of
        ``R^i L_d`` from two decomposed pixels along ``d`` (the nearest of ``q + d, q + 2d, q + 3d``)
        to the target strip's centre, which lies ``(1 − α) / 2`` pixel from ``q``'s centre towards the
        target: from ``p_1 = q + d`` it is ``(1 + α) / 2`` pixel away.
    found : (N,) bool
        Edge pixels with at least one such pair.
    spread : (N,) float64
        How far the directions disagree: the standard deviation over ``d`` of the extrapolated
        light ``Σ_i c̃_i`` over its mean (RMS over channels); 0 where fewer than two directions have a pair.
    """
    k, _, _, c = components.shape
    alpha = cov[ys, xs].astype(np.float64)
    total = np.zeros((k, len(ys), c))
    square = np.zeros((len(ys), c))  # Σ_d (Σ_i c̃_i)², for the spread
    count = np.zeros(len(ys))
    for d in DIRECTIONS:
        at = _steps(inside, ys, xs, d)
        done = np.zeros(len(ys), bool)
        for i, j in PAIRS:
            ok = at[i][2] & at[j][2] & ~done
            if not ok.any():
                continue
            near = components[:, at[i][0][ok], at[i][1][ok]].astype(np.float64)
            far = components[:, at[j][0][ok], at[j][1][ok]].astype(np.float64)
            reach = (i - 1 + (1 + alpha[ok]) / 2) / (j - i)  # from p_i to the strip, in steps p_i − p_j
            extrapolated = near + (near - far) * reach[None, :, None]
            total[:, ok] += extrapolated
            square[ok] += extrapolated.sum(axis=0) ** 2
            count += ok
            done |= ok
    found = count > 0
    mean = total / np.maximum(count, 1)[None, :, None]
    light = mean.sum(axis=0)
    deviation = np.maximum(square - count[:, None] * light**2, 0).sum(axis=-1) / np.maximum(count - 1, 1)
    power = (light**2).sum(axis=-1)
    spread = np.where((count > 1) & (power > 0), np.sqrt(deviation / np.where(power > 0, power, 1.0)), 0.0)
    return alpha[None, :, None] * mean, found, spread


def _ramp(x: np.ndarray, bounds: tuple[float, float]) -> np.ndarray:
    """0 up to ``bounds[0]``, 1 from ``bounds[1]``, linear between."""
    return np.clip((x - bounds[0]) / (bounds[1] - bounds[0]), 0, 1)


def _texture(photo, inside, ys, xs, radius: int = 2) -> np.ndarray:
    """How textured the target is next to edge pixels ``(ys, xs)``: what a quadratic trend leaves of its photograph.

    Parameters
    ----------
    photo : (H, W, C) float
        The photograph.
    inside : (H, W) bool
        The decomposed target pixels.
    ys, xs : (N,) int
        The edge pixels.
    radius : int
        Half-size of the square window around each edge pixel whose target pixels are fitted.

    Returns
    -------
    (N,) float64
        ``τ = sqrt((Σ r² / (n − p)) / (Σ I² / n))``: the residuals ``r`` of a least-squares fit of
        ``1, y, x, y², x², xy`` (``p`` its rank) to the photograph ``I`` of the ``n`` target pixels
        in the window, per degree of freedom, over the pixels' mean square, over all channels;
        0 where ``n ≤ p``.

    Notes
    -----
    Shading — direct light falling off, interreflections growing towards a concave corner — is
    smooth over a few pixels, and a quadratic follows it (the ideal supersampled Cornell box's
    right wall: τ ≤ 0.034 beside every edge pixel at 48², ≤ 0.013 at 128²; path-traced at 512 spp,
    48², ≤ 0.032); an albedo texture is not (Fig. 12's checker wall at 48²: median 0.07, up to
    0.24), and it is what a linear extrapolation from the solid pixels (:func:`_strip`) misses. A
    texture that varies across a straight edge only goes unseen: the window holds two target
    columns there, which the quadratic fits exactly, and the strip's directions all read them
    alike.
    """
    h, w = inside.shape
    dy, dx = (a.ravel() for a in np.mgrid[-radius:radius + 1, -radius:radius + 1])
    py, px = ys[:, None] + dy[None], xs[:, None] + dx[None]  # (N, P)
    ok = (py >= 0) & (py < h) & (px >= 0) & (px < w)
    py, px = np.clip(py, 0, h - 1), np.clip(px, 0, w - 1)
    ok &= inside[py, px]
    terms = np.stack([np.ones_like(dy), dy, dx, dy * dy, dx * dx, dy * dx], axis=-1).astype(np.float64)  # (P, 6)
    design = np.where(ok[:, :, None], terms[None], 0.0)  # (N, P, 6)
    value = np.where(ok[:, :, None], photo[py, px], 0.0).astype(np.float64)  # (N, P, C)
    residual = value - design @ (np.linalg.pinv(design) @ value)
    n = ok.sum(axis=1)
    dof = n - np.linalg.matrix_rank(design)
    power = (value * value).sum(axis=(1, 2)) / np.maximum(n, 1)
    spread = (residual * residual).sum(axis=(1, 2)) / np.maximum(dof, 1)
    return np.where((dof > 0) & (power > 0), np.sqrt(spread / np.where(power > 0, power, 1.0)), 0.0)


def _along_edge(part, cov, ys, xs, radius: int) -> np.ndarray:
    """The neighbour's part of edge pixels with its interaction shares averaged along the edge.

    Parameters
    ----------
    part : (K, N, C) float
        The neighbour's part of edge pixels ``(ys, xs)``: index 0 its light the target did not
        reach, ``1..K-1`` its ``C R^i L_d``.
    cov : (H, W) float
        Coverage.
    ys, xs : (N,) int
        The edge pixels.
    radius : int
        Half-size in pixels of the square window averaged over.

    Returns
    -------
    (K, N, C) float64
        Each pixel's own total ``T = Σ_j part_j`` (so κ = 1 is unchanged) divided in the shares
        ``s_j = Σ_q w_pq T(q) part_j(q) / Σ_q w_pq T(q)²`` of the edge pixels q in the window,
        with ``w_pq`` the overlap of the two pixels' edge orientations.

    Notes
    -----
    An edge pixel is not re-emitted, so each of its observations is interreflected light only,
    far noisier than the directly lit target's (a path tracer at 1024 spp: 2–15 % per capture
    against 0.1–1 %), and the decomposition (Eq. 9) passes that noise to its components, which
    recoloring multiplies by ``κ^{m+1}`` (Eq. 4). The neighbour's shares ``C R^m L_d / T`` of
    its strip vary slowly along the edge, a curve, while they change across it: the edge pixels
    of the window lie along the curve, so fitting one set of shares to them averages about
    ``2 radius + 1`` pixels without reading the two surfaces' pixels on either side. ``s_j`` is
    the least-squares slope of ``part_j`` against ``T`` over those pixels: a pixel with little
    of the neighbour in it (coverage near 1) has shares that are mostly noise and counts little.
    (Measured on the path-traced Cornell box, 64², 1024 spp, κ = (2, 0.125, 8), radius 4 after
    noise reduction of radius 4: edge pixels 7.6 → 6.5 %; the plain mean of the shares gives
    14 %, weights from each pixel's Monte Carlo variance 7.4 %.) The orientation — the
    coverage's gradient, binned into 8 directions with linear weights, ``w_pq`` the sum over
    bins of the product of the two pixels' weights: 1 for the same direction, 0 from 45° apart
    — keeps the two edges that meet at a corner apart.
    """
    k, n, c = part.shape
    h, w = cov.shape
    rows = slice(max(int(ys.min()) - radius, 0), min(int(ys.max()) + radius + 1, h))
    cols = slice(max(int(xs.min()) - radius, 0), min(int(xs.max()) + radius + 1, w))
    py, px = ys - rows.start, xs - cols.start
    local = np.ascontiguousarray(cov[rows, cols], np.float32)
    gy = cv2.Sobel(local, cv2.CV_32F, 0, 1, ksize=3, borderType=cv2.BORDER_REPLICATE)[py, px]
    gx = cv2.Sobel(local, cv2.CV_32F, 1, 0, ksize=3, borderType=cv2.BORDER_REPLICATE)[py, px]
    turn = (np.arctan2(gy, gx) / (np.pi / 4)) % 8  # the direction the target lies in, in eighths of a turn
    low = np.floor(turn).astype(int) % 8
    frac = (turn - np.floor(turn)).astype(np.float32)
    bins = [(low, 1 - frac), ((low + 1) % 8, frac)]
    total = part.sum(axis=0)  # (N, C): T
    size = (2 * radius + 1,) * 2
    shape = (rows.stop - rows.start, cols.stop - cols.start)
    num = np.zeros((k, n, c))
    den = np.zeros((n, c))
    for b in range(8):
        weight = np.zeros(n, np.float32)
        for idx, wt in bins:
            weight += np.where(idx == b, wt, 0).astype(np.float32)
        if not weight.any():
            continue
        for j in range(-1, k):
            value = total * total if j < 0 else total * part[j]
            for ch in range(c):
                img = np.zeros(shape, np.float32)
                img[py, px] = weight * value[:, ch]
                got = cv2.boxFilter(img, -1, size, normalize=False, borderType=cv2.BORDER_CONSTANT)[py, px] * weight
                if j < 0:
                    den[:, ch] += got
                else:
                    num[j, :, ch] += got
    ok = den > 0
    return np.where(ok[None], num / np.where(ok, den, 1.0)[None] * total[None], part)
