"""Projector response: recover gamma curves and black level from noisy simulated ramps."""

from __future__ import annotations

import numpy as np
import pytest

from engine.calibrate import ProjectorResponse, fit_response, ramp_levels, response_patterns
from engine.errors import InputError

GAMMA = np.array([2.2, 2.0, 2.4])
BLACK = np.array([0.02, 0.03, 0.015])
SHAPE = (40, 50)


def simulate(levels, *, channels="together", seed=0, noise=0.003, ambient_level=0.05, crosstalk=None):
    """Captures of a ramp: per-pixel scale × (black + (1 − black) · level^γ) + ambient + noise.

    ``crosstalk`` (3×3, rows = camera channels) mixes projector primaries into camera channels.
    Returns captures (M, H, W, 3) float32 and a noisy ambient capture.
    """
    rng = np.random.default_rng(seed)
    scale = (0.2 + 0.8 * rng.random(SHAPE + (1,))) * np.array([1.0, 0.8, 0.6])
    ambient = ambient_level * rng.random(SHAPE + (3,))
    mix = np.eye(3) if crosstalk is None else np.asarray(crosstalk)
    caps = []
    if channels == "together":
        inputs = [np.full(3, v) for v in levels]
    else:
        inputs = [np.eye(3)[c] * v for c in range(3) for v in levels]
    for p in inputs:
        light = BLACK + (1 - BLACK) * p**GAMMA  # per projector primary, relative to its full
        cam = mix @ light  # camera channels
        caps.append(scale * cam + ambient + rng.normal(0, noise, SHAPE + (3,)))
    amb_capture = ambient + rng.normal(0, noise, SHAPE + (3,))
    return np.stack(caps).astype(np.float32), amb_capture.astype(np.float32)


@pytest.mark.parametrize("seed", [0, 1])
def test_recovers_gamma_and_black_level(seed):
    lv = ramp_levels(17)
    caps, amb = simulate(lv, seed=seed)
    before = caps.copy()
    r = fit_response(list(caps), lv, ambient=amb)
    np.testing.assert_array_equal(caps, before)
    np.testing.assert_array_equal(fit_response(caps, lv, ambient=amb).table, r.table)
    np.testing.assert_allclose(r.black_level, BLACK, atol=0.001)
    np.testing.assert_allclose(r.table, lv[:, None] ** GAMMA, atol=0.002)
    p = np.linspace(0, 1, 301)[:, None].repeat(3, 1)
    f = r.forward(p)
    assert f.dtype == np.float32
    np.testing.assert_allclose(f, p**GAMMA, atol=0.002)
    v = np.linspace(0, 1, 301)[:, None].repeat(3, 1)
    q = r.linearize(v)
    assert q.dtype == np.float32 and np.all(np.diff(q, axis=0) >= 0)
    np.testing.assert_allclose(r.forward(q), v, atol=1e-4)
    hi = v[:, 0] >= 0.02
    np.testing.assert_allclose(q[hi], v[hi] ** (1 / GAMMA), atol=0.004)
    assert np.all(np.diff(r.table, axis=0) >= 0)


def test_without_ambient_capture_the_ambient_counts_as_black():
    lv = ramp_levels(9)
    caps, _ = simulate(lv, ambient_level=0.0)
    r = fit_response(caps, lv)
    np.testing.assert_allclose(r.black_level, BLACK, atol=0.002)


def test_separate_channels_are_immune_to_crosstalk():
    lv = ramp_levels(9)
    mix = np.array([[0.85, 0.15, 0.0], [0.1, 0.8, 0.1], [0.0, 0.25, 0.75]])
    caps, amb = simulate(lv, channels="separate", crosstalk=mix)
    assert caps.shape[0] == 27
    r = fit_response(caps, lv, channels="separate", ambient=amb)
    np.testing.assert_allclose(r.table, lv[:, None] ** GAMMA, atol=0.004)
    # Camera-channel black level: all-black light over all-white light, per camera channel.
    expected_b = (mix @ BLACK) / mix.sum(axis=1)
    np.testing.assert_allclose(r.black_level, expected_b, atol=0.002)


def test_mask_limits_the_pixels_used():
    lv = ramp_levels(9)
    caps, amb = simulate(lv)
    mask = np.zeros(SHAPE, bool)
    mask[5:20, 5:30] = True
    spoiled = caps.copy()
    spoiled[:, ~mask] = 0.7  # a region the projector does not reach
    r = fit_response(spoiled, lv, ambient=amb, mask=mask)
    np.testing.assert_allclose(r.table, lv[:, None] ** GAMMA, atol=0.006)


