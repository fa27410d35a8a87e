"""J-colour, the artist chooses colours, not κ (issue 14), through the real window only.

1. On the demo (the ideal Cornell box at 64², the right wall acquired): the wall's colour is shown;
   a colour from the colour dialog and one typed in set κ as the engine does, the canvas shows the
   engine's recolor, the new albedo has the chosen colour's chromaticity (the scene's truth); keep
   luminance; undo; the eyedropper on the left wall gives the right wall the colour seen there.
2. On the virtual checker scene (ideal, 96²): a lab tech acquires the right wall then the orange
   panel, the Checker button measures the ColorChecker, the panel's absolute albedo is shown (within
   2 % of the scene's truth); a typed albedo sets κ, one of 1 or more is refused with the reason; the
   eyedropper on the right wall (a measured target) gives the panel the wall's colour.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from PySide6.QtCore import Qt
from PySide6.QtGui import QColor, QImage
from PySide6.QtWidgets import QColorDialog, QDockWidget, QDoubleSpinBox, QFileDialog, QLabel, QListWidget

import devices
from app.model.display import rgb32_to_rgb, to_rgb32
from app.model.files import recolored_image
from engine.acquire.predict import relative_error
from engine.colour import luminance_weights, parse_colour, pick_colour
from engine.recolor import recolor
from engine.session import Session
from engine.workflow import run_calibration, target_colour
from tests.app.qt.user import User

DEMO_RES = (64, 64)
CHECKER_RES = (96, 96)


def _numbers(text: str) -> list[float]:
    return [float(v) for v in re.findall(r"-?\d+\.\d+", text)]


def _chromaticity(rgb) -> np.ndarray:
    rgb = np.asarray(rgb, np.float64)
    return rgb / rgb.sum()


@pytest.fixture
def demo(make_window, qtbot, monkeypatch):
    import app.model.demo

    real = app.model.demo.open_demo
    monkeypatch.setattr(app.model.demo, "open_demo", lambda name, **kw: real(name, **dict(kw, resolution=DEMO_RES)))
    window = make_window()
    user = User(qtbot, window)
    user.trigger("demo")
    return window, user


def test_the_artist_picks_colours_on_the_demo(demo, monkeypatch, dialogs, tmp_path):
    window, user = demo
    doc = window.doc
    wall = doc.target(doc.current)
    assert wall.name == "right_wall" and doc.acquisition.cascade == (wall.uid,)
    engine = target_colour(window.session, doc.decomposition, wall.mask)  # what `albedit recolor` uses
    exposure = user.find("display_exposure", QDoubleSpinBox).value()
    albedo = user.find("colour_albedo", QLabel)
    assert "relative" in albedo.text() and "target's plane" in albedo.text()  # shown as typed, no HTML entities
    assert albedo.textFormat() == Qt.TextFormat.PlainText
    assert not user.find("colour_albedo_entry").isEnabled()  # no colour checker: albedo is relative
    truth = window.rig.truth.albedo()[wall.mask].mean(axis=0)

    # the colour dialog: κ as the engine computes it, the swatch shows the chosen colour back
    monkeypatch.setattr(QColorDialog, "getColor", staticmethod(lambda *a, **k: QColor("#3355cc")))
    user.click("colour_choose")
    kappa = engine.for_colour(parse_colour("#3355cc") / 2.0**exposure)
    np.testing.assert_allclose(wall.kappa, kappa, rtol=1e-9)
    assert user.find("colour_value", QLabel).text().startswith("#3355cc")
    # the new albedo has the chosen colour's chromaticity (white-balanced by D: the paint's colour)
    np.testing.assert_allclose(_chromaticity(truth * wall.kappa), _chromaticity(parse_colour("#3355cc")), atol=0.01)
    # the canvas shows the engine's recolor (noise-aware, once prepared), and that is the rig's exact result
    user.wait_until(lambda: doc.trusted is not None and window.canvas.frame.request is not None
                    and np.allclose(window.canvas.frame.request.kappa, wall.kappa))
    shown = rgb32_to_rgb(window.canvas.frame.pixels).astype(int)
    expected = rgb32_to_rgb(to_rgb32(recolored_image(doc), exposure=exposure)).astype(int)  # noise-aware
    assert np.abs(shown - expected).max() <= 1
    exact = window.rig.truth.recolor([(wall.mask, wall.kappa)])
    assert relative_error(recolor(doc.decomposition, wall.kappa), exact) < 0.01
    user.trigger("undo")
    np.testing.assert_allclose(wall.kappa, (2.0, 0.125, 8.0))  # the demo's κ again
    assert user.find("colour_value", QLabel).text() != "" and not user.find("colour_value").text().startswith("#3355cc")

    # typed in CIE Lab, keeping the wall's luminance (as photographed): hue and chroma change, brightness not
    user.click("colour_keep_luminance")
    user.type_into("colour_entry", "lab:60,-10,-30")
    wanted = parse_colour("lab:60,-10,-30")
    np.testing.assert_allclose(wall.kappa, engine.for_colour(wanted / 2.0**exposure, keep_luminance=True), rtol=1e-9)
    weights = luminance_weights()
    assert engine.colour(wall.kappa) @ weights == pytest.approx(engine.current @ weights)
    np.testing.assert_allclose(_chromaticity(truth * wall.kappa), _chromaticity(wanted), atol=0.01)
    assert user.find("colour_entry").text() == "lab:60,-10,-30"  # what the target shows: the box keeps it
    user.click("colour_keep_luminance")

    # the eyedropper on the left wall (painted, not measured): the colour the photograph shows there
    left = doc.by_name("left_wall")
    ys, xs = np.nonzero(left.mask)
    x, y = int(np.median(xs)), int(np.median(ys))
    user.click("colour_eyedropper")
    assert window.canvas.picking
    masks_before = [t.mask.copy() for t in doc.targets]
    user.click_on_canvas(window.canvas, x + 0.5, y + 0.5)
    assert not window.canvas.picking and not user.find("colour_eyedropper").isChecked()  # one pick
    assert all(np.array_equal(a, t.mask) for a, t in zip(masks_before, doc.targets, strict=True))  # nothing painted
    np.testing.assert_allclose(wall.kappa, engine.for_seen(pick_colour(doc.photograph, x, y)), rtol=1e-9)
    assert user.find("colour_entry").text() == ""  # the typed colour is no longer the target's: not left to mislead

    # the eyedropper on a reference picture opened beside the canvas: a paint colour from elsewhere
    picture = np.zeros((20, 30, 3), np.uint8)
    picture[:, 15:] = (200, 120, 40)
    path = tmp_path / "swatches.png"
    assert QImage(picture.data, 30, 20, 90, QImage.Format.Format_RGB888).save(str(path))
    monkeypatch.setattr(QFileDialog, "getOpenFileName", staticmethod(lambda *a, **k: (str(path), "")))
    user.click("colour_reference")
    view = user.find("colour_reference_view")
    assert user.find("reference", QDockWidget).isVisible()
    user.qtbot.mouseClick(view, Qt.MouseButton.LeftButton, pos=view.to_widget(22.5, 10.5).toPoint())
    np.testing.assert_allclose(wall.kappa, engine.for_colour(parse_colour("#c87828") / 2.0**exposure), rtol=1e-6)
    assert user.find("colour_value", QLabel).text().startswith("#c87828")

    # a κ the captured order cannot follow is applied with the warning and what would help
    user.click("kappa_link")
    user.type_into("kappa_R_value", "15")
    warning = user.find("colour_warning", QLabel).text()
    assert wall.kappa[0] == 15 and ("has not converged" in warning or "diverges" in warning)
    assert dialogs.texts() == []


@pytest.fixture
def checker_lab(make_window, qtbot, tmp_path):
    """The checker scene's photograph with the right wall and the panel painted, a calibrated session, the rig."""
    from app.model.document import Document

    rig = devices.open_rig("virtual:checker", ideal=True, resolution=CHECKER_RES)
    session = Session.create(tmp_path / "s", rig_name=rig.identity, camera_resolution=rig.camera.resolution,
                             projector_resolution=rig.projector.resolution)
    run_calibration(rig, session)
    doc = Document(np.asarray(rig.truth.photograph(), np.float32), source=rig.name, truth=rig.truth)
    doc.add_target("right_wall", rig.targets["right_wall"])
    doc.add_target("panel", rig.targets["panel"])
    doc.mark_saved()
    window = make_window(doc, session, rig=rig)
    return window, User(qtbot, window), rig


