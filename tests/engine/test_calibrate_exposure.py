"""Exposure report and black frame: fractions, verdicts in plain words."""

from __future__ import annotations

import numpy as np
import pytest

from engine.calibrate import black_frame, exposure_report
from engine.errors import InputError

SHAPE = (50, 60)


def frame(seed=0):
    rng = np.random.default_rng(seed)
    return (0.2 + 0.6 * rng.random(SHAPE + (3,))).astype(np.float32)


def test_good_frame_is_ok():
    img = frame()
    r = exposure_report(img, saturated=np.zeros(SHAPE, bool), full_scale=1.0)
    assert r.ok and r.verdict == "ok"
    assert r.saturated_fraction == 0 and r.underexposed_fraction == 0 and r.pixels == 3000
    assert str(r).startswith("ok: 0.0% of 3000 pixels saturated")


def test_over_and_under_exposure_fractions_on_the_target_only():
    img = frame()
    sat = np.zeros(SHAPE, bool)
    sat[:10] = True  # 600 pixels clipped
    img[40:, :, :] = 0.001  # 600 pixels too dark
    r = exposure_report(img, saturated=sat, full_scale=1.0)
    assert r.saturated_fraction == pytest.approx(0.2) and r.underexposed_fraction == pytest.approx(0.2)
    assert r.verdict == "over- and under-exposed" and not r.ok
    target = np.zeros(SHAPE, bool)
    target[15:35] = True
    t = exposure_report(img, target=target, saturated=sat, full_scale=1.0)
    assert t.ok and t.pixels == 1200 and "target pixels" in t.message
    over = exposure_report(img, target=~(np.arange(50) >= 40)[:, None].repeat(60, 1), saturated=sat, full_scale=1.0)
    assert over.verdict == "over-exposed" and "shorten the exposure" in over.message
    under = exposure_report(img, target=np.arange(50)[:, None].repeat(60, 1) >= 10, saturated=sat, full_scale=1.0)
    assert under.verdict == "under-exposed" and "lengthen the exposure" in under.message


def test_full_scale_alone_detects_clipping_and_unknown_is_said():
    img = frame()
    img[:5] = 0.9
    r = exposure_report(img, full_scale=0.9)
    assert r.saturated_fraction == pytest.approx(0.1) and r.verdict == "over-exposed"
    u = exposure_report(img)
    assert u.saturated_fraction is None and "saturation not checked" in u.message


def test_ambient_light_is_reported():
    img = frame()
    r = exposure_report(img, black=img * 0.7, full_scale=1.0, saturated=np.zeros(SHAPE, bool))
    assert r.ambient_fraction == pytest.approx(0.7, rel=1e-5)
    assert r.verdict == "too much ambient light" and "darken the room" in r.message
    assert exposure_report(img, black=img * 0.1, full_scale=1.0).verdict == "ok"


def test_black_frame_averages_and_keeps_negatives():
    rng = np.random.default_rng(0)
    caps = rng.normal(0.0, 0.01, (16,) + SHAPE + (3,)).astype(np.float32)
    before = caps.copy()
    b = black_frame(caps)
    np.testing.assert_array_equal(caps, before)
    assert b.dtype == np.float32 and b.shape == SHAPE + (3,)
    assert (b < 0).any()  # not clipped
    assert b.std() == pytest.approx(0.01 / 4, rel=0.1)  # noise down by √N


def test_bad_inputs():
    img = frame()
    with pytest.raises(InputError, match=r"image must have shape \(H, W, 3\)"):
        exposure_report(img[..., 0])
    with pytest.raises(InputError, match="saturated must be a boolean"):
        exposure_report(img, saturated=np.zeros(SHAPE))
    with pytest.raises(InputError, match="full_scale must be a positive number"):
        exposure_report(img, full_scale=0)
    with pytest.raises(InputError, match=r"low must be in \[0, 1\)"):
        exposure_report(img, low=2)
    with pytest.raises(InputError, match="same shape"):
        black_frame([img, img[:3]])
    assert exposure_report(img, target=np.zeros(SHAPE, bool)).verdict == "no pixels"
