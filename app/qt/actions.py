"""The main window's actions, menus and toolbars, as data.

Every action is one :class:`ActionSpec` row: its objectName (docs/ui.md; tests find it by that
name, the window keeps it as ``act_<name>``), menu text, the window method it triggers, its
shortcut, its tip, and *when* it is enabled (a condition named in :data:`CONDITIONS`, evaluated
by the window). Tool and view actions come from their own tables (:class:`Tool`,
:data:`app.model.views.VIEWS`). :data:`MENUS` and :data:`TOOLBARS` lay them out; ``@name``
entries are filled by the window (recent files, tools, views).

:class:`KeepAppShortcuts` lets the window's Ctrl shortcuts (undo, export, save…) work while a
spin box or line edit has the keyboard focus, as they do everywhere else.
"""

from __future__ import annotations

from dataclasses import dataclass

from PySide6.QtCore import QEvent, QObject, Qt
from PySide6.QtGui import QAction, QActionGroup, QKeySequence
from PySide6.QtWidgets import (
    QAbstractSpinBox,
    QApplication,
    QDoubleSpinBox,
    QLineEdit,
    QSpinBox,
    QToolBar,
    QWidget,
)

from app.model.painting import Painter, Tool
from app.model.views import NEED_HINTS, VIEWS, CanvasView, Need

K = QKeySequence.StandardKey


@dataclass(frozen=True)
class ActionSpec:
    """One action of the main window.

    Attributes
    ----------
    name : str
        objectName; the window's attribute is ``act_<name>``.
    text : str
        Menu text (``&`` marks the mnemonic).
    slot : str
        The window method called on trigger (checkable actions pass their state).
    shortcut : str, StandardKey or tuple, optional
    tip : str
    when : str
        Enabled while this condition holds (see :data:`CONDITIONS`).
    checkable, checked : bool
    """

    name: str
    text: str
    slot: str
    shortcut: str | QKeySequence.StandardKey | tuple | None = None
    tip: str = ""
    when: str = "idle"
    checkable: bool = False
    checked: bool = False


#: When actions are enabled (the window evaluates each by name), each with what the user can do when it does not
#: hold: a disabled action's tooltip says it (menus show tooltips). Every condition but ``always`` and
#: ``last_rig`` also needs no running job, and all but those and ``idle`` an open document.
CONDITIONS = {
    "always": "",
    "idle": "wait for the running job to end",
    "document": "open a session or an image first (File ▸ Open)",
    "editable_target": "select a target whose mask is not locked by an acquisition",
    "decomposition": NEED_HINTS[Need.DECOMPOSITION],
    "acquirable": "open a rig first (Rig ▸ Calibrate Rig…)",
    "rig": "no rig is open",
    "last_rig": "a rig is open, or none was opened before",
}

