"""The calibration wizard: choose a rig, set the exposure, calibrate into a session, review.

Pages, in order:

1. **Rig** — what :func:`devices.available` lists (unavailable rigs greyed, with the reason),
   the virtual rig's options, and the session folder (an existing session resumes).
2. **Projector** — the screen the projector window opens on, when the backend has one.
   Leaving this page opens the rig (on a worker) and the session.
3. **Exposure** — a live view grabbed on a worker (latest frame wins), saturated pixels in
   magenta, the exposure report in words.
4. **Calibrate** — run :func:`engine.workflow.run_calibration` on a worker with progress,
   time left, Pause/Resume and Cancel (finished captures stay in the session, so Start
   again — or a new wizard on the same folder — resumes), or reuse the calibration of another
   session of the same rig.
5. **Results** — the measured projector response and the Gray-code coverage map.
6. **Summary** — what was measured, what failed and how to fix it (engine messages verbatim).

On Finish with a calibration, :attr:`CalibrationWizard.finished_session` carries the session.
"""

from __future__ import annotations

import datetime as _dt
import html
import threading
from pathlib import Path

import numpy as np
from PySide6.QtCore import Qt, QTimer, Signal
from PySide6.QtWidgets import (
    QButtonGroup,
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QFileDialog,
    QFormLayout,
    QGridLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QListWidget,
    QListWidgetItem,
    QPushButton,
    QRadioButton,
    QSpinBox,
    QTextBrowser,
    QVBoxLayout,
    QWidget,
    QWizard,
    QWizardPage,
)

import devices
from app.qt.rig_views import CoverageMap, LiveView, ProgressEta, ResponsePlot, finish_job, rig_lock, worker_rig
from app.qt.worker import Job, LatestWorker, UiCaller
from devices.qtscreen import identify_pattern
from engine.acquire import calibration_budget
from engine.calibrate import AutoExposure, exposure_report, projector_lit
from engine.errors import DeviceError, InputError, SessionError
from engine.progress import checkpoint
from engine.session import Session
from engine.workflow import load_calibration, open_session_for_rig, run_calibration, save_calibration

__all__ = ["CalibrationWizard"]

_RED = "#c0392b"


def _esc(text: str) -> str:
    """Escape text for a rich-text label (quotes stay readable)."""
    return html.escape(text, quote=False)
_NO_SCREEN_BACKENDS = ("virtual", "replay")


# ---------------------------------------------------------------------------------- helpers
def _open_rig(name: str, options: dict, *, progress=None, should_stop=None):
    """Open a rig on a worker (virtual set-ups report their build progress)."""
    checkpoint(should_stop, "opening the rig")
    if name.startswith("virtual:"):
        options = dict(options, progress=progress)
    return devices.open_rig(name, **options)


def _calibrate(rig, session, *, levels, crosstalk, caller, progress=None, should_stop=None):
    """Job body: take the rig's lock (waiting for the live view to let go), then calibrate."""
    lock = rig_lock(rig)
    while not lock.acquire(timeout=0.05):
        checkpoint(should_stop, "calibration")
    try:
        return run_calibration(worker_rig(rig, caller), session, levels=levels, crosstalk=crosstalk,
                               progress=progress, should_stop=should_stop)
    finally:
        lock.release()


def _error_text(exc: BaseException) -> str:
    return str(exc) or type(exc).__name__


def _fix_for(exc: BaseException) -> str:
    """What to do about a failure, beyond the engine's own words."""
    if isinstance(exc, SessionError):
        return "Go back to the first page and choose a new session folder."
    if isinstance(exc, DeviceError):
        return "Check the cables and power, then go back to the first page to open the rig again."
    if isinstance(exc, InputError):
        return "Fix what the message says, then press Start again: captures already taken are reused."
    return "This is unexpected: the message above and the session folder help a bug report."


def _red(text: str) -> str:
    return f"<span style='color:{_RED}'>{_esc(text)}</span>"


