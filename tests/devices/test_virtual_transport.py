"""Virtual rig: the light-transport model and its ground truth.

Linearity, energy conservation, reciprocity, convergence, the interaction series, and the
paper's identity (Eqs. 6 and 9) on an ideal co-axial rig.
"""

from __future__ import annotations

import json
from math import comb

import numpy as np
import pytest

from devices.virtual import open_rig
from devices.virtual.geometry import polygon_form_factor
from devices.virtual.setup import patch_to_patch
from engine.errors import InputError


@pytest.fixture(scope="session")
def cache(tmp_path_factory):
    """One set-up cache for the whole session (the same path in every virtual-rig test file)."""
    return tmp_path_factory.getbasetemp() / "virtual-cache"


@pytest.fixture(scope="module")
def cornell(cache):
    return open_rig("cornell", ideal=True, resolution=(64, 64), cache_dir=cache)


@pytest.fixture(scope="module")
def wedge(cache):
    return open_rig("wedge", ideal=True, resolution=(48, 48), cache_dir=cache)


def _closed_cube(tmp_path, *, emit_ceiling: bool, box: bool = False, everything: bool = False) -> str:
    """A closed 1 m cube (all faces inward), camera inside; optionally an emitting ceiling,
    or (``everything``) every wall emitting radiance 1 with albedo 0.5 (a furnace)."""
    def quad(p0, p1, p3):
        p0, p1, p3 = map(np.asarray, (p0, p1, p3))
        return [p0.tolist(), p1.tolist(), (p1 + p3 - p0).tolist(), p3.tolist()]
    surfaces = [
        {"name": "floor", "corners": quad([0, 0, 0], [0, 0, 1], [1, 0, 0]), "albedo": [0.7, 0.6, 0.5]},
        {"name": "ceiling", "corners": quad([0, 1, 0], [1, 1, 0], [0, 1, 1]), "albedo": [0.5, 0.5, 0.5]},
        {"name": "back", "corners": quad([0, 0, 1], [0, 1, 1], [1, 0, 1]), "albedo": [0.8, 0.8, 0.8]},
        {"name": "front", "corners": quad([0, 0, 0], [1, 0, 0], [0, 1, 0]), "albedo": [0.6, 0.6, 0.6]},
        {"name": "left", "corners": quad([0, 0, 0], [0, 1, 0], [0, 0, 1]), "albedo": [0.7, 0.2, 0.2]},
        {"name": "right", "corners": quad([1, 0, 0], [1, 0, 1], [1, 1, 0]), "albedo": [0.2, 0.7, 0.2]},
    ]
    if emit_ceiling:
        surfaces[1]["emission"] = [2.0, 2.0, 2.0]
    if everything:
        for surf in surfaces:
            surf["emission"], surf["albedo"] = [1.0, 1.0, 1.0], [0.5, 0.5, 0.5]
    data = {"name": "cube", "camera": {"position": [0.5, 0.5, 0.05], "look_at": [0.5, 0.5, 1], "fov_deg": 90},
            "projector": {"power": [1, 1, 1]}, "surfaces": surfaces,
            "targets": {"right": [{"surface": "right"}]}, "patch_size": 0.25}
    if box:
        data["boxes"] = [{"name": "box", "base_center": [0.4, 0, 0.6], "size": [0.3, 0.4, 0.3],
                          "rotation_deg": 20, "albedo": [0.6, 0.6, 0.6]}]
    path = tmp_path / "cube.json"
    path.write_text(json.dumps(data))
    return str(path)


# --- geometry -----------------------------------------------------------------------------

def _numeric_form_factor(x, n, corners, m=400):
    s = (np.arange(m) + 0.5) / m
    a, b = np.meshgrid(s, s, indexing="ij")
    o, u, v = corners[0], corners[1] - corners[0], corners[3] - corners[0]
    p = o + a.reshape(-1, 1) * u + b.reshape(-1, 1) * v
    ne = np.cross(u, v)
    area = np.linalg.norm(ne)
    ne /= area
    d = p - x
    r2 = np.einsum("ij,ij->i", d, d)
    k = np.maximum(d @ n, 0) * np.maximum(-(d @ ne), 0) / (np.pi * r2**2)
    return k.sum() * area / m**2