ACTIONS: tuple[ActionSpec, ...] = (
    ActionSpec("open", "&Open Session…", "on_open_session", K.Open, "Open a session folder"),
    ActionSpec("open_image", "Open &Image…", "on_open_image", "Ctrl+Shift+O",
               "Open a photograph (EXR, TIFF, PNG, JPEG, camera RAW) to paint targets on"),
    ActionSpec("demo", "Virtual Rig &Demo", "open_demo", None, "Open the virtual Cornell box, calibrated and acquired"),
    ActionSpec("save", "&Save", "save", K.Save, "Save the edit into the session", "document"),
    ActionSpec("save_as", "Save &As…", "save_as", K.SaveAs, "Save into a new session folder", "document"),
    ActionSpec("export", "&Export Recolored Image…", "on_export", "Ctrl+E",
               "Write the full-resolution recolored image (EXR, TIFF, PNG)", "decomposition"),
    ActionSpec("quit", "&Quit", "close", K.Quit, "", "always"),
    ActionSpec("undo", "&Undo", "", K.Undo, "Undo the last edit", "always"),
    ActionSpec("redo", "&Redo", "", (K.Redo, "Ctrl+Shift+Z"), "Redo the edit undone last", "always"),
    ActionSpec("add_target", "&Add Target", "on_add_target", "Ctrl+T", "A new, empty target", "document"),
    ActionSpec("delete_target", "&Delete Target", "on_delete_target", None, "Delete the selected target",
               "editable_target"),
    ActionSpec("clear_mask", "&Clear Mask", "on_clear_mask", "Ctrl+Backspace", "Erase the selected target's mask",
               "editable_target"),
    ActionSpec("invert_mask", "&Invert Mask", "on_invert_mask", "Ctrl+I", "Invert the selected target's mask",
               "editable_target"),
    ActionSpec("refine_edge", "&Refine Edge", "on_refine_edge", "Ctrl+R",
               "Give the selected target's edge pixels the fraction of them on the target, from the photograph",
               "editable_target"),
    ActionSpec("overlays", "Show &Overlays", "on_overlays", "O", "Target outlines and unreachable-pixel hatching",
               "document", checkable=True, checked=True),
    ActionSpec("brush_larger", "Larger Brush", "on_brush_larger", "]", "Brush diameter × 1.25", "document"),
    ActionSpec("brush_smaller", "Smaller Brush", "on_brush_smaller", "[", "Brush diameter ÷ 1.25", "document"),
    ActionSpec("noise_aware", "Noise-&Aware Recolor", "on_noise_aware", None,
               "Recolor trusting each interaction component only as far as its measured noise allows "
               "(preview and export); off: the plain κ-weighted sum", "decomposition", checkable=True, checked=True),
    ActionSpec("fit", "&Fit", "on_fit", "Ctrl+0", "The whole image in the window", "document"),
    ActionSpec("zoom_100", "&100 %", "on_zoom_100", "Ctrl+1", "One camera pixel per screen pixel", "document"),
    ActionSpec("zoom_in", "Zoom &In", "on_zoom_in", (K.ZoomIn, "Ctrl+="), "", "document"),  # = is + unshifted
    ActionSpec("zoom_out", "Zoom &Out", "on_zoom_out", K.ZoomOut, "", "document"),
    ActionSpec("calibrate", "&Calibrate Rig…", "calibrate", None,
               "Calibrate a camera–projector rig (the open one, or one the wizard opens) for this document"),
    ActionSpec("acquire", "&Acquire…", "acquire", None,
               "Measure the included targets on the rig, in cascade order", "acquirable"),
    ActionSpec("discard", "&Discard Acquisition", "on_discard", None,
               "Forget the measured decomposition: every κ and mask becomes editable", "decomposition"),
    ActionSpec("reopen_rig", "&Reopen Last Rig", "reopen_rig", None, "Open the rig used last, with its options",
               "last_rig"),
    ActionSpec("close_rig", "Close &Rig", "close_rig", None, "Release the camera and projector", "rig"),
    ActionSpec("about", "&About Albedit", "on_about", None, "", "always"),
)

#: Tool actions: ``tool_<name>`` with its key.
TOOL_KEYS = {Tool.BRUSH: "B", Tool.ERASER: "E", Tool.POLYGON: "P", Tool.LASSO: "L", Tool.FILL: "F"}
TOOL_TIPS = {
    Tool.BRUSH: "Brush (B): paint the selected target; Alt or the right button erases",
    Tool.ERASER: "Eraser (E)",
    Tool.POLYGON: "Polygon (P): click vertices; double-click, Enter or the first vertex closes it",
    Tool.LASSO: "Lasso (L): drag around an area",
    Tool.FILL: "Fill by similar colour (F; tolerance in the toolbar); Alt subtracts",
}

#: Menus: (objectName, title, entries); "-" separates, "@recent", "@tools", "@views" are filled in.
MENUS: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("menu_file", "&File", ("open", "open_image", "demo", "@recent", "-", "save", "save_as", "export", "-", "quit")),
    ("menu_edit", "&Edit", ("undo", "redo")),
    ("menu_targets", "&Targets", ("add_target", "delete_target", "-", "@tools", "-", "brush_larger", "brush_smaller",
                                  "clear_mask", "invert_mask", "refine_edge", "overlays")),
    ("menu_view", "&View", ("@views", "-", "noise_aware", "-", "fit", "zoom_100", "zoom_in", "zoom_out")),
    ("menu_rig", "&Rig", ("calibrate", "acquire", "discard", "-", "reopen_rig", "close_rig")),
    ("menu_help", "&Help", ("about",)),
)

#: Toolbars: (objectName, title, entries); "#name" entries are the window's widgets.
TOOLBARS: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("tools", "Tools", ("@tools", "-", "#brush_size", "#brush_hardness", "#fill_tolerance", "-", "clear_mask",
                        "invert_mask", "refine_edge")),
    ("view", "View", ("@views", "-", "#display_exposure", "fit", "zoom_100")),
)


def key_sequences(shortcut) -> list[QKeySequence]:
    """The key sequences of an :class:`ActionSpec` shortcut (standard keys expand per platform)."""
    if shortcut is None:
        return []
    out: list[QKeySequence] = []
    for s in shortcut if isinstance(shortcut, tuple) else (shortcut,):
        seqs = QKeySequence.keyBindings(s) if isinstance(s, QKeySequence.StandardKey) else [QKeySequence(s)]
        out += [q for q in seqs if q not in out]
    return out


