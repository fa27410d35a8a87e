"""The wizard's last three pages: calibrate (or reuse a calibration), its results, a summary."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QButtonGroup,
    QCheckBox,
    QFileDialog,
    QGridLayout,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QRadioButton,
    QSpinBox,
    QTextBrowser,
    QVBoxLayout,
    QWidget,
    QWizardPage,
)

from app.qt.calibration_wizard.common import error_text, esc, fix_for, red
from app.qt.rig_views import CoverageMap, ResponsePlot
from app.qt.worker import JobProgress
from engine.acquire import calibration_budget
from engine.errors import SessionError
from engine.workflow import load_calibration

#: Page ids, in order.
PAGE_RIG, PAGE_PROJECTOR, PAGE_EXPOSURE, PAGE_CALIBRATE, PAGE_RESULTS, PAGE_SUMMARY = range(6)


# ---------------------------------------------------------------------------------- page 4: calibrate
class CalibrationPage(QWizardPage):
    """Run the calibration (or reuse another session's), with progress, pause and cancel."""

    def __init__(self, wizard):
        super().__init__()
        self.setTitle("Calibrate")
        self.setSubTitle("Black, white, the Gray code and a grey ramp. Each capture is written to the session as "
                         "it is taken: a cancelled or crashed calibration resumes where it stopped.")
        self.w = wizard
        self.setObjectName("wizard_calibrate_page")
        self.mode_run = QRadioButton("Calibrate now", objectName="wizard_mode_run")
        self.mode_reuse = QRadioButton("Use the calibration of an existing session (same rig)",
                                       objectName="wizard_mode_reuse")
        self.mode_run.setChecked(True)
        group = QButtonGroup(self)
        group.addButton(self.mode_run)
        group.addButton(self.mode_reuse)

        self.levels = QSpinBox(minimum=3, maximum=256, value=17, objectName="wizard_levels")
        self.levels.setMaximumWidth(90)
        self.crosstalk = QCheckBox("also measure colour crosstalk (3 more captures)", objectName="wizard_crosstalk")
        self.start = QPushButton("Start", objectName="calibrate_start")
        self.eta = JobProgress("calibrate_progress", unit="captures", stacked=True, buttons=False)
        self.pause, self.cancel = self.eta.pause, self.eta.cancel
        self.info = QLabel(objectName="wizard_calibrate_info")
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

        self.reuse_path = QLineEdit(objectName="wizard_reuse_path")
        self.reuse_path.setPlaceholderText("a calibrated session folder")
        browse = QPushButton("Browse…", objectName="wizard_reuse_browse")
        browse.clicked.connect(self._on_browse)
        self.use = QPushButton("Use it", objectName="wizard_reuse_use")
        reuse_box = QWidget()
        row = QHBoxLayout(reuse_box)
        row.setContentsMargins(24, 0, 0, 0)
        row.addWidget(self.reuse_path, 1)
        row.addWidget(browse)
        row.addWidget(self.use)
        self.reuse_box = reuse_box

        self.status = QLabel(objectName="wizard_calibrate_status")
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
                self.status.setText(red(f"The session's calibration cannot be read: {error_text(exc)}"))
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
        return PAGE_RESULTS if self.w.calibration is not None else PAGE_SUMMARY

    # -- run -----------------------------------------------------------------------------
    def _on_start(self) -> None:
        self.status.clear()
        self.w.start_calibration(levels=self.levels.value(), crosstalk=self.crosstalk.isChecked())

    def _on_cancel(self) -> None:
        if self.w.job is not None:
            self.w.cancel_requested = True

    def on_finished(self, calibration) -> None:
        self.status.setText(f"Calibrated. {esc(calibration.metadata.get('coverage', ''))}")

    def on_failed(self, exc) -> None:
        self.status.setText(red(error_text(exc)) + "<br>" + esc(fix_for(exc)) +
                            " Next shows a summary.")

    def on_cancelled(self, _exc) -> None:
        have = sum(1 for c in self.w.session.captures if c.name.startswith("cal-"))
        self.status.setText(f"Cancelled. The {have} captures taken so far are kept in the session: "
                            "press Resume to continue where it stopped.")

    # -- reuse ---------------------------------------------------------------------------
    def _on_browse(self) -> None:
        path = QFileDialog.getExistingDirectory(self, "Calibrated session", self.reuse_path.text())
        if path:
            self.reuse_path.setText(path)

    def _on_use(self) -> None:
        ok, message = self.w.reuse_calibration(self.reuse_path.text().strip())
        self.status.setText(esc(message) if ok else red(message))
        self._update()


# ---------------------------------------------------------------------------------- page 5: results
class ResultsPage(QWizardPage):
    """The measured response and where the Gray code decoded."""

    def __init__(self, wizard):
        super().__init__()
        self.setObjectName("wizard_results_page")
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
        self.coverage_text.setText(f"Coverage: {esc(cal.correspondence.summary())}")
        self.exposure_text.setText(f"Exposure: {esc(str(cal.metadata.get('exposure', 'not recorded')))}")


# ---------------------------------------------------------------------------------- page 6: summary
class SummaryPage(QWizardPage):
    """What was done, what failed and how to fix it."""

    def __init__(self, wizard):
        super().__init__()
        self.setObjectName("wizard_summary_page")
        self.setTitle("Summary")
        self.setSubTitle("What was measured, and anything to fix before acquiring.")
        self.w = wizard
        self.text = QTextBrowser(objectName="wizard_summary")
        self.text.setOpenLinks(False)
        QVBoxLayout(self).addWidget(self.text)

    def initializePage(self) -> None:  # noqa: N802 (Qt name)
        self.text.setHtml(self.w.summary_html())
