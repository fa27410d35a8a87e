"""J10, a photograph the rig's camera did not take: a 32×24 photograph is open and the lab tech calibrates a
32×32 camera. The wizard says so before anything is captured and again in its summary; after Finish the
photograph keeps no calibration it cannot use (Save works, into a session of its own size), and Acquire
refuses in one line naming both sizes, instead of an edit that can no longer be saved.

Synchronous jobs on the ideal virtual rig; every step through the real window.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtWidgets import QFileDialog, QLabel, QWizard

import devices
from engine import imageio
from engine.session import Session
from tests.app.qt.test_journey_lab import calibrate
from tests.app.qt.user import TIMEOUT_MS, User


def test_a_photograph_of_another_size_than_the_camera(make_window, qtbot, tmp_path, monkeypatch, dialogs):
    with devices.open_rig("virtual:cornell", ideal=True, resolution=(24, 32)) as rig:
        photo = rig.truth.photograph()
    imageio.write_image(tmp_path / "room.exr", photo)
    window = make_window()
    user = User(qtbot, window)
    window.open_path(tmp_path / "room.exr")
    qtbot.waitUntil(lambda: window.doc is not None and window.job is None, timeout=TIMEOUT_MS)
    user.click("target_add")
    user.drag_on_canvas(window.canvas, [(20.5, 8.5), (20.5, 16.5)])
    doc = window.doc

    # the rig page warns as soon as the chosen camera is not the photograph's size
    user.trigger("calibrate")
    wizard = window.findChild(QWizard, "calibration_wizard")
    w = User(qtbot, wizard)
    note = w.find("wizard_size_note", QLabel)
    w.type_into("wizard_rig_name", "virtual:cornell", enter=False)
    assert not note.isVisible()  # the wizard proposes the photograph's own size
    w.type_into("wizard_res_h", "32", enter=False)
    assert note.isVisible() and "32×24" in note.text() and "32×32" in note.text()
    w.type_into("wizard_res_h", "24", enter=False)
    assert not note.isVisible()
    w.click("wizard_cancel")
    qtbot.waitUntil(lambda: window.findChild(QWizard, "calibration_wizard") is None, timeout=TIMEOUT_MS)

    summary = calibrate(window, qtbot, identify=False, rig="virtual:cornell", resolution=32)
    assert "The open photograph is 32×24, the camera 32×32" in summary and "Nothing to fix" not in summary
    assert window.rig is not None and window.rig.camera.resolution == (32, 32)  # the rig stays open
    assert window.session is None  # the photograph did not take a calibration of another camera
    assert "not used for the open photograph" in window.statusBar().currentMessage()

    # Acquire refuses in one line; Save (As) keeps the painted target, in a session of the photograph's size
    user.trigger("acquire")
    (kind, title, text), = [d for d in dialogs.shown if d[0] == "critical"]
    assert title == "Cannot acquire" and "32×32" in text and "32×24" in text and "\n" not in text.strip()
    monkeypatch.setattr(QFileDialog, "getSaveFileName", staticmethod(lambda *a, **k: (str(tmp_path / "saved"), "")))
    user.trigger("save")
    qtbot.waitUntil(lambda: window.job is None and not doc.is_dirty(), timeout=TIMEOUT_MS)
    saved = Session.open(tmp_path / "saved")
    assert tuple(saved.camera_resolution) == (24, 32) and not saved.read_calibration()[0]
    np.testing.assert_array_equal(saved.read_mask(saved.state["edit"]["targets"][0]["mask"]), doc.targets[0].mask)
