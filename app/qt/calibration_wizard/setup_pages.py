"""The wizard's first two pages: which rig (and its options, and the session folder), which screen."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QFileDialog,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QListWidget,
    QListWidgetItem,
    QPushButton,
    QSpinBox,
    QVBoxLayout,
    QWizardPage,
)

import devices
from app.qt.calibration_wizard.common import NO_SCREEN_BACKENDS, SIMULATED, error_text, esc, red
from app.qt.worker import JobProgress


def rig_text(rig) -> str:
    """A rig in words: its name and resolutions (never a Python repr)."""
    (ch, cw), (ph, pw) = rig.camera.resolution, rig.projector.resolution
    return f"{rig.name} — camera {cw}×{ch}, projector {pw}×{ph}"


class RigPage(QWizardPage):
    """Which rig, its options, and which session folder."""

    def __init__(self, wizard):
        super().__init__()
        self.setObjectName("wizard_rig_page")
        self.setTitle("Choose the rig")
        self.setSubTitle("The camera and projector to calibrate, and the session folder the captures go to.")
        self.w = wizard
        self.rigs_label = QLabel("Rigs on this machine (greyed: cannot be opened, with the reason):")
        self.rigs_label.setWordWrap(True)
        self.rigs = QListWidget(objectName="wizard_rigs")
        self.rigs.setMinimumHeight(90)
        self.rig_name = QLineEdit(objectName="wizard_rig_name")
        self.rig_name.setPlaceholderText("backend:argument, e.g. virtual:cornell or opencv:0")
        self.given = QLabel(objectName="wizard_given_rig")
        self.given.setWordWrap(True)
        self.size_note = QLabel(objectName="wizard_size_note")  # a camera of another size than the photograph
        self.size_note.setWordWrap(True)
        self.size_note.hide()

        self.virtual = QGroupBox("Virtual rig", objectName="wizard_virtual")
        self.ideal = QCheckBox("ideal (no noise, linear projector)", objectName="wizard_ideal")
        self.pose = QComboBox(objectName="wizard_pose")
        self.pose.addItems(["coaxial", "offset"])
        self.res_h = QSpinBox(minimum=8, maximum=4096, value=128, objectName="wizard_res_h")
        self.res_w = QSpinBox(minimum=8, maximum=4096, value=128, objectName="wizard_res_w")
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

        self.session_path = QLineEdit(objectName="wizard_session_path")
        browse = QPushButton("Browse…", objectName="wizard_session_browse")
        browse.clicked.connect(self._on_browse)
        row = QHBoxLayout()
        row.addWidget(self.session_path, 1)
        row.addWidget(browse)
        note = QLabel("A new folder starts a session; an existing session folder resumes its interrupted calibration.")
        note.setWordWrap(True)

        lay = QVBoxLayout(self)
        lay.addWidget(self.rigs_label)
        lay.addWidget(self.rigs, 3)
        lay.addWidget(self.given)
        name_row = QHBoxLayout()
        name_row.addWidget(QLabel("Rig"))
        name_row.addWidget(self.rig_name, 1)
        lay.addLayout(name_row)
        lay.addWidget(self.virtual)
        lay.addWidget(self.size_note)
        lay.addWidget(QLabel("Session folder"))
        lay.addLayout(row)
        lay.addWidget(note)
        lay.addStretch(1)  # with the list hidden (an open rig), the rest stays together at the top

        self.rigs.currentItemChanged.connect(self._on_pick)
        self.rig_name.textChanged.connect(self._on_name_changed)
        self.session_path.textChanged.connect(self.completeChanged)
        for spin in (self.res_h, self.res_w):
            spin.valueChanged.connect(self._update_size_note)
        self._fill()

    def _fill(self) -> None:
        w = self.w
        if w.given_rig is not None:  # the rig is open already: nothing to choose
            for widget in (self.rigs_label, self.rigs, self.virtual):
                widget.hide()
            self.rig_name.setText(w.given_rig.name)
            self.rig_name.setReadOnly(True)
            self.given.setText(f"Using the rig that is open: {esc(rig_text(w.given_rig))}.")
            return
        self.given.hide()
        try:
            entries = devices.available()
        except Exception as exc:  # noqa: BLE001 - a broken probe must not break the wizard
            entries = []
            self.given.setText(red(f"Listing rigs failed: {error_text(exc)}"))
            self.given.show()
        for a in entries:
            item = QListWidgetItem(f"{a.name} — {a.reason}" if a.reason else a.name)
            item.setData(Qt.ItemDataRole.UserRole, a.name)
            item.setToolTip(a.reason or a.name)
            if not a.ok:
                item.setFlags(item.flags() & ~Qt.ItemFlag.ItemIsEnabled & ~Qt.ItemFlag.ItemIsSelectable)
            self.rigs.addItem(item)
        if not entries:
            self.rigs.hide()
            self.rigs_label.setText("No rig was found on this machine: type its name below (backend:argument).")
        wanted = w.initial_rig_name
        for i in range(self.rigs.count()):
            item = self.rigs.item(i)
            name = item.data(Qt.ItemDataRole.UserRole)
            if item.flags() & Qt.ItemFlag.ItemIsEnabled and (wanted is None or name == wanted):
                self.rigs.setCurrentItem(item)
                break
        if wanted is not None:
            self.rig_name.setText(wanted)
        self._on_name_changed(self.rig_name.text())

    def _on_pick(self, item, _previous=None) -> None:
        if item is not None and item.flags() & Qt.ItemFlag.ItemIsEnabled:
            self.rig_name.setText(item.data(Qt.ItemDataRole.UserRole))

    def _on_name_changed(self, text: str) -> None:
        self.virtual.setEnabled(text.startswith(SIMULATED))
        self._update_size_note()
        self.completeChanged.emit()

    def _update_size_note(self, *_args) -> None:
        """Warn while the camera chosen (an open rig's, or a simulated one's resolution) is not the open
        photograph's size; other cameras are checked once open (the projector page)."""
        w = self.w
        if w.given_rig is not None:
            camera = w.given_rig.camera.resolution
        elif self.rig_name.text().startswith(SIMULATED):
            camera = (self.res_h.value(), self.res_w.value())
        else:
            camera = None
        why = "" if camera is None else w.mismatch(camera)
        self.size_note.setText(red(f"{why}: its calibration cannot be used for the photograph's targets (a "
                                   "camera of the photograph's size can).") if why else "")
        self.size_note.setVisible(bool(why))

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
        """Options for :func:`devices.open_rig` from this page (simulated rigs only)."""
        if not self.rig_name.text().startswith(SIMULATED):
            return {}
        return {"ideal": self.ideal.isChecked(), "projector": self.pose.currentText(),
                "resolution": (self.res_h.value(), self.res_w.value())}


