"""The Albedo dock's colour controls: the target's colour, colour requests, absolute albedo.

The artist sees the current target's colour (a swatch of its direct light ``R^0 L_d``,
white-balanced) and asks for another one: the colour dialog, a typed colour (hex, sRGB, Lab or
linear), an absolute albedo (once a colour checker measured the session), the eyedropper on the
photograph (another measured target: its albedo; elsewhere: the colour seen there) or on a
reference picture opened beside the canvas. Every request becomes κ through
:class:`app.model.colour.ColourEditor` — the same κ as ``albedit recolor`` — as one undo step.
Requests physics refuses (an albedo of 1 or more) change nothing and say why; recolors the
captured order cannot follow are applied with a warning.

The controls bind model ↔ control as :class:`~app.qt.panels.AlbedoPanel` does: they write the
document through the editor, and the document's events update them.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from PySide6.QtCore import QPointF, Qt, Signal
from PySide6.QtGui import QColor, QImage, QMouseEvent, QPainter, QPaintEvent
from PySide6.QtWidgets import (
    QCheckBox,
    QColorDialog,
    QFileDialog,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QMessageBox,
    QPushButton,
    QToolButton,
    QVBoxLayout,
    QWidget,
)

from app.model.colour import ColourEditor, session_colours
from app.model.document import Document
from engine.colour import to_hex, to_lab
from engine.errors import InputError, SessionError

#: Reference pictures the eyedropper reads (8-bit sRGB: what a colour from elsewhere is).
REFERENCE_FILTER = "Pictures (*.png *.jpg *.jpeg *.tif *.tiff *.bmp)"


def _srgb_words(image: QImage) -> np.ndarray:
    """(H, W, 3) sRGB-encoded 0–1 values of a QImage."""
    rgb = image.convertToFormat(QImage.Format.Format_RGB888)
    h, w, stride = rgb.height(), rgb.width(), rgb.bytesPerLine()
    raw = np.frombuffer(rgb.constBits(), np.uint8, count=stride * h).reshape(h, stride)
    return raw[:, : 3 * w].reshape(h, w, 3).astype(np.float32) / 255.0


class ReferenceView(QWidget):
    """A picture from elsewhere, scaled to fit; a click emits the picture pixel ``(x, y)`` picked.

    Signals
    -------
    picked(float, float)
    """

    picked = Signal(float, float)

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent, objectName="colour_reference_view")
        self.image: QImage | None = None
        self.pixels: np.ndarray | None = None  # (H, W, 3) sRGB-encoded 0–1
        self.setMinimumSize(160, 120)
        self.setCursor(Qt.CursorShape.CrossCursor)
        self.setToolTip("Click a colour: the target takes it")

    def set_image(self, image: QImage) -> None:
        """Show ``image`` (any format Qt reads; its pixels are taken as sRGB-encoded)."""
        self.image = image
        self.pixels = _srgb_words(image)
        self.update()

    def placed(self) -> tuple[float, float, float]:
        """``(scale, x0, y0)``: where the picture is drawn (aspect kept, centred)."""
        if self.image is None:
            return 1.0, 0.0, 0.0
        scale = min(self.width() / self.image.width(), self.height() / self.image.height())
        return scale, (self.width() - scale * self.image.width()) / 2, (self.height() - scale * self.image.height()) / 2

    def to_widget(self, x: float, y: float) -> QPointF:
        """Widget position of picture pixel coordinates ``(x, y)``."""
        scale, x0, y0 = self.placed()
        return QPointF(x0 + scale * x, y0 + scale * y)

    def paintEvent(self, event: QPaintEvent) -> None:  # noqa: N802 - Qt override
        p = QPainter(self)
        p.fillRect(self.rect(), self.palette().window())
        if self.image is not None:
            scale, x0, y0 = self.placed()
            p.drawImage(QPointF(x0, y0), self.image.scaled(max(1, round(scale * self.image.width())),
                                                            max(1, round(scale * self.image.height())),
                                                            Qt.AspectRatioMode.IgnoreAspectRatio,
                                                            Qt.TransformationMode.SmoothTransformation))
        p.end()

    def mousePressEvent(self, e: QMouseEvent) -> None:  # noqa: N802 - Qt override
        if self.image is None or e.button() != Qt.MouseButton.LeftButton:
            return
        scale, x0, y0 = self.placed()
        x, y = (e.position().x() - x0) / scale, (e.position().y() - y0) / scale
        if 0 <= x < self.image.width() and 0 <= y < self.image.height():
            self.picked.emit(x, y)


class ColourPanel(QWidget):
    """The current target's colour and the ways to ask for another.

    Parameters
    ----------
    document : Document
    session : callable
        Returns the document's session now (or None); its colour facts (each target's D, the
        colour checker's fit) are read when the acquisition or the checker changes.
    exposure : callable
        Returns the display exposure in stops: the swatch shows the colour as the canvas does,
        and a chosen colour means what the canvas will show.

    Signals
    -------
    picking(bool)
        The eyedropper is on (the canvas picks instead of painting) or off.
    checker_requested()
        Measure a colour checker on the rig (the window runs it as a job).
    reference_requested()
        Open a reference picture beside the canvas.
    message(str)
        One line for the status bar.
    """

    picking = Signal(bool)
    checker_requested = Signal()
    reference_requested = Signal()
    message = Signal(str)

    def __init__(self, document: Document, session: Callable, exposure: Callable[[], float],
                 parent: QWidget | None = None):
        super().__init__(parent)
        self.doc = document
        self._session = session
        self._exposure = exposure
        self.editor = ColourEditor(document, {})
        self._known: tuple | None = None  # what the editor's colours were read for
        self._read_error = ""
        self.uid = -1
        self.can_measure = False
        self._typed_for: tuple | None = None  # (target uid, κ) the typed boxes' request gave
        self._requesting = False

        self.swatch = QLabel(objectName="colour_swatch")
        self.swatch.setFixedSize(56, 28)
        self.swatch.setAutoFillBackground(True)
        self.value = QLabel(objectName="colour_value")
        self.value.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.choose = QPushButton("Colour…", objectName="colour_choose")
        self.choose.setToolTip("Choose the target's new colour: κ follows per channel")
        self.entry = QLineEdit(objectName="colour_entry")
        self.entry.setPlaceholderText("#3355cc, srgb:0.2,0.33,0.8, lab:50,10,-40 or linear R,G,B")
        self.entry.setToolTip("Type a colour and press Enter: hex or srgb: (sRGB as shown), lab: (CIE L*a*b*), "
                              "or linear R,G,B (the photograph's units)")
        self.keep_luminance = QCheckBox("Keep luminance", objectName="colour_keep_luminance")
        self.keep_luminance.setToolTip("Change hue and chroma only: the target stays as bright as in the photograph")
        self.eyedropper = QToolButton(text="Eyedropper", objectName="colour_eyedropper", checkable=True)
        self.eyedropper.setToolTip("Click another surface on the canvas: the target takes its colour (a measured "
                                   "target: its albedo; elsewhere: the colour the photograph shows there)")
        self.reference = QToolButton(text="Reference…", objectName="colour_reference")
        self.reference.setToolTip("Open a picture from elsewhere beside the canvas and pick a colour in it")
        self.albedo = QLabel(objectName="colour_albedo")
        self.albedo.setWordWrap(True)
        self.albedo.setTextFormat(Qt.TextFormat.PlainText)  # engine messages: never read as HTML
        self.albedo_entry = QLineEdit(objectName="colour_albedo_entry")
        self.albedo_entry.setPlaceholderText("albedo R,G,B")
        self.checker = QPushButton("Checker", objectName="colour_checker")
        self.warning = QLabel(objectName="colour_warning")
        self.warning.setWordWrap(True)
        self.warning.setTextFormat(Qt.TextFormat.PlainText)

        top = QHBoxLayout()
        top.addWidget(self.swatch)
        top.addWidget(self.value, 1)
        typed = QHBoxLayout()
        typed.addWidget(self.entry, 1)
        typed.addWidget(self.choose)
        picks = QHBoxLayout()
        picks.addWidget(self.eyedropper)
        picks.addWidget(self.reference)
        picks.addStretch(1)
        albedo = QHBoxLayout()
        albedo.addWidget(self.albedo_entry, 1)
        albedo.addWidget(self.checker)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(QLabel("<b>Colour</b>"))
        lay.addLayout(top)
        lay.addLayout(typed)
        lay.addLayout(picks)
        lay.addWidget(self.keep_luminance, 0, Qt.AlignmentFlag.AlignLeft)
        lay.addWidget(self.albedo)
        lay.addLayout(albedo)
        lay.addWidget(self.warning)

        self.choose.clicked.connect(self._choose)
        self.entry.returnPressed.connect(lambda: self._request(self.editor.request_colour, self.entry.text(),
                                                               box=self.entry, exposure=self._exposure()))
        self.albedo_entry.returnPressed.connect(self._typed_albedo)
        self.keep_luminance.toggled.connect(self._keep_luminance)
        self.eyedropper.toggled.connect(self.picking)
        self.reference.clicked.connect(self.reference_requested)
        self.checker.clicked.connect(self.checker_requested)
        ev = document.events
        ev.current.connect(lambda _uid: self.refresh())
        ev.kappa.connect(lambda uid, _k: self.refresh() if uid == self.uid else None)
        ev.targets.connect(self.refresh)
        ev.acquisition.connect(self.refresh)
        self.refresh()

    # ------------------------------------------------------------------ what is known
    def colours_changed(self) -> None:
        """Read the colour facts again (the session's checker or D changed)."""
        self._known = None
        self.refresh()

    def _read_colours(self) -> str:
        """Bring the editor's colours up to date; returns why they cannot be read ("" when they can)."""
        acq = self.doc.acquisition
        session = self._session()
        checker = None if session is None else repr(session.state.get("colour"))
        key = (None if acq is None else id(acq.raw), None if acq is None else acq.cascade, id(session), checker)
        if key == self._known:
            return self._read_error
        self._known, self._read_error = key, ""
        try:
            self.editor.colours = session_colours(self.doc, session)
        except (InputError, SessionError, OSError) as exc:
            self.editor.colours = {}
            self._read_error = f"The session's colour facts cannot be read: {exc}"
        return self._read_error

    def kappa_high(self, uid: int) -> np.ndarray | None:
        """Per-channel top of the κ range of target ``uid`` (None: nothing measured bounds it)."""
        self._read_colours()
        try:
            return self.editor.kappa_range(uid)[1]
        except InputError:
            return None

    def apply_kappa(self, uid: int, kappa) -> None:
        """κ from the κ controls: checked against the target's colour facts when it has them.

        Raises
        ------
        InputError
            Impossible (an albedo of 1 or more) or locked: nothing changed.
        """
        self._read_colours()
        try:
            self.editor.colour(uid)
        except InputError:  # no colour facts (not the free acquired target): κ as typed
            self.doc.set_kappa(uid, kappa)
            return
        self._show_outcome(self.editor.set_kappa(uid, kappa))

    # ------------------------------------------------------------------ model → controls
    def refresh(self) -> None:
        """Show the current target's colour, albedo and what can be asked (or why nothing can).

        A typed colour or albedo stays in its box only while it is what the target shows: another target, or
        its κ moved by other means, empties the boxes (they held the last request, read as the target's)."""
        uid = self.doc.current
        kappa = None if uid == -1 else tuple(self.doc.target(uid).kappa)
        if not self._requesting and (uid, kappa) != self._typed_for:
            for box in (self.entry, self.albedo_entry):
                box.clear()
        self.uid = uid
        reason = self._read_colours()
        known = ""
        if uid == -1:
            known = "No target selected."
        elif lock := self.doc.kappa_lock(uid):
            known = lock
        else:
            try:
                self.editor.colour(uid).current  # noqa: B018 - measured from the target's D: may be refused
            except InputError as exc:
                known = reason or str(exc)
        for w in (self.choose, self.entry, self.keep_luminance, self.eyedropper, self.reference):
            w.setEnabled(not known)
        self.checker.setEnabled(self.can_measure)
        self.checker.setToolTip("Measure a ColorChecker Classic in the scene on the open rig: absolute albedo"
                                if self.can_measure else "Needs the session's rig open (Rig ▸ Reopen or Calibrate) to "
                                "measure a ColorChecker Classic in the scene")
        if known:
            self.eyedropper.setChecked(False)
            self._set_swatch(None)
            self.value.setText("")
            self.albedo.setText(known)
            self.albedo_entry.setEnabled(False)
            self.albedo_entry.setToolTip("")
            return
        c = self.editor.colour(uid)
        linear = c.colour(self.doc.target(uid).kappa) * 2.0 ** self._exposure()
        hexa = to_hex(linear)
        self._set_swatch(hexa)
        lab = to_lab(linear)
        self.value.setText(f"{hexa}  L*a*b* {lab[0]:.0f}, {lab[1]:.0f}, {lab[2]:.0f}")
        self.value.setToolTip(f"The target's direct colour with its κ now (linear R, G, B "
                              f"{', '.join(f'{v:.4g}' for v in linear)}), white-balanced, at the display exposure")
        self.albedo.setText(self.editor.albedo_text(uid))
        absolute = c.albedo is not None
        self.albedo_entry.setEnabled(absolute)
        self.albedo_entry.setToolTip("Type the absolute albedo wanted (e.g. a paint maker's data), below 1" if absolute
                                     else c.relative)

    def _set_swatch(self, hexa: str | None) -> None:
        colour = QColor(hexa) if hexa else self.palette().window().color()
        self.swatch.setStyleSheet(f"background: {colour.name()}; border: 1px solid palette(mid);")
        self.swatch.setToolTip(hexa or "")

    def _show_outcome(self, warning: str, *, error: bool = False) -> None:
        self.warning.setStyleSheet("color: #c03030;" if error else "color: #a06000;" if warning else "")
        self.warning.setText(warning)
        if warning:
            self.message.emit(warning)

    # ------------------------------------------------------------------ controls → model
    def _request(self, fn, *args, box: QLineEdit | None = None, **kwargs) -> bool:
        """Run a colour request on the current target; a refusal changes nothing and says why. ``box``: the
        typed box it came from, which keeps its text (the other box, and both for a pick or the dialog, empty)."""
        if self.uid == -1:
            return False
        for other in (self.entry, self.albedo_entry):
            if other is not box:
                other.clear()
        self._typed_for = (self.uid, tuple(self.doc.target(self.uid).kappa))  # a refusal keeps the text to mend
        self._requesting = True
        try:
            warning = fn(self.uid, *args, **kwargs)
        except InputError as exc:
            self._show_outcome(str(exc), error=True)
            QMessageBox.warning(self, "Colour", str(exc))
            return False
        finally:
            self._requesting = False
        self._typed_for = (self.uid, tuple(self.doc.target(self.uid).kappa))
        self._show_outcome(warning)
        return True

    def _choose(self) -> None:
        now = self.swatch.toolTip() or "#808080"
        chosen = QColorDialog.getColor(QColor(now), self, "The target's new colour")
        if chosen.isValid():
            self._request(self.editor.request_colour, chosen.name(), exposure=self._exposure())

    def _typed_albedo(self) -> None:
        text = self.albedo_entry.text()
        try:
            values = [float(v) for v in text.replace(";", ",").split(",")]
        except ValueError:
            values = []
        if len(values) != 3 or not all(math.isfinite(v) for v in values):
            msg = f"an albedo is three numbers R,G,B such as 0.2,0.1,0.8; got {text!r}"
            self._show_outcome(msg, error=True)
            QMessageBox.warning(self, "Albedo", msg)
            return
        self._request(self.editor.request_albedo, values, box=self.albedo_entry)

    def _keep_luminance(self, on: bool) -> None:
        self.editor.keep_luminance = bool(on)

    def pick_photograph(self, x: float, y: float) -> None:
        """The eyedropper clicked camera pixel ``(x, y)``: the target takes the colour there (one pick)."""
        self.eyedropper.setChecked(False)
        self._request(self.editor.pick, int(math.floor(x)), int(math.floor(y)))

    def pick_reference(self, pixels: np.ndarray, x: float, y: float) -> None:
        """A click on the reference picture (sRGB-encoded ``pixels``) at ``(x, y)``."""
        self._request(self.editor.pick_reference, pixels, int(math.floor(x)), int(math.floor(y)),
                      exposure=self._exposure())

    def open_reference(self) -> QImage | None:
        """Ask for a reference picture; None when cancelled or unreadable (said in a dialog)."""
        path, _ = QFileDialog.getOpenFileName(self, "Reference picture", "", REFERENCE_FILTER)
        if not path:
            return None
        image = QImage(path)
        if image.isNull():
            QMessageBox.warning(self, "Reference picture", f"cannot read {path} as a picture ({REFERENCE_FILTER})")
            return None
        return image