def test_polygon_form_factor_matches_numerical_integration_including_clipped_quads():
    rng = np.random.default_rng(3)
    got, want = [], []
    for _ in range(25):
        corners = rng.normal(size=(3, 3))
        corners = np.stack([corners[0], corners[1], corners[1] + corners[2] - corners[0], corners[2]])
        ne = np.cross(corners[1] - corners[0], corners[3] - corners[0])
        ne /= np.linalg.norm(ne)
        centre = corners.mean(axis=0)
        x = centre + ne * rng.uniform(0.5, 2.0) + rng.normal(size=3) * 0.5  # in front, not too close
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)  # random receiver orientation: many quads straddle its horizon
        got.append(polygon_form_factor(x[None], n[None], corners[None])[0])
        want.append(_numeric_form_factor(x, n, corners))
    got, want = np.array(got), np.array(want)
    assert np.sum((want > 0) & (want < 0.9 * np.max(want))) > 5  # the cases cover a range
    np.testing.assert_allclose(got, want, rtol=2e-3, atol=1e-5)


def test_closed_cube_form_factors_sum_to_one(tmp_path):
    rig = open_rig(_closed_cube(tmp_path, emit_ceiling=False), ideal=True, resolution=(16, 16), cache_dir=False)
    sums = rig.setup.gn.sum(axis=1)
    np.testing.assert_allclose(sums, 1.0, atol=1e-9)
    assert rig.setup.rescaled_rows == 0


def test_form_factor_rows_never_exceed_one_and_few_needed_rescaling(cornell):
    sums = cornell.setup.gn.sum(axis=1)
    assert sums.max() <= 1 + 1e-12
    assert cornell.setup.rescaled_rows < 0.05 * len(sums)
    # interpolation rows are convex, averaging rows are convex
    w = cornell.setup.interp
    live = cornell.setup.quad >= 0
    np.testing.assert_allclose(np.asarray(w.sum(axis=1)).ravel()[live], 1.0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(cornell.setup.mavg.sum(axis=1)).ravel(), 1.0, atol=1e-12)
    assert w.min() >= 0 and cornell.setup.mavg.min() >= 0


def test_patch_form_factors_are_reciprocal(cornell):
    s = cornell.setup
    f = patch_to_patch(cornell.scene, s)
    assert f.sum(axis=1).max() <= 1 + 1e-9
    af = s.patch_area[:, None] * f
    big = (f > 2e-3) & (f.T > 2e-3)
    rel = np.abs(af - af.T)[big] / np.maximum(af, af.T)[big]
    assert big.sum() > 10000
    assert np.median(rel) < 0.025
    assert np.quantile(rel, 0.9) < 0.15


def test_furnace_closed_box_conserves_energy_exactly(tmp_path):
    """Every wall emits Le and reflects rho: the exact answer is L = Le / (1 - rho) everywhere.

    The discretised transport neither loses nor creates light: sample form factors sum to 1
    in a closed box, so the constant solution is reproduced to rounding.
    """
    rig = open_rig(_closed_cube(tmp_path, emit_ceiling=True, everything=True), ideal=True, resolution=(24, 24),
                   cache_dir=False)
    img = rig.truth.photograph().astype(np.float64)
    np.testing.assert_allclose(img, 1.0 / (1.0 - 0.5), rtol=1e-6)
    r = rig.renderer
    e = r.direct_light(None, ambient=True, dtype=np.float64)
    live = rig.setup.quad >= 0
    np.testing.assert_allclose(e[live], 1.0, rtol=1e-9)  # each point sees the other walls, F sums to 1


def test_reflected_light_never_exceeds_received_light(cornell):
    r = cornell.renderer
    e = r.direct_light(np.ones((64, 64, 3), np.float32), ambient=True, dtype=np.float64)
    radiance = r.base.solve(e)
    from devices.virtual.transport import gather
    received = e + gather(cornell.setup, radiance)
    live = cornell.setup.quad >= 0
    np.testing.assert_allclose(radiance[live], (r.rho * received)[live], rtol=1e-9, atol=1e-12)
    assert np.all(radiance <= received)
    # the scene's radiance is bounded by the geometric series of its brightest albedo
    rho_max = r.rho.max()
    assert radiance.max() <= rho_max * e.max() / (1 - rho_max)


def test_indirect_light_converges_as_patches_get_finer(cache):
    flood = np.ones((64, 64, 3), np.float32)
    imgs = [open_rig("wedge", ideal=True, resolution=(64, 64), cache_dir=cache, patch_size=p)
            .truth.photograph(ambient=False, pattern=flood).astype(np.float64)
            for p in (0.3, 0.15, 0.075)]
    d1, d2 = np.abs(imgs[0] - imgs[1]), np.abs(imgs[1] - imgs[2])
    assert d2.mean() < 0.5 * d1.mean()
    assert d2.max() < d1.max()
    assert d2.mean() < 0.005 * imgs[2].mean()