class ProjectorPage(QWizardPage):
    """The projector's screen (when the backend draws the projector as a window); opens the rig."""

    def __init__(self, wizard):
        super().__init__()
        self.setObjectName("wizard_projector_page")
        self.setTitle("Projector")
        self.w = wizard
        self.note = QLabel(objectName="wizard_projector_note")
        self.note.setWordWrap(True)
        self.screens = QListWidget(objectName="wizard_screens")
        self.status = QLabel(objectName="wizard_open_status")
        self.status.setWordWrap(True)
        self.eta = JobProgress("open_rig_progress", hide_when_idle=True, stacked=True)
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
        elif backend in NO_SCREEN_BACKENDS:
            simulated = f"The {'virtual' if backend == 'virtual' else 'path-traced'} rig simulates its projector " \
                "(its pose is chosen on the first page): there is no screen to choose."
            self.note.setText(simulated if backend != "replay" else
                              "A replay rig serves recorded captures back: it has no projector screen.")
            self.screens.hide()
        else:
            self.screens.show()
            try:
                found = [a for a in devices.available_projectors() if a.ok]
            except Exception as exc:  # noqa: BLE001 - shown, the rig then opens with its default
                found = []
                self.note.setText(red(f"Cannot list screens ({error_text(exc)}); the rig opens with its default "
                                      "projector."))
            for a in found:  # "qtscreen:1 — HDMI-1 1024x768": every projector a registered backend offers
                item = QListWidgetItem(f"{a.name} — {a.reason}" if a.reason else a.name)
                item.setData(Qt.ItemDataRole.UserRole, a.name)
                self.screens.addItem(item)
            if found:
                self.note.setText("The projector is a full-screen window on one of these screens (usually not "
                                  "the primary):")
                self.screens.setCurrentRow(1 if len(found) > 1 else 0)

    def options(self) -> dict:
        item = self.screens.currentItem()
        if self.screens.isHidden() or item is None:
            return {}
        return {"projector": item.data(Qt.ItemDataRole.UserRole)}

    def isComplete(self) -> bool:  # noqa: N802 (Qt name)
        return not self.w.busy

    def validatePage(self) -> bool:  # noqa: N802 (Qt name)
        return self.w.ensure_rig_and_session()