# ---------------------------------------------------------------------------------- page 1: rig
class RigPage(QWizardPage):
    """Which rig, its options, and which session folder."""

    def __init__(self, wizard: CalibrationWizard):
        super().__init__()
        self.setTitle("Choose the rig")
        self.setSubTitle("The camera and projector to calibrate, and the session folder the captures go to.")
        self.w = wizard
        self.rigs = QListWidget()
        self.rigs.setMinimumHeight(120)
        self.rig_name = QLineEdit()
        self.rig_name.setPlaceholderText("backend:argument, e.g. virtual:cornell or opencv:0")
        self.given = QLabel()
        self.given.setWordWrap(True)

        self.virtual = QGroupBox("Virtual rig")
        self.ideal = QCheckBox("ideal (no noise, linear projector)")
        self.pose = QComboBox()
        self.pose.addItems(["coaxial", "offset"])
        self.res_h = QSpinBox(minimum=8, maximum=4096, value=128)
        self.res_w = QSpinBox(minimum=8, maximum=4096, value=128)
        res = QHBoxLayout()
        res.addWidget(self.res_h)
        res.addWidget(QLabel("×"))
        res.addWidget(self.res_w)
        res.addWidget(QLabel("(H × W camera pixels)"))
        res.addStretch(1)
        form = QFormLayout(self.virtual)
        form.addRow(self.ideal)
        form.addRow("Projector pose", self.pose)
        form.addRow("Resolution", res)

        self.session_path = QLineEdit()
        browse = QPushButton("Browse…")
        browse.clicked.connect(self._on_browse)
        row = QHBoxLayout()
        row.addWidget(self.session_path, 1)
        row.addWidget(browse)
        note = QLabel("A new folder starts a session; an existing session folder resumes its interrupted calibration.")
        note.setWordWrap(True)

        lay = QVBoxLayout(self)
        lay.addWidget(QLabel("Rigs on this machine (greyed: cannot be opened, with the reason):"))
        lay.addWidget(self.rigs, 1)
        lay.addWidget(self.given)
        name_row = QHBoxLayout()
        name_row.addWidget(QLabel("Rig"))
        name_row.addWidget(self.rig_name, 1)
        lay.addLayout(name_row)
        lay.addWidget(self.virtual)
        lay.addWidget(QLabel("Session folder"))
        lay.addLayout(row)
        lay.addWidget(note)

        self.rigs.currentItemChanged.connect(self._on_pick)
        self.rig_name.textChanged.connect(self._on_name_changed)
        self.session_path.textChanged.connect(self.completeChanged)
        self._fill()

    def _fill(self) -> None:
        w = self.w
        if w.given_rig is not None:
            self.rigs.hide()
            self.virtual.hide()
            self.rig_name.setText(w.given_rig.name)
            self.rig_name.setReadOnly(True)
            self.given.setText(f"Using the rig that is already open: {w.given_rig!r}.")
            return
        self.given.hide()
        try:
            entries = devices.available()
        except Exception as exc:  # noqa: BLE001 - a broken probe must not break the wizard
            entries = []
            self.given.setText(_red(f"Listing rigs failed: {_error_text(exc)}"))
            self.given.show()
        for a in entries:
            item = QListWidgetItem(f"{a.name} — {a.reason}" if a.reason else a.name)
            item.setData(Qt.ItemDataRole.UserRole, a.name)
            item.setToolTip(a.reason or a.name)
            if not a.ok:
                item.setFlags(item.flags() & ~Qt.ItemFlag.ItemIsEnabled & ~Qt.ItemFlag.ItemIsSelectable)
            self.rigs.addItem(item)
        wanted = w.initial_rig_name
        for i in range(self.rigs.count()):
            item = self.rigs.item(i)
            if item.flags() & Qt.ItemFlag.ItemIsEnabled and (wanted is None or item.data(Qt.ItemDataRole.UserRole) == wanted):
                self.rigs.setCurrentItem(item)
                break
        if wanted is not None:
            self.rig_name.setText(wanted)
        self._on_name_changed(self.rig_name.text())

    def _on_pick(self, item, _previous=None) -> None:
        if item is not None and item.flags() & Qt.ItemFlag.ItemIsEnabled:
            self.rig_name.setText(item.data(Qt.ItemDataRole.UserRole))

    def _on_name_changed(self, text: str) -> None:
        self.virtual.setEnabled(text.startswith("virtual:"))
        self.completeChanged.emit()

    def _on_browse(self) -> None:
        path = QFileDialog.getExistingDirectory(self, "Session folder", self.session_path.text())
        if path:
            self.session_path.setText(path)

    def initializePage(self) -> None:  # noqa: N802 (Qt name)
        if not self.session_path.text():
            self.session_path.setText(str(self.w.default_session_path()))

    def isComplete(self) -> bool:  # noqa: N802 (Qt name)
        name = self.rig_name.text().strip()
        return bool(name) and ":" in name and bool(self.session_path.text().strip())

    def options(self) -> dict:
        """Options for :func:`devices.open_rig` from this page (virtual rigs only)."""
        if not self.rig_name.text().startswith("virtual:"):
            return {}
        return {"ideal": self.ideal.isChecked(), "projector": self.pose.currentText(),
                "resolution": (self.res_h.value(), self.res_w.value())}


# ---------------------------------------------------------------------------------- page 2: projector
class ProjectorPage(QWizardPage):
    """The projector's screen (when the backend draws the projector as a window); opens the rig."""

    def __init__(self, wizard: CalibrationWizard):
        super().__init__()
        self.setTitle("Projector")
        self.w = wizard
        self.note = QLabel()
        self.note.setWordWrap(True)
        self.screens = QListWidget()
        self.status = QLabel()
        self.status.setWordWrap(True)
        self.eta = ProgressEta(unit="steps")
        self.eta.hide()
        lay = QVBoxLayout(self)
        lay.addWidget(self.note)
        lay.addWidget(self.screens, 1)
        lay.addStretch(1)
        lay.addWidget(self.eta)
        lay.addWidget(self.status)

    def initializePage(self) -> None:  # noqa: N802 (Qt name)
        self.screens.clear()
        self.status.clear()
        name = self.w.rig_page.rig_name.text().strip()
        backend = name.partition(":")[0]
        self.setSubTitle(f"Where {name} shows its patterns. Next opens the rig.")
        if self.w.given_rig is not None:
            self.note.setText("The rig is already open; its projector is set.")
            self.screens.hide()
        elif backend in _NO_SCREEN_BACKENDS:
            self.note.setText(
                "The virtual rig simulates its projector (its pose is chosen on the first page): there is no "
                "screen to choose." if backend == "virtual" else
                "A replay rig serves recorded captures back: it has no projector screen.")
            self.screens.hide()
        else:
            self.screens.show()
            try:
                from devices.qtscreen import list_screens

                found = list_screens()
            except Exception as exc:  # noqa: BLE001 - shown, the rig then opens with its default
                found = []
                self.note.setText(_red(f"Cannot list screens ({_error_text(exc)}); the rig opens with its default projector."))
            for s in found:
                item = QListWidgetItem(str(s))
                item.setData(Qt.ItemDataRole.UserRole, s.index)
                self.screens.addItem(item)
            if found:
                self.note.setText("The projector is a full-screen window on one of these screens (usually not the primary):")
                self.screens.setCurrentRow(1 if len(found) > 1 else 0)

    def options(self) -> dict:
        item = self.screens.currentItem()
        if self.screens.isHidden() or item is None:
            return {}
        return {"projector": f"qtscreen:{item.data(Qt.ItemDataRole.UserRole)}"}

    def isComplete(self) -> bool:  # noqa: N802 (Qt name)
        return not self.w.busy

    def validatePage(self) -> bool:  # noqa: N802 (Qt name)
        return self.w.ensure_rig_and_session()


