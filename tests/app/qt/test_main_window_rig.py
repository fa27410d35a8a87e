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
        window.act_acquire.trigger()
        panel = window.rigs.panel
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


def test_the_acquisition_dock_follows_the_document_and_the_rig_can_be_closed_and_reopened(
        make_window, qtbot, tmp_path, monkeypatch, dialogs):
    """Defect 4: the dock kept a stale rig, session and target list; Acquire went grey for good."""
    import app.model.demo
    from tests.app.qt.user import User

    real = app.model.demo.open_demo
    monkeypatch.setattr(app.model.demo, "open_demo",
                        lambda name, **kw: real(name, **dict(kw, resolution=(32, 32), cache_dir=False)))
    window = make_window()
    user = User(qtbot, window)
    assert not window.act_acquire.isEnabled() and not window.act_reopen_rig.isEnabled()
    user.trigger("demo")
    demo_session, rig = window.session, window.rig
    user.trigger("acquire")
    panel, dock = window.rigs.panel, window.rigs.dock
    assert dock.isVisible() and panel.rig is rig and panel.session is demo_session
    assert panel.targets_label.text() == "Targets: <b>right_wall</b> (κ free)"  # only the included target
    doc = window.doc
    user.rename_row(user.find("targets_list"), len(doc.targets) - 1, "the green wall")
    assert "the green wall" in panel.targets_label.text()  # follows a rename
    wall = doc.by_name("the green wall")
    assert "(acquired, κ free)" not in panel.targets_label.text()

    dock.close()  # closing the dock keeps Acquire available
    assert window.act_acquire.isEnabled()
    user.trigger("acquire")
    assert dock.isVisible()

    user.trigger("close_rig")
    assert rig.closed and window.rig is None and panel.rig is None
    assert window.act_reopen_rig.isEnabled() and window.act_reopen_rig.text() == "&Reopen virtual:cornell"
    assert window.act_acquire.isEnabled()  # acquiring reopens the last rig
    user.trigger("acquire")
    assert window.rig is not None and not window.rig.closed and panel.rig is window.rig
    assert not window.act_reopen_rig.isEnabled() and window.act_close_rig.isEnabled()

    # another document: the rig stays open, the dock follows the new session and targets
    from PySide6.QtWidgets import QFileDialog

    monkeypatch.setattr(QFileDialog, "getSaveFileName", staticmethod(lambda *a, **k: (str(tmp_path / "copy"), "")))
    doc.set_kappa(wall.uid, (1.0, 2.0, 0.5))
    user.trigger("save")  # the demo's Save is a Save As
    assert window.session.path == tmp_path / "copy" and panel.session is window.session
    assert window.open_path(tmp_path / "copy")
    assert panel.session is window.session and panel.session.path == tmp_path / "copy"
    assert panel.rig is window.rig and not window.rig.closed
    assert [n for n, _ in panel.targets] == [t.name for t in window.doc.acquisition_targets()]
    assert panel.targets[-1][0] == "the green wall"
