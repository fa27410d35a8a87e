"""Painting target masks from plain mouse events, without Qt.

The canvas turns Qt mouse events into :class:`MouseEvent` (image coordinates, float, pixel
``(i, j)`` covering ``j <= x < j + 1``, ``i <= y < i + 1``) and hands them to a
:class:`Painter`, which edits the :class:`~app.model.document.Document`. Tests drive the painter with
the same plain events, no window needed (napari's ``_labels_mouse_bindings`` pattern).

One drag is one undo step: a brush drag opens a stroke on press and closes it on release,
and the document records the stroke's bounding box and old values.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

import cv2
import numpy as np

from app.model.document import BBox, Document
from engine.errors import InputError


class Tool(StrEnum):
    """Mask tools."""

    BRUSH = "brush"
    ERASER = "eraser"
    POLYGON = "polygon"
    LASSO = "lasso"
    FILL = "fill"


class EventType(StrEnum):
    PRESS = "press"
    MOVE = "move"
    RELEASE = "release"
    DOUBLE_CLICK = "double_click"


@dataclass(frozen=True)
class MouseEvent:
    """A mouse event in image coordinates.

    ``subtract`` (Alt held, or the right button) makes add-type tools remove pixels.
    """

    type: EventType
    x: float
    y: float
    buttons: frozenset[str] = field(default_factory=lambda: frozenset({"left"}))
    subtract: bool = False


def press(x, y, **kw) -> MouseEvent:
    """Shorthand for a left-button press at (x, y)."""
    return MouseEvent(EventType.PRESS, float(x), float(y), **kw)


def move(x, y, **kw) -> MouseEvent:
    """Shorthand for a move with the left button held."""
    return MouseEvent(EventType.MOVE, float(x), float(y), **kw)


def release(x, y, **kw) -> MouseEvent:
    """Shorthand for a left-button release."""
    return MouseEvent(EventType.RELEASE, float(x), float(y), buttons=frozenset(), **kw)


def capsule(p0: tuple[float, float], p1: tuple[float, float], radius: float, shape: tuple[int, int]):
    """Pixels within ``radius`` of the segment p0–p1 (x, y), and the pixels containing p0, p1.

    Parameters
    ----------
    p0, p1 : (x, y) float
        Segment end points in image coordinates.
    radius : float
        Brush radius in pixels (half the brush size).
    shape : (H, W)
        Image shape; the result is clipped to it.

    Returns
    -------
    bbox : (y0, y1, x0, x1) or None
        Bounding box of the stamp inside the image (None if it misses the image).
    stamp : (y1 - y0, x1 - x0) bool

    Examples
    --------
    >>> bbox, stamp = capsule((2.5, 2.5), (2.5, 2.5), 1.0, (5, 5))
    >>> bbox
    (1, 4, 1, 4)
    >>> stamp.astype(int)
    array([[0, 1, 0],
           [1, 1, 1],
           [0, 1, 0]])
    """
    bbox, dist = _segment_distance(p0, p1, radius, shape)
    if bbox is None:
        return None, None
    stamp = dist * dist <= radius * radius
    y0, y1, x0, x1 = bbox
    for px, py in (p0, p1):  # a brush always paints the pixel under the cursor
        j, i = int(np.floor(px)) - x0, int(np.floor(py)) - y0
        if 0 <= i < y1 - y0 and 0 <= j < x1 - x0:
            stamp[i, j] = True
    return bbox, stamp


def feathered_capsule(p0: tuple[float, float], p1: tuple[float, float], radius: float, hardness: float,
                      shape: tuple[int, int]):
    """A feathered brush's stamp along the segment p0–p1: coverage 1 near it, falling to 0 at ``radius``.

    Parameters
    ----------
    p0, p1 : (x, y) float
        Segment end points in image coordinates.
    radius : float
        Brush radius in pixels (half the brush size).
    hardness : float in [0, 1)
        The fraction of the radius painted fully; coverage falls linearly from there to 0 at
        ``radius`` (the feather). 1 is the hard brush of :func:`capsule`.
    shape : (H, W)

    Returns
    -------
    bbox : (y0, y1, x0, x1) or None
        Bounding box of the stamp inside the image (None if it misses the image).
    weight : (y1 - y0, x1 - x0) float32
        Coverage the stamp paints, by the distance of each pixel centre to the segment.

    Examples
    --------
    >>> bbox, w = feathered_capsule((2.5, 2.5), (2.5, 2.5), 2.0, 0.5, (5, 5))
    >>> w[2].tolist()
    [0.0, 1.0, 1.0, 1.0, 0.0]
    >>> float(w[1, 1])  # distance √2 from the centre: (2 − √2) / (2 − 1)
    0.5857864...
    """
    bbox, dist = _segment_distance(p0, p1, radius, shape)
    if bbox is None:
        return None, None
    inner = hardness * radius
    weight = np.clip((radius - dist) / max(radius - inner, 1e-9), 0.0, 1.0)
    return bbox, weight.astype(np.float32)


def _segment_distance(p0, p1, radius: float, shape: tuple[int, int]):
    """The box of pixels within ``radius`` of the segment p0–p1 (clipped to ``shape``) and each
    pixel centre's distance to the segment; ``(None, None)`` when the box misses the image."""
    (ax, ay), (bx, by) = p0, p1
    h, w = shape
    y0 = max(int(np.floor(min(ay, by) - radius)), 0)
    y1 = min(int(np.floor(max(ay, by) + radius)) + 1, h)
    x0 = max(int(np.floor(min(ax, bx) - radius)), 0)
    x1 = min(int(np.floor(max(ax, bx) + radius)) + 1, w)
    if y0 >= y1 or x0 >= x1:
        return None, None
    yy = (np.arange(y0, y1, dtype=np.float64) + 0.5)[:, None]
    xx = (np.arange(x0, x1, dtype=np.float64) + 0.5)[None, :]
    dx, dy = bx - ax, by - ay
    seg2 = dx * dx + dy * dy
    t = np.clip(((xx - ax) * dx + (yy - ay) * dy) / seg2, 0.0, 1.0) if seg2 > 0 else np.zeros((1, 1))
    return (y0, y1, x0, x1), np.hypot(xx - (ax + t * dx), yy - (ay + t * dy))


