"""J2 on a scene with no light but the projector's (the paper's wedge, Figs. 7-9): the lab tech opens its
photograph, calibrates the wedge rig in the wizard, paints the right wall, opens Rig ▸ Acquire and finds the
photograph's projector flood already set from the scene (the panel photographed every scene under projector black:
here a dark image whose recolor is the dark image), acquires, drags κ and gets the truth under that flood.

Threaded, as in the app, on the ideal virtual wedge at 24².
"""

from __future__ import annotations

import numpy as np
from PySide6.QtWidgets import QDoubleSpinBox, QSlider

import devices
from app.qt.panels import kappa_to_ticks
from engine import imageio
from engine.acquire.predict import relative_error
from engine.recolor import recolor
from engine.session import Session
from tests.app.qt.test_journey_lab import calibrate, paint_wall
from tests.app.qt.user import TIMEOUT_MS, User

RES = 24


def test_a_projector_lit_scene_is_acquired_under_its_flood(make_window, qtbot, tmp_path, dialogs):
    with devices.open_rig("virtual:wedge", ideal=True, resolution=(RES, RES)) as rig:
        flood = np.ones((*rig.projector.resolution, 3), np.float32)
        photo, wall = rig.truth.photograph(pattern=flood), rig.targets["right"]
    imageio.write_image(tmp_path / "wedge.exr", photo)
    window = make_window(synchronous=False)
    user = User(qtbot, window)
    window.open_path(tmp_path / "wedge.exr")
    qtbot.waitUntil(lambda: window.doc is not None and window.job is None, timeout=TIMEOUT_MS)
    summary = calibrate(window, qtbot, identify=False, rig="virtual:wedge", resolution=RES)
    assert "see no surface" in summary  # the void beside the wedge, said once, with what it means
    assert window.rig is not None and window.rig.name.startswith("virtual:wedge")

    doc = window.doc
    paint_wall(user, window, wall)
    target = doc.target(doc.current)
    user.trigger("acquire")
    flood_box = user.find("acquire_flood", QDoubleSpinBox)
    assert flood_box.value() == 100.0 and flood_box.isEnabled()  # the scene's natural light, set for the user
    user.type_into("acquire_order", "3")
    panel = window.rigs.panel
    with qtbot.waitSignal(panel.acquired, timeout=TIMEOUT_MS) as blocker:
        user.click("acquire_start")
    assert dialogs.texts("critical") == [] and doc.acquisition is not None
    assert Session.open(window.session.path).state["plan"]["photograph_pattern"]
    np.testing.assert_allclose(blocker.args[0].acquisition.observations[0][wall].mean(), photo[wall].mean(),
                               rtol=0.02)  # photographed under the flood, as the user's photograph was

    user.drag_slider(user.find("kappa_G", QSlider), [kappa_to_ticks(0.7), kappa_to_ticks(0.5)])
    kappa = target.kappa.copy()
    truth = window.rig.truth.recolor([(target.mask, kappa)], ambient=window.rig.ambient, pattern=flood)
    assert relative_error(recolor(doc.decomposition, kappa), truth) < 0.01
    assert relative_error(photo, truth) > 0.02  # the edit is visible: the test could fail
    qtbot.waitUntil(lambda: window.job is None, timeout=TIMEOUT_MS)