# --- linearity ----------------------------------------------------------------------------

def test_captures_are_linear_in_the_projector_pattern(cornell):
    rng = np.random.default_rng(1)
    p1 = rng.uniform(0, 0.5, (64, 64, 3)).astype(np.float32)
    p2 = rng.uniform(0, 0.5, (64, 64, 3)).astype(np.float32)

    def shot(p):
        cornell.projector.show(p)
        return cornell.camera.capture().image.astype(np.float64)

    black = shot(np.zeros_like(p1))
    a, b, ab = shot(p1) - black, shot(p2) - black, shot(p1 + p2) - black
    scale = np.abs(ab).max()
    np.testing.assert_allclose(ab, a + b, atol=2e-6 * scale)
    half = shot(0.5 * p1) - black
    np.testing.assert_allclose(half, 0.5 * a, atol=2e-6 * scale)
    assert a.min() >= -1e-6 * scale and a.max() > 0


def test_ideal_capture_is_exactly_the_truth_and_the_ambient_switch_works(cornell):
    p = np.full((64, 64, 3), 0.3, np.float32)
    cornell.projector.show(p)
    np.testing.assert_allclose(cornell.camera.capture().image, cornell.truth.photograph(pattern=p), rtol=1e-6)
    cornell.blank()
    cornell.ambient = False
    try:
        assert np.all(cornell.camera.capture().image == 0)
        np.testing.assert_array_equal(cornell.truth.photograph(ambient=False), 0)
    finally:
        cornell.ambient = True
    assert cornell.camera.capture().image.mean() > 0.05


# --- interaction series and components ----------------------------------------------------

@pytest.fixture(scope="module")
def right_wall_terms(cornell):
    return cornell.truth.interactions(cornell.targets["right_wall"], 80).astype(np.float64)


@pytest.mark.parametrize("kappa", [0.1, 0.5, 1.0, 2.0, (2.0, 0.125, 8.0)])
def test_interaction_series_sums_to_the_recoloured_photograph(cornell, right_wall_terms, kappa):
    mask = cornell.targets["right_wall"]
    terms = right_wall_terms
    k = np.broadcast_to(np.asarray(kappa, np.float64), (3,))
    series = sum(k**n * terms[n] for n in range(81))
    truth = cornell.truth.recolor([(mask, kappa)]).astype(np.float64)
    np.testing.assert_allclose(series, truth, atol=1e-6 * truth.max())
    # the terms decay geometrically: 80 terms are far more than enough
    peaks = np.abs(terms[1:]).max(axis=(1, 2))  # (n, 3)
    assert np.all(peaks[10] < 1e-3 * peaks[0])
    assert np.all(np.abs(k**80 * terms[80]).max() < 1e-6 * truth.max())


def test_interaction_series_with_projector_light_and_two_walls(wedge):
    mask = wedge.targets["union"]
    p = np.random.default_rng(2).uniform(0, 1, (48, 48, 3)).astype(np.float32)
    terms = wedge.truth.interactions(mask, 60, ambient=False, pattern=p).astype(np.float64)
    k = np.array([1.5, 1.2, 0.25])  # Fig. 9
    series = sum(k**n * terms[n] for n in range(61))
    truth = wedge.truth.recolor([(wedge.targets["left"], k), (wedge.targets["right"], k)], ambient=False,
                                pattern=p).astype(np.float64)
    np.testing.assert_allclose(series, truth, atol=1e-6 * truth.max())
    np.testing.assert_allclose(terms.sum(axis=0), wedge.truth.photograph(ambient=False, pattern=p),
                               atol=1e-6 * truth.max())


def test_recolor_of_two_targets_differs_from_recolouring_each_alone(wedge):
    """The paper's Fig. 8 point: interreflections between targets make the edits interact."""
    left, right = wedge.targets["left"], wedge.targets["right"]
    kl, kr = np.array([1.5, 4.5, 0.5]), np.array([2.0, 0.125, 1.2])
    flood = np.ones((48, 48, 3), np.float32)
    base = wedge.truth.photograph(ambient=False, pattern=flood).astype(np.float64)
    both = wedge.truth.recolor([(left, kl), (right, kr)], ambient=False, pattern=flood).astype(np.float64)
    only_l = wedge.truth.recolor([(left, kl)], ambient=False, pattern=flood).astype(np.float64)
    only_r = wedge.truth.recolor([(right, kr)], ambient=False, pattern=flood).astype(np.float64)
    naive = only_l + only_r - base
    assert np.abs(both - naive).max() > 0.01 * both.max()
    # identity and mask-free recolouring leave the photograph unchanged
    np.testing.assert_allclose(wedge.truth.recolor([(left, 1.0)], ambient=False, pattern=flood), base, rtol=1e-6)


