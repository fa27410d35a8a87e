"""engine.edge: soft masks, refining a hard mask, recoloring pixels that are partly target."""

from __future__ import annotations

import numpy as np
import pytest

from engine.decompose import Decomposition
from engine.edge import blend_edges, check_coverage, edge, refine_mask, solid
from engine.errors import InputError
from engine.recolor import recolor

A = np.array([0.1, 0.8, 0.1], np.float32)  # target colour
B = np.array([0.7, 0.65, 0.6], np.float32)  # neighbour colour


def _two_sides(h=12, w=14, seed=0):
    """A vertical edge: target on the right, with true coverage ``alpha`` on column 6."""
    rng = np.random.default_rng(seed)
    alpha = np.zeros((h, w), np.float32)
    alpha[:, 7:] = 1.0
    alpha[:, 6] = rng.uniform(0.05, 0.95, h)
    photo = (alpha[:, :, None] * A + (1 - alpha[:, :, None]) * B).astype(np.float32)
    return alpha, photo


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_refine_mask_recovers_the_coverage_of_mixed_pixels(dtype):
    alpha, photo = _two_sides()
    painted = alpha >= 0.5
    cov = refine_mask(painted, photo.astype(dtype), snap=0.0)
    assert cov.dtype == np.float32
    np.testing.assert_allclose(cov, alpha, atol=1e-5)
    snapped = refine_mask(painted, photo.astype(dtype))  # within 0.1 of 0 or 1: exactly 0 or 1
    np.testing.assert_array_equal(snapped[alpha <= 0.1], 0)
    np.testing.assert_array_equal(snapped[alpha >= 0.9], 1)
    assert solid(cov).sum() == (alpha == 1).sum() and edge(cov).sum() == edge(alpha).sum()


def test_refine_mask_leaves_what_other_targets_claim():
    """Coverage never exceeds what touching targets leave (a cascade refuses coverages summing
    past 1): a neighbour's hard mask keeps the refined edge off its pixels, a neighbour's soft
    edge caps it; unclaimed pixels are refined as before."""
    alpha, photo = _two_sides()
    right = alpha >= 0.5
    free = refine_mask(right, photo, snap=0.0)
    blocked = refine_mask(right, photo, snap=0.0, claimed=~right)  # the left target, still hard
    np.testing.assert_array_equal(blocked, np.where(right, free, 0))  # its own edge still refined
    claimed = np.zeros(alpha.shape, np.float32)
    claimed[:, 6] = np.linspace(0.0, 0.9, alpha.shape[0])  # the left target refined first
    shared = refine_mask(right, photo, snap=0.0, claimed=claimed)
    np.testing.assert_allclose(shared, np.minimum(free, 1 - claimed), atol=1e-6)
    assert (shared + claimed).max() <= 1.0 + 1e-6 and (shared[:, 6] < free[:, 6]).any()
    with pytest.raises(InputError, match="claimed"):
        refine_mask(right, photo, claimed=np.full(alpha.shape, 2.0, np.float32))


def test_refine_mask_follows_a_linear_shading_gradient():
    alpha, photo = _two_sides()
    ramp = np.linspace(0.6, 1.4, photo.shape[1], dtype=np.float32)[None, :, None]
    shaded = (alpha[:, :, None] * A + (1 - alpha[:, :, None]) * B) * ramp  # both sides shaded alike
    cov = refine_mask(alpha >= 0.5, shaded.astype(np.float32), snap=0.0)
    np.testing.assert_allclose(cov[:, 6], alpha[:, 6], atol=0.03)