def test_the_checker_makes_albedo_absolute(checker_lab, dialogs):
    window, user, rig = checker_lab
    doc = window.doc
    albedo = rig.truth.albedo()
    truth = {t.name: albedo[t.mask].mean(axis=0) for t in doc.targets}
    # acquire the cascade: the right wall (κ fixed at 1), then the panel (free), order 2
    user.trigger("acquire")
    user.type_into("acquire_order", "2")
    user.click("acquire_start")
    assert "Captured" in user.find("acquire_status").text()
    panel = doc.by_name("panel")
    lst = user.find("targets_list", QListWidget)
    user.select_row(lst, 1)
    assert doc.current == panel.uid
    assert "relative" in user.find("colour_albedo", QLabel).text()

    # the Checker button: detected, measured, the panel's absolute albedo shown (ideal rig: within 2 %)
    user.click("colour_checker")
    shown = user.find("colour_albedo", QLabel).text()
    assert shown.startswith("Absolute albedo "), shown
    now, measured = np.array(_numbers(shown)[:3]), np.array(_numbers(shown)[3:6])
    np.testing.assert_allclose(measured, truth["panel"], rtol=0.02)
    np.testing.assert_allclose(now, measured, rtol=1e-3)  # κ = 1
    assert "24 of 24 patches" in window.statusBar().currentMessage()

    # a typed albedo: κ follows, and the scene's albedo becomes it
    user.type_into("colour_albedo_entry", "0.3,0.2,0.5")
    np.testing.assert_allclose(truth["panel"] * panel.kappa, [0.3, 0.2, 0.5], rtol=0.02)
    kappa = panel.kappa.copy()
    # an albedo of 1 or more is refused with the reason; nothing changes
    user.type_into("colour_albedo_entry", "0.3,1.2,0.5")
    np.testing.assert_array_equal(panel.kappa, kappa)
    assert "impossible" in dialogs.texts("warning")[-1] and "impossible" in user.find("colour_warning").text()
    # so is a typed κ that would reach it (the κ range stops below 1 / albedo)
    green = user.find("kappa_G_value", QDoubleSpinBox)
    user.click("kappa_link")
    assert not user.find("kappa_link").isChecked()
    user.type_into(green, f"{1.05 / measured[1]:.3f}")
    np.testing.assert_array_equal(panel.kappa, kappa)
    assert "albedo of 1 or more" in dialogs.texts("warning")[-1]

    # the eyedropper on the right wall, a measured target: the panel takes the wall's albedo (its
    # chromaticity; the wall is out of the chart's plane, so its brightness is not absolute)
    wall = doc.by_name("right_wall")
    ys, xs = np.nonzero(wall.mask)
    x, y = int(np.median(xs)), int(np.median(ys))
    user.click("colour_eyedropper")
    user.click_on_canvas(window.canvas, x + 0.5, y + 0.5)
    np.testing.assert_allclose(_chromaticity(truth["panel"] * panel.kappa), _chromaticity(truth["right_wall"]),
                               atol=0.01)


