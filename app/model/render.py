"""What the canvas shows, computed without Qt: the data every view draws from.

A :class:`ViewRenderer` holds screen-sized copies of everything a view needs (the decomposition
packed by :func:`engine.recolor.prepare_preview`, the photograph averaged the same way) so a
slider event costs one preview recolor plus one display conversion. Full resolution is used
for export (:mod:`app.model.files`), for the pixel read-out (:meth:`ViewRenderer.pixel`), which
recolors the single pixel under the cursor exactly, and for the :class:`Detail` of the visible
region once the canvas is zoomed in past the preview's resolution. Which view draws what is
the table in :mod:`app.model.views`.

With the noise-aware data (``trusted``, :mod:`engine.trust`) the recolored views show
:func:`engine.trust.recolor_trusted` at full resolution, area-averaged — what export writes. It
costs about half a second per κ at 512² (bench/trusted.py), so a request marked ``fast`` (a slider
moving) takes the plain preview path and the exact frame follows when the slider rests
(:class:`app.qt.preview.PreviewController`).

Renderers are immutable after :meth:`ViewRenderer.prepare` and only read their own copies (the
noise-aware recolor of the last κ is cached under a lock), so the preview workers can render
from one on their threads while the user keeps editing.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from app.model.display import recolor_rgb32, to_rgb32
from engine.errors import InputError
from engine.recolor import area_average, prepare_preview, recolor, recolor_preview
from engine.trust import TrustedRecolor, recolor_trusted


@dataclass(frozen=True)
class Request:
    """Everything a frame depends on besides the renderer's data.

    ``view`` is a :class:`app.model.views.CanvasView`; ``kappa`` is the κ the decomposition is
    recolored with (the last cascade target's); ``edit`` is the whole edit as
    ``((MaskSnapshot, kappa), ...)`` per target, for views that show every target (ground truth,
    the naive recolor). ``fast``: recolor plainly even when the noise-aware data is there (a
    slider moving; the exact frame follows).
    """

    view: str
    kappa: tuple[float, float, float] = (1.0, 1.0, 1.0)
    exposure: float = 0.0
    edit: tuple = ()
    grid: tuple[int, int] = (1, 1)
    fast: bool = False


@dataclass(frozen=True)
class ScaleBar:
    """Legend of a false-colour view: ``lo`` … ``hi`` in linear radiance on ``cmap``."""

    lo: float
    hi: float
    cmap: np.ndarray
    label: str


@dataclass(frozen=True)
class Tile:
    """One labelled tile of the components view, in frame pixels."""

    y: int
    x: int
    h: int
    w: int
    label: str


@dataclass(eq=False)
class PreviewFrame:
    """A displayable frame.

    Attributes
    ----------
    pixels : (h, w) uint32
        ``0xFFRRGGBB``; drawn stretched over ``extent``.
    extent : (H, W)
        Size in camera pixels the frame covers (the image, or the components grid).
    second : (h, w) uint32, optional
        The other half of the split view (the original).
    linear : (h, w, 3) float32, optional
        The linear image behind ``pixels`` (preview resolution) when the view computed one
        (not the recolored and split views, which go straight to pixels).
    scale : ScaleBar, optional
    tiles : list of Tile
    note : str
        One line for the status bar ("relative error 0.61 %").
    banner : str
        A message the canvas draws over the picture (what the view cannot show yet).
    """

    view: str
    pixels: np.ndarray
    extent: tuple[int, int]
    second: np.ndarray | None = None
    linear: np.ndarray | None = None
    scale: ScaleBar | None = None
    tiles: list[Tile] = field(default_factory=list)
    note: str = ""
    banner: str = ""
    request: Request | None = None
    request_id: int = 0
    generation: int = 0


@dataclass(eq=False)
class Detail:
    """A full-resolution patch of a frame: the visible region when zoomed in.

    Attributes
    ----------
    pixels : (y1 - y0, x1 - x0) uint32
        ``0xFFRRGGBB`` words of camera pixels ``[y0:y1, x0:x1]``.
    region : (y0, y1, x0, x1)
        Where the patch goes, in camera pixels.
    request : Request
        The request the patch was rendered for: it belongs on a frame of the same request.
    second : ndarray, optional
        The original's patch in the split view.
    """

    pixels: np.ndarray
    region: tuple[int, int, int, int]
    request: Request
    second: np.ndarray | None = None
    generation: int = 0


def preview_factor(shape: tuple[int, int], max_shape: tuple[int, int]) -> int:
    """Integer reduction that fits ``shape`` into ``max_shape`` (as prepare_preview uses)."""
    h, w = shape
    mh, mw = max(int(max_shape[0]), 1), max(int(max_shape[1]), 1)
    return max(1, int(np.ceil(max(h / mh, w / mw))))


def component_grid(order: int, extent: tuple[int, int], view: tuple[int, int]) -> tuple[int, int]:
    """Rows and columns for ``order`` tiles of size ``extent`` that show them largest in ``view``.

    Examples
    --------
    >>> component_grid(4, (480, 640), (720, 1280))
    (2, 2)
    >>> component_grid(3, (480, 640), (400, 1800))
    (1, 3)
    """
    h, w = extent
    vh, vw = max(view[0], 1), max(view[1], 1)
    best, best_scale = (1, order), -1.0
    for rows in range(1, order + 1):
        cols = -(-order // rows)
        scale = min(vw / (cols * w), vh / (rows * h))
        if scale > best_scale + 1e-12:
            best, best_scale = (rows, cols), scale
    return best


class ViewRenderer:
    """Screen-sized data for every view of one document state (photograph + acquisition).

    Parameters
    ----------
    photograph : (H, W, 3) float32
    decomposition : engine.decompose.Decomposition, optional
    truth : callable, optional
        ``truth(edit) -> (H, W, 3)`` full-resolution ground truth of an edit (virtual rig),
        where ``edit`` is the request's ``edit``; see :class:`app.qt.preview.PreviewController`.
    emitters : (H, W) bool, optional
        Pixels that see a lamp (``rig.truth.emitters()``): the error view also reports the
        error without them, since a lamp dominates the image's norm.
    max_shape : (h, w)
        Largest preview size (the screen, in device pixels).
    trusted : engine.trust.TrustedDecomposition, optional
        The acquisition's noise-aware data: the recolored views show
        :func:`engine.trust.recolor_trusted` (plainly for ``fast`` requests).
    """

    def __init__(self, photograph: np.ndarray, decomposition=None, *, truth=None, emitters=None,
                 max_shape=(1080, 1920), trusted=None):
        self.photograph = photograph
        self.decomposition = decomposition
        self.trusted = trusted if decomposition is not None else None
        self._trusted_cache: tuple[tuple, TrustedRecolor] | None = None
        self._trusted_lock = threading.Lock()
        self.truth = truth
        self.emitters = emitters
        self.shape: tuple[int, int] = photograph.shape[:2]
        self.factor = preview_factor(self.shape, max_shape)
        self.pack = None
        self.small_photo: np.ndarray | None = None
        self._tiles: dict[tuple[int, int], tuple[np.ndarray, list[Tile]]] = {}
        self._truth_cache: tuple[Any, np.ndarray] | None = None
        self._naive_parts: tuple | None = None  # (mask snapshots, rest, per-target parts) of naive_small

    # ------------------------------------------------------------------ preparation
    def prepare(self) -> ViewRenderer:
        """Compute the reduced copies (slow for big images: run it on a worker)."""
        if self.decomposition is not None:
            small = (-(-self.shape[0] // self.factor), -(-self.shape[1] // self.factor))
            self.pack = prepare_preview(self.decomposition, small)
            if self.pack.shape != tuple(-(-s // self.factor) for s in self.shape):
                raise InputError(f"preview pack shape {self.pack.shape} does not match factor {self.factor}")
        self.small_photo = area_average(self.photograph, self.factor)
        return self

    @property
    def prepared(self) -> bool:
        return self.small_photo is not None

    # ------------------------------------------------------------------ frames
    def detail(self, request: Request, region: tuple[int, int, int, int], *, original: bool = False,
               split: bool = False) -> Detail | None:
        """Full-resolution pixels of ``region`` = (y0, y1, x0, x1): recolored (or the photograph).

        None where the preview already is full resolution or the region is empty. Recolored
        pixels are :func:`app.model.display.recolor_rgb32` of the cropped decomposition, so they
        equal the export's pixels there; nothing acquired (or ``original``): the photograph.
        ``split`` adds the photograph's patch as the second half.
        """
        if self.factor == 1:
            return None
        y0, y1, x0, x1 = clip_region(region, self.shape)
        if y1 <= y0 or x1 <= x0:
            return None

        def photo():
            return to_rgb32(np.ascontiguousarray(self.photograph[y0:y1, x0:x1]), exposure=request.exposure)

        if original or self.decomposition is None:
            return Detail(photo(), (y0, y1, x0, x1), request)
        if self.exact(request):
            pixels = to_rgb32(np.ascontiguousarray(self.trusted_recolor(request.kappa).image[y0:y1, x0:x1]),
                              exposure=request.exposure)
            return Detail(pixels, (y0, y1, x0, x1), request, second=photo() if split else None)
        pixels = recolor_rgb32(self.decomposition.crop(y0, y1, x0, x1), request.kappa, exposure=request.exposure)
        return Detail(pixels, (y0, y1, x0, x1), request, second=photo() if split else None)

    def exact(self, request: Request) -> bool:
        """Whether ``request`` is drawn with the noise-aware recolor (its data is here and it is not ``fast``)."""
        return self.trusted is not None and not request.fast

    def trusted_recolor(self, kappa) -> TrustedRecolor:
        """:func:`engine.trust.recolor_trusted` at full resolution (the last κ's is cached)."""
        key = _kappa_key(kappa)
        with self._trusted_lock:
            if self._trusted_cache is None or self._trusted_cache[0] != key:
                self._trusted_cache = (key, recolor_trusted(self.trusted, key))
            return self._trusted_cache[1]

    def cached_trusted(self, kappa) -> TrustedRecolor | None:
        """The noise-aware recolor of ``kappa`` if it is computed already (read-outs never wait for it)."""
        key = _kappa_key(kappa)
        cached = self._trusted_cache
        return cached[1] if cached is not None and cached[0] == key else None

    def recolored_small(self, kappa, *, fast: bool = False) -> np.ndarray:
        """Linear preview of the recolored image (the photograph when nothing is acquired).

        Noise-aware (the area average of :meth:`trusted_recolor`) when its data is here and not ``fast``.
        """
        if self.pack is None:
            return self.small_photo
        if self.trusted is not None and not fast:
            return area_average(self.trusted_recolor(kappa).image, self.factor)
        return recolor_preview(self.pack, kappa)

    def naive_small(self, edit) -> np.ndarray:
        """The naive per-pixel recolor at preview resolution: every target's pixels times its κ.

        What a photo editor does without measurements (interreflections keep their colour).
        Exactly the area average of the full-resolution naive recolor: the photograph's average
        over each target's own pixels (a later target wins where they overlap) is computed once
        per set of masks, so a κ change costs one multiply-add per target.
        """
        snaps = tuple(snap for snap, _ in edit)
        if self._naive_parts is None or self._naive_parts[0] != snaps:
            covered = np.zeros(self.shape, bool)
            parts = []
            for snap in reversed(snaps):  # cascade order: later targets first, they win overlaps
                own = snap.mask & ~covered
                covered |= own
                parts.append(area_average(np.where(own[..., None], self.photograph, np.float32(0)), self.factor))
            rest = area_average(np.where(covered[..., None], np.float32(0), self.photograph), self.factor)
            self._naive_parts = (snaps, rest, parts[::-1])
        _, rest, parts = self._naive_parts
        out = rest.copy()
        for part, (_, kappa) in zip(parts, edit, strict=True):
            out += part * np.asarray(kappa, np.float32)
        return out

    def naive_pixel(self, x: int, y: int, edit) -> np.ndarray:
        """The naive recolor at one full-resolution pixel."""
        value = self.photograph[y, x].astype(np.float32)
        for snap, kappa in reversed(edit):
            if snap.mask[y, x]:
                return value * np.asarray(kappa, np.float32)
        return value

    def has_truth(self, edit) -> bool:
        """Whether the ground truth of ``edit`` is computed already (read-out never waits for it)."""
        return self._truth_cache is not None and self._truth_cache[0] == edit

    def truth_full(self, edit) -> np.ndarray:
        """Full-resolution ground truth of ``edit`` (cached for the last edit)."""
        if self.has_truth(edit):
            return self._truth_cache[1]
        image = np.asarray(self.truth(edit), np.float32)
        self._truth_cache = (edit, image)
        return image

    def component_tiles(self, grid: tuple[int, int], exposure: float):
        """The paper's Fig. 6 layout: tile i shows R^i L_d inside, C R^(i-1) L_d outside.

        Tile 0 shows ``L_d = R^0 L_d`` on the target and the unreached light ``L̄_d`` elsewhere.
        Tile i is brightened by 4^i (the paper's 1, 4, 16, 64) so higher orders are visible.
        """
        key = (grid, exposure)
        if key in self._tiles:
            return self._tiles[key]
        d = self.pack.decomposition
        comps, unreached, target = d.components, d.unreached, d.target
        rows, cols = grid
        h, w = target.shape
        k = comps.shape[0]
        n = max(rows, cols)  # the grid never exceeds the preview size in either direction
        th, tw = -(-h // n), -(-w // n)
        canvas = np.full((rows * th, cols * tw), 0xFF202020, np.uint32)
        tiles = []
        inside = target[:, :, None]
        for i in range(k):
            outside = unreached if i == 0 else comps[i - 1]
            if i - 1 >= d.outside_order:
                outside = np.zeros_like(unreached)
            merged = np.where(inside, comps[i], outside) * np.float32(4.0**i)
            small = area_average(merged, n)
            r, c = divmod(i, cols)
            tile = to_rgb32(np.ascontiguousarray(small), exposure=exposure)
            canvas[r * th : (r + 1) * th, c * tw : (c + 1) * tw] = tile
            label = "R⁰L_d | L̄_d" if i == 0 else f"R{_sup(i)}L_d | C R{_sup(i - 1)}L_d"
            tiles.append(Tile(r * th, c * tw, th, tw, f"{label}   ×{4 ** i}"))
        self._tiles = {key: (canvas, tiles)}
        return canvas, tiles

    def pixel(self, x: int, y: int, kappa) -> np.ndarray:
        """Full-resolution recolored value at one pixel: the noise-aware recolor's when it is computed for
        ``kappa``, else through :func:`engine.recolor.recolor`."""
        if self.trusted is not None and (done := self.cached_trusted(kappa)) is not None:
            return done.image[y, x]
        return recolor(self.decomposition.crop(y, y + 1, x, x + 1), kappa)[0, 0]


def clip_region(region, shape: tuple[int, int]) -> tuple[int, int, int, int]:
    """``(y0, y1, x0, x1)`` clipped to an image of ``shape`` (may come out empty)."""
    y0, y1, x0, x1 = (int(v) for v in region)
    h, w = shape
    return max(y0, 0), min(y1, h), max(x0, 0), min(x1, w)


def _sup(n: int) -> str:
    return str(n).translate(str.maketrans("0123456789", "⁰¹²³⁴⁵⁶⁷⁸⁹"))


class MaskSnapshot:
    """An immutable copy of a mask, compared by (uid, version) so edits hash cheaply."""

    __slots__ = ("version", "mask")

    def __init__(self, version: tuple[int, int], mask: np.ndarray):
        self.version = version
        self.mask = mask
        mask.flags.writeable = False

    def __eq__(self, other) -> bool:
        return isinstance(other, MaskSnapshot) and other.version == self.version

    def __hash__(self) -> int:
        return hash(self.version)


def _kappa_key(kappa) -> tuple[float, float, float]:
    """``kappa`` (scalar or per channel) as the hashable per-channel key of the noise-aware recolor cache."""
    r, g, b = (float(k) for k in np.broadcast_to(np.asarray(kappa, float), (3,)))
    return r, g, b
