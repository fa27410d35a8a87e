"""Frames without Qt: display conversion, preview maths, views, read-out."""

from __future__ import annotations

import numpy as np
import pytest

from app.model import views
from app.model.display import MAGNITUDE_MAP, false_colour, recolor_rgb32, rgb32_to_rgb, robust_max, to_rgb32
from app.model.render import MaskSnapshot, Request, ViewRenderer, component_grid, preview_factor
from app.model.views import VIEWS, CanvasView
from engine.errors import InputError
from engine.imageio import to_display
from engine.recolor import area_average, prepare_preview, recolor, recolor_preview
from tests.app.conftest import FakeTruth, make_decomposition

DETAIL_VIEWS = {spec.view for spec in VIEWS if spec.detail}


@pytest.mark.parametrize("exposure", [0.0, 1.5, -2.25])
def test_rgb32_matches_engine_display_conversion(rng, exposure):
    img = (rng.random((37, 53, 3), dtype=np.float32) * 3 - 0.5).astype(np.float32)
    img[0, :8, 0] = (np.arange(8) + 0.5) / 65535 / 2.0**exposure  # exact rounding ties
    np.testing.assert_array_equal(rgb32_to_rgb(to_rgb32(img, exposure=exposure)), to_display(img, exposure=exposure))


def test_rgb32_bad_input():
    with pytest.raises(InputError, match="float"):
        to_rgb32(np.zeros((2, 2, 3), np.uint8))
    with pytest.raises(InputError, match="exposure"):
        to_rgb32(np.zeros((2, 2, 3), np.float32), exposure=np.inf)
    with pytest.raises(InputError, match="out must be"):
        to_rgb32(np.zeros((2, 2, 3), np.float32), out=np.zeros((3, 2), np.uint32))


@pytest.mark.parametrize("k", [1, 2, 4, 7])
@pytest.mark.parametrize("kappa, exposure", [((2.0, 0.125, 8.0), 0.0), (0.7, -1.5), ((16, 1 / 16, 1), 2.0)])
def test_fused_recolor_display_is_bit_identical(k, kappa, exposure):
    d, _ = make_decomposition(k, h=33, w=71, k=k)
    expected = to_rgb32(recolor(d, kappa), exposure=exposure)
    np.testing.assert_array_equal(recolor_rgb32(d, kappa, exposure=exposure), expected)


def test_false_colour_and_scale():
    words = false_colour(np.array([[-1.0, 0.5, 3.0]]), 0.0, 1.0, MAGNITUDE_MAP)
    rgb = rgb32_to_rgb(words)[0]
    np.testing.assert_array_equal(rgb[0], MAGNITUDE_MAP[0])
    np.testing.assert_array_equal(rgb[2], MAGNITUDE_MAP[255])
    assert robust_max(np.array([0.0, -4.0]), percentile=100) == 4.0
    with pytest.raises(InputError, match="hi > lo"):
        false_colour(np.zeros((1, 1)), 1.0, 1.0, MAGNITUDE_MAP)