# ---------------------------------------------------------------------------------- page 3: exposure
class ExposurePage(QWizardPage):
    """Live view on a worker, exposure control, saturation overlay and the exposure report."""

    #: Frames automatic exposure may take before it gives up.
    AUTO_MAX_STEPS = 12

    def __init__(self, wizard: CalibrationWizard):
        super().__init__()
        self.setTitle("Camera exposure")
        self.setSubTitle("Under projector white, nothing on the surfaces to edit may clip (magenta), and "
                         "the darkest of them should stay well above black.")
        self.w = wizard
        self.live = LiveView()
        self.exposure = QDoubleSpinBox(decimals=3, minimum=0.001, maximum=3_600_000.0, suffix=" ms")
        self.exposure.setStepType(QDoubleSpinBox.StepType.AdaptiveDecimalStepType)
        longer, shorter = QPushButton("×2"), QPushButton("÷2")
        longer.clicked.connect(lambda: self.exposure.setValue(self.exposure.value() * 2))
        shorter.clicked.connect(lambda: self.exposure.setValue(self.exposure.value() / 2))
        self.auto_button = QPushButton("Auto")
        self.auto_button.setToolTip("Adjust the exposure until the brightest projector-lit surfaces sit just "
                                    "below clipping (a lamp in view may still clip: it is not projector light)")
        self.auto_button.clicked.connect(self.start_auto)
        self.level = QComboBox()
        self.level.addItems(["white (what calibration checks)", "black (ambient light only)",
                             "identify (grid and centre cross: check pose and focus)"])
        self.overlay = QCheckBox("show saturated pixels", checked=True)
        self.overlay.toggled.connect(self.live.set_show_saturation)
        self.report = QLabel("waiting for the camera…")
        self.report.setWordWrap(True)
        controls = QHBoxLayout()
        controls.addWidget(QLabel("Exposure"))
        controls.addWidget(self.exposure)
        controls.addWidget(shorter)
        controls.addWidget(longer)
        controls.addWidget(self.auto_button)
        controls.addSpacing(12)
        controls.addWidget(QLabel("Projector"))
        controls.addWidget(self.level)
        controls.addStretch(1)
        controls.addWidget(self.overlay)
        lay = QVBoxLayout(self)
        lay.addWidget(self.live, 1)
        lay.addLayout(controls)
        lay.addWidget(self.report)
        self.timer = QTimer(self)
        self.timer.timeout.connect(self._tick)
        self.worker: LatestWorker | None = None
        self.grabbed_on = ""  # name of the thread that grabbed the last frame (tests, diagnostics)
        self._shown = None  # (exposure, level) the worker last applied
        self.auto: AutoExposure | None = None  # running automatic exposure
        self.auto_message = ""
        self._auto_steps = 0
        self._auto_asked: float | None = None  # the exposure of the frame the next step waits for
        self._auto_black: np.ndarray | None = None  # radiance under projector black
        self._patterns: dict = {}  # projector images of the levels, by (level, rig, resolution)

    # -- live loop (UI thread) -------------------------------------------------------------
    def initializePage(self) -> None:  # noqa: N802 (Qt name)
        cam = self.w.rig.camera
        exposure = getattr(cam, "exposure", None)
        self.exposure.setEnabled(exposure is not None)
        if exposure is not None:
            self.exposure.setValue(float(exposure) * 1000.0)
        self.live.reset_scale()
        self.start_live()

    def cleanupPage(self) -> None:  # noqa: N802 (Qt name) - Back
        self.stop_live()

    def validatePage(self) -> bool:  # noqa: N802 (Qt name)
        self.stop_live()
        return True

    def start_live(self) -> None:
        self.stop_live()
        self._shown = None
        # No Qt parent: the worker's thread keeps it alive until a grab in flight has returned.
        self.worker = LatestWorker(self._grab, synchronous=self.w.synchronous)
        self.worker.done.connect(self._on_frame)
        self.worker.failed.connect(self._on_grab_failed)
        self.timer.start(self.w.live_interval_ms)
        self._tick()

    def stop_live(self) -> None:
        """Stop asking for frames. Never waits: a grab in flight finishes on its own."""
        self.timer.stop()
        if self.worker is not None:
            self.worker.done.disconnect(self._on_frame)
            self.worker.failed.disconnect(self._on_grab_failed)
            self.worker.close(timeout=0)
            self.worker = None

    def _tick(self) -> None:
        if self.worker is None or not self.worker.idle() or self.w.rig is None:
            return
        exposure = self.exposure.value() / 1000.0 if self.exposure.isEnabled() else None
        self.worker.submit((exposure, self._pattern()))

    def _pattern(self) -> tuple[str, np.ndarray]:
        """(key, projector image) of the chosen projector level (made once per rig and level)."""
        hp, wp = self.w.rig.projector.resolution
        key = ("white", "black", "identify")[self.level.currentIndex()]
        cached = self._patterns.get((key, self.w.rig.name, hp, wp))
        if cached is None:
            cached = (identify_pattern((hp, wp), label=f"{self.w.rig.name}  {wp}x{hp}") if key == "identify"
                      else np.full((hp, wp, 3), 1.0 if key == "white" else 0.0, np.float32))
            self._patterns[(key, self.w.rig.name, hp, wp)] = cached
        return key, cached

    # -- automatic exposure (UI thread: each live frame is one step) --------------------------
    def start_auto(self) -> None:
        """Take a frame under projector black (what ambient light lights), then step the
        exposure frame by frame under projector white until the projector-lit pixels settle."""
        if not self.exposure.isEnabled():
            self.report.setText(_red("This camera's exposure cannot be set from Albedit."))
            return
        self.level.setCurrentIndex(1)
        self.auto = AutoExposure(percentile=99.5, max_saturated=0.005)
        self._auto_steps = 0
        self._auto_black = None
        self._auto_asked = self.exposure.value() / 1000.0
        self.auto_button.setEnabled(False)
        self.auto_button.setText("Auto…")

    def _auto_step(self, result) -> None:
        if result["asked"] != self._auto_asked:
            return  # grabbed before the last change (the camera may round what was asked: use its value)
        if self._auto_black is None:
            if result["level"] == "black":
                self._auto_black = result["image"]
                self.level.setCurrentIndex(0)
            return
        if result["level"] != "white":
            return
        self._auto_steps += 1
        lit = result["lit"]  # judged on the worker; a frame grabbed before the black one was known has none
        if lit is None:
            lit = projector_lit(result["image"], self._auto_black)
        wanted = self.auto.step(result["image"], result["saturated"], exposure=result["exposure"], target=lit)
        if wanted is None or self._auto_steps >= self.AUTO_MAX_STEPS:
            self.auto = None
            self.auto_button.setEnabled(True)
            self.auto_button.setText("Auto")
            self.auto_message = (
                f"Auto exposure settled at {result['exposure'] * 1000:.4g} ms after {self._auto_steps} frames "
                "(judged on projector-lit pixels; a lamp in view may clip: captures complete it from shorter exposures)."
                if wanted is None else f"Auto exposure gave up after {self._auto_steps} frames: set it by hand.")
            return
        self.exposure.setValue(wanted * 1000.0)
        self._auto_asked = self.exposure.value() / 1000.0  # as the spin box rounded it

    def _on_frame(self, _rid: int, result) -> None:
        if result is None:  # the rig was busy
            return
        self.grabbed_on = result["thread"]
        self.live.set_frame(result["image"], result["saturated"], exposure=result["exposure"], gain=result["gain"])
        if self.auto is not None:
            self._auto_step(result)
        style = "" if result["ok"] else f" style='color:{_RED}'"
        text = f"<span{style}>{_esc(result['report'])}</span>"
        if self.auto is not None:
            text = f"auto exposure: frame {self._auto_steps}…<br>" + text
        elif self.auto_message:
            text = f"{_esc(self.auto_message)}<br>" + text
        self.report.setText(text)

    def _on_grab_failed(self, _rid: int, exc) -> None:
        self.report.setText(_red(f"Camera: {_error_text(exc)}"))

    # -- worker side -------------------------------------------------------------------
    def _grab(self, request):
        """One live frame (worker thread): apply exposure and projector level, capture, judge."""
        rig = self.w.rig
        lock = rig_lock(rig)
        if not lock.acquire(blocking=False):
            return None
        try:
            exposure, (level, pattern) = request
            cam = rig.camera
            if exposure is not None and not np.isclose(getattr(cam, "exposure", exposure), exposure, rtol=1e-6):
                cam.exposure = exposure
            if self._shown is None or self._shown != level:
                worker_rig(rig, self.w.ui).projector.show(pattern)
                self._shown = level
            frame = cam.capture()
            black = self._auto_black  # known after Auto: judge where the projector's light is
            lit = projector_lit(frame.image, black) if black is not None and level == "white" else None
            report = exposure_report(frame.image, saturated=frame.saturated, target=lit,
                                     label=None if lit is None else "projector-lit pixels")
            return {
                "image": np.asarray(frame.image, np.float32),
                "saturated": np.asarray(frame.saturated, bool),
                "exposure": float(frame.exposure),
                "gain": float(getattr(frame, "gain", 1.0)),
                "report": report.message,
                "ok": report.ok,
                "level": level,
                "asked": exposure,
                "lit": lit,
                "thread": threading.current_thread().name,
            }
        finally:
            lock.release()


