"""Painting from plain mouse events, without Qt: expected masks, one drag = one undo step."""

from __future__ import annotations

from itertools import pairwise

import numpy as np
import pytest

from app.model.document import Document
from app.model.painting import (
    EventType,
    MouseEvent,
    Painter,
    Tool,
    capsule,
    move,
    polygon_mask,
    press,
    release,
    similar_region,
)

H, W = 40, 60


def _capsule_reference(p0, p1, r, shape=(H, W)):
    """Independent per-pixel reference: pixel centres within r of the segment."""
    out = np.zeros(shape, bool)
    (ax, ay), (bx, by) = p0, p1
    for i in range(shape[0]):
        for j in range(shape[1]):
            px, py = j + 0.5, i + 0.5
            d2 = (bx - ax) ** 2 + (by - ay) ** 2
            t = 0.0 if d2 == 0 else min(max(((px - ax) * (bx - ax) + (py - ay) * (by - ay)) / d2, 0.0), 1.0)
            out[i, j] = (px - ax - t * (bx - ax)) ** 2 + (py - ay - t * (by - ay)) ** 2 <= r * r
    for x, y in (p0, p1):
        if 0 <= x < shape[1] and 0 <= y < shape[0]:
            out[int(y), int(x)] = True
    return out


@pytest.fixture
def doc():
    img = np.full((H, W, 3), 0.2, np.float32)
    img[10:30, 30:50] = (0.8, 0.1, 0.1)  # a red patch for the fill tool
    d = Document(img)
    d.add_target("t")
    return d


def _drag(painter, points, **kw):
    painter.handle(press(*points[0], **kw))
    for p in points[1:]:
        painter.handle(move(*p, **kw))
    painter.handle(release(*points[-1], **kw))


@pytest.mark.parametrize("size", [1, 5, 12])
def test_brush_drag_paints_the_swept_capsules(doc, size):
    p = Painter(doc)
    p.set_size(size)
    pts = [(5.2, 5.7), (20.4, 8.1), (33.0, 30.5)]
    _drag(p, pts)
    expected = np.zeros((H, W), bool)
    for a, b in pairwise(pts):
        expected |= _capsule_reference(a, b, size / 2)
    np.testing.assert_array_equal(doc.target(doc.current).mask, expected)


def test_one_drag_is_one_undo_step_storing_its_bounding_box(doc):
    t = doc.target(doc.current)
    p = Painter(doc)
    p.set_size(4)
    _drag(p, [(5, 5), (8, 6)])
    first = t.mask.copy()
    n = doc.history.count()
    _drag(p, [(10, 20), (15, 22), (25, 25), (12, 35)])
    assert doc.history.count() == n + 1
    atom = doc.history._commands[-1]
    y0, y1, x0, x1 = atom.bbox
    assert atom.before[0].shape == (y1 - y0, x1 - x0) and atom.before[0].size < H * W / 2
    second = t.mask.copy()
    doc.history.undo()
    np.testing.assert_array_equal(t.mask, first)
    doc.history.redo()
    np.testing.assert_array_equal(t.mask, second)
    doc.history.undo()
    doc.history.undo()
    assert not t.mask.any()


def test_eraser_and_alt_subtract(doc):
    t = doc.target(doc.current)
    t.mask[:] = True
    p = Painter(doc)
    p.set_size(3)
    p.set_tool(Tool.ERASER)
    _drag(p, [(10.5, 10.5), (10.5, 10.5)])
    assert (~t.mask).sum() == _capsule_reference((10.5, 10.5), (10.5, 10.5), 1.5).sum()
    p.set_tool(Tool.BRUSH)
    _drag(p, [(40.5, 20.5), (40.5, 20.5)], subtract=True)
    assert not t.mask[20, 40]


def test_polygon_closes_on_double_click_and_enter(doc):
    t = doc.target(doc.current)
    p = Painter(doc)
    p.set_tool(Tool.POLYGON)
    for xy in [(2, 2), (12, 2), (12, 10)]:
        p.handle(press(*xy))
    assert p.polygon and not t.mask.any()
    p.handle(MouseEvent(EventType.DOUBLE_CLICK, 2.0, 10.0))
    assert not p.polygon
    # pixel centres strictly inside the rectangle (2..12 x 2..10) minus one triangle half
    assert t.mask[3, 11] and not t.mask[9, 3] and t.mask.sum() > 30
    n = doc.history.count()
    for xy in [(30, 30), (40, 30), (40, 38)]:
        p.handle(press(*xy))
    p.close_polygon()
    assert doc.history.count() == n + 1 and t.mask[31, 39]


def test_polygon_and_lasso_rasterise_like_fillpoly():
    bbox, stamp = polygon_mask([(0, 0), (4, 0), (4, 4), (0, 4)], (10, 10))
    assert bbox == (0, 5, 0, 5)
    assert stamp.sum() == 16 and stamp[:4, :4].all()


