"""The File menu of the main window: open, save, save as, export, recent files, unsaved changes.

:class:`FileControl` runs each as a job of its window (reading a 24 MP session or writing its
decomposition takes seconds), decides where a document is saved (:mod:`app.model.saving`), and
asks before anything unsaved would be lost.
"""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import QObject, QTimer
from PySide6.QtWidgets import QFileDialog, QMessageBox

from app import APP_NAME
from app.model import files, saving
from engine.progress import checkpoint
from engine.raw import RAW_EXTENSIONS

MAX_RECENT = 8
EXPORT_FILTERS = {
    "OpenEXR, half float (*.exr)": (".exr", "half"),
    "OpenEXR, float (*.exr)": (".exr", "float"),
    "TIFF, 16-bit linear (*.tif *.tiff)": (".tif", "uint16"),
    "TIFF, float (*.tif *.tiff)": (".tif", "float"),
    "PNG, 8-bit sRGB for sharing (*.png)": (".png", "uint8"),
}


class FileControl(QObject):
    """The file side of a :class:`~app.qt.main_window.MainWindow` (its File menu's slots)."""

    def __init__(self, window):
        super().__init__(window)
        self.w = window

    def open_path(self, path) -> bool:
        """Open a session folder or an image; errors are shown, nothing else changes."""
        if not self.maybe_save():
            return False
        if self.w.job is not None:
            self.w.statusBar().showMessage(
                f"{self.w.job.name} is still running: open {Path(path).name} when it is done", 8000)
            return False
        outcome = {}

        def work(progress=None, should_stop=None):  # a 24 MP session is ~1.7 GB to read: seconds
            opened = files.open_document(path)
            checkpoint(should_stop, "opening")
            return opened

        def done(result):
            doc, session, warnings = result
            self.w.set_document(doc, session)
            self.add_recent(path)
            outcome["ok"] = True
            if warnings:
                QMessageBox.warning(self.w, "Opened with warnings", "\n".join(warnings))

        self.w.run_job(work, name=f"Opening {Path(path).name}", on_done=done, pausable=False,
                     on_failed=lambda exc: self.w.show_error("Cannot open", exc))
        return bool(outcome.get("ok")) if self.w.synchronous else True

    def on_open_session(self) -> None:
        path = QFileDialog.getExistingDirectory(self.w, "Open session folder", self.last_dir())
        if path:
            self.open_path(path)

    def on_open_image(self) -> None:
        raws = " ".join(f"*{e}" for e in sorted(RAW_EXTENSIONS))
        path, _ = QFileDialog.getOpenFileName(self.w, "Open image", self.last_dir(),
                                              f"Images (*.exr *.tif *.tiff *.png *.jpg *.jpeg {raws})")
        if path:
            self.open_path(path)

    def save(self) -> bool:
        """Save into the current session (Save As when there is none, or for the demo). True when saved."""
        if self.w.doc is None:
            return False
        if self.w.session is None or self.w.demo:
            return self.save_as()
        return self._save_into(self.w.session, None)

    def save_as(self, path=None) -> bool:
        """Save into a new session folder (see :func:`app.model.saving.save_as`)."""
        if self.w.doc is None:
            return False
        if path is None:
            path, _ = QFileDialog.getSaveFileName(self.w, "Save session as (a new folder)", self.last_dir(),
                                                  "Albedit session folder (*)")
            if not path:
                return False
        return self._save_into(None, Path(path))

    def _save_into(self, session, new_path: Path | None) -> bool:
        doc, source = self.w.doc, self.w.session
        rig = self.w.rig  # a new folder is set up for the open rig, unless its camera cannot take the photo
        projector = None if rig is None or doc.camera_mismatch(rig.camera.resolution) else \
            tuple(rig.projector.resolution)

        def work(progress=None, should_stop=None):
            if new_path is None:
                return saving.save_into(doc, session)
            return saving.save_as(doc, new_path, source=source, projector_resolution=projector)

        outcome = {}

        def done(s):
            self.w.session, self.w.demo = s, False
            doc.mark_saved()
            outcome["ok"] = True
            if new_path is not None:
                self.add_recent(new_path)
            self.w.rigs.follow_document()
            self.w._update_title()
            self.w.statusBar().showMessage(f"Saved {s.path}", 5000)

        self.w.run_job(work, name="Saving", on_done=done, pausable=False, cancellable=False)
        return bool(outcome.get("ok")) if self.w.synchronous else True

    def on_export(self) -> None:
        if self.w.doc is None:
            return
        path, chosen = QFileDialog.getSaveFileName(self.w, "Export recolored image", self.last_dir(),
                                                   ";;".join(EXPORT_FILTERS))
        if not path:
            return
        ext, dtype = EXPORT_FILTERS.get(chosen, (Path(path).suffix.lower(), None))
        note = ""
        if Path(path).suffix.lower() not in files.EXPORT_FORMATS:
            typed = Path(path).suffix
            path = path + ext
            note = f" ({typed or 'no extension'} is not an export format: {ext} was added)"
        self.export(path, dtype=dtype, note=note)

    def export(self, path, *, dtype: str | None = None, clip: bool = False, note: str = "") -> None:
        """Export the full-resolution recolored image on a worker (see :func:`app.model.files.export_image`).

        The noise-aware recolor's data is prepared first when it is asked for and not ready yet, so an export
        never writes the plain recolor by accident. ``note`` ends the status bar's "Exported …" line."""
        if self.w.prepare_trusted_first(lambda: self.export(path, dtype=dtype, clip=clip, note=note)):
            return
        exposure = self.w.exposure_spin.value()

        def failed(exc):
            if isinstance(exc, files.NeedsClipping) and not clip:
                answer = QMessageBox.question(self.w, "Export", f"{exc}\n\nClip those values to 1 and export anyway?")
                if answer == QMessageBox.StandardButton.Yes:
                    QTimer.singleShot(0, lambda: self.export(path, dtype=dtype, clip=True, note=note))
                return
            self.w.show_error("Export failed", exc)

        self.w.run_job(files.export_image, self.w.doc, path, dtype=dtype, exposure=exposure, clip=clip,
                     name="Exporting", on_done=lambda p: self.w.statusBar().showMessage(f"Exported {p}{note}", 10000),
                     on_failed=failed)

    def maybe_save(self) -> bool:
        """Ask about unsaved changes. True when it is fine to go on (saved or discarded)."""
        if self.w.doc is None or not self.w.doc.is_dirty():
            return True
        answer = self.ask_unsaved()
        if answer == QMessageBox.StandardButton.Cancel:
            return False
        if answer == QMessageBox.StandardButton.Discard:
            return True
        if not self.save():
            return False
        if self.w.job is not None:  # a threaded save: wait for it before going on
            self.w.job.wait()
        return not self.w.doc.is_dirty()

    def ask_unsaved(self) -> QMessageBox.StandardButton:
        """The unsaved-changes prompt (Save / Discard / Cancel)."""
        box = QMessageBox(QMessageBox.Icon.Warning, APP_NAME, "The document has unsaved changes.",
                          QMessageBox.StandardButton.Save | QMessageBox.StandardButton.Discard
                          | QMessageBox.StandardButton.Cancel, self.w)
        box.setInformativeText("Save the targets and albedo changes before closing?")
        box.setDefaultButton(QMessageBox.StandardButton.Save)
        box.setObjectName("unsaved_prompt")
        return QMessageBox.StandardButton(box.exec())

    # ================================================================== recent files
    def recent(self) -> list[str]:
        value = self.w.settings.value("recent", [])
        if isinstance(value, str):
            value = [value]
        return [str(v) for v in (value or [])]

    def add_recent(self, path) -> None:
        path = str(Path(path).resolve())
        items = [path] + [p for p in self.recent() if p != path]
        self.w.settings.setValue("recent", items[:MAX_RECENT])
        self.w.settings.setValue("last_dir", str(Path(path).parent))

    def last_dir(self) -> str:
        return str(self.w.settings.value("last_dir", str(Path.home())))

    def fill_recent(self) -> None:
        self.w.recent_menu.clear()
        items = self.recent()
        for p in items:
            a = self.w.recent_menu.addAction(p)
            a.triggered.connect(lambda _c=False, p=p: self.open_path(p))
        if not items:
            self.w.recent_menu.addAction("(none)").setEnabled(False)
