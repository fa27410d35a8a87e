"""The canvas: shows frames, target overlays and tool feedback; zoom, pan, split divider.

Qt mouse events become plain :class:`app.model.painting.MouseEvent` in camera-pixel coordinates and
go to the :class:`~app.model.painting.Painter`; the canvas itself never edits masks. Pan with the
middle button or with Space held; zoom with the wheel (around the cursor), Fit and 100 %.
Every move of the view is announced (:attr:`Canvas.viewport_changed`) so the preview can
sharpen the visible region; a :class:`~app.model.render.Detail` is drawn over the frame of the same
request and dropped when a frame of another request arrives.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QPointF, QRectF, Qt, Signal
from PySide6.QtGui import (
    QBrush,
    QColor,
    QFont,
    QFontMetrics,
    QFontMetricsF,
    QImage,
    QLinearGradient,
    QMouseEvent,
    QPainter,
    QPen,
    QPolygonF,
)
from PySide6.QtWidgets import QWidget

from app.model.document import Document
from app.model.painting import EventType, MouseEvent, Painter, Tool
from app.model.render import Detail, PreviewFrame
from app.model.views import CanvasView

_BACKGROUND = QColor(38, 38, 40)
_OVERLAY_ALPHA = 0  # other targets: outline only, so the recoloring stays visible
_CURRENT_ALPHA = 28  # the current target: a light tint under its outline


def _qimage(words: np.ndarray) -> QImage:
    """Wrap (h, w) uint32 0xFFRRGGBB words without copying (the array must outlive the image)."""
    h, w = words.shape
    return QImage(words.data, w, h, 4 * w, QImage.Format.Format_RGB32)


def _qimages(first: np.ndarray, second: np.ndarray | None) -> tuple[QImage, QImage | None]:
    return _qimage(first), (_qimage(second) if second is not None else None)


#: How the banner's text is laid out in its strip.
BANNER_FLAGS = Qt.AlignmentFlag.AlignCenter | Qt.TextFlag.TextWordWrap


class Canvas(QWidget):
    """Image view with painting.

    Signals
    -------
    cursor_moved(object)
        ``(x, y)`` camera pixel under the cursor, or None when it leaves the image.
    zoom_changed(float)
        Screen pixels per camera pixel.
    viewport_changed(tuple, float)
        The camera pixels ``(y0, y1, x0, x1)`` on screen and the zoom, after every zoom, pan
        or resize.
    picked(float, float)
        While :attr:`picking` (the eyedropper): the camera pixel ``(x, y)`` clicked; a click
        picks instead of painting.
    """

    cursor_moved = Signal(object)
    zoom_changed = Signal(float)
    viewport_changed = Signal(tuple, float)
    picked = Signal(float, float)

    MIN_ZOOM, MAX_ZOOM = 1.0 / 64.0, 64.0

    def __init__(self, document: Document, painter: Painter, parent: QWidget | None = None):
        super().__init__(parent)
        self.setMouseTracking(True)
        self.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        self.setMinimumSize(320, 240)
        self.setAttribute(Qt.WidgetAttribute.WA_OpaquePaintEvent)
        self.doc = document
        self.painter = painter
        self.frame: PreviewFrame | None = None
        self._images: tuple[QImage, QImage | None] | None = None
        self.detail: Detail | None = None
        self._detail_images: tuple[QImage, QImage | None] | None = None
        self.zoom = 1.0
        self.offset = QPointF(0.0, 0.0)  # widget position of camera pixel (0, 0)
        self._extent: tuple[int, int] = document.shape
        self._fitted = True
        self.split = 0.5  # split-view divider, fraction of the image width
        self.show_overlays = True
        self._overlay = np.zeros(document.shape, np.uint32)
        self._overlay_image = QImage(self._overlay.data, document.shape[1], document.shape[0], 4 * document.shape[1],
                                     QImage.Format.Format_ARGB32_Premultiplied)
        self._mouse: QPointF | None = None
        self._pan_from: tuple[QPointF, QPointF] | None = None
        self._space = False
        self._dragging_split = False
        self._painting = False
        self.picking = False
        self.paint_count = 0  # frames painted (benchmarks wait on it)
        self.painted_request = 0
        ev = document.events
        ev.mask.connect(self._on_mask)
        ev.targets.connect(self._rebuild_overlay)
        ev.current.connect(lambda _uid: self._rebuild_overlay())
        self._rebuild_overlay()

    # ------------------------------------------------------------------ frames and geometry
    def set_frame(self, frame: PreviewFrame) -> None:
        """Show ``frame`` (keeps a reference: the QImages wrap its arrays)."""
        extent_changed = tuple(frame.extent) != self._extent
        self.frame = frame
        self._images = _qimages(frame.pixels, frame.second)
        if self.detail is not None and not self._matches(self.detail):
            self.detail = self._detail_images = None
        if extent_changed:
            self._extent = tuple(frame.extent)
            self.fit()
        self.update()

    def set_detail(self, detail: Detail) -> None:
        """Draw ``detail`` over the frame while the frame on screen is of the same request."""
        if not self._matches(detail):
            return
        self.detail = detail
        self._detail_images = _qimages(detail.pixels, detail.second)
        self.update()

    def _matches(self, detail: Detail) -> bool:
        f = self.frame
        return f is not None and f.generation == detail.generation and f.request == detail.request

    def visible_region(self) -> tuple[int, int, int, int]:
        """Camera pixels ``(y0, y1, x0, x1)`` inside the widget (clipped to the image)."""
        h, w = self._extent
        top_left = self.to_image(QPointF(0.0, 0.0))
        bottom_right = self.to_image(QPointF(float(self.width()), float(self.height())))
        y0, x0 = max(int(np.floor(top_left.y())), 0), max(int(np.floor(top_left.x())), 0)
        y1, x1 = min(int(np.ceil(bottom_right.y())), h), min(int(np.ceil(bottom_right.x())), w)
        return y0, max(y1, y0), x0, max(x1, x0)

    def _view_moved(self) -> None:
        self.update()
        if self._paints_camera_pixels():
            self.viewport_changed.emit(self.visible_region(), self.zoom)

    def fit(self) -> None:
        """Zoom so the whole image fits, centred."""
        h, w = self._extent
        if self.width() < 2 or self.height() < 2:
            return
        z = min(self.width() / w, self.height() / h)
        self._set_zoom(z, QPointF((self.width() - w * z) / 2, (self.height() - h * z) / 2))
        self._fitted = True

    def zoom_to(self, zoom: float, anchor: QPointF | None = None) -> None:
        """Set the zoom (screen px per camera px) keeping ``anchor`` (widget coords) fixed."""
        zoom = float(min(max(zoom, self.MIN_ZOOM), self.MAX_ZOOM))
        if anchor is None:
            anchor = QPointF(self.width() / 2, self.height() / 2)
        img = self.to_image(anchor)
        self._set_zoom(zoom, QPointF(anchor.x() - img.x() * zoom, anchor.y() - img.y() * zoom))
        self._fitted = False

    def zoom_by(self, factor: float, anchor: QPointF | None = None) -> None:
        self.zoom_to(self.zoom * factor, anchor)

    def _set_zoom(self, zoom: float, offset: QPointF) -> None:
        changed = zoom != self.zoom
        self.zoom, self.offset = zoom, offset
        self._view_moved()
        if changed:
            self.zoom_changed.emit(zoom)

    def to_image(self, p: QPointF) -> QPointF:
        """Widget coordinates → camera-pixel coordinates (float)."""
        return QPointF((p.x() - self.offset.x()) / self.zoom, (p.y() - self.offset.y()) / self.zoom)

    def to_widget(self, p: QPointF) -> QPointF:
        return QPointF(p.x() * self.zoom + self.offset.x(), p.y() * self.zoom + self.offset.y())

    def image_rect(self) -> QRectF:
        h, w = self._extent
        return QRectF(self.offset.x(), self.offset.y(), w * self.zoom, h * self.zoom)

    def _paints_camera_pixels(self) -> bool:
        return self.frame is None or self.frame.view != CanvasView.COMPONENTS

    # ------------------------------------------------------------------ overlays
    @staticmethod
    def _word(colour, alpha: int) -> np.uint32:
        r, g, b = (int(c * alpha / 255) for c in colour)  # premultiplied ARGB
        return np.uint32((alpha << 24) | (r << 16) | (g << 8) | b)

    @staticmethod
    def _words(colour, alpha: np.ndarray) -> np.ndarray:
        """Premultiplied ARGB words of one colour at per-pixel ``alpha`` (uint32 0..255), as :meth:`_word`."""
        r, g, b = ((np.uint32(c) * alpha) // np.uint32(255) for c in colour)
        return (alpha << np.uint32(24)) | (r << np.uint32(16)) | (g << np.uint32(8)) | b

    def _compose(self, y0: int, y1: int, x0: int, x1: int) -> None:
        """Redraw the overlay in a box: light fill, strong outline, hatched unreachable pixels.

        The outline covers a target's edge band — pixels partly on it (coverage between 0 and
        1, a feathered stroke or a refined edge) and the whole pixels next to them or to the
        outside — with an alpha proportional to each pixel's coverage, so a soft edge shows as a
        ramp; a binary mask's band is its one-pixel boundary at full alpha.
        """
        h, w = self.doc.shape
        # one extra pixel around the box so outlines at its border see their neighbours
        ey0, ey1, ex0, ex1 = max(y0 - 1, 0), min(y1 + 1, h), max(x0 - 1, 0), min(x1 + 1, w)
        region = np.zeros((ey1 - ey0, ex1 - ex0), np.uint32)
        painted = np.zeros(region.shape, bool)
        for t in self.doc.targets:
            cov = None if t.coverage is None else t.coverage[ey0:ey1, ex0:ex1]
            seen = t.mask[ey0:ey1, ex0:ex1] if cov is None else cov > 0
            if not seen.any():
                continue
            whole = seen if cov is None else cov >= 1
            p = np.pad(whole, 1, mode="edge")
            interior = p[:-2, 1:-1] & p[2:, 1:-1] & p[1:-1, :-2] & p[1:-1, 2:] & whole
            current = t.uid == self.doc.current
            band = seen & ~interior
            region[interior] = self._word(t.colour, _CURRENT_ALPHA if current else _OVERLAY_ALPHA)
            strong = 255 if current else 200
            if cov is None:
                region[band] = self._word(t.colour, strong)
            else:
                alpha = np.rint(np.clip(cov[band], 0, 1) * strong).astype(np.uint32)
                region[band] = self._words(t.colour, alpha)
            painted |= seen
        if self.doc.unreachable is not None:
            unreach = self.doc.unreachable[ey0:ey1, ex0:ex1]
            if unreach.any():
                yy, xx = np.mgrid[ey0:ey1, ex0:ex1]
                stripe = ((xx + yy) // 2) % 4 == 0
                region[unreach & stripe & ~painted] = np.uint32(0x40404040)  # grey hatch: not reachable
                region[unreach & stripe & painted] = np.uint32(0xF0F00000)  # red hatch: painted but refused
        self._overlay[y0:y1, x0:x1] = region[y0 - ey0 : y1 - ey0, x0 - ex0 : x1 - ex0]

    def _rebuild_overlay(self) -> None:
        h, w = self.doc.shape
        self._compose(0, h, 0, w)
        self.update()

    def _on_mask(self, uid: int, bbox) -> None:
        self._compose(*bbox)
        self.update()

    # ------------------------------------------------------------------ painting
    def paintEvent(self, event) -> None:  # noqa: N802 - Qt override
        p = QPainter(self)
        p.fillRect(self.rect(), _BACKGROUND)
        rect = self.image_rect()
        if self._images is not None:
            self._draw_pair(p, rect, self._images, rect)
        if self._detail_images is not None:
            y0, y1, x0, x1 = self.detail.region
            place = QRectF(self.to_widget(QPointF(x0, y0)), self.to_widget(QPointF(x1, y1)))
            self._draw_pair(p, place, self._detail_images, rect)
        if self.show_overlays and self._paints_camera_pixels():
            p.setRenderHint(QPainter.RenderHint.SmoothPixmapTransform, self.zoom < 1.0)
            p.drawImage(rect, self._overlay_image)
        p.setRenderHint(QPainter.RenderHint.Antialiasing, True)
        if self.frame is not None and self.frame.second is not None:
            self._draw_divider(p, rect)
        if self.frame is not None and self.frame.tiles:
            self._draw_tiles(p, rect)
        self._draw_tool(p)
        if self.frame is not None and self.frame.scale is not None:
            self._draw_scale(p)
        if self.frame is not None and self.frame.banner:
            self._draw_banner(p)
        p.end()
        self.paint_count += 1
        if self.frame is not None:
            self.painted_request = self.frame.request_id

    def _draw_pair(self, p: QPainter, place: QRectF, images, rect: QRectF) -> None:
        """Draw ``images`` (first, optional second) stretched over ``place``; with a second, the
        split divider at ``self.split`` of the image ``rect`` cuts between them."""
        first, second = images
        p.setRenderHint(QPainter.RenderHint.SmoothPixmapTransform, place.width() / max(first.width(), 1) < 2.0)
        if second is None:
            p.drawImage(place, first)
            return
        cut = min(max(rect.left() + rect.width() * self.split, place.left()), place.right())
        p.save()
        p.setClipRect(QRectF(place.left(), place.top(), cut - place.left(), place.height()))
        p.drawImage(place, first)
        p.setClipRect(QRectF(cut, place.top(), place.right() - cut, place.height()))
        p.drawImage(place, second)
        p.restore()

    def _draw_divider(self, p: QPainter, rect: QRectF) -> None:
        x = rect.left() + rect.width() * self.split
        p.setPen(QPen(QColor(255, 255, 255, 220), 2))
        p.drawLine(QPointF(x, rect.top()), QPointF(x, rect.bottom()))
        cy = min(max(rect.center().y(), 20), self.height() - 20)
        p.setBrush(QColor(255, 255, 255, 230))
        p.drawEllipse(QPointF(x, cy), 9, 9)
        p.setPen(QPen(QColor(40, 40, 40), 2))
        p.drawLine(QPointF(x - 4, cy), QPointF(x - 1, cy - 3))
        p.drawLine(QPointF(x - 4, cy), QPointF(x - 1, cy + 3))
        p.drawLine(QPointF(x + 4, cy), QPointF(x + 1, cy - 3))
        p.drawLine(QPointF(x + 4, cy), QPointF(x + 1, cy + 3))
        p.setFont(self._caption_font())
        for text, box in self.split_captions(rect).items():
            p.setPen(Qt.PenStyle.NoPen)
            p.setBrush(QColor(0, 0, 0, 150))
            p.drawRoundedRect(box, 4, 4)
            p.setPen(QColor(235, 235, 235))
            p.drawText(box, Qt.AlignmentFlag.AlignCenter, text)

    def _draw_tiles(self, p: QPainter, rect: QRectF) -> None:
        fh, fw = self.frame.pixels.shape
        sx, sy = rect.width() / fw, rect.height() / fh
        p.setPen(QPen(QColor(20, 20, 20), 2))
        p.setBrush(Qt.BrushStyle.NoBrush)
        for t in self.frame.tiles:
            box = QRectF(rect.left() + t.x * sx, rect.top() + t.y * sy, t.w * sx, t.h * sy)
            p.drawRect(box)
            label = QRectF(box.left() + 6, box.top() + 6, p.fontMetrics().horizontalAdvance(t.label) + 12, 20)
            p.save()
            p.setPen(Qt.PenStyle.NoPen)
            p.setBrush(QColor(0, 0, 0, 160))
            p.drawRoundedRect(label, 4, 4)
            p.setPen(QColor(240, 240, 240))
            p.drawText(label, Qt.AlignmentFlag.AlignCenter, t.label)
            p.restore()

    def _draw_tool(self, p: QPainter) -> None:
        if not self._paints_camera_pixels():
            return
        pts = self.painter.polygon
        if pts:
            poly = QPolygonF([self.to_widget(QPointF(x, y)) for x, y in pts])
            if self._mouse is not None and self.painter.tool == Tool.POLYGON:
                poly.append(self._mouse)
            for colour, width in ((QColor(0, 0, 0, 200), 3), (QColor(255, 255, 255), 1)):
                p.setPen(QPen(colour, width, Qt.PenStyle.SolidLine))
                p.drawPolyline(poly)
            p.setBrush(QColor(255, 255, 255))
            for pt in poly:
                p.drawEllipse(pt, 2.5, 2.5)
        if self._mouse is not None and self.picking:  # the eyedropper's averaged square (5×5 camera pixels)
            r = 2.5 * self.zoom
            p.setBrush(Qt.BrushStyle.NoBrush)
            for colour, width in ((QColor(0, 0, 0, 180), 3), (QColor(255, 255, 255), 1)):
                p.setPen(QPen(colour, width))
                p.drawRect(QRectF(self._mouse.x() - r, self._mouse.y() - r, 2 * r, 2 * r))
            return
        if self._mouse is not None and self.painter.tool in (Tool.BRUSH, Tool.ERASER) and self._pan_from is None:
            r = self.painter.size * self.zoom / 2
            p.setBrush(Qt.BrushStyle.NoBrush)
            for colour, width in ((QColor(0, 0, 0, 180), 3), (QColor(255, 255, 255), 1)):
                style = Qt.PenStyle.DashLine if self.painter.tool == Tool.ERASER else Qt.PenStyle.SolidLine
                p.setPen(QPen(colour, width, style))
                p.drawEllipse(self._mouse, r, r)

    def _caption_font(self) -> QFont:
        font = QFont(self.font())
        font.setPointSizeF(max(font.pointSizeF(), 9))
        return font

    def banner_strip(self) -> tuple[QRectF, QRectF]:
        """Where the banner is drawn (the strip across the top, its text's box); empty without a banner."""
        if self.frame is None or not self.frame.banner:
            return QRectF(), QRectF()
        inner = QRectF(12, 0, max(self.width() - 24, 10), 1000)
        box = QFontMetricsF(self.font()).boundingRect(inner, BANNER_FLAGS, self.frame.banner)
        return QRectF(0, 0, self.width(), box.height() + 12), QRectF(12, 6, inner.width(), box.height())

    def split_captions(self, rect: QRectF) -> dict[str, QRectF]:
        """The split view's two captions beside the divider of the image drawn at ``rect``: at the picture's
        top, but below the banner and inside the canvas when the picture reaches above it."""
        metrics = QFontMetricsF(self._caption_font())
        x = rect.left() + rect.width() * self.split
        top = max(rect.top(), self.banner_strip()[0].bottom(), 0.0) + 8
        boxes = {}
        for text, right in (("recolored", False), ("original", True)):
            tw = metrics.horizontalAdvance(text) + 12
            boxes[text] = QRectF(x + 14 if right else x - 14 - tw, top, tw, 20)
        return boxes

    def _draw_banner(self, p: QPainter) -> None:
        """A strip across the top of the canvas saying what the view cannot show yet."""
        strip, box = self.banner_strip()
        p.setFont(self.font())
        p.setPen(Qt.PenStyle.NoPen)
        p.setBrush(QColor(30, 60, 110, 215))
        p.drawRect(strip)
        p.setPen(QColor(245, 245, 245))
        p.drawText(box, BANNER_FLAGS, self.frame.banner)

    def _draw_scale(self, p: QPainter) -> None:
        s = self.frame.scale
        font = QFont(self.font())
        font.setPointSizeF(max(font.pointSizeF() - 1, 7))
        w, h = max(240, QFontMetrics(font).horizontalAdvance(s.label) + 4), 12  # the whole label fits
        x, y = self.width() - w - 24, self.height() - 58
        p.setPen(Qt.PenStyle.NoPen)
        p.setBrush(QColor(0, 0, 0, 170))
        p.drawRoundedRect(QRectF(x - 12, y - 24, w + 24, 64), 6, 6)
        grad = QLinearGradient(x, 0, x + w, 0)
        for i in range(0, 256, 15):
            r, g, b = (int(v) for v in s.cmap[i])
            grad.setColorAt(i / 255, QColor(r, g, b))
        r, g, b = (int(v) for v in s.cmap[255])
        grad.setColorAt(1.0, QColor(r, g, b))
        p.setBrush(QBrush(grad))
        p.drawRect(QRectF(x, y, w, h))
        p.setPen(QColor(230, 230, 230))
        p.setFont(font)
        p.drawText(QRectF(x, y - 20, w, 16), Qt.AlignmentFlag.AlignLeft, s.label)
        lo, hi = f"{s.lo:.3g}", f"{s.hi:.3g}"
        p.drawText(QRectF(x, y + h + 2, w, 16), Qt.AlignmentFlag.AlignLeft, lo)
        p.drawText(QRectF(x, y + h + 2, w, 16), Qt.AlignmentFlag.AlignRight, hi)
        if s.lo < 0 < s.hi:
            p.drawText(QRectF(x, y + h + 2, w, 16), Qt.AlignmentFlag.AlignHCenter, "0")

    # ------------------------------------------------------------------ input
    def _plain(self, kind: EventType, e: QMouseEvent) -> MouseEvent:
        img = self.to_image(e.position())
        buttons = set()
        if e.buttons() & Qt.MouseButton.LeftButton or e.button() == Qt.MouseButton.LeftButton:
            buttons.add("left")
        if e.buttons() & Qt.MouseButton.RightButton or e.button() == Qt.MouseButton.RightButton:
            buttons.add("right")
        subtract = bool(e.modifiers() & Qt.KeyboardModifier.AltModifier) or "right" in buttons
        return MouseEvent(kind, img.x(), img.y(), frozenset(buttons), subtract)

    def set_picking(self, on: bool) -> None:
        """The eyedropper: the next left clicks emit :attr:`picked` instead of painting."""
        self.picking = bool(on)
        self.update()

    def _near_divider(self, pos: QPointF) -> bool:
        if self.frame is None or self.frame.second is None:
            return False
        rect = self.image_rect()
        return abs(pos.x() - (rect.left() + rect.width() * self.split)) <= 8

    def mousePressEvent(self, e: QMouseEvent) -> None:  # noqa: N802
        self.setFocus()
        if e.button() == Qt.MouseButton.MiddleButton or (e.button() == Qt.MouseButton.LeftButton and self._space):
            self._pan_from = (e.position(), QPointF(self.offset))
            self.setCursor(Qt.CursorShape.ClosedHandCursor)
            return
        if e.button() == Qt.MouseButton.LeftButton and self._near_divider(e.position()):
            self._dragging_split = True
            return
        if self.picking and e.button() == Qt.MouseButton.LeftButton and self._paints_camera_pixels():
            img = self.to_image(e.position())
            self.picked.emit(img.x(), img.y())
            return
        if e.button() in (Qt.MouseButton.LeftButton, Qt.MouseButton.RightButton) and self._paints_camera_pixels():
            self._painting = self.painter.handle(self._plain(EventType.PRESS, e))
            self.update()

    def mouseDoubleClickEvent(self, e: QMouseEvent) -> None:  # noqa: N802
        if self.painter.tool == Tool.POLYGON and self._paints_camera_pixels():
            self.painter.handle(self._plain(EventType.DOUBLE_CLICK, e))
            self.update()
        else:
            self.mousePressEvent(e)

    def mouseMoveEvent(self, e: QMouseEvent) -> None:  # noqa: N802
        pos = e.position()
        self._mouse = pos
        if self._pan_from is not None:
            start, offset = self._pan_from
            self.offset = QPointF(offset.x() + pos.x() - start.x(), offset.y() + pos.y() - start.y())
            self._fitted = False
            self._view_moved()
            return
        if self._dragging_split:
            rect = self.image_rect()
            self.split = float(min(max((pos.x() - rect.left()) / max(rect.width(), 1.0), 0.0), 1.0))
            self.update()
            return
        self.setCursor(Qt.CursorShape.SplitHCursor if self._near_divider(pos) else
                       Qt.CursorShape.OpenHandCursor if self._space else Qt.CursorShape.CrossCursor)
        if self._painting or self.painter.polygon:
            self.painter.handle(self._plain(EventType.MOVE, e))
        img = self.to_image(pos)
        ix, iy = int(np.floor(img.x())), int(np.floor(img.y()))
        h, w = self.doc.shape
        inside = self._paints_camera_pixels() and 0 <= ix < w and 0 <= iy < h
        self.cursor_moved.emit((ix, iy) if inside else None)
        self.update()

    def mouseReleaseEvent(self, e: QMouseEvent) -> None:  # noqa: N802
        if self._pan_from is not None and e.button() in (Qt.MouseButton.MiddleButton, Qt.MouseButton.LeftButton):
            self._pan_from = None
            self.setCursor(Qt.CursorShape.OpenHandCursor if self._space else Qt.CursorShape.CrossCursor)
            return
        if self._dragging_split:
            self._dragging_split = False
            return
        if self._painting:
            self._painting = False
            self.painter.handle(self._plain(EventType.RELEASE, e))
            self.update()

    def leaveEvent(self, e) -> None:  # noqa: N802
        self._mouse = None
        self.cursor_moved.emit(None)
        self.update()

    def wheelEvent(self, e) -> None:  # noqa: N802
        steps = e.angleDelta().y() / 120.0
        if steps:
            self.zoom_by(1.25**steps, e.position())

    def keyPressEvent(self, e) -> None:  # noqa: N802
        if e.key() == Qt.Key.Key_Space and not e.isAutoRepeat():
            self._space = True
            self.setCursor(Qt.CursorShape.OpenHandCursor)
            return
        if e.key() in (Qt.Key.Key_Return, Qt.Key.Key_Enter) and self.painter.polygon:
            self.painter.close_polygon(subtract=bool(e.modifiers() & Qt.KeyboardModifier.AltModifier))
            self.update()
            return
        if e.key() == Qt.Key.Key_Escape and self.painter.polygon:
            self.painter.cancel()
            self.update()
            return
        super().keyPressEvent(e)

    def keyReleaseEvent(self, e) -> None:  # noqa: N802
        if e.key() == Qt.Key.Key_Space and not e.isAutoRepeat():
            self._space = False
            self.setCursor(Qt.CursorShape.CrossCursor)
            return
        super().keyReleaseEvent(e)

    def resizeEvent(self, e) -> None:  # noqa: N802
        if self._fitted:
            self.fit()
        else:
            self._view_moved()
        super().resizeEvent(e)
