"""Hardware checks of a real rig, run only with ``pytest tests/devices --device NAME``.

NAME is any ``devices.open_rig`` name (``gphoto2``, ``opencv:0``, ``hotfolder:/folder``,
``harvesters:/path/producer.cti``). Point the projector at a matte, light, static surface that
fills the camera's view, and expose so that projector white does not clip.
"""

from __future__ import annotations

import numpy as np
import pytest

import devices


@pytest.fixture
def rig(device_name):
    with devices.open_rig(device_name) as r:
        yield r


def _flat(rig, level):
    hp, wp = rig.projector.resolution
    return np.full((hp, wp, 3), level, np.float32)


def _lit(white, black):
    """Pixels the projector lights well and no frame clips."""
    ok = ~(white.saturated | black.saturated)
    gain = (white.image - black.image).mean(axis=2)
    return ok & (gain > 0.2 * np.percentile(gain[ok], 99))


def test_projector_light_is_seen_and_the_frame_is_linear_radiance_with_device(rig):
    black = (rig.projector.show(_flat(rig, 0.0)), rig.camera.capture())[1]
    white = (rig.projector.show(_flat(rig, 1.0)), rig.camera.capture())[1]
    assert white.image.shape == (*rig.camera.resolution, 3) and white.image.dtype == np.float32
    lit = _lit(white, black)
    assert lit.mean() > 0.05, "the projector's light is not seen: check cabling, screen and focus"
    again = (rig.projector.show(_flat(rig, 0.0)), rig.camera.capture())[1]
    # black right after white: a stale (queued) frame or too short a settle time shows up here
    np.testing.assert_allclose(again.image[lit].mean(), black.image[lit].mean(), rtol=0.1,
                               atol=0.02 * white.image[lit].mean())


def test_radiance_does_not_depend_on_exposure_with_device(rig):
    cam = rig.camera
    rig.projector.show(_flat(rig, 0.5))
    start = cam.exposure
    try:
        first = cam.capture()
        try:
            cam.exposure = start / 2
        except (ValueError, RuntimeError) as exc:
            pytest.skip(f"exposure is not settable on this rig: {exc}")
        second = cam.capture()
    finally:
        cam.exposure = start
    ok = ~(first.saturated | second.saturated)
    bright = first.image.mean(axis=2) > np.percentile(first.image.mean(axis=2)[ok], 50)
    ratio = second.image[ok & bright].mean() / first.image[ok & bright].mean()
    # linear radiance: half the exposure, same radiance (a gamma-encoded camera gives ~0.73)
    assert ratio == pytest.approx(1.0, abs=0.05), f"radiance ratio {ratio:.3f} at half exposure: not linear"
