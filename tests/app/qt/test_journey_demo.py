"""J1, the artist on the demo: open → add a target → paint it with brush and eraser → include only it
→ acquire → drag κ → undo/redo → save → close → reopen → the same picture → export EXR and TIFF
from the app → ``albedit export`` on the saved session gives the same pixels and metadata.

Driven through the real window only (tests/app/qt/user.py); the demo's rig is made small (48²)
instead of the size that fills the screen, and the file dialogs' answers are given.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QFileDialog, QListWidget, QMessageBox, QSlider

from app.qt.panels import kappa_to_ticks
from engine import imageio
from engine.acquire.predict import relative_error
from engine.recolor import recolor
from tests.app.qt.user import User

RES = (48, 48)


def _answer_file_dialogs(monkeypatch, *, save=None, folder=None):
    if save is not None:
        monkeypatch.setattr(QFileDialog, "getSaveFileName", staticmethod(lambda *a, **k: save))
    if folder is not None:
        monkeypatch.setattr(QFileDialog, "getExistingDirectory", staticmethod(lambda *a, **k: str(folder)))


def test_the_artist_on_the_demo(make_window, qtbot, tmp_path, monkeypatch, dialogs):
    import app.model.demo

    real = app.model.demo.open_demo
    monkeypatch.setattr(app.model.demo, "open_demo", lambda name, **kw: real(name, **dict(kw, resolution=RES)))
    window = make_window()
    user = User(qtbot, window)
    user.trigger("demo")
    doc = window.doc
    lst = user.find("targets_list", QListWidget)
    assert user.rows(lst) == ["left_wall", "short_box", "right_wall"] and window.demo

    # a new target on the back wall, painted with the brush, trimmed with the eraser
    user.click("target_add")
    new = doc.target(doc.current)
    assert new.name == "target 4" and lst.currentItem().text() == "target 4"
    user.type_into("brush_size", "3")
    window.canvas.setFocus()
    user.press(Qt.Key.Key_B)
    user.drag_on_canvas(window.canvas, [(20, 12), (28, 12), (28, 16), (20, 16)])
    painted = int(new.mask.sum())
    user.press(Qt.Key.Key_E)
    user.drag_on_canvas(window.canvas, [(24, 11), (24, 17)])
    # the eraser cut the top and bottom strokes where it crossed them, and left them beside the cut
    assert 0 < int(new.mask.sum()) < painted and not new.mask[12, 24] and not new.mask[16, 24]
    assert new.mask[12, 20] and new.mask[16, 20] and new.mask[12, 28] and new.mask[16, 28]

    # include only it: the demo's targets are left out already, the acquired right wall too now
    user.toggle_row(lst, 2)
    assert [t.name for t in doc.acquisition_targets()] == ["target 4"]
    user.select_row(lst, 3)

    # acquire: the demo's session holds the right wall's plan, so a new session folder is offered
    user.trigger("acquire")
    assert user.find("acquire_targets").text() == "Targets: <b>target 4</b> (κ free)"
    dialogs.answers = [QMessageBox.StandardButton.Yes]
    user.click("acquire_start")
    assert "new session folder" in dialogs.texts("question")[-1]
    assert doc.acquisition is not None and doc.acquisition.cascade == (new.uid,)
    session = window.session
    assert not window.demo and Path(session.path).parent == Path.home() / "Albedit" / "sessions"
    assert "Captured" in user.find("acquire_status").text()

    # drag κ (linked), undo, redo
    user.drag_slider(user.find("kappa_B", QSlider), [kappa_to_ticks(1.5), kappa_to_ticks(3.0)])
    np.testing.assert_allclose(new.kappa, [3.0, 3.0, 3.0], rtol=0.02)
    kappa = new.kappa.copy()
    user.trigger("undo")
    np.testing.assert_array_equal(new.kappa, [1, 1, 1])
    user.trigger("redo")
    np.testing.assert_array_equal(new.kappa, kappa)
    truth = window.rig.truth.recolor([(new.mask, kappa)])  # the back wall, lighter with its interreflections
    assert relative_error(recolor(doc.decomposition, kappa), truth) < 0.01
    shown = window.canvas.frame.pixels.copy()

    user.trigger("save")
    assert not doc.is_dirty() and not window.isWindowModified()
    assert window.close()

    # reopen: the same picture
    again = make_window()
    user = User(qtbot, again)
    _answer_file_dialogs(monkeypatch, folder=session.path)
    user.trigger("open")
    reopened = again.doc
    assert [t.name for t in reopened.targets] == ["left_wall", "short_box", "right_wall", "target 4"]
    assert [reopened.target(u).name for u in reopened.acquisition.cascade] == ["target 4"]
    np.testing.assert_array_equal(reopened.by_name("target 4").kappa, kappa)
    np.testing.assert_array_equal(again.canvas.frame.pixels, shown)

    # export EXR and TIFF from the app; the command line exports the saved session the same way
    for name, chosen in (("app.exr", "OpenEXR, float (*.exr)"), ("app.tif", "TIFF, float (*.tif *.tiff)")):
        _answer_file_dialogs(monkeypatch, save=(str(tmp_path / name), chosen))
        user.trigger("export")
        ours = tmp_path / name
        cli = tmp_path / f"cli{ours.suffix}"
        run = subprocess.run([sys.executable, "-m", "app.main", "export", str(session.path), "-o", str(cli)],
                             capture_output=True, text=True, timeout=120)
        assert run.returncode == 0, run.stderr
        np.testing.assert_array_equal(imageio.read_image(cli), imageio.read_image(ours))
        meta_app, meta_cli = imageio.read_metadata(ours)["edit"], imageio.read_metadata(cli)["edit"]
        assert meta_app == meta_cli and meta_app["cascade"] == ["target 4"]