def test_lasso_drag_fills_the_traced_outline(doc):
    t = doc.target(doc.current)
    p = Painter(doc)
    p.set_tool(Tool.LASSO)
    _drag(p, [(20, 20), (30, 20), (30, 30), (20, 30)])
    np.testing.assert_array_equal(t.mask[20:30, 20:30], True)
    assert t.mask.sum() == 100


def test_fill_by_similar_colour_selects_the_connected_patch(doc):
    t = doc.target(doc.current)
    p = Painter(doc)
    p.set_tool(Tool.FILL)
    p.handle(press(35, 15))
    expected = np.zeros((H, W), bool)
    expected[10:30, 30:50] = True
    np.testing.assert_array_equal(t.mask, expected)
    p.handle(press(35, 15, subtract=True))
    assert not t.mask.any()


def test_similar_region_follows_a_surfaces_shading_and_stops_at_its_edge():
    """Steps between neighbours are compared (log colour, per channel), so a wall's gradual shading is one
    region (compared with the seed alone, the default tolerance took a crescent of the demo's back wall);
    a step stops it, and it never drifts more than 10 tolerances in brightness or 2 in hue from the seed."""
    shading = np.geomspace(0.1, 0.24, 24, dtype=np.float32)  # ×2.4 across, 4 % a pixel
    img = np.repeat(np.concatenate([shading, shading[-1:] * 2])[None, :, None], 3, axis=2)  # then a step ×2
    got = similar_region(np.repeat(img, 5, axis=0), 0.5, 2.5, 0.1)
    assert got[:, :24].all() and not got[:, 24].any()
    long = np.repeat(np.geomspace(0.01, 1.0, 100, dtype=np.float32)[None, :, None], 3, axis=2)  # ×100, 5 % a pixel
    reach = similar_region(np.repeat(long, 5, axis=0), 0.5, 2.5, 0.1)[2]
    assert 20 <= reach.sum() <= 23  # as far as e^(10 × 0.1): 2.7× the seed
    drift = np.ones((5, 60, 3), np.float32)
    drift[..., 0] = np.geomspace(1.0, 3.0, 60, dtype=np.float32)  # the hue slides towards red, 2 % a pixel
    reach = similar_region(drift, 0.5, 2.5, 0.1)[2]
    assert 15 <= reach.sum() <= 18  # the red-vs-grey share moves by 2 tolerances after about 16 pixels


def test_clear_and_invert_are_undoable(doc):
    t = doc.target(doc.current)
    t.mask[5:9, 5:9] = True
    before = t.mask.copy()
    doc.invert_mask(t.uid)
    np.testing.assert_array_equal(t.mask, ~before)
    doc.clear_mask(t.uid)
    assert not t.mask.any()
    doc.history.undo()
    np.testing.assert_array_equal(t.mask, ~before)
    doc.history.undo()
    np.testing.assert_array_equal(t.mask, before)


def test_brush_size_keys_and_painting_without_target():
    doc = Document(np.ones((8, 8, 3), np.float32))
    warnings = []
    doc.events.warning.connect(warnings.append)
    p = Painter(doc)
    p.set_size(10)
    p.grow()
    assert p.size == 12.5
    p.shrink()
    p.shrink()
    assert p.size == 8.0
    p.set_size(0)
    p.shrink()
    assert p.size == 1.0
    p.set_tool(Tool.ERASER)
    assert not p.handle(press(1, 1)) and "add or select a target" in warnings[-1]  # nothing to erase
    assert doc.targets == []
    # the first brush stroke on a photograph without targets starts one (it warned and painted nothing)
    p.set_tool(Tool.BRUSH)
    p.set_size(3)
    assert p.handle(press(1, 1))
    p.handle(release(1, 1))
    assert [t.name for t in doc.targets] == ["target 1"] and doc.current == doc.targets[0].uid
    assert doc.targets[0].mask[1, 1]
    doc.history.undo()
    assert len(doc.targets) == 1 and not doc.targets[0].mask.any()  # the stroke, then the target
    doc.history.undo()
    assert doc.targets == []
    doc.add_target("a")
    doc.add_target("b")
    doc.set_current(-1)  # targets but none selected: which one is the user's to say
    n = len(warnings)
    assert not p.handle(press(1, 1)) and len(warnings) == n + 1 and "add or select a target" in warnings[-1]


def test_refused_edit_becomes_a_warning_not_an_exception(acquired_doc):
    warnings = []
    acquired_doc.events.warning.connect(warnings.append)
    acquired_doc.set_current(acquired_doc.by_name("wall").uid)
    p = Painter(acquired_doc)
    assert not p.handle(press(40, 20))
    assert "acquired" in warnings[-1]


def test_capsule_outside_the_image():
    assert capsule((-50, -50), (-40, -40), 2, (10, 10)) == (None, None)


