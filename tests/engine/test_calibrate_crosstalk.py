"""Colour crosstalk: fit the mixing matrix from primaries, unmix with counted clamping."""

from __future__ import annotations

import numpy as np
import pytest

from engine.calibrate import Crosstalk, crosstalk_patterns, fit_crosstalk
from engine.errors import InputError

MIX = np.array([[0.80, 0.18, 0.02], [0.10, 0.75, 0.15], [0.02, 0.23, 0.75]])  # rows sum to 1
SHAPE = (30, 40)


def primaries(seed=0, noise=0.002):
    rng = np.random.default_rng(seed)
    rho = 0.1 + 0.8 * rng.random(SHAPE + (3,))
    falloff = 0.5 + 0.5 * rng.random(SHAPE + (1,))
    black = 0.03 + 0.01 * rng.random(SHAPE + (3,))
    caps = np.stack([falloff * rho * MIX[:, j] + black + rng.normal(0, noise, SHAPE + (3,)) for j in range(3)])
    return caps.astype(np.float32), black.astype(np.float32)


def test_recovers_the_matrix_and_unmixes():
    caps, black = primaries()
    before = caps.copy()
    x = fit_crosstalk(caps, black=black)
    np.testing.assert_array_equal(caps, before)
    np.testing.assert_allclose(x.matrix, MIX, atol=0.005)
    np.testing.assert_allclose(x.matrix.sum(axis=1), 1.0)
    rng = np.random.default_rng(1)
    p = rng.random(SHAPE + (3,)).astype(np.float32)
    got, clamped = x.unmix(x.mix(p))
    assert got.dtype == np.float32 and clamped == 0
    np.testing.assert_allclose(got, p, atol=1e-5)


def test_out_of_gamut_colours_are_counted_not_hidden():
    x = Crosstalk(MIX)
    desired = np.array([[[1.0, 0.0, 0.0], [0.5, 0.5, 0.5]], [[0.0, 1.0, 0.0], [0.2, 0.3, 0.4]]], np.float32)
    raw, n = x.unmix(desired, clamp=False)
    assert n == 2 and (raw[0, 0] < 0).any() and (raw[1, 0] < 0).any()
    clamped, n2 = x.unmix(desired)
    assert n2 == 2 and clamped.min() == 0
    np.testing.assert_array_equal(clamped[0, 1], raw[0, 1])


def test_no_crosstalk_is_identity():
    p, n = Crosstalk.none().unmix([[0.2, 0.4, 0.6]])
    np.testing.assert_allclose(p, [[0.2, 0.4, 0.6]], atol=1e-7)
    assert n == 0


def test_patterns_and_serialisation():
    seq = crosstalk_patterns((2, 3))
    assert len(seq) == 3 and seq[1].dtype == np.float32
    np.testing.assert_array_equal(seq[1][0, 0], [0, 1, 0])
    x = Crosstalk(MIX)
    np.testing.assert_array_equal(Crosstalk.from_dict(x.to_dict()).matrix, x.matrix)
    with pytest.raises(InputError, match="not a valid crosstalk"):
        Crosstalk.from_dict({})


def test_bad_inputs():
    caps, black = primaries()
    with pytest.raises(InputError, match="expected 3 captures"):
        fit_crosstalk(caps[:2])
    with pytest.raises(InputError, match="black must have shape"):
        fit_crosstalk(caps, black=black[:5])
    with pytest.raises(InputError, match="channel saw no projector light"):
        fit_crosstalk(np.zeros_like(caps))
    same = np.stack([caps[0]] * 3)
    with pytest.raises(InputError, match="singular.*primaries are not independent"):
        fit_crosstalk(same, black=black)
    with pytest.raises(InputError, match="3×3"):
        Crosstalk(np.eye(2))
    with pytest.raises(InputError, match="last axis of 3"):
        Crosstalk.none().unmix(np.zeros((4, 2)))
