"""The main window: menus, toolbars, canvas, side panels, status bar, files and jobs.

It owns one document at a time (with its undo stack, painter, preview controller and
canvas) and runs every long piece of work — opening, saving, exporting, noise reduction — as a
:class:`~app.qt.worker.Job` with progress, pause and cancel in the status bar. Actions, menus
and toolbars are the tables of :mod:`app.qt.actions`; the rig (calibration wizard, acquisition
dock) is :class:`~app.qt.rig_control.RigControl`. Errors are shown as dialogs with the engine's
message; nothing the user did is dropped when something fails.

Over 500 lines on purpose: it wires the document's events to every dock, view and job; the
menus' slots live in file_control and rig_control, the tables in actions.
"""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import QSettings, QSignalBlocker, Qt, QTimer
from PySide6.QtGui import QGuiApplication, QUndoGroup, QUndoStack
from PySide6.QtWidgets import (
    QApplication,
    QDockWidget,
    QLabel,
    QMainWindow,
    QMessageBox,
    QVBoxLayout,
    QWidget,
)

import app
from app.model.document import Document
from app.model.history import History
from app.model.painting import Painter, Tool
from app.model.render import component_grid
from app.model.views import NEED_HINTS, CanvasView
from app.qt import actions
from app.qt.actions import KeepAppShortcuts
from app.qt.canvas import Canvas
from app.qt.checker_corners import CornerPlacement
from app.qt.colour_panel import ColourPanel, ReferenceView
from app.qt.file_control import FileControl
from app.qt.layout import fit_to_screen, scrolling
from app.qt.panels import AlbedoPanel, NoiseReductionPanel, TargetPanel
from app.qt.preview import PreviewController
from app.qt.rig_control import RigControl
from app.qt.undo import QtHistory
from app.qt.worker import Job, JobProgress, UiCaller, run_on_rig
from engine.errors import InputError, SessionError

APP_NAME = app.APP_NAME
#: The size the window asks for on a large screen; smaller screens get their available area.
PREFERRED_SIZE = (1500, 920)
#: The settings key remembering the user's choice of recolor (View ▸ Noise-Aware Recolor) for new acquisitions.
NOISE_AWARE_SETTING = "recolor/noise_aware"
LINK_SETTING = "albedo/link_channels"


