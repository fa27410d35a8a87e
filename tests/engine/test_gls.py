"""The weighted (GLS) decomposition: same answer on exact data, the right covariance, weights matter."""

import numpy as np
import pytest

import engine.decompose as decompose_module
from engine.decompose import Decomposition, decompose
from engine.errors import InputError
from engine.figurate import outside_matrix, transport_matrix
from engine.noise import pack_covariance, packed_index, unpack_covariance
from engine.recolor import recolor, recolor_variance


def _diagonal(order, shape, sd):
    """Packed covariance with independent observations of standard deviations ``sd`` (K,)."""
    full = np.zeros((order, order) + shape, np.float32)
    for r in range(order):
        full[r, r] = sd[r] ** 2
    return pack_covariance(full)


@pytest.mark.parametrize("order", [2, 4, 6])
@pytest.mark.parametrize("constraint", ["ordered", "nonnegative", "none"])
def test_exact_data_give_the_unweighted_answer(stack, order, constraint):
    obs, inside, outside, unreached, target = stack(order, dtype=np.float64, seed=order)
    cov = _diagonal(order, obs.shape[1:], 0.01 * np.arange(1, order + 1))
    plain = decompose(obs, target, constraint=constraint)
    weighted = decompose(obs, target, constraint=constraint, covariance=cov)
    scale = np.abs(obs).max() * 1e-9 * np.linalg.cond(transport_matrix(order))
    np.testing.assert_allclose(weighted.components, plain.components, atol=scale)
    np.testing.assert_allclose(weighted.unreached, plain.unreached, atol=scale)
    assert weighted.covariance.shape == cov.shape and weighted.covariance.dtype == np.float32


