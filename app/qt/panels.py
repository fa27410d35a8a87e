"""Side panels: the target list (cascade order) and the albedo controls of the current target.

Widgets only bind model ↔ control (napari's layer-controls pattern): a control writes the
:class:`~app.model.document.Document`; the document's signal updates the control inside a signal
blocker; nothing else.
"""

from __future__ import annotations

import html
import math

import numpy as np
from PySide6.QtCore import QSignalBlocker, Qt, QTimer, Signal
from PySide6.QtGui import QColor, QIcon, QPixmap
from PySide6.QtWidgets import (
    QAbstractItemView,
    QCheckBox,
    QDoubleSpinBox,
    QGridLayout,
    QHBoxLayout,
    QLabel,
    QListWidget,
    QListWidgetItem,
    QMessageBox,
    QPushButton,
    QSlider,
    QSpinBox,
    QToolButton,
    QVBoxLayout,
    QWidget,
)

from app.model.colour import linked_kappa
from app.model.document import Document
from app.model.noise import denoise_radius
from app.model.target import KAPPA_MAX, KAPPA_MIN
from engine.errors import InputError

#: Slider ticks per doubling of κ (the slider is logarithmic).
TICKS_PER_STOP = 100
#: The κ boxes take values up to this, so one typed beyond a target's range reaches the panel and is
#: answered with the range (a spin box's own maximum silently drops the keystroke: "40" became 4).
TYPED_MAX = 999.0


def kappa_to_ticks(kappa: float) -> int:
    """Slider position of κ on the log scale (1 → 0, 2 → 100, 1/16 → -400).

    Examples
    --------
    >>> kappa_to_ticks(2.0), kappa_to_ticks(1 / 16), kappa_to_ticks(100.0)
    (100, -400, 400)
    """
    k = min(max(float(kappa), KAPPA_MIN), KAPPA_MAX)
    return int(round(math.log2(k) * TICKS_PER_STOP))


def ticks_to_kappa(ticks: int) -> float:
    """κ at a slider position (inverse of :func:`kappa_to_ticks`).

    Examples
    --------
    >>> ticks_to_kappa(-100), ticks_to_kappa(400)
    (0.5, 16.0)
    """
    return float(2.0 ** (ticks / TICKS_PER_STOP))


def coverage_text(target) -> str:
    """One line on a target's coverage (Targets panel).

    Examples
    --------
    >>> from app.model.target import Target
    >>> cov = np.array([[1.0, 0.5, 0.0]], np.float32)
    >>> coverage_text(Target(1, "wall", cov >= 0.5, coverage=cov))
    'Coverage: 1 px wholly target, 1 edge px partly (mean 50 %): soft edge'
    >>> coverage_text(Target(1, "wall", cov >= 0.5))
    'Coverage: 2 px, hard edge (Refine Edge or a feathered brush makes it soft)'
    """
    if target.coverage is None or not target.edge_pixels():
        return f"Coverage: {int(np.count_nonzero(target.mask))} px, hard edge (Refine Edge or a feathered brush " \
            "makes it soft)"
    cov = target.coverage
    part = (cov > 0) & (cov < 1)
    return (f"Coverage: {int(np.count_nonzero(cov >= 1))} px wholly target, {int(part.sum())} edge px partly "
            f"(mean {100 * float(cov[part].mean()):.0f} %): soft edge")


def _swatch(colour, size: int = 14) -> QIcon:
    pm = QPixmap(size, size)
    pm.fill(QColor(*colour))
    return QIcon(pm)


