"""The wizard's exposure page: a live view grabbed on a worker, exposure controls and auto exposure.

The logic (what to apply, judging frames, auto-exposure steps) is the Qt-free
:class:`app.model.exposure.ExposureController`; this page binds it to widgets and runs the
live loop while the page is on screen — also after Back from a later page.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QSignalBlocker, Qt, QTimer
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QGridLayout,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QVBoxLayout,
    QWizardPage,
)

from app.model.exposure import LEVELS, ExposureController, judge
from app.qt.calibration_wizard.common import RED, error_text, esc, red
from app.qt.rig_views import LiveView
from app.qt.worker import LatestWorker, rig_lock, worker_rig
from devices.qtscreen import identify_pattern

_LEVEL_LABELS = ("white (what calibration checks)", "black (ambient light only)",
                 "identify (grid and centre cross: check pose and focus)")


class ExposurePage(QWizardPage):
    """Live view on a worker, exposure control, saturation overlay and the exposure report."""

    def __init__(self, wizard):
        super().__init__()
        self.setObjectName("wizard_exposure_page")
        self.setTitle("Camera exposure")
        self.setSubTitle("Under projector white, nothing on the surfaces to edit may clip (magenta), and "
                         "the darkest of them should stay well above black.")
        self.w = wizard
        self.live = LiveView()
        self.live.setObjectName("wizard_live_view")
        self.exposure = QDoubleSpinBox(decimals=3, minimum=0.001, maximum=3_600_000.0, suffix=" ms",
                                       objectName="wizard_exposure")
        self.exposure.setStepType(QDoubleSpinBox.StepType.AdaptiveDecimalStepType)
        self.exposure.setKeyboardTracking(False)
        shorter = QPushButton("÷2", objectName="wizard_exposure_shorter")
        longer = QPushButton("×2", objectName="wizard_exposure_longer")
        longer.clicked.connect(lambda: self.exposure.setValue(self.exposure.value() * 2))
        shorter.clicked.connect(lambda: self.exposure.setValue(self.exposure.value() / 2))
        self.auto_button = QPushButton("Auto", objectName="wizard_auto_exposure")
        self.auto_button.setToolTip("Adjust the exposure until the brightest projector-lit surfaces sit just "
                                    "below clipping (a lamp in view may still clip: it is not projector light)")
        self.auto_button.clicked.connect(self.start_auto)
        self.level = QComboBox(objectName="wizard_projector_level")
        self.level.addItems(_LEVEL_LABELS)
        self.overlay = QCheckBox("show saturated pixels", checked=True, objectName="wizard_show_saturation")
        self.overlay.toggled.connect(self.live.set_show_saturation)
        self.report = QLabel("waiting for the camera…", objectName="wizard_exposure_report")
        self.report.setWordWrap(True)
        lines = self.report.fontMetrics().lineSpacing()
        self.report.setFixedHeight(4 * lines + 4)  # the controls above must not move under the mouse
        self.report.setAlignment(self.report.alignment() | Qt.AlignmentFlag.AlignTop)
        controls = QGridLayout()  # two rows: fits a 1366×768 screen with long labels
        row = QHBoxLayout()
        for w in (QLabel("Exposure"), self.exposure, shorter, longer, self.auto_button):
            row.addWidget(w)
        row.addStretch(1)
        controls.addLayout(row, 0, 0)
        row = QHBoxLayout()
        for w in (QLabel("Projector"), self.level, self.overlay):
            row.addWidget(w)
        row.addStretch(1)
        controls.addLayout(row, 1, 0)
        lay = QVBoxLayout(self)
        lay.addWidget(self.live, 1)
        lay.addLayout(controls)
        lay.addWidget(self.report)
        self.exposure.valueChanged.connect(self._on_exposure_edited)
        self.level.currentIndexChanged.connect(self._on_level_chosen)
        self.timer = QTimer(self)
        self.timer.timeout.connect(self._tick)
        self.worker: LatestWorker | None = None
        self.controller = ExposureController(exposure=None)
        self.grabbed_on = ""  # name of the thread that grabbed the last frame (tests, diagnostics)
        self._shown = None  # the projector level the worker last applied
        self._patterns: dict = {}  # projector images of the levels, by (level, rig, resolution)

    # -- the page's life -------------------------------------------------------------------
    def initializePage(self) -> None:  # noqa: N802 (Qt name)
        cam = self.w.rig.camera
        exposure = getattr(cam, "exposure", None)
        self.controller = ExposureController(exposure=exposure)
        self.exposure.setEnabled(exposure is not None)
        self.auto_button.setEnabled(exposure is not None)
        self._sync()
        self.live.reset_scale()

    @property
    def auto(self):
        """The running auto exposure (None when it is not running)."""
        return self.controller.auto

    def start_live(self) -> None:
        """Grab frames on a worker while the page is on screen (the wizard calls it when it is shown)."""
        if self.worker is not None or self.w.rig is None:
            return
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
        exposure, level = self.controller.request()
        self.worker.submit((exposure, level, self._pattern(level), self.controller.black))

    def _pattern(self, level: str) -> np.ndarray:
        """The projector image of ``level`` (made once per rig and level)."""
        hp, wp = self.w.rig.projector.resolution
        key = (level, self.w.rig.name, hp, wp)
        if key not in self._patterns:
            self._patterns[key] = (identify_pattern((hp, wp), label=f"{self.w.rig.name}  {wp}x{hp}")
                                   if level == "identify"
                                   else np.full((hp, wp, 3), 1.0 if level == "white" else 0.0, np.float32))
        return self._patterns[key]

    # -- controls → controller -------------------------------------------------------------
    def _on_exposure_edited(self, ms: float) -> None:
        self.controller.set_exposure(ms / 1000.0)
        self._sync()

    def _on_level_chosen(self, index: int) -> None:
        self.controller.set_level(LEVELS[index])
        self._sync()

    def start_auto(self) -> None:
        """Auto exposure: a frame under projector black, then steps under white (a few frames)."""
        refusal = self.controller.start_auto()
        if refusal:
            self.report.setText(red(refusal))
        self._sync()

    def _sync(self) -> None:
        """Controller → controls (without echoing back)."""
        c = self.controller
        with QSignalBlocker(self.exposure), QSignalBlocker(self.level):
            if c.exposure is not None:
                self.exposure.setValue(c.exposure * 1000.0)
            self.level.setCurrentIndex(LEVELS.index(c.level))
        self.auto_button.setEnabled(c.exposure is not None and not c.running)
        self.auto_button.setText("Auto…" if c.running else "Auto")

    # -- frames (UI thread) ----------------------------------------------------------------
    def _on_frame(self, _rid: int, f) -> None:
        if f is None:  # the rig was busy
            return
        self.grabbed_on = f.thread
        self.live.set_frame(f.image, f.saturated, exposure=f.exposure, gain=f.gain, full_scale=f.full_scale)
        self.controller.on_frame(f)
        self._sync()
        text, ok = self.controller.status(f)
        body = esc(text).replace("\n", "<br>")
        self.report.setText(body if ok else f"<span style='color:{RED}'>{body}</span>")

    def _on_grab_failed(self, _rid: int, exc) -> None:
        self.report.setText(red(f"Camera: {error_text(exc)}"))

    # -- worker side -----------------------------------------------------------------------
    def _grab(self, request):
        """One live frame (worker thread): apply exposure and projector level, capture, judge."""
        rig = self.w.rig
        lock = rig_lock(rig)
        if not lock.acquire(blocking=False):
            return None
        try:
            exposure, level, pattern, black = request
            cam = rig.camera
            if exposure is not None and not np.isclose(getattr(cam, "exposure", exposure), exposure, rtol=1e-6):
                cam.exposure = exposure
            if self._shown != level:
                worker_rig(rig, self.w.ui).projector.show(pattern)
                self._shown = level
            return judge(cam.capture(), level, exposure, black)
        finally:
            lock.release()