class KeepAppShortcuts(QObject):
    """Event filter: Ctrl shortcuts of ``window``'s actions win over a focused spin box or line edit.

    A focused text field claims Ctrl+Z (its own text undo) and Ctrl+E (end of line) before the
    window sees them, so after typing a κ the app's Undo and Export stopped working. Copy,
    cut, paste and select-all stay with the field; plain keys (digits are view shortcuts) too.
    """

    _TEXT_KEYS = (K.Copy, K.Cut, K.Paste, K.SelectAll)

    def __init__(self, window):
        super().__init__(window)
        self.window = window
        self._text = {q for k in self._TEXT_KEYS for q in QKeySequence.keyBindings(k)}

    def eventFilter(self, obj, event) -> bool:  # noqa: N802 (Qt name)
        if event.type() != QEvent.Type.ShortcutOverride:
            return False
        focus = QApplication.focusWidget()
        if not isinstance(focus, (QAbstractSpinBox, QLineEdit)) or not self.window.isAncestorOf(focus):
            return False
        if not event.modifiers() & (event.modifiers().ControlModifier | event.modifiers().MetaModifier):
            return False
        seq = QKeySequence(event.keyCombination())
        if seq in self._text:
            return False
        for action in self.window.actions():
            if action.isEnabled() and seq in action.shortcuts():
                event.ignore()
                return True  # not accepted by the field: the shortcut goes to the window's action
        return False

def install(window) -> None:
    """Make ``window``'s actions (as ``act_<name>``, tools, views), toolbars (with their spin boxes) and menus."""
    _install_actions(window)
    _install_toolbars(window)
    _install_menus(window)


def _add_action(window, name: str, text: str, slot, shortcut=None, tip: str = "", *, checkable=False) -> QAction:
    a = QAction(text, window, objectName=name)
    a.setShortcuts(key_sequences(shortcut))
    a.setCheckable(checkable)
    if tip:
        a.setStatusTip(tip)
        a.setToolTip(tip)
    if slot is not None:
        a.triggered.connect(slot)
    window.addAction(a)
    return a

def _install_actions(window) -> None:
    window.when: dict[str, str] = {}
    for spec in ACTIONS:
        if spec.name in ("undo", "redo"):  # QUndoGroup's: their text names the step ("Undo Paint 'wall'")
            a = (window.undo_group.createUndoAction if spec.name == "undo" else window.undo_group.createRedoAction)(
                window, spec.text)
            a.setObjectName(spec.name)
            a.setShortcuts(key_sequences(spec.shortcut))
            window.addAction(a)
        else:
            target = getattr(window.rigs, spec.slot, None) or getattr(window.files, spec.slot, None) or \
                getattr(window, spec.slot)
            slot = target if spec.checkable else (lambda _c=False, f=target: f())
            a = _add_action(window, spec.name, spec.text, slot, spec.shortcut, spec.tip, checkable=spec.checkable)
            a.setChecked(spec.checked)
        window.when[spec.name] = spec.when
        setattr(window, f"act_{spec.name}", a)
    window.tool_group = QActionGroup(window)
    window.tool_actions: dict[Tool, QAction] = {}
    for tool, key in TOOL_KEYS.items():
        a = _add_action(window, f"tool_{tool.value}", tool.value.capitalize(),
                             lambda _c=False, t=tool: window.set_tool(t), key, TOOL_TIPS[tool], checkable=True)
        window.tool_group.addAction(a)
        window.tool_actions[tool] = a
    window.tool_actions[Tool.BRUSH].setChecked(True)
    window.view_group = QActionGroup(window)
    window.view_actions: dict[CanvasView, QAction] = {}
    for spec in VIEWS:
        a = _add_action(window, f"view_{spec.view.value}", spec.label, lambda _c=False, v=spec.view: window.set_view(v),
                             spec.shortcut, f"{spec.label.replace('&', '')} ({spec.shortcut}): {spec.tip}",
                             checkable=True)
        a.setIconText(spec.short)
        window.view_group.addAction(a)
        window.view_actions[spec.view] = a
    window.view_actions[CanvasView.RECOLORED].setChecked(True)

