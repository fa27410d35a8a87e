"""The main window: albedo sliders and the preview, locks, files, export, prompts, errors."""

from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtWidgets import QMessageBox

from app.model import files
from app.model.display import to_rgb32
from app.model.document import Document
from app.model.views import CanvasView
from app.qt.panels import kappa_to_ticks
from engine import imageio
from engine.recolor import prepare_preview, recolor, recolor_preview
from engine.session import Session

Button = QMessageBox.StandardButton


def _drag_slider(slider, ticks_seq):
    slider.setSliderDown(True)  # emits sliderPressed, as a mouse grab does
    for t in ticks_seq:
        slider.setValue(t)
    slider.setSliderDown(False)


def test_slider_moves_change_the_preview_as_engine_recolor_predicts(make_window, acquired_doc):
    w = make_window(acquired_doc)
    d = acquired_doc.decomposition
    panel = w.albedo_panel
    assert panel.uid == acquired_doc.by_name("wall").uid
    panel.link.setChecked(False)
    steps = w.undo_group.activeStack().count()
    _drag_slider(panel.sliders[0], [20, 60, 100])  # R: κ 1 → 2 in one drag
    _drag_slider(panel.sliders[2], [-100, -300])  # B: κ 1 → 1/8
    kappa = np.array([2.0, 1.0, 0.125])
    np.testing.assert_array_equal(acquired_doc.by_name("wall").kappa, kappa)
    assert w.undo_group.activeStack().count() == steps + 2  # one undo step per drag
    pack = prepare_preview(d, w._screen_shape())
    frame = w.canvas.frame
    np.testing.assert_array_equal(frame.pixels, to_rgb32(recolor_preview(pack, kappa)))
    assert frame.pixels.shape == d.target.shape  # the synthetic image fits the screen: full resolution
    np.testing.assert_array_equal(frame.pixels, to_rgb32(recolor(d, kappa)))
    panel.link.setChecked(True)
    _drag_slider(panel.sliders[1], [100])  # G doubles: linked channels keep their ratios
    np.testing.assert_allclose(acquired_doc.by_name("wall").kappa, kappa * 2)
    np.testing.assert_array_equal(w.canvas.frame.pixels, to_rgb32(recolor(d, acquired_doc.by_name("wall").kappa)))
    panel.spins[0].setValue(3.0)  # numeric entry
    assert acquired_doc.by_name("wall").kappa[0] == 3.0
    assert panel.sliders[0].value() == kappa_to_ticks(3.0)
    w.act_undo.trigger()
    w.act_undo.trigger()
    np.testing.assert_array_equal(acquired_doc.by_name("wall").kappa, kappa)
    np.testing.assert_array_equal(w.canvas.frame.pixels, to_rgb32(recolor(d, kappa)))
    assert panel.sliders[2].value() == -300  # the model's undo moved the slider back
    panel.reset.click()
    np.testing.assert_array_equal(acquired_doc.by_name("wall").kappa, [1, 1, 1])


def test_earlier_cascade_target_is_locked_with_a_reason(make_window, acquired_doc):
    w = make_window(acquired_doc)
    floor = acquired_doc.by_name("floor")
    acquired_doc.set_current(floor.uid)
    panel = w.albedo_panel
    assert not any(s.isEnabled() for s in panel.sliders + panel.spins) and not panel.reset.isEnabled()
    assert "fixed" in panel.sliders[0].toolTip() and "paper Sec. 4" in panel.sliders[0].toolTip()
    np.testing.assert_array_equal([panel.spins[c].value() for c in range(3)], [0.5, 1.0, 1.0])
    acquired_doc.set_current(acquired_doc.by_name("wall").uid)
    assert all(s.isEnabled() for s in panel.sliders) and "Last target" in panel.note.text()
    assert not w.act_clear_mask.isEnabled()  # acquired masks are fixed too