class TargetPanel(QWidget):
    """List of targets in cascade order: add, rename (double click), delete, reorder, include.

    Each row's check box says whether the next acquisition measures that target; the list
    is rebuilt from the document on every change (the view is told about every row: nothing
    is hidden from it by blocked model signals), and edits made while rebuilding are ignored.
    """

    message = Signal(str)

    def __init__(self, document: Document, parent: QWidget | None = None):
        super().__init__(parent)
        self.doc = document
        self._syncing = False
        self.list = QListWidget(objectName="targets_list")
        self.list.setDragDropMode(QAbstractItemView.DragDropMode.InternalMove)
        self.list.setDefaultDropAction(Qt.DropAction.MoveAction)
        triggers = QAbstractItemView.EditTrigger
        self.list.setEditTriggers(triggers.DoubleClicked | triggers.EditKeyPressed)
        self.list.setToolTip("Targets in cascade order (first acquired first). Drag to reorder, double-click to "
                             "rename; the check box includes a target in the next acquisition.")
        self.add_button = QToolButton(text="+", toolTip="Add a target", objectName="target_add")
        self.remove_button = QToolButton(text="−", toolTip="Delete the selected target", objectName="target_remove")
        self.up_button = QToolButton(text="▲", toolTip="Move earlier in the cascade", objectName="target_up")
        self.down_button = QToolButton(text="▼", toolTip="Move later in the cascade", objectName="target_down")
        buttons = QHBoxLayout()
        for b in (self.add_button, self.remove_button, self.up_button, self.down_button):
            buttons.addWidget(b)
        buttons.addStretch(1)
        self.coverage = QLabel(objectName="target_coverage")
        self.coverage.setWordWrap(True)
        self.coverage.setToolTip("How much of the selected target is wholly target (re-emitted by the projector) "
                                 "and how many edge pixels are partly target (recolored from both sides)")
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.list)
        layout.addLayout(buttons)
        layout.addWidget(self.coverage)
        self.caution = QLabel(objectName="target_caution")  # a lamp painted into the selected target
        self.caution.setWordWrap(True)
        self.caution.setStyleSheet("color: #c0392b")
        self.caution.hide()
        layout.addWidget(self.caution)
        self._caution_timer = QTimer(self, singleShot=True, interval=150)  # after the stroke, not at every dab
        self._caution_timer.timeout.connect(self._show_caution)
        self.add_button.clicked.connect(lambda: self._guard(self.doc.add_target))
        self.remove_button.clicked.connect(self._remove)
        self.up_button.clicked.connect(lambda: self._move(-1))
        self.down_button.clicked.connect(lambda: self._move(+1))
        self.list.currentItemChanged.connect(self._on_selected)
        self.list.itemChanged.connect(self._on_item_changed)
        self.list.model().rowsMoved.connect(self._on_rows_moved)
        document.events.targets.connect(self.refresh)
        document.events.current.connect(self._on_current)
        document.events.acquisition.connect(self.refresh)
        document.events.mask.connect(self._on_mask)
        self.refresh()

    def refresh(self) -> None:
        """Rebuild the list from the document."""
        self._syncing = True
        try:
            self.list.clear()
            for i, t in enumerate(self.doc.targets):
                item = QListWidgetItem(_swatch(t.colour), t.name)
                item.setData(Qt.ItemDataRole.UserRole, t.uid)
                flags = item.flags() | Qt.ItemFlag.ItemIsEditable | Qt.ItemFlag.ItemIsDragEnabled
                item.setFlags((flags | Qt.ItemFlag.ItemIsUserCheckable) & ~Qt.ItemFlag.ItemIsDropEnabled)
                item.setCheckState(Qt.CheckState.Checked if t.included else Qt.CheckState.Unchecked)
                lock = self.doc.mask_lock(t.uid)
                tip = f"cascade position {i + 1}; " + ("included in" if t.included else "left out of") + \
                    " the next acquisition (check box)"
                item.setToolTip(tip + (f"\n{lock}" if lock else ""))
                if lock:  # acquired: shown in italics (the name itself stays editable)
                    font = item.font()
                    font.setItalic(True)
                    item.setFont(font)
                self.list.addItem(item)
                if t.uid == self.doc.current:
                    self.list.setCurrentItem(item)
        finally:
            self._syncing = False
        self._update_buttons()

    def _on_mask(self, uid: int, _bbox) -> None:
        if uid == self.doc.current:
            self._show_coverage()

    def _show_coverage(self) -> None:
        """The selected target's coverage: pixels wholly on it, and edge pixels partly on it."""
        uid = self.doc.current
        self._caution_timer.start()
        if uid == -1:
            self.coverage.setText("")
            return
        self.coverage.setText(coverage_text(self.doc.target(uid)))

    def _show_caution(self) -> None:
        """Whether the selected target holds a lamp or a highlight (its own light, which κ cannot recolor)."""
        uid = self.doc.current
        lines = [] if uid == -1 else self.doc.lamp_cautions([uid])
        self.caution.setText(lines[0] if lines else "")
        self.caution.setVisible(bool(lines))

    def _uid(self, item) -> int:
        return -1 if item is None else int(item.data(Qt.ItemDataRole.UserRole))

    def _update_buttons(self) -> None:
        self._show_coverage()
        uid = self.doc.current
        has = uid != -1
        self.remove_button.setEnabled(has and not self.doc.mask_lock(uid))
        movable = has and self.doc.acquisition is None
        i = self.doc.index(uid) if has else -1
        self.up_button.setEnabled(movable and i > 0)
        self.down_button.setEnabled(movable and 0 <= i < len(self.doc.targets) - 1)

    def _guard(self, fn, *args) -> None:
        try:
            fn(*args)
        except InputError as exc:
            self.message.emit(str(exc))
            self.refresh()

    def _remove(self) -> None:
        uid = self.doc.current
        if uid == -1:
            return
        self._guard(self.doc.remove_target, uid)

    def _move(self, step: int) -> None:
        uid = self.doc.current
        if uid != -1:
            self._guard(self.doc.move_target, uid, self.doc.index(uid) + step)

    def _on_selected(self, item, _previous) -> None:
        if not self._syncing:
            self.doc.set_current(self._uid(item))

    def _on_current(self, uid: int) -> None:
        self._syncing = True
        try:
            for row in range(self.list.count()):
                if self._uid(self.list.item(row)) == uid:
                    self.list.setCurrentRow(row)
        finally:
            self._syncing = False
        self._update_buttons()

    def _on_item_changed(self, item) -> None:
        uid = self._uid(item)
        if self._syncing or uid == -1:
            return
        t = self.doc.target(uid)
        included = item.checkState() == Qt.CheckState.Checked
        if included != t.included:
            self._guard(self.doc.set_included, uid, included)
        elif item.text() != t.name:
            self._guard(self.doc.rename_target, uid, item.text())

    def _on_rows_moved(self, *_args) -> None:
        if self._syncing:
            return
        order = [self._uid(self.list.item(r)) for r in range(self.list.count())]
        for index, uid in enumerate(order):
            if self.doc.index(uid) != index:
                self._guard(self.doc.move_target, uid, index)
                break
        QTimer.singleShot(0, self.refresh)  # not inside the view's own drop handling


