"""Fixtures for the app tests: synthetic decompositions, documents, windows (offscreen Qt)."""

from __future__ import annotations

import os

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from app.model.document import Document  # noqa: E402
from engine.decompose import Decomposition, observe  # noqa: E402
from engine.recolor import recolor  # noqa: E402

H, W, K = 48, 64, 4


def make_decomposition(rng, *, h=H, w=W, k=K, target=None):
    """Random components with the paper's ordering, and the photograph they predict.

    Built as the brief says: obs[r] = Σ_n M[r, n] inside[n] on the target; outside
    obs[0] = unreached + Σ_n M[0, n] outside[n] (engine.decompose.observe does the sums).
    """
    rng = np.random.default_rng(rng)
    if target is None:
        target = np.zeros((h, w), bool)
        target[h // 4 : 3 * h // 4, w // 2 : w - 4] = True
    decay = np.cumprod(rng.uniform(0.2, 0.6, size=(k, 1, 1, 3)), axis=0).astype(np.float32)
    inside = rng.uniform(0.5, 1.0, size=(1, h, w, 3)).astype(np.float32) * decay
    outside = rng.uniform(0.0, 0.3, size=(k - 1, h, w, 3)).astype(np.float32) * decay[: k - 1]
    unreached = rng.uniform(0.1, 0.6, size=(h, w, 3)).astype(np.float32)
    d = Decomposition.from_components(inside, outside, unreached, target)
    return d, observe(d)[0]


class FakeTruth:
    """Ground truth of a synthetic scene: the true decomposition of one target, recolored."""

    def __init__(self, decomposition: Decomposition):
        self.d = decomposition
        self.calls = 0

    def recolor(self, pairs):
        self.calls += 1
        kappa = np.ones(3)
        for mask, k in pairs:
            if np.array_equal(mask, self.d.target):
                kappa = np.asarray(k, float)
        return recolor(self.d, kappa)


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


@pytest.fixture
def synthetic():
    """(decomposition, photograph) of a seeded random scene."""
    return make_decomposition(7)


@pytest.fixture
def acquired_doc(synthetic):
    """A document with two targets, 'floor' then 'wall', cascade acquired (wall last, free)."""
    d, photo = synthetic
    doc = Document(photo, truth=FakeTruth(d), source="synthetic")
    floor_mask = np.zeros(d.target.shape, bool)
    floor_mask[2:10, 2:20] = True
    floor = doc.add_target("floor", floor_mask, kappa=(0.5, 1.0, 1.0))
    wall = doc.add_target("wall", d.target)
    doc.set_acquisition([floor.uid, wall.uid], d)
    doc.history.clear()
    doc.mark_saved()
    return doc


@pytest.fixture
def make_window(qtbot, tmp_path):
    """Factory for a synchronous MainWindow with private settings."""
    from PySide6.QtCore import QSettings

    from app.qt.main_window import MainWindow

    windows = []

    def make(document=None, session=None, **kw):
        settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
        kw.setdefault("synchronous", True)
        w = MainWindow(document, session, settings=settings, **kw)
        w.resize(1200, 800)
        w.show()
        qtbot.waitExposed(w)
        w.activateWindow()  # shortcuts go to the active window, as on a desktop
        qtbot.waitUntil(w.isActiveWindow)
        windows.append(w)
        return w

    yield make
    for w in windows:  # close without the unsaved-changes prompt
        if w.doc is not None:
            w.doc.mark_saved()
        w.close()
        w.deleteLater()


class Dialogs:
    """Records message boxes instead of showing them (a modal dialog would hang a test)."""

    def __init__(self):
        self.shown: list[tuple[str, str, str]] = []
        self.answers: list = []  # answers for question boxes and the unsaved prompt, in order

    def _answer(self, default):
        return self.answers.pop(0) if self.answers else default

    def texts(self, kind=None) -> list[str]:
        return [text for k, _title, text in self.shown if kind is None or k == kind]


@pytest.fixture(autouse=True)
def dialogs(monkeypatch):
    from PySide6.QtWidgets import QMessageBox

    from app.qt.file_control import FileControl

    rec = Dialogs()
    for kind in ("critical", "warning", "information"):
        monkeypatch.setattr(QMessageBox, kind, staticmethod(
            lambda parent, title, text, *a, kind=kind, **k: rec.shown.append((kind, title, text))
            or QMessageBox.StandardButton.Ok))

    def question(parent, title, text, *a, **k):
        rec.shown.append(("question", title, text))
        return rec._answer(QMessageBox.StandardButton.No)

    def unsaved(self):
        rec.shown.append(("unsaved", "", "The document has unsaved changes."))
        return rec._answer(QMessageBox.StandardButton.Cancel)

    monkeypatch.setattr(QMessageBox, "question", staticmethod(question))
    monkeypatch.setattr(FileControl, "ask_unsaved", unsaved)
    return rec


@pytest.fixture(scope="session")
def virtual_cache(tmp_path_factory):
    """One virtual-rig set-up cache for every app test that opens a rig."""
    path = tmp_path_factory.getbasetemp() / "virtual-cache"
    path.mkdir(exist_ok=True)
    return path
