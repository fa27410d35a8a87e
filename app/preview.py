"""Live preview: document changes → render requests → frames, latest request wins.

:class:`PreviewController` watches a :class:`~app.model.Document`, keeps a
:class:`~app.render.Renderer` for its current photograph and acquisition, and sends a
:class:`~app.render.Request` to a :class:`~app.worker.LatestWorker` on every change that
affects the picture (κ, view, exposure, masks for ground truth). Frames come back on the UI
thread through :attr:`PreviewController.frame_ready`; results older than the frame on screen,
or from a replaced renderer, are dropped.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QObject, Signal

from app.model import Document
from app.render import NEEDS_DECOMPOSITION, NEEDS_TRUTH, Frame, Renderer, Request, View
from app.worker import LatestWorker


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
    frame_ready(Frame)
    failed(str)
    """

    frame_ready = Signal(object)
    failed = Signal(str)

    def __init__(self, document: Document, *, max_shape=(1080, 1920), synchronous: bool = False,
                 parent: QObject | None = None):
        super().__init__(parent)
        self.doc = document
        self.max_shape = tuple(int(v) for v in max_shape)
        self.view = View.RECOLORED
        self.exposure = 0.0
        self.grid = (1, 1)
        self.worker = LatestWorker(self._render, synchronous=synchronous, parent=self)
        self.worker.done.connect(self._on_done)
        self.worker.failed.connect(self._on_failed)
        self.generation = 0
        self.renderer: Renderer | None = None
        self.frame: Frame | None = None
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
    def set_view(self, view: View | str) -> None:
        self.view = View(view)
        self.request()

    def set_exposure(self, stops: float) -> None:
        self.exposure = float(stops)
        self.request()

    def set_grid(self, grid: tuple[int, int]) -> None:
        if tuple(grid) != self.grid:
            self.grid = tuple(grid)
            if self.view == View.COMPONENTS:
                self.request()

    def available(self, view: View) -> bool:
        """Whether ``view`` can be shown for this document."""
        if view in NEEDS_DECOMPOSITION and self.doc.decomposition is None:
            return False
        if view in NEEDS_TRUTH and self.doc.truth is None:
            return False
        return True

    # ------------------------------------------------------------------ requests
    def rebuild(self) -> None:
        """New renderer for the document's photograph and acquisition (drops older frames)."""
        self.generation += 1
        truth = self._truth if self.doc.truth is not None else None
        self.renderer = Renderer(self.doc.photograph, self.doc.decomposition, truth=truth, max_shape=self.max_shape)
        self.request()

    def request(self) -> int:
        """Ask for a frame of the current state; returns the request id."""
        req = Request(self.view, tuple(float(k) for k in self.doc.recolor_kappa()), self.exposure,
                      self._edit() if self.view in NEEDS_TRUTH else (), self.grid)
        self.last_request = req
        self.last_id = self.worker.submit((self.generation, self.renderer, req))
        return self.last_id

    def readout(self, x: int, y: int):
        """(label, RGB) of the linear value at camera pixel (x, y) in the current view, or None."""
        r = self.renderer
        if r is None or self.view == View.COMPONENTS:
            return None
        edit = self.last_request.edit if self.last_request else ()
        if self.view in NEEDS_TRUTH and not r.has_truth(edit):
            return None  # ground truth still being computed: never block the UI thread for it
        return r.readout(self.view, x, y, self.doc.recolor_kappa(), edit)

    def close(self) -> None:
        self.worker.close()

    # ------------------------------------------------------------------ internals
    @staticmethod
    def _render(payload) -> Frame:
        generation, renderer, request = payload
        frame = renderer.render(request)
        frame.generation = generation
        return frame

    def _on_done(self, rid: int, frame: Frame) -> None:
        if frame.generation != self.generation or rid <= self._shown_id:
            return  # stale: a newer frame is on screen, or the renderer was replaced
        self._shown_id = rid
        frame.request_id = rid
        self.frame = frame
        self.frame_ready.emit(frame)

    def _on_failed(self, rid: int, exc: Exception) -> None:
        self.failed.emit(f"preview failed: {exc}")

    def _on_kappa(self, uid: int, kappa) -> None:
        acq = self.doc.acquisition
        if (acq is not None and uid == acq.cascade[-1]) or self.view in NEEDS_TRUTH:
            self.request()

    def _on_mask(self, uid: int, bbox) -> None:
        self._mask_versions[uid] = self._mask_versions.get(uid, 0) + 1
        if self.view in NEEDS_TRUTH:
            self.request()

    def _on_targets(self) -> None:
        if self.view in NEEDS_TRUTH:
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
