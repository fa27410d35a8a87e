"""Small widgets and helpers shared by the calibration wizard and the acquisition panel.

- :class:`LiveView` — a camera frame with a saturation overlay; brightness follows the exposure.
- :class:`CoverageMap` — the Gray-code status of every camera pixel, coloured by
  :class:`~engine.calibrate.PixelStatus`, with a legend of counts.
- :class:`ResponsePlot` — the projector response as measured (per channel) and as fitted.
- :class:`ThumbnailStrip` — captures as they arrive, downscaled, in sRGB.

(Progress displays and rig jobs live in :mod:`app.qt.worker`.)

Display conversions clip to [0, 1] here, for the screen only; measurement data stay float.
"""

from __future__ import annotations

import math

import numpy as np
from PySide6.QtCore import QPointF, QRectF, QSize, Qt
from PySide6.QtGui import QColor, QFont, QIcon, QImage, QPainter, QPainterPath, QPen, QPixmap
from PySide6.QtWidgets import (
    QAbstractItemView,
    QListView,
    QListWidget,
    QListWidgetItem,
    QSizePolicy,
    QWidget,
)

from engine.calibrate import PixelStatus
from engine.imageio import to_display

__all__ = [
    "CoverageMap",
    "LiveView",
    "ResponsePlot",
    "STATUS_COLOURS",
    "ThumbnailStrip",
    "display_rgb",
    "downscale",
    "rgb_to_qimage",
]

#: Colour of each Gray-code pixel status on the coverage map, and its legend text.
STATUS_COLOURS: dict[PixelStatus, tuple[str, str]] = {
    PixelStatus.DECODED: ("#3fae5a", "decoded"),
    PixelStatus.UNLIT: ("#3b4a8f", "unlit (projector shadow or no surface)"),
    PixelStatus.LOW_CONTRAST: ("#f0a030", "low contrast"),
    PixelStatus.OUT_OF_RANGE: ("#d0306a", "outside the projector"),
}

_SATURATED = QColor(255, 0, 200)
_CHANNELS = (("R", QColor(220, 50, 50)), ("G", QColor(40, 160, 60)), ("B", QColor(50, 90, 230)))


# ---------------------------------------------------------------------------------- helpers
def downscale(image: np.ndarray, max_size: int) -> np.ndarray:
    """Area-average ``image`` by the smallest integer factor that fits ``max_size`` pixels.

    Parameters
    ----------
    image : (H, W) or (H, W, C) float
    max_size : int
        Largest side of the result, in pixels.

    Returns
    -------
    (h, w) or (h, w, C) float32
        ``h = H // f``, ``w = W // f`` with ``f = ceil(max(H, W) / max_size)`` (edge rows and
        columns that do not fill a block are dropped).

    Examples
    --------
    >>> downscale(np.arange(16, dtype=np.float32).reshape(4, 4), 2).tolist()
    [[2.5, 4.5], [10.5, 12.5]]
    """
    a = np.asarray(image, np.float32)
    f = max(1, math.ceil(max(a.shape[:2]) / max(int(max_size), 1)))
    if f == 1:
        return a
    h, w = a.shape[0] // f, a.shape[1] // f
    blocks = a[: h * f, : w * f].reshape((h, f, w, f) + a.shape[2:])
    return blocks.mean(axis=(1, 3), dtype=np.float32)


