"""ColorChecker placement, detection, sampling and the absolute albedo fit (engine.checker, engine.albedo)."""

import numpy as np
import pytest

from engine.albedo import AlbedoScale, fit_albedo_scale, reference_scale
from engine.checker import (
    Checker,
    NoChart,
    checker_from_corners,
    detect_checker,
    patch_names,
    reference_reflectances,
    sample_patches,
)
from engine.errors import InputError

SHAPE = (160, 240)
CORNERS = np.array([[52.0, 38.0], [196.0, 30.0], [190.0, 128.0], [58.0, 122.0]])  # a chart seen slightly in perspective


def _photograph(corners, light=(1.0, 0.85, 0.6)):
    """A chart drawn into a grey room under a warm light: swatches 80 % of each cell, black gaps."""
    img = np.full(SHAPE + (3,), 0.3, np.float32)
    card = Checker(np.asarray(corners, float), SHAPE)
    img[card.mask(fraction=1.0)] = 0.03
    for i, m in enumerate(card.patch_masks(fraction=0.8)):
        img[m] = reference_reflectances()[i]
    return img * np.asarray(light, np.float32)


def test_reference_reflectances_are_colour_sciences_chart_in_camera_channels():
    rho = reference_reflectances()
    assert rho.shape == (24, 3) and not rho.flags.writeable
    assert len(patch_names()) == 24 and patch_names()[5] == "bluish green"
    grey = rho[18:24]
    assert np.all(np.diff(grey.mean(axis=1)) < 0)  # white → black
    assert np.ptp(grey, axis=1).max() < 0.01  # neutral
    assert rho[14].argmax() == 0 and rho[13].argmax() == 1 and rho[12].argmax() == 2  # red, green, blue patches
    with pytest.raises(InputError, match="unknown camera sensitivities"):
        reference_reflectances("no such camera")


def test_manual_corners_place_patches_in_perspective():
    c = checker_from_corners(CORNERS, SHAPE)
    masks = c.patch_masks()
    assert masks.shape == (24,) + SHAPE and np.all(masks.sum(axis=(1, 2)) > 20)
    assert not (masks.sum(axis=0) > 1).any()
    cy, cx = np.nonzero(masks[0])
    np.testing.assert_allclose([cx.mean(), cy.mean()], c.centres()[0], atol=0.6)
    with pytest.raises(InputError, match="convex"):
        checker_from_corners(CORNERS[[0, 2, 1, 3]], SHAPE)
    with pytest.raises(InputError, match="outside the 240×160 image"):
        checker_from_corners(CORNERS + [100, 0], SHAPE)
    with pytest.raises(InputError, match="4 points"):
        checker_from_corners(CORNERS[:3], SHAPE)


@pytest.mark.parametrize("turn", [0, 2], ids=["upright", "upside-down"])
def test_detection_finds_the_chart_and_its_orientation(turn):
    corners = np.roll(CORNERS, turn, axis=0)  # upside down: dark skin at the bottom right
    img = _photograph(corners)
    found = detect_checker(img)
    assert found.source == "detected"
    assert np.abs(found.centres() - Checker(corners, SHAPE).centres()).max() < 2.0
    means, counts = sample_patches(img, found)
    assert counts.min() > 10
    np.testing.assert_allclose(means / means[18], reference_reflectances() / reference_reflectances()[18], atol=1e-3)


def test_no_chart_is_a_clear_error_that_offers_manual_corners():
    rng = np.random.default_rng(0)
    with pytest.raises(NoChart, match="place its four corners by hand"):  # the app then offers to place them
        detect_checker(rng.uniform(0.2, 0.4, SHAPE + (3,)).astype(np.float32))
    with pytest.raises(InputError, match="black") as black:
        detect_checker(np.zeros(SHAPE + (3,), np.float32))
    assert not isinstance(black.value, NoChart)  # nothing to place corners on


def test_fit_recovers_the_scale_and_drops_a_bad_patch():
    rho = reference_reflectances()
    scale = np.array([1.1, 0.9, 1.4])
    d = rho * scale
    d[6] *= 1.5  # a glint on the orange patch
    d[20] = np.nan  # a patch the projector did not reach
    fit = fit_albedo_scale(d, rho)
    np.testing.assert_allclose(fit.scale, scale, rtol=1e-9)
    assert not fit.used[6] and not fit.used[20] and fit.used.sum() == 22
    assert fit.rms_residual < 1e-9 and fit.residual[6, 0] == pytest.approx(0.5)
    with pytest.raises(InputError, match="at least 6"):
        fit_albedo_scale(np.where(np.arange(24)[:, None] < 5, d, np.nan), rho)


def test_fit_models_a_projector_lighting_the_charts_plane_unevenly():
    rho = reference_reflectances()
    v, u = np.divmod(np.arange(24), 6)
    xy = np.stack([40.0 + 12 * u, 30.0 + 12 * v], axis=1)  # projector pixels of the patch centres

    def light(p):
        return (1.0 + 0.004 * p[..., 0] - 0.006 * p[..., 1]) ** 3  # h / z³ on a tilted plane

    scale = np.array([1.1, 0.9, 1.4])
    d = rho * scale * light(xy)[:, None]
    uniform = fit_albedo_scale(d, rho)
    assert uniform.rms_residual > 0.05
    fit = fit_albedo_scale(d, rho, patch_xy=xy)
    assert fit.rms_residual < 1e-9 and fit.used.all()
    # a target in the same plane, beside the chart
    target = np.ones((2, 2), bool)
    pix = np.stack(np.meshgrid([120.0, 125.0], [90.0, 95.0]), axis=-1)
    albedo = np.array([0.3, 0.5, 0.2])
    direct = albedo * scale * light(pix)[..., None]
    np.testing.assert_allclose(fit.albedo(direct, target, pix), albedo, rtol=1e-9)
    with pytest.raises(InputError, match="projector coordinates"):
        fit.albedo(direct, target)


def test_albedo_from_a_checker_scale_and_from_a_reference_card():
    target = np.zeros((4, 5), bool)
    target[1:3, 1:4] = True
    falloff = np.linspace(0.5, 2.0, 20).reshape(4, 5, 1)  # projector light varies across the target
    rho = np.array([0.1, 0.8, 0.1])
    direct = falloff * rho
    # a global scale is right only where the light matches where the chart was
    assert AlbedoScale(np.ones(3)).albedo(np.ones((4, 5, 1)) * rho, target).tolist() == pytest.approx(rho.tolist())
    # a card laid over the target cancels the light per pixel
    card = reference_scale(falloff * np.full(3, 0.9), [0.9, 0.9, 0.9], target)
    np.testing.assert_allclose(card.albedo(direct, target), rho)
    with pytest.raises(InputError, match="no measured D"):
        reference_scale(np.zeros((4, 5, 3)), [0.9, 0.9, 0.9], target)
    with pytest.raises(InputError, match=r"in \(0, 1\)"):
        reference_scale(falloff * np.full(3, 0.9), [1.0, 0.9, 0.9], target)
