"""The acquisition panel: capture a target (or a cascade of targets) into a calibrated session.

A dockable widget over :func:`engine.workflow.run_capture`. The caller gives the rig, the
session and the targets in cascade order with the fixed κ of all but the last; the panel
offers the order, adaptive capture (Sec. 5), per-channel or RGB emission and frame averaging,
runs the capture on a worker with progress, time left, pause and cancel, and shows each
capture as a thumbnail as it arrives. Every finished capture is already in the session, so
a cancel, a crash or a quit loses nothing: Resume (or a new panel on the same session) runs
the same plan again and the session serves back what it holds.
"""

from __future__ import annotations

import html

import numpy as np
from PySide6.QtCore import Signal
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QMessageBox,
    QPushButton,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from app.qt.rig_views import ThumbnailStrip
from app.qt.worker import Job, JobProgress, UiCaller, run_on_rig
from engine.acquire import CAPTURE_PREFIX, Adaptive, CaptureSettings
from engine.calibrate.graycode import fill_correspondence
from engine.errors import InputError, SessionError
from engine.text import counted
from engine.workflow import Unreachable, check_rig, estimated_report, load_calibration, preflight, run_capture
from engine.workflow.calibration import ACQUISITION_GROUP, PHOTOGRAPH_PATTERN

__all__ = ["AcquisitionPanel", "POLICIES", "unreachable_target_pixels"]

#: Adaptive-capture choices: (label, engine policy).
POLICIES = (("brute force (capture everything)", "brute"), ("linear prediction (paper)", "linear"),
            ("span prediction", "span"))
_EMISSIONS = (("one primary at a time (3 shots per step)", True), ("RGB at once, crosstalk-corrected", False))
_RED = "#c0392b"


def _esc(text: str) -> str:
    """Escape text for a rich-text label (quotes stay readable)."""
    return html.escape(text, quote=False)


def unreachable_target_pixels(calibration, mask: np.ndarray) -> np.ndarray:
    """Target pixels the projector cannot reach: no correspondence, even after filling.

    Undecoded pixels surrounded by decoded ones of the same target (concave corners) get a
    projector pixel from their neighbours (:func:`engine.calibrate.graycode.fill_correspondence`);
    the rest cannot be re-lit and make a target unusable.

    Parameters
    ----------
    calibration : engine.calibrate.Calibration
    mask : (H, W) bool

    Returns
    -------
    (H, W) bool
    """
    mask = np.asarray(mask, bool)
    filled, _ = fill_correspondence(calibration.correspondence, mask)
    return mask & ~filled.valid


