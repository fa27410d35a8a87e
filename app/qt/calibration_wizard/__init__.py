"""The calibration wizard: choose a rig, set the exposure, calibrate into a session, review.

Pages, in order (one module each pair):

1. **Rig** (:mod:`.setup_pages`) — what :func:`devices.available` lists (unavailable rigs
   greyed, with the reason), the virtual rig's options, and the session folder (an existing
   session resumes). It starts from the open rig, else the document's rig and resolution, else
   the wizard's last choices (QSettings).
2. **Projector** — the screen the projector window opens on, when the backend has one.
   Leaving this page opens the rig (on a worker) and the session.
3. **Exposure** (:mod:`.exposure_page`) — a live view grabbed on a worker while the page is on
   screen, saturated pixels in magenta, the exposure report in words, auto exposure.
4. **Calibrate** (:mod:`.calibration_pages`) — :func:`engine.workflow.run_calibration` on a
   worker with progress, time left, Pause/Resume and Cancel (finished captures stay in the
   session, so Start again — or a new wizard on the same folder — resumes), or reuse the
   calibration of another session of the same rig.
5. **Results** — the measured projector response and the Gray-code coverage map.
6. **Summary** — what was measured, what failed and how to fix it (engine messages verbatim).

On Finish with a calibration, :attr:`CalibrationWizard.finished_session` carries the session.
A wizard closed without a calibration deletes the session folder it created if nothing was
captured into it.
"""

from __future__ import annotations

import datetime as _dt
import shutil
from pathlib import Path

from PySide6.QtCore import QSettings, Signal
from PySide6.QtWidgets import QAbstractSpinBox, QLineEdit, QWidget, QWizard

import devices
from app.model.demo import DEMO_RIG
from app.model.document import camera_mismatch
from app.qt.calibration_wizard.calibration_pages import (
    PAGE_CALIBRATE,
    PAGE_EXPOSURE,
    PAGE_PROJECTOR,
    PAGE_RESULTS,
    PAGE_RIG,
    PAGE_SUMMARY,
    CalibrationPage,
    ResultsPage,
    SummaryPage,
)
from app.qt.calibration_wizard.common import NO_SCREEN_BACKENDS, SIMULATED, EnterCommits, error_text, esc, fix_for, red
from app.qt.calibration_wizard.exposure_page import ExposurePage
from app.qt.calibration_wizard.setup_pages import ProjectorPage, RigPage
from app.qt.layout import fit_to_screen
from app.qt.worker import Job, UiCaller, run_on_rig
from engine.errors import InputError
from engine.progress import checkpoint
from engine.session import Session
from engine.workflow import (
    adopt_calibration,
    calibration_problems,
    load_compatible_calibration,
    open_session_for_rig,
    run_calibration,
)

__all__ = ["CalibrationWizard"]

#: QSettings keys of the wizard's remembered choices.
SETTINGS = "wizard"


def _open_rig(name: str, options: dict, *, progress=None, should_stop=None):
    """Open a rig on a worker (simulated rigs report their set-up progress)."""
    checkpoint(should_stop, "opening the rig")
    if name.startswith(SIMULATED):
        options = dict(options, progress=progress)
    return devices.open_rig(name, **options)


