"""The Rig menu: calibrate into a session, acquire the painted targets, edit the result."""

import numpy as np

import devices
from app.model.document import Document
from engine.recolor import recolor
from engine.session import Session
from engine.workflow import run_calibration


def test_acquire_from_the_main_window_gives_an_editable_decomposition(make_window, qtbot, tmp_path, dialogs):
    rig = devices.open_rig("virtual:cornell", resolution=(24, 24), ideal=True, cache_dir=tmp_path / "cache")
    try:
        session = Session.create(tmp_path / "s", rig_name=rig.identity, camera_resolution=rig.camera.resolution,
                                 projector_resolution=rig.projector.resolution)
        run_calibration(rig, session)
        photo = rig.truth.photograph()
        doc = Document(photo)
        doc.add_target("right_wall", rig.targets["right_wall"])
        window = make_window(doc, session, rig=rig)
        window.acquire()
        panel = window._acquisition_dock.widget()
        with qtbot.waitSignal(panel.acquired, timeout=60_000):
            job = panel.start()
            assert job is not None, dialogs.shown
        assert doc.acquisition is not None
        kappa = np.array([2.0, 0.125, 8.0])
        truth = rig.truth.recolor([(rig.targets["right_wall"], kappa)])
        ours = recolor(doc.acquisition.decomposition, kappa)
        assert np.linalg.norm(ours - truth) / np.linalg.norm(truth) < 0.01
    finally:
        rig.close()
