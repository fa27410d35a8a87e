"""The editing model without Qt: targets, κ, locks, undo, dirty state."""

from __future__ import annotations

import numpy as np
import pytest

from app.model.document import Document
from app.model.history import History
from engine.errors import InputError


@pytest.fixture
def doc():
    return Document(np.ones((20, 30, 3), np.float32))


def test_photograph_is_checked():
    with pytest.raises(InputError, match="floating-point"):
        Document(np.ones((4, 4, 3), np.uint8))
    with pytest.raises(InputError, match="3 channels"):
        Document(np.ones((4, 4, 2), np.float32))
    with pytest.raises(InputError, match="shape"):
        Document(np.ones((4, 4, 3), np.float32), unreachable=np.zeros((3, 4), bool))


def test_target_list_edits_undo_and_redo(doc):
    a = doc.add_target("a")
    b = doc.add_target("b")
    c = doc.add_target("a")  # names stay unique
    assert [t.name for t in doc.targets] == ["a", "b", "a (2)"]
    assert doc.current == c.uid and len({t.colour for t in doc.targets}) == 3
    doc.rename_target(b.uid, "wall")
    doc.move_target(c.uid, 0)
    doc.remove_target(a.uid)
    assert [t.name for t in doc.targets] == ["a (2)", "wall"]
    for expected in (["a (2)", "a", "wall"], ["a", "wall", "a (2)"], ["a", "b", "a (2)"], ["a", "b"], ["a"], []):
        doc.history.undo()
        assert [t.name for t in doc.targets] == expected
    for _ in range(6):
        doc.history.redo()
    assert [t.name for t in doc.targets] == ["a (2)", "wall"]


@pytest.mark.parametrize("name, match", [("", "empty"), ("b", "already used")])
def test_bad_rename_is_refused(doc, name, match):
    a = doc.add_target("a")
    doc.add_target("b")
    with pytest.raises(InputError, match=match):
        doc.rename_target(a.uid, name)


def test_kappa_gesture_is_one_undo_step(doc):
    t = doc.add_target("a")
    seen = []
    doc.events.kappa.connect(lambda uid, k: seen.append(k.copy()))
    steps = doc.history.count()
    doc.begin_kappa_gesture(t.uid)
    for v in (1.1, 1.5, 2.0, 3.0):
        doc.set_kappa(t.uid, [v, 1.0, 0.5])
    doc.end_kappa_gesture()
    assert doc.history.count() == steps + 1 and len(seen) == 4
    np.testing.assert_array_equal(t.kappa, [3.0, 1.0, 0.5])
    doc.history.undo()
    np.testing.assert_array_equal(t.kappa, [1, 1, 1])
    doc.history.redo()
    np.testing.assert_array_equal(t.kappa, [3.0, 1.0, 0.5])


@pytest.mark.parametrize("kappa", [-1.0, np.nan, [1, 2]])
def test_bad_kappa_is_refused(doc, kappa):
    t = doc.add_target("a")
    with pytest.raises(InputError, match="kappa"):
        doc.set_kappa(t.uid, kappa)


def test_acquisition_locks_earlier_cascade_targets(acquired_doc):
    doc = acquired_doc
    floor, wall = doc.by_name("floor"), doc.by_name("wall")
    assert "fixed" in doc.kappa_lock(floor.uid) and "'wall'" in doc.kappa_lock(floor.uid)
    assert doc.kappa_lock(wall.uid) == ""
    with pytest.raises(InputError, match="fixed"):
        doc.set_kappa(floor.uid, 2.0)
    doc.set_kappa(wall.uid, [2.0, 0.125, 8.0])
    np.testing.assert_array_equal(doc.recolor_kappa(), [2.0, 0.125, 8.0])
    for edit in (lambda: doc.clear_mask(wall.uid), lambda: doc.invert_mask(floor.uid),
                 lambda: doc.begin_stroke(wall.uid), lambda: doc.remove_target(floor.uid),
                 lambda: doc.move_target(wall.uid, 0)):
        with pytest.raises(InputError, match="acquired|acquisition|fixed"):
            edit()
    new = doc.add_target("later")
    assert doc.kappa_lock(new.uid) == "" and doc.mask_lock(new.uid) == ""
    doc.discard_acquisition()
    assert doc.kappa_lock(floor.uid) == "" and doc.decomposition is None
    doc.set_kappa(floor.uid, 2.0)


def test_acquisition_must_match_the_last_target(synthetic):
    d, photo = synthetic
    doc = Document(photo)
    t = doc.add_target("t", d.target)
    other = doc.add_target("o", ~d.target)
    with pytest.raises(InputError, match="outside the mask"):
        doc.set_acquisition([t.uid, other.uid], d)
    smaller = d.target.copy()
    smaller[d.target.nonzero()[0][0]] = False  # the reachable part of the mask is fine
    doc.set_acquisition([t.uid], type(d)(d.components, d.unreached, smaller))
    assert doc.acquisition.cascade == (t.uid,)


