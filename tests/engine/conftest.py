from math import comb

import numpy as np
import pytest

from engine.acquire import PreparedTarget
from engine.calibrate import Calibration, Correspondence, ProjectorResponse


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


# --- an exact co-axial stand-in rig for acquisition tests -------------------------------

H, W, C = 8, 10, 3
GAMMA = 2.2


class _Frame:
    def __init__(self, image):
        self.image, self.exposure, self.gain, self.black_level = image, 1.0, 1.0, 0.0
        self.saturated = np.zeros(image.shape[:2], bool)
        self.metadata = {}


class PatchRig:
    """Exact co-axial camera-projector stand-in; counts what it was asked to do."""

    name = "patch-rig"

    def __init__(self, seed=0, *, ambient=True, targets=1):
        rng = np.random.default_rng(seed)
        n = H * W
        self.targets = []
        for y0, x0 in [(1, 1), (1, 6), (5, 3)][:targets]:
            m = np.zeros((H, W), bool)
            m[y0 : y0 + 3, x0 : x0 + 3] = True
            self.targets.append(m)
        self.target = np.logical_or.reduce(self.targets) if targets > 1 else self.targets[0]
        if targets == 1:
            self.target = np.zeros((H, W), bool)
            self.target[2:6, 3:7] = True
            self.targets = [self.target]
        t = self.target.ravel()
        g = rng.random((n, n)) ** 3
        g[np.ix_(t, t)] *= 12
        g = (g + g.T) / 2
        np.fill_diagonal(g, 0)
        self.f = g * 0.85 / g.sum(axis=1).max()
        self.albedo = rng.uniform(0.1, 0.8, (n, C))
        self.albedo[t] = rng.uniform(0.05, 0.45, (t.sum(), C))
        self.emission = np.zeros((n, C))
        if ambient:
            lights = rng.choice(np.flatnonzero(~t), 6, replace=False)
            self.emission[lights] = rng.uniform(1.0, 5.0, (6, C))
        self.gain = rng.uniform(0.5, 1.5, n)  # projector irradiance factor per pixel
        self.direct = (self.albedo * self.gain[:, None]).reshape(H, W, C)
        self.camera = self
        self.projector = self
        self.resolution = (H, W)
        self.bit_depth = 8
        self.exposure = 1.0
        self.shown = np.zeros((H, W, C), np.float32)
        self.captures = 0

    def show(self, image):
        assert image.shape == (H, W, 3) and image.min() >= 0 and image.max() <= 1
        self.shown = image

    def capture(self):
        self.captures += 1
        light = self.shown.astype(np.float64) ** GAMMA  # the projector's response
        e = self.emission + (self.direct * light).reshape(-1, C)
        return _Frame(self.solve(self.albedo, e).reshape(H, W, C).astype(np.float32))

    def solve(self, albedo, e):
        n = self.f.shape[0]
        return np.stack([np.linalg.solve(np.eye(n) - albedo[:, c, None] * self.f, e[:, c]) for c in range(C)], 1)

    def truth(self, kappa, *, projector_light=0.0, pairs=None):
        """The scene with target albedos scaled (``pairs`` of (mask, κ), or the target by
        ``kappa``), ambient on, the projector at ``projector_light`` everywhere."""
        a = self.albedo.copy()
        for mask, kap in pairs if pairs is not None else [(self.target, kappa)]:
            a[mask.ravel()] *= np.asarray(kap)
        e = self.emission + a * self.gain[:, None] * projector_light
        return self.solve(a, e).reshape(H, W, C)


def stand_in_calibration(rig):
    levels = np.linspace(0, 1, 257)
    table = np.repeat((levels**GAMMA)[:, None], 3, axis=1)
    return Calibration(
        rig_name=rig.name,
        camera_resolution=(H, W),
        projector_resolution=(H, W),
        black_frame=np.zeros((H, W, 3), np.float32),
        response=ProjectorResponse(levels, table, np.zeros(3)),
        correspondence=Correspondence.identity((H, W)),
    )


def exact_prepared(rig, mask=None):
    t = rig.target if mask is None else mask
    return PreparedTarget(
        t.copy(), np.zeros_like(t), np.where(t[:, :, None], rig.direct, 0).astype(np.float32),
        Correspondence.identity((H, W))
    )