class CalibrationWizard(QWizard):
    """Calibrate a camera–projector rig into a session folder.

    Parameters
    ----------
    parent : QWidget, optional
    rig : devices.base.Rig, optional
        An open rig to calibrate (the rig page then only asks for the session folder). The
        wizard never closes a rig it was given.
    rig_name : str, optional
        Preselect this rig on the first page (default: the last one chosen, else the demo's).
    rig_options : dict, optional
        Extra :func:`devices.open_rig` options for virtual rigs (``cache_dir``, ``seed``).
    photograph : (H, W), optional
        The open document's size: proposed as a simulated camera's resolution, and a camera of
        another size is warned about on the way and in the summary (its calibration cannot be
        used for the photograph's targets).
    session_path : str or Path, optional
        Session folder to propose (default: a new dated folder under ``sessions_dir``).
    sessions_dir : str or Path, optional
        Where new session folders are proposed (default: the last one, else ``~/Albedit/sessions``).
    settings : QSettings, optional
        Where the wizard remembers its choices (rig, virtual options, folders, ramp levels) on Finish.
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

    PAGE_RIG, PAGE_PROJECTOR, PAGE_EXPOSURE = PAGE_RIG, PAGE_PROJECTOR, PAGE_EXPOSURE
    PAGE_CALIBRATE, PAGE_RESULTS, PAGE_SUMMARY = PAGE_CALIBRATE, PAGE_RESULTS, PAGE_SUMMARY
    #: The size asked for on a large screen (smaller screens get their available area).
    PREFERRED_SIZE = (820, 640)

    def __init__(self, parent: QWidget | None = None, *, rig=None, rig_name: str | None = None,
                 rig_options: dict | None = None, photograph=None, session_path=None, sessions_dir=None,
                 settings: QSettings | None = None, keep_rig: bool = False, synchronous: bool = False,
                 live_interval_ms: int = 200):
        super().__init__(parent)
        self.setObjectName("calibration_wizard")
        self.setWindowTitle("Calibrate the rig")
        self.setWizardStyle(QWizard.WizardStyle.ClassicStyle)
        self.setOption(QWizard.WizardOption.NoBackButtonOnLastPage, True)
        fit_to_screen(self, self.PREFERRED_SIZE)
        self.settings = settings
        self.synchronous = bool(synchronous)
        self.live_interval_ms = int(live_interval_ms)
        self.keep_rig = bool(keep_rig)
        self.given_rig = rig
        self.photograph = None if photograph is None else (int(photograph[0]), int(photograph[1]))
        self.initial_rig_name = rig_name or self._remembered("rig") or DEMO_RIG
        self.rig_options = dict(rig_options or {})
        folder = sessions_dir or self._remembered("sessions_dir")
        self.sessions_dir = Path(folder) if folder else Path.home() / "Albedit" / "sessions"
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
        self._created: Path | None = None  # a session folder this wizard created

        self.rig_page = RigPage(self)
        self.projector_page = ProjectorPage(self)
        self.exposure_page = ExposurePage(self)
        self.calibration_page = CalibrationPage(self)
        self.results_page = ResultsPage(self)
        self.summary_page = SummaryPage(self)
        for pid, page in zip(range(6), (self.rig_page, self.projector_page, self.exposure_page,
                                        self.calibration_page, self.results_page, self.summary_page), strict=True):
            self.setPage(pid, page)
        self._restore_choices()
        if session_path is not None:
            self.rig_page.session_path.setText(str(session_path))
        for button, name in self.BUTTON_NAMES.items():
            self.button(button).setObjectName(name)
        self._enter = EnterCommits(self)
        for w in self.findChildren(QAbstractSpinBox) + self.findChildren(QLineEdit):
            w.installEventFilter(self._enter)
        self.currentIdChanged.connect(self._on_page)

    #: objectNames of the wizard's buttons (docs/ui.md).
    BUTTON_NAMES = {QWizard.WizardButton.BackButton: "wizard_back", QWizard.WizardButton.NextButton: "wizard_next",
                    QWizard.WizardButton.FinishButton: "wizard_finish",
                    QWizard.WizardButton.CancelButton: "wizard_cancel"}

    # -- remembered choices --------------------------------------------------------------
    def _remembered(self, key: str, default=None):
        return default if self.settings is None else self.settings.value(f"{SETTINGS}/{key}", default)

    def _restore_choices(self) -> None:
        page = self.rig_page
        page.ideal.setChecked(str(self._remembered("ideal", "true")).lower() == "true")
        page.pose.setCurrentText(str(self._remembered("pose", "coaxial")))
        h, w = self.photograph or (int(self._remembered("res_h", 128)), int(self._remembered("res_w", 128)))
        page.res_h.setValue(int(h))
        page.res_w.setValue(int(w))
        self.calibration_page.levels.setValue(int(self._remembered("levels", 17)))
        self.calibration_page.crosstalk.setChecked(str(self._remembered("crosstalk", "false")).lower() == "true")

    def _remember_choices(self) -> None:
        if self.settings is None:
            return
        page = self.rig_page
        for key, value in (("rig", page.rig_name.text().strip()), ("ideal", page.ideal.isChecked()),
                           ("pose", page.pose.currentText()), ("res_h", page.res_h.value()),
                           ("res_w", page.res_w.value()), ("levels", self.calibration_page.levels.value()),
                           ("crosstalk", self.calibration_page.crosstalk.isChecked())):
            self.settings.setValue(f"{SETTINGS}/{key}", value)
        if self.session is not None:
            self.settings.setValue(f"{SETTINGS}/sessions_dir", str(Path(self.session.path).parent))

    def rig_spec(self) -> tuple[str, dict]:
        """(name, JSON-able options) of the rig chosen on the first pages: how to reopen it."""
        name, options = self._spec()
        return name, {k: list(v) if isinstance(v, tuple) else v for k, v in options.items() if k != "cache_dir"}

    def _on_page(self, page_id: int) -> None:
        """The live view runs while the exposure page is on screen (also after Back from a later page)."""
        if page_id == self.PAGE_EXPOSURE and self.rig is not None:
            self.exposure_page.start_live()
        else:
            self.exposure_page.stop_live()

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
        if name.startswith(SIMULATED):
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
            page.status.setText(f"Opening {esc(name)}…")
            # Hardware backends open a Qt projector window, which only the UI thread may create.
            on_ui = self.synchronous or name.partition(":")[0] not in NO_SCREEN_BACKENDS
            job = Job(_open_rig, name, options, name=f"Opening {name}", synchronous=on_ui)
            page.eta.attach(job, pausable=False)

            def opened(rig):
                self.rig, self._opened = rig, key
                self.rig_opened.emit(rig)

            def failed(exc):
                page.status.setText(red(f"Cannot open {name}: {error_text(exc)}"))

            job.finished.connect(opened)
            job.failed.connect(failed)
            job.cancelled.connect(lambda exc: page.status.setText(str(exc)))
            job.ended.connect(lambda: self._job_ended(job))
            self._run(job)
            if self.busy:  # threaded: continue when it is done
                job.finished.connect(lambda _rig: self.currentId() == self.PAGE_PROJECTOR and self.next())
                return False
            if self.rig is None or self._opened != key:
                return False
        try:
            path = Path(self.rig_page.session_path.text().strip()).expanduser()
            if self.session is None or Path(self.session.path).resolve() != path.resolve():
                self._discard_created()
                new = not (path / "manifest.json").exists() and not (path.exists() and any(path.iterdir()))
                self.session = open_session_for_rig(path, self.rig)
                self._created = path if new else None
                self.calibration, self.failure = None, None
        except Exception as exc:  # noqa: BLE001 - shown on the page, engine's words
            self.session = None
            page.status.setText(red(error_text(exc)) + "<br>" + esc(fix_for(exc)))
            return False
        size = self.mismatch(self.rig.camera.resolution)
        page.status.setText(f"Opened {esc(self.rig.name)}; session {esc(str(self.session.path))}."
                            + (f"<br>{red(size + ': this calibration cannot be used for it.')}" if size else ""))
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
        job = Job(run_on_rig, run_calibration, self.rig, self.session, levels=levels, crosstalk=crosstalk,
                  caller=self.ui, name="Calibrating", synchronous=self.synchronous)
        page.eta.attach(job)
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
            calibration = load_compatible_calibration(path, self.rig)
            adopt_calibration(self.session, calibration)
        except Exception as exc:  # noqa: BLE001 - the refusal is shown in the engine's words
            return False, f"Refused: {error_text(exc)}"
        self.calibration, self.failure = calibration, None
        self.calibrated.emit(calibration)
        return True, f"Using the calibration of {path} ({calibration.metadata.get('coverage', '')})."

    def mismatch(self, camera_resolution) -> str:
        """Why a camera of ``camera_resolution`` cannot acquire the open photograph's targets, as a
        sentence; ``""`` when it can, or when no photograph is open."""
        if self.photograph is None:
            return ""
        why = camera_mismatch(self.photograph, camera_resolution)
        return why and f"{why[:1].upper()}{why[1:]}"

    # -- summary -------------------------------------------------------------------------
    def problems(self) -> list[tuple[str, str]]:
        """(what, how to fix) pairs for the summary page."""
        out = []
        size = "" if self.rig is None else self.mismatch(self.rig.camera.resolution)
        if size:
            out.append((size, "The calibration stays in its session folder for photographs this camera takes; the "
                              "open photograph keeps none. To acquire its targets, calibrate a camera of its size "
                              "(a simulated rig: its resolution on the first page)."))
        if self.failure is not None:
            out.append((error_text(self.failure), fix_for(self.failure)))
        if self.calibration is not None:
            out += calibration_problems(self.calibration)
        return out

    def summary_html(self) -> str:
        rows = []
        if self.rig is not None:
            rows.append(f"<b>Rig</b>: {esc(self.rig.name)}")
        if self.session is not None:
            rows.append(f"<b>Session</b>: {esc(str(self.session.path))}")
        cal = self.calibration
        if cal is not None:
            rows.append(f"<b>Calibrated</b>: {esc(str(cal.metadata.get('date', '')))} — "
                        f"{len([c for c in self.session.captures if c.name.startswith('cal-')])} captures")
            rows.append(f"<b>Coverage</b>: {esc(cal.correspondence.summary())}")
            rows.append(f"<b>Exposure</b>: {esc(str(cal.metadata.get('exposure', '')))}")
        else:
            rows.append(red("No calibration: the session cannot be used for acquisition yet."))
        problems = self.problems()
        if problems:
            items = "".join(f"<li>{red(what)}<br>{esc(fix)}</li>" for what, fix in problems)
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

    def _discard_created(self) -> None:
        """Delete the session folder this wizard created if nothing was captured or calibrated into it."""
        path, self._created = self._created, None
        session = self.session
        if path is None or session is None or Path(session.path) != path:
            return
        if not session.captures and not session.read_calibration()[0]:
            shutil.rmtree(path, ignore_errors=True)

    def done(self, result: int) -> None:
        self.exposure_page.stop_live()
        accepted = result == QWizard.DialogCode.Accepted and self.calibration is not None
        if self.busy:  # stop the worker before the rig closes and the pages go
            self.cancel_requested = True
            self.job.wait(15.0, cancel=True)
        if accepted:
            self.result_session = self.session
            self._remember_choices()
        else:
            self._discard_created()
        if not (accepted and self.keep_rig):
            self._close_rig()
        super().done(result)
        if accepted:
            self.finished_session.emit(self.session)