def test_refine_mask_unmixes_an_edge_between_two_textures():
    """Both sides textured along the edge (cells of 2 and 3 rows): a direction that crosses a cell's
    edge extrapolates a colour the pixel does not hold. The mean over directions was up to 0.61 off;
    the pairs of side colours that explain the pixel best are within 0.02."""
    a2, b2 = np.array([0.5, 0.3, 0.05], np.float32), np.array([0.2, 0.25, 0.6], np.float32)
    alpha, _ = _two_sides(h=24)
    rows = np.arange(24)[:, None, None]
    inside, outside = np.where(rows // 2 % 2 == 0, A, a2), np.where(rows // 3 % 2 == 0, B, b2)
    photo = (alpha[:, :, None] * inside + (1 - alpha[:, :, None]) * outside).astype(np.float32)
    cov = refine_mask(alpha >= 0.5, photo, snap=0.0)
    np.testing.assert_allclose(cov, alpha, atol=0.02)


def test_refine_mask_gives_the_same_coverage_whatever_its_chunk(monkeypatch):
    """The boundary is unmixed a chunk of pixels at a time (bounded memory): chunks of 5 pixels give exactly the
    coverage of one chunk holding them all."""
    import engine.edge

    alpha, photo = _two_sides(h=24)
    photo = photo * np.linspace(0.5, 1.5, 24, dtype=np.float32)[:, None, None]  # a gradient down the edge
    whole = refine_mask(alpha >= 0.5, photo, snap=0.0)
    monkeypatch.setattr(engine.edge, "CHUNK", 5)
    np.testing.assert_array_equal(refine_mask(alpha >= 0.5, photo, snap=0.0), whole)
    assert not np.array_equal(whole, (alpha >= 0.5).astype(np.float32))


def test_refine_mask_keeps_pixels_without_contrast_and_far_from_the_edge():
    photo = np.full((8, 8, 3), 0.5, np.float32)
    m = np.zeros((8, 8), bool)
    m[:, 4:] = True
    np.testing.assert_array_equal(refine_mask(m, photo), m.astype(np.float32))


def _decomposition(order=3, h=12, w=14):
    """Two flat sides with known interaction shares, and an edge column mixing them."""
    alpha, photo = _two_sides(h, w)
    s_in = np.array([0.7, 0.2, 0.1])[:order] / np.array([0.7, 0.2, 0.1])[:order].sum()
    s_out = np.array([0.6, 0.3, 0.1])[:order] / np.array([0.6, 0.3, 0.1])[:order].sum()  # [L̄_d, C R^0, C R^1]
    target = alpha >= 1
    comps = np.zeros((order, h, w, 3), np.float32)
    unreached = np.zeros((h, w, 3), np.float32)
    comps[:, target] = s_in[:, None, None] * A
    out = alpha <= 0
    unreached[out] = s_out[0] * B
    for i in range(order - 1):
        comps[i, out] = s_out[i + 1] * B
    # the edge column is not re-emitted: its non-target decomposition (Eq. 9) holds its target
    # part one interaction late (L̄_d = R^0 L_d, C R^m L_d = R^{m+1} L_d) plus its neighbour's
    col = ~target & ~out
    a = alpha[col][:, None]
    unreached[col] = a * A * s_in[0] + (1 - a) * B * s_out[0]
    for m in range(order - 1):
        comps[m, col] = a * A * s_in[m + 1] + (1 - a) * B * s_out[m + 1]
    return Decomposition(comps, unreached, target), alpha, photo, s_in, s_out


def test_blend_edges_recolors_each_side_with_its_own_shares():
    d, alpha, photo, s_in, s_out = _decomposition()
    blended, changed = blend_edges(d, alpha, photo)
    np.testing.assert_array_equal(changed, edge(alpha))
    kappa = np.array([2.0, 0.125, 8.0])
    f_a = sum(kappa ** (i + 1) * s for i, s in enumerate(s_in))
    f_b = s_out[0] + sum(kappa ** (i + 1) * s for i, s in enumerate(s_out[1:]))
    expected = alpha[:, :, None] * A * f_a + (1 - alpha[:, :, None]) * B * f_b
    got = recolor(blended, kappa)
    np.testing.assert_allclose(got, expected, rtol=2e-5, atol=1e-6)
    np.testing.assert_allclose(recolor(blended, 1.0), photo, rtol=1e-5, atol=1e-7)  # κ = 1: the photograph
    # decomposed as non-target, the edge's target part misses one κ: the seam
    assert np.abs(recolor(d, kappa)[changed] - expected[changed]).max() > 0.1


def test_blend_edges_keeps_dark_and_negative_edge_pixels_bounded():
    """An earlier cascade target is decomposed under emissions on a later one: its edge pixels
    are then lit only by interreflections, and camera noise or a re-emitted difference leaves
    some with no light or negative light. Blending must keep them as small as their light and
    still give the photograph at κ = 1 (a floored division once made such a pixel ~1e26 times
    its light, and its shares then swamped every smoothing window around it)."""
    d, alpha, photo, *_ = _decomposition()
    col = edge(alpha)
    scale = np.ones(alpha.shape, np.float32)
    scale[col] = np.resize([-0.01, 0.0, 1e-9, 0.5], int(col.sum()))  # negative, dark, all but dark, lit
    dark_photo = (photo * scale[:, :, None]).astype(np.float32)
    neg = d.components * scale[None, :, :, None], d.unreached * scale[:, :, None]
    d = Decomposition(neg[0].astype(np.float32), neg[1].astype(np.float32), d.target)
    dark_photo[:, 5] *= -1e-3  # the neighbour beside the edge: noise around zero
    blended, changed = blend_edges(d, alpha, dark_photo)
    assert changed[col].all()
    for kappa in (1.0, np.array([2.0, 6.0, 0.5])):
        got = recolor(blended, kappa)
        assert np.isfinite(got).all()
        bound = float(np.max(kappa)) ** 3 * (np.abs(dark_photo) + np.abs(d.unreached)).sum(axis=-1)[col] * 3
        assert (np.abs(got[col]).max(axis=-1) <= bound + 1e-12).all()
    np.testing.assert_allclose(recolor(blended, 1.0)[col], dark_photo[col], rtol=1e-5, atol=1e-9)


def test_blend_edges_leaves_hard_masks_and_lonely_edges_alone():
    d, alpha, photo, *_ = _decomposition()
    same, changed = blend_edges(d, alpha >= 0.5, photo)
    assert same is d and not changed.any()
    lonely = np.zeros_like(alpha)
    lonely[0, 0] = 0.5  # no target pixel within the radius
    _, changed = blend_edges(d, lonely, photo, radius=1)
    assert not changed.any()


def test_bad_input_names_the_argument():
    d, alpha, photo, *_ = _decomposition()
    with pytest.raises(InputError, match="coverage must be finite and in"):
        blend_edges(d, alpha * 2, photo)
    with pytest.raises(InputError, match="radius must be"):
        blend_edges(d, alpha, photo, radius=0)
    with pytest.raises(InputError, match="photograph must have"):
        blend_edges(d, alpha, photo[:-1])
    with pytest.raises(InputError, match="boolean mask or float coverage"):
        check_coverage("m", np.ones((2, 2), np.uint8), (2, 2))
    with pytest.raises(InputError, match="mask must be a boolean"):
        refine_mask(alpha, photo)


def _noisy_edge(d, alpha, sigma, seed):
    """``d`` with seeded Gaussian noise of ``sigma`` × the pixel's light on its edge pixels' components."""
    rng = np.random.default_rng(seed)
    col = edge(alpha)
    comps, unreached = d.components.copy(), d.unreached.copy()
    light = comps[:, col].sum(axis=0) + unreached[col]
    unreached[col] += sigma * light * rng.standard_normal(light.shape)
    for m in range(comps.shape[0]):
        comps[m, col] += sigma * light * rng.standard_normal(light.shape)
    return Decomposition(comps, unreached, d.target)


def test_blend_edges_along_the_edge_removes_noise_and_keeps_exact_data():
    """Edge pixels are not re-emitted: their components hold interreflected light only, the noisiest
    observations. Fitting the neighbour's shares along the edge (a column of 48 pixels with known
    components, noise of 2 % of the light per component) brings the κ = (2, 0.125, 8) recolor of the
    edge pixels closer to the truth; noise-free, the result is the exact one either way."""
    d, alpha, photo, s_in, s_out = _decomposition(order=3, h=48)
    kappa = np.array([2.0, 0.125, 8.0])
    f_a = sum(kappa ** (i + 1) * s for i, s in enumerate(s_in))
    f_b = s_out[0] + sum(kappa ** (i + 1) * s for i, s in enumerate(s_out[1:]))
    expected = alpha[:, :, None] * A * f_a + (1 - alpha[:, :, None]) * B * f_b
    col = edge(alpha)
    exact = recolor(blend_edges(d, alpha, photo, along=4)[0], kappa)
    np.testing.assert_allclose(exact, expected, rtol=2e-5, atol=1e-6)
    for seed in range(3):
        noisy = _noisy_edge(d, alpha, 0.02, seed)
        errors = [np.linalg.norm(recolor(blend_edges(noisy, alpha, photo, along=r)[0], kappa)[col] - expected[col])
                  for r in (0, 2, 4)]
        assert errors[2] < errors[1] < 0.7 * errors[0], errors
        np.testing.assert_allclose(recolor(blend_edges(noisy, alpha, photo, along=4)[0], 1.0)[col], photo[col],
                                   rtol=1e-4, atol=1e-6)  # κ = 1: still the photograph


def test_blend_edges_along_keeps_two_edges_of_a_corner_apart():
    """Two edges meeting at a corner border different neighbours (shares (0.6, 0.3, 0.1) left of the
    target, (0.3, 0.3, 0.4) above it): averaged along each edge, noise-free, every edge pixel keeps
    its own neighbour's shares except the corner pixel, which lies on both."""
    h = w = 16
    alpha = np.zeros((h, w), np.float32)
    alpha[6:, 6:] = 1.0
    alpha[5, 6:] = 0.4  # the edge above the target
    alpha[6:, 5] = 0.7  # the edge left of it
    s_in = np.array([0.7, 0.2, 0.1])
    s_left, s_above = np.array([0.6, 0.3, 0.1]), np.array([0.3, 0.3, 0.4])
    target, col = alpha >= 1, edge(alpha)
    comps = np.zeros((3, h, w, 3), np.float32)
    unreached = np.zeros((h, w, 3), np.float32)
    comps[:, target] = s_in[:, None, None] * A
    above = np.zeros((h, w), bool)
    above[:5, 5:] = True
    for mask, s in ((~target & ~col & ~above, s_left), (above, s_above)):
        unreached[mask] = s[0] * B
        for i in range(2):
            comps[i, mask] = s[i + 1] * B
    s_edge = np.where((np.arange(h) == 5)[:, None, None], s_above, s_left)  # (h, 1, 3): by row
    s_edge = np.broadcast_to(s_edge, (h, w, 3))
    a = alpha[col][:, None]
    unreached[col] = a * A * s_in[0] + (1 - a) * B * s_edge[col, 0:1]
    for m in range(2):
        comps[m, col] = a * A * s_in[m + 1] + (1 - a) * B * s_edge[col, m + 1:m + 2]
    photo = (comps.sum(axis=0) + unreached).astype(np.float32)
    d = Decomposition(comps, unreached, target)
    kappa = np.array([2.0, 0.125, 8.0])
    own = recolor(blend_edges(d, alpha, photo)[0], kappa)
    along = recolor(blend_edges(d, alpha, photo, along=4)[0], kappa)
    away = col.copy()
    away[4:7, 4:7] = False  # the corner's pixels lie on both edges
    np.testing.assert_allclose(along[away], own[away], rtol=1e-4, atol=1e-6)


def _textured_against_void(alpha):
    """A checker-textured target (albedo ``A`` or ``A2`` pixel by pixel) beside a void (no surface, radiance 0).

    Coverage ``alpha``; the rest of every pixel is void. Returns the decomposition (the edge pixels
    decomposed as non-target: their target part one interaction late, Eq. 9), the photograph and the
    recolor expected at κ = (2, 0.125, 8).
    """
    h, w = alpha.shape
    s_in = np.array([0.7, 0.2, 0.1])
    a2 = np.array([0.6, 0.3, 0.05], np.float32)
    yy, xx = np.mgrid[:h, :w]
    colour = np.where(((yy + xx) % 2 == 0)[:, :, None], A, a2) * alpha[:, :, None]
    target = alpha >= 1
    comps = (s_in[:, None, None, None] * colour[None]).astype(np.float32)
    unreached = np.zeros((h, w, 3), np.float32)
    col = edge(alpha)
    unreached[col] = comps[0, col]  # L̄_d = R^0 L_d, C R^m L_d = R^{m+1} L_d
    comps[0, col], comps[1, col], comps[2, col] = comps[1, col], comps[2, col], 0
    kappa = np.array([2.0, 0.125, 8.0])
    expected = colour * sum(kappa ** (i + 1) * s for i, s in enumerate(s_in))
    return Decomposition(comps, unreached, target), colour.astype(np.float32), kappa, expected


def test_blend_edges_takes_all_the_light_of_a_pixel_against_the_void_beyond_the_frame():
    """A textured target fills the frame; its top row has coverage 0.94, the rest of it beyond the frame
    (nothing the camera saw): no window holds an outside pixel, yet the row is blended, all its light as
    the target's, and recolors exactly (it used to be left silently as non-target)."""
    alpha = np.ones((10, 12), np.float32)
    alpha[0] = 0.94
    d, photo, kappa, expected = _textured_against_void(alpha)
    blended, changed = blend_edges(d, alpha, photo)
    np.testing.assert_array_equal(changed, edge(alpha))
    np.testing.assert_allclose(recolor(blended, kappa), expected, rtol=2e-5, atol=1e-7)
    np.testing.assert_allclose(recolor(blended, 1.0), photo, rtol=1e-5, atol=1e-7)


def test_blend_edges_takes_all_the_light_of_a_pixel_against_a_void_in_the_frame():
    """A textured target beside a void inside the frame (radiance 0): the split gives the target all the
    edge pixel's light, exactly, where extrapolating the texture from the solid pixels would not."""
    alpha = np.zeros((10, 12), np.float32)
    alpha[:, 6:] = 1.0
    alpha[:, 5] = np.random.default_rng(1).uniform(0.1, 0.9, 10)
    d, photo, kappa, expected = _textured_against_void(alpha)
    blended, changed = blend_edges(d, alpha, photo)
    np.testing.assert_array_equal(changed, edge(alpha))
    np.testing.assert_allclose(recolor(blended, kappa), expected, rtol=2e-5, atol=1e-7)


def _edge_scene(colour, alpha, s_in, s_out, b_scale=None):
    """A target of per-pixel colour ``colour`` (coverage ``alpha``) beside a neighbour of colour ``B``.

    The edge pixels hold ``alpha`` of the target (its colour at the pixel) and ``1 − alpha`` of the
    neighbour; the target's interactions have shares ``s_in`` and the neighbour's ``s_out``, those of
    the neighbour's strip in an edge pixel ``s_out`` too. ``b_scale`` (H, W), optional, shades the
    neighbour. Returns the decomposition (edge pixels as non-target: the target part one interaction
    late, Eq. 9), the photograph and the recolor expected at κ = (2, 0.125, 8).
    """
    h, w = alpha.shape
    target, col = alpha >= 1, edge(alpha)
    out = ~target & ~col
    b = np.broadcast_to(B, (h, w, 3)) * (1 if b_scale is None else b_scale[:, :, None])
    a_part = alpha[:, :, None] * colour  # the target's light in each pixel
    b_part = (1 - alpha[:, :, None]) * b
    comps = np.zeros((3, h, w, 3), np.float32)
    unreached = np.zeros((h, w, 3), np.float32)
    comps[:, target] = s_in[:, None, None] * colour[target]
    unreached[out] = s_out[0] * b[out]
    for i in range(2):
        comps[i, out] = s_out[i + 1] * b[out]
    unreached[col] = a_part[col] * s_in[0] + b_part[col] * s_out[0]
    for m in range(2):
        comps[m, col] = a_part[col] * s_in[m + 1] + b_part[col] * s_out[m + 1]
    photo = (comps.sum(axis=0) + unreached).astype(np.float32)
    kappa = np.array([2.0, 0.125, 8.0])
    f_a = sum(kappa ** (i + 1) * s for i, s in enumerate(s_in))
    f_b = s_out[0] + sum(kappa ** (i + 1) * s for i, s in enumerate(s_out[1:]))
    expected = a_part * f_a + b_part * f_b
    return Decomposition(comps, unreached, target), photo, kappa, expected


def test_blend_edges_splits_by_radiance_beside_a_textured_target():
    """A textured target (a checker of 2-pixel squares, albedo ``A`` or ``A2``, within a plain border
    one pixel wide of albedo ``A``) beside a smooth lit neighbour: the strip of target in an edge pixel
    is plain, but a linear extrapolation from the two solid pixels beyond it reads the checker and
    misses it by tens of percent. The texture around the edge sends those pixels to the radiance
    split, exact here (the strip is as bright as the solid pixels beside it): the edge pixels'
    recolor is exact, where the strip left 12 % error; κ = 1 still gives the photograph."""
    h, w = 16, 14
    alpha = np.zeros((h, w), np.float32)
    alpha[:, 7:] = 1.0
    alpha[:, 6] = np.random.default_rng(2).uniform(0.3, 0.9, h)
    yy, xx = np.mgrid[:h, :w]
    a2 = np.array([0.6, 0.3, 0.05], np.float32)
    checker = ((yy // 2 + xx // 2) % 2 == 1) & (xx >= 8)
    colour = np.where(checker[:, :, None], a2, A).astype(np.float32)
    s_in, s_out = np.array([0.7, 0.2, 0.1]), np.array([0.6, 0.3, 0.1])
    d, photo, kappa, expected = _edge_scene(colour, alpha, s_in, s_out)
    blended, changed = blend_edges(d, alpha, photo)
    col = edge(alpha)
    np.testing.assert_array_equal(changed, col)
    np.testing.assert_allclose(recolor(blended, kappa)[col], expected[col], rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(recolor(blended, 1.0)[col], photo[col], rtol=1e-5, atol=1e-7)
    # noise-reduced before the blend, an edge pixel's F mixes its neighbours' shares, which the split's
    # target part would take whole: the strip is kept, with its error
    strip = recolor(blend_edges(d, alpha, photo, smoothed=True)[0], kappa)
    assert np.linalg.norm(strip[col] - expected[col]) > 0.1 * np.linalg.norm(expected[col])


def test_blend_edges_keeps_the_strip_beside_a_smooth_steep_target():
    """A smooth target whose light steepens towards the edge (as interreflections do at a concave
    corner: 30 % more light a pixel nearer), beside a neighbour whose outside pixels' interaction
    shares differ from those of its strip in the edge pixels (the outside pixels' observations miss
    the edge strip's re-emission): the strip extrapolates the target exactly, the radiance split
    would take the wrong shares; the edge pixels keep the strip (exact to 1e-5), not the split's error."""
    h, w = 16, 14
    alpha = np.zeros((h, w), np.float32)
    alpha[:, 7:] = 1.0
    alpha[:, 6] = np.random.default_rng(3).uniform(0.3, 0.9, h)
    xx = np.mgrid[:h, :w][1].astype(np.float32)
    # linear in x from the strip's centre on: 1.3× per pixel towards the edge, exact for the strip
    centre = 6 + (1 - alpha[:, 6:7]) / 2
    ramp = np.where(xx >= 7, 1 + 0.3 * (12 - xx), 1 + 0.3 * (12 - centre))
    colour = (A * ramp[:, :, None]).astype(np.float32)
    s_in, s_out = np.array([0.7, 0.2, 0.1]), np.array([0.6, 0.3, 0.1])
    d, photo, kappa, expected = _edge_scene(colour, alpha, s_in, s_out)
    out = alpha <= 0
    d.unreached[out] *= 1.15  # the outside pixels' shares are off: more unreached light, less interreflection
    d.components[:, out] *= 0.7
    blended, _ = blend_edges(d, alpha, photo)
    col = edge(alpha)
    got = recolor(blended, kappa)
    np.testing.assert_allclose(got[col], expected[col], rtol=1e-4, atol=1e-6)