def test_projector_not_visible():
    lv = ramp_levels(9)
    rng = np.random.default_rng(3)
    caps = (0.3 + rng.normal(0, 0.002, (9,) + SHAPE + (3,))).astype(np.float32)
    message = "camera saw no change between projector black and white.*projector on and pointed at"
    with pytest.raises(InputError, match=message):
        fit_response(caps, lv)


def test_reversed_or_shuffled_ramps_are_refused():
    lv = ramp_levels(9)
    caps, _ = simulate(lv, ambient_level=0.0)
    with pytest.raises(InputError, match="got darker.*pattern order"):
        fit_response(caps[::-1], lv)
    shuffled = caps[[0, 1, 5, 3, 4, 2, 6, 7, 8]]
    with pytest.raises(InputError, match="not monotonic.*settle"):
        fit_response(shuffled, lv)


def test_small_noise_dips_are_made_monotonic():
    lv = np.linspace(0, 1, 33)
    caps, _ = simulate(lv, noise=0.05, ambient_level=0.0, seed=4)
    r = fit_response(caps, lv)
    assert np.any(np.diff(r.raw_table, axis=0) < 0)  # the measurement dipped ...
    assert np.all(np.diff(r.table, axis=0) >= 0)  # ... the fit does not
    np.testing.assert_allclose(r.table, lv[:, None] ** GAMMA, atol=0.02)


def test_stepped_dlp_curve_inverts_to_a_function():
    lv = np.linspace(0, 1, 9)
    table = np.repeat(np.array([0, 0.1, 0.1, 0.1, 0.4, 0.5, 0.7, 0.9, 1.0])[:, None], 3, 1)
    r = ProjectorResponse(lv, table, 0.0)
    v = np.linspace(0, 1, 50)[:, None].repeat(3, 1)
    q = r.linearize(v)
    assert np.all(np.diff(q[:, 0]) >= 0)
    np.testing.assert_allclose(r.forward(q), v, atol=0.01)


def test_bad_arguments():
    lv = ramp_levels(5)
    caps, _ = simulate(lv, ambient_level=0.0)
    with pytest.raises(InputError, match="expected 5 captures for 5 levels"):
        fit_response(caps[:4], lv)
    with pytest.raises(InputError, match="expected 15 captures"):
        fit_response(caps, lv, channels="separate")
    with pytest.raises(InputError, match="from exactly 0"):
        fit_response(caps, [0.1, 0.3, 0.5, 0.7, 1.0])
    with pytest.raises(InputError, match="floating-point"):
        fit_response((caps * 255).astype(np.uint8), lv)
    with pytest.raises(InputError, match="channels must be one of"):
        fit_response(caps, lv, channels="rgb")
    with pytest.raises(InputError, match="mask selects no camera pixels"):
        fit_response(caps, lv, mask=np.zeros(SHAPE, bool))
    r = ProjectorResponse.linear()
    with pytest.raises(InputError, match=r"values must lie in \[0, 1\].*2 values"):
        r.linearize([[1.2, 0.5, -0.1]])
    with pytest.raises(InputError, match="last axis of 3"):
        r.forward([0.5, 0.5])
    with pytest.raises(InputError, match="non-decreasing"):
        ProjectorResponse(np.linspace(0, 1, 3), np.array([[0.0] * 3, [0.8] * 3, [0.5] * 3]), 0.0)


def test_patterns_and_serialisation():
    lv = ramp_levels(5)
    seq = response_patterns(lv, (3, 4))
    assert len(seq) == 5 and seq[2].dtype == np.float32 and np.all(seq[2] == np.float32(lv[2]))
    sep = response_patterns(lv, (3, 4), channels="separate")
    assert len(sep) == 15 and np.all(sep[7][..., 1] == np.float32(lv[2])) and np.all(sep[7][..., [0, 2]] == 0)
    caps, amb = simulate(lv)
    r = fit_response(caps, lv, ambient=amb)
    back = ProjectorResponse.from_dict(r.to_dict())
    v = np.linspace(0, 1, 11)[:, None].repeat(3, 1)
    np.testing.assert_array_equal(back.linearize(v), r.linearize(v))
    np.testing.assert_array_equal(back.black_level, r.black_level)
    with pytest.raises(InputError, match="not a valid projector response"):
        ProjectorResponse.from_dict({"levels": [0, 1]})
    assert (ramp_levels(3, bit_depth=8) * 255).tolist() == [0, 128, 255]
