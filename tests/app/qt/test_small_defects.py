"""Issue 10, defect 14 (the smaller ones) that no journey covers on its way."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
from PySide6.QtWidgets import QMessageBox

import app
from tests.app.qt.user import User


def test_noise_reduction_is_one_undo_step(make_window, acquired_doc, qtbot):
    window = make_window(acquired_doc)
    user = User(qtbot, window)
    measured = acquired_doc.decomposition
    user.type_into("noise_radius", "2")
    user.click("noise_apply")
    assert acquired_doc.acquisition.denoise == 2 and acquired_doc.decomposition is not measured
    assert window.act_undo.text() == "&Undo Noise reduction 2 px"
    user.trigger("undo")
    assert acquired_doc.acquisition.denoise == 0 and acquired_doc.decomposition is measured
    assert "Off" in user.find("noise_state").text()
    user.trigger("redo")
    assert acquired_doc.acquisition.denoise == 2


def test_the_version_is_in_about_and_on_the_command_line(make_window, qtbot, monkeypatch):
    shown = []
    monkeypatch.setattr(QMessageBox, "about", staticmethod(lambda parent, title, text: shown.append(text)))
    User(qtbot, make_window()).trigger("about")
    assert f"Albedit {app.__version__}" in shown[0] and app.__version__ not in ("", "unknown")
    out = subprocess.run([sys.executable, "-m", "app.main", "--version"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == f"albedit {app.__version__}"


def test_an_exception_escaping_a_slot_fails_the_test(qtbot):
    """The harness itself: pytest-qt's exception capture is on for every test (never disabled here)."""
    from PySide6.QtWidgets import QPushButton

    button = QPushButton()
    qtbot.addWidget(button)
    button.clicked.connect(lambda: np.zeros(2)[5])
    with qtbot.captureExceptions() as caught:
        button.click()
    assert len(caught) == 1 and caught[0][0] is IndexError


def test_a_greyscale_photograph_opens_as_grey_rgb(make_window, qtbot, tmp_path):
    """Defect 14: a greyscale PNG was refused ("an RGB image is needed, got shape (300, 400, 1)")."""
    from engine import imageio

    grey = np.linspace(0, 1, 12 * 16, dtype=np.float32).reshape(12, 16)
    imageio.write_image(tmp_path / "grey.png", imageio.to_display(np.repeat(grey[..., None], 3, 2))[..., :1])
    window = make_window()
    assert window.open_path(tmp_path / "grey.png")
    photo = window.doc.photograph
    assert photo.shape == (12, 16, 3)
    np.testing.assert_array_equal(photo[..., 0], photo[..., 1])
    np.testing.assert_array_equal(photo[..., 0], photo[..., 2])


def test_an_export_that_needs_clipping_says_so_by_its_type(acquired_doc, tmp_path):
    """Issue 12: the window asked about clipping by matching the message text."""
    import pytest

    from app.model import files

    acquired_doc.set_kappa(acquired_doc.by_name("wall").uid, 16.0)
    with pytest.raises(files.NeedsClipping, match="allow clipping"):
        files.export_image(acquired_doc, tmp_path / "x.tif", dtype="uint16", exposure=8.0)
    assert files.export_image(acquired_doc, tmp_path / "x.tif", dtype="uint16", exposure=8.0, clip=True).exists()


def test_refine_edge_shows_a_busy_cursor_while_it_works(make_window, qtbot, monkeypatch, tmp_path):
    """Refine Edge runs on the window's thread (seconds on a long outline): the wait cursor shows meanwhile and is
    gone afterwards, also when the refinement refuses."""
    from PySide6.QtCore import Qt
    from PySide6.QtWidgets import QApplication

    from app.model.document import Document
    from engine import imageio
    from engine.errors import InputError

    imageio.write_image(tmp_path / "photo.png", np.full((12, 16, 3), 128, np.uint8))
    window = make_window()
    user = User(qtbot, window)
    assert window.open_path(tmp_path / "photo.png")
    user.trigger("add_target")
    seen = []

    def refine(doc, uid):
        seen.append(QApplication.overrideCursor().shape())
        raise InputError("no photograph to refine from")

    monkeypatch.setattr(Document, "refine_edge", refine)
    user.trigger("refine_edge")
    assert seen == [Qt.CursorShape.WaitCursor] and QApplication.overrideCursor() is None
    assert "no photograph to refine from" in window.statusBar().currentMessage()
