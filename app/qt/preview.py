"""Live preview: document changes → render requests → frames, latest request wins.

:class:`PreviewController` watches a :class:`~app.model.document.Document`, keeps a
:class:`~app.model.render.ViewRenderer` for its current photograph and acquisition, and sends a
:class:`~app.model.render.Request` to a :class:`~app.qt.worker.LatestWorker` on every change that
affects the picture (κ, view, exposure, masks for ground truth). Frames come back on the UI
thread through :attr:`PreviewController.frame_ready`; results older than the frame on screen,
or from a replaced renderer, are dropped.

Zoomed in past the preview's resolution, the visible region is also rendered at full
resolution (:func:`app.model.views.render_detail`) on a second worker once the picture
has been still for :attr:`PreviewController.DETAIL_DELAY_MS`, and arrives through
:attr:`PreviewController.detail_ready`: drags stay on the fast screen-sized path, and what the
user inspects at 100 % is the export's pixels.

With the noise-aware recolor (the document's ``trusted`` data, :mod:`engine.trust`) a frame
costs about half a second at 512² instead of 4 ms (bench/trusted.py): every change is first drawn on the
fast plain path (a ``fast`` request), and once the picture has been still for
:attr:`PreviewController.EXACT_DELAY_MS` the exact noise-aware frame — what export writes — is
rendered on a third worker and replaces it.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from PySide6.QtCore import QObject, QTimer, Signal

from app.model import views
from app.model.document import Document
from app.model.render import Detail, MaskSnapshot, PreviewFrame, Request, ViewRenderer, clip_region
from app.model.views import CanvasView, Need
from app.qt.worker import LatestWorker


class PreviewController(QObject):
    """Drives the canvas from the document.

    Parameters
    ----------
    document : Document
    max_shape : (h, w)
        Preview resolution cap (the screen in device pixels): the "screen-sized copy".
    synchronous : bool
        Render inside :meth:`request` (tests, benchmarks).

    Signals
    -------
    frame_ready(PreviewFrame)
    detail_ready(Detail)
        A full-resolution patch of the visible region for the frame of the same request.
    failed(str)
    """

    frame_ready = Signal(object)
    detail_ready = Signal(object)
    failed = Signal(str)

    #: Stillness before the full-resolution detail is rendered (ms).
    DETAIL_DELAY_MS = 120
    #: Stillness before the noise-aware frame replaces the fast plain one (ms).
    EXACT_DELAY_MS = 150
    #: Largest detail region (camera pixels); bigger regions keep the preview alone.
    MAX_DETAIL_PIXELS = 4_000_000
    #: Preview pixels magnified at least this much on screen get a detail.
    DETAIL_MAGNIFICATION = 1.25

    def __init__(self, document: Document, *, max_shape=(1080, 1920), synchronous: bool = False,
                 parent: QObject | None = None):
        super().__init__(parent)
        self.doc = document
        self.max_shape = tuple(int(v) for v in max_shape)
        self.view = CanvasView.RECOLORED
        self.exposure = 0.0
        self.grid = (1, 1)
        self.worker = LatestWorker(self._render, synchronous=synchronous, parent=self)
        self.worker.done.connect(self._on_done)
        self.worker.failed.connect(self._on_failed)
        self.detail_worker = LatestWorker(self._render_detail, synchronous=synchronous, parent=self)
        self.detail_worker.done.connect(self._on_detail)
        self.detail_worker.failed.connect(self._on_failed)
        self.exact_worker = LatestWorker(self._render, synchronous=synchronous, parent=self)
        self.exact_worker.done.connect(self._on_exact)
        self.exact_worker.failed.connect(self._on_failed)
        self._exact_timer = QTimer(self)
        self._exact_timer.setSingleShot(True)
        self._exact_timer.setInterval(self.EXACT_DELAY_MS)
        self._exact_timer.timeout.connect(self._submit_exact)
        self.viewport: tuple[tuple[int, int, int, int], float] | None = None
        self.detail: Detail | None = None  # the newest detail of the current request
        self._detail_timer = QTimer(self)
        self._detail_timer.setSingleShot(True)
        self._detail_timer.setInterval(self.DETAIL_DELAY_MS)
        self._detail_timer.timeout.connect(self._submit_detail)
        self.generation = 0
        self.renderer: ViewRenderer | None = None
        self.frame: PreviewFrame | None = None
        self.last_request: Request | None = None
        self.last_id = 0
        self._shown_id = 0
        self._mask_versions: dict[int, int] = {}
        self._mask_snapshots: dict[tuple[int, int], MaskSnapshot] = {}
        ev = document.events
        ev.kappa.connect(self._on_kappa)
        ev.mask.connect(self._on_mask)
        ev.targets.connect(self._on_targets)
        ev.acquisition.connect(self.rebuild)
        self.rebuild()

    # ------------------------------------------------------------------ settings
    def set_view(self, view: CanvasView | str) -> None:
        self.view = CanvasView(view)
        self.request()

    def set_exposure(self, stops: float) -> None:
        self.exposure = float(stops)
        self.request()

    def set_grid(self, grid: tuple[int, int]) -> None:
        if tuple(grid) != self.grid:
            self.grid = tuple(grid)
            if self.view == CanvasView.COMPONENTS:
                self.request()

    def set_viewport(self, region: tuple[int, int, int, int], zoom: float) -> None:
        """The camera pixels ``(y0, y1, x0, x1)`` on screen and the zoom (screen px per camera px)."""
        viewport = (tuple(int(v) for v in region), float(zoom))
        if viewport != self.viewport:
            self.viewport = viewport
            self._schedule_detail()

    def wants_detail(self) -> bool:
        """Whether the current view, zoom and region call for a full-resolution detail."""
        r = self.renderer
        if r is None or self.viewport is None or not views.shown(r, self.view).detail:
            return False
        region, zoom = self.viewport
        y0, y1, x0, x1 = clip_region(region, r.shape)
        area = max(y1 - y0, 0) * max(x1 - x0, 0)
        return r.factor > 1 and r.factor * zoom >= self.DETAIL_MAGNIFICATION and 0 < area <= self.MAX_DETAIL_PIXELS

    def available(self, view: CanvasView) -> bool:
        """Whether ``view`` can be shown for this document (it has everything the view needs)."""
        return not self.missing(view)

    def missing(self, view: CanvasView) -> list[Need]:
        """What ``view`` needs that this document does not have."""
        have = {Need.DECOMPOSITION: self.doc.decomposition is not None, Need.TRUTH: self.doc.truth is not None}
        return [n for n in sorted(views.VIEW_SPECS[CanvasView(view)].needs) if not have[n]]

    # ------------------------------------------------------------------ requests
    def rebuild(self) -> None:
        """New renderer for the document's photograph and acquisition (drops older frames)."""
        self.generation += 1
        truth = self._truth if self.doc.truth is not None else None
        emitters = getattr(self.doc.truth, "emitters", None)
        self.renderer = ViewRenderer(self.doc.photograph, self.doc.decomposition, truth=truth,
                                     emitters=emitters() if callable(emitters) else None, max_shape=self.max_shape,
                                     trusted=self.doc.trusted)
        self.request()

    def request(self) -> int:
        """Ask for a frame of the current state; returns the request id."""
        req = Request(self.view, tuple(float(k) for k in self.doc.recolor_kappa()), self.exposure,
                      self._edit() if self._shows_edit() else (), self.grid)
        if self.renderer is not None and self.renderer.trusted is not None and not self.worker.synchronous:
            req = replace(req, fast=True)  # the plain path now, the exact frame when the picture is still
            self._exact_timer.start()
        self.last_request = req
        self.last_id = self.worker.submit((self.generation, self.renderer, req))
        if req.fast:
            return self.last_id
        self._schedule_detail()
        return self.last_id

    def readout(self, x: int, y: int):
        """(label, RGB) of the linear value at camera pixel (x, y) in the current view, or None."""
        r = self.renderer
        if r is None:
            return None
        edit = self.last_request.edit if self.last_request else ()
        if Need.TRUTH in views.shown(r, self.view).needs and not r.has_truth(edit):
            return None  # ground truth still being computed: never block the UI thread for it
        return views.readout(r, self.view, x, y, self.doc.recolor_kappa(), edit)

    def close(self) -> None:
        self._detail_timer.stop()
        self._exact_timer.stop()
        self.worker.close()
        self.detail_worker.close()
        self.exact_worker.close()

    # ------------------------------------------------------------------ internals
    @staticmethod
    def _render(payload) -> PreviewFrame:
        generation, renderer, request = payload
        frame = views.render(renderer, request)
        frame.generation, frame.request = generation, request
        return frame

    @staticmethod
    def _render_detail(payload) -> Detail | None:
        generation, renderer, request, region = payload
        detail = views.render_detail(renderer, request, region)
        if detail is not None:
            detail.generation = generation
        return detail

    def _submit_exact(self) -> None:
        if self.last_request is None or not self.last_request.fast:
            return
        self.last_request = replace(self.last_request, fast=False)
        self.exact_worker.submit((self.generation, self.renderer, self.last_request))
        self._schedule_detail()

    def _on_exact(self, rid: int, frame: PreviewFrame) -> None:
        if frame.generation != self.generation or frame.request != self.last_request:
            return  # the picture changed since: a newer fast frame is on screen, its exact one comes later
        frame.request_id = self._shown_id
        self.frame = frame
        self.frame_ready.emit(frame)
        if self.detail is not None:
            self.detail_ready.emit(self.detail)

    def _schedule_detail(self) -> None:
        if not self.wants_detail():
            self._detail_timer.stop()
        elif self.worker.synchronous:
            self._submit_detail()
        else:
            self._detail_timer.start()  # restarts: only a still picture gets a detail

    def _submit_detail(self) -> None:
        if self.wants_detail() and self.last_request is not None:
            self.detail_worker.submit((self.generation, self.renderer, self.last_request, self.viewport[0]))

    def _on_detail(self, rid: int, detail: Detail | None) -> None:
        if detail is not None and detail.generation == self.generation and detail.request == self.last_request:
            self.detail = detail
            self.detail_ready.emit(detail)

    def _on_done(self, rid: int, frame: PreviewFrame) -> None:
        if frame.generation != self.generation or rid <= self._shown_id:
            return  # stale: a newer frame is on screen, or the renderer was replaced
        shown = self.frame
        if (frame.request is not None and frame.request.fast and shown is not None and shown.request is not None
                and shown.generation == frame.generation and shown.request == replace(frame.request, fast=False)):
            return  # the exact frame of this very picture is on screen already
        self._shown_id = rid
        frame.request_id = rid
        self.frame = frame
        self.frame_ready.emit(frame)
        if self.detail is not None:  # it may have been faster than its frame; the canvas keeps only a match
            self.detail_ready.emit(self.detail)

    def _on_failed(self, rid: int, exc: Exception) -> None:
        self.failed.emit(f"preview failed: {exc}")

    def _shows_edit(self) -> bool:
        """Whether the view on screen draws every target's mask and κ (ground truth, naive recolor)."""
        spec = views.shown(self.renderer, self.view)
        return spec.edit and (Need.TRUTH in spec.needs or self.doc.decomposition is None)

    def _on_kappa(self, uid: int, kappa) -> None:
        acq = self.doc.acquisition
        if (acq is not None and uid == acq.cascade[-1]) or self._shows_edit():
            self.request()

    def _on_mask(self, uid: int, bbox) -> None:
        self._mask_versions[uid] = self._mask_versions.get(uid, 0) + 1
        if self._shows_edit():
            self.request()

    def _on_targets(self) -> None:
        if self._shows_edit():
            self.request()

    def _edit(self) -> tuple:
        """Hashable key of the whole edit; each mask is copied once per version."""
        key = []
        live = {}
        for t in self.doc.targets:
            if not t.mask.any():
                continue
            version = (t.uid, self._mask_versions.get(t.uid, 0))
            snap = self._mask_snapshots.get(version) or MaskSnapshot(version, t.mask.copy())
            live[version] = snap
            key.append((snap, tuple(float(k) for k in t.kappa)))
        self._mask_snapshots = live
        return tuple(key)

    def _truth(self, edit) -> np.ndarray:
        return self.doc.truth.recolor([(snap.mask, np.array(kappa)) for snap, kappa in edit])