# ---------------------------------------------------------------------------------- page 4: calibrate
class CalibrationPage(QWizardPage):
    """Run the calibration (or reuse another session's), with progress, pause and cancel."""

    def __init__(self, wizard: CalibrationWizard):
        super().__init__()
        self.setTitle("Calibrate")
        self.setSubTitle("Black, white, the Gray code and a grey ramp. Each capture is written to the session as "
                         "it is taken: a cancelled or crashed calibration resumes where it stopped.")
        self.w = wizard
        self.mode_run = QRadioButton("Calibrate now")
        self.mode_reuse = QRadioButton("Use the calibration of an existing session (same rig)")
        self.mode_run.setChecked(True)
        group = QButtonGroup(self)
        group.addButton(self.mode_run)
        group.addButton(self.mode_reuse)

        self.levels = QSpinBox(minimum=3, maximum=256, value=17)
        self.levels.setMaximumWidth(90)
        self.crosstalk = QCheckBox("also measure colour crosstalk (3 more captures)")
        self.start = QPushButton("Start")
        self.pause = QPushButton("Pause")
        self.pause.setCheckable(True)
        self.cancel = QPushButton("Cancel")
        self.eta = ProgressEta(unit="captures")
        self.info = QLabel()
        self.info.setWordWrap(True)
        run_box = QWidget()
        grid = QGridLayout(run_box)
        grid.setContentsMargins(24, 0, 0, 0)
        grid.addWidget(QLabel("Grey levels of the response ramp"), 0, 0)
        grid.addWidget(self.levels, 0, 1)
        grid.addWidget(self.crosstalk, 1, 0, 1, 3)
        buttons = QHBoxLayout()
        for b in (self.start, self.pause, self.cancel):
            buttons.addWidget(b)
        buttons.addStretch(1)
        grid.setColumnStretch(2, 1)
        grid.addLayout(buttons, 2, 0, 1, 3)
        grid.addWidget(self.eta, 3, 0, 1, 3)
        self.run_box = run_box

        self.reuse_path = QLineEdit()
        self.reuse_path.setPlaceholderText("a calibrated session folder")
        browse = QPushButton("Browse…")
        browse.clicked.connect(self._on_browse)
        self.use = QPushButton("Use it")
        reuse_box = QWidget()
        row = QHBoxLayout(reuse_box)
        row.setContentsMargins(24, 0, 0, 0)
        row.addWidget(self.reuse_path, 1)
        row.addWidget(browse)
        row.addWidget(self.use)
        self.reuse_box = reuse_box

        self.status = QLabel()
        self.status.setWordWrap(True)
        self.status.setTextFormat(Qt.TextFormat.RichText)
        lay = QVBoxLayout(self)
        lay.addWidget(self.mode_run)
        lay.addWidget(run_box)
        lay.addWidget(self.mode_reuse)
        lay.addWidget(reuse_box)
        lay.addWidget(self.info)
        lay.addWidget(self.status)
        lay.addStretch(1)

        self.mode_run.toggled.connect(self._update)
        self.start.clicked.connect(self._on_start)
        self.pause.toggled.connect(self._on_pause)
        self.cancel.clicked.connect(self._on_cancel)
        self.use.clicked.connect(self._on_use)
        self.levels.valueChanged.connect(self._update)
        self.crosstalk.toggled.connect(self._update)

    # -- state ---------------------------------------------------------------------------
    def initializePage(self) -> None:  # noqa: N802 (Qt name)
        w = self.w
        if w.calibration is None and w.session is not None and w.session.read_calibration()[0]:
            try:
                w.calibration = load_calibration(w.session)
                self.status.setText(f"This session is already calibrated ({w.calibration.metadata.get('date', '')}). "
                                    "Next shows the results; choose a new session folder to calibrate again.")
            except Exception as exc:  # noqa: BLE001 - a damaged calibration is reported, not fatal
                self.status.setText(_red(f"The session's calibration cannot be read: {_error_text(exc)}"))
        self._update()

    def budget(self) -> int:
        return calibration_budget(self.w.rig.projector.resolution, levels=self.levels.value(),
                                  crosstalk=self.crosstalk.isChecked())

    def _update(self) -> None:
        w = self.w
        running = w.job is not None and w.job.running
        run_mode = self.mode_run.isChecked()
        self.run_box.setEnabled(run_mode or running)
        self.reuse_box.setEnabled(not run_mode and not running)
        self.mode_run.setEnabled(not running)
        self.mode_reuse.setEnabled(not running)
        self.levels.setEnabled(not running)
        self.crosstalk.setEnabled(not running)
        self.start.setEnabled(run_mode and not running and w.calibration is None)
        self.pause.setEnabled(running)
        self.cancel.setEnabled(running)
        if w.session is not None and w.rig is not None:
            have = sum(1 for c in w.session.captures if c.name.startswith("cal-"))
            total = self.budget()
            self.start.setText("Resume" if 0 < have < total and w.calibration is None else "Start")
            if w.calibration is not None:
                self.info.setText(f"The session is calibrated ({have} captures).")
            else:
                self.info.setText(f"{total} captures: black, white, Gray code and the response ramp"
                                  + (", crosstalk" if self.crosstalk.isChecked() else "")
                                  + (f"; {have} already in the session will be reused." if have else "."))
        self.completeChanged.emit()

    def isComplete(self) -> bool:  # noqa: N802 (Qt name)
        running = self.w.job is not None and self.w.job.running
        return not running and (self.w.calibration is not None or self.w.failure is not None)

    def nextId(self) -> int:  # noqa: N802 (Qt name)
        return CalibrationWizard.PAGE_RESULTS if self.w.calibration is not None else CalibrationWizard.PAGE_SUMMARY

    # -- run -----------------------------------------------------------------------------
    def _on_start(self) -> None:
        self.status.clear()
        self.eta.reset()
        self.pause.setChecked(False)
        self.w.start_calibration(levels=self.levels.value(), crosstalk=self.crosstalk.isChecked())

    def _on_pause(self, on: bool) -> None:
        job = self.w.job
        if job is None or not job.running or (on and self.w.cancel_requested):
            return  # a pause after a cancel would hold the worker forever
        job.pause() if on else job.resume()

    def _on_paused(self, on: bool) -> None:
        self.pause.setChecked(on)
        self.pause.setText("Resume" if on else "Pause")
        if on:
            self.eta.set_note("paused (the projector holds its pattern)")

    def _on_cancel(self) -> None:
        if self.w.job is not None:
            self.w.cancel_requested = True
            self.w.job.cancel()

    def on_finished(self, calibration) -> None:
        self.status.setText(f"Calibrated. {_esc(calibration.metadata.get('coverage', ''))}")
        self.eta.set_note("done")

    def on_failed(self, exc) -> None:
        self.status.setText(_red(_error_text(exc)) + "<br>" + _esc(_fix_for(exc)) +
                            " Next shows a summary.")

    def on_cancelled(self, _exc) -> None:
        have = sum(1 for c in self.w.session.captures if c.name.startswith("cal-"))
        self.status.setText(f"Cancelled. The {have} captures taken so far are kept in the session: "
                            "press Resume to continue where it stopped.")
        self.eta.set_note("cancelled")

    # -- reuse ---------------------------------------------------------------------------
    def _on_browse(self) -> None:
        path = QFileDialog.getExistingDirectory(self, "Calibrated session", self.reuse_path.text())
        if path:
            self.reuse_path.setText(path)

    def _on_use(self) -> None:
        ok, message = self.w.reuse_calibration(self.reuse_path.text().strip())
        self.status.setText(_esc(message) if ok else _red(message))
        self._update()