def test_views_are_offered_when_they_make_sense(make_window, synthetic, acquired_doc):
    d, photo = synthetic
    bare = make_window(Document(photo))
    enabled = {v for v, a in bare.view_actions.items() if a.isEnabled()}
    assert enabled == {CanvasView.RECOLORED, CanvasView.ORIGINAL, CanvasView.SPLIT, CanvasView.DIFFERENCE}
    assert not bare.act_export.isEnabled()
    # a disabled entry says why, in its tooltip (shown by the menus too)
    assert bare.act_export.toolTip().endswith("(unavailable: acquire a target first (Rig ▸ Acquire…))")
    assert "unavailable: acquire a target first" in bare.view_actions[CanvasView.COMPONENTS].toolTip()
    assert "acquire a target first" in bare.view_actions[CanvasView.ERROR].toolTip()
    assert "ground truth" in bare.view_actions[CanvasView.TRUTH].toolTip()
    assert all(a.menu().toolTipsVisible() for a in bare.menuBar().actions())
    assert "unavailable" not in bare.act_save.toolTip()
    seen = []
    bare.run_job(lambda progress=None, should_stop=None: seen.append(bare.act_save.toolTip()), name="Exporting")
    assert seen and seen[0].endswith("(unavailable: wait for Exporting to end)")
    assert "(unavailable: open a rig first" in bare.act_acquire.toolTip()
    assert bare.act_close_rig.toolTip().endswith("(unavailable: no rig is open)")
    empty = make_window()
    assert empty.act_save.toolTip().endswith("(unavailable: open a session or an image first (File ▸ Open))")
    assert empty.view_actions[CanvasView.ORIGINAL].toolTip().endswith("(unavailable: open a session or an image "
                                                                     "first (File ▸ Open))")
    w = make_window(acquired_doc)
    assert not any("unavailable" in a.toolTip() for a in w.view_actions.values())
    assert all(a.isEnabled() for a in w.view_actions.values())
    w.set_view(CanvasView.TRUTH)
    wall = acquired_doc.by_name("wall")
    acquired_doc.set_kappa(wall.uid, 2.0)
    np.testing.assert_array_equal(w.canvas.frame.linear, recolor(d, 2.0))
    w.set_view(CanvasView.ERROR)
    assert w.canvas.frame.note.startswith("relative error 0.00 %") and w.canvas.frame.scale is not None
    w.set_view(CanvasView.COMPONENTS)
    assert len(w.canvas.frame.tiles) == d.order
    acquired_doc.discard_acquisition()
    assert w.preview.view == CanvasView.RECOLORED and not w.view_actions[CanvasView.COMPONENTS].isEnabled()


@pytest.mark.parametrize(
    "suffix, dtype, tol",
    [(".exr", "half", 1e-3), (".exr", "float", 0.0), (".tif", "float", 0.0), (".tif", "uint16", 0.6 / 65535)],
)
def test_export_writes_pixels_and_the_edit(make_window, acquired_doc, tmp_path, suffix, dtype, tol):
    w = make_window(acquired_doc)
    wall = acquired_doc.by_name("wall")
    acquired_doc.set_kappa(wall.uid, [2.0, 0.125, 1.5])
    expected = recolor(acquired_doc.decomposition, [2.0, 0.125, 1.5])
    exposure = 0.0
    if dtype == "uint16":
        exposure = -float(np.ceil(np.log2(expected.max())))
        w.exposure_spin.setValue(exposure)
    path = tmp_path / f"out{suffix}"
    w.export(path, dtype=dtype)
    back = imageio.read_image(path)
    np.testing.assert_allclose(back, expected * np.float32(2.0**exposure), rtol=tol, atol=tol)
    meta = imageio.read_metadata(path)["edit"]
    assert meta["cascade"] == ["floor", "wall"] and meta["order"] == 4 and meta["kappa"] == [2.0, 0.125, 1.5]
    assert [t["name"] for t in meta["targets"]] == ["floor", "wall"]
    assert meta["targets"][0]["kappa"] == [0.5, 1.0, 1.0] and meta["targets"][1]["pixels"] == int(wall.mask.sum())


def test_png_export_and_refusals(make_window, acquired_doc, tmp_path, dialogs):
    w = make_window(acquired_doc)
    w.exposure_spin.setValue(1.0)
    w.export(tmp_path / "share.png")
    png = imageio.read_image(tmp_path / "share.png", srgb=False)
    expected = imageio.to_display(recolor(acquired_doc.decomposition, 1.0), exposure=1.0)
    np.testing.assert_array_equal(np.round(png * 255).astype(np.uint8), expected)
    assert imageio.read_metadata(tmp_path / "share.png")["edit"]["display"]["exposure"] == 1.0
    # a 16-bit TIFF cannot hold values above 1: asked, refused without clipping
    w.exposure_spin.setValue(6.0)
    dialogs.answers = [Button.No]
    w.export(tmp_path / "bright.tif", dtype="uint16")
    assert "allow clipping" in dialogs.texts("question")[-1] and not (tmp_path / "bright.tif").exists()
    dialogs.answers = [Button.Yes]
    w.export(tmp_path / "bright.tif", dtype="uint16")
    from PySide6.QtCore import QCoreApplication

    QCoreApplication.processEvents()  # the clipped export is queued after the answer
    meta = imageio.read_metadata(tmp_path / "bright.tif")["edit"]["linear"]
    assert meta["clipped_values"] > 0
    w.export(tmp_path / "missing" / "x.exr")  # an unwritable place: an error dialog, nothing else
    assert dialogs.texts("critical") and "Export failed" in [t for k, t, _ in dialogs.shown if k == "critical"]
    assert w.job is None and w.canvas.isEnabled()