@pytest.mark.parametrize("shape, factor", [((48, 64), 3), ((47, 61), 4), ((10, 10), 1)])
def test_area_average_lines_up_with_the_preview_pack(rng, shape, factor):
    d, photo = make_decomposition(rng, h=shape[0], w=shape[1], k=2)
    pack = prepare_preview(d, (-(-shape[0] // factor), -(-shape[1] // factor)))
    # the pack is linear in the components: the average of the photograph is its κ = 1 recolor
    np.testing.assert_allclose(area_average(photo, factor), recolor_preview(pack, 1.0), rtol=2e-6, atol=2e-7)


@pytest.mark.parametrize("max_shape", [(1080, 1920), (20, 20)])
def test_recolored_frame_is_the_engines_preview(synthetic, max_shape):
    d, photo = synthetic
    r = ViewRenderer(photo, d, max_shape=max_shape).prepare()
    kappa = (2.0, 0.125, 8.0)
    frame = views.render(r, Request(CanvasView.RECOLORED, kappa, 0.5))
    expected = recolor_preview(prepare_preview(d, max_shape), kappa)
    np.testing.assert_array_equal(r.recolored_small(kappa), expected)
    np.testing.assert_array_equal(frame.pixels, to_rgb32(expected, exposure=0.5))  # fused path, bit-exact
    if max_shape == (1080, 1920):  # no reduction: exactly the full-resolution recolor
        np.testing.assert_array_equal(frame.pixels, to_rgb32(recolor(d, kappa), exposure=0.5))
    assert frame.extent == photo.shape[:2]


def test_views_and_fallbacks(synthetic):
    d, photo = synthetic
    r = ViewRenderer(photo, d, truth=lambda edit: recolor(d, edit[0]) if edit else photo).prepare()
    split = views.render(r, Request(CanvasView.SPLIT, (2, 2, 2)))
    np.testing.assert_array_equal(split.second, to_rgb32(photo))
    diff = views.render(r, Request(CanvasView.DIFFERENCE, (2, 2, 2)))
    assert diff.scale is not None and diff.scale.lo == -diff.scale.hi > -np.inf
    err = views.render(r, Request(CanvasView.ERROR, (2, 2, 2), edit=((2.0, 2.0, 2.0),)))
    assert err.note.startswith("relative error 0.00 %")
    truth = views.render(r, Request(CanvasView.TRUTH, (1, 1, 1), edit=((3.0, 3.0, 3.0),)))
    np.testing.assert_array_equal(truth.linear, recolor(d, 3.0))
    bare = ViewRenderer(photo).prepare()  # nothing acquired, no truth, no target: the photograph
    for view in CanvasView:
        f = views.render(bare, Request(view, (4, 4, 4)))
        if view == CanvasView.DIFFERENCE:
            assert f.banner == views.NAIVE_BANNER and f.scale is not None
            continue
        np.testing.assert_array_equal(f.pixels, to_rgb32(photo))
        assert f.view in (CanvasView.ORIGINAL, CanvasView.RECOLORED, CanvasView.SPLIT)
        assert f.banner == (views.NAIVE_BANNER if f.view != CanvasView.ORIGINAL else "")


def test_before_acquisition_the_recolored_view_is_a_naive_recolor_with_a_banner(synthetic):
    d, photo = synthetic
    r = ViewRenderer(photo, max_shape=(12, 16)).prepare()
    first = np.zeros(photo.shape[:2], bool)
    first[:20, :30] = True
    second = np.zeros_like(first)
    second[10:, 20:] = True  # overlaps the first: the later target (cascade order) wins
    edit = ((MaskSnapshot((1, 0), first), (2.0, 1.0, 0.5)), (MaskSnapshot((2, 0), second), (1.0, 3.0, 1.0)))
    frame = views.render(r, Request(CanvasView.RECOLORED, edit=edit))
    scale = np.ones(photo.shape, np.float32)
    scale[first] = (2.0, 1.0, 0.5)
    scale[second] = (1.0, 3.0, 1.0)
    naive = photo * scale
    np.testing.assert_allclose(r.naive_small(edit), area_average(naive, r.factor), rtol=2e-6, atol=1e-7)
    assert frame.banner == views.NAIVE_BANNER and "Interreflections follow only once" in frame.banner
    for x, y in ((0, 0), (25, 15), (40, 40)):
        label, value = views.readout(r, CanvasView.RECOLORED, x, y, (1, 1, 1), edit)
        assert label == "naive recolor"
        np.testing.assert_allclose(value, naive[y, x], rtol=1e-6)


def test_components_view_follows_fig6_layout(synthetic):
    d, photo = synthetic
    r = ViewRenderer(photo, d).prepare()
    rows, cols = component_grid(d.order, photo.shape[:2], (800, 1200))
    frame = views.render(r, Request(CanvasView.COMPONENTS, grid=(rows, cols)))
    assert len(frame.tiles) == d.order and frame.extent == (rows * photo.shape[0], cols * photo.shape[1])
    assert frame.tiles[0].label.startswith("R⁰L_d | L̄_d") and frame.tiles[2].label.endswith("×16")
    # tile 0: L_d on the target, the unreached light elsewhere; tile 1: R¹L_d inside, C R⁰L_d outside
    n = max(rows, cols)
    t0 = frame.pixels[: frame.tiles[0].h, : frame.tiles[0].w]
    expected0 = np.where(d.target[..., None], d.components[0], d.unreached)
    np.testing.assert_array_equal(t0, to_rgb32(area_average(expected0, n)))
    t1 = frame.tiles[1]
    expected1 = np.where(d.target[..., None], d.components[1], d.components[0]) * np.float32(4)
    np.testing.assert_array_equal(frame.pixels[t1.y : t1.y + t1.h, t1.x : t1.x + t1.w],
                                  to_rgb32(area_average(expected1, n)))


def test_readout_is_exact_at_full_resolution(synthetic):
    d, photo = synthetic
    r = ViewRenderer(photo, d, truth=FakeTruth(d).recolor, max_shape=(8, 8)).prepare()
    kappa = np.array([2.0, 0.5, 3.0])
    full = recolor(d, kappa)
    ys, xs = np.nonzero(d.target)
    for x, y in ((0, 0), (int(xs[3]), int(ys[3])), (photo.shape[1] - 1, photo.shape[0] - 1)):
        label, value = views.readout(r, CanvasView.RECOLORED, x, y, kappa)
        assert label == "recolored"
        np.testing.assert_array_equal(value, full[y, x])
        label, value = views.readout(r, CanvasView.DIFFERENCE, x, y, kappa)
        np.testing.assert_array_equal(value, full[y, x] - photo[y, x])
        assert views.readout(r, CanvasView.ORIGINAL, x, y, kappa)[1] is photo[y, x] or np.array_equal(
            views.readout(r, CanvasView.ORIGINAL, x, y, kappa)[1], photo[y, x])
    assert views.readout(r, CanvasView.RECOLORED, -1, 0, kappa) is None


def test_preview_factor_and_grid():
    assert preview_factor((3000, 4000), (1080, 1920)) == 3
    assert preview_factor((100, 100), (1080, 1920)) == 1
    assert component_grid(4, (100, 100), (100, 400)) == (1, 4)
    assert component_grid(1, (100, 100), (100, 400)) == (1, 1)


@pytest.mark.parametrize("view", sorted(DETAIL_VIEWS))
def test_detail_is_the_full_resolution_frame_cropped(synthetic, view):
    d, photo = synthetic
    renderer = ViewRenderer(photo, d, max_shape=(12, 16)).prepare()
    assert renderer.factor == 4
    request = Request(view, (2.0, 0.125, 8.0), exposure=0.5)
    detail = views.render_detail(renderer, request, (-5, 20, 30, 999))  # clipped to the image
    assert detail.region == (0, 20, 30, 64) and detail.request == request
    recolored = recolor_rgb32(d, request.kappa, exposure=0.5)[:20, 30:]
    original = to_rgb32(photo, exposure=0.5)[:20, 30:]
    np.testing.assert_array_equal(detail.pixels, original if view == CanvasView.ORIGINAL else recolored)
    if view == CanvasView.SPLIT:
        np.testing.assert_array_equal(detail.second, original)
    else:
        assert detail.second is None


def test_no_detail_where_the_preview_is_full_resolution_or_the_view_is_diagnostic(synthetic):
    d, photo = synthetic
    assert views.render_detail(ViewRenderer(photo, d).prepare(), Request(CanvasView.RECOLORED), (0, 10, 0, 10)) is None
    small = ViewRenderer(photo, d, max_shape=(12, 16)).prepare()
    diagnostic = {v for v in CanvasView if not views.shown(small, v).detail}
    assert diagnostic == {CanvasView.DIFFERENCE, CanvasView.COMPONENTS, CanvasView.NOISE}  # truth views: the original
    for view in diagnostic:
        assert views.render_detail(small, Request(view), (0, 10, 0, 10)) is None
    assert views.render_detail(small, Request(CanvasView.RECOLORED), (60, 70, 0, 10)) is None  # outside the image
    # nothing acquired yet: the recolored view's detail is the photograph
    bare = views.render_detail(ViewRenderer(photo, max_shape=(12, 16)).prepare(), Request(CanvasView.RECOLORED),
                               (0, 10, 0, 10))
    np.testing.assert_array_equal(bare.pixels, to_rgb32(photo)[:10, :10])


def test_noise_view_is_the_engines_predicted_sigma(rng):
    from dataclasses import replace

    from engine.recolor import recolor_variance

    d, photo = make_decomposition(rng, h=24, w=36, k=3)
    cov = (rng.random((6,) + d.shape) * 1e-4).astype(np.float32)
    cov[[1, 2, 4]] *= 0.1  # off-diagonal terms (packed (0,1), (0,2), (1,2)) smaller than the variances
    d = replace(d, covariance=cov)
    kappa = (2.0, 0.125, 8.0)
    full = views.render(ViewRenderer(photo, d).prepare(), Request(CanvasView.NOISE, kappa))
    np.testing.assert_array_equal(full.linear, np.sqrt(recolor_variance(d, kappa)))
    assert full.note.startswith("predicted σ on the target: mean") and full.scale.lo == 0 < full.scale.hi
    r = ViewRenderer(photo, d, max_shape=(8, 12)).prepare()  # factor 3: the mean variance of each block
    small = views.render(r, Request(CanvasView.NOISE, kappa))
    expected = np.sqrt(area_average(recolor_variance(d, kappa), 3))
    whole = area_average(d.target.astype(np.float32), 3)
    pure = (whole == 0) | (whole == 1)  # blocks wholly on or off the target
    np.testing.assert_allclose(small.linear[pure], expected[pure], rtol=1e-5)
    label, value = views.readout(r, CanvasView.NOISE, 20, 12, kappa)
    assert label == "predicted σ"
    np.testing.assert_allclose(value, np.sqrt(recolor_variance(d, kappa))[12, 20], rtol=1e-6)
    plain = views.render(ViewRenderer(photo, replace(d, covariance=None)).prepare(), Request(CanvasView.NOISE, kappa))
    assert plain.banner == views.NO_NOISE_BANNER
    np.testing.assert_array_equal(plain.pixels, to_rgb32(photo))
