"""The paper's method on a small random diffuse radiosity scene with exact transport.

Every 'pixel' is a patch seen by the camera. Light transport: L = E + ρ ⊙ (F L). The
re-emission of Sec. 3.3 is simulated exactly: the projector makes the direct outgoing
radiance of the target equal the previous observation, with the original light off.
"""

import numpy as np
import pytest

from engine.decompose import decompose
from engine.recolor import recolor

H, W, C = 8, 10, 3


def _scene(seed):
    rng = np.random.default_rng(seed)
    n = H * W
    area = rng.uniform(0.5, 2.0, n)
    # symmetric coupling -> reciprocal form factors A_i F_ij = A_j F_ji; rows sum to < 0.65
    target = np.zeros((H, W), bool)
    target[2:6, 3:7] = True
    t = target.ravel()
    g = rng.random((n, n)) ** 3
    g[np.ix_(t, t)] *= 12  # a concave target that sees itself a lot (strong R)
    g = (g + g.T) / 2
    np.fill_diagonal(g, 0)
    f = g * area[None, :]
    f *= 0.85 / f.sum(axis=1).max()
    albedo = rng.uniform(0.1, 0.8, (n, C))
    albedo[target.ravel()] = rng.uniform(0.05, 0.45, (target.sum(), C))
    emission = np.zeros((n, C))
    lights = rng.choice(np.flatnonzero(~target.ravel()), 6, replace=False)
    emission[lights] = rng.uniform(1.0, 5.0, (6, C))
    return f, albedo, emission, target


def _error(image, truth, emission):
    """Relative error over the pixels that are not light sources."""
    lit = emission.reshape(H, W, C).any(axis=-1)
    return np.linalg.norm((image - truth)[~lit]) / np.linalg.norm(truth[~lit])


def _solve(f, albedo, emission):
    n = f.shape[0]
    return np.stack([np.linalg.solve(np.eye(n) - albedo[:, c, None] * f, emission[:, c]) for c in range(C)], axis=1)


def _observations(f, albedo, emission, target, order):
    t = target.ravel()
    obs = [_solve(f, albedo, emission)]
    for _ in range(1, order):
        emitted = np.where(t[:, None], obs[-1], 0.0)  # (I_{r-1} ∩ A): direct outgoing radiance on A
        obs.append(_solve(f, albedo, emitted))
    return np.stack(obs).reshape(order, H, W, C).astype(np.float32)


def _truth(f, albedo, emission, target, kappa):
    scaled = albedo.copy()
    scaled[target.ravel()] *= kappa
    return _solve(f, scaled, emission).reshape(H, W, C)


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("kappa", [0.1, 0.5, 2.0, (2.0, 0.125, 1.5)])
@pytest.mark.parametrize("constraint", ["ordered", "none"])
def test_recolor_converges_to_the_resolved_scene(seed, kappa, constraint):
    f, albedo, emission, target = _scene(seed)
    truth = _truth(f, albedo, emission, target, np.asarray(kappa))
    photograph = _observations(f, albedo, emission, target, 1)[0]
    naive = np.where(target[:, :, None], photograph * np.asarray(kappa, np.float32), photograph)
    naive_error = _error(naive, truth, emission)
    errors = []
    for order in range(1, 7):
        obs = _observations(f, albedo, emission, target, order)
        d = decompose(obs, target, constraint=constraint)
        errors.append(_error(recolor(d, kappa), truth, emission))
    errors = np.array(errors)
    assert naive_error > 0.005  # recoloring the target's pixels alone is visibly wrong here
    # error falls as K grows (truncation of the interaction series, Eq. 3-4) ...
    assert (np.diff(errors) < 0).all(), errors
    # ... to a remainder that is float32 rounding, far below the naive recolor's error
    assert errors[-1] < 1e-5 and errors[-1] < 1e-3 * naive_error, errors


def test_kappa_one_is_the_photograph_at_every_order():
    f, albedo, emission, target = _scene(3)
    for order in (1, 3, 5):
        obs = _observations(f, albedo, emission, target, order)
        out = recolor(decompose(obs, target), 1.0)
        np.testing.assert_allclose(out, obs[0], rtol=1e-4)