class AlbedoPanel(QWidget):
    """κ of the current target: R, G, B log sliders with numeric entry, link toggle, reset.

    A slider drag is one undo step (begin/end gesture); typing a value is one step. Linked
    channels scale by one factor, which stops where the first channel reaches the range, so
    the ratios (the hue of the change) are never lost. Earlier cascade targets are locked after
    acquisition, with a tooltip saying why.

    The range is 0 (black, typed) or 1/16 (the slider) up to the target's κ ceiling when its
    colour was measured (``colour``: :class:`~app.qt.colour_panel.ColourPanel`; 1 / albedo with
    a colour checker, else where the interreflection series diverges), else 16; with ``colour``
    every κ is checked against the target's colour facts (an albedo of 1 or more is refused).
    """

    CHANNELS = ("R", "G", "B")

    #: A one-line message for the status bar (a typed κ beyond the range, a κ beyond the slider's end).
    message = Signal(str)

    def __init__(self, document: Document, parent: QWidget | None = None, *, colour=None):
        super().__init__(parent)
        self.doc = document
        self.colour = colour
        self.uid = -1
        self._beyond: tuple = ()  # the channels whose κ is past the slider's end (said once)
        self.high = np.full(3, KAPPA_MAX)  # top of the κ range per channel
        grid = QGridLayout(self)
        grid.setContentsMargins(0, 0, 0, 0)
        self.title = QLabel("No target selected", objectName="albedo_title")
        self.title.setWordWrap(True)
        grid.addWidget(self.title, 0, 0, 1, 3)
        self.sliders: list[QSlider] = []
        self.spins: list[QDoubleSpinBox] = []
        lo, hi = kappa_to_ticks(KAPPA_MIN), kappa_to_ticks(KAPPA_MAX)
        for c, name in enumerate(self.CHANNELS):
            label = QLabel(f"κ {name}")
            slider = QSlider(Qt.Orientation.Horizontal, objectName=f"kappa_{name}")
            slider.setRange(lo, hi)
            slider.setPageStep(TICKS_PER_STOP // 4)
            slider.setTickInterval(TICKS_PER_STOP)
            slider.setTickPosition(QSlider.TickPosition.TicksBelow)
            slider.setMinimumWidth(80)
            spin = QDoubleSpinBox(objectName=f"kappa_{name}_value")
            spin.setRange(0.0, TYPED_MAX)
            spin.setDecimals(4)
            spin.setStepType(QDoubleSpinBox.StepType.AdaptiveDecimalStepType)
            spin.setKeyboardTracking(False)
            grid.addWidget(label, c + 1, 0)
            grid.addWidget(slider, c + 1, 1)
            grid.addWidget(spin, c + 1, 2)
            slider.sliderPressed.connect(self._begin)
            slider.sliderReleased.connect(self._end)
            slider.valueChanged.connect(lambda v, c=c: self._on_slider(c, v))
            spin.valueChanged.connect(lambda v, c=c: self._on_spin(c, v))
            self.sliders.append(slider)
            self.spins.append(spin)
        self.link = QCheckBox("Link channels", objectName="kappa_link")
        self.link.setToolTip("Move R, G and B together (their ratios, i.e. the hue of the change, are kept)")
        self.link.setChecked(True)
        self.reset = QPushButton("Reset", objectName="kappa_reset")
        self.reset.setToolTip("κ = 1: the original albedo")
        self.reset.clicked.connect(self._reset)
        grid.addWidget(self.link, 4, 0, 1, 2, Qt.AlignmentFlag.AlignLeft)  # clicks beside its text do not toggle it
        grid.addWidget(self.reset, 4, 2)
        self.note = QLabel(objectName="albedo_note")
        self.note.setWordWrap(True)
        self.note.setStyleSheet("color: palette(placeholder-text);")
        grid.addWidget(self.note, 5, 0, 1, 3)
        grid.setColumnStretch(1, 1)
        ev = document.events
        ev.current.connect(self._on_current)
        ev.kappa.connect(self._on_kappa)
        ev.targets.connect(lambda: self._on_current(self.doc.current))
        ev.acquisition.connect(lambda: self._on_current(self.doc.current))
        self._on_current(document.current)

    # ------------------------------------------------------------------ model → controls
    def refresh(self) -> None:
        """Show the current target again (its κ range may have changed: a colour checker was measured)."""
        self._on_current(self.doc.current)

    def _on_current(self, uid: int) -> None:
        self.uid = uid
        has = uid != -1
        lock = self.doc.kappa_lock(uid) if has else ""
        for w in (*self.sliders, *self.spins, self.reset, self.link):
            w.setEnabled(has and not lock)
            w.setToolTip(lock) if lock else None
        self._set_range(uid if has and not lock else -1)
        if not lock:
            self.reset.setToolTip("κ = 1: the original albedo")
            for c, s in enumerate((*self.sliders, *self.spins)):
                top = self.high[c % 3]
                s.setToolTip(f"Albedo scale κ of this channel: log slider 1/16 … {top:.3g}, typed 0 (black) … "
                             f"{top:.3g}" + (" (the measured limit)" if top != KAPPA_MAX else ""))
        if not has:
            self.title.setText("No target selected")
            self.note.setText("")
            self._show(np.ones(3))
            return
        t = self.doc.target(uid)
        self.title.setText(f"<b>{html.escape(t.name)}</b>" + (" — locked" if lock else ""))
        self.setToolTip(lock)
        acq = self.doc.acquisition
        if lock:
            self.note.setText(lock)
        elif acq is None:
            self.note.setText("Not acquired yet: the recolored view multiplies this target's pixels by κ (a naive "
                              "recolor); acquire it on a rig for its interreflections to follow.")
        elif uid not in acq.cascade:
            self.note.setText("This target was added after the acquisition: acquire again to recolor it.")
        else:
            self.note.setText("Last target of the cascade: free to edit.")
        self._show(t.kappa)

    def _on_kappa(self, uid: int, kappa) -> None:
        if uid == self.uid:
            self._show(kappa)

    def _set_range(self, uid: int) -> None:
        """The controls' range: up to the target's κ ceiling (just below it: the ceiling itself is refused)."""
        high = None if uid == -1 or self.colour is None else self.colour.kappa_high(uid)
        self.high = np.full(3, KAPPA_MAX) if high is None else np.asarray(high, np.float64) * (1 - 1e-9)
        for c in range(3):
            top = math.floor(math.log2(max(min(self.high[c], KAPPA_MAX), KAPPA_MIN)) * TICKS_PER_STOP)
            with QSignalBlocker(self.sliders[c]), QSignalBlocker(self.spins[c]):
                self.sliders[c].setRange(kappa_to_ticks(KAPPA_MIN), max(top, kappa_to_ticks(KAPPA_MIN)))

    def _show(self, kappa) -> None:
        for c in range(3):
            with QSignalBlocker(self.sliders[c]), QSignalBlocker(self.spins[c]):
                self.sliders[c].setValue(kappa_to_ticks(kappa[c]))
                self.spins[c].setValue(float(kappa[c]))
        ends = [ticks_to_kappa(s.maximum()) for s in self.sliders]
        beyond = tuple(c for c in range(3) if kappa[c] > ends[c] * (1 + 1e-6))
        if beyond and beyond != self._beyond:  # e.g. a colour asked for more than the slider shows
            self.message.emit("; ".join(f"κ {self.CHANNELS[c]} = {kappa[c]:.3g} is past the slider's end "
                                        f"({ends[c]:.3g})" for c in beyond) + ": its box shows it, and takes values "
                              f"up to {min(self.high[beyond[0]], TYPED_MAX):.3g}")
        self._beyond = beyond

    # ------------------------------------------------------------------ controls → model
    def _begin(self) -> None:
        if self.uid != -1:
            self.doc.begin_kappa_gesture(self.uid)

    def _end(self) -> None:
        self.doc.end_kappa_gesture()

    def _on_slider(self, channel: int, ticks: int) -> None:
        self._set(channel, ticks_to_kappa(ticks), low=KAPPA_MIN)

    def _on_spin(self, channel: int, value: float) -> None:
        top = float(self.high[channel])
        if value > top:
            why = "Albedit's range" if top == KAPPA_MAX else "the measured limit"
            self.message.emit(f"κ {self.CHANNELS[channel]} is at most {top:.3g} ({why}): {value:g} was not applied")
            if self.uid != -1:
                self._show(self.doc.target(self.uid).kappa)
            return
        self._set(channel, float(value), low=0.0)

    def _set(self, channel: int, value: float, *, low: float) -> None:
        if self.uid == -1:
            return
        kappa = linked_kappa(self.doc.target(self.uid).kappa, channel, value, linked=self.link.isChecked(), low=low,
                             high=self.high)
        try:
            if self.colour is not None:
                self.colour.apply_kappa(self.uid, kappa)
            else:
                self.doc.set_kappa(self.uid, kappa)
        except InputError as exc:
            QMessageBox.warning(self, "Albedo", str(exc))
        self._show(self.doc.target(self.uid).kappa)  # a linked move may have stopped at a limit

    def _reset(self) -> None:
        if self.uid != -1:
            self.doc.reset_kappa(self.uid)


class NoiseReductionPanel(QWidget):
    """Noise reduction of the acquired decomposition: a radius and Apply.

    Recoloring multiplies the noise of interaction component i by κ^{i+1}; the filter
    (:func:`engine.denoise.denoise_components`) smooths the interreflection components along
    the photograph's edges and leaves κ = 1 unchanged. Applying it is a job of a few seconds
    on large images, so it is asked for (:attr:`apply_requested`), not run on every change.

    Signals
    -------
    apply_requested(int)
        The radius to apply (0: back to the measured decomposition).
    """

    apply_requested = Signal(int)

    def __init__(self, document: Document, parent: QWidget | None = None):
        super().__init__(parent)
        self.doc = document
        self.radius = QSpinBox(objectName="noise_radius")
        self.radius.setRange(0, 32)
        self.radius.setSuffix(" px")
        self.radius.setSpecialValueText("off")
        self.radius.setToolTip("Filter radius: larger removes more noise and blurs interreflections more (0 = off)")
        self.apply = QPushButton("Apply", objectName="noise_apply")
        self.apply.setToolTip("Smooth the interreflection components along the photograph's edges; "
                              "κ = 1 still gives the photograph exactly")
        self.apply.clicked.connect(lambda: self.apply_requested.emit(self.radius.value()))
        self.state = QLabel(objectName="noise_state")
        self.state.setWordWrap(True)
        self.state.setStyleSheet("color: palette(placeholder-text);")
        row = QHBoxLayout()
        row.addWidget(QLabel("Noise reduction"))
        row.addWidget(self.radius, 1)
        row.addWidget(self.apply)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addLayout(row)
        lay.addWidget(self.state)
        self._judged = None
        self._suggested, self._noise = 0, 0.0
        document.events.acquisition.connect(self._update)
        self._update()

    def _update(self) -> None:
        acq = self.doc.acquisition
        for w in (self.radius, self.apply):
            w.setEnabled(acq is not None)
        if acq is None:
            self.state.setText("Acquire a target first: noise reduction filters its decomposition.")
            return
        if acq.raw is not self._judged:  # a new measurement: suggest the radius its noise calls for
            self._judged = acq.raw
            self._suggested, self._noise = denoise_radius(acq.raw)
            with QSignalBlocker(self.radius):
                self.radius.setValue(acq.denoise or self._suggested)
        if math.isnan(self._noise):
            suggestion = ("Its noise cannot be measured (fewer than 16 target pixels inside its edge, or order 1): "
                          "no radius is suggested.")
        else:
            suggestion = (f"Its noise is {100 * self._noise:.2g} % of the interreflections: "
                          + (f"radius {self._suggested} px is suggested." if self._suggested else "no need to filter."))
        if acq.denoise:
            self.state.setText(f"Applied: radius {acq.denoise} px (saved with the edit; export uses it). {suggestion}")
        else:
            self.state.setText(f"Off: the decomposition as measured. {suggestion}")
