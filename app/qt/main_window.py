"""The main window: menus, toolbars, canvas, side panels, status bar, files and jobs.

It owns one document at a time (with its undo stack, painter, preview controller and
canvas) and runs every long piece of work — opening the demo rig, saving, exporting — as a
:class:`~app.qt.worker.Job` with progress, pause and cancel in the status bar. Errors are shown
as dialogs with the engine's message; nothing the user did is dropped when something fails.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from PySide6.QtCore import QSettings, QSignalBlocker, Qt, QTimer
from PySide6.QtGui import QAction, QActionGroup, QGuiApplication, QKeySequence, QUndoGroup, QUndoStack
from PySide6.QtWidgets import (
    QDockWidget,
    QDoubleSpinBox,
    QFileDialog,
    QHBoxLayout,
    QLabel,
    QMainWindow,
    QMessageBox,
    QProgressBar,
    QSpinBox,
    QToolButton,
    QVBoxLayout,
    QWidget,
)

from app.model import files
from app.model.document import Document
from app.model.history import History
from app.model.painting import Painter, Tool
from app.model.render import View, component_grid
from app.qt.canvas import Canvas
from app.qt.panels import AlbedoPanel, NoiseReductionPanel, TargetPanel
from app.qt.preview import PreviewController
from app.qt.undo import QtHistory
from app.qt.worker import Job
from engine.errors import InputError
from engine.progress import checkpoint
from engine.session import Session

APP_NAME = "Albedit"
MAX_RECENT = 8

_VIEW_LABELS = {
    View.RECOLORED: "&Recolored",
    View.ORIGINAL: "&Original",
    View.SPLIT: "&Split Before/After",
    View.DIFFERENCE: "&Difference",
    View.COMPONENTS: "Interaction &Components",
    View.TRUTH: "&Ground Truth",
    View.ERROR: "&Error vs Ground Truth",
}
_VIEW_SHORT = {
    View.RECOLORED: "Recolored", View.ORIGINAL: "Original", View.SPLIT: "Split", View.DIFFERENCE: "Difference",
    View.COMPONENTS: "Components", View.TRUTH: "Truth", View.ERROR: "Error",
}
_TOOL_KEYS = {Tool.BRUSH: "B", Tool.ERASER: "E", Tool.POLYGON: "P", Tool.LASSO: "L", Tool.FILL: "F"}
_EXPORT_FILTERS = {
    "OpenEXR, half float (*.exr)": (".exr", "half"),
    "OpenEXR, float (*.exr)": (".exr", "float"),
    "TIFF, 16-bit linear (*.tif *.tiff)": (".tif", "uint16"),
    "TIFF, float (*.tif *.tiff)": (".tif", "float"),
    "PNG, 8-bit sRGB for sharing (*.png)": (".png", "uint8"),
}


class JobProgress(QWidget):
    """Status-bar progress of the running job: message, bar, pause and cancel."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.label = QLabel()
        self.bar = QProgressBar()
        self.bar.setMaximumWidth(220)
        self.bar.setTextVisible(True)
        self.pause = QToolButton(text="Pause", checkable=True)
        self.cancel = QToolButton(text="Cancel")
        lay = QHBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        for w in (self.label, self.bar, self.pause, self.cancel):
            lay.addWidget(w)
        self.job: Job | None = None
        self.hide()

    def attach(self, job: Job, *, pausable: bool = True, cancellable: bool = True) -> None:
        """Follow ``job``; Pause and Cancel are shown only where the job honours them."""
        self.job = job
        self.label.setText(job.name)
        self.bar.setRange(0, 0)
        self.pause.setChecked(False)
        self.pause.setVisible(pausable)
        self.cancel.setVisible(cancellable)
        job.progress.connect(self._on_progress)
        job.paused.connect(self.pause.setChecked)
        job.ended.connect(self._on_ended)
        self.pause.toggled.connect(self._on_pause)
        self.cancel.clicked.connect(job.cancel)
        self.show()

    def _on_progress(self, step: int, total: int, message: str) -> None:
        if total > 0:
            self.bar.setRange(0, total)
            self.bar.setValue(step)
        self.label.setText(f"{self.job.name}: {message}" if self.job else message)

    def _on_pause(self, on: bool) -> None:
        if self.job is not None:
            self.job.pause() if on else self.job.resume()

    def _on_ended(self) -> None:
        self.pause.toggled.disconnect(self._on_pause)
        if self.job is not None:
            self.cancel.clicked.disconnect(self.job.cancel)
        self.job = None
        self.hide()


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
        Recent files; tests pass a temporary one.
    """

    #: What the empty window says.
    PLACEHOLDER = "Open a session or an image (File menu), or start the virtual-rig demo."

    def __init__(self, document: Document | None = None, session=None, *, synchronous: bool = False,
                 settings: QSettings | None = None, rig=None):
        super().__init__()
        self.synchronous = synchronous
        self.settings = settings if settings is not None else QSettings(APP_NAME, APP_NAME)
        self.doc: Document | None = None
        self.session = session
        self.rig = rig
        self.scratch: Path | None = None
        self.job: Job | None = None
        self.undo_group = QUndoGroup(self)
        self.preview: PreviewController | None = None
        self.canvas: Canvas | None = None
        self.painter: Painter | None = None
        self._placeholder = QLabel(self.PLACEHOLDER)
        self._placeholder.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.setCentralWidget(self._placeholder)
        self.resize(1500, 920)
        self._build_actions()
        self._build_menus()
        self._build_toolbars()
        self._build_docks()
        self._build_status()
        if document is not None:
            self.set_document(document, session, rig=rig)
        self._update_title()
        self._update_actions()

    # ================================================================== construction
    def _action(self, text: str, slot=None, shortcut=None, *, checkable=False, tip: str = "") -> QAction:
        a = QAction(text, self)
        if shortcut is not None:
            a.setShortcuts(shortcut if isinstance(shortcut, list) else [QKeySequence(shortcut)])
        a.setCheckable(checkable)
        if tip:
            a.setStatusTip(tip)
            a.setToolTip(tip)
        if slot is not None:
            a.triggered.connect(slot)
        self.addAction(a)
        return a

    def _build_actions(self) -> None:
        K = QKeySequence.StandardKey
        self.act_open = self._action("&Open Session…", self._on_open_session, K.Open)
        self.act_open_image = self._action("Open &Image…", self._on_open_image, "Ctrl+Shift+O")
        self.act_demo = self._action("Virtual Rig &Demo", lambda: self.open_demo(), tip="Open the virtual Cornell box")
        self.act_save = self._action("&Save", self.save, K.Save)
        self.act_save_as = self._action("Save &As…", self.save_as, K.SaveAs)
        self.act_export = self._action("&Export Recolored Image…", self._on_export, "Ctrl+E")
        self.act_quit = self._action("&Quit", self.close, K.Quit)
        self.act_undo = self.undo_group.createUndoAction(self, "&Undo")
        self.act_undo.setShortcuts(QKeySequence.keyBindings(K.Undo))
        self.act_redo = self.undo_group.createRedoAction(self, "&Redo")
        redo_keys = QKeySequence.keyBindings(K.Redo)
        if QKeySequence("Ctrl+Shift+Z") not in redo_keys:  # the binding, on every platform
            redo_keys.append(QKeySequence("Ctrl+Shift+Z"))
        self.act_redo.setShortcuts(redo_keys)
        for a in (self.act_undo, self.act_redo):
            self.addAction(a)
        self.act_add = self._action("&Add Target", lambda: self._guard(self.doc.add_target), "Ctrl+T")
        self.act_delete = self._action("&Delete Target", self._on_delete_target)
        self.act_clear = self._action("&Clear Mask", lambda: self._mask_op("clear_mask"), "Ctrl+Backspace")
        self.act_invert = self._action("&Invert Mask", lambda: self._mask_op("invert_mask"), "Ctrl+I")
        self.act_overlays = self._action("Show &Overlays", self._on_overlays, "O", checkable=True)
        self.act_overlays.setChecked(True)
        self.act_bigger = self._action("Larger Brush", lambda: self._brush("grow"), "]")
        self.act_smaller = self._action("Smaller Brush", lambda: self._brush("shrink"), "[")
        self.tool_group = QActionGroup(self)
        self.tool_actions: dict[Tool, QAction] = {}
        for tool, key in _TOOL_KEYS.items():
            a = self._action(tool.value.capitalize(), lambda _c=False, t=tool: self.set_tool(t), key, checkable=True)
            a.setToolTip(f"{tool.value.capitalize()} ({key})")
            self.tool_group.addAction(a)
            self.tool_actions[tool] = a
        self.tool_actions[Tool.BRUSH].setChecked(True)
        self.tool_actions[Tool.POLYGON].setToolTip("Polygon: click vertices; double-click, Enter or the first vertex closes it")
        self.tool_actions[Tool.FILL].setToolTip("Fill by similar colour (tolerance in the toolbar); Alt subtracts")
        self.view_group = QActionGroup(self)
        self.view_actions: dict[View, QAction] = {}
        for i, (view, label) in enumerate(_VIEW_LABELS.items()):
            a = self._action(label, lambda _c=False, v=view: self.set_view(v), str(i + 1), checkable=True)
            a.setIconText(_VIEW_SHORT[view])
            a.setToolTip(f"{label.replace('&', '')} ({i + 1})")
            self.view_group.addAction(a)
            self.view_actions[view] = a
        self.view_actions[View.RECOLORED].setChecked(True)
        self.act_fit = self._action("&Fit", lambda: self.canvas and self.canvas.fit(), "Ctrl+0")
        self.act_100 = self._action("&100 %", lambda: self.canvas and self.canvas.zoom_to(1.0), "Ctrl+1")
        self.act_zoom_in = self._action("Zoom &In", lambda: self.canvas and self.canvas.zoom_by(1.25), K.ZoomIn)
        self.act_zoom_out = self._action("Zoom &Out", lambda: self.canvas and self.canvas.zoom_by(0.8), K.ZoomOut)
        self.act_acquire = self._action("&Acquire…", self.acquire, tip="Measure the targets on the rig (cascade)")
        self.act_calibrate = self._action("&Calibrate Rig…", self.calibrate, tip="Calibrate a camera–projector rig into a session")
        self.act_discard = self._action("&Discard Acquisition", self._on_discard)
        self.act_about = self._action("&About Albedit", self._on_about)

    def _build_menus(self) -> None:
        mb = self.menuBar()
        m = mb.addMenu("&File")
        for a in (self.act_open, self.act_open_image, self.act_demo):
            m.addAction(a)
        self.recent_menu = m.addMenu("Open &Recent")
        self.recent_menu.aboutToShow.connect(self._fill_recent)
        m.addSeparator()
        for a in (self.act_save, self.act_save_as, self.act_export):
            m.addAction(a)
        m.addSeparator()
        m.addAction(self.act_quit)
        m = mb.addMenu("&Edit")
        m.addAction(self.act_undo)
        m.addAction(self.act_redo)
        m = mb.addMenu("&Targets")
        for a in (self.act_add, self.act_delete):
            m.addAction(a)
        m.addSeparator()
        for a in self.tool_actions.values():
            m.addAction(a)
        m.addSeparator()
        for a in (self.act_bigger, self.act_smaller, self.act_clear, self.act_invert, self.act_overlays):
            m.addAction(a)
        m = mb.addMenu("&View")
        for a in self.view_actions.values():
            m.addAction(a)
        m.addSeparator()
        for a in (self.act_fit, self.act_100, self.act_zoom_in, self.act_zoom_out):
            m.addAction(a)
        m = mb.addMenu("&Rig")
        m.addAction(self.act_calibrate)
        m.addAction(self.act_acquire)
        m.addAction(self.act_discard)
        m = mb.addMenu("&Help")
        m.addAction(self.act_about)

    def _build_toolbars(self) -> None:
        tb = self.addToolBar("Tools")
        tb.setObjectName("tools")
        for a in self.tool_actions.values():
            tb.addAction(a)
        tb.addSeparator()
        tb.addWidget(QLabel(" Size "))
        self.size_spin = QSpinBox()
        self.size_spin.setRange(int(Painter.MIN_SIZE), int(Painter.MAX_SIZE))
        self.size_spin.setSuffix(" px")
        self.size_spin.setToolTip("Brush diameter in camera pixels ([ and ] change it)")
        self.size_spin.valueChanged.connect(lambda v: self.painter and self.painter.set_size(v))
        tb.addWidget(self.size_spin)
        tb.addWidget(QLabel(" Tolerance "))
        self.tol_spin = QDoubleSpinBox()
        self.tol_spin.setRange(0.005, 2.0)
        self.tol_spin.setSingleStep(0.01)
        self.tol_spin.setDecimals(3)
        self.tol_spin.setValue(0.1)
        self.tol_spin.setToolTip("Fill tolerance: largest |log colour difference| to the clicked pixel (0.1 ≈ ±10 %)")
        self.tol_spin.valueChanged.connect(lambda v: self.painter and setattr(self.painter, "tolerance", float(v)))
        tb.addWidget(self.tol_spin)
        tb.addSeparator()
        tb.addAction(self.act_clear)
        tb.addAction(self.act_invert)
        tb = self.addToolBar("View")
        tb.setObjectName("view")
        for v in (View.RECOLORED, View.ORIGINAL, View.SPLIT, View.DIFFERENCE, View.COMPONENTS, View.TRUTH, View.ERROR):
            tb.addAction(self.view_actions[v])
        tb.addSeparator()
        tb.addWidget(QLabel(" Exposure "))
        self.exposure_spin = QDoubleSpinBox()
        self.exposure_spin.setRange(-12.0, 12.0)
        self.exposure_spin.setSingleStep(0.25)
        self.exposure_spin.setSuffix(" EV")
        self.exposure_spin.setToolTip("Display exposure in stops (does not change the data)")
        self.exposure_spin.valueChanged.connect(lambda v: self.preview and self.preview.set_exposure(v))
        tb.addWidget(self.exposure_spin)
        tb.addAction(self.act_fit)
        tb.addAction(self.act_100)

    def _build_docks(self) -> None:
        self.targets_dock = QDockWidget("Targets (cascade order)", self)
        self.targets_dock.setObjectName("targets")
        self.albedo_dock = QDockWidget("Albedo", self)
        self.albedo_dock.setObjectName("albedo")
        for d in (self.targets_dock, self.albedo_dock):
            d.setFeatures(QDockWidget.DockWidgetFeature.DockWidgetMovable | QDockWidget.DockWidgetFeature.DockWidgetFloatable)
            self.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, d)
        self.target_panel: TargetPanel | None = None
        self.albedo_panel: AlbedoPanel | None = None
        self.noise_panel: NoiseReductionPanel | None = None

    def _build_status(self) -> None:
        sb = self.statusBar()
        self.readout = QLabel()
        self.readout.setMinimumWidth(560)
        self.readout.setStyleSheet("font-family: monospace;")
        self.note = QLabel()
        self.zoom_label = QLabel()
        self.progress = JobProgress()
        sb.addWidget(self.note, 1)  # temporary messages cover this one only
        sb.addPermanentWidget(self.readout)
        sb.addPermanentWidget(self.progress)
        sb.addPermanentWidget(self.zoom_label)

    # ================================================================== document
    def set_document(self, document: Document, session=None, *, rig=None, scratch: Path | None = None) -> None:
        """Show ``document`` (replacing the current one, whose rig is closed).

        ``scratch`` is a temporary folder holding ``session`` (the demo's): Save copies the
        session elsewhere, and the folder is deleted when the document is closed.
        """
        self._teardown()
        self.doc, self.session = document, session
        self.rig, self.scratch = rig, scratch
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
        self.setCentralWidget(self.canvas)
        self.preview = PreviewController(document, max_shape=self._screen_shape(), synchronous=self.synchronous, parent=self)
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
        self.targets_dock.setWidget(self.target_panel)
        self.albedo_dock.setWidget(self._padded(self.albedo_panel, self.noise_panel))
        ev = document.events
        ev.dirty.connect(lambda _d: self._update_title())
        ev.warning.connect(lambda m: self.statusBar().showMessage(m, 8000))
        ev.acquisition.connect(self._update_actions)
        ev.current.connect(lambda _u: self._update_actions())
        ev.targets.connect(self._update_actions)
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
        rig, scratch, self.rig, self.scratch = self.rig, self.scratch, None, None
        try:
            if rig is not None:
                rig.close()
        finally:
            if scratch is not None:
                shutil.rmtree(scratch, ignore_errors=True)

    @staticmethod
    def _padded(*widgets: QWidget) -> QWidget:
        box = QWidget()
        lay = QVBoxLayout(box)
        for w in widgets:
            lay.addWidget(w)
            lay.addSpacing(8)
        lay.addStretch(1)
        return box

    def _screen_shape(self) -> tuple[int, int]:
        screen = QGuiApplication.primaryScreen()
        if screen is None:
            return (1080, 1920)
        size, dpr = screen.size(), screen.devicePixelRatio()
        return (max(int(size.height() * dpr), 256), max(int(size.width() * dpr), 256))

    # ================================================================== state → UI
    def _update_title(self) -> None:
        name = "(no document)"
        if self.scratch is not None and self.doc is not None:
            name = f"{self.doc.source} demo (not saved)"
        elif self.session is not None:
            name = Path(self.session.path).name
        elif self.doc is not None:
            name = Path(self.doc.source).name if self.doc.source and ":" not in self.doc.source else self.doc.source or "untitled"
        self.setWindowTitle(f"{name}[*] — {APP_NAME}")
        self.setWindowModified(self.doc is not None and self.doc.is_dirty())

    def _update_actions(self, *_args) -> None:
        has = self.doc is not None
        idle = self.job is None
        cur = has and self.doc.current != -1
        for a in (self.act_save, self.act_save_as, self.act_add, self.act_overlays, self.act_fit, self.act_100,
                  self.act_zoom_in, self.act_zoom_out):
            a.setEnabled(has and idle)
        for a in (self.act_clear, self.act_invert):
            a.setEnabled(cur and idle and not self.doc.mask_lock(self.doc.current))
        self.act_delete.setEnabled(cur and idle and not self.doc.mask_lock(self.doc.current))
        self.act_export.setEnabled(has and idle and self.doc.decomposition is not None)
        self.act_export.setToolTip("" if has and self.doc.decomposition is not None else "Acquire first: export needs a decomposition")
        self.act_acquire.setEnabled(has and idle and self.rig is not None)
        self.act_discard.setEnabled(has and idle and self.doc.acquisition is not None)
        for a in (self.act_open, self.act_open_image, self.act_demo):
            a.setEnabled(idle)
        for view, a in self.view_actions.items():
            a.setEnabled(has and self.preview is not None and self.preview.available(view))
        if has and self.preview is not None and not self.preview.available(self.preview.view):
            self.set_view(View.RECOLORED)

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

    def set_view(self, view: View | str) -> None:
        view = View(view)
        self.view_actions[view].setChecked(True)
        if self.preview is not None:
            self._update_grid()
            self.preview.set_view(view)

    def _update_grid(self) -> None:
        """Rows × columns of the components view that show the tiles largest in the canvas."""
        if self.preview is None or self.doc.decomposition is None:
            return
        size = self.canvas.size() if self.canvas is not None else self.size()
        self.preview.set_grid(component_grid(self.doc.decomposition.order, self.doc.shape, (size.height(), size.width())))

    def _checked_tool(self) -> Tool:
        return next((t for t, a in self.tool_actions.items() if a.isChecked()), Tool.BRUSH)

    def _checked_view(self) -> View:
        return next((v for v, a in self.view_actions.items() if a.isChecked()), View.RECOLORED)

    def _brush(self, how: str) -> None:
        if self.painter is None:
            return
        getattr(self.painter, how)()
        with QSignalBlocker(self.size_spin):
            self.size_spin.setValue(int(round(self.painter.size)))
        self.canvas.update()

    def _mask_op(self, name: str) -> None:
        if self.doc is not None and self.doc.current != -1:
            self._guard(getattr(self.doc, name), self.doc.current)

    def _on_delete_target(self) -> None:
        if self.doc is not None and self.doc.current != -1:
            self._guard(self.doc.remove_target, self.doc.current)

    def _on_overlays(self, on: bool) -> None:
        if self.canvas is not None:
            self.canvas.show_overlays = on
            self.canvas.update()

    def _on_discard(self) -> None:
        if self.doc is None or self.doc.acquisition is None:
            return
        answer = QMessageBox.question(
            self, "Discard acquisition",
            "Forget the measured decomposition? Every κ and mask becomes editable again; "
            "recoloring needs a new acquisition.")
        if answer == QMessageBox.StandardButton.Yes:
            self.doc.discard_acquisition()
            self.preview.rebuild()

    def calibrate(self) -> None:
        """Run the calibration wizard on the current rig (or one it opens) into a session."""
        from app.qt.calibration_wizard import CalibrationWizard

        wizard = CalibrationWizard(self, rig=self.rig, keep_rig=self.rig is None)
        wizard.finished_session.connect(lambda session: self._on_calibrated(wizard, session))
        wizard.open()

    def _on_calibrated(self, wizard, session) -> None:
        if self.rig is None and wizard.rig is not None:
            self.rig = wizard.rig
        if self.session is None:
            self.session = session
        self.statusBar().showMessage(f"Calibrated into {session.path}", 10000)
        self._update_actions()

    def acquire(self) -> None:
        """Check the targets can be acquired, then measure them on the rig (cascade order)."""
        if self.doc is None:
            return
        try:
            self.doc.check_acquirable()
        except InputError as exc:
            self.show_error("Cannot acquire", exc)
            return
        from app.qt.acquisition_panel import AcquisitionPanel

        targets = [(t.name, t.mask) for t in self.doc.targets]
        fixed = [t.kappa for t in self.doc.targets[:-1]]
        if getattr(self, "_acquisition_dock", None) is None:
            panel = AcquisitionPanel(self.rig, self.session, targets, fixed, parent=self, synchronous=self.synchronous)
            panel.acquired.connect(self._on_acquired)
            dock = QDockWidget("Acquisition", self)
            dock.setObjectName("acquisition")
            dock.setWidget(panel)
            self.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, dock)
            self._acquisition_dock = dock
        else:
            panel = self._acquisition_dock.widget()
            panel.set_rig(self.rig)
            panel.set_session(self.session)
            panel.set_targets(targets, fixed)
        self._acquisition_dock.show()
        self._acquisition_dock.raise_()

    def _on_acquired(self, result) -> None:
        """A finished cascade becomes the document's acquisition; the last target stays free."""
        from engine.workflow import load_decomposition, plan_key

        by_name = {t.name: t.uid for t in self.doc.targets}
        try:
            cascade = [by_name[name] for name, _ in result.targets]
            self.doc.set_acquisition(cascade, load_decomposition(self.session), key=plan_key(self.session))
        except (KeyError, InputError) as exc:
            self.show_error("Cannot use the acquisition", exc)
            return
        self.preview.rebuild()
        self.statusBar().showMessage(
            f"Acquired {result.images} images ({result.predicted} predicted); drag the κ sliders of "
            f"{result.targets[-1][0]!r}", 15000)

    def _guard(self, fn, *args):
        try:
            return fn(*args)
        except InputError as exc:
            self.statusBar().showMessage(str(exc), 8000)
            return None

    def show_error(self, title: str, exc: BaseException) -> None:
        """An error dialog with the engine's message."""
        QMessageBox.critical(self, title, str(exc) or type(exc).__name__)

    def _on_about(self) -> None:
        QMessageBox.about(self, f"About {APP_NAME}",
                          "<b>Albedit</b> — measurement-based editing of diffuse albedo with consistent "
                          "interreflections.<br>Paint targets, acquire them on a camera–projector rig, then "
                          "change their albedo with every interreflection following.")

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

        def finished(result):
            if on_done is not None:
                on_done(result)

        def failed(exc):
            if on_failed is not None:
                on_failed(exc)
            else:
                self.show_error(f"{name} failed", exc)

        def ended():
            self.job = None
            self._set_busy(False)
            self._update_actions()
            if self.centralWidget() is self._placeholder:
                self._placeholder.setText(self.PLACEHOLDER)

        job.finished.connect(finished)
        job.failed.connect(failed)
        job.cancelled.connect(lambda exc: self.statusBar().showMessage(str(exc), 8000))
        job.ended.connect(ended)
        self.progress.attach(job, pausable=pausable, cancellable=cancellable)
        if self.centralWidget() is self._placeholder:  # nothing open yet: say what is coming
            self._placeholder.setText(f"{name}…\n\nIts progress is in the status bar.")
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
        """Noise-reduce the acquired decomposition with ``radius`` (a job; 0 switches it off)."""
        doc = self.doc
        acq = None if doc is None else doc.acquisition
        if acq is None:
            return
        if int(radius) == acq.denoise:
            self.statusBar().showMessage(
                "Noise reduction is already off" if not acq.denoise else f"Radius {acq.denoise} px is already applied", 5000)
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

    def open_demo(self, rig_name: str = "virtual:cornell") -> None:
        """Open the virtual rig with its scene targets painted (on a worker, with progress)."""
        if not self.maybe_save():
            return
        from app.model.demo import open_demo

        def done(result):
            doc, rig, session = result
            self.set_document(doc, session, rig=rig, scratch=None if session is None else Path(session.path).parent)
            if session is not None:
                self.statusBar().showMessage(
                    f"Acquired {doc.targets[-1].name!r} on {rig_name} and recolored it as in the paper's Fig. 6; "
                    "try the κ sliders and the Error view", 15000)

        self.run_job(open_demo, rig_name, name=f"Opening the {rig_name} demo", on_done=done)

    def open_path(self, path) -> bool:
        """Open a session folder or an image; errors are shown, nothing else changes."""
        if not self.maybe_save():
            return False
        if self.job is not None:
            self.statusBar().showMessage(f"{self.job.name} is still running: open {Path(path).name} when it is done", 8000)
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

    def _on_open_session(self) -> None:
        path = QFileDialog.getExistingDirectory(self, "Open session folder", self._last_dir())
        if path:
            self.open_path(path)

    def _on_open_image(self) -> None:
        path, _ = QFileDialog.getOpenFileName(
            self, "Open image", self._last_dir(),
            "Images (*.exr *.tif *.tiff *.png *.jpg *.jpeg *.nef *.cr2 *.cr3 *.arw *.dng *.raf *.orf *.rw2)")
        if path:
            self.open_path(path)

    def save(self) -> bool:
        """Save into the current session (Save As when there is none). True when saved."""
        if self.doc is None:
            return False
        if self.session is None or self.scratch is not None:
            return self.save_as()
        return self._save_into(self.session, None)

    def save_as(self, path=None) -> bool:
        """Save into a new session folder: a copy of the current session (captures, calibration)
        or, for a plain image, a new session holding the photograph; then the edit."""
        if self.doc is None:
            return False
        if path is None:
            path, _ = QFileDialog.getSaveFileName(self, "Save session as (a new folder)", self._last_dir(),
                                                  "Albedit session folder (*)")
            if not path:
                return False
        return self._save_into(None, Path(path))

    def _save_into(self, session, new_path: Path | None) -> bool:
        doc = self.doc
        projector = None
        if self.rig is not None:
            projector = tuple(self.rig.projector.resolution)

        source = self.session

        def work(progress=None, should_stop=None):
            if new_path is not None and source is not None:
                if new_path.exists() and any(new_path.iterdir()):
                    raise InputError(f"{new_path} exists and is not empty: choose a new folder name")
                shutil.copytree(source.path, new_path, dirs_exist_ok=True)
                target = Session.open(new_path)
            elif new_path is not None:
                return files.create_session(new_path, doc, projector_resolution=projector, mark_saved=False)
            else:
                target = session
            files.save_document(doc, target, mark_saved=False)
            return target

        outcome = {}

        def done(s):
            if self.scratch is not None:  # the demo's scratch folder is no longer needed
                shutil.rmtree(self.scratch, ignore_errors=True)
                self.scratch = None
            self.session = s
            doc.mark_saved()
            outcome["ok"] = True
            if new_path is not None:
                self._add_recent(new_path)
            self._update_title()
            self.statusBar().showMessage(f"Saved {s.path}", 5000)

        self.run_job(work, name="Saving", on_done=done, pausable=False, cancellable=False)
        return bool(outcome.get("ok")) if self.synchronous else True

    def _on_export(self) -> None:
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
        self._wait_for_job()  # a threaded save: wait for it before going on
        return not self.doc.is_dirty()

    def _wait_for_job(self, timeout: float = 60.0) -> None:
        """Let the running job finish, keeping the UI thread serving it (it may ask for UI calls)."""
        job, waited = self.job, 0.0
        while job is not None and self.job is job and waited < timeout:  # until its end reached the window
            QGuiApplication.processEvents()
            job.join(0.02)
            waited += 0.02

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
            self.job.cancel()
            self._wait_for_job(10.0)
        if not self.maybe_save():
            event.ignore()
            return
        dock = getattr(self, "_acquisition_dock", None)
        if dock is not None:
            dock.widget().shutdown()  # a running acquisition stops; its captures stay in the session
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
        if self.preview is not None and self.preview.view == View.COMPONENTS:
            self._update_grid()
