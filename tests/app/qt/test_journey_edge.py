"""J6, the artist at a target's edge: on the ideal supersampled demo (mixed pixels at every edge),
discard the demo's acquisition → feather the right wall's edge with a soft brush (the canvas
shows the feather: the overlay's opacity follows the coverage) → Refine Edge (shown the same
way) → undo → redo → acquire → recolor: the seam along the wall's edge shrinks (the error on its edge
pixels against the rig's truth falls well below the binary mask's and the naive recolor's) → save
→ quit → reopen: the soft coverage, κ and the picture are back → export EXR: the same pixels as
``albedit export`` on the saved session.
Not yet reached at this size: the edge pixels' error is still about 8× the interior's (the issue
asks for a wall-with-edge error within 1.5× the interior's).

Driven through the real window only (tests/app/qt/user.py); the demo's rig is made small (40²)
and supersampled (4×4 per pixel) instead of the ideal one-point-per-pixel rig that fills the screen.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
from PySide6.QtCore import QPoint, Qt
from PySide6.QtGui import QImage
from PySide6.QtWidgets import QCheckBox, QFileDialog, QLabel, QListWidget, QMessageBox
from scipy.ndimage import binary_erosion

from engine import imageio
from engine.acquire.predict import relative_error
from engine.recolor import recolor
from tests.app.qt.user import User

RES = (40, 40)
KAPPA = (0.5, 1.2, 0.8)


def _screen(canvas) -> np.ndarray:
    """The canvas as drawn now: (h, w, 3) int RGB."""
    img = canvas.grab().toImage().convertToFormat(QImage.Format.Format_RGB888)
    row = img.bytesPerLine()
    return np.frombuffer(img.constBits(), np.uint8, row * img.height()).reshape(img.height(), row)[
        :, : 3 * img.width()].reshape(img.height(), img.width(), 3).astype(int)


def assert_overlay_follows_coverage(user: User, target) -> int:
    """On screen, the target's overlay at each partly covered pixel has the alpha of its coverage.

    Pixels drawn over by a later target in the list or by the unreachable hatching are left out.
    The canvas is grabbed with Show Overlays on and off; at each camera pixel's centre the
    overlay's opacity is ``(shown - photo) / (colour - photo)`` in the channel where the
    target's colour differs most from the photo; nine in ten must be within 0.05 of the
    coverage (the rest may lie under the canvas's captions). Returns how many pixels were read.
    """
    canvas = user.window.canvas
    assert user.action("overlays").isChecked()
    shown = _screen(canvas)
    user.trigger("overlays")
    photo = _screen(canvas)
    user.trigger("overlays")
    doc = user.window.doc
    later = doc.targets[[t.uid for t in doc.targets].index(target.uid) + 1:]
    others = np.zeros(doc.shape, bool) if doc.unreachable is None else doc.unreachable.copy()
    for t in later:
        others |= t.mask if t.coverage is None else t.coverage > 0
    cov = target.coverage
    partial = (cov > 0) & (cov < 1) & ~others
    ys, xs = np.nonzero(partial)
    at = [user.canvas_point(canvas, x + 0.5, y + 0.5) for y, x in zip(ys, xs, strict=True)]
    sy, sx = np.array([p.y() for p in at]), np.array([p.x() for p in at])
    under, over = photo[sy, sx], shown[sy, sx]
    gap = np.asarray(target.colour)[None, :] - under
    ch = np.argmax(np.abs(gap), axis=1)
    rows = np.arange(len(ch))
    strong = np.abs(gap[rows, ch]) >= 60  # enough contrast to read the opacity to a few percent
    assert strong.sum() >= 0.5 * len(ch), (strong.sum(), len(ch))
    alpha = (over - under)[rows, ch] / gap[rows, ch]
    # pixels under the canvas's own captions (a banner strip, the scale) read wrong: a few percent
    off = np.abs(alpha - cov[partial])[strong]
    assert np.mean(off <= 0.05) >= 0.9 and np.median(off) <= 0.02, (off.round(3), cov[partial][strong])
    return int(strong.sum())


def _small_demo(make_window, qtbot, monkeypatch):
    """A window showing the demo (Help ▸ Demo) on a small supersampled rig: (window, user)."""
    import app.model.demo

    real = app.model.demo.open_demo
    monkeypatch.setattr(app.model.demo, "open_demo",
                        lambda name, **kw: real(name, **dict(kw, resolution=RES, supersample=4)))
    window = make_window()
    user = User(qtbot, window)
    user.trigger("demo")
    return window, user


def test_the_artist_refines_an_edge_and_the_seam_shrinks(make_window, qtbot, tmp_path, monkeypatch, dialogs):
    window, user = _small_demo(make_window, qtbot, monkeypatch)
    doc = window.doc
    lst = user.find("targets_list", QListWidget)
    wall = doc.by_name("right_wall")
    hard = doc.decomposition  # the demo acquired the binary mask

    # the truth's own coverage of the wall: interior pixels and edge pixels (partly wall)
    cov = doc.truth.coverage(wall.mask)
    edge = (cov > 0) & (cov < 1)
    interior = binary_erosion(cov >= 1, np.ones((3, 3), bool))
    assert edge.sum() > 20

    dialogs.answers = [QMessageBox.StandardButton.Yes]
    user.trigger("discard")
    assert doc.acquisition is None
    user.select_row(lst, 2)
    assert doc.current == wall.uid
    coverage_label = user.find("target_coverage", QLabel)
    assert "hard edge" in coverage_label.text()

    # a feathered dab on the wall's edge: partial coverage, shown by the Targets panel
    user.type_into("brush_size", "3")
    user.type_into("brush_hardness", "0")
    window.canvas.setFocus()
    user.press(Qt.Key.Key_B)
    ys, xs = np.nonzero(edge & wall.mask)
    y, x = int(ys[len(ys) // 2]), int(xs[len(xs) // 2])
    user.drag_on_canvas(window.canvas, [(x + 0.5, y + 0.5), (x + 0.5, y + 0.5)])
    feathered = wall.coverage.copy()
    assert wall.edge_pixels() > 0 and "soft edge" in coverage_label.text()
    # the canvas shows the feather: the overlay's opacity follows the coverage, pixel by pixel
    assert assert_overlay_follows_coverage(user, wall) >= 2

    # Refine Edge from the photograph, undo it (the feathered coverage is back), redo it
    user.trigger("refine_edge")
    refined = wall.coverage.copy()
    assert user.find("refine_edge_button").isEnabled()
    assert np.abs(refined - cov)[edge].mean() < 0.5 * np.abs(feathered - cov)[edge].mean()
    assert f"{wall.edge_pixels()} edge px" in coverage_label.text()
    assert assert_overlay_follows_coverage(user, wall) >= 20  # the refined edge, on the canvas
    user.trigger("undo")
    np.testing.assert_array_equal(wall.coverage, feathered)
    user.press(Qt.Key.Key_Z, Qt.KeyboardModifier.ControlModifier | Qt.KeyboardModifier.ShiftModifier)
    np.testing.assert_array_equal(wall.coverage, refined)

    # acquire the soft target: the demo's session holds the binary mask's plan, so a new folder is offered
    user.trigger("acquire")
    dialogs.answers = [QMessageBox.StandardButton.Yes]
    user.click("acquire_start")
    assert doc.acquisition is not None and doc.acquisition.cascade == (wall.uid,)
    assert "Captured" in user.find("acquire_status").text()
    link = user.find("kappa_link", QCheckBox)
    if link.isChecked():  # each channel its own κ: click the box (the label's centre may lie past its text)
        qtbot.mouseClick(link, Qt.MouseButton.LeftButton, pos=QPoint(6, link.height() // 2))
    assert not link.isChecked()
    for name, value in zip(("kappa_R_value", "kappa_G_value", "kappa_B_value"), KAPPA, strict=True):
        user.type_into(name, f"{value:g}")
    np.testing.assert_allclose(wall.kappa, KAPPA, rtol=1e-3)
    kappa = wall.kappa.copy()
    truth = doc.truth.recolor([(wall.mask, kappa)])
    ours = recolor(doc.decomposition, kappa)
    before = recolor(hard, kappa)
    whole = cov > 0
    naive = np.where(wall.mask[:, :, None], doc.photograph * kappa.astype(np.float32), doc.photograph)
    e = {name: tuple(relative_error(img, truth, where) for where in (whole, interior, edge))
         for name, img in (("soft", ours), ("hard", before), ("naive", naive))}
    # measured at 40²: wall with its edge / interior / edge pixels: soft 2.03 / 0.45 / 3.83 %,
    # hard 2.09 / 0.29 / 6.75 %, naive 4.77 / 3.04 / 11.70 % (ideal rig: no noise, deterministic;
    # the hard mask's interior improved from 0.73 % with the D-weighted projector pattern, and
    # the hard mask from 2.28 / 0.51 / 7.16 % when shared Gray-code decodes at the concave corner
    # were refilled from their neighbours; the soft one was 1.93 / 0.82 / 4.13 % before that and
    # the edge's stand-in)
    assert e["soft"][2] < 0.65 * e["hard"][2] and e["soft"][2] < 0.5 * e["naive"][2], e  # the seam shrinks
    assert e["soft"][0] < e["hard"][0], e  # the wall as a whole too
    assert e["soft"][1] < 0.01 and e["soft"][1] < 0.3 * e["naive"][1], e  # its interior stays well measured

    # save, quit, reopen: the soft edge, κ and the picture come back
    shown = window.canvas.frame.pixels.copy()
    session = window.session
    user.trigger("save")
    assert not doc.is_dirty() and window.close()
    again = make_window()
    user = User(qtbot, again)
    monkeypatch.setattr(QFileDialog, "getExistingDirectory", staticmethod(lambda *a, **k: str(session.path)))
    user.trigger("open")
    back = again.doc.by_name("right_wall")
    np.testing.assert_array_equal(back.coverage, refined)
    np.testing.assert_array_equal(back.kappa, kappa)
    assert not user.find("kappa_link", QCheckBox).isChecked()  # unlinked before: a preference, remembered
    np.testing.assert_array_equal(recolor(again.doc.decomposition, kappa), ours)
    user.wait_until(lambda: again.canvas.frame is not None and np.array_equal(again.canvas.frame.pixels, shown))
    user.select_row(user.find("targets_list", QListWidget), 2)
    assert f"{back.edge_pixels()} edge px" in user.find("target_coverage", QLabel).text()

    # export EXR from the app: the recolored soft edit, and the command line's export of the session agrees
    app_exr, cli_exr = tmp_path / "app.exr", tmp_path / "cli.exr"
    monkeypatch.setattr(QFileDialog, "getSaveFileName",
                        staticmethod(lambda *a, **k: (str(app_exr), "OpenEXR, float (*.exr)")))
    user.trigger("export")
    exported = imageio.read_image(app_exr)
    # what the canvas shows (the noise-aware recolor by default) is what is written; against the truth it is
    # the soft edit's accuracy (measured: 1.14 / 0.25 / 3.01 % against the plain recolor's 1.11 / 0.25 / 2.98 %)
    mode = user.find("recolor_mode", QLabel).text()
    assert imageio.read_metadata(app_exr)["edit"]["recolor"] == ("noise-aware" if mode == "noise-aware recolor"
                                                                 else "plain")
    for where, plain in zip((whole, interior, edge), e["soft"], strict=True):
        assert relative_error(exported, truth, where) < 1.1 * plain
    run = subprocess.run([sys.executable, "-m", "app.main", "export", str(session.path), "-o", str(cli_exr)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    np.testing.assert_array_equal(imageio.read_image(cli_exr), exported)
    assert imageio.read_metadata(app_exr)["edit"] == imageio.read_metadata(cli_exr)["edit"]


def test_a_stray_feathered_dab_is_reported_after_acquiring(make_window, qtbot, monkeypatch, dialogs):
    """The artist's feathered dab lands far from the wall it was meant for: acquiring says that its
    pixels could not be split between target and neighbour (they recolor as not target)."""
    window, user = _small_demo(make_window, qtbot, monkeypatch)
    doc = window.doc
    wall = doc.by_name("right_wall")
    dialogs.answers = [QMessageBox.StandardButton.Yes]
    user.trigger("discard")
    user.select_row(user.find("targets_list", QListWidget), 2)
    assert doc.current == wall.uid

    # a soft dab on a pixel corner at the far left of the frame, no wall pixel within 3 px: 2 × 2 half-covered pixels
    user.type_into("brush_size", "3")
    user.type_into("brush_hardness", "0")
    window.canvas.setFocus()
    user.press(Qt.Key.Key_B)
    y, x = RES[0] // 2, 4
    assert not wall.mask[y - 5:y + 5, x - 5:x + 5].any()
    user.drag_on_canvas(window.canvas, [(x, y), (x, y)])
    stray = (wall.coverage > 0) & (wall.coverage < 1)
    stray[:, RES[1] // 2:] = False
    assert stray.sum() == 4 and not (wall.coverage[:, : RES[1] // 2] >= 1).any()

    user.trigger("acquire")
    dialogs.answers = [QMessageBox.StandardButton.Yes]
    user.click("acquire_start")
    status = user.find("acquire_status").text()
    assert "Captured" in status and "4 edge pixels (partly target) have no wholly-target" in status, status