def _entries(window, entries):
    """Resolve a menu or toolbar layout: actions, "-" separators, "@" groups, "#" widgets."""
    groups = {"@tools": list(window.tool_actions.values()), "@views": list(window.view_actions.values())}
    for e in entries:
        if e in groups:
            yield from groups[e]
        else:
            yield window._toolbar_widgets[e[1:]] if e.startswith("#") else e if e in ("-", "@recent") else \
                getattr(window, f"act_{e}")

def _install_menus(window) -> None:
    for name, title, entries in MENUS:
        menu = window.menuBar().addMenu(title)
        menu.setObjectName(name)
        menu.setToolTipsVisible(True)  # a disabled entry's tooltip says why (:data:`CONDITIONS`)
        for e in _entries(window, entries):
            if e == "-":
                menu.addSeparator()
            elif e == "@recent":
                window.recent_menu = menu.addMenu("Open &Recent")
                window.recent_menu.setObjectName("menu_recent")
                window.recent_menu.aboutToShow.connect(window.files.fill_recent)
            else:
                menu.addAction(e)

def _install_toolbars(window) -> None:
    window.size_spin = QSpinBox(objectName="brush_size")
    window.size_spin.setRange(int(Painter.MIN_SIZE), int(Painter.MAX_SIZE))
    window.size_spin.setPrefix("Size ")
    window.size_spin.setSuffix(" px")
    window.size_spin.setToolTip("Brush diameter in camera pixels ([ and ] change it)")
    window.size_spin.valueChanged.connect(lambda v: window.painter and window.painter.set_size(v))
    window.hardness_spin = QSpinBox(objectName="brush_hardness")
    window.hardness_spin.setRange(0, 100)
    window.hardness_spin.setValue(100)
    window.hardness_spin.setPrefix("Hardness ")
    window.hardness_spin.setSuffix(" %")
    window.hardness_spin.setToolTip("Brush hardness: the part of the radius painted fully; below 100 % the rest is "
                                    "feathered (partial coverage: a soft edge)")
    window.hardness_spin.valueChanged.connect(lambda v: window.painter and window.painter.set_hardness(v / 100))
    window.tol_spin = QDoubleSpinBox(objectName="fill_tolerance")
    window.tol_spin.setRange(0.005, 2.0)
    window.tol_spin.setSingleStep(0.01)
    window.tol_spin.setDecimals(3)
    window.tol_spin.setValue(0.1)
    window.tol_spin.setPrefix("Tolerance ")
    window.tol_spin.setToolTip("Fill tolerance: largest |log colour difference| between neighbouring pixels "
                               "(0.1 ≈ ±10 %): the fill follows shading and stops at an edge")
    window.tol_spin.valueChanged.connect(lambda v: window.painter and setattr(window.painter, "tolerance", float(v)))
    window.exposure_spin = QDoubleSpinBox(objectName="display_exposure")
    window.exposure_spin.setRange(-12.0, 12.0)
    window.exposure_spin.setSingleStep(0.25)
    window.exposure_spin.setPrefix("Exposure ")
    window.exposure_spin.setSuffix(" EV")
    window.exposure_spin.setToolTip("Display exposure in stops (does not change the data)")
    window.exposure_spin.valueChanged.connect(lambda v: window.preview and window.preview.set_exposure(v))
    window._toolbar_widgets = {"brush_size": window.size_spin, "brush_hardness": window.hardness_spin,
                               "fill_tolerance": window.tol_spin,
                             "display_exposure": window.exposure_spin}
    for name, title, entries in TOOLBARS:
        tb = window.addToolBar(title)
        tb.setObjectName(name)
        for e in _entries(window, entries):
            if e == "-":
                tb.addSeparator()
            elif isinstance(e, QWidget):
                tb.addWidget(e)
            else:
                tb.addAction(e)
                tb.widgetForAction(e).setObjectName(f"{e.objectName()}_button")


def wrap_toolbars(window) -> None:
    """Start a new row of the window's top toolbars where the next one would not fit beside those before it.

    Qt keeps a row of toolbars on one line and hides what does not fit behind a » button (on a
    1366 px laptop: the View toolbar's Noise σ, exposure and zoom); this wraps them instead, and
    joins the rows again when the window is wide enough. Called on every resize.
    """
    used = 0
    for name, _title, _entries in TOOLBARS:
        tb = window.findChild(QToolBar, name)
        if tb is None or tb.isHidden() or window.toolBarArea(tb) != Qt.ToolBarArea.TopToolBarArea:
            continue
        need = tb.sizeHint().width()
        wrap = used > 0 and used + need > window.width()
        if wrap != window.toolBarBreak(tb):
            (window.insertToolBarBreak if wrap else window.removeToolBarBreak)(tb)
        used = need if wrap else used + need