# ---------------------------------------------------------------------------------- page 5: results
class ResultsPage(QWizardPage):
    """The measured response and where the Gray code decoded."""

    def __init__(self, wizard: CalibrationWizard):
        super().__init__()
        self.setTitle("Results")
        self.setSubTitle("Only decoded pixels can be re-lit by the projector: targets must lie on them.")
        self.w = wizard
        self.coverage = CoverageMap()
        self.response = ResponsePlot()
        self.coverage_text = QLabel()
        self.coverage_text.setWordWrap(True)
        self.exposure_text = QLabel()
        self.exposure_text.setWordWrap(True)
        grid = QGridLayout(self)
        grid.addWidget(QLabel("<b>Coverage of the Gray code</b>"), 0, 0)
        grid.addWidget(QLabel("<b>Projector response</b>"), 0, 1)
        grid.addWidget(self.coverage, 1, 0)
        grid.addWidget(self.response, 1, 1)
        grid.addWidget(self.coverage_text, 2, 0, 1, 2)
        grid.addWidget(self.exposure_text, 3, 0, 1, 2)
        grid.setRowStretch(1, 1)

    def initializePage(self) -> None:  # noqa: N802 (Qt name)
        cal, session = self.w.calibration, self.w.session
        background = None
        if session is not None and session.has_capture("cal-white"):
            try:
                background = session.read_capture("cal-white")
            except SessionError:
                background = None
        self.coverage.set_status(cal.correspondence.status, background)
        self.response.set_response(cal.response)
        self.coverage_text.setText(f"Coverage: {_esc(cal.correspondence.summary())}")
        self.exposure_text.setText(f"Exposure: {_esc(str(cal.metadata.get('exposure', 'not recorded')))}")