def test_a_feathered_brush_paints_partial_coverage_and_one_drag_undoes_at_once(doc):
    from app.model.painting import feathered_capsule

    t = doc.target(doc.current)
    p = Painter(doc)
    p.set_size(10)
    p.set_hardness(0.4)
    n = doc.history.count()
    _drag(p, [(10, 10), (20, 12)])
    assert doc.history.count() == n + 1
    cov = t.coverage
    # the union of the stamps along the drag: max of the swept stamp (press, move, release)
    bbox, w = feathered_capsule((10, 10), (20, 12), 5.0, 0.4, (H, W))
    y0, y1, x0, x1 = bbox
    np.testing.assert_array_equal(cov[y0:y1, x0:x1], w)
    assert 0 < t.edge_pixels() == np.count_nonzero((w > 0) & (w < 1))
    np.testing.assert_array_equal(t.mask, cov >= 0.5)
    assert t.acquired_mask().dtype == np.float32
    # the eraser's feather lowers coverage to 1 - weight
    p.set_tool(Tool.ERASER)
    _drag(p, [(20, 12), (20, 12)])
    _, e = feathered_capsule((20, 12), (20, 12), 5.0, 0.4, (H, W))
    assert cov[12, 20] == 0 and cov[12, 24] == pytest.approx(min(w[12 - y0, 24 - x0], 1 - e[5, 9]))
    doc.history.undo()
    np.testing.assert_array_equal(t.coverage[y0:y1, x0:x1], w)
    doc.history.undo()
    assert not t.coverage.any() and not t.mask.any() and t.edge_pixels() == 0
    assert t.acquired_mask().dtype == bool  # a coverage of 0/1 only is a binary mask


def test_hard_tools_on_a_soft_edge_keep_its_coverage_outside_what_they_change(doc):
    t = doc.target(doc.current)
    p = Painter(doc)
    p.set_size(8)
    p.set_hardness(0.0)
    _drag(p, [(30, 20), (30, 20)])  # a soft dab on the red patch's left edge
    soft = t.coverage.copy()
    assert t.edge_pixels() > 0
    p.set_hardness(1.0)
    _drag(p, [(5, 35), (5, 35)])  # a hard dab far away: the soft dab stays soft
    np.testing.assert_array_equal(t.coverage[10:30, 30:50], soft[10:30, 30:50])
    assert t.coverage[35, 5] == 1
    p.set_tool(Tool.FILL)
    p.fill(t.uid, 45, 15)  # the red patch: coverage 1 there, the soft dab's feather outside it kept
    assert (t.coverage[10:30, 30:50] == 1).all()
    outside = soft.copy()
    outside[10:30, 30:50] = 0
    assert ((t.coverage >= outside) | (outside == 0)).all() and t.edge_pixels() > 0
    doc.history.undo()
    np.testing.assert_array_equal(t.coverage[10:30, 30:50], soft[10:30, 30:50])
    doc.invert_mask(t.uid)
    np.testing.assert_allclose(t.coverage[10:30, 30:50], 1 - soft[10:30, 30:50])


def test_refine_edge_finds_the_coverage_of_mixed_pixels_and_undoes(doc):
    img = np.full((H, W, 3), 0.1, np.float32)
    img[:, 30:] = 0.9
    img[:, 29] = 0.1 + 0.8 * 0.25  # a quarter of column 29 is the bright wall
    d = Document(img)
    t = d.add_target("wall", np.zeros((H, W), bool) | (np.arange(W) >= 30)[None, :])
    assert d.refine_edge(t.uid) == H
    np.testing.assert_allclose(t.coverage[:, 29], 0.25, atol=1e-6)
    assert (t.coverage[:, 30:] == 1).all() and not t.mask[:, 29].any()
    assert d.history.undo_text() == "Refine edge 'wall'"
    d.history.undo()
    assert t.edge_pixels() == 0 and t.acquired_mask().dtype == bool
    d.history.redo()
    assert t.edge_pixels() == H


def test_refine_edge_leaves_what_a_touching_target_covers():
    """Refining two touching targets in turn never makes their coverages overlap (the
    acquisition would refuse them)."""
    img = np.full((H, W, 3), 0.1, np.float32)
    img[:, 30:] = 0.9
    img[:, 29] = 0.1 + 0.8 * 0.25
    d = Document(img)
    right = d.add_target("wall", np.zeros((H, W), bool) | (np.arange(W) >= 30)[None, :])
    left = d.add_target("floor", np.zeros((H, W), bool) | (np.arange(W) < 30)[None, :])
    d.refine_edge(right.uid)  # column 29 belongs to the floor's hard mask: the wall cannot take it
    assert (right.coverage[:, 29] == 0).all()
    d.refine_edge(left.uid)
    d.refine_edge(right.uid)
    total = left.coverage + right.coverage
    assert total.max() <= 1.0 + 1e-6 and (right.coverage[:, 30:] == 1).all()