def polygon_mask(points, shape: tuple[int, int]):
    """Rasterise a closed polygon (x, y vertices in image coordinates) to its bbox and stamp.

    A pixel is inside when its centre is (even-odd rule, scanline per pixel row), so a
    rectangle from (0, 0) to (4, 4) covers exactly the 4×4 pixels under it.

    Examples
    --------
    >>> polygon_mask([(0, 0), (4, 0), (4, 4), (0, 4)], (10, 10))[1].sum()
    np.int64(16)
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[0] < 3 or pts.shape[1] != 2:
        raise InputError(f"a polygon needs at least 3 (x, y) points, got shape {pts.shape}")
    h, w = shape
    x0 = max(int(np.floor(pts[:, 0].min())), 0)
    x1 = min(int(np.ceil(pts[:, 0].max())) + 1, w)
    y0 = max(int(np.floor(pts[:, 1].min())), 0)
    y1 = min(int(np.ceil(pts[:, 1].max())) + 1, h)
    if y0 >= y1 or x0 >= x1:
        return None, None
    ax, ay = pts[:, 0], pts[:, 1]
    bx, by = np.roll(ax, -1), np.roll(ay, -1)
    stamp = np.zeros((y1 - y0, x1 - x0), bool)
    for i in range(y1 - y0):
        yc = y0 + i + 0.5
        crossing = (ay <= yc) != (by <= yc)
        if not crossing.any():
            continue
        ca = np.flatnonzero(crossing)
        xs = np.sort(ax[ca] + (yc - ay[ca]) * (bx[ca] - ax[ca]) / (by[ca] - ay[ca]))
        # pixel j is inside a span [xl, xr) when its centre j + 0.5 is
        starts = np.clip(np.ceil(xs[0::2] - 0.5).astype(np.int64) - x0, 0, x1 - x0)
        stops = np.clip(np.ceil(xs[1::2] - 0.5).astype(np.int64) - x0, 0, x1 - x0)
        for a, b in zip(starts, stops, strict=True):  # a closed polygon crosses a row an even number of times
            stamp[i, a:b] = True
    return (y0, y1, x0, x1), stamp


def similar_region(image: np.ndarray, x: float, y: float, tolerance: float) -> np.ndarray:
    """Pixels connected to (x, y) through steps of similar colour: one surface, across its shading.

    Colours are compared in log radiance (a tolerance of 0.1 is about ±10 % per channel, in shadows and
    highlights alike), lightly smoothed first (:data:`SMOOTH`: camera noise would stop the fill at single
    pixels). A pixel joins when it is within ``tolerance`` of a 4-connected neighbour already in, so the
    fill follows a surface's gradual shading — a wall lit from one side, an interreflection's glow — and
    stops at the step between two surfaces; it never drifts further from the seed (the median of its
    5×5 neighbourhood) than :data:`BRIGHTNESS_SPAN` tolerances in brightness nor :data:`HUE_SPAN` in hue,
    so a slow gradient cannot lead it onto another surface. (Compared with the seed alone, the default
    tolerance took 0-40 % of a virtual scene's wall at 256², a crescent of the Cornell box's back wall; now
    87-100 %, and beyond it at most a few of its edge pixels: ``bench/fill.py``.)

    Parameters
    ----------
    image : (H, W, 3) float32
        Linear radiance.
    x, y : float
        Seed in image coordinates.
    tolerance : float
        Largest |log(c) − log(c')| per channel between neighbours.

    Returns
    -------
    (H, W) bool

    Examples
    --------
    >>> ramp = np.repeat(np.geomspace(0.1, 0.4, 8, dtype=np.float32)[None, :, None], 3, axis=2)
    >>> image = np.concatenate([ramp, ramp * np.float32([1, 0.2, 0.2])])  # a grey ramp over a red one
    >>> similar_region(image, 0.5, 0.5, 0.25).astype(int).tolist()
    [[1, 1, 1, 1, 1, 1, 1, 1], [0, 0, 0, 0, 0, 0, 0, 0]]
    """
    return _similar_from_log(_log_image(image), x, y, tolerance)


#: Smoothing of the log image before a fill (Gaussian σ, camera pixels).
SMOOTH = 0.7
#: How far a fill may drift from its seed, in tolerances: in brightness (shading) and in hue.
BRIGHTNESS_SPAN, HUE_SPAN = 10.0, 2.0


def _log_image(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The image in log radiance, as it is and smoothed (:data:`SMOOTH`): what a fill compares (computed once
    per image by the painter)."""
    floor = max(float(np.percentile(image, 99.5)) * 1e-4, 1e-12)
    raw = np.log(np.maximum(image, floor)).astype(np.float32)
    return raw, cv2.GaussianBlur(raw, (0, 0), SMOOTH)


class Painter:
    """Turns mouse events into mask edits on the document's current target.

    Parameters
    ----------
    document : Document
    image : (H, W, 3) float32, optional
        What "fill by similar colour" compares; default the photograph.

    Attributes
    ----------
    tool : Tool
    size : float
        Brush diameter in camera pixels.
    hardness : float
        Fraction of the brush radius painted fully (1: a hard brush, binary mask; less: a
        feathered brush whose edge paints partial coverage, :func:`feathered_capsule`).
    tolerance : float
        Fill tolerance in log radiance.
    polygon : list of (x, y)
        Vertices of the polygon or lasso being drawn (for the canvas to show).
    """

    MIN_SIZE, MAX_SIZE = 1.0, 1000.0

    def __init__(self, document: Document, *, image: np.ndarray | None = None):
        self.doc = document
        self.image = document.photograph if image is None else image
        self.tool = Tool.BRUSH
        self.size = 20.0
        self.hardness = 1.0
        self.tolerance = 0.1
        self.polygon: list[tuple[float, float]] = []
        self._last: tuple[float, float] | None = None
        self._erasing = False
        self._log: np.ndarray | None = None
        self._log_source: np.ndarray | None = None

    # ------------------------------------------------------------ settings
    def set_tool(self, tool: Tool | str) -> None:
        self.cancel()
        self.tool = Tool(tool)

    def set_size(self, size: float) -> None:
        """Brush diameter, clamped to MIN_SIZE..MAX_SIZE (a UI setting, not data)."""
        self.size = float(min(max(size, self.MIN_SIZE), self.MAX_SIZE))

    def set_hardness(self, hardness: float) -> None:
        """Brush hardness, clamped to 0..1 (a UI setting, not data)."""
        self.hardness = float(min(max(hardness, 0.0), 1.0))

    def grow(self) -> None:
        """``]``: brush 25 % larger (at least one pixel)."""
        self.set_size(max(self.size * 1.25, self.size + 1))

    def shrink(self) -> None:
        """``[``: brush 20 % smaller (at least one pixel)."""
        self.set_size(min(self.size / 1.25, self.size - 1))

    # ------------------------------------------------------------ events
    def handle(self, event: MouseEvent) -> bool:
        """Apply one event; returns True when it was consumed (the canvas then repaints).

        Refused edits (e.g. the mask of an acquired target) are reported through the
        document's ``warning`` signal, never raised into the UI's event handler.
        """
        try:
            return self._handle(event)
        except InputError as exc:
            self.polygon, self._last = [], None
            self.doc.events.warning.emit(str(exc))
            return False

    def _handle(self, event: MouseEvent) -> bool:
        uid = self.doc.current
        if uid == -1 and event.type == EventType.PRESS and not self.doc.targets and self._adds(event):
            uid = self.doc.add_target().uid  # the first stroke on a new photograph starts its first target
        if uid == -1:
            if event.type == EventType.PRESS:
                self.doc.events.warning.emit("add or select a target before painting")
            return False
        if self.tool in (Tool.BRUSH, Tool.ERASER):
            return self._brush(uid, event)
        if self.tool == Tool.LASSO:
            return self._lasso(uid, event)
        if self.tool == Tool.POLYGON:
            return self._polygon(uid, event)
        if self.tool == Tool.FILL and event.type == EventType.PRESS:
            self.fill(uid, event.x, event.y, subtract=event.subtract)
            return True
        return False

    def _adds(self, event: MouseEvent) -> bool:
        """The event would add to a mask (not the eraser, not a subtracting modifier)."""
        return self.tool != Tool.ERASER and not event.subtract

    def cancel(self) -> None:
        """Escape: drop an unfinished polygon/lasso; close an open stroke."""
        self.polygon = []
        self._last = None
        self.doc.end_stroke()

    def close_polygon(self, *, subtract: bool = False) -> None:
        """Enter / double click: fill the polygon being drawn into the current target."""
        pts, self.polygon = self.polygon, []
        if len(pts) >= 3 and self.doc.current != -1:
            self._fill_polygon(self.doc.current, pts, subtract)

    def fill(self, uid: int, x: float, y: float, *, subtract: bool = False) -> None:
        """Add (or remove) the connected region of similar colour around (x, y)."""
        if self._log is None or self._log_source is not self.image:
            self._log, self._log_source = _log_image(self.image), self.image
        region = _similar_from_log(self._log, x, y, self.tolerance)
        self._apply_region(uid, region, subtract, "Fill")

    # ------------------------------------------------------------ tools
    def _brush(self, uid: int, e: MouseEvent) -> bool:
        if e.type == EventType.PRESS:
            self._erasing = self.tool == Tool.ERASER or e.subtract
            self.doc.begin_stroke(uid, soft=self.hardness < 1)
            self._last = (e.x, e.y)
            self._stamp(uid, (e.x, e.y), (e.x, e.y))
            return True
        if self._last is None:
            return False  # hover
        if e.type == EventType.MOVE:
            self._stamp(uid, self._last, (e.x, e.y))
            self._last = (e.x, e.y)
            return True
        if e.type == EventType.RELEASE:
            self._stamp(uid, self._last, (e.x, e.y))
            self._last = None
            self.doc.end_stroke()
            return True
        return False

    def _stamp(self, uid: int, p0, p1) -> None:
        if self.hardness < 1:
            bbox, weight = feathered_capsule(p0, p1, self.size / 2.0, self.hardness, self.doc.shape)
            if bbox is not None:
                self.doc.paint_soft(uid, bbox, weight, not self._erasing)
            return
        bbox, stamp = capsule(p0, p1, self.size / 2.0, self.doc.shape)
        if bbox is not None:
            self.doc.paint(uid, bbox, stamp, not self._erasing)

    def _lasso(self, uid: int, e: MouseEvent) -> bool:
        if e.type == EventType.PRESS:
            self.polygon = [(e.x, e.y)]
            self._erasing = e.subtract
            return True
        if not self.polygon:
            return False
        if e.type == EventType.MOVE:
            last = self.polygon[-1]
            if (e.x - last[0]) ** 2 + (e.y - last[1]) ** 2 >= 0.25:
                self.polygon.append((e.x, e.y))
            return True
        if e.type == EventType.RELEASE:
            self.polygon.append((e.x, e.y))
            pts, self.polygon = self.polygon, []
            if len(pts) >= 3:
                self._fill_polygon(uid, pts, self._erasing)
            return True
        return False

    def _polygon(self, uid: int, e: MouseEvent) -> bool:
        if e.type == EventType.DOUBLE_CLICK:
            self.close_polygon(subtract=e.subtract)
            return True
        if e.type == EventType.PRESS:
            if len(self.polygon) >= 3:
                fx, fy = self.polygon[0]
                if (e.x - fx) ** 2 + (e.y - fy) ** 2 <= 4.0:  # clicked the first vertex
                    self.close_polygon(subtract=e.subtract)
                    return True
            self.polygon.append((e.x, e.y))
            return True
        return False

    def _fill_polygon(self, uid: int, pts, subtract: bool) -> None:
        bbox, stamp = polygon_mask(pts, self.doc.shape)
        if bbox is None:
            return
        self._apply_region(uid, stamp, subtract, "Polygon", bbox=bbox)

    def _apply_region(self, uid: int, region: np.ndarray, subtract: bool, text: str, *, bbox: BBox | None = None):
        if bbox is None:
            rows = np.flatnonzero(region.any(axis=1))
            if rows.size == 0:
                return
            cols = np.flatnonzero(region.any(axis=0))
            bbox = (int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1)
            region = region[bbox[0] : bbox[1], bbox[2] : bbox[3]]
        y0, y1, x0, x1 = bbox
        t = self.doc.target(uid)
        if t.coverage is not None:  # a soft edge keeps its coverage outside the region
            new = np.where(region, np.float32(0 if subtract else 1), t.coverage[y0:y1, x0:x1])
        else:
            old = t.mask[y0:y1, x0:x1]
            new = old & ~region if subtract else old | region
        self.doc.set_mask_region(uid, bbox, new, text)


def _similar_from_log(logs: tuple[np.ndarray, np.ndarray], x: float, y: float, tolerance: float) -> np.ndarray:
    logimg, smooth = logs
    h, w = logimg.shape[:2]
    j, i = int(np.floor(x)), int(np.floor(y))
    if not (0 <= i < h and 0 <= j < w):
        return np.zeros((h, w), bool)
    tol = float(tolerance)
    seed = np.median(smooth[max(i - 2, 0) : i + 3, max(j - 2, 0) : j + 3].reshape(-1, 3), axis=0)
    hue = seed - seed.mean()

    def drifted(values: np.ndarray) -> np.ndarray:  # (..., 3): beyond the spans from the seed (brightness, hue)
        planes = [values[..., k] for k in range(3)]
        level = (planes[0] + planes[1] + planes[2]) / np.float32(3)
        out = np.abs(level - seed.mean()) > BRIGHTNESS_SPAN * tol
        for k in range(3):
            out |= np.abs(planes[k] - level - hue[k]) > HUE_SPAN * tol
        return out

    far = drifted(smooth)
    far[i, j] = False  # the pixel clicked is always in
    gated = smooth.copy()
    gated[far] = 1e6  # unreachable: no step is that small
    mask = np.zeros((h + 2, w + 2), np.uint8)
    flags = 4 | cv2.FLOODFILL_MASK_ONLY | (1 << 8)  # a floating range: each pixel against its neighbour
    cv2.floodFill(gated, mask, (j, i), (0, 0, 0), (tol,) * 3, (tol,) * 3, flags)
    region = mask[1:-1, 1:-1].astype(bool)
    # the smoothing blurred the surface's own rim into its neighbour's colour: a pixel beside the region whose
    # unsmoothed colour is that of the region pixel next to it joins (a hard edge is filled to its last pixel),
    # within the spans too; twice, as a corner's pixel is beside two rim pixels only
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    for _ in range(2):
        ys, xs = np.nonzero(cv2.dilate(region.view(np.uint8), cross).view(bool) & ~region)
        keep = ~drifted(logimg[ys, xs])
        ys, xs = ys[keep], xs[keep]
        join = np.zeros(len(ys), bool)
        for dy, dx in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            ny, nx = np.clip(ys + dy, 0, h - 1), np.clip(xs + dx, 0, w - 1)
            join |= region[ny, nx] & np.all(np.abs(logimg[ys, xs] - logimg[ny, nx]) <= tol, axis=-1)
        region[ys[join], xs[join]] = True
    return region
