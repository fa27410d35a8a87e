"""J11, the artist paints the ceiling lamp: the Targets panel says at once that the target holds a light
source (κ would scale the lamp's own light, which its albedo does not change), Acquire asks before it
measures it (No: nothing is acquired), and a wall painted beside it, with the lamp left out, acquires
without a question.

Synchronous jobs on the ideal virtual rig at 32²; every step through the real window.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtWidgets import QLabel, QMessageBox

import devices
from engine import imageio
from tests.app.qt.test_journey_lab import RES, calibrate, paint_wall
from tests.app.qt.user import TIMEOUT_MS, User


def test_a_lamp_painted_as_a_target_is_pointed_out(make_window, qtbot, tmp_path, dialogs):
    with devices.open_rig("virtual:cornell", ideal=True, resolution=(RES, RES)) as rig:
        photo, lamp, wall = rig.truth.photograph(), rig.truth.emitters(), rig.targets["right_wall"]
    imageio.write_image(tmp_path / "room.exr", photo)
    window = make_window()
    user = User(qtbot, window)
    window.open_path(tmp_path / "room.exr")
    qtbot.waitUntil(lambda: window.doc is not None and window.job is None, timeout=TIMEOUT_MS)
    calibrate(window, qtbot, identify=False)
    caution = user.find("target_caution", QLabel)

    # the lamp, painted with a stroke along its middle row (the first stroke starts "target 1")
    ys, xs = np.nonzero(lamp)
    y = float(np.median(ys)) + 0.5
    user.type_into("brush_size", "3")
    user.drag_on_canvas(window.canvas, [(xs.min() + 0.5, y), (xs.max() + 0.5, y)])
    doc = window.doc
    painted = doc.targets[0].mask
    assert (painted & lamp).sum() >= 4
    qtbot.waitUntil(caution.isVisible, timeout=TIMEOUT_MS)
    assert "pixels of 'target 1' are over 8× the scene's median brightness: a light source" in caution.text()

    user.trigger("acquire")  # asks; the default answer is No
    assert [(k, t) for k, t, _ in dialogs.shown] == [("question", "Acquire a light source?")]
    assert window.rigs.dock is None or not window.rigs.dock.isVisible()
    assert window.statusBar().currentMessage().startswith("Not acquired: ")

    # the wall instead, the lamp left out: no question, the dock opens
    paint_wall(user, window, wall)
    qtbot.waitUntil(lambda: not caution.isVisible(), timeout=TIMEOUT_MS)
    user.toggle_row(user.find("targets_list"), 0)
    assert [t.included for t in doc.targets] == [False, True]
    dialogs.answers = [QMessageBox.StandardButton.Yes]  # (not asked)
    user.trigger("acquire")
    assert len(dialogs.shown) == 1 and window.rigs.dock.isVisible()
    assert [n for n, _ in window.rigs.panel.targets] == ["target 2"]
