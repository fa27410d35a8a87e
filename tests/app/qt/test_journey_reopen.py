"""J9, coming back to a session: an acquisition interrupted and never saved (the window quit, changes
discarded) is found in File ▸ Open Recent and resumed there; a target left out of the acquisition stays
left out after Save and Open; a session of the open simulated rig gets its Ground Truth and Error views back.

Threaded, as in the app, on the ideal virtual rig at 32²; the user cancels when a capture's thumbnail
arrives, so nothing depends on timing.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtWidgets import QMenu, QMessageBox, QPushButton

import devices
from app.model.files import recolored_image
from app.model.views import CanvasView
from engine.acquire.predict import relative_error
from tests.app.qt.test_journey_lab import RES, calibrate, open_room, paint_wall
from tests.app.qt.user import TIMEOUT_MS, User


def open_recent(window, path) -> None:
    """File ▸ Open Recent ▸ ``path`` (the entry must be there)."""
    menu = window.findChild(QMenu, "menu_recent")
    menu.aboutToShow.emit()
    entries = {a.text(): a for a in menu.actions()}
    assert str(path) in entries, f"{path} is not in Open Recent: {list(entries)}"
    entries[str(path)].trigger()


def test_an_interrupted_acquisition_is_resumed_after_reopening(make_window, qtbot, tmp_path, dialogs):
    window, user, _photo, wall, left = open_room(make_window, qtbot, tmp_path)
    calibrate(window, qtbot, identify=False)
    session = window.session.path
    assert user.action("view_truth").isEnabled()  # the photograph is the open simulated rig's scene

    paint_wall(user, window, wall)
    wall_mask = window.doc.target(window.doc.current).mask.copy()
    user.trigger("acquire")
    panel = window.rigs.panel
    arrivals = []

    def cancel_soon(name):  # the lab tech tries to quit at the first capture, thinks better of it, then cancels
        arrivals.append(name)
        if len(arrivals) == 1:
            dialogs.answers = [QMessageBox.StandardButton.No]
            assert not window.close() and window.isVisible() and panel.busy
            (_kind, _title, text), = [d for d in dialogs.shown if d[0] == "question"]
            assert text.startswith("An acquisition is running. Quit and stop it?") and str(session) in text
        if len(arrivals) == 2:
            user.click(user.find("acquire_progress_cancel", QPushButton))

    panel.thumbnail_added.connect(cancel_soon)
    user.click("acquire_start")
    qtbot.waitUntil(lambda: not panel.busy and window.job is None, timeout=TIMEOUT_MS)
    assert "Cancelled" in user.find("acquire_status").text()
    kept = {c.name: c.sha256 for c in window.session.captures if c.name.startswith("acq-")}
    assert len(kept) >= 2

    # quit, discarding the unsaved edit: the captures are in the session, the plan with them
    dialogs.answers = [QMessageBox.StandardButton.Discard]
    window.close()
    assert not window.isVisible()

    # the next day: File ▸ Open Recent finds the session the wizard made, and Resume continues it
    window = make_window(synchronous=False)
    user = User(qtbot, window)
    open_recent(window, session)
    qtbot.waitUntil(lambda: window.doc is not None and window.job is None, timeout=TIMEOUT_MS)
    doc = window.doc
    assert [t.name for t in doc.targets] == ["target 1"]
    np.testing.assert_array_equal(doc.targets[0].mask, wall_mask)
    user.trigger("acquire")  # reopens the last rig, then shows the dock
    qtbot.waitUntil(lambda: window.rigs.panel is not None and window.job is None, timeout=TIMEOUT_MS)
    panel = window.rigs.panel
    assert user.find("acquire_start").text() == "Resume"
    with qtbot.waitSignal(panel.acquired, timeout=TIMEOUT_MS):
        user.click("acquire_start")
    after = {c.name: c.sha256 for c in window.session.captures}
    assert {n: after[n] for n in kept} == kept  # reused, not retaken
    # the acquisition is one undo step (it cleared the history before): undone, it is discarded; redone, back
    measured = doc.acquisition
    assert window.act_undo.text() == "&Undo Acquire 'target 1'"
    user.trigger("undo")
    assert doc.acquisition is None and not doc.mask_lock(doc.targets[0].uid)
    user.trigger("redo")
    assert doc.acquisition is measured
    with devices.open_rig("virtual:cornell", ideal=True, resolution=(RES, RES)) as check:
        truth = check.truth.recolor([(wall_mask, np.array([0.5, 1.0, 2.0]))])
        surfaces = ~check.truth.emitters()
    doc.set_kappa(doc.targets[0].uid, (0.5, 1.0, 2.0))
    assert relative_error(recolored_image(doc), truth, surfaces) < 0.01

    # the truth views came back with the rig: the Error view measures the recolor against the scene
    assert user.action("view_truth").isEnabled() and user.action("view_error").isEnabled()
    user.trigger("view_error")
    qtbot.waitUntil(lambda: window.preview.frame is not None and window.preview.frame.request.view == CanvasView.ERROR
                    and window.preview.frame.request.kappa == (0.5, 1.0, 2.0), timeout=TIMEOUT_MS)
    assert "relative error" in window.preview.frame.note

    # a reference target, left out of the acquisition, stays left out after Save and Open
    paint_wall(user, window, left)
    targets = user.find("targets_list")
    user.toggle_row(targets, 1)
    assert not doc.targets[1].included
    user.trigger("save")
    qtbot.waitUntil(lambda: window.job is None and not doc.is_dirty(), timeout=TIMEOUT_MS)
    window.open_path(session)  # File ▸ Open of the same folder
    qtbot.waitUntil(lambda: window.doc is not doc and window.job is None, timeout=TIMEOUT_MS)
    again = window.doc
    assert [(t.name, t.included) for t in again.targets] == [("target 1", True), ("target 2", False)]
    assert [n for n, _ in window.rigs.panel.targets] == ["target 1"]  # the next acquisition: only the wall
    assert "Start shows it again" in user.find("acquire_status").text()
    assert dialogs.texts("critical") == []
