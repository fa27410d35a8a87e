"""Exposure report and black frame: fractions, verdicts in plain words."""

from __future__ import annotations

import numpy as np
import pytest

from engine.calibrate import AutoExposure, black_frame, exposure_report, projector_lit
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


# --- automatic exposure -------------------------------------------------------------------


def _full_scale_level(frame, model, percentile):
    """Where the frame's bright end sits, as a fraction of the virtual camera's clip level."""
    clip_electrons = min(model.full_well, (model.white_level - model.black_level) * model.electrons_per_dn)
    level = np.percentile(frame.image.max(axis=-1), percentile)
    return level * model.electrons_per_radiance * frame.exposure / clip_electrons


@pytest.mark.parametrize("start", [1e-5, 10.0])  # 12 stops under, 8 stops over
def test_auto_exposure_converges_on_the_virtual_camera(tmp_path_factory, start):
    import devices

    cache = tmp_path_factory.getbasetemp() / "virtual-cache"
    with devices.open_rig("virtual:cornell", resolution=(48, 48), seed=3, cache_dir=cache) as rig:
        rig.ambient = False  # expose for the projector's white, as the wizard's Auto does
        rig.projector.show(np.ones(rig.projector.resolution + (3,), np.float32))
        rig.camera.exposure = start
        auto = AutoExposure(percentile=99.5, max_saturated=0.005)
        for steps in range(1, 16):  # noqa: B007 (read after the loop)
            frame = rig.camera.capture()
            wanted = auto.step(frame.image, frame.saturated, exposure=frame.exposure)
            if wanted is None:
                break
            rig.camera.exposure = wanted
        assert wanted is None and steps <= 10
        assert frame.saturated.mean() <= 0.005
        assert 0.8 / 1.26 <= _full_scale_level(frame, rig.camera.model, 99.5) <= 0.8 * 1.26


def test_auto_exposure_steps_blindly_until_it_has_seen_clipping_then_remembers_it():
    auto = AutoExposure(step_factor=2.0)
    img = np.full(SHAPE + (3,), 1.0, np.float32)
    none = np.zeros(SHAPE, bool)
    assert auto.step(img, none, exposure=1.0) == 2.0
    everything = np.ones(SHAPE, bool)
    assert auto.step(img, everything, exposure=2.0) == 1.0  # all clipped: back off
    assert auto.clip_constant == pytest.approx(2.0)  # radiance 1 clipped at 2 s
    # nothing clips any more, but the clip level is known: jump straight to 0.8 of it
    assert auto.step(img * 0.5, none, exposure=1.0) == pytest.approx(0.8 * 2.0 / 0.5)
    # judged on the target only: the bright half outside it does not count
    target = np.zeros(SHAPE, bool)
    target[:, :10] = True
    lit = img.copy()
    lit[:, 10:] = 100.0
    assert auto.step(lit, none, exposure=1.6, target=target) is None  # radiance 1 at 0.8 × clip: settled
    assert auto.step(lit, none, exposure=1.6) == pytest.approx(0.016)  # the whole frame: expose for 100


def test_auto_exposure_bad_input():
    auto = AutoExposure()
    img = np.ones(SHAPE + (3,), np.float32)
    with pytest.raises(InputError, match="exposure"):
        auto.step(img, np.zeros(SHAPE, bool), exposure=0.0)
    with pytest.raises(InputError, match="saturated"):
        auto.step(img, np.zeros((2, 2), bool), exposure=1.0)
    with pytest.raises(InputError, match="target is empty"):
        auto.step(img, np.zeros(SHAPE, bool), exposure=1.0, target=np.zeros(SHAPE, bool))


def test_projector_lit_leaves_out_ambient_sources_and_distrusts_a_dark_frame():
    black = np.zeros(SHAPE + (3,), np.float32)
    black[:5, :5] = 50.0  # a lamp, as bright under projector black
    white = black + 1.0
    lit = projector_lit(white, black)
    assert not lit[:5, :5].any() and lit[5:].all()
    assert projector_lit(black, black) is None  # no projector light seen anywhere: judge the whole frame
    with pytest.raises(InputError, match="black"):
        projector_lit(white, black[:3])
