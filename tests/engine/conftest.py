from math import comb

import numpy as np
import pytest


def synthesize(inside, outside, unreached, target):
    """Observations from known components through Eq. 6 (inside) and Eq. 9 (outside),
    written independently of engine.decompose.observe."""
    k = inside.shape[0]
    obs = np.zeros_like(inside)
    t = target[:, :, None]
    for r in range(k):
        for n in range(k):
            obs[r] += np.where(t, comb(n + r, r) * inside[n], 0)
        for n in range(outside.shape[0]):
            obs[r] += np.where(t, 0, comb(n + r, r) * outside[n])
    obs[0] += np.where(t, 0, unreached)
    return obs


def random_components(order, shape, rng, *, dtype=np.float32, unreached_light=True, decay=0.4):
    """Components inside the 'ordered' feasible set: positive and decreasing with order."""
    h, w, c = shape
    base = rng.uniform(0.2, 1.0, (h, w, c))
    ratios = rng.uniform(0.2, 1.0, (order, h, w, c)) * decay
    ratios[0] = 1.0
    comps = base * np.cumprod(ratios, axis=0)
    target = np.zeros((h, w), bool)
    target[h // 4 : 3 * h // 4, w // 3 : 2 * w // 3] = True
    n_out = order - 1 if unreached_light else order
    outside = comps[:n_out] * 0.5
    unreached = rng.uniform(0.0, 1.0, (h, w, c)) if unreached_light else np.zeros((h, w, c))
    return comps.astype(dtype), outside.astype(dtype), unreached.astype(dtype), target


@pytest.fixture
def stack():
    """Factory: (observations, inside, outside, unreached, target) from random components."""

    def make(order=4, shape=(24, 30, 3), *, seed=0, dtype=np.float32, unreached_light=True):
        rng = np.random.default_rng(seed)
        inside, outside, unreached, target = random_components(
            order, shape, rng, dtype=dtype, unreached_light=unreached_light
        )
        obs = synthesize(inside.astype(np.float64), outside.astype(np.float64), unreached.astype(np.float64), target)
        return obs.astype(dtype), inside, outside, unreached, target

    return make