class MainWindow(QMainWindow):
    """Albedit's main window.

    Parameters
    ----------
    document : Document, optional
        Show this document (else an empty window until :meth:`open_path` / :meth:`open_demo`).
    session : engine.session.Session, optional
        Where ``document`` is saved.
    synchronous : bool
        Preview and jobs run on the calling thread (tests).
    settings : QSettings, optional
        Recent files, the last rig, the wizard's choices; tests pass a temporary one.
    rig : devices.base.Rig, optional
        An open rig (the window closes it when it closes).
    """

    #: What the empty window says.
    PLACEHOLDER = "Open a session or an image (File menu), or start the virtual-rig demo."

    def __init__(self, document: Document | None = None, session=None, *, synchronous: bool = False,
                 settings: QSettings | None = None, rig=None):
        super().__init__()
        self.setObjectName("main_window")
        self.synchronous = synchronous
        self.settings = settings if settings is not None else QSettings(APP_NAME, APP_NAME)
        self.doc: Document | None = None
        self.session = session
        self.demo = False  # the document is the demo's: Save goes to Save As, the cached session stays
        self.job: Job | None = None
        self.undo_group = QUndoGroup(self)
        self.preview: PreviewController | None = None
        self.canvas: Canvas | None = None
        self.painter: Painter | None = None
        self.target_panel: TargetPanel | None = None
        self.albedo_panel: AlbedoPanel | None = None
        self.colour_panel: ColourPanel | None = None
        self.corners: CornerPlacement | None = None  # placing a colour checker by hand (made with the canvas)
        self._ui = UiCaller(self)
        self.noise_panel: NoiseReductionPanel | None = None
        self._placeholder = QLabel(self.PLACEHOLDER, objectName="placeholder")
        self._placeholder.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self._placeholder.setWordWrap(True)
        self.setCentralWidget(self._placeholder)
        fit_to_screen(self, PREFERRED_SIZE)
        self.rigs = RigControl(self, rig)
        self.files = FileControl(self)
        actions.install(self)
        self._build_docks()
        self._build_status()
        self._shortcuts = KeepAppShortcuts(self)
        QApplication.instance().installEventFilter(self._shortcuts)
        if document is not None:
            self.set_document(document, session)
        self._update_title()
        self._update_actions()

    @property
    def rig(self):
        """The open rig, or None."""
        return self.rigs.rig

    # ================================================================== construction
    def _build_docks(self) -> None:
        self.targets_dock = QDockWidget("Targets (cascade order)", self, objectName="targets")
        self.albedo_dock = QDockWidget("Albedo", self, objectName="albedo")
        for d in (self.targets_dock, self.albedo_dock):
            d.setFeatures(QDockWidget.DockWidgetFeature.DockWidgetMovable
                          | QDockWidget.DockWidgetFeature.DockWidgetFloatable)
            self.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, d)
        self.reference_dock = QDockWidget("Reference picture", self, objectName="reference")
        self.reference_view = ReferenceView()
        self.reference_view.picked.connect(
            lambda x, y: self.colour_panel and self.colour_panel.pick_reference(self.reference_view.pixels, x, y))
        self.reference_dock.setWidget(self.reference_view)
        self.addDockWidget(Qt.DockWidgetArea.LeftDockWidgetArea, self.reference_dock)
        self.reference_dock.hide()  # until a reference picture is opened

    def _build_status(self) -> None:
        sb = self.statusBar()
        sb.setObjectName("status")
        self.readout = QLabel(objectName="readout")
        self._cursor: tuple[int, int] | None = None  # the image pixel under the mouse, for the readout
        self.readout.setMinimumWidth(380)
        self.readout.setStyleSheet("font-family: monospace;")
        self.note = QLabel(objectName="view_note")
        self.recolor_mode = QLabel(objectName="recolor_mode")
        self.recolor_mode.setContentsMargins(12, 0, 0, 0)  # a long temporary message is clipped short of it
        self.zoom_label = QLabel(objectName="zoom")
        self.zoom_label.setMinimumWidth(self.zoom_label.fontMetrics().horizontalAdvance("  1600 %"))
        self.zoom_label.setAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
        self.progress = JobProgress("job_progress", hide_when_idle=True)
        self.progress.label.setMinimumWidth(240)
        self.progress.setMaximumWidth(640)
        self.readout.hide()  # until the mouse is over the image: a temporary message has its room
        sb.messageChanged.connect(lambda m: m and sb.setToolTip(f"Last message: {m}"))  # when it is clipped or gone
        sb.addWidget(self.note, 1)  # temporary messages cover this one only
        sb.addPermanentWidget(self.recolor_mode)
        sb.addPermanentWidget(self.readout)
        sb.addPermanentWidget(self.progress)
        sb.addPermanentWidget(self.zoom_label)

    # ================================================================== document
    def set_document(self, document: Document, session=None, *, rig=None, demo: bool = False) -> None:
        """Show ``document`` (replacing the current one; the open rig stays open).

        ``rig``: use this open rig from now on (closing another one). ``demo``: the document is
        the virtual-rig demo's, whose session lives in the user's cache and is reused by the
        next demo: Save makes a copy (Save As).
        """
        if rig is not None:
            self.rigs.adopt(rig)
        self._teardown()
        self.doc, self.session, self.demo = document, session, demo
        stack = QUndoStack(self)
        document.use_history(QtHistory(stack))
        self.undo_group.addStack(stack)
        self.undo_group.setActiveStack(stack)
        self.painter = Painter(document)
        self.painter.set_size(self.size_spin.value() if self.size_spin.value() > 1 else 20)
        self.painter.set_hardness(self.hardness_spin.value() / 100)
        self.painter.tolerance = self.tol_spin.value()
        self.painter.set_tool(self._checked_tool())
        with QSignalBlocker(self.size_spin):
            self.size_spin.setValue(int(self.painter.size))
        self.canvas = Canvas(document, self.painter)
        self.canvas.setObjectName("canvas")
        self.setCentralWidget(self.canvas)
        self.canvas.show()  # now, not on the next event-loop turn (the focus cannot go to a hidden widget)
        self.canvas.setFocus()  # single-key shortcuts (tools, views) work at once
        self.preview = PreviewController(document, max_shape=self._screen_shape(), synchronous=self.synchronous,
                                         parent=self)
        self.preview.exposure = self.exposure_spin.value()
        self.preview.view = self._checked_view()
        self.preview.frame_ready.connect(self._on_frame)
        self.preview.detail_ready.connect(self.canvas.set_detail)
        self.canvas.viewport_changed.connect(self.preview.set_viewport)
        self.preview.failed.connect(lambda msg: self.statusBar().showMessage(msg, 8000))
        self._cursor = None  # a new canvas: nothing under the mouse yet
        self.canvas.cursor_moved.connect(self._on_cursor)
        self.canvas.zoom_changed.connect(lambda z: self.zoom_label.setText(f"{100 * z:.0f} %"))
        self.zoom_label.setText(f"{100 * self.canvas.zoom:.0f} %")  # the fit already happened
        self.target_panel = TargetPanel(document)
        self.target_panel.message.connect(lambda m: self.statusBar().showMessage(m, 8000))
        self.colour_panel = ColourPanel(document, lambda: self.session, self.exposure_spin.value)
        self.corners = CornerPlacement(self.canvas, lambda m: self.statusBar().showMessage(m, 20000))
        self.corners.placed.connect(self.measure_checker)
        self.colour_panel.picking.connect(self._on_eyedropper)
        self.canvas.picked.connect(self._on_picked)
        self.colour_panel.message.connect(lambda m: self.statusBar().showMessage(m, 8000))
        self.colour_panel.checker_requested.connect(self.measure_checker)
        self.colour_panel.reference_requested.connect(self.open_reference)
        self.exposure_spin.valueChanged.connect(self.colour_panel.refresh)
        self.albedo_panel = AlbedoPanel(document, colour=self.colour_panel)
        self.albedo_panel.message.connect(lambda m: self.statusBar().showMessage(m, 8000))
        # "Link channels" is how the user likes to drag κ, not part of the edit: remembered across documents
        self.albedo_panel.link.setChecked(self._flag(LINK_SETTING))
        self.albedo_panel.link.toggled.connect(lambda on: self.settings.setValue(LINK_SETTING, bool(on)))
        self.noise_panel = NoiseReductionPanel(document)
        self.noise_panel.apply_requested.connect(self.apply_noise_reduction)
        self.targets_dock.setWidget(scrolling(self.target_panel, "targets_scroll"))
        self.albedo_dock.setWidget(scrolling(self._stacked(self.albedo_panel, self.colour_panel, self.noise_panel),
                                             "albedo_scroll"))
        ev = document.events
        ev.dirty.connect(lambda _d: self._update_title())
        ev.warning.connect(lambda m: self.statusBar().showMessage(m, 8000))
        ev.acquisition.connect(self._update_actions)
        ev.acquisition.connect(self._on_acquisition)
        ev.current.connect(lambda _u: self._update_actions())
        ev.targets.connect(self._update_actions)
        self.rigs.follow_document()
        self._update_grid()
        self.preview.request()
        self._update_title()
        self._update_actions()
        self._on_acquisition()

    def _teardown(self) -> None:
        if self.doc is not None:  # the document outlives its window: back to a Qt-free history
            self.doc.use_history(History())
        if self.preview is not None:
            self.preview.close()
            self.preview.deleteLater()
        if self.colour_panel is not None:
            self.exposure_spin.valueChanged.disconnect(self.colour_panel.refresh)
        for stack in self.undo_group.stacks():
            self.undo_group.removeStack(stack)
            stack.deleteLater()
        self.preview = self.canvas = self.painter = self.colour_panel = self.corners = None

    @staticmethod
    def _stacked(*widgets: QWidget) -> QWidget:
        box = QWidget()
        lay = QVBoxLayout(box)
        for w in widgets:
            lay.addWidget(w)
            lay.addSpacing(8)
        lay.addStretch(1)
        return box

    def _screen_shape(self) -> tuple[int, int]:
        screen = self.screen() or QGuiApplication.primaryScreen()
        if screen is None:
            return (1080, 1920)
        size, dpr = screen.size(), screen.devicePixelRatio()
        return (max(int(size.height() * dpr), 256), max(int(size.width() * dpr), 256))

    # ================================================================== state → UI
    def _update_title(self) -> None:
        name = "(no document)"
        if self.demo and self.doc is not None:
            name = f"{self.doc.source} demo (not saved)"
        elif self.session is not None:
            name = Path(self.session.path).name
        elif self.doc is not None:
            source = self.doc.source
            name = Path(source).name if source and ":" not in source else source or "untitled"
        self.setWindowTitle(f"{name}[*] — {APP_NAME}")
        self.setWindowModified(self.doc is not None and self.doc.is_dirty())

    def condition(self, name: str) -> bool:
        """Whether the condition ``name`` of :data:`app.qt.actions.CONDITIONS` holds now."""
        doc, idle = self.doc, self.job is None
        if name == "always":
            return True
        if name == "idle":
            return idle
        if doc is None or not idle:
            return name == "last_rig" and self.rigs.rig is None and self.rigs.last is not None
        return {
            "document": True,
            "editable_target": doc.current != -1 and not doc.mask_lock(doc.current),
            "decomposition": doc.decomposition is not None,
            "acquirable": self.rigs.rig is not None or self.rigs.last is not None,
            "rig": self.rigs.rig is not None,
            "last_rig": self.rigs.rig is None and self.rigs.last is not None,
        }[name]

    def why_not(self, name: str) -> str:
        """What the user can do for the condition ``name`` of :data:`app.qt.actions.CONDITIONS` to hold."""
        if name in ("always", "last_rig"):  # these hold with or without a document or a job
            return actions.CONDITIONS[name]
        if self.job is not None:
            return f"wait for {self.job.name} to end"
        if self.doc is None and name != "idle":
            return actions.CONDITIONS["document"]
        return actions.CONDITIONS[name]

    def _update_actions(self, *_args) -> None:
        for name, when in self.when.items():
            if name not in ("undo", "redo"):  # the undo group enables those
                _offer(getattr(self, f"act_{name}"), "" if self.condition(when) else self.why_not(when))
        last = self.rigs.last
        self.act_reopen_rig.setText(f"&Reopen {last[0]}" if last else "&Reopen Last Rig")
        for a in self.tool_actions.values():
            a.setEnabled(self.condition("document"))
        for view, a in self.view_actions.items():
            if self.doc is None or self.preview is None:
                _offer(a, actions.CONDITIONS["document"])
            else:
                _offer(a, "; ".join(NEED_HINTS[n] for n in self.preview.missing(view)))
        if self.colour_panel is not None:
            self.colour_panel.can_measure = self.condition("rig") and self.session is not None
            self.colour_panel.refresh()
        acq = None if self.doc is None else self.doc.acquisition
        self.act_noise_aware.setChecked(acq is None or acq.noise_aware)
        self.recolor_mode.setText("" if self.doc is None else self.doc.recolor_note())
        if self.doc is not None and self.preview is not None and not self.preview.available(self.preview.view):
            self.set_view(CanvasView.RECOLORED)

    def _on_frame(self, frame) -> None:
        if self.canvas is None:
            return
        self.canvas.set_frame(frame)
        self.note.setText(frame.note)
        self._on_cursor(self._cursor)  # the readout reads what is shown now (a κ drag, an acquisition)

    def _on_cursor(self, pos) -> None:
        self._cursor = pos
        if pos is None or self.preview is None:
            self.readout.setText("")
            self.readout.hide()
            return
        x, y = pos
        value = self.preview.readout(x, y)
        text = f"x {x:5d}  y {y:5d}"
        if value is not None:
            label, rgb = value
            text += f"   {label}: R {rgb[0]:.4g}  G {rgb[1]:.4g}  B {rgb[2]:.4g}"
        names = [t.name for t in self.doc.targets if t.mask[y, x]]
        if names:
            text += f"   [{', '.join(names)}]"
        self.readout.setText(text)
        self.readout.show()

    # ================================================================== user actions
    def set_tool(self, tool: Tool | str) -> None:
        tool = Tool(tool)
        with QSignalBlocker(self.tool_group):
            self.tool_actions[tool].setChecked(True)
        if self.corners is not None:  # another tool ends placing a colour checker's corners
            self.corners.cancel()
        if self.painter is not None:
            self.painter.set_tool(tool)
            self.canvas.update()

    def set_view(self, view: CanvasView | str) -> None:
        view = CanvasView(view)
        self.view_actions[view].setChecked(True)
        if self.preview is not None:
            self._update_grid()
            self.preview.set_view(view)

    def _update_grid(self) -> None:
        """Rows × columns of the components view that show the tiles largest in the canvas."""
        if self.preview is None or self.doc.decomposition is None:
            return
        size = self.canvas.size() if self.canvas is not None else self.size()
        self.preview.set_grid(component_grid(self.doc.decomposition.order, self.doc.shape,
                                             (size.height(), size.width())))

    def _checked_tool(self) -> Tool:
        return next((t for t, a in self.tool_actions.items() if a.isChecked()), Tool.BRUSH)

    def _checked_view(self) -> CanvasView:
        return next((v for v, a in self.view_actions.items() if a.isChecked()), CanvasView.RECOLORED)

    def _brush(self, how: str) -> None:
        if self.painter is None:
            return
        getattr(self.painter, how)()
        with QSignalBlocker(self.size_spin):
            self.size_spin.setValue(int(round(self.painter.size)))
        self.canvas.update()

    def on_brush_larger(self) -> None:
        self._brush("grow")

    def on_brush_smaller(self) -> None:
        self._brush("shrink")

    def on_fit(self) -> None:
        if self.canvas is not None:
            self.canvas.fit()

    def on_zoom_100(self) -> None:
        if self.canvas is not None:
            self.canvas.zoom_to(1.0)

    def on_zoom_in(self) -> None:
        if self.canvas is not None:
            self.canvas.zoom_by(1.25)

    def on_zoom_out(self) -> None:
        if self.canvas is not None:
            self.canvas.zoom_by(0.8)

    def on_add_target(self) -> None:
        if self.doc is not None:
            self._guard(self.doc.add_target)

    def _on_current_target(self, method: str) -> None:
        if self.doc is not None and self.doc.current != -1:
            self._guard(getattr(self.doc, method), self.doc.current)

    def on_delete_target(self) -> None:
        self._on_current_target("remove_target")

    def on_clear_mask(self) -> None:
        self._on_current_target("clear_mask")

    def on_invert_mask(self) -> None:
        self._on_current_target("invert_mask")

    def on_refine_edge(self) -> None:
        if self.doc is None or self.doc.current == -1:
            return
        uid = self.doc.current
        before = self.doc.history.count()
        # synchronous (a fraction of a second for a target's outline; seconds for 10⁵ boundary pixels): say so
        QApplication.setOverrideCursor(Qt.CursorShape.WaitCursor)
        try:
            self._guard(self.doc.refine_edge, uid)
        finally:
            QApplication.restoreOverrideCursor()
        if self.doc.history.count() != before:
            t = self.doc.target(uid)
            self.statusBar().showMessage(f"{t.name!r}: {t.edge_pixels()} edge pixels are partly target", 5000)

    def on_overlays(self, on: bool) -> None:
        if self.canvas is not None:
            self.canvas.show_overlays = on
            self.canvas.update()

    def on_discard(self) -> None:
        if self.doc is None or self.doc.acquisition is None:
            return
        answer = QMessageBox.question(
            self, "Discard acquisition",
            "Forget the measured decomposition? Every κ and mask becomes editable again; "
            "recoloring needs a new acquisition (Edit ▸ Undo brings it back).")
        if answer == QMessageBox.StandardButton.Yes:
            self.doc.discard_acquisition()
            self.preview.rebuild()

    def _guard(self, fn, *args):
        try:
            return fn(*args)
        except InputError as exc:
            self.statusBar().showMessage(str(exc), 8000)
            return None

    def show_error(self, title: str, exc: BaseException) -> None:
        """An error dialog with the engine's message."""
        QMessageBox.critical(self, title, str(exc) or type(exc).__name__)

    def on_about(self) -> None:
        QMessageBox.about(self, f"About {APP_NAME}",
                          f"<b>Albedit {app.__version__}</b> — measurement-based editing of diffuse albedo with "
                          "consistent interreflections.<br>Paint targets, acquire them on a camera–projector rig, "
                          "then change their albedo with every interreflection following.")

    # ================================================================== jobs
    def run_job(self, fn, *args, name: str, on_done=None, on_failed=None, pausable: bool = True,
                cancellable: bool = True, **kwargs) -> Job:
        """Run ``fn(*args, progress=, should_stop=, **kwargs)`` as the window's job.

        ``pausable`` / ``cancellable``: whether ``fn`` polls ``should_stop`` often enough for
        Pause / Cancel to mean something (they are hidden otherwise).
        """
        if self.job is not None:
            raise InputError(f"{self.job.name} is still running")
        job = Job(fn, *args, name=name, synchronous=self.synchronous, parent=self, **kwargs)
        self.job = job

        def failed(exc):
            (on_failed or (lambda e: self.show_error(f"{name} failed", e)))(exc)

        def ended():
            self.job = None
            self._set_busy(False)
            self._update_actions()
            if self.centralWidget() is self._placeholder:
                self._placeholder.setText(self.PLACEHOLDER)
            QTimer.singleShot(0, self._prepare_trusted)  # an acquisition may have waited for this job

        if on_done is not None:
            job.finished.connect(on_done)
        job.failed.connect(failed)
        job.cancelled.connect(lambda exc: self.statusBar().showMessage(str(exc), 8000))
        job.ended.connect(ended)
        self.progress.attach(job, pausable=pausable, cancellable=cancellable)
        if self.centralWidget() is self._placeholder:  # nothing open yet: say what is coming, as it goes
            self._placeholder.setText(f"{name}…\n\nIts progress is in the status bar.")
            job.progress.connect(lambda step, total, message: self._placeholder.setText(
                f"{name}…\n\n{message}" + (f" ({100 * step // total} %)" if total > 0 else ""))
                if self.centralWidget() is self._placeholder else None)
        self._set_busy(True)
        self._update_actions()
        job.start()
        return job

    def _set_busy(self, busy: bool) -> None:
        """While a job runs the document is read by it: no edits, no undo."""
        for w in (self.canvas, self.target_panel, self.albedo_panel, self.colour_panel, self.noise_panel):
            if w is not None:
                w.setEnabled(not busy)
        stacks = self.undo_group.stacks()
        self.undo_group.setActiveStack(None if busy or not stacks else stacks[-1])

    # ================================================================== noise-aware recolor
    def noise_aware_default(self) -> bool:
        """The recolor a new acquisition gets: the user's last choice (View ▸ Noise-Aware Recolor), else noise-aware."""
        return self._flag(NOISE_AWARE_SETTING)

    def _flag(self, key: str) -> bool:
        """A yes/no preference, yes unless the user said no (QSettings stores it as text in an INI file)."""
        return str(self.settings.value(key, "true")).lower() not in ("false", "0")

    def on_noise_aware(self, on: bool) -> None:
        """View ▸ Noise-Aware Recolor: noise-aware or plain recolor for preview and export (one undo step)."""
        doc = self.doc
        if doc is None or doc.acquisition is None:
            return
        self.settings.setValue(NOISE_AWARE_SETTING, bool(on))
        self._guard(doc.set_noise_aware, bool(on))
        QTimer.singleShot(0, self._prepare_trusted)

    def prepare_trusted_first(self, then) -> bool:
        """Prepare the noise-aware data now if it is asked for and missing, and call ``then`` once that job ended.

        Returns True when ``then`` was deferred (a threaded preparation runs), False when the caller can go on
        (nothing to prepare, prepared already, or refused with the reason recorded).
        """
        if self.doc is None or not self.doc.needs_trusted() or self.job is not None:
            return False
        self._prepare_trusted()
        if self.job is None:
            return False
        self.job.ended.connect(lambda: QTimer.singleShot(0, then))
        return True

    def _on_acquisition(self) -> None:
        """The acquisition changed: say which recolor is shown; prepare the noise-aware one if it is asked for."""
        if self.doc is not None:
            self.recolor_mode.setText(self.doc.recolor_note())
        QTimer.singleShot(0, self._prepare_trusted)

    def _prepare_trusted(self) -> None:
        """Prepare the acquisition's noise-aware data as the window's job (once per acquisition; cached in the
        session), or record why it is recolored plainly (no session)."""
        from engine.workflow import NoNoiseModel, load_trusted

        doc, session = self.doc, self.session
        if doc is None or not doc.needs_trusted() or self.job is not None:
            return  # nothing asked for, or a job runs: its end calls this again
        key = doc.acquisition.key
        if session is None:
            doc.set_trusted(key, None, "the noise-aware recolor needs the acquisition's session (its captures and "
                                       "their noise): save the document into one, or acquire again")
            self.statusBar().showMessage(doc.recolor_note(), 8000)
            return

        def done(trusted):
            doc.set_trusted(key, trusted)

        def failed(exc):
            doc.set_trusted(key, None, str(exc) or type(exc).__name__)
            self.statusBar().showMessage(doc.recolor_note(), 12000)
            if not isinstance(exc, (NoNoiseModel, SessionError, InputError)):
                self.show_error("Noise-aware recolor", exc)

        def cancelled(_exc):
            doc.set_trusted(key, None, "its preparation was cancelled (View ▸ Noise-Aware Recolor off and on "
                                       "prepares it again)")

        job = self.run_job(load_trusted, session, key, name="Preparing the noise-aware recolor", on_done=done,
                           on_failed=failed)
        job.cancelled.connect(cancelled)

    # ================================================================== colour
    def _on_eyedropper(self, on: bool) -> None:
        """The Albedo dock's eyedropper, toggled: it ends placing a colour checker's corners."""
        if self.corners is not None:
            self.corners.cancel()
        if self.canvas is not None:
            self.canvas.set_picking(on)

    def _on_picked(self, x: float, y: float) -> None:
        """A canvas pick: a colour checker's corner while placing one, else the eyedropper's colour."""
        if self.corners is not None and self.corners.active:
            self.corners.pick(x, y)
        elif self.colour_panel is not None:
            self.colour_panel.pick_photograph(x, y)

    def measure_checker(self, corners=None) -> None:
        """The Albedo dock's Checker button: find a ColorChecker in the scene and measure it on the open rig
        (a job); the session's targets get absolute albedo. When the detector finds no chart, the user may
        place its four corners by hand on the canvas (:class:`app.qt.checker_corners.CornerPlacement`), which
        measures it at ``corners`` ((4, 2) camera pixels)."""
        from engine.checker import NoChart
        from engine.workflow import run_checker

        rig, session, doc = self.rigs.rig, self.session, self.doc
        if rig is None or session is None or doc is None:
            self.statusBar().showMessage("Measuring a colour checker needs an open rig and a session", 8000)
            return

        def done(record):
            self.statusBar().showMessage(f"{record.report()}: albedo is absolute now", 12000)
            if doc is self.doc and self.colour_panel is not None:
                self.colour_panel.colours_changed()
                self.albedo_panel.refresh()

        def failed(exc):
            if not (isinstance(exc, NoChart) and corners is None and self.corners is not None):
                self.show_error("Colour checker", exc)
            elif QMessageBox.question(self, "Colour checker", f"{exc}.\n\nPlace its four corners by hand on the "
                                      "picture?") == QMessageBox.StandardButton.Yes:
                self.corners.start()
            else:  # the question said it all
                self.statusBar().showMessage(f"Colour checker: {exc}", 12000)

        self.run_job(run_on_rig, run_checker, rig, session, caller=self._ui, corners=corners,
                     name="Measuring the colour checker", on_done=done, on_failed=failed)

    def open_reference(self) -> None:
        """The Albedo dock's Reference button: a picture from elsewhere beside the canvas, to pick colours in."""
        if self.colour_panel is None or (image := self.colour_panel.open_reference()) is None:
            return
        self.reference_view.set_image(image)
        self.reference_dock.show()

    # ================================================================== files
    def apply_noise_reduction(self, radius: int) -> None:
        """Noise-reduce the acquired decomposition with ``radius`` (a job; 0 switches it off; undoable)."""
        doc = self.doc
        acq = None if doc is None else doc.acquisition
        if acq is None:
            return
        if int(radius) == acq.denoise:
            self.statusBar().showMessage("Noise reduction is already off" if not acq.denoise
                                         else f"Radius {acq.denoise} px is already applied", 5000)
            return
        if int(radius) == 0:
            doc.set_noise_reduction(0)
            return
        from engine.denoise import denoise_components
        from engine.workflow import noise_reduced

        def done(d):
            if doc is self.doc and doc.acquisition is not None and doc.acquisition.raw is acq.raw:
                doc.set_noise_reduction(int(radius), d)
                self.statusBar().showMessage(f"Noise reduction applied (radius {int(radius)} px)", 8000)

        if self.session is not None:  # as `albedit recolor --denoise`: a soft mask is filtered before its edge blend
            self.run_job(noise_reduced, self.session, acq.key, acq.raw, int(radius), name="Noise reduction",
                         on_done=done)
        else:
            self.run_job(denoise_components, acq.raw, doc.photograph, radius=int(radius), name="Noise reduction",
                         on_done=done)

    def open_demo(self, rig_name: str | None = None) -> None:
        """Open the virtual-rig demo (File ▸ Virtual Rig Demo)."""
        if self.files.maybe_save():
            self.rigs.open_demo(rig_name)

    def calibrate(self) -> None:
        """Rig ▸ Calibrate Rig (see :meth:`RigControl.calibrate`)."""
        self.rigs.calibrate()

    def acquire(self) -> None:
        """Rig ▸ Acquire (see :meth:`RigControl.acquire`)."""
        self.rigs.acquire()

    def open_path(self, path) -> bool:
        """Open a session folder or an image (see :meth:`FileControl.open_path`)."""
        return self.files.open_path(path)

    def save(self) -> bool:
        return self.files.save()

    def save_as(self, path=None) -> bool:
        return self.files.save_as(path)

    def export(self, path, *, dtype: str | None = None, clip: bool = False) -> None:
        self.files.export(path, dtype=dtype, clip=clip)

    def closeEvent(self, event) -> None:  # noqa: N802 - Qt override
        if self.rigs.acquiring() and QMessageBox.question(
                self, APP_NAME, "An acquisition is running. Quit and stop it?\n\nThe captures taken so far stay in "
                f"{self.session.path}: open it again (File ▸ Open Recent) and Rig ▸ Acquire… resumes it.",
                QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.No,
                QMessageBox.StandardButton.No) != QMessageBox.StandardButton.Yes:
            event.ignore()
            return
        if self.job is not None:  # background work (opening, preparing, noise reduction): recomputed next time
            self.job.wait(10.0, cancel=True)
        if not self.files.maybe_save():
            event.ignore()
            return
        self.rigs.shutdown()  # a running acquisition stops (its captures stay), the rig closes
        self._teardown()
        event.accept()

    def resizeEvent(self, e) -> None:  # noqa: N802
        super().resizeEvent(e)
        actions.wrap_toolbars(self)
        if self.preview is not None and self.preview.view == CanvasView.COMPONENTS:
            self._update_grid()


def _offer(action, why: str) -> None:
    """Enable ``action`` when ``why`` is empty; else disable it, its tooltip ending in what the user can do."""
    tip = action.statusTip() or action.text().replace("&", "")
    action.setEnabled(not why)
    action.setToolTip(f"{tip} (unavailable: {why})" if why else tip)
