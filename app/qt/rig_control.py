"""The Rig menu of the main window: the open rig, the calibration wizard and the acquisition dock.

:class:`RigControl` keeps the rig the user opened (the demo's, the wizard's, or the last one
reopened) independently of the document: opening another document keeps it open; Rig ▸ Close
Rig releases it and Rig ▸ Reopen opens it again with the same options (remembered in
QSettings, so also after a restart). The acquisition dock follows the open document — its
session, its targets (the included ones, in cascade order) and their κ — whenever any of them
changes, and the calibration wizard starts from the document's rig and resolution.
"""

from __future__ import annotations

import json
from datetime import datetime
from pathlib import Path

from PySide6.QtCore import QObject, Qt, QTimer
from PySide6.QtWidgets import QDockWidget, QMessageBox

from app.qt.acquisition_panel import AcquisitionPanel
from app.qt.layout import scrolling
from engine.errors import InputError, SessionError

#: QSettings keys.
LAST_RIG = "rig/last"


def _open_rig(name: str, options: dict, *, progress=None, should_stop=None):
    """Job body: open a rig (virtual set-ups report their build progress)."""
    import devices

    if name.startswith(("virtual:", "mitsuba:")):  # simulated rigs report their set-up progress
        options = dict(options, progress=progress)
    return devices.open_rig(name, **options)