def test_unconstrained_covariance_is_the_propagated_one_and_matches_sampling():
    order, n = 3, 40000
    rng = np.random.default_rng(0)
    comps = np.array([1.0, 0.3, 0.08])
    sd = np.array([0.01, 0.02, 0.04])
    shape = (1, n, 1)
    target = np.zeros((1, n), bool)
    target[0, : n // 2] = True
    m_in, m_out = transport_matrix(order), outside_matrix(order)
    outside = np.array([0.5, 0.2, 0.05])  # L̄_d, C R^0 L_d, C R^1 L_d
    clean = np.where(target[None, :, :, None], (m_in @ comps)[:, None, None, None],
                     (m_out @ outside)[:, None, None, None])
    obs = clean + rng.standard_normal((order,) + shape) * sd[:, None, None, None]
    d = decompose(obs, target, constraint="none", covariance=_diagonal(order, shape, sd))
    off = np.concatenate([d.unreached[None], d.components[:2]])
    for region, matrix, truth, values in ((target, m_in, comps, d.components), (~target, m_out, outside, off)):
        inv = np.linalg.inv(matrix)
        expected = inv @ np.diag(sd**2) @ inv.T
        got = unpack_covariance(d.covariance)[:, :, region, 0].mean(axis=-1, dtype=np.float64)
        np.testing.assert_allclose(got, expected, rtol=1e-4)
        sample = np.cov(values[:, region, 0])
        np.testing.assert_allclose(sample, expected, rtol=0.05, atol=0.03 * np.abs(expected).max())
        mean = values[:, region, 0].mean(axis=-1, dtype=np.float64)
        assert np.all(np.abs(mean - truth) < 4 * np.sqrt(np.diag(expected) / region.sum()))
    sd_comp, sd_unr = d.standard_deviation()
    assert sd_comp.shape == d.components.shape and sd_unr.shape == d.unreached.shape
    # off the target (the last loop's region) C R^0 L_d is unknown 1, L̄_d unknown 0
    assert sd_comp[0, 0, n - 1, 0] == pytest.approx(np.sqrt(expected[1, 1]), rel=1e-4)
    assert sd_unr[0, n - 1, 0] == pytest.approx(np.sqrt(expected[0, 0]), rel=1e-4)
    assert sd_unr[0, 0, 0] == 0


def test_weights_decide_where_the_ordering_constraint_binds():
    """One observation far noisier than the others: where the ordering binds, GLS leans on the
    precise ones and lands closer to the truth than the unweighted projection."""
    order, n = 3, 20000
    rng = np.random.default_rng(1)
    comps = np.array([1.0, 0.2, 0.0])  # the last component is at its bound
    sd = np.array([0.002, 0.002, 0.2])
    shape = (1, n, 1)
    target = np.ones((1, n), bool)
    target[0, 0] = False  # a target may not cover every pixel
    clean = (transport_matrix(order) @ comps)[:, None, None, None]
    obs = clean + rng.standard_normal((order,) + shape) * sd[:, None, None, None]
    cov = _diagonal(order, shape, sd)
    plain = decompose(obs, target)
    weighted = decompose(obs, target, covariance=cov)
    t = target[0]
    err_plain = np.abs(plain.components[:2, 0, t, 0] - comps[:2, None]).mean()
    err_weighted = np.abs(weighted.components[:2, 0, t, 0] - comps[:2, None]).mean()
    assert err_weighted < 0.7 * err_plain
    # an active constraint fixes its increment: no spread along it
    variance = np.asarray(weighted.covariance)[packed_index(2, 2, 3), 0, t, 0]
    assert np.all(variance[weighted.components[2, 0, t, 0] == 0] < 1e-12)


def test_recolor_variance_is_the_weighted_covariance():
    order = 3
    rng = np.random.default_rng(2)
    shape = (4, 5, 3)
    target = np.zeros(shape[:2], bool)
    target[1:3, 1:4] = True
    full = rng.uniform(0.1, 1.0, (order, order) + shape)
    full = np.einsum("ikhwc,jkhwc->ijhwc", full, full).astype(np.float32)  # positive semi-definite
    d = Decomposition(np.zeros((order,) + shape, np.float32), np.zeros(shape, np.float32), target,
                      constraint="none", covariance=pack_covariance(full))
    kappa = np.array([0.5, 1.0, 3.0])
    var = recolor_variance(d, kappa)
    for y, x, inside in ((1, 1, True), (0, 0, False)):
        for c in range(3):
            w = kappa[c] ** (np.arange(order) + (1 if inside else 0))
            assert var[y, x, c] == pytest.approx(w @ full[:, :, y, x, c] @ w, rel=1e-5)


def test_bad_covariances_are_refused(stack):
    obs, *_, target = stack(3, seed=4)
    with pytest.raises(InputError, match="covariance must have shape"):
        decompose(obs, target, covariance=np.zeros((3,) + obs.shape[1:], np.float32))
    with pytest.raises(InputError, match="non-finite"):
        decompose(obs, target, covariance=np.full((6,) + obs.shape[1:], np.nan, np.float32))
    plain = decompose(obs, target)
    with pytest.raises(InputError, match="no covariance"):
        plain.standard_deviation()
    with pytest.raises(InputError, match="no covariance"):
        recolor_variance(plain, 2.0)


def test_weighted_tiles_give_the_same_answer(stack, monkeypatch):
    obs, *_, target = stack(4, shape=(21, 17, 3), seed=6)
    cov = _diagonal(4, obs.shape[1:], [0.01, 0.02, 0.03, 0.04])
    noisy = obs + np.random.default_rng(3).standard_normal(obs.shape).astype(np.float32) * 0.02
    whole = decompose(noisy, target, covariance=cov)
    monkeypatch.setattr(decompose_module, "TILE_PIXELS", 40)
    tiled = decompose(noisy, target, covariance=cov)
    np.testing.assert_array_equal(whole.components, tiled.components)
    np.testing.assert_array_equal(whole.covariance, tiled.covariance)
    assert np.isfinite(recolor(whole, 2.0)).all()
