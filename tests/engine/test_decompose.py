import numpy as np
import pytest

import engine.decompose as decompose_module
from engine.decompose import Decomposition, decompose, observe
from engine.errors import Cancelled, InputError
from engine.figurate import transport_matrix

COND = {k: np.linalg.cond(transport_matrix(k)) for k in range(1, 9)}


def _tolerance(order, dtype):
    eps = np.finfo(dtype).eps
    return 8 * eps * COND[order]


@pytest.mark.parametrize("order", [1, 2, 3, 4, 5, 6])
@pytest.mark.parametrize("constraint", ["ordered", "nonnegative", "none"])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_exact_stacks_decompose_back(stack, order, constraint, dtype):
    obs, inside, outside, unreached, target = stack(order, dtype=dtype, seed=order)
    d = decompose(obs, target, constraint=constraint)
    assert d.components.dtype == dtype and d.residual.dtype == np.float32
    assert d.inside.shape == inside.shape and d.outside.shape == (order - 1,) + obs.shape[1:]
    scale = np.abs(obs).max()
    tol = _tolerance(order, dtype) * scale
    t = target[None, :, :, None]
    np.testing.assert_allclose(d.inside, np.where(t, inside, 0), atol=tol)
    np.testing.assert_allclose(d.outside, np.where(t, 0, outside), atol=tol)
    np.testing.assert_allclose(d.unreached, np.where(t[0], 0, unreached), atol=tol)
    assert d.residual.max() < (1e-5 if dtype == np.float32 else 1e-10)
    assert d.order == order and d.constraint == constraint and d.target is not target


@pytest.mark.parametrize("order", [2, 4])
def test_projector_only_lighting_frees_one_outside_component(stack, order):
    obs, inside, outside, unreached, target = stack(order, unreached_light=False, seed=3)
    d = decompose(obs, target, unreached_light=False)
    assert d.outside.shape[0] == order and not d.unreached.any()
    tol = _tolerance(order, np.float32) * np.abs(obs).max()
    np.testing.assert_allclose(d.outside, np.where(target[None, :, :, None], 0, outside), atol=tol)


def test_tiles_give_the_same_answer(stack, monkeypatch):
    obs, *_, target = stack(4, shape=(37, 23, 3), seed=5)
    whole = decompose(obs, target)
    monkeypatch.setattr(decompose_module, "TILE_PIXELS", 50)  # 2 rows per tile, ragged last tile
    tiled = decompose(obs, target)
    np.testing.assert_array_equal(whole.components, tiled.components)
    np.testing.assert_array_equal(whole.residual, tiled.residual)


def test_observe_is_the_inverse_of_decompose(stack):
    obs, *_, target = stack(5, seed=8)
    d = decompose(obs, target)
    np.testing.assert_allclose(observe(d), obs, atol=1e-5 * np.abs(obs).max())
    # more observations than the order continue the figurate sequence
    assert observe(d, order=7).shape[0] == 7


def test_observe_with_kappa_is_the_recolored_scene_sequence(stack):
    obs, inside, outside, unreached, target = stack(3, seed=9)
    d = Decomposition.from_components(inside, outside, unreached, target)
    kappa = np.array([0.5, 1.0, 2.0])
    scaled = Decomposition.from_components(
        inside * kappa ** np.arange(1, 4)[:, None, None, None],
        outside * kappa ** np.arange(1, 3)[:, None, None, None],
        unreached,
        target,
    )
    np.testing.assert_allclose(observe(d, kappa=kappa), observe(scaled), rtol=1e-5)


def test_residual_flags_inconsistent_pixels(stack):
    obs, *_, target = stack(3, seed=2)
    bad = obs.copy()
    y, x = np.argwhere(target)[0]
    bad[2, y, x] = -5.0  # violates R^2 L_d >= 0 by far
    d = decompose(bad, target)
    assert d.residual[y, x] > 0.1
    assert np.median(d.residual) < 1e-5


def test_progress_and_cancel(stack, monkeypatch):
    obs, *_, target = stack(3, shape=(20, 10, 3))
    monkeypatch.setattr(decompose_module, "TILE_PIXELS", 40)
    calls = []
    decompose(obs, target, progress=lambda s, t, m: calls.append((s, t)))
    assert calls[0] == (0, 5) and calls[-1] == (5, 5)
    with pytest.raises(Cancelled):
        decompose(obs, target, should_stop=lambda: True)


def test_inputs_are_not_modified(stack):
    obs, *_, target = stack(3)
    before = obs.copy(), target.copy()
    decompose(obs, target)
    np.testing.assert_array_equal(obs, before[0])
    np.testing.assert_array_equal(target, before[1])


@pytest.mark.parametrize(
    "mutate, match",
    [
        (lambda o, t: (o[:0], t), r"K >= 1"),
        (lambda o, t: (o, t[:-1]), r"target must have shape \(24, 30\)"),
        (lambda o, t: (o.astype(np.uint16), t), "floating-point"),
        (lambda o, t: (np.where(o > 0.5, np.nan, o), t), "non-finite"),
        (lambda o, t: (o[..., :2], t), "1 or 3 channels"),
        (lambda o, t: (o[0], t), "4 dimensions"),
        (lambda o, t: (o, np.zeros_like(t)), "target is empty"),
        (lambda o, t: (o, np.ones_like(t)), "covers every pixel"),
        (lambda o, t: (o, t.astype(np.uint8)), "boolean mask"),
        (lambda o, t: (np.concatenate([o] * 3), t), "at most 8"),
    ],
)
def test_bad_input_is_named(stack, mutate, match):
    obs, *_, target = stack(3)
    o, t = mutate(obs, target)
    with pytest.raises(InputError, match=match):
        decompose(o, t)


def test_bad_constraint(stack):
    obs, *_, target = stack(2)
    with pytest.raises(InputError, match="constraint must be one of"):
        decompose(obs, target, constraint="monotone")


def test_the_observations_summed_over_the_target_are_kept_where_they_still_hold(stack):
    """``observed`` is Eq. 6's left side for the whole target, untouched by the constraint (which clips noisy
    components at 0, a bias up): kept through the session cache, noise reduction and the edge blend; a crop,
    whose target is another, has none."""
    from engine.denoise import denoise_components
    from engine.edge import blend_edges

    obs, *_, target = stack(4, seed=3)
    noisy = obs + np.random.default_rng(3).normal(0, 0.02, obs.shape).astype(obs.dtype)
    d = decompose(noisy, target)
    expected = noisy[:, target].astype(np.float64).sum(axis=1)
    np.testing.assert_allclose(d.observed, expected, rtol=1e-12)
    np.testing.assert_array_equal(Decomposition.from_arrays(d.to_arrays()).observed, d.observed)
    corrupt = d.to_arrays() | {"observed": np.full_like(d.observed, np.nan)}
    with pytest.raises(InputError, match="observed contains 12 non-finite values"):
        Decomposition.from_arrays(corrupt)
    np.testing.assert_array_equal(denoise_components(d, noisy[0], radius=1).observed, d.observed)
    coverage = target.astype(np.float32)
    coverage[~target & np.roll(target, 1, axis=1)] = 0.5
    np.testing.assert_array_equal(blend_edges(d, coverage, noisy[0])[0].observed, d.observed)
    assert d.crop(0, 5, 0, 5).observed is None
    with pytest.raises(InputError, match="observed must be None or a float array of shape"):
        Decomposition(d.components, d.unreached, d.target, observed=np.zeros((3, 3)))
