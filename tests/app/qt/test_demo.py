"""The virtual-rig demo (acquired through engine.workflow) and the gui entry point."""

from __future__ import annotations

import numpy as np
import pytest

from app.model import files
from app.model.demo import DEMO_KAPPA, open_demo
from app.model.render import View
from engine import imageio
from engine.recolor import recolor

RIG = {"resolution": (48, 48), "cache_dir": False}


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    doc, rig, session = open_demo(folder=tmp_path_factory.mktemp("demo"), **RIG)
    yield doc, rig, session
    rig.close()


def test_demo_acquires_the_right_wall_like_fig6(demo):
    doc, rig, session = demo
    assert [t.name for t in doc.targets][-1] == "right_wall" and set(rig.targets) == {t.name for t in doc.targets}
    wall = doc.by_name("right_wall")
    np.testing.assert_array_equal(wall.kappa, DEMO_KAPPA)
    assert doc.acquisition.cascade == (wall.uid,) and not doc.is_dirty()
    assert doc.unreachable is not None and doc.unreachable.shape == doc.shape
    doc.check_acquirable([wall.uid])  # the app agrees with the engine, which acquired every pixel
    truth = rig.truth.recolor([(wall.mask, np.array(DEMO_KAPPA))])
    est = recolor(doc.decomposition, DEMO_KAPPA)
    assert np.linalg.norm(est - truth) / np.linalg.norm(truth) < 0.01
    # the wall really turned from green to blue
    g, b = est[wall.mask].mean(axis=0)[1:]
    g0, b0 = doc.photograph[wall.mask].mean(axis=0)[1:]
    assert g0 > b0 and b > g


def test_unreachable_pixels_are_the_unlit_ones():
    from types import SimpleNamespace

    from app.model.files import unreachable_pixels

    status = np.array([[0, 1, 2, 3]], np.uint8)  # decoded, unlit, low contrast, out of range
    cal = SimpleNamespace(correspondence=SimpleNamespace(status=status))
    assert unreachable_pixels(cal).tolist() == [[False, True, False, True]]


def test_demo_session_reopens_with_its_acquisition(demo):
    doc, _, session = demo
    reopened, _, warnings = files.open_document(session.path)
    assert warnings == []
    assert [t.name for t in reopened.targets] == ["right_wall"]  # the plan's targets
    np.testing.assert_array_equal(reopened.photograph, doc.photograph)
    np.testing.assert_array_equal(reopened.unreachable, doc.unreachable)  # from the session's calibration
    np.testing.assert_array_equal(reopened.decomposition.components, doc.decomposition.components)


def test_window_demo_saves_a_copy_and_cleans_up(make_window, tmp_path, monkeypatch):
    import app.model.demo

    real = app.model.demo.open_demo
    monkeypatch.setattr(app.model.demo, "open_demo", lambda name, **kw: real(name, **RIG, **kw))
    w = make_window()
    w.open_demo()
    assert w.doc is not None and w.scratch is not None and w.scratch.exists()
    scratch = w.scratch
    assert "demo (not saved)" in w.windowTitle() and w.rig is not None
    w.set_view(View.ERROR)
    assert w.canvas.frame.note.startswith("relative error") and "without the lamp" in w.canvas.frame.note
    assert w.save_as(tmp_path / "kept")
    assert not scratch.exists() and w.scratch is None
    doc, session, _ = files.open_document(tmp_path / "kept")
    assert any(c.meta.get("kind") == "photograph" for c in session.captures)
    np.testing.assert_array_equal(doc.by_name("right_wall").kappa, DEMO_KAPPA)
    w.export(tmp_path / "fig6.exr", dtype="float")
    np.testing.assert_array_equal(imageio.read_image(tmp_path / "fig6.exr"), recolor(w.doc.decomposition, DEMO_KAPPA))


_MAIN_SCRIPT = """
import sys
import numpy as np
from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QApplication
from app.qt.gui import main
from app.qt.main_window import MainWindow

tries = [0]

def check():  # the path opens on a worker: wait for it (up to 20 s)
    windows = [w for w in QApplication.topLevelWidgets() if isinstance(w, MainWindow) and w.isVisible()]
    tries[0] += 1
    if (not windows or windows[0].doc is None) and tries[0] < 200:
        QTimer.singleShot(100, check)
        return
    print("windows", len(windows), "document", windows[0].doc.shape if windows and windows[0].doc else None)
    for w in windows:
        w.close()

app = QApplication(["albedit"])  # main() uses the running application
QTimer.singleShot(100, check)
print("exit", main([sys.argv[1]]))
"""


def test_gui_main_opens_a_path_and_returns(tmp_path, synthetic):
    """In a subprocess: after a QApplication.exec() in-process, PySide stops delivering queued
    signals from Python threads to later tests (seen with pytest-qt; not in a plain script)."""
    import os
    import subprocess
    import sys

    _, photo = synthetic
    imageio.write_image(tmp_path / "p.exr", photo)
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", XDG_CONFIG_HOME=str(tmp_path / "config"))
    out = subprocess.run([sys.executable, "-c", _MAIN_SCRIPT, str(tmp_path / "p.exr")], env=env,
                         capture_output=True, text=True, timeout=60, cwd=os.getcwd())
    assert out.returncode == 0, out.stderr
    assert "windows 1 document (48, 64)" in out.stdout and "exit 0" in out.stdout
