"""Direct image D: Nayar high-frequency separation on a synthetic scene with known split."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from engine.calibrate import direct_image, high_frequency_patterns
from engine.errors import InputError

SHAPE = (64, 72)  # co-axial rig: camera pixel = projector pixel; multiples of the period


def blur(img, sigma):
    """Wide blur, periodic at the borders so the checkerboards stay exactly half lit."""
    return ndimage.gaussian_filter(img, (sigma, sigma, 0), mode="wrap")


def scene(seed=0):
    rng = np.random.default_rng(seed)
    v, u = np.indices(SHAPE, dtype=np.float64)
    rho = np.stack([0.5 + 0.3 * np.sin(u / 11 + c) * np.cos(v / 13) for c in range(3)], -1)
    rho *= 0.9 + 0.1 * rng.random(SHAPE + (1,))  # a little texture
    ambient = 0.05 + 0.02 * rng.random(SHAPE + (3,))
    return rho, ambient


def capture(pattern, rho, ambient, b, *, gain=0.6, sigma=6.0, noise=0.0, rng=None):
    """Direct ρ·E plus global = gain · ρ · blur(ρ · E) (the mean emitted light, blurred)."""
    e = b + (1 - b) * pattern  # emitted light relative to full white, per channel
    glob = gain * rho * blur(rho * e, sigma)
    img = ambient + rho * e + glob
    if noise:
        img = img + rng.normal(0, noise, img.shape)
    return img.astype(np.float32)


def truth(rho, b, mask=None, gain=0.6, sigma=6.0):
    """L_d and L_g under full white on the lit area (the rest of the projector at black)."""
    lit = np.ones(SHAPE + (3,)) if mask is None else np.repeat(mask[..., None], 3, -1).astype(float)
    glob = gain * rho * blur(rho * lit, sigma)
    return rho, glob


@pytest.mark.parametrize("b", [0.0, 0.04, np.array([0.02, 0.05, 0.08])])
def test_recovers_direct_and_global(b):
    b = np.broadcast_to(np.asarray(b, float), (3,))
    rho, amb = scene()
    pats = high_frequency_patterns(SHAPE)
    caps = np.stack([capture(p, rho, amb, b) for p in pats])
    before = caps.copy()
    d = direct_image(caps, black_fraction=b, ambient=amb)
    np.testing.assert_array_equal(caps, before)
    ld, lg = truth(rho, b)
    assert d.direct.dtype == np.float32 and d.global_light.dtype == np.float32
    # The small residual comes from the surface texture at the checkerboard's frequency.
    np.testing.assert_allclose(d.direct, ld, atol=0.002)
    np.testing.assert_allclose(d.global_light, lg, atol=0.002)
    np.testing.assert_allclose(d.per_input, (1 - b) * ld, atol=0.002)
    from_list = direct_image(list(caps), black_fraction=b, ambient=amb)
    np.testing.assert_array_equal(from_list.direct, d.direct)
    # Without the black-level correction the direct image is measurably wrong when b > 0.
    if b.max() > 0:
        naive = direct_image(caps, ambient=amb)
        assert np.abs(naive.direct - ld).max() > 0.01


def test_noise_biases_max_minus_min_by_about_two_sigma():
    rho, amb = scene(1)
    b = np.full(3, 0.04)
    rng = np.random.default_rng(1)
    sigma = 0.001
    caps = np.stack([capture(p, rho, amb, b, noise=sigma, rng=rng) for p in high_frequency_patterns(SHAPE)])
    d = direct_image(caps, black_fraction=b, ambient=amb)
    ld, lg = truth(rho, b)
    err = d.direct - ld
    assert sigma < err.mean() < 3 * sigma  # E[max of 4] − E[min of 4] ≈ 2.06 σ
    assert np.abs(err).max() < 0.01 and np.abs(d.global_light - lg).max() < 0.012


def test_restricted_to_target_footprint():
    rho, amb = scene(2)
    v, u = np.indices(SHAPE)
    target = (v - 30) ** 2 + (u - 36) ** 2 <= 20**2
    b = np.full(3, 0.03)
    pats = high_frequency_patterns(SHAPE, mask_projector=target)
    for p in pats:
        assert np.all(p[~target] == 0)
    caps = np.stack([capture(p, rho, amb, b) for p in pats])
    d = direct_image(caps, black_fraction=b, ambient=amb, target=target)
    # Exact but for the global light's dependence on which boundary cells are lit: a few
    # per cent at the target's edge, where the blurred checkerboard is not half lit.
    err = np.abs(d.direct - rho)[target]
    assert np.median(err) < 0.002 and err.max() < 0.015
    assert np.all(d.direct[~target] == 0) and np.all(d.global_light[~target] == 0)
    # The global part is the target's own interreflection plus a small term from the black
    # level of the unlit surroundings: 2c / (1 + b), c = their constant contribution.
    _, lg = truth(rho, b, target)
    rest = capture(np.zeros(SHAPE + (3,)), rho, amb, b) - amb - rho * b
    rest_from_outside = rest - 0.6 * rho * blur(rho * b * target[..., None], 6.0)
    expected = lg + 2 * rest_from_outside / (1 + b)
    gerr = np.abs(d.global_light - expected)[target]
    assert np.median(gerr) < 0.002 and gerr.max() < 0.015


@pytest.mark.parametrize("period,shifts", [(8, 2), (6, 3), (10, 2), (12, 4)])
def test_every_pixel_is_fully_lit_and_fully_unlit(period, shifts):
    pats = np.stack([p[..., 0] for p in high_frequency_patterns((40, 50), period=period, shifts=shifts)])
    assert pats.shape[0] == 2 * shifts**2
    assert np.all(pats.mean(axis=0) == 0.5)  # lit in exactly half
    full_lit = np.stack([ndimage.minimum_filter(p, 3, mode="nearest") for p in pats]).max(axis=0)
    full_unlit = np.stack([ndimage.maximum_filter(p, 3, mode="nearest") for p in pats]).min(axis=0)
    assert np.all(full_lit == 1) and np.all(full_unlit == 0)


def test_bad_arguments():
    caps = np.zeros((4,) + SHAPE + (3,), np.float32)
    with pytest.raises(InputError, match="black_fraction must be"):
        direct_image(caps, black_fraction=1.0)
    with pytest.raises(InputError, match="black_fraction must be"):
        direct_image(caps, black_fraction=[0.1, 0.2])
    with pytest.raises(InputError, match="at least 2"):
        direct_image(caps[:1])
    with pytest.raises(InputError, match="ambient must have shape"):
        direct_image(caps, ambient=np.zeros((3, 3, 3), np.float32))
    with pytest.raises(InputError, match="floating-point"):
        direct_image(caps.astype(np.uint8))
    with pytest.raises(InputError, match="period must be an even integer"):
        high_frequency_patterns(SHAPE, period=7)
    with pytest.raises(InputError, match="shifts must be an integer in 1..4"):
        high_frequency_patterns(SHAPE, shifts=5)
    with pytest.raises(InputError, match="mask_projector must be a boolean"):
        high_frequency_patterns(SHAPE, mask_projector=np.ones((3, 3), bool))
    with pytest.raises(InputError, match="footprint is empty"):
        high_frequency_patterns(SHAPE, mask_projector=np.zeros(SHAPE, bool))