def test_components_are_the_interaction_terms_split_by_the_mask(cornell):
    mask = cornell.targets["right_wall"]
    c = cornell.truth.components(mask, 4)
    terms = cornell.truth.interactions(mask, 4)
    assert c.inside.shape == (4, 64, 64, 3) and c.outside.shape == (4, 64, 64, 3) and c.order == 4
    assert c.inside.dtype == np.float32
    np.testing.assert_array_equal(c.inside[:, mask], terms[1:, mask])
    np.testing.assert_array_equal(c.outside[:, ~mask], terms[1:, ~mask])
    np.testing.assert_array_equal(c.unreached[~mask], terms[0][~mask])
    assert np.all(c.inside[:, ~mask] == 0) and np.all(c.outside[:, mask] == 0) and np.all(c.unreached[mask] == 0)
    # paths that never touched the target cannot end on it: L_0 is 0 on the mask
    np.testing.assert_array_equal(terms[0][mask], 0)
    # ordering the paper's solver assumes: R^i L_d decreases inside
    assert np.all(c.inside[1:][:, mask] <= c.inside[:-1][:, mask] + 1e-7)


def test_recolor_refuses_divergent_kappas_and_bad_pairs(cornell):
    everything = np.ones((64, 64), bool)
    with pytest.raises(InputError, match="interaction series diverges"):
        cornell.truth.recolor([(everything, 30.0)])
    with pytest.raises(InputError, match=r"pairs\[0\] kappa must be finite and non-negative"):
        cornell.truth.recolor([(everything, -1.0)])
    with pytest.raises(InputError, match=r"pairs\[0\] mask must have shape \(64, 64\)"):
        cornell.truth.recolor([(np.ones((8, 8), bool), 1.0)])
    with pytest.raises(InputError, match=r"pairs\[0\] must be a \(mask, kappa\) pair"):
        cornell.truth.recolor([everything])
    with pytest.raises(InputError, match=r"pattern values must be in \[0, 1\]"):
        cornell.truth.photograph(pattern=np.full((64, 64, 3), 2.0, np.float32))


# --- the paper's identity -------------------------------------------------------------------

def _reemission_sequence(rig, mask, n_obs):
    """Algorithm of Sec. 3.3 on the rig: I_0 with projector black, then emit (I_{r-1} on A) / D."""
    d = rig.truth.direct(mask)
    assert np.all(d[mask] > 0)
    rig.blank()
    i0 = rig.camera.capture().image.astype(np.float64)
    obs, prev = [i0], i0
    hp, wp = rig.projector.resolution
    for _ in range(1, n_obs):
        pattern = np.zeros((hp, wp, 3))
        pattern[mask] = prev[mask] / d[mask]
        scale = pattern.max()  # Sec. 6 step 1: emit at most 1, undo the scale after capture
        rig.projector.show((pattern / scale).astype(np.float32))
        cur = (rig.camera.capture().image - i0) * scale
        obs.append(cur)
        prev = cur
    return obs


@pytest.mark.parametrize("scene, target", [("cornell", "right_wall"), ("wedge", "left"), ("three", "beige")])
def test_reemitting_the_observation_applies_the_transport_operator(cache, scene, target):
    """Eq. 6 inside and Eq. 9 outside: I_r = sum_n binom(n + r, r) R^n L_d (+ L̄_d for r = 0)."""
    rig = open_rig(scene, ideal=True, resolution=(48, 48), cache_dir=cache, ambient=True)
    mask = rig.targets[target]
    n_obs, n_terms = 5, 150
    obs = _reemission_sequence(rig, mask, n_obs)
    c = rig.truth.components(mask, n_terms)
    interacted = (c.inside + c.outside).astype(np.float64)  # R^n L_d on A, C R^n L_d elsewhere
    for r in range(n_obs):
        expected = sum(comb(n + r, r) * interacted[n] for n in range(n_terms))
        if r == 0:
            expected = expected + c.unreached
        err = np.abs(obs[r] - expected).max() / np.abs(expected).max()
        assert err < 1e-4, (r, err)
    # the re-emitted sequence really carries information beyond the photograph
    assert np.abs(obs[2] - obs[1]).max() > 0.05 * np.abs(obs[1]).max()
