"""The main window: menus, toolbars, canvas, side panels, status bar, files and jobs.

It owns one document at a time (with its undo stack, painter, preview controller and
canvas) and runs every long piece of work — opening, saving, exporting, noise reduction — as a
:class:`~app.qt.worker.Job` with progress, pause and cancel in the status bar. Actions, menus
and toolbars are the tables of :mod:`app.qt.actions`; the rig (calibration wizard, acquisition
dock) is :class:`~app.qt.rig_control.RigControl`. Errors are shown as dialogs with the engine's
message; nothing the user did is dropped when something fails.
"""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import QSettings, QSignalBlocker, Qt, QTimer
from PySide6.QtGui import QAction, QActionGroup, QGuiApplication, QUndoGroup, QUndoStack
from PySide6.QtWidgets import (
    QApplication,
    QDockWidget,
    QDoubleSpinBox,
    QFileDialog,
    QLabel,
    QMainWindow,
    QMessageBox,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

import app
from app.model import files, saving
from app.model.document import Document
from app.model.history import History
from app.model.painting import Painter, Tool
from app.model.render import component_grid
from app.model.views import VIEWS, CanvasView
from app.qt.actions import ACTIONS, MENUS, TOOL_KEYS, TOOL_TIPS, TOOLBARS, KeepAppShortcuts, key_sequences
from app.qt.canvas import Canvas
from app.qt.layout import fit_to_screen, scrolling
from app.qt.panels import AlbedoPanel, NoiseReductionPanel, TargetPanel
from app.qt.preview import PreviewController
from app.qt.rig_control import RigControl
from app.qt.undo import QtHistory
from app.qt.worker import Job, JobProgress
from engine.errors import InputError
from engine.imageio import RAW_EXTENSIONS
from engine.progress import checkpoint

APP_NAME = "Albedit"
MAX_RECENT = 8
#: The size the window asks for on a large screen; smaller screens get their available area.
PREFERRED_SIZE = (1500, 920)

_EXPORT_FILTERS = {
    "OpenEXR, half float (*.exr)": (".exr", "half"),
    "OpenEXR, float (*.exr)": (".exr", "float"),
    "TIFF, 16-bit linear (*.tif *.tiff)": (".tif", "uint16"),
    "TIFF, float (*.tif *.tiff)": (".tif", "float"),
    "PNG, 8-bit sRGB for sharing (*.png)": (".png", "uint8"),
}


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
        self.noise_panel: NoiseReductionPanel | None = None
        self._placeholder = QLabel(self.PLACEHOLDER, objectName="placeholder")
        self._placeholder.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self._placeholder.setWordWrap(True)
        self.setCentralWidget(self._placeholder)
        fit_to_screen(self, PREFERRED_SIZE)
        self.rigs = RigControl(self, rig)
        self._build_actions()
        self._build_toolbars()
        self._build_menus()
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
    def _add_action(self, name: str, text: str, slot, shortcut=None, tip: str = "", *, checkable=False) -> QAction:
        a = QAction(text, self, objectName=name)
        a.setShortcuts(key_sequences(shortcut))
        a.setCheckable(checkable)
        if tip:
            a.setStatusTip(tip)
            a.setToolTip(tip)
        if slot is not None:
            a.triggered.connect(slot)
        self.addAction(a)
        return a

    def _build_actions(self) -> None:
        self.when: dict[str, str] = {}
        for spec in ACTIONS:
            if spec.name in ("undo", "redo"):  # QUndoGroup's: their text names the step ("Undo Paint 'wall'")
                a = (self.undo_group.createUndoAction if spec.name == "undo" else self.undo_group.createRedoAction)(
                    self, spec.text)
                a.setObjectName(spec.name)
                a.setShortcuts(key_sequences(spec.shortcut))
                self.addAction(a)
            else:
                target = getattr(self.rigs, spec.slot, None) or getattr(self, spec.slot)
                slot = target if spec.checkable else (lambda _c=False, f=target: f())
                a = self._add_action(spec.name, spec.text, slot, spec.shortcut, spec.tip, checkable=spec.checkable)
                a.setChecked(spec.checked)
            self.when[spec.name] = spec.when
            setattr(self, f"act_{spec.name}", a)
        self.tool_group = QActionGroup(self)
        self.tool_actions: dict[Tool, QAction] = {}
        for tool, key in TOOL_KEYS.items():
            a = self._add_action(f"tool_{tool.value}", tool.value.capitalize(),
                                 lambda _c=False, t=tool: self.set_tool(t), key, TOOL_TIPS[tool], checkable=True)
            self.tool_group.addAction(a)
            self.tool_actions[tool] = a
        self.tool_actions[Tool.BRUSH].setChecked(True)
        self.view_group = QActionGroup(self)
        self.view_actions: dict[CanvasView, QAction] = {}
        for spec in VIEWS:
            a = self._add_action(f"view_{spec.view.value}", spec.label, lambda _c=False, v=spec.view: self.set_view(v),
                                 spec.shortcut, f"{spec.label.replace('&', '')} ({spec.shortcut}): {spec.tip}",
                                 checkable=True)
            a.setIconText(spec.short)
            self.view_group.addAction(a)
            self.view_actions[spec.view] = a
        self.view_actions[CanvasView.RECOLORED].setChecked(True)

    def _entries(self, entries):
        """Resolve a menu or toolbar layout: actions, "-" separators, "@" groups, "#" widgets."""
        groups = {"@tools": list(self.tool_actions.values()), "@views": list(self.view_actions.values())}
        for e in entries:
            if e in groups:
                yield from groups[e]
            else:
                yield self._toolbar_widgets[e[1:]] if e.startswith("#") else e if e in ("-", "@recent") else \
                    getattr(self, f"act_{e}")

    def _build_menus(self) -> None:
        for name, title, entries in MENUS:
            menu = self.menuBar().addMenu(title)
            menu.setObjectName(name)
            for e in self._entries(entries):
                if e == "-":
                    menu.addSeparator()
                elif e == "@recent":
                    self.recent_menu = menu.addMenu("Open &Recent")
                    self.recent_menu.setObjectName("menu_recent")
                    self.recent_menu.aboutToShow.connect(self._fill_recent)
                else:
                    menu.addAction(e)

    def _build_toolbars(self) -> None:
        self.size_spin = QSpinBox(objectName="brush_size")
        self.size_spin.setRange(int(Painter.MIN_SIZE), int(Painter.MAX_SIZE))
        self.size_spin.setPrefix("Size ")
        self.size_spin.setSuffix(" px")
        self.size_spin.setToolTip("Brush diameter in camera pixels ([ and ] change it)")
        self.size_spin.valueChanged.connect(lambda v: self.painter and self.painter.set_size(v))
        self.tol_spin = QDoubleSpinBox(objectName="fill_tolerance")
        self.tol_spin.setRange(0.005, 2.0)
        self.tol_spin.setSingleStep(0.01)
        self.tol_spin.setDecimals(3)
        self.tol_spin.setValue(0.1)
        self.tol_spin.setPrefix("Tolerance ")
        self.tol_spin.setToolTip("Fill tolerance: largest |log colour difference| to the clicked pixel (0.1 ≈ ±10 %)")
        self.tol_spin.valueChanged.connect(lambda v: self.painter and setattr(self.painter, "tolerance", float(v)))
        self.exposure_spin = QDoubleSpinBox(objectName="display_exposure")
        self.exposure_spin.setRange(-12.0, 12.0)
        self.exposure_spin.setSingleStep(0.25)
        self.exposure_spin.setPrefix("Exposure ")
        self.exposure_spin.setSuffix(" EV")
        self.exposure_spin.setToolTip("Display exposure in stops (does not change the data)")
        self.exposure_spin.valueChanged.connect(lambda v: self.preview and self.preview.set_exposure(v))
        self._toolbar_widgets = {"brush_size": self.size_spin, "fill_tolerance": self.tol_spin,
                                 "display_exposure": self.exposure_spin}
        for name, title, entries in TOOLBARS:
            tb = self.addToolBar(title)
            tb.setObjectName(name)
            for e in self._entries(entries):
                if e == "-":
                    tb.addSeparator()
                elif isinstance(e, QWidget):
                    tb.addWidget(e)
                else:
                    tb.addAction(e)
                    tb.widgetForAction(e).setObjectName(f"{e.objectName()}_button")

    def _build_docks(self) -> None:
        self.targets_dock = QDockWidget("Targets (cascade order)", self, objectName="targets")
        self.albedo_dock = QDockWidget("Albedo", self, objectName="albedo")
        for d in (self.targets_dock, self.albedo_dock):
            d.setFeatures(QDockWidget.DockWidgetFeature.DockWidgetMovable
                          | QDockWidget.DockWidgetFeature.DockWidgetFloatable)
            self.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, d)

    def _build_status(self) -> None:
        sb = self.statusBar()
        sb.setObjectName("status")
        self.readout = QLabel(objectName="readout")
        self.readout.setMinimumWidth(380)
        self.readout.setStyleSheet("font-family: monospace;")
        self.note = QLabel(objectName="view_note")
        self.zoom_label = QLabel(objectName="zoom")
        self.progress = JobProgress("job_progress", hide_when_idle=True)
        self.progress.label.setMinimumWidth(240)
        self.progress.setMaximumWidth(640)
        sb.addWidget(self.note, 1)  # temporary messages cover this one only
        sb.addPermanentWidget(self.readout)
        sb.addPermanentWidget(self.progress)
        sb.addPermanentWidget(self.zoom_label)

    # ================================================================== document
    def set_document(self, document: Document, session=None, *, demo: bool = False) -> None:
        """Show ``document`` (replacing the current one; the open rig stays open).

        ``demo``: the document is the virtual-rig demo's, whose session lives in the user's
        cache and is reused by the next demo: Save makes a copy (Save As).
        """
        self._teardown()
        self.doc, self.session, self.demo = document, session, demo
        stack = QUndoStack(self)
        document.use_history(QtHistory(stack))
        self.undo_group.addStack(stack)
        self.undo_group.setActiveStack(stack)
        self.painter = Painter(document)
        self.painter.set_size(self.size_spin.value() if self.size_spin.value() > 1 else 20)
        self.painter.tolerance = self.tol_spin.value()
        self.painter.set_tool(self._checked_tool())
        with QSignalBlocker(self.size_spin):
            self.size_spin.setValue(int(self.painter.size))
        self.canvas = Canvas(document, self.painter)
        self.canvas.setObjectName("canvas")
        self.setCentralWidget(self.canvas)
        self.canvas.setFocus()  # single-key shortcuts (tools, views) work at once
        self.preview = PreviewController(document, max_shape=self._screen_shape(), synchronous=self.synchronous,
                                         parent=self)
        self.preview.exposure = self.exposure_spin.value()
        self.preview.view = self._checked_view()
        self.preview.frame_ready.connect(self._on_frame)
        self.preview.detail_ready.connect(self.canvas.set_detail)
        self.canvas.viewport_changed.connect(self.preview.set_viewport)
        self.preview.failed.connect(lambda msg: self.statusBar().showMessage(msg, 8000))
        self.canvas.cursor_moved.connect(self._on_cursor)
        self.canvas.zoom_changed.connect(lambda z: self.zoom_label.setText(f"{100 * z:.0f} %"))
        self.target_panel = TargetPanel(document)
        self.target_panel.message.connect(lambda m: self.statusBar().showMessage(m, 8000))
        self.albedo_panel = AlbedoPanel(document)
        self.noise_panel = NoiseReductionPanel(document)
        self.noise_panel.apply_requested.connect(self.apply_noise_reduction)
        self.targets_dock.setWidget(scrolling(self.target_panel, "targets_scroll"))
        self.albedo_dock.setWidget(scrolling(self._stacked(self.albedo_panel, self.noise_panel), "albedo_scroll"))
        ev = document.events
        ev.dirty.connect(lambda _d: self._update_title())
        ev.warning.connect(lambda m: self.statusBar().showMessage(m, 8000))
        ev.acquisition.connect(self._update_actions)
        ev.current.connect(lambda _u: self._update_actions())
        ev.targets.connect(self._update_actions)
        self.rigs.follow_document()
        self._update_grid()
        self.preview.request()
        self._update_title()
        self._update_actions()

    def _teardown(self) -> None:
        if self.doc is not None:  # the document outlives its window: back to a Qt-free history
            self.doc.use_history(History())
        if self.preview is not None:
            self.preview.close()
            self.preview.deleteLater()
        for stack in self.undo_group.stacks():
            self.undo_group.removeStack(stack)
            stack.deleteLater()
        self.preview = self.canvas = self.painter = None

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

    def _update_actions(self, *_args) -> None:
        for name, when in self.when.items():
            if name not in ("undo", "redo"):  # the undo group enables those
                getattr(self, f"act_{name}").setEnabled(self.condition(when))
        self.act_export.setToolTip(self.act_export.statusTip() if self.condition("decomposition")
                                   else "Acquire first: export needs a decomposition")
        last = self.rigs.last
        self.act_reopen_rig.setText(f"&Reopen {last[0]}" if last else "&Reopen Last Rig")
        for a in self.tool_actions.values():
            a.setEnabled(self.condition("document"))
        for view, a in self.view_actions.items():
            a.setEnabled(self.doc is not None and self.preview is not None and self.preview.available(view))
        if self.doc is not None and self.preview is not None and not self.preview.available(self.preview.view):
            self.set_view(CanvasView.RECOLORED)

    def _on_frame(self, frame) -> None:
        if self.canvas is None:
            return
        self.canvas.set_frame(frame)
        self.note.setText(frame.note)

    def _on_cursor(self, pos) -> None:
        if pos is None or self.preview is None:
            self.readout.setText("")
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

    # ================================================================== user actions
    def set_tool(self, tool: Tool | str) -> None:
        tool = Tool(tool)
        with QSignalBlocker(self.tool_group):
            self.tool_actions[tool].setChecked(True)
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
        for w in (self.canvas, self.target_panel, self.albedo_panel, self.noise_panel):
            if w is not None:
                w.setEnabled(not busy)
        stacks = self.undo_group.stacks()
        self.undo_group.setActiveStack(None if busy or not stacks else stacks[-1])

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

        def done(d):
            if doc is self.doc and doc.acquisition is not None and doc.acquisition.raw is acq.raw:
                doc.set_noise_reduction(int(radius), d)
                self.statusBar().showMessage(f"Noise reduction applied (radius {int(radius)} px)", 8000)

        self.run_job(denoise_components, acq.raw, doc.photograph, radius=int(radius), name="Noise reduction",
                     on_done=done)

    def open_demo(self, rig_name: str | None = None) -> None:
        """Open the virtual-rig demo: calibrated and acquired on a worker, with progress."""
        if self.maybe_save():
            self.rigs.open_demo(rig_name)

    def open_path(self, path) -> bool:
        """Open a session folder or an image; errors are shown, nothing else changes."""
        if not self.maybe_save():
            return False
        if self.job is not None:
            self.statusBar().showMessage(f"{self.job.name} is still running: open {Path(path).name} when it is done",
                                         8000)
            return False
        outcome = {}

        def work(progress=None, should_stop=None):  # a 24 MP session is ~1.7 GB to read: seconds
            opened = files.open_document(path)
            checkpoint(should_stop, "opening")
            return opened

        def done(result):
            doc, session, warnings = result
            self.set_document(doc, session)
            self._add_recent(path)
            outcome["ok"] = True
            if warnings:
                QMessageBox.warning(self, "Opened with warnings", "\n".join(warnings))

        self.run_job(work, name=f"Opening {Path(path).name}", on_done=done, pausable=False,
                     on_failed=lambda exc: self.show_error("Cannot open", exc))
        return bool(outcome.get("ok")) if self.synchronous else True

    def on_open_session(self) -> None:
        path = QFileDialog.getExistingDirectory(self, "Open session folder", self._last_dir())
        if path:
            self.open_path(path)

    def on_open_image(self) -> None:
        raws = " ".join(f"*{e}" for e in sorted(RAW_EXTENSIONS))
        path, _ = QFileDialog.getOpenFileName(self, "Open image", self._last_dir(),
                                              f"Images (*.exr *.tif *.tiff *.png *.jpg *.jpeg {raws})")
        if path:
            self.open_path(path)

    def save(self) -> bool:
        """Save into the current session (Save As when there is none, or for the demo). True when saved."""
        if self.doc is None:
            return False
        if self.session is None or self.demo:
            return self.save_as()
        return self._save_into(self.session, None)

    def save_as(self, path=None) -> bool:
        """Save into a new session folder (see :func:`app.model.saving.save_as`)."""
        if self.doc is None:
            return False
        if path is None:
            path, _ = QFileDialog.getSaveFileName(self, "Save session as (a new folder)", self._last_dir(),
                                                  "Albedit session folder (*)")
            if not path:
                return False
        return self._save_into(None, Path(path))

    def _save_into(self, session, new_path: Path | None) -> bool:
        doc, source = self.doc, self.session
        projector = None if self.rig is None else tuple(self.rig.projector.resolution)

        def work(progress=None, should_stop=None):
            if new_path is None:
                return saving.save_into(doc, session)
            return saving.save_as(doc, new_path, source=source, projector_resolution=projector)

        outcome = {}

        def done(s):
            self.session, self.demo = s, False
            doc.mark_saved()
            outcome["ok"] = True
            if new_path is not None:
                self._add_recent(new_path)
            self.rigs.follow_document()
            self._update_title()
            self.statusBar().showMessage(f"Saved {s.path}", 5000)

        self.run_job(work, name="Saving", on_done=done, pausable=False, cancellable=False)
        return bool(outcome.get("ok")) if self.synchronous else True

    def on_export(self) -> None:
        if self.doc is None:
            return
        path, chosen = QFileDialog.getSaveFileName(self, "Export recolored image", self._last_dir(),
                                                   ";;".join(_EXPORT_FILTERS))
        if not path:
            return
        ext, dtype = _EXPORT_FILTERS.get(chosen, (Path(path).suffix.lower(), None))
        if Path(path).suffix.lower() not in files.EXPORT_FORMATS:
            path = path + ext
        self.export(path, dtype=dtype)

    def export(self, path, *, dtype: str | None = None, clip: bool = False) -> None:
        """Export the full-resolution recolored image on a worker (see :func:`app.model.files.export_image`)."""
        exposure = self.exposure_spin.value()

        def failed(exc):
            if isinstance(exc, InputError) and "allow clipping" in str(exc) and not clip:
                answer = QMessageBox.question(self, "Export", f"{exc}\n\nClip those values to 1 and export anyway?")
                if answer == QMessageBox.StandardButton.Yes:
                    QTimer.singleShot(0, lambda: self.export(path, dtype=dtype, clip=True))
                return
            self.show_error("Export failed", exc)

        self.run_job(files.export_image, self.doc, path, dtype=dtype, exposure=exposure, clip=clip,
                     name="Exporting", on_done=lambda p: self.statusBar().showMessage(f"Exported {p}", 5000),
                     on_failed=failed)

    def maybe_save(self) -> bool:
        """Ask about unsaved changes. True when it is fine to go on (saved or discarded)."""
        if self.doc is None or not self.doc.is_dirty():
            return True
        answer = self.ask_unsaved()
        if answer == QMessageBox.StandardButton.Cancel:
            return False
        if answer == QMessageBox.StandardButton.Discard:
            return True
        if not self.save():
            return False
        if self.job is not None:  # a threaded save: wait for it before going on
            self.job.wait()
        return not self.doc.is_dirty()

    def ask_unsaved(self) -> QMessageBox.StandardButton:
        """The unsaved-changes prompt (Save / Discard / Cancel)."""
        box = QMessageBox(QMessageBox.Icon.Warning, APP_NAME, "The document has unsaved changes.",
                          QMessageBox.StandardButton.Save | QMessageBox.StandardButton.Discard
                          | QMessageBox.StandardButton.Cancel, self)
        box.setInformativeText("Save the targets and albedo changes before closing?")
        box.setDefaultButton(QMessageBox.StandardButton.Save)
        box.setObjectName("unsaved_prompt")
        return QMessageBox.StandardButton(box.exec())

    def closeEvent(self, event) -> None:  # noqa: N802 - Qt override
        if self.job is not None:
            self.job.wait(10.0, cancel=True)
        if not self.maybe_save():
            event.ignore()
            return
        self.rigs.shutdown()  # a running acquisition stops (its captures stay), the rig closes
        self._teardown()
        event.accept()

    # ================================================================== recent files
    def _recent(self) -> list[str]:
        value = self.settings.value("recent", [])
        if isinstance(value, str):
            value = [value]
        return [str(v) for v in (value or [])]

    def _add_recent(self, path) -> None:
        path = str(Path(path).resolve())
        items = [path] + [p for p in self._recent() if p != path]
        self.settings.setValue("recent", items[:MAX_RECENT])
        self.settings.setValue("last_dir", str(Path(path).parent))

    def _last_dir(self) -> str:
        return str(self.settings.value("last_dir", str(Path.home())))

    def _fill_recent(self) -> None:
        self.recent_menu.clear()
        items = self._recent()
        for p in items:
            a = self.recent_menu.addAction(p)
            a.triggered.connect(lambda _c=False, p=p: self.open_path(p))
        if not items:
            self.recent_menu.addAction("(none)").setEnabled(False)

    def resizeEvent(self, e) -> None:  # noqa: N802
        super().resizeEvent(e)
        if self.preview is not None and self.preview.view == CanvasView.COMPONENTS:
            self._update_grid()