def test_save_and_reopen_restores_the_edit(make_window, acquired_doc, tmp_path):
    w = make_window(acquired_doc)
    wall = acquired_doc.by_name("wall")
    acquired_doc.set_kappa(wall.uid, [2.0, 0.125, 8.0])
    extra = acquired_doc.add_target("later")
    acquired_doc.paint(extra.uid, (0, 5, 0, 5), np.ones((5, 5), bool), True)
    assert w.save_as(tmp_path / "s") and not acquired_doc.is_dirty() and not w.isWindowModified()
    doc, session, warnings = files.open_document(tmp_path / "s")
    assert warnings == [] and not doc.is_dirty() and isinstance(session, Session)
    assert [t.name for t in doc.targets] == ["floor", "wall", "later"]
    for a, b in zip(doc.targets, acquired_doc.targets, strict=True):
        np.testing.assert_array_equal(a.mask, b.mask)
        np.testing.assert_array_equal(a.kappa, b.kappa)
    np.testing.assert_array_equal(doc.photograph, acquired_doc.photograph)
    assert [doc.target(u).name for u in doc.acquisition.cascade] == ["floor", "wall"]
    np.testing.assert_array_equal(recolor(doc.decomposition, doc.recolor_kappa()),
                                  recolor(acquired_doc.decomposition, [2, 0.125, 8]))
    assert doc.kappa_lock(doc.by_name("floor").uid)
    # save again into the same session, then reopen in the window through recent files
    acquired_doc.rename_target(extra.uid, "renamed")
    assert w.save() and not acquired_doc.is_dirty()
    assert w.files.recent()[0] == str((tmp_path / "s").resolve())
    assert w.open_path(tmp_path / "s")
    assert [t.name for t in w.doc.targets] == ["floor", "wall", "renamed"]


def test_failed_save_loses_nothing(make_window, acquired_doc, tmp_path, monkeypatch, dialogs):
    w = make_window(acquired_doc)
    assert w.save_as(tmp_path / "s")
    wall = acquired_doc.by_name("wall")
    acquired_doc.set_kappa(wall.uid, 3.0)

    def broken(self, **fields):
        raise OSError("disk full")

    monkeypatch.setattr(Session, "update", broken)
    assert not w.save()
    assert "disk full" in dialogs.texts("critical")[-1]
    assert acquired_doc.is_dirty() and acquired_doc.by_name("wall").kappa[0] == 3.0
    monkeypatch.undo()
    doc, _, _ = files.open_document(tmp_path / "s")
    assert doc.by_name("wall").kappa[0] == 1.0  # the previous save is intact
    assert w.save()
    doc, _, _ = files.open_document(tmp_path / "s")
    assert doc.by_name("wall").kappa[0] == 3.0


def test_unsaved_changes_prompt_on_quit(make_window, acquired_doc, tmp_path, dialogs, monkeypatch):
    w = make_window(acquired_doc)
    acquired_doc.set_kappa(acquired_doc.by_name("wall").uid, 2.0)
    dialogs.answers = [Button.Cancel]
    assert not w.close() and w.isVisible() and acquired_doc.is_dirty()
    dialogs.answers = [Button.Save]
    from PySide6.QtWidgets import QFileDialog

    monkeypatch.setattr(QFileDialog, "getSaveFileName", staticmethod(lambda *a, **k: (str(tmp_path / "saved"), "")))
    assert w.close()
    assert [k for k, _, _ in dialogs.shown].count("unsaved") == 2
    doc, _, _ = files.open_document(tmp_path / "saved")
    assert doc.by_name("wall").kappa[0] == 2.0


def test_discard_closes_without_saving(make_window, synthetic, dialogs):
    _, photo = synthetic
    doc = Document(photo)
    w = make_window(doc)
    doc.add_target("x")
    dialogs.answers = [Button.Discard]
    assert w.close()
    assert dialogs.texts("unsaved")