def test_a_chart_the_detector_misses_is_placed_by_hand(checker_lab, dialogs, monkeypatch, qtbot):
    """The detector's message said "place its four corners by hand" and the app had no way to: now the lab tech
    answers Yes, clicks the four corners on the canvas (Esc would cancel), and the albedo is as absolute as when
    the chart is found."""
    from PySide6.QtWidgets import QMessageBox

    import engine.workflow.colour as workflow_colour
    from engine.checker import NoChart, detect_checker

    window, user, rig = checker_lab
    doc = window.doc
    truth = rig.truth.albedo()[doc.by_name("panel").mask].mean(axis=0)
    corners = detect_checker(doc.photograph).corners  # where the chart is (the lab tech sees it)
    user.trigger("acquire")
    user.type_into("acquire_order", "2")
    user.click("acquire_start")
    user.select_row(user.find("targets_list", QListWidget), 1)

    def missed(_image):  # a chart the detector cannot find (half hidden, too oblique, too far)
        raise NoChart("no ColorChecker found in the photograph: place its four corners by hand "
                      "(dark skin, bluish green, black, white)")

    monkeypatch.setattr(workflow_colour, "detect_checker", missed)
    dialogs.answers = [QMessageBox.StandardButton.No]
    user.click("colour_checker")
    assert not window.corners.active and "relative" in user.find("colour_albedo", QLabel).text()  # No: nothing
    dialogs.answers = [QMessageBox.StandardButton.Yes]
    user.click("colour_checker")
    assert window.corners.active and window.canvas.picking
    assert "dark skin (top left) patch (1 of 4; Esc cancels)" in window.statusBar().currentMessage()
    user.click_on_canvas(window.canvas, *corners[0])
    user.press(Qt.Key.Key_Escape)  # changed their mind: start again
    assert not window.corners.active and not window.canvas.picking
    assert window.statusBar().currentMessage() == "Placing the colour checker's corners was cancelled"
    for other in (lambda: user.trigger("tool_lasso"), lambda: user.click("colour_eyedropper")):
        dialogs.answers = [QMessageBox.StandardButton.Yes]
        user.click("colour_checker")
        assert window.corners.active
        other()  # another tool, or the eyedropper, ends the placing too
        assert not window.corners.active
    user.click("colour_eyedropper")  # the eyedropper off again
    user.trigger("tool_brush")
    assert not window.canvas.picking
    dialogs.answers = [QMessageBox.StandardButton.Yes]
    user.click("colour_checker")
    masks = [t.mask.copy() for t in doc.targets]
    for i, (x, y) in enumerate(corners):
        if i:
            assert f"({i + 1} of 4; Esc cancels)" in window.statusBar().currentMessage()
        user.click_on_canvas(window.canvas, x, y)
    qtbot.waitUntil(lambda: window.job is None)
    shown = user.find("colour_albedo", QLabel).text()
    assert shown.startswith("Absolute albedo "), shown
    np.testing.assert_allclose(np.array(_numbers(shown)[3:6]), truth, rtol=0.03)
    assert not window.canvas.picking and all(np.array_equal(m, t.mask) for m, t in zip(masks, doc.targets,
                                                                                      strict=True))
    assert [k for k, _t, _x in dialogs.shown].count("critical") == 0