def test_unreachable_pixels_are_shown_and_refused_for_acquisition():
    unreachable = np.zeros((10, 10), bool)
    unreachable[:, :3] = True
    doc = Document(np.ones((10, 10, 3), np.float32), unreachable=unreachable)
    warnings = []
    doc.events.warning.connect(warnings.append)
    t = doc.add_target("a")
    with pytest.raises(InputError, match="empty"):
        doc.check_acquirable()
    box = np.ones((4, 6), bool)
    doc.paint(t.uid, (0, 4, 0, 6), box, True)
    assert warnings and "12 pixels" in warnings[-1]
    assert doc.unreachable_conflicts() == {"a": 12}
    with pytest.raises(InputError, match="cannot reach.*'a': 12 px"):
        doc.check_acquirable()
    doc.paint(t.uid, (0, 4, 0, 3), np.ones((4, 3), bool), False)
    doc.check_acquirable()


def test_dirty_follows_the_undo_stack(doc):
    flips = []
    doc.events.dirty.connect(flips.append)
    t = doc.add_target("a")
    assert doc.is_dirty()
    doc.mark_saved()
    assert not doc.is_dirty()
    doc.set_kappa(t.uid, 2.0)
    doc.history.undo()
    assert not doc.is_dirty()
    doc.history.undo()
    assert doc.is_dirty()
    assert flips == [True, False, True, False, True]


def test_history_drops_redo_tail_and_unreachable_clean_state():
    h = History()

    class Cmd:
        text = "x"

        def __init__(self, log, v):
            self.log, self.v = log, v

        def redo(self):
            self.log.append(self.v)

        def undo(self):
            self.log.remove(self.v)

    log = []
    h.push(Cmd(log, 1))
    h.push(Cmd(log, 2))
    h.set_clean()
    h.undo()
    h.push(Cmd(log, 3))
    assert log == [1, 3] and not h.can_redo() and not h.is_clean()
    h.undo()
    assert not h.is_clean()  # the saved state (1, 2) can never come back
    h.push(Cmd(log, 4), applied=True)
    assert log == [1] and h.undo_text() == "x"


def test_model_painting_and_rendering_never_import_qt():
    """The editing model, painting, rendering and files are Qt-free (STYLE.md: model/view split)."""
    import pkgutil
    import subprocess
    import sys

    import app.model

    modules = ", ".join(f"app.model.{m.name}" for m in pkgutil.iter_modules(app.model.__path__))
    code = (f"import sys, {modules}; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('PySide6', 'shiboken6')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_noise_reduction_swaps_the_decomposition_and_back(acquired_doc, synthetic):
    from engine.denoise import denoise_components

    doc = acquired_doc
    measured = doc.decomposition
    with pytest.raises(InputError, match="filtered decomposition"):
        doc.set_noise_reduction(3)
    with pytest.raises(InputError, match=">= 0"):
        doc.set_noise_reduction(-1)
    with pytest.raises(InputError, match="does not match"):
        cropped = type(measured)(measured.components[:, :4], measured.unreached[:4], measured.target[:4])
        doc.set_noise_reduction(3, cropped)
    filtered = denoise_components(measured, doc.photograph, radius=3)
    seen = []
    doc.events.acquisition.connect(lambda: seen.append(doc.acquisition and doc.acquisition.denoise))
    doc.set_noise_reduction(3, filtered)
    assert doc.decomposition is filtered and doc.acquisition.raw is measured and seen == [3] and doc.is_dirty()
    assert doc.kappa_lock(doc.by_name("floor").uid)  # still the same measurement: locks kept
    doc.set_noise_reduction(0)
    assert doc.decomposition is measured and doc.acquisition.measured is None and seen == [3, 0]
    doc.discard_acquisition()
    with pytest.raises(InputError, match="nothing is acquired"):
        doc.set_noise_reduction(0)


def test_a_soft_edge_is_saved_and_reopened_exactly(tmp_path):
    from app.model.files import create_session, open_document

    img = np.full((12, 16, 3), 0.2, np.float32)
    img[:, 8:] = 0.8
    img[:, 7] = 0.35
    doc = Document(img)
    hard = doc.add_target("wall", np.zeros((12, 16), bool) | (np.arange(16) >= 8)[None, :])
    doc.add_target("plain", np.eye(12, 16, dtype=bool) & (np.arange(16) < 6))  # away from the wall's edge
    assert doc.refine_edge(hard.uid) == 12
    create_session(tmp_path / "s", doc)
    again, _, _ = open_document(tmp_path / "s")
    wall, plain = again.by_name("wall"), again.by_name("plain")
    np.testing.assert_array_equal(wall.coverage, hard.coverage)
    np.testing.assert_array_equal(wall.mask, hard.mask)
    assert plain.coverage is None and plain.mask.dtype == bool