def test_real_unsaved_prompt_offers_save_discard_cancel(make_window, acquired_doc, qtbot, monkeypatch):
    from PySide6.QtCore import QTimer
    from PySide6.QtWidgets import QApplication

    from app.qt.file_control import FileControl

    monkeypatch.undo()  # the genuine dialog this time
    w = make_window(acquired_doc)
    seen = {}

    def answer():
        box = QApplication.activeModalWidget()
        seen["buttons"] = sorted(box.button(b).text().replace("&", "")
                                 for b in (Button.Save, Button.Discard, Button.Cancel))
        box.button(Button.Cancel).click()

    QTimer.singleShot(50, answer)
    assert FileControl.ask_unsaved(w.files) == Button.Cancel
    assert len(seen["buttons"]) == 3 and {"Cancel", "Save"} <= set(seen["buttons"])


def test_acquire_refuses_unreachable_pixels(make_window, dialogs):
    unreachable = np.zeros((20, 30), bool)
    unreachable[:, :5] = True
    doc = Document(np.ones((20, 30, 3), np.float32), unreachable=unreachable)
    t = doc.add_target("t")
    doc.paint(t.uid, (0, 10, 0, 10), np.ones((10, 10), bool), True)

    class Rig:  # a camera of the photograph's size; nothing else is reached before the refusal
        camera = type("Camera", (), {"resolution": (20, 30)})()

        def close(self):
            pass

    w = make_window(doc, rig=Rig())
    doc.paint(t.uid, (12, 14, 0, 2), np.ones((2, 2), bool), True)
    assert "not reachable by the projector" in w.statusBar().currentMessage()
    w.act_acquire.trigger()
    assert "cannot reach" in dialogs.texts("critical")[-1] and "54 px" in dialogs.texts("critical")[-1]
    red = np.uint32(0xF0F00000)
    assert (w.canvas._overlay[:10, :5] == red).any() and not (w.canvas._overlay[:, 10:] == red).any()


def test_open_image_and_bad_paths(make_window, tmp_path, dialogs, synthetic):
    _, photo = synthetic
    imageio.write_image(tmp_path / "photo.exr", photo)
    w = make_window()
    assert not w.act_save.isEnabled()
    assert w.open_path(tmp_path / "photo.exr")
    np.testing.assert_array_equal(w.doc.photograph, photo)
    before = w.doc
    assert not w.open_path(tmp_path / "nope.exr")
    assert w.doc is before and "nope.exr" in dialogs.texts("critical")[-1]


def test_empty_window_says_what_is_loading(make_window):
    w = make_window()
    seen = []

    def work(progress=None, should_stop=None):
        seen.append(w.centralWidget().text())
        return 1

    w.run_job(work, name="Opening the virtual:cornell demo")
    assert seen[0].startswith("Opening the virtual:cornell demo…") and "status bar" in seen[0]
    assert w.centralWidget().text() == w.PLACEHOLDER


def test_noise_reduction_applies_previews_exports_and_is_restored(make_window, acquired_doc, tmp_path, dialogs):
    from engine.denoise import denoise_components

    w = make_window(acquired_doc)
    wall = acquired_doc.by_name("wall")
    acquired_doc.set_kappa(wall.uid, [2.0, 0.5, 4.0])
    measured = acquired_doc.decomposition
    panel = w.noise_panel
    assert panel.apply.isEnabled() and "Off" in panel.state.text()
    panel.radius.setValue(3)
    panel.apply.click()  # a job (synchronous in tests)
    expected = denoise_components(measured, acquired_doc.photograph, radius=3)
    d = acquired_doc.decomposition
    assert acquired_doc.acquisition.denoise == 3 and "radius 3" in panel.state.text()
    np.testing.assert_array_equal(d.components, expected.components)
    # the preview is the pack of the filtered decomposition, and so is the export
    kappa = acquired_doc.recolor_kappa()
    np.testing.assert_array_equal(w.canvas.frame.pixels, to_rgb32(recolor(d, kappa)))
    w.export(tmp_path / "out.exr", dtype="float")
    np.testing.assert_array_equal(imageio.read_image(tmp_path / "out.exr"), recolor(expected, kappa))
    assert imageio.read_metadata(tmp_path / "out.exr")["edit"]["denoise"] == 3
    # saved and reopened: the same filtered decomposition, without recomputing it
    assert w.save_as(tmp_path / "s")
    doc, session, warnings = files.open_document(tmp_path / "s")
    assert warnings == [] and doc.acquisition.denoise == 3
    np.testing.assert_array_equal(doc.decomposition.components, expected.components)
    np.testing.assert_array_equal(doc.acquisition.raw.components, measured.components)
    # the filtered copy is a disposable cache entry: without it the edit opens unfiltered, and says so
    for p in (tmp_path / "s" / "cache").glob("*-denoise3.npz"):
        p.unlink()
    doc, _, warnings = files.open_document(tmp_path / "s")
    assert doc.acquisition.denoise == 0 and "noise reduction (radius 3) could not be restored" in warnings[0]
    # switching it off needs no job, and saving then drops the filtered copy from the cache
    panel.radius.setValue(0)
    panel.apply.click()
    assert acquired_doc.decomposition is measured and "Off" in panel.state.text()
    panel.radius.setValue(2)
    panel.apply.click()
    assert w.save()
    assert [k for k in Session.open(tmp_path / "s").cache_keys() if "-denoise" in k] == [
        f"{acquired_doc.acquisition.key}-denoise2"]


