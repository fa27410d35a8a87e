"""J7, the artist's strong edit on a real (noisy) camera: the demo on the realistic rig → the canvas shows the
noise-aware recolor (engine.trust), prepared once as a job → drag κ → the shown pixels are recolor_trusted's →
View ▸ Noise-Aware Recolor off (plain) and Undo (back) → the Predicted Noise view shows the σ of the recolor shown
→ export writes the shown pixels, its metadata says which recolor → Save keeps the choice.

Driven through the real window only (tests/app/qt/user.py); the realistic rig made small (48²). A document
without a session falls back to the plain recolor and says so in the status bar.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtWidgets import QFileDialog, QLabel, QSlider

from app.model.display import recolor_rgb32, to_rgb32
from app.qt.panels import kappa_to_ticks
from engine import imageio
from engine.recolor import recolor_variance
from engine.session import Session
from engine.trust import recolor_trusted
from engine.workflow import load_trusted, saved_edit
from tests.app.qt.user import User


def _shows(window, view: str, kappa) -> bool:
    frame = window.canvas.frame
    return (frame is not None and frame.view == view and frame.request is not None and not frame.request.fast
            and np.allclose(frame.request.kappa, kappa))


def test_the_artist_edits_with_the_noise_aware_recolor_and_exports_it(realistic_demo, monkeypatch, tmp_path):
    window, user = realistic_demo
    doc = window.doc
    wall = doc.by_name("right_wall")
    mode = user.find("recolor_mode", QLabel)
    user.wait_until(lambda: mode.text() == "noise-aware recolor")  # prepared as the window's job, once
    assert user.action("noise_aware").isChecked() and doc.trusted is not None
    trusted = load_trusted(window.session, doc.acquisition.key)  # what the job cached in the session

    # drag κ_B of the acquired wall up to the paper's strongest edit; the canvas shows recolor_trusted's pixels
    user.select_row(user.find("targets_list"), 2)
    user.drag_slider(user.find("kappa_B", QSlider), [kappa_to_ticks(4.0), kappa_to_ticks(8.0)])
    assert abs(wall.kappa[2] - 8.0) < 0.2
    kappa = wall.kappa.copy()
    user.wait_until(lambda: _shows(window, "recolored", kappa))
    # the paper's edit converges: no false warning from clipped noise (the limit read 5.9, "diverges")
    message = window.statusBar().currentMessage()
    assert "diverges" not in message and "has not converged" not in message, message
    exposure = user.find("display_exposure").value()
    expected = recolor_trusted(trusted, kappa)
    np.testing.assert_array_equal(window.canvas.frame.linear, expected.image)  # 48²: the preview is full size
    np.testing.assert_array_equal(window.canvas.frame.pixels, to_rgb32(expected.image, exposure=exposure))

    # the Predicted Noise view shows the σ the noise-aware recolor predicts for itself
    user.trigger("view_noise")
    user.wait_until(lambda: _shows(window, "noise", kappa))
    np.testing.assert_array_equal(window.canvas.frame.linear, expected.sigma)
    assert user.find("view_note", QLabel).text().startswith("predicted σ on the target (noise-aware recolor): mean")

    # plain: one undo step; the status bar says so; the noise view follows the recolor shown
    user.trigger("noise_aware")
    assert not user.action("noise_aware").isChecked() and not doc.acquisition.noise_aware
    assert mode.text().startswith("plain recolor")
    user.wait_until(lambda: _shows(window, "noise", kappa) and window.canvas.frame.note.startswith(
        "predicted σ on the target: mean"))
    np.testing.assert_array_equal(window.canvas.frame.linear, np.sqrt(recolor_variance(doc.decomposition, kappa)))
    user.trigger("view_recolored")
    user.wait_until(lambda: _shows(window, "recolored", kappa) and window.canvas.frame.linear is None)
    np.testing.assert_array_equal(window.canvas.frame.pixels, recolor_rgb32(doc.decomposition, kappa,
                                                                            exposure=exposure))
    user.trigger("undo")
    assert user.action("noise_aware").isChecked() and doc.acquisition.noise_aware and mode.text() == \
        "noise-aware recolor"
    user.wait_until(lambda: _shows(window, "recolored", kappa) and window.canvas.frame.linear is not None)
    np.testing.assert_array_equal(window.canvas.frame.linear, expected.image)

    # export writes exactly the pixels shown, and says how they were recolored
    window.export(tmp_path / "edit.exr", dtype="float")
    np.testing.assert_array_equal(imageio.read_image(tmp_path / "edit.exr"), window.canvas.frame.linear)
    meta = imageio.read_metadata(tmp_path / "edit.exr")["edit"]
    assert meta["recolor"] == "noise-aware" and np.allclose(meta["kappa"], kappa)

    # the choice is saved with the edit (the demo's Save is a Save As)
    monkeypatch.setattr(QFileDialog, "getSaveFileName", staticmethod(lambda *a, **k: (str(tmp_path / "kept"), "")))
    user.trigger("noise_aware")  # plain
    assert not window.noise_aware_default()  # remembered for the next acquisition
    assert window.save()
    assert saved_edit(Session.open(tmp_path / "kept")).acquisition.noise_aware is False
    window.export(tmp_path / "plain.exr", dtype="float")
    assert imageio.read_metadata(tmp_path / "plain.exr")["edit"]["recolor"] == "plain"


def test_without_a_session_the_recolor_is_plain_and_the_status_bar_says_why(make_window, qtbot, acquired_doc):
    window = make_window(acquired_doc)
    user = User(qtbot, window)
    mode = user.find("recolor_mode", QLabel)
    user.wait_until(lambda: mode.text().startswith("plain recolor: the noise-aware recolor needs the acquisition's "
                                                   "session"))
    assert "\n" not in mode.text() and acquired_doc.trusted is None
    assert user.action("noise_aware").isChecked()  # still asked for, and saved so with the edit
