"""The virtual-rig demo (acquired through engine.workflow) and the gui entry point."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from app.model import files
from app.model.demo import DEMO_KAPPA, open_demo
from app.model.views import CanvasView
from engine import imageio
from engine.recolor import recolor
from engine.trust import recolor_trusted

RIG = {"resolution": (48, 48), "cache_dir": False}


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    d = open_demo(folder=tmp_path_factory.mktemp("demo"), **RIG)
    yield d.document, d.rig, d.session
    d.rig.close()


def test_demo_acquires_the_right_wall_like_fig6(demo):
    doc, rig, session = demo
    assert [t.name for t in doc.targets][-1] == "right_wall" and set(rig.targets) == {t.name for t in doc.targets}
    wall = doc.by_name("right_wall")
    assert [t.name for t in doc.acquisition_targets()] == ["right_wall"]  # the others are painted for reference
    np.testing.assert_array_equal(wall.kappa, DEMO_KAPPA)
    assert doc.acquisition.cascade == (wall.uid,) and not doc.is_dirty()
    assert doc.unreachable is not None and doc.unreachable.shape == doc.shape
    doc.check_acquirable([wall.uid])  # the app agrees with the engine, which acquired every pixel
    # replayed offline (the noise-aware recolor), the captures carry the ideal projector's rounding, not 8 bits'
    assert session.metadata["projector_bit_depth"] == rig.projector.bit_depth == 24
    truth = rig.truth.recolor([(wall.mask, np.array(DEMO_KAPPA))])
    est = recolor(doc.decomposition, DEMO_KAPPA)
    assert np.linalg.norm(est - truth) / np.linalg.norm(truth) < 0.01
    # the wall really turned from green to blue
    g, b = est[wall.mask].mean(axis=0)[1:]
    g0, b0 = doc.photograph[wall.mask].mean(axis=0)[1:]
    assert g0 > b0 and b > g


def test_unreachable_pixels_are_the_unlit_ones():
    from types import SimpleNamespace

    from app.model.files import unlit_pixels

    status = np.array([[0, 1, 2, 3]], np.uint8)  # decoded, unlit, low contrast, out of range
    cal = SimpleNamespace(correspondence=SimpleNamespace(status=status))
    assert unlit_pixels(cal).tolist() == [[False, True, False, True]]


def test_demo_session_reopens_with_its_acquisition(demo):
    doc, _, session = demo
    reopened, _, warnings = files.open_document(session.path)
    assert warnings == []
    assert [t.name for t in reopened.targets] == ["right_wall"]  # the plan's targets
    np.testing.assert_array_equal(reopened.photograph, doc.photograph)
    np.testing.assert_array_equal(reopened.unreachable, doc.unreachable)  # from the session's calibration
    np.testing.assert_array_equal(reopened.decomposition.components, doc.decomposition.components)


def test_window_demo_saves_a_copy_and_reuses_its_cached_session(make_window, tmp_path, monkeypatch):
    """Defect 12: the demo's session lives in the cache folder and is reused; Save As copies it."""
    import app.model.demo

    real = app.model.demo.open_demo
    monkeypatch.setattr(app.model.demo, "open_demo", lambda name, **kw: real(name, **dict(kw, **RIG)))
    w = make_window()
    w.open_demo()
    assert w.doc is not None and w.demo and w.session is not None and w.rig is not None
    cached = Path(w.session.path)
    assert cached.parent == Path(os.environ["XDG_CACHE_HOME"]) / "albedit" / "demo"  # the user cache, not doubled
    taken = {c.name: c.sha256 for c in w.session.captures}
    assert "demo (not saved)" in w.windowTitle()
    w.set_view(CanvasView.ERROR)
    assert w.canvas.frame.note.startswith("relative error") and "without the lamp" in w.canvas.frame.note
    from PySide6.QtWidgets import QFileDialog

    monkeypatch.setattr(QFileDialog, "getSaveFileName", staticmethod(lambda *a, **k: (str(tmp_path / "kept"), "")))
    assert w.save()  # the demo's Save is a Save As: the cached session stays as it was
    doc, session, _ = files.open_document(tmp_path / "kept")
    assert any(c.meta.get("kind") == "photograph" for c in session.captures)
    np.testing.assert_array_equal(doc.by_name("right_wall").kappa, DEMO_KAPPA)
    assert not w.demo and Path(w.session.path) == tmp_path / "kept" and cached.exists()
    w.export(tmp_path / "fig6.exr", dtype="float")
    assert w.doc.trusted is not None  # export prepares the noise-aware recolor first when it is not ready yet
    np.testing.assert_array_equal(imageio.read_image(tmp_path / "fig6.exr"),
                                  recolor_trusted(w.doc.trusted, DEMO_KAPPA).image)
    w.open_demo()  # a second start: the same session, nothing captured again
    assert Path(w.session.path) == cached and {c.name: c.sha256 for c in w.session.captures} == taken


def test_old_demo_sessions_are_pruned(tmp_path):
    import os

    from app.model.demo import KEEP

    d = open_demo(folder=tmp_path, acquire=True, **RIG)
    d.rig.close()
    used = Path(d.session.path)
    for i in range(3):  # sessions of other set-ups, older
        old = tmp_path / f"demo-cornell-{i:016d}"
        old.mkdir()
        os.utime(old, (1000 + i, 1000 + i))
    d = open_demo(folder=tmp_path, **RIG)
    d.rig.close()
    left = sorted(p.name for p in tmp_path.iterdir())
    assert len(left) == KEEP and used.name in left and "demo-cornell-0000000000000002" in left



def test_a_demo_session_left_by_an_older_acquisition_is_built_again(tmp_path, monkeypatch):
    """The demo's session is a cache: captures an older Albedit took with other patterns are replaced."""
    from engine.acquire.emission import Emitter

    current = Emitter._warp
    with monkeypatch.context() as older:  # an acquisition whose re-emission patterns differ
        older.setattr(Emitter, "_warp", lambda self, light: current(self, light) * np.float32(0.9))
        d = open_demo(folder=tmp_path, **RIG)
        d.rig.close()
    first = Path(d.session.path)
    shutil.rmtree(first / "cache")  # its decomposition is recomputed from those captures (as after a format change)
    d = open_demo(folder=tmp_path, **RIG)  # raised "taken with a different projector pattern" before
    d.rig.close()
    assert Path(d.session.path) == first and d.session.state.get("status") == "captured"
    wall = d.document.by_name("right_wall")
    truth = d.rig.truth.recolor([(d.rig.targets["right_wall"], DEMO_KAPPA)])
    ours = recolor(d.document.decomposition, DEMO_KAPPA)
    assert wall is not None and np.linalg.norm(ours - truth) / np.linalg.norm(truth) < 0.05

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