def test_noise_reduction_of_a_soft_mask_session_filters_before_the_edge_blend_as_the_cli_does(make_window, tmp_path):
    from PySide6.QtCore import Qt
    from PySide6.QtTest import QTest
    from PySide6.QtWidgets import QPushButton, QSpinBox

    import devices
    from engine.denoise import denoise_components
    from engine.workflow import load_decomposition, open_session_for_rig, run_calibration, run_capture

    with devices.open_rig("virtual:cornell", resolution=(24, 24), seed=2, supersample=2) as rig:
        session = open_session_for_rig(tmp_path / "s", rig)
        run_calibration(rig, session, levels=5)
        run_capture(rig, session, [("right_wall", rig.coverage["right_wall"])], 3)
    doc, session, warnings = files.open_document(tmp_path / "s")
    measured = doc.decomposition
    assert measured.blended is not None and measured.blended.any()  # a soft mask: edge pixels blended
    w = make_window(doc, session)
    radius = w.findChild(QSpinBox, "noise_radius")
    radius.setValue(2)
    QTest.mouseClick(w.findChild(QPushButton, "noise_apply"), Qt.MouseButton.LeftButton)  # a job (synchronous)
    assert doc.acquisition.denoise == 2
    # the same decomposition as `albedit recolor --denoise 2`, not the blended one filtered
    expected = load_decomposition(Session.open(tmp_path / "s"), doc.acquisition.key, denoise=2)
    np.testing.assert_array_equal(doc.decomposition.components, expected.components)
    filtered_after = denoise_components(measured, doc.photograph, radius=2)
    assert not np.allclose(doc.decomposition.components[:, measured.blended],
                           filtered_after.components[:, measured.blended])


def test_application_icon_renders(qtbot):
    from PySide6.QtGui import QIcon

    from app.qt.gui import ICON

    assert not QIcon(str(ICON)).pixmap(32, 32).isNull()


def test_job_progress_offers_pause_and_cancel_only_where_they_work(make_window, acquired_doc, tmp_path):
    w = make_window(acquired_doc)
    shown = {}
    attach = w.progress.attach

    def spy(job, **kw):  # what the status bar shows while each job runs
        attach(job, **kw)
        shown[job.name] = (w.progress.pause.isVisibleTo(w), w.progress.cancel.isVisibleTo(w))

    w.progress.attach = spy
    w.save_as(tmp_path / "s")
    w.open_path(tmp_path / "s")
    assert shown["Saving"] == (False, False) and shown["Opening s"] == (False, True)
    w.noise_panel.radius.setValue(2)
    w.noise_panel.apply.click()
    assert shown["Noise reduction"] == (True, True)


def test_toolbars_wrap_onto_a_second_row_when_the_window_is_narrow(make_window, acquired_doc, qtbot):
    """On a laptop-wide window the View toolbar's end (Noise σ, exposure, zoom) was hidden behind »."""
    from PySide6.QtWidgets import QToolBar

    w = make_window(acquired_doc)
    tools, view = w.findChild(QToolBar, "tools"), w.findChild(QToolBar, "view")
    w.resize(tools.sizeHint().width() + view.sizeHint().width() + 40, 800)
    qtbot.waitUntil(lambda: not w.toolBarBreak(view))
    qtbot.waitUntil(lambda: view.geometry().top() == tools.geometry().top())  # one row
    w.resize(tools.sizeHint().width() + 40, 800)
    qtbot.waitUntil(lambda: w.toolBarBreak(view))
    qtbot.waitUntil(lambda: view.geometry().top() >= tools.geometry().bottom())  # its own row, nothing hidden
    assert view.geometry().width() >= view.sizeHint().width()
    w.resize(tools.sizeHint().width() + view.sizeHint().width() + 40, 800)
    qtbot.waitUntil(lambda: not w.toolBarBreak(view))  # wide again: one row again
