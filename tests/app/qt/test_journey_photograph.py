"""J3, the artist with a plain photograph: open it → paint and name a target → set κ → the preview is
a naive per-pixel recolor under a banner saying interreflections need a capture → save as a
session → a lab tech opens it, calibrates and acquires with that target → the artist's κ now
recolors with consistent interreflections.

The photograph is the ideal virtual rig's (32²), so the rig can acquire the same scene; the file
dialogs' answers are given; everything else goes through the real window (tests/app/qt/user.py).
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QFileDialog, QListWidget, QWizard
from scipy.ndimage import binary_erosion

import devices
from app.model.display import to_rgb32
from app.model.views import NAIVE_BANNER
from engine import imageio
from engine.acquire.predict import relative_error
from engine.recolor import recolor
from tests.app.qt.user import User

RES = 32
KAPPA = (2.0, 0.125, 8.0)


def test_the_artist_with_a_photograph_and_the_lab_tech(make_window, qtbot, tmp_path, monkeypatch, dialogs):
    with devices.open_rig("virtual:cornell", ideal=True, resolution=(RES, RES)) as rig:
        photo, wall = rig.truth.photograph(), rig.targets["right_wall"]
    imageio.write_image(tmp_path / "room.exr", photo)
    window = make_window()
    user = User(qtbot, window)
    monkeypatch.setattr(QFileDialog, "getOpenFileName", staticmethod(lambda *a, **k: (str(tmp_path / "room.exr"), "")))
    user.trigger("open_image")
    doc = window.doc
    np.testing.assert_array_equal(doc.photograph, photo)

    # paint the green wall (a stroke down its middle) and name it
    user.click("target_add")
    user.type_into("brush_size", "2")
    inner = binary_erosion(wall, iterations=2)
    column = int(np.argmax(inner.sum(axis=0)))  # the wall's tallest column: a stroke down its middle
    ys = np.flatnonzero(inner[:, column])
    x = column + 0.5
    user.drag_on_canvas(window.canvas, [(x, ys.min() + 0.5), (x, (ys.min() + ys.max()) / 2), (x, ys.max() + 0.5)])
    target = doc.target(doc.current)
    assert target.mask.sum() > 10 and not (target.mask & ~wall).any()
    lst = user.find("targets_list", QListWidget)
    user.rename_row(lst, 0, "green wall")
    user.click("kappa_link")  # unlink: type each channel
    for channel, value in zip("RGB", KAPPA, strict=True):
        user.type_into(f"kappa_{channel}_value", f"{value:g}")
    np.testing.assert_array_equal(target.kappa, KAPPA)

    # nothing measured yet: a naive recolor, and the banner says what is missing
    frame = window.canvas.frame
    assert frame.banner == NAIVE_BANNER and "Interreflections follow only once" in frame.banner
    naive = np.where(target.mask[..., None], photo * np.float32(KAPPA), photo).astype(np.float32)
    np.testing.assert_array_equal(frame.pixels, to_rgb32(naive))
    # before/after: the split view's captions are not hidden under the banner
    user.click("view_split_button")
    user.wait_until(lambda: window.canvas.frame.second is not None)
    canvas = window.canvas
    strip = canvas.banner_strip()[0]
    assert canvas.frame.banner and strip.height() > 0
    for caption in canvas.split_captions(canvas.image_rect()).values():
        assert caption.top() >= strip.bottom() and canvas.rect().toRectF().contains(caption)
    user.click("view_recolored_button")

    monkeypatch.setattr(QFileDialog, "getSaveFileName", staticmethod(lambda *a, **k: (str(tmp_path / "artist"), "")))
    user.trigger("save")  # a photograph has no session yet: Save asks for a new session folder
    assert not doc.is_dirty() and window.session is not None
    painted = target.mask.copy()
    assert window.close()

    # the lab tech opens the session, calibrates the rig and acquires the artist's target
    tech = make_window()
    user = User(qtbot, tech)
    monkeypatch.setattr(QFileDialog, "getExistingDirectory", staticmethod(lambda *a, **k: str(tmp_path / "artist")))
    user.trigger("open")
    doc = tech.doc
    assert [t.name for t in doc.targets] == ["green wall"] and doc.acquisition is None
    np.testing.assert_array_equal(doc.photograph, photo)
    np.testing.assert_array_equal(doc.by_name("green wall").kappa, KAPPA)
    user.trigger("calibrate")
    wizard = tech.findChild(QWizard, "calibration_wizard")
    wuser = User(qtbot, wizard)
    assert wizard.rig_page.rig_name.text() == "virtual:cornell" and wizard.rig_page.ideal.isChecked()
    assert (wizard.rig_page.res_h.value(), wizard.rig_page.res_w.value()) == (RES, RES)  # the photograph's
    wuser.click("wizard_next")
    wuser.click("wizard_next")  # opens the rig
    assert wizard.currentId() == wizard.PAGE_EXPOSURE
    wuser.click("wizard_auto_exposure")
    qtbot.waitUntil(lambda: wizard.exposure_page.auto is None, timeout=30_000)
    wuser.click("wizard_next")
    wuser.click("calibrate_start")
    qtbot.waitUntil(wizard.calibration_page.isComplete, timeout=60_000)
    wuser.click("wizard_next")
    wuser.click("wizard_next")
    wuser.click("wizard_finish")
    assert tech.rig is not None and tech.session.read_calibration()[0]  # the photograph's session took it

    user.trigger("acquire")
    user.click("acquire_start")
    assert dialogs.texts("critical") == [] and doc.acquisition is not None
    assert [doc.target(u).name for u in doc.acquisition.cascade] == ["green wall"]
    frame = tech.canvas.frame
    assert frame.banner == ""
    truth = tech.rig.truth.recolor([(painted, np.array(KAPPA))])
    ours = recolor(doc.decomposition, doc.recolor_kappa())
    surfaces = ~tech.rig.truth.emitters()  # the lamp dominates the norm; every method reproduces it
    err_ours, err_naive = relative_error(ours, truth, surfaces), relative_error(naive, truth, surfaces)
    assert err_ours < 0.01 and err_naive > 3 * err_ours  # the interreflections followed the artist's κ

    user.press(Qt.Key.Key_S, Qt.KeyboardModifier.ControlModifier)
    assert not doc.is_dirty()
    assert tech.close()
    artist = make_window()
    User(qtbot, artist).trigger("open")
    assert artist.doc.acquisition is not None
    np.testing.assert_array_equal(recolor(artist.doc.decomposition, artist.doc.recolor_kappa()), ours)