# ---------------------------------------------------------------------------------- page 6: summary
class SummaryPage(QWizardPage):
    """What was done, what failed and how to fix it."""

    def __init__(self, wizard: CalibrationWizard):
        super().__init__()
        self.setTitle("Summary")
        self.setSubTitle("What was measured, and anything to fix before acquiring.")
        self.w = wizard
        self.text = QTextBrowser()
        self.text.setOpenLinks(False)
        QVBoxLayout(self).addWidget(self.text)

    def initializePage(self) -> None:  # noqa: N802 (Qt name)
        self.text.setHtml(self.w.summary_html())


# ---------------------------------------------------------------------------------- the wizard
class CalibrationWizard(QWizard):
    """Calibrate a camera–projector rig into a session folder.

    Parameters
    ----------
    parent : QWidget, optional
    rig : devices.base.Rig, optional
        An open rig to calibrate (the rig page then only asks for the session folder). The
        wizard never closes a rig it was given.
    rig_name : str, optional
        Preselect this rig on the first page (e.g. ``"virtual:cornell"``).
    rig_options : dict, optional
        Extra :func:`devices.open_rig` options for virtual rigs (``cache_dir``, ``seed``).
    session_path : str or Path, optional
        Session folder to propose (default: a new dated folder under ``sessions_dir``).
    sessions_dir : str or Path, optional
        Where new session folders are proposed (default ``~/Albedit/sessions``).
    keep_rig : bool
        On Finish, leave the rig the wizard opened open: the caller takes it from :attr:`rig`
        and must close it. Otherwise it is closed when the wizard closes.
    synchronous : bool
        Jobs and the live view run on the UI thread (tests).
    live_interval_ms : int
        Live-view period.

    Signals
    -------
    finished_session(object)
        The calibrated :class:`engine.session.Session`, on Finish.
    calibrated(object)
        The :class:`engine.calibrate.Calibration`, when a run or a reuse succeeds.
    rig_opened(object)
        The rig, once opened.
    job_started(object)
        Each :class:`app.qt.worker.Job` the wizard starts (opening the rig, calibrating).

    Attributes
    ----------
    rig, session, calibration, failure
        Current state; ``failure`` is the last job's exception (or None).
    result_session : Session or None
        The calibrated session once the wizard was accepted.
    """

    finished_session = Signal(object)
    calibrated = Signal(object)
    rig_opened = Signal(object)
    job_started = Signal(object)

    PAGE_RIG, PAGE_PROJECTOR, PAGE_EXPOSURE, PAGE_CALIBRATE, PAGE_RESULTS, PAGE_SUMMARY = range(6)

    def __init__(self, parent: QWidget | None = None, *, rig=None, rig_name: str | None = None,
                 rig_options: dict | None = None, session_path=None, sessions_dir=None, keep_rig: bool = False,
                 synchronous: bool = False, live_interval_ms: int = 200):
        super().__init__(parent)
        self.setWindowTitle("Calibrate the rig")
        self.setWizardStyle(QWizard.WizardStyle.ClassicStyle)
        self.setOption(QWizard.WizardOption.NoBackButtonOnLastPage, True)
        self.resize(820, 640)
        self.synchronous = bool(synchronous)
        self.live_interval_ms = int(live_interval_ms)
        self.keep_rig = bool(keep_rig)
        self.given_rig = rig
        self.initial_rig_name = rig_name
        self.rig_options = dict(rig_options or {})
        self.sessions_dir = Path(sessions_dir) if sessions_dir is not None else Path.home() / "Albedit" / "sessions"
        self.ui = UiCaller(self)
        self.rig = rig
        self.session: Session | None = None
        self.calibration = None
        self.failure: BaseException | None = None
        self.result_session: Session | None = None
        self.job: Job | None = None
        self.cancel_requested = False
        self._opened: tuple | None = None if rig is None else (rig.name, ())
        self._pending_close = False

        self.rig_page = RigPage(self)
        self.projector_page = ProjectorPage(self)
        self.exposure_page = ExposurePage(self)
        self.calibration_page = CalibrationPage(self)
        self.results_page = ResultsPage(self)
        self.summary_page = SummaryPage(self)
        for pid, page in zip(range(6), (self.rig_page, self.projector_page, self.exposure_page,
                                        self.calibration_page, self.results_page, self.summary_page)):
            self.setPage(pid, page)
        if session_path is not None:
            self.rig_page.session_path.setText(str(session_path))

    # -- state ---------------------------------------------------------------------------
    @property
    def busy(self) -> bool:
        return self.job is not None and self.job.running

    def default_session_path(self) -> Path:
        stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
        return self.sessions_dir / f"calibration-{stamp}"

    def _spec(self) -> tuple:
        name = self.rig_page.rig_name.text().strip()
        options = dict(self.rig_page.options(), **self.projector_page.options())
        if name.startswith("virtual:"):
            options.update(self.rig_options)
        return name, options

    def ensure_rig_and_session(self) -> bool:
        """Open the chosen rig (on a worker) and the session; True once both are ready.

        While the rig opens this returns False and the wizard moves on by itself when done.
        """
        if self.busy:
            return False
        page = self.projector_page
        name, options = self._spec()
        key = (name, tuple(sorted((k, repr(v)) for k, v in options.items())))
        if self.given_rig is None and (self.rig is None or self._opened != key):
            self._close_rig()
            page.status.setText(f"Opening {_esc(name)}…")
            # Hardware backends open a Qt projector window, which only the UI thread may create.
            on_ui = self.synchronous or name.partition(":")[0] not in _NO_SCREEN_BACKENDS
            job = Job(_open_rig, name, options, name=f"Opening {name}", synchronous=on_ui)
            job.progress.connect(page.eta.update_progress)

            def opened(rig):
                self.rig, self._opened = rig, key
                self.rig_opened.emit(rig)

            def failed(exc):
                page.status.setText(_red(f"Cannot open {name}: {_error_text(exc)}"))

            job.finished.connect(opened)
            job.failed.connect(failed)
            job.cancelled.connect(lambda exc: page.status.setText(str(exc)))
            job.ended.connect(lambda: self._job_ended(job))
            job.ended.connect(page.eta.hide)
            self._run(job)
            page.eta.show()
            if self.busy:  # threaded: continue when it is done
                job.finished.connect(lambda _rig: self.currentId() == self.PAGE_PROJECTOR and self.next())
                return False
            if self.rig is None or self._opened != key:
                return False
        try:
            path = Path(self.rig_page.session_path.text().strip()).expanduser()
            if self.session is None or Path(self.session.path).resolve() != path.resolve():
                self.session = open_session_for_rig(path, self.rig)
                self.calibration, self.failure = None, None
        except Exception as exc:  # noqa: BLE001 - shown on the page, engine's words
            self.session = None
            page.status.setText(_red(_error_text(exc)) + "<br>" + _esc(_fix_for(exc)))
            return False
        page.status.setText(f"Opened {_esc(self.rig.name)}; session {_esc(str(self.session.path))}.")
        return True

    def _run(self, job: Job) -> None:
        self.job = job
        self.cancel_requested = False
        self.job_started.emit(job)
        job.start()
        for page in (self.projector_page, self.calibration_page):
            page.completeChanged.emit()

    def _job_ended(self, job: Job) -> None:
        if self.job is job:
            self.job = None
        if self._pending_close:
            self._close_rig()
        self.projector_page.completeChanged.emit()
        self.calibration_page._update()

    def start_calibration(self, *, levels: int = 17, crosstalk: bool = False) -> Job:
        """Calibrate the open rig into the session on a worker (resumes from the session's captures)."""
        if self.busy:
            raise InputError(f"{self.job.name} is still running")
        if self.rig is None or self.session is None:
            raise InputError("open a rig and a session first (the first two pages)")
        self.exposure_page.stop_live()
        self.failure = None
        page = self.calibration_page
        job = Job(_calibrate, self.rig, self.session, levels=levels, crosstalk=crosstalk, caller=self.ui,
                  name="Calibrating", synchronous=self.synchronous)
        job.progress.connect(page.eta.update_progress)
        job.paused.connect(page._on_paused)
        job.finished.connect(self._on_calibrated)
        job.finished.connect(page.on_finished)
        job.failed.connect(self._on_failed)
        job.failed.connect(page.on_failed)
        job.cancelled.connect(page.on_cancelled)
        job.ended.connect(lambda: self._job_ended(job))
        self._run(job)
        page._update()
        return job

    def _on_calibrated(self, calibration) -> None:
        self.calibration = calibration
        self.calibrated.emit(calibration)

    def _on_failed(self, exc) -> None:
        self.failure = exc

    def reuse_calibration(self, path: str) -> tuple[bool, str]:
        """Copy another session's calibration into this session if it fits the rig.

        Returns
        -------
        (ok, message)
            The refusal reason is the engine's message.
        """
        if not path:
            return False, "Choose a calibrated session folder first."
        try:
            calibration = load_calibration(Session.open(path))
            calibration.check_compatible(self.rig.identity, tuple(self.rig.camera.resolution),
                                         tuple(self.rig.projector.resolution))
            mine = self.session.read_calibration()[0]
            if mine and mine != calibration.to_dict()[0]:
                raise SessionError(f"session {self.session.path} already has a different calibration; "
                                   "use a new session folder")
            if not mine:
                save_calibration(self.session, calibration)
        except Exception as exc:  # noqa: BLE001 - the refusal is shown in the engine's words
            return False, f"Refused: {_error_text(exc)}"
        self.calibration, self.failure = calibration, None
        self.calibrated.emit(calibration)
        return True, f"Using the calibration of {path} ({calibration.metadata.get('coverage', '')})."

    # -- summary -------------------------------------------------------------------------
    def problems(self) -> list[tuple[str, str]]:
        """(what, how to fix) pairs for the summary page."""
        out = []
        if self.failure is not None:
            out.append((_error_text(self.failure), _fix_for(self.failure)))
        cal = self.calibration
        if cal is not None:
            counts = cal.correspondence.counts()
            total = max(sum(counts.values()), 1)
            if counts["decoded"] < 0.98 * total:
                fixes = ["targets can only be edited where the projector reaches: keep them on the green "
                         "pixels of the coverage map"]
                if counts["unlit"]:
                    fixes.append("unlit pixels are in the projector's shadow: targets there cannot be edited; "
                                 "place the projector closer to the camera's viewpoint")
                if counts["low_contrast"]:
                    fixes.append("low contrast: focus the projector, lengthen the exposure, darken the room")
                if counts["out_of_range"]:
                    fixes.append("out of range codes come from noise or strong indirect light: darken the room")
                out.append((cal.correspondence.summary(), "; ".join(fixes) + "."))
            exposure = str(cal.metadata.get("exposure", ""))
            if exposure and not exposure.startswith("ok"):
                out.append((f"Exposure: {exposure}", "Go back to the exposure page, adjust, and calibrate into a "
                            "new session folder."))
        return out

    def summary_html(self) -> str:
        rows = []
        if self.rig is not None:
            rows.append(f"<b>Rig</b>: {_esc(self.rig.name)}")
        if self.session is not None:
            rows.append(f"<b>Session</b>: {_esc(str(self.session.path))}")
        cal = self.calibration
        if cal is not None:
            rows.append(f"<b>Calibrated</b>: {_esc(str(cal.metadata.get('date', '')))} — "
                        f"{len([c for c in self.session.captures if c.name.startswith('cal-')])} captures")
            rows.append(f"<b>Coverage</b>: {_esc(cal.correspondence.summary())}")
            rows.append(f"<b>Exposure</b>: {_esc(str(cal.metadata.get('exposure', '')))}")
        else:
            rows.append(_red("No calibration: the session cannot be used for acquisition yet."))
        problems = self.problems()
        if problems:
            items = "".join(f"<li>{_red(what)}<br>{_esc(fix)}</li>" for what, fix in problems)
            rows.append(f"<b>What failed and how to fix it</b><ul>{items}</ul>")
        elif cal is not None:
            rows.append("Nothing to fix. Finish, then paint targets and acquire them.")
        return "<p>" + "</p><p>".join(rows) + "</p>"

    # -- closing -------------------------------------------------------------------------
    def take_rig(self):
        """Hand the rig the wizard opened to the caller (who must close it); returns it."""
        rig, self.keep_rig = self.rig, True
        return rig

    def _close_rig(self) -> None:
        """Close the rig the wizard opened, once no job uses it."""
        if self.rig is None or self.rig is self.given_rig:
            return
        if self.busy:
            self._pending_close = True
            return
        self._pending_close = False
        rig, self.rig, self._opened = self.rig, None, None
        try:
            rig.close()
        except Exception:  # noqa: BLE001 - closing is best effort; the device reports on reopen
            pass

    def done(self, result: int) -> None:
        self.exposure_page.stop_live()
        accepted = result == QWizard.DialogCode.Accepted and self.calibration is not None
        if self.busy:  # stop the worker before the rig closes and the pages go
            self.cancel_requested = True
            finish_job(self.job)
        if accepted:
            self.result_session = self.session
        if not (accepted and self.keep_rig):
            self._close_rig()
        super().done(result)
        if accepted:
            self.finished_session.emit(self.session)
