"""What the canvas shows, computed without Qt: one :class:`Frame` per :class:`Request`.

A :class:`Renderer` holds screen-sized copies of everything a view needs (the decomposition
packed by :func:`engine.recolor.prepare_preview`, the photograph averaged the same way) so a
slider event costs one preview recolor plus one display conversion. Full resolution is used
for export (:mod:`app.model.files`), for the pixel read-out (:meth:`Renderer.readout`), which
recolors the single pixel under the cursor exactly, and for the :class:`Detail` of the visible
region once the canvas is zoomed in past the preview's resolution.

Renderers are immutable after :meth:`Renderer.prepare` and only read their own copies, so the
preview worker can call :meth:`Renderer.render` on its thread while the user keeps editing.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

import numpy as np

from app.model.display import MAGNITUDE_MAP, SIGNED_MAP, false_colour, luminance, recolor_rgb32, robust_max, to_rgb32
from engine.acquire.predict import relative_error
from engine.errors import InputError
from engine.recolor import area_average, prepare_preview, recolor, recolor_preview


class View(StrEnum):
    """Canvas views (the View menu)."""

    RECOLORED = "recolored"
    ORIGINAL = "original"
    SPLIT = "split"
    DIFFERENCE = "difference"
    COMPONENTS = "components"
    TRUTH = "truth"
    ERROR = "error"


#: Views that only make sense with a decomposition / with ground truth (virtual rig).
NEEDS_DECOMPOSITION = frozenset({View.DIFFERENCE, View.COMPONENTS, View.ERROR})
NEEDS_TRUTH = frozenset({View.TRUTH, View.ERROR})
#: Views that sharpen to full resolution when zoomed in (the diagnostic false-colour views
#: keep the preview's scale and resolution).
DETAIL_VIEWS = frozenset({View.RECOLORED, View.ORIGINAL, View.SPLIT})


@dataclass(frozen=True)
class Request:
    """Everything a frame depends on besides the renderer's data.

    ``kappa`` is the κ the decomposition is recolored with (the last cascade target's);
    ``edit`` is the whole edit as ``((mask_version, kappa), ...)`` per target, for ground truth.
    """

    view: View
    kappa: tuple[float, float, float] = (1.0, 1.0, 1.0)
    exposure: float = 0.0
    edit: tuple = ()
    grid: tuple[int, int] = (1, 1)


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
class Frame:
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
    """

    view: View
    pixels: np.ndarray
    extent: tuple[int, int]
    second: np.ndarray | None = None
    linear: np.ndarray | None = None
    scale: ScaleBar | None = None
    tiles: list[Tile] = field(default_factory=list)
    note: str = ""
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


class Renderer:
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
    """

    def __init__(self, photograph: np.ndarray, decomposition=None, *, truth=None, emitters=None,
                 max_shape=(1080, 1920)):
        self.photograph = photograph
        self.decomposition = decomposition
        self.truth = truth
        self.emitters = emitters
        self.shape: tuple[int, int] = photograph.shape[:2]
        self.factor = preview_factor(self.shape, max_shape)
        self.pack = None
        self.small_photo: np.ndarray | None = None
        self._tiles: dict[tuple[int, int], tuple[np.ndarray, list[Tile]]] = {}
        self._truth_cache: tuple[Any, np.ndarray] | None = None

    # ------------------------------------------------------------------ preparation
    def prepare(self) -> Renderer:
        """Compute the reduced copies (slow for big images: run it on a worker)."""
        if self.decomposition is not None:
            self.pack = prepare_preview(self.decomposition, (-(-self.shape[0] // self.factor), -(-self.shape[1] // self.factor)))
            if self.pack.shape != tuple(-(-s // self.factor) for s in self.shape):
                raise InputError(f"preview pack shape {self.pack.shape} does not match factor {self.factor}")
        self.small_photo = area_average(self.photograph, self.factor)
        return self

    @property
    def prepared(self) -> bool:
        return self.small_photo is not None

    # ------------------------------------------------------------------ frames
    def render(self, request: Request) -> Frame:
        """Compute the frame of ``request`` (views that can't be shown fall back to the original)."""
        if not self.prepared:
            self.prepare()
        view = View(request.view)
        if view in NEEDS_DECOMPOSITION and self.pack is None and view != View.ERROR:
            view = View.ORIGINAL
        if view in NEEDS_TRUTH and self.truth is None:
            view = View.ORIGINAL
        if view == View.ERROR and self.pack is None:
            view = View.TRUTH
        ev = request.exposure
        if view == View.ORIGINAL:
            return Frame(view, to_rgb32(self.small_photo, exposure=ev), self.shape, linear=self.small_photo)
        if view in (View.RECOLORED, View.SPLIT):
            if self.pack is None:
                pixels, note = to_rgb32(self.small_photo, exposure=ev), "not acquired yet: showing the photograph"
            else:  # the hot path: recolor and display conversion fused, no float image in between
                pixels, note = recolor_rgb32(self.pack.decomposition, request.kappa, exposure=ev), ""
            second = to_rgb32(self.small_photo, exposure=ev) if view == View.SPLIT else None
            return Frame(view, pixels, self.shape, second=second, note=note)
        if view == View.DIFFERENCE:
            lin = self.recolored_small(request.kappa)
            delta = luminance(lin) - luminance(self.small_photo)
            s = robust_max(delta)
            return Frame(view, false_colour(delta, -s, s, SIGNED_MAP), self.shape, linear=lin,
                         scale=ScaleBar(-s, s, SIGNED_MAP, "Δ luminance (recolored − original)"))
        if view == View.COMPONENTS:
            pixels, tiles = self.component_tiles(request.grid, ev)
            rows, cols = request.grid
            return Frame(view, pixels, (rows * self.shape[0], cols * self.shape[1]), tiles=tiles,
                         note="inside the target R^i L_d, outside C R^(i-1) L_d (first tile: L_d and L̄_d)")
        truth_full = self.truth_full(request.edit)
        truth_small = area_average(truth_full, self.factor)
        if view == View.TRUTH:
            return Frame(view, to_rgb32(truth_small, exposure=ev), self.shape, linear=truth_small, note="ground truth")
        lin = self.recolored_small(request.kappa)
        err = np.abs(luminance(lin) - luminance(truth_small))
        s = robust_max(err)
        note = f"relative error {100 * relative_error(lin, truth_small):.2f} %"
        if self.emitters is not None and self.emitters.any():
            surfaces = area_average(self.emitters.astype(np.float32), self.factor) == 0
            note += f", {100 * relative_error(lin, truth_small, surfaces):.2f} % without the lamp"
        return Frame(view, false_colour(err, 0.0, s, MAGNITUDE_MAP), self.shape, linear=lin,
                     scale=ScaleBar(0.0, s, MAGNITUDE_MAP, "|recolored − ground truth| (luminance)"),
                     note=note + " (preview resolution)")

    def render_detail(self, request: Request, region: tuple[int, int, int, int]) -> Detail | None:
        """Full-resolution pixels of ``region`` = (y0, y1, x0, x1) in ``request``'s view.

        Returns None where the preview already is full resolution or the view has no detail
        (:data:`DETAIL_VIEWS`). Recolored pixels are :func:`app.model.display.recolor_rgb32` of the
        cropped decomposition, so they equal the export's pixels there.
        """
        view = View(request.view)
        if self.factor == 1 or view not in DETAIL_VIEWS:
            return None
        y0, y1, x0, x1 = clip_region(region, self.shape)
        if y1 <= y0 or x1 <= x0:
            return None

        def photo():
            return to_rgb32(np.ascontiguousarray(self.photograph[y0:y1, x0:x1]), exposure=request.exposure)

        if view == View.ORIGINAL or self.decomposition is None:
            return Detail(photo(), (y0, y1, x0, x1), request)
        pixels = recolor_rgb32(self.decomposition.crop(y0, y1, x0, x1), request.kappa, exposure=request.exposure)
        return Detail(pixels, (y0, y1, x0, x1), request, second=photo() if view == View.SPLIT else None)

    def recolored_small(self, kappa) -> np.ndarray:
        """Linear preview of the recolored image (the photograph when nothing is acquired)."""
        if self.pack is None:
            return self.small_photo
        return recolor_preview(self.pack, kappa)

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
            canvas[r * th : (r + 1) * th, c * tw : (c + 1) * tw] = to_rgb32(np.ascontiguousarray(small), exposure=exposure)
            label = "R⁰L_d | L̄_d" if i == 0 else f"R{_sup(i)}L_d | C R{_sup(i - 1)}L_d"
            tiles.append(Tile(r * th, c * tw, th, tw, f"{label}   ×{4 ** i}"))
        self._tiles = {key: (canvas, tiles)}
        return canvas, tiles

    # ------------------------------------------------------------------ read-out
    def readout(self, view: View, x: int, y: int, kappa, edit=()) -> tuple[str, np.ndarray] | None:
        """Exact linear value(s) at camera pixel (x, y) for the status bar, or None outside.

        Returns a label and an RGB value; recolored values come from the full-resolution
        decomposition at that pixel (same maths as :func:`engine.recolor.recolor`).
        """
        h, w = self.shape
        if not (0 <= x < w and 0 <= y < h):
            return None
        photo = self.photograph[y, x]
        view = View(view)
        if view == View.ORIGINAL or (self.decomposition is None and view not in NEEDS_TRUTH):
            return "original", photo
        if view in NEEDS_TRUTH and self.truth is not None:
            t = self.truth_full(edit)[y, x]
            if view == View.TRUTH or self.decomposition is None:
                return "ground truth", t
            return "recolored − truth", self.pixel(x, y, kappa) - t
        if self.decomposition is None:
            return "original", photo
        value = self.pixel(x, y, kappa)
        if view == View.DIFFERENCE:
            return "recolored − original", value - photo
        return "recolored", value

    def pixel(self, x: int, y: int, kappa) -> np.ndarray:
        """Full-resolution recolored value at one pixel, through :func:`engine.recolor.recolor`."""
        return recolor(self.decomposition.crop(y, y + 1, x, x + 1), kappa)[0, 0]


def clip_region(region, shape: tuple[int, int]) -> tuple[int, int, int, int]:
    """``(y0, y1, x0, x1)`` clipped to an image of ``shape`` (may come out empty)."""
    y0, y1, x0, x1 = (int(v) for v in region)
    h, w = shape
    return max(y0, 0), min(y1, h), max(x0, 0), min(x1, w)


def _sup(n: int) -> str:
    return str(n).translate(str.maketrans("0123456789", "⁰¹²³⁴⁵⁶⁷⁸⁹"))