def display_rgb(image: np.ndarray, *, scale: float | None = None, percentile: float = 99.5) -> np.ndarray:
    """8-bit sRGB of linear radiance for the screen: scaled, then :func:`engine.imageio.to_display`.

    Parameters
    ----------
    image : (H, W, 3) float
        Linear radiance (negative noise and values above white are clipped, for display only).
    scale : float, optional
        Multiply by this before encoding; default: the ``percentile`` of the finite values
        maps to 1 (an all-dark image stays dark).

    Returns
    -------
    (H, W, 3) uint8

    Examples
    --------
    >>> display_rgb(np.full((1, 2, 3), 4.0, np.float32))[0, 0].tolist()
    [255, 255, 255]
    >>> display_rgb(np.full((1, 1, 3), 0.18, np.float32), scale=1.0)[0, 0].tolist()
    [118, 118, 118]
    """
    a = np.nan_to_num(np.asarray(image, np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    if scale is None:
        top = float(np.percentile(a, percentile)) if a.size else 0.0
        scale = 1.0 / top if top > 0 else 1.0
    return to_display(a * np.float32(scale))


def rgb_to_qimage(rgb: np.ndarray) -> QImage:
    """Copy an (H, W, 3) uint8 array into a QImage (RGB888)."""
    a = np.ascontiguousarray(rgb, np.uint8)
    h, w = a.shape[:2]
    return QImage(a.data, w, h, 3 * w, QImage.Format.Format_RGB888).copy()


# ---------------------------------------------------------------------------------- live view
class LiveView(QWidget):
    """A camera frame scaled to fit (nearest neighbour), saturated pixels painted magenta.

    White on screen is the camera's full scale when frames say where it is; otherwise the first
    frame sets the display scale and later frames are shown at ``exposure × gain`` relative to
    it, so the picture brightens with a longer exposure as the sensor does.

    Attributes
    ----------
    frames : int
        Frames shown so far.
    saturated_fraction : float
        Share of the last frame's pixels that clipped.
    """

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.setMinimumSize(200, 160)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.show_saturation = True
        self.frames = 0
        self.saturated_fraction = 0.0
        self._image: QImage | None = None
        self._overlay: QImage | None = None
        self._scale: float | None = None

    def reset_scale(self) -> None:
        """Let the next frame set the display scale again (another rig or scene)."""
        self._scale = None

    def set_frame(self, image: np.ndarray, saturated: np.ndarray | None = None, *, exposure: float = 1.0,
                  gain: float = 1.0, full_scale: float | None = None) -> None:
        """Show one frame: linear radiance ``image`` (H, W, 3), ``saturated`` (H, W) bool.

        With a known ``full_scale`` (``Frame.full_scale``), white on screen is where the camera
        clips, so only a saturated frame looks white. A camera that does not clip (``inf``)
        gives the same radiance at every exposure: the picture keeps the first frame's scale.
        """
        a = np.asarray(image, np.float32)
        if full_scale is not None and np.isfinite(full_scale) and full_scale > 0:
            scale = 1.0 / float(full_scale)
        else:
            sensor = float(exposure) * float(gain) if full_scale is None else 1.0
            if self._scale is None:
                top = float(np.percentile(a, 99.5)) if a.size else 0.0
                self._scale = 0.8 / (top * sensor) if top > 0 and sensor > 0 else 1.0
            scale = self._scale * sensor
        self._image = rgb_to_qimage(display_rgb(a, scale=scale))
        sat = np.zeros(a.shape[:2], bool) if saturated is None else np.asarray(saturated, bool)
        self.saturated_fraction = float(sat.mean()) if sat.size else 0.0
        rgba = np.zeros(sat.shape + (4,), np.uint8)
        rgba[sat] = (_SATURATED.red(), _SATURATED.green(), _SATURATED.blue(), 255)
        h, w = sat.shape
        self._overlay = QImage(np.ascontiguousarray(rgba).data, w, h, 4 * w, QImage.Format.Format_RGBA8888).copy()
        self.frames += 1
        self.update()

    def set_show_saturation(self, on: bool) -> None:
        self.show_saturation = bool(on)
        self.update()

    def _target(self) -> QRectF:
        if self._image is None:
            return QRectF(self.rect())
        iw, ih = self._image.width(), self._image.height()
        s = min(self.width() / iw, self.height() / ih)
        return QRectF((self.width() - iw * s) / 2, (self.height() - ih * s) / 2, iw * s, ih * s)

    def paintEvent(self, event) -> None:  # noqa: N802 (Qt name)
        p = QPainter(self)
        p.fillRect(self.rect(), QColor(24, 24, 24))
        if self._image is None:
            p.setPen(QColor(180, 180, 180))
            p.drawText(self.rect(), Qt.AlignmentFlag.AlignCenter, "waiting for the camera…")
            return
        r = self._target()
        p.setRenderHint(QPainter.RenderHint.SmoothPixmapTransform, False)
        p.drawImage(r, self._image)
        if self.show_saturation and self._overlay is not None and self.saturated_fraction > 0:
            p.drawImage(r, self._overlay)
        p.setPen(QColor(255, 255, 255))
        p.drawText(r.adjusted(6, 4, -6, -4), Qt.AlignmentFlag.AlignLeft | Qt.AlignmentFlag.AlignTop,
                   f"saturated {100 * self.saturated_fraction:.2f}%")
        p.end()


# ---------------------------------------------------------------------------------- coverage map
class CoverageMap(QWidget):
    """Where the Gray code decoded: one colour per :class:`PixelStatus`, over the scene.

    Call :meth:`set_status` with the correspondence's ``status`` (and optionally a capture
    under projector white as a dim background); the legend gives each status's pixel count.

    Attributes
    ----------
    counts : dict[PixelStatus, int]
    """

    LEGEND_ROW = 18

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.setMinimumSize(220, 200)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.counts: dict[PixelStatus, int] = {}
        self._image: QImage | None = None

    def set_status(self, status: np.ndarray, background: np.ndarray | None = None) -> None:
        """Show ``status`` (H, W) PixelStatus codes; ``background`` (H, W, 3) linear radiance."""
        s = np.asarray(status)
        rgb = np.zeros(s.shape + (3,), np.float32)
        for code, (colour, _) in STATUS_COLOURS.items():
            c = QColor(colour)
            rgb[s == code] = (c.red(), c.green(), c.blue())
        if background is not None:  # shade decoded pixels by the scene; problems keep full colour
            grey = display_rgb(np.asarray(background, np.float32)).mean(axis=-1, dtype=np.float32) / 255.0
            decoded = s == PixelStatus.DECODED
            rgb[decoded] *= (0.45 + 0.55 * grey[decoded])[:, None]
        self._image = rgb_to_qimage(np.clip(rgb, 0, 255).astype(np.uint8))
        n = np.bincount(s.ravel().astype(np.int64), minlength=len(PixelStatus))
        self.counts = {p: int(n[p]) for p in PixelStatus}
        self.update()

    def legend_lines(self) -> list[str]:
        """The legend's text, one line per status: ``"decoded: 570 (99.0%)"``."""
        total = max(sum(self.counts.values()), 1)
        return [f"{STATUS_COLOURS[p][1]}: {n} ({100 * n / total:.1f}%)" for p, n in self.counts.items()]

    def paintEvent(self, event) -> None:  # noqa: N802 (Qt name)
        p = QPainter(self)
        p.fillRect(self.rect(), self.palette().window())
        legend_h = self.LEGEND_ROW * len(PixelStatus) + 6
        area = QRectF(0, 0, self.width(), max(self.height() - legend_h, 10))
        if self._image is None:
            p.drawText(area, Qt.AlignmentFlag.AlignCenter, "no calibration yet")
        else:
            iw, ih = self._image.width(), self._image.height()
            s = min(area.width() / iw, area.height() / ih)
            r = QRectF((area.width() - iw * s) / 2, (area.height() - ih * s) / 2, iw * s, ih * s)
            p.drawImage(r, self._image)
            p.setPen(QPen(self.palette().text().color(), 1))
            p.drawRect(r)
        y = area.bottom() + 6
        lines = self.legend_lines() if self.counts else [STATUS_COLOURS[q][1] for q in PixelStatus]
        for code, line in zip(PixelStatus, lines, strict=True):
            p.fillRect(QRectF(8, y + 3, 12, 12), QColor(STATUS_COLOURS[code][0]))
            p.setPen(self.palette().text().color())
            p.drawText(QRectF(26, y, self.width() - 30, self.LEGEND_ROW),
                       Qt.AlignmentFlag.AlignLeft | Qt.AlignmentFlag.AlignVCenter, line)
            y += self.LEGEND_ROW
        p.end()


# ---------------------------------------------------------------------------------- response plot
class ResponsePlot(QWidget):
    """The projector response per channel: measured points joined by lines, the fit dashed.

    x: projector input 0…1; y: light above black relative to white (``raw_table`` as
    measured, ``table`` after forcing it monotonic). A dotted diagonal marks a linear projector.
    """

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.setMinimumSize(240, 200)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.levels: np.ndarray | None = None
        self.measured: np.ndarray | None = None
        self.fitted: np.ndarray | None = None
        self.black_level: np.ndarray | None = None

    def set_response(self, response) -> None:
        """Plot an :class:`engine.calibrate.ProjectorResponse`."""
        self.levels = np.asarray(response.levels, float)
        self.fitted = np.asarray(response.table, float)
        raw = response.raw_table
        self.measured = self.fitted if raw is None else np.asarray(raw, float)
        self.black_level = np.asarray(response.black_level, float)
        self.update()

    def paintEvent(self, event) -> None:  # noqa: N802 (Qt name)
        p = QPainter(self)
        p.setRenderHint(QPainter.RenderHint.Antialiasing, True)
        p.fillRect(self.rect(), self.palette().base())
        text = self.palette().text().color()
        fm = p.fontMetrics()
        left, right, top, bottom = fm.horizontalAdvance("0.00") + 14, 12, fm.height() + 10, 2 * fm.height() + 12
        plot = QRectF(left, top, max(self.width() - left - right, 20), max(self.height() - top - bottom, 20))
        lo, hi = 0.0, 1.0
        if self.measured is not None:
            lo = min(0.0, float(np.nanmin(self.measured)))
            hi = max(1.0, float(np.nanmax(self.measured)))

        def pt(x: float, y: float) -> QPointF:
            return QPointF(plot.left() + x * plot.width(), plot.bottom() - (y - lo) / (hi - lo) * plot.height())

        p.setPen(QPen(text, 1))
        p.drawText(QRectF(0, 2, self.width(), fm.height() + 4), Qt.AlignmentFlag.AlignHCenter,
                   "Projector response (measured)")
        grid = QColor(text)
        grid.setAlpha(50)
        for t in (0.0, 0.25, 0.5, 0.75, 1.0):
            p.setPen(QPen(grid, 1))
            p.drawLine(pt(t, lo), pt(t, hi))
            p.drawLine(pt(0, t), pt(1, t))
            p.setPen(text)
            x = pt(t, lo)
            p.drawText(QRectF(x.x() - 20, plot.bottom() + 2, 40, fm.height()), Qt.AlignmentFlag.AlignHCenter, f"{t:g}")
            y = pt(0, t)
            p.drawText(QRectF(0, y.y() - fm.height() / 2, left - 4, fm.height()),
                       Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter, f"{t:.2f}")
        p.drawText(QRectF(plot.left(), plot.bottom() + fm.height() + 2, plot.width(), fm.height() + 4),
                   Qt.AlignmentFlag.AlignHCenter, "projector input → light above black (relative to white)")
        p.setPen(QPen(text, 1))
        p.drawRect(plot)
        dotted = QPen(grid, 1, Qt.PenStyle.DotLine)
        p.setPen(dotted)
        p.drawLine(pt(0, 0), pt(1, 1))
        if self.levels is None:
            p.drawText(plot, Qt.AlignmentFlag.AlignCenter, "no calibration yet")
            p.end()
            return
        for c, (_label, colour) in enumerate(_CHANNELS):
            fit = QPainterPath(pt(self.levels[0], self.fitted[0, c]))
            for x, y in zip(self.levels[1:], self.fitted[1:, c], strict=True):
                fit.lineTo(pt(x, y))
            p.setPen(QPen(colour, 1, Qt.PenStyle.DashLine))
            p.drawPath(fit)
            meas = QPainterPath(pt(self.levels[0], self.measured[0, c]))
            for x, y in zip(self.levels[1:], self.measured[1:, c], strict=True):
                meas.lineTo(pt(x, y))
            p.setPen(QPen(colour, 1.6))
            p.drawPath(meas)
            p.setBrush(colour)
            for x, y in zip(self.levels, self.measured[:, c], strict=True):
                p.drawEllipse(pt(x, y), 2.2, 2.2)
            p.setBrush(Qt.BrushStyle.NoBrush)
        # legend, inside the plot's upper left
        y = plot.top() + 6
        for c, (label, colour) in enumerate(_CHANNELS):
            p.setPen(QPen(colour, 2))
            p.drawLine(QPointF(plot.left() + 8, y + 6), QPointF(plot.left() + 24, y + 6))
            p.setPen(text)
            b = "" if self.black_level is None else f"  at black {self.black_level[c]:.3f} of white"
            p.drawText(QPointF(plot.left() + 28, y + 6 + fm.ascent() / 2 - 1), f"{label}{b}")
            y += fm.height() + 2
        p.setPen(text)
        p.drawText(QPointF(plot.left() + 8, y + 6 + fm.ascent() / 2), "— measured   - - fitted")
        p.end()


# ---------------------------------------------------------------------------------- thumbnails
class ThumbnailStrip(QListWidget):
    """A horizontal strip of captures, newest last, scrolled to the newest."""

    def __init__(self, parent: QWidget | None = None, *, size: int = 72):
        super().__init__(parent)
        self.thumb_size = int(size)
        self.setViewMode(QListView.ViewMode.IconMode)
        self.setFlow(QListView.Flow.LeftToRight)
        self.setWrapping(False)
        self.setMovement(QListView.Movement.Static)
        self.setSelectionMode(QAbstractItemView.SelectionMode.NoSelection)
        self.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAsNeeded)
        self.setVerticalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.setIconSize(QSize(self.thumb_size, self.thumb_size))
        self.setTextElideMode(Qt.TextElideMode.ElideMiddle)
        self.setGridSize(QSize(self.thumb_size + 16, self.thumb_size + 22))
        font = QFont(self.font())
        font.setPointSizeF(max(font.pointSizeF() * 0.8, 6))
        self.setFont(font)
        self.setFixedHeight(self.thumb_size + 22 + self.horizontalScrollBar().sizeHint().height() + 8)

    @staticmethod
    def make_thumbnail(image: np.ndarray, size: int) -> np.ndarray:
        """(h, w, 3) uint8 sRGB of a capture, at most ``size`` pixels on a side (worker-safe)."""
        return display_rgb(downscale(image, size))

    def add_thumbnail(self, name: str, rgb: np.ndarray) -> QListWidgetItem:
        """Append a thumbnail made by :meth:`make_thumbnail`."""
        pix = QPixmap.fromImage(rgb_to_qimage(rgb)).scaled(
            self.thumb_size, self.thumb_size, Qt.AspectRatioMode.KeepAspectRatio,
            Qt.TransformationMode.FastTransformation)
        item = QListWidgetItem(QIcon(pix), name.removeprefix("acq-").removeprefix("cal-"))
        item.setToolTip(name)
        item.setData(Qt.ItemDataRole.UserRole, name)
        self.addItem(item)
        self.scrollToItem(item)
        return item

    def names(self) -> list[str]:
        """Capture names, in arrival order."""
        return [self.item(i).data(Qt.ItemDataRole.UserRole) for i in range(self.count())]
