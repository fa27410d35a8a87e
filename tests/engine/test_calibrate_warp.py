"""Camera↔projector warps: averaging, hole filling inside the footprint only, round trips."""

from __future__ import annotations

import numpy as np
import pytest

from engine.calibrate import (
    Correspondence,
    estimate_hole_radius,
    projector_footprint,
    projector_to_camera_map,
    warp_to_camera,
    warp_to_projector,
)
from engine.errors import InputError

CAM = (60, 80)


def scaled(scale, *, proj=(100, 140), offset=(8, 10), cam=CAM, invalid=None):
    """Correspondence of an affine rig: projector = offset + scale · camera (rounded)."""
    v, u = np.indices(cam)
    x = np.floor(offset[1] + scale * u + 0.5).astype(np.int32)
    y = np.floor(offset[0] + scale * v + 0.5).astype(np.int32)
    valid = (x < proj[1]) & (y < proj[0])
    if invalid is not None:
        valid &= ~invalid
    return Correspondence.from_maps(np.where(valid, x, 0), np.where(valid, y, 0), valid, proj)


def smooth_image(cam=CAM, channels=3):
    v, u = np.indices(cam, dtype=np.float32)
    return np.stack([1 + np.sin(u / 9 + c) * np.cos(v / 7) for c in range(channels)], -1).astype(np.float32)


def disc(cam=CAM, centre=(30, 40), radius=18):
    v, u = np.indices(cam)
    return (v - centre[0]) ** 2 + (u - centre[1]) ** 2 <= radius**2


def test_coarse_camera_round_trip_and_holes_filled_inside_footprint_only():
    corr = scaled(1.5)
    img = smooth_image()
    target = disc()
    before = img.copy()
    proj = warp_to_projector(img, corr, (100, 140), target=target)
    np.testing.assert_array_equal(img, before)
    assert proj.dtype == np.float32 and proj.shape == (100, 140, 3)
    # One camera pixel per projector pixel: the round trip is exact on the target.
    back = warp_to_camera(proj, corr)
    np.testing.assert_array_equal(back[target], img[target])
    # The projected disc (centre (8 + 45, 10 + 60), radius 27) is filled, nothing outside it is lit.
    pv, pu = np.indices((100, 140))
    r = np.hypot(pv - 53, pu - 70)
    lit = np.any(proj != 0, axis=-1)
    assert lit[r <= 26].all()
    assert not lit[r >= 29].any()
    # Hole values are averages of their neighbours: smooth like the image.
    hit = projector_to_camera_map(corr, target=target).count > 0
    assert (~hit & (r <= 26)).sum() > 500
    assert np.abs(np.diff(proj[..., 0], axis=1))[r[:, :-1] <= 25].max() < 0.3
    unfilled = warp_to_projector(img, corr, target=target, fill_holes=False)
    assert np.all(unfilled[~hit] == 0)
    np.testing.assert_array_equal(unfilled[hit], proj[hit])


def test_fine_camera_averages_many_to_one():
    corr = scaled(0.5, proj=(40, 50), offset=(2, 3))
    img = smooth_image()
    proj = warp_to_projector(img, corr)
    # Reference: explicit accumulation.
    ok = corr.valid
    sums = np.zeros((40, 50, 3))
    n = np.zeros((40, 50))
    np.add.at(sums, (corr.y[ok], corr.x[ok]), img[ok])
    np.add.at(n, (corr.y[ok], corr.x[ok]), 1)
    hit = n > 0
    assert n.max() >= 4
    np.testing.assert_allclose(proj[hit], sums[hit] / n[hit, None], rtol=1e-6)
    m = projector_to_camera_map(corr)
    assert m.count.dtype == np.int32 and np.array_equal(m.count, n.astype(np.int32))
    assert np.isnan(m.u[~hit]).all()
    vv, uu = np.indices(CAM)
    su = np.zeros((40, 50))
    np.add.at(su, (corr.y[ok], corr.x[ok]), uu[ok])
    np.testing.assert_allclose(m.u[hit], su[hit] / n[hit], rtol=1e-6)
    assert estimate_hole_radius(corr) == 1


def test_undecoded_pixels_are_not_emitted_and_are_reported():
    hole = np.zeros(CAM, bool)
    hole[20:25, 30:35] = True
    corr = scaled(1.0, invalid=hole)
    target = disc()
    assert corr.missing(target).sum() == 25
    assert corr.summary(target).startswith("25 of")
    img = np.ones(CAM + (3,), np.float32)
    img[hole] = 100.0  # undecoded pixels must not leak into the projector image
    proj = warp_to_projector(img, corr, target=target)
    assert proj.max() == 1.0


def test_plane_images_and_fill_value():
    corr = scaled(1.0)
    plane = smooth_image(channels=1)[..., 0]
    proj = warp_to_projector(plane, corr)
    assert proj.shape == (100, 140)
    back = warp_to_camera(proj, Correspondence.from_maps(corr.x, corr.y, disc(), corr.projector_resolution), fill=-5)
    assert back.shape == CAM and np.all(back[~disc()] == -5)
    np.testing.assert_array_equal(back[disc()], plane[disc()])


def test_footprint_matches_the_target():
    corr = scaled(2.0, proj=(130, 170))
    fp = projector_footprint(corr, target=disc())
    pv, pu = np.indices((130, 170))
    r = np.hypot(pv - 68, pu - 90)
    assert fp[r <= 33].all() and not fp[r >= 39].any()
    assert estimate_hole_radius(corr) == 1
    assert estimate_hole_radius(scaled(3.0, proj=(200, 260))) == 2


def test_bad_arguments():
    corr = scaled(1.0)
    with pytest.raises(InputError, match=r"camera_image must have shape \(60, 80\)"):
        warp_to_projector(np.zeros((10, 10, 3), np.float32), corr)
    with pytest.raises(InputError, match="floating-point"):
        warp_to_projector(np.zeros(CAM + (3,), np.uint8), corr)
    with pytest.raises(InputError, match="decoded for a 140×100 projector"):
        warp_to_projector(np.zeros(CAM + (3,), np.float32), corr, (768, 1024))
    with pytest.raises(InputError, match="must be an engine.calibrate.Correspondence"):
        warp_to_projector(np.zeros(CAM + (3,), np.float32), (corr.x, corr.y))
    with pytest.raises(InputError, match="NaN"):
        warp_to_projector(np.full(CAM, np.nan, np.float32), corr)
    with pytest.raises(InputError, match="target must have shape"):
        warp_to_projector(np.zeros(CAM, np.float32), corr, target=np.ones((3, 3), bool))
    with pytest.raises(InputError, match="hole_radius must be an integer"):
        warp_to_projector(np.zeros(CAM, np.float32), corr, hole_radius=-1)
    with pytest.raises(InputError, match="projector_image must have shape"):
        warp_to_camera(np.zeros((3, 3), np.float32), corr)