class RigControl(QObject):
    """The rig side of a :class:`~app.qt.main_window.MainWindow`.

    Parameters
    ----------
    window : MainWindow
    rig : devices.base.Rig, optional
        An already open rig (closed with the window).

    Attributes
    ----------
    rig : Rig or None
        The open rig.
    last : (name, options) or None
        The rig to reopen (Rig ▸ Reopen).
    dock : QDockWidget or None
        The acquisition dock ("acquisition"), made on first use.
    """

    def __init__(self, window, rig=None):
        super().__init__(window)
        self.w = window
        self.last: tuple[str, dict] | None = self._load_last()
        self.dock: QDockWidget | None = None
        self.calibration = None  # a calibration made since that the document's session could not take
        self.panel: AcquisitionPanel | None = None
        self._watched = None
        self.rig = rig  # the window builds its actions after this: no update yet

    # ------------------------------------------------------------------ the rig
    def _load_last(self):
        raw = self.w.settings.value(LAST_RIG, "")
        try:
            name, options = json.loads(raw) if raw else (None, None)
        except (TypeError, ValueError):
            return None
        return (str(name), dict(options)) if name else None

    def adopt(self, rig, options: dict | None = None) -> None:
        """Use the open ``rig`` (closing another one); remember how to reopen it."""
        if rig is self.rig:
            return
        self._close()
        self.rig = rig
        if options is not None:
            self.last = (rig.name, options)
            self.w.settings.setValue(LAST_RIG, json.dumps([rig.name, options]))
        self.follow_document()
        self.w._update_actions()

    def _close(self) -> None:
        rig, self.rig = self.rig, None
        if self.panel is not None and not self.panel.busy:
            self.panel.set_rig(None)
        if rig is not None:
            try:
                rig.close()
            except Exception as exc:  # noqa: BLE001 - closing is best effort; the device says so on reopen
                self.w.statusBar().showMessage(f"Closing {rig.name}: {exc}", 8000)

    def close_rig(self) -> None:
        """Rig ▸ Close Rig: release the camera and projector (not while an acquisition runs)."""
        if self.panel is not None and self.panel.busy:
            self.w.statusBar().showMessage("An acquisition is running: cancel it before closing the rig", 8000)
            return
        self._close()
        self.w._update_actions()

    def reopen_rig(self, then=None) -> None:
        """Rig ▸ Reopen: open the last rig with its options (a job: virtual rigs build a set-up)."""
        if self.last is None:
            return
        name, options = self.last

        def done(rig):
            self.adopt(rig, options)
            self.w.statusBar().showMessage(f"Opened {name}", 5000)
            if then is not None:
                then()

        self.w.run_job(_open_rig, name, options, name=f"Opening {name}", on_done=done, pausable=False,
                       on_failed=lambda exc: self.w.show_error(f"Cannot open {name}", exc))

    def open_demo(self, rig_name: str | None = None, **rig_options) -> None:
        """The virtual-rig demo on a worker: its document, session and rig become the window's.

        Its resolution fills the canvas at ≤ 100 % (:func:`app.model.demo.demo_resolution`); its
        session lives in the user's cache folder beside the rigs' set-ups (:func:`app.model.demo.default_folder`,
        ``~/.cache/albedit/demo``) and is reused by the next start.
        """
        from app.model.demo import DEMO_RIG, demo_resolution, open_demo

        rig_name = rig_name or DEMO_RIG
        area = self.w.centralWidget()
        dpr = self.w.devicePixelRatioF()
        rig_options.setdefault("resolution", demo_resolution((int(area.height() * dpr), int(area.width() * dpr))))

        def done(demo):
            doc, session = demo.document, demo.session
            self.adopt(demo.rig, demo.options)
            self.w.set_document(doc, session, demo=session is not None)
            if session is not None:
                self.w.statusBar().showMessage(
                    f"Acquired {doc.targets[-1].name!r} on {rig_name} and recolored it as in the paper's Fig. 6; "
                    "try the κ sliders and the Error view", 15000)

        self.w.run_job(open_demo, rig_name, name=f"Opening the {rig_name} demo", on_done=done,
                       **rig_options)

    # ------------------------------------------------------------------ calibration
    def calibrate(self) -> None:
        """Rig ▸ Calibrate: the wizard, starting from the open rig or the document's rig and resolution."""
        from app.qt.calibration_wizard import CalibrationWizard

        doc, session = self.w.doc, self.w.session
        name = self.rig.name if self.rig is not None else None
        if name is None and session is not None and ":" in session.rig_name:  # not a plain photograph's
            name = session.rig_name
        if name is None and self.last is not None:
            name = self.last[0]
        wizard = CalibrationWizard(self.w, rig=self.rig, keep_rig=self.rig is None, rig_name=name,
                                   photograph=None if doc is None else doc.shape, settings=self.w.settings,
                                   synchronous=self.w.synchronous)
        wizard.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose)
        wizard.finished_session.connect(lambda s: self._on_calibrated(wizard, s))
        wizard.open()

    def _on_calibrated(self, wizard, session) -> None:
        """The document uses the new calibration: its session adopts it when it has none; a session
        calibrated otherwise is left as it is, and the next acquisition goes to a new session folder.
        A calibration of a camera of another size than the photograph is not used for it at all."""
        from engine.workflow import adopt_calibration, load_calibration

        if self.rig is None and wizard.rig is not None:
            self.adopt(wizard.take_rig(), wizard.rig_spec()[1])
        calibration = wizard.calibration
        mine, doc = self.w.session, self.w.doc
        size = "" if doc is None else doc.camera_mismatch(session.camera_resolution)
        if size:
            self.w.statusBar().showMessage(f"Calibrated into {session.path}; not used for the open photograph "
                                           f"({size})", 15000)
            self.w._update_actions()
            return
        if mine is None:
            self.w.session = session
        elif Path(mine.path).resolve() != Path(session.path).resolve():
            if not mine.read_calibration()[0]:
                adopt_calibration(mine, calibration)  # e.g. a photograph's session: acquisition can start
            elif load_calibration(mine).to_dict()[0] != calibration.to_dict()[0]:
                self.calibration = calibration  # taken into the new session folder of the next acquisition
        self.follow_document()
        self._remember_session()
        self.w.statusBar().showMessage(f"Calibrated into {session.path}", 10000)
        self.w._update_actions()

    # ------------------------------------------------------------------ acquisition
    def acquire(self) -> None:
        """Rig ▸ Acquire: the acquisition dock for the document's included targets (reopening the rig)."""
        doc = self.w.doc
        if doc is None:
            return
        if self.rig is None and self.last is not None:
            self.reopen_rig(then=self.acquire)
            return
        size = "" if self.rig is None else doc.camera_mismatch(self.rig.camera.resolution)
        try:
            if size:
                raise InputError(f"{size}: calibrate a camera of the photograph's size (Rig ▸ Calibrate Rig…), "
                                 "or open a photograph this camera took")
            doc.check_acquirable()
        except InputError as exc:
            self.w.show_error("Cannot acquire", exc)
            return
        cautions = doc.lamp_cautions()
        if cautions and QMessageBox.question(
                self.w, "Acquire a light source?", "\n".join(c[:1].upper() + c[1:] + "." for c in cautions)
                + "\n\nAcquire anyway?") != QMessageBox.StandardButton.Yes:
            self.w.statusBar().showMessage("Not acquired: " + cautions[0], 15000)
            return
        self._ensure_dock()
        self.follow_document()
        self.dock.show()
        self.dock.raise_()
        # a short dock (a 1024×700 screen) opens scrolled to Start, not to the settings above it
        QTimer.singleShot(0, lambda: self.dock is not None and self.dock.widget().ensureWidgetVisible(
            self.panel.start_button))

    def _ensure_dock(self) -> None:
        if self.dock is not None:
            return
        self.panel = AcquisitionPanel(self.rig, self.w.session, parent=self.w, synchronous=self.w.synchronous)
        self.panel.branch = self._branch
        self.panel.acquired.connect(self._on_acquired)
        self.panel.started.connect(lambda _job: self._remember_session())
        self.panel.busy_changed.connect(lambda busy: self.w._set_busy(busy))
        self.dock = QDockWidget("Acquisition", self.w, objectName="acquisition")
        area = scrolling(self.panel, "acquisition_scroll")
        self.dock.setWidget(area)
        # a short dock scrolls to what matters now: the progress while it runs, the outcome after
        self.panel.started.connect(lambda _job: area.ensureWidgetVisible(self.panel.eta))
        self.panel.busy_changed.connect(lambda busy: busy or area.ensureWidgetVisible(self.panel.status))
        self.w.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, self.dock)

    def follow_document(self) -> None:
        """Point the acquisition dock at the open document (its session, rig and targets)."""
        doc = self.w.doc
        if doc is not self._watched:
            if self._watched is not None:
                for sig in (self._watched.events.targets, self._watched.events.acquisition):
                    sig.disconnect(self._on_document_changed)
                self._watched.events.kappa.disconnect(self._on_kappa)
                self._watched.events.mask.disconnect(self._on_mask)
            if doc is not None:
                for sig in (doc.events.targets, doc.events.acquisition):
                    sig.connect(self._on_document_changed)
                doc.events.kappa.connect(self._on_kappa)
                doc.events.mask.connect(self._on_mask)
            self._watched = doc
        self._attach_truth()
        self._on_document_changed()

    def _attach_truth(self) -> None:
        """A reopened session of the open simulated rig gets its scene's ground truth back (the Ground Truth
        and Error views), when the scene reproduces its photograph (:func:`app.model.scene_truth.scene_truth`)."""
        from app.model.scene_truth import scene_truth

        doc, rig = self.w.doc, self.rig
        if doc is None or doc.truth is not None or getattr(rig, "truth", None) is None:
            return
        doc.truth, _why = scene_truth(rig, self.w.session, doc.photograph)
        if doc.truth is not None:
            self.w.preview.rebuild()
            self.w._update_actions()

    def _on_kappa(self, uid: int, _kappa) -> None:
        """Only the fixed κ of earlier cascade targets matter to the dock (not a slider drag on the last)."""
        included = [t.uid for t in self.w.doc.acquisition_targets()] if self.w.doc is not None else []
        if uid in included[:-1]:
            self._on_document_changed()

    def _on_mask(self, uid: int, _bbox) -> None:
        """The dock follows masks as painted; a target whose edge turned soft (or hard) hands it its new array."""
        panel = self.panel
        if panel is None or panel.busy or self.w.doc is None:
            return
        held = {name: m for name, m in panel.targets}
        t = self.w.doc.target(uid)
        if t.name in held and held[t.name] is not t.acquired_mask():
            self._on_document_changed()

    def _on_document_changed(self, *_args) -> None:
        panel, doc = self.panel, self.w.doc
        if panel is None or panel.busy:
            return
        panel.set_rig(self.rig)
        if panel.session is not self.w.session:
            panel.set_session(self.w.session)
        targets = [] if doc is None else doc.acquisition_targets()
        panel.set_targets([(t.name, t.acquired_mask()) for t in targets], [t.kappa for t in targets[:-1]])

    def _branch(self, reason: str):
        """The session holds another plan, or a calibration of another set-up: offer a new session folder."""
        from app.model.saving import branch_session
        from engine.workflow import check_rig, load_calibration

        old = self.w.session
        try:
            check_rig(load_calibration(old), self.rig)
        except (InputError, SessionError):
            if self.calibration is None:  # no calibration of this set-up to acquire with: calibrate first
                return None
        if self.w.demo:  # the demo's session lives in the cache: the new one goes where sessions go
            base = Path(str(self.w.settings.value("wizard/sessions_dir", Path.home() / "Albedit" / "sessions")))
            stem = base / f"demo-{datetime.now():%Y%m%d-%H%M%S}"
            kept = "the demo's session"
        else:
            stem, kept = Path(old.path), Path(old.path).name
        path, n = stem, 2
        while path.exists():
            path, n = Path(f"{stem}-{n}"), n + 1
        answer = QMessageBox.question(
            self.w, "Acquire into a new session folder?",
            f"{reason[:1].upper()}{reason[1:]}\n\nAcquire into a new session folder, {path}? The calibration "
            f"is reused and {kept} is kept as it is.")
        if answer != QMessageBox.StandardButton.Yes:
            return None
        try:
            new = branch_session(old, path, self.rig, calibration=self.calibration)
        except (InputError, SessionError, OSError) as exc:
            self.w.show_error("Cannot make the new session folder", exc)
            return None
        self.calibration = None
        self.w.session, self.w.demo = new, False
        self.w._update_title()
        return new

    def _remember_session(self) -> None:
        """The window's session folder (made by the wizard or for an acquisition) goes to File ▸ Open Recent:
        an acquisition left unfinished there is found again. Not the demo's (it lives in the cache)."""
        if self.w.session is not None and not self.w.demo:
            self.w.files.add_recent(self.w.session.path)

    def _on_acquired(self, result) -> None:
        """A finished cascade becomes the document's acquisition; the last target stays free."""
        doc = self.w.doc
        by_name = {t.name: t.uid for t in doc.targets}
        try:
            cascade = [by_name[name] for name, _ in result.targets]
            doc.set_acquisition(cascade, result.decomposition, key=result.key, noise_aware=self.w.noise_aware_default())
        except (KeyError, InputError, SessionError) as exc:
            self.w.show_error("Cannot use the acquisition", exc)
            return
        self.w.preview.rebuild()
        self.w.statusBar().showMessage(
            f"Acquired {result.targets[-1][0]!r} in {result.shots} camera shots: drag its κ sliders", 15000)

    def acquiring(self) -> bool:
        """Whether an acquisition is running (or paused) in the dock."""
        return self.panel is not None and self.panel.busy

    def shutdown(self) -> None:
        """The window closes: stop an acquisition (its captures stay in the session), close the rig."""
        if self.panel is not None:
            self.panel.shutdown()
        self._close()

    @staticmethod
    def session_folder(session) -> Path | None:
        return None if session is None else Path(session.path)