class AcquisitionPanel(QWidget):
    """Acquire the observations of the last of some targets (Sec. 3.3–5), on a worker.

    Parameters
    ----------
    rig : devices.base.Rig, optional
        An open rig (the panel never closes it).
    session : engine.session.Session, optional
        A session holding the rig's calibration (see :class:`app.qt.calibration_wizard.CalibrationWizard`).
    targets : sequence of (str, (H, W) bool)
        Targets in cascade order; the last one is acquired, the others are recolored by their
        ``fixed_kappa`` first (Sec. 4).
    fixed_kappa : sequence of float or (3,)
        κ of every target but the last.
    parent : QWidget, optional
    synchronous : bool
        Run the capture on the UI thread (tests).
    thumb_size : int
        Thumbnail side in pixels.

    Signals
    -------
    acquired(object)
        The :class:`engine.acquire.CascadeResult`; its decomposition is cached in the session
        (:func:`engine.workflow.load_decomposition`).
    failed(object)
        The exception of a failed run (also shown in a dialog).
    cancelled()
        A run stopped on Cancel; its captures stay in the session.
    refused(str)
        Start was refused (also shown in a dialog): the reason.
    started(object)
        The :class:`app.qt.worker.Job` of a run.
    busy_changed(bool)
        A run started / ended (the main window locks editing meanwhile).
    thumbnail_added(str)
        A capture's thumbnail arrived (its name).
    """

    acquired = Signal(object)
    failed = Signal(object)
    cancelled = Signal()
    refused = Signal(str)
    started = Signal(object)
    busy_changed = Signal(bool)
    thumbnail_added = Signal(str)
    _thumbnail_ready = Signal(str, object)

    title = "Acquisition"

    def __init__(self, rig=None, session=None, targets=(), fixed_kappa=(), *, parent: QWidget | None = None,
                 synchronous: bool = False, thumb_size: int = 72):
        super().__init__(parent)
        self.synchronous = bool(synchronous)
        self.ui = UiCaller(self)
        self.rig = rig
        self.session = None
        self.targets: list[tuple[str, np.ndarray]] = []
        self.fixed_kappa: list = []
        self.job: Job | None = None
        self._cancelling = False
        self._conflict = False
        self._error_shown = False
        #: ``branch(reason) -> Session or None``: asked when the session holds another plan; a new
        #: session to acquire into (the owner asks the user), or None to stay refused.
        self.branch = None
        self._left_out: list[str] = []
        self.result = None

        self.order = QSpinBox(minimum=1, maximum=8, value=4, objectName="acquire_order")
        self.order.setToolTip("K: the photograph plus K−1 re-emissions per target (a K-th order decomposition)")
        self.policy = QComboBox(objectName="acquire_policy")
        for label, _ in POLICIES:
            self.policy.addItem(label)
        self.threshold = QDoubleSpinBox(decimals=2, minimum=0.01, maximum=50.0, value=1.0, suffix=" %",
                                        objectName="acquire_threshold")
        self.threshold.setToolTip("relative error accepted for a predicted capture (paper: 1 %)")
        self.emission = QComboBox(objectName="acquire_emission")
        for label, _ in _EMISSIONS:
            self.emission.addItem(label)
        self.frames = QSpinBox(minimum=1, maximum=256, value=1, objectName="acquire_frames")
        self.frames.setToolTip("frames averaged per capture: noise falls as 1/√frames")
        self.flood = QDoubleSpinBox(decimals=0, minimum=0.0, maximum=100.0, value=0.0, suffix=" %",
                                    objectName="acquire_flood")
        self.flood.setSpecialValueText("off: the scene's own light")
        self.flood.setToolTip("photograph the scene under a uniform projector flood of this level, for a scene lit "
                              "by the projector alone (the paper's Figs. 3, 8 and 11); off photographs it under "
                              "projector black. A rig that knows its scene's light sets it.")
        self.leave_out = QCheckBox("Leave out target pixels the projector cannot reach", objectName="acquire_leave_out")
        self.leave_out.setToolTip("otherwise Start refuses a target with such pixels; left-out pixels keep "
                                  "their colour when the target is recolored")
        form = QFormLayout()
        form.addRow("Order", self.order)
        form.addRow("Adaptive", self.policy)
        form.addRow("Threshold", self.threshold)
        form.addRow("Emission", self.emission)
        form.addRow("Frames averaged", self.frames)
        form.addRow("Photograph flood", self.flood)
        form.addRow(self.leave_out)

        self.targets_label = QLabel(objectName="acquire_targets")
        self.targets_label.setWordWrap(True)
        self.start_button = QPushButton("Start", objectName="acquire_start")
        self.eta = JobProgress("acquire_progress", unit="camera shots", stacked=True, buttons=False)
        self.pause_button, self.cancel_button = self.eta.pause, self.eta.cancel
        buttons = QHBoxLayout()
        for b in (self.start_button, self.pause_button, self.cancel_button):
            buttons.addWidget(b)
        buttons.addStretch(1)
        self.thumbnails = ThumbnailStrip(size=thumb_size)
        self.thumbnails.setObjectName("acquire_thumbnails")
        self.status = QLabel(objectName="acquire_status")
        self.status.setWordWrap(True)

        lay = QVBoxLayout(self)
        lay.addWidget(self.targets_label)
        lay.addLayout(form)
        lay.addLayout(buttons)
        lay.addWidget(self.eta)
        lay.addWidget(self.thumbnails)
        lay.addWidget(self.status)
        lay.addStretch(1)

        self.policy.currentIndexChanged.connect(self._update)
        self.start_button.clicked.connect(self.start)
        self._thumbnail_ready.connect(self._on_thumbnail)
        self.set_targets(targets, fixed_kappa)
        self.set_session(session)
        self.set_rig(rig)  # its scene's light sets the photograph's flood

    # ------------------------------------------------------------------ inputs
    @property
    def busy(self) -> bool:
        return self.job is not None and self.job.running

    def set_rig(self, rig) -> None:
        """Use ``rig`` for the next run (not while one runs); a rig that knows its scene's light sets the
        photograph's flood, unless the session holds a plan (which keeps its own)."""
        if self.busy:
            raise InputError("cannot change the rig while an acquisition runs")
        self.rig = rig
        if rig is not None and not (self.session is not None and self.session.state.get("plan")):
            self._scene_flood(unknown=0.0)
        self._update()

    def _scene_flood(self, unknown: float | None = None) -> None:
        """Set the photograph's flood (percent) to the natural light of the rig's scene; to ``unknown`` for a
        rig that does not know its scene (None: leave it as the user set it)."""
        lighting = getattr(self.rig, "lighting", None)
        level = unknown if lighting is None else 100.0 * float(lighting.get("projector_flood", 0.0))
        if level is not None:
            self.flood.setValue(level)

    def set_session(self, session) -> None:
        """Use ``session``; an interrupted plan in it sets the controls so Resume continues it."""
        if self.busy:
            raise InputError("cannot change the session while an acquisition runs")
        self.session = session
        self.status.clear()
        plan = None if session is None else session.state.get("plan")
        if plan:
            self.order.setValue(int(plan["order"]))
            self.emission.setCurrentIndex(0 if plan["settings"].get("per_channel", True) else 1)
            adaptive = plan.get("adaptive")
            policy = "brute" if adaptive is None else adaptive["policy"]
            self.policy.setCurrentIndex([p for _, p in POLICIES].index(policy))
            if adaptive is not None:
                self.threshold.setValue(100.0 * float(adaptive["threshold"]))
            self.flood.setValue(_flood_level(session) if plan.get("photograph_pattern") else 0.0)
            kept = len(self._plan_captures())
            if session.state.get("status") == "captured":
                self._note(f"This session holds an acquisition of {', '.join(plan['targets'])} "
                           f"(order {plan['order']}); Start shows it again without new captures.")
            else:
                self._note(f"An interrupted acquisition of {', '.join(plan['targets'])} (order {plan['order']}) "
                           f"is in this session with {counted(kept, 'capture')}: Resume continues it.")
        else:  # the previous session's plan no longer sets the flood
            self._scene_flood()
        self._update()

    def set_targets(self, targets, fixed_kappa=()) -> None:
        """Targets in cascade order as (name, mask), and the fixed κ of all but the last.

        A mask is ``(H, W)`` bool, or float coverage for a target with a soft edge.

        The masks are not copied (the panel follows a document's targets as they are painted);
        a run captures them as they are when it starts, and editing is locked while it runs.
        """
        if self.busy:
            raise InputError("cannot change the targets while an acquisition runs")
        self.targets = [(str(n), m if np.asarray(m).dtype.kind == "f" else np.asarray(m, bool)) for n, m in targets]
        if self._error_shown:  # a refusal was about the targets as they were
            self._note("")
        self.fixed_kappa = [np.broadcast_to(np.asarray(k, float), (3,)).copy() for k in fixed_kappa]
        self._update()

    # ------------------------------------------------------------------ settings
    def capture_settings(self) -> CaptureSettings:
        return CaptureSettings(per_channel=_EMISSIONS[self.emission.currentIndex()][1])

    def photograph_pattern(self) -> np.ndarray | None:
        """The projector pattern the photograph is taken under: a uniform flood, or None (projector black)."""
        level = self.flood.value() / 100.0
        if level <= 0 or self.rig is None:
            return None
        return np.full((*self.rig.projector.resolution, 3), level, np.float32)

    def adaptive(self) -> Adaptive | None:
        policy = POLICIES[self.policy.currentIndex()][1]
        return None if policy == "brute" else Adaptive(policy, self.threshold.value() / 100.0)

    def _plan_captures(self) -> list[str]:
        if self.session is None:
            return []
        return [c.name for c in self.session.captures if c.name.startswith(f"{CAPTURE_PREFIX}-")]

    def check_ready(self) -> str:
        """Why a run cannot start now, in plain words; ``""`` when it can."""
        return self._prepare()[0]

    def _prepare(self) -> tuple[str, list, dict[str, int]]:
        """(refusal reason or "", the targets to acquire, pixels left out per target)."""
        self._conflict = False
        if self.busy:
            return f"{self.job.name} is still running.", [], {}
        if self.rig is None:
            return "No rig is open: open and calibrate one first (Rig ▸ Calibrate Rig…).", [], {}
        if self.session is None:
            return "No session: calibrate the rig first (Rig ▸ Calibrate Rig…).", [], {}
        calibrated = bool(self.session.read_calibration()[0])
        if calibrated:
            try:
                check_rig(load_calibration(self.session), self.rig)
            except (InputError, SessionError) as exc:  # made for another set-up (e.g. another resolution)
                self._conflict = True
                return f"{exc}.", [], {}
        try:
            checked = preflight(
                self.rig, self.session, self.targets, int(self.order.value()), fixed_kappa=self.fixed_kappa,
                settings=self.capture_settings(), adaptive=self.adaptive(), frames=int(self.frames.value()),
                photograph_pattern=self.photograph_pattern(),
                unreachable=Unreachable.LEAVE_OUT if self.leave_out.isChecked() else Unreachable.REFUSE)
        except SessionError as exc:
            # preflight's SessionErrors: no calibration, or another plan in this (calibrated) session
            self._conflict = calibrated and self.session.state.get("plan") is not None
            return str(exc), [], {}
        except InputError as exc:
            return str(exc), [], {}
        return "", checked.targets, checked.left_out

    # ------------------------------------------------------------------ run
    def start(self) -> Job | None:
        """Start (or resume) the acquisition; None and a dialog if it cannot start."""
        reason, targets, left_out = self._prepare()
        if reason and self._conflict and self.branch is not None:
            branched = self.branch(reason)  # the owner offers a new session folder
            if branched is None:
                self._note(reason, error=True)
                return None
            self.set_session(branched)
            reason, targets, left_out = self._prepare()
        if reason:
            self._note(reason, error=True)
            self.refused.emit(reason)
            QMessageBox.warning(self, "Cannot start the acquisition", reason)
            return None
        self.result = None
        size = self.thumbnails.thumb_size
        self.thumbnails.clear()

        def on_capture(name, image):  # worker thread: downscale there, paint on the UI thread
            self._thumbnail_ready.emit(name, ThumbnailStrip.make_thumbnail(image, size))

        resumed = len(self._plan_captures())
        job = Job(run_on_rig, run_capture, self.rig, self.session, targets, int(self.order.value()),
                  caller=self.ui, fixed_kappa=[k.copy() for k in self.fixed_kappa],
                  settings=self.capture_settings(), adaptive=self.adaptive(), frames=int(self.frames.value()),
                  photograph_pattern=self.photograph_pattern(), on_capture=on_capture, name="Acquiring",
                  synchronous=self.synchronous)
        job.finished.connect(self._on_finished)
        job.failed.connect(self._on_failed)
        job.cancelled.connect(self._on_cancelled)
        job.ended.connect(lambda: self._on_ended(job))
        self.job = job
        self._cancelling = False
        notes = [f"{counted(resumed, 'capture')} already in the session reused." if resumed else "Acquiring…"]
        self._left_out = [f"{n} pixels of {name!r} the projector cannot reach were left out."
                          for name, n in left_out.items()]
        notes += self._left_out
        self._note("\n".join(notes))
        self.busy_changed.emit(True)
        self.eta.attach(job)
        self.started.emit(job)
        job.start()
        if self.busy:  # threaded: lock the controls until it ends (a synchronous run has ended already)
            self._update()
        return job

    def pause(self) -> None:
        """Hold the run before its next capture (the projector keeps its pattern)."""
        if self.busy and not self._cancelling:  # a pause after a cancel would hold the worker forever
            self.job.pause()

    def resume(self) -> None:
        """Continue a paused run."""
        if self.busy:
            self.job.resume()

    def cancel(self) -> None:
        """Stop the run at the next capture; what was captured stays in the session."""
        if self.busy:
            self._cancelling = True
            self.job.cancel()

    def shutdown(self, *, timeout: float = 15.0) -> bool:
        """Cancel any run and wait for it to stop (captures taken are kept); True once idle.

        Called by :meth:`closeEvent`; call it before deleting a panel that was never shown.
        """
        if not self.busy:
            return True
        self._cancelling = True
        return self.job.wait(timeout, cancel=True)

    def closeEvent(self, event) -> None:  # noqa: N802 (Qt name)
        self.shutdown()
        super().closeEvent(event)

    # ------------------------------------------------------------------ job signals (UI thread)
    def _on_thumbnail(self, name: str, rgb) -> None:
        self.thumbnails.add_thumbnail(name, rgb)
        self.thumbnail_added.emit(name)

    def _on_finished(self, result) -> None:
        self.result = result
        lines = [f"Captured {result.report(result.shots)}."]
        lines += self._left_out + [f"{name}: {prepared.report()}" for name, prepared in result.targets]
        if self.session is not None and (line := estimated_report(self.session)):
            lines.append(line + ".")
        self._note("\n".join(lines))
        self.acquired.emit(result)

    def _on_failed(self, exc) -> None:
        message = str(exc) or type(exc).__name__
        self._note(message, error=True)
        self.failed.emit(exc)
        QMessageBox.critical(self, "Acquisition failed", message)

    def _on_cancelled(self, _exc) -> None:
        kept = len(self._plan_captures())
        self._note(f"Cancelled. The {counted(kept, 'capture')} taken so far stay in the session: Resume continues "
                   "where it stopped.")
        self.cancelled.emit()

    def _on_ended(self, job: Job) -> None:
        if self.job is job:
            self.job = None
        self._update()
        self.busy_changed.emit(False)

    # ------------------------------------------------------------------ display
    def _note(self, text: str, *, error: bool = False) -> None:
        self._error_shown = error
        body = _esc(text).replace("\n", "<br>")
        self.status.setText(f"<span style='color:{_RED}'>{body}</span>" if error else body)

    def _update(self) -> None:
        busy = self.busy
        for w in (self.order, self.policy, self.emission, self.frames, self.flood, self.leave_out):
            w.setEnabled(not busy)
        self.threshold.setEnabled(not busy and POLICIES[self.policy.currentIndex()][1] != "brute")
        self.start_button.setEnabled(not busy)
        interrupted = (self.session is not None and self.session.state.get("plan") is not None
                       and self.session.state.get("status") != "captured" and bool(self._plan_captures()))
        self.start_button.setText("Resume" if interrupted and not busy else "Start")
        if self.targets:
            parts = [f"{_esc(n)} (κ fixed {', '.join(f'{v:g}' for v in k)})"
                     for (n, _), k in zip(self.targets[:-1], self.fixed_kappa, strict=False)]
            parts.append(f"<b>{_esc(self.targets[-1][0])}</b> (κ free)")
            self.targets_label.setText("Targets: " + " → ".join(parts))
        else:
            self.targets_label.setText("No target yet: paint one.")


def _flood_level(session) -> float:
    """The flood (percent) an acquisition in ``session`` photographed its scene under (0 when unknown)."""
    try:
        pattern = session.read_array(ACQUISITION_GROUP, PHOTOGRAPH_PATTERN)
    except SessionError:  # not stored (a session captured before patterns were kept) or unreadable
        return 0.0
    return 100.0 * float(np.mean(pattern))
