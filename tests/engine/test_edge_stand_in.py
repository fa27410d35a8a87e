"""The target part of a soft mask's edge pixels cannot be re-emitted: the emitted pixels next to
it stand in for it, so that the observations keep to Eq. 6 (against the virtual rig's truth)."""

from contextlib import contextmanager
from math import comb

import numpy as np

import devices
from engine.acquire import CaptureSettings, Recorder, acquire_single, calibrate_rig
from engine.acquire.predict import relative_error
from engine.denoise import denoise_components
from engine.edge import stand_in
from engine.recolor import recolor

KAPPA = np.array([0.5, 1.2, 0.8])


@contextmanager
def calibrated_box(size: int, cache):
    """The ideal Cornell box with 4×4-supersampled pixels, calibrated: (rig, recorder, calibration)."""
    with devices.open_rig("virtual:cornell", ideal=True, resolution=(size, size), supersample=4,
                          cache_dir=cache) as rig:
        rec = Recorder(rig, None)
        yield rig, rec, calibrate_rig(rec, rig_name=rig.identity)


def test_standing_in_for_the_edge_makes_the_observations_those_of_the_whole_target(tmp_path):
    with calibrated_box(32, tmp_path) as (rig, rec, cal):
        cov, hard = rig.coverage["right_wall"], rig.targets["right_wall"]
        terms = rig.truth.interactions(hard, 10)
        # the observations if the whole target surface, edge strip included, re-emitted (Eq. 6 and 9)
        exact = [sum(comb(n - 1 + r, r) * terms[n] for n in range(1, 11)) for r in (1, 2)]
        truth = rig.truth.recolor([(hard, KAPPA)])
        surfaces = ~rig.truth.emitters()
        obs_err, img_err = {}, {}
        for on in (False, True):
            acq = acquire_single(rec, cal, cov, 3, name=f"stand-in-{on}", settings=CaptureSettings(stand_in=on))
            emitted = acq.target.mask
            obs_err[on] = max(relative_error(acq.observations[r], exact[r - 1], emitted) for r in (1, 2))
            img_err[on] = relative_error(recolor(acq.target.decompose(acq.observations), KAPPA), truth, surfaces)
    # measured at 32²: observations 6.3 % → 4.7 % off, recolor 1.25 % → 1.04 % over the image (3.1 %
    # and 0.75 % if the pattern's scale made room for the raised light instead of cutting it at τ)
    assert obs_err[True] < 0.8 * obs_err[False] and obs_err[True] < 0.05, obs_err
    assert img_err[True] < 0.9 * img_err[False] and img_err[True] < 0.011, img_err


def test_stand_in_gives_each_edge_pixels_coverage_to_its_nearest_emitted_pixels():
    cov = np.zeros((5, 6), np.float32)
    cov[:, 2:] = 1
    cov[:, 1] = 0.4
    emitted = cov >= 1
    emitted[2, 2] = False  # a hole: its coverage is not stood in for (the caller gives edge coverage only)
    edge_only = np.where(cov < 1, cov, 0)
    b = stand_in(edge_only, emitted)
    assert np.isclose(b.sum(), edge_only.sum())  # nothing lost, nothing made up
    assert (b[~emitted] == 0).all() and (b[:, 3:] == 0).all()  # only the emitted pixels next to the edge
    gap = emitted.copy()
    gap[:, 2] = False  # two pixels away: the next ring takes it
    assert np.isclose(stand_in(edge_only, gap)[:, 3].sum(), edge_only.sum())
    assert stand_in(edge_only, gap, radius=1).sum() == 0  # farther than the radius: nobody


def test_settings_store_the_stand_in_only_when_it_is_off():
    on, off = CaptureSettings(), CaptureSettings(stand_in=False)
    assert "stand_in" not in on.to_dict()  # plans stored before it existed stay equal
    assert CaptureSettings.from_dict(off.to_dict()) == off and CaptureSettings.from_dict(on.to_dict()) == on


def test_the_truth_splits_each_pixels_interactions_into_the_targets_part_and_the_rest(tmp_path):
    with devices.open_rig("virtual:cornell", ideal=True, resolution=(24, 24), supersample=4,
                          cache_dir=tmp_path) as rig:
        hard, cov = rig.targets["right_wall"], rig.coverage["right_wall"]
        on, off = rig.truth.interactions_by_surface(hard, 3)
        np.testing.assert_allclose(on + off, rig.truth.interactions(hard, 3), rtol=1e-5, atol=1e-7)
    mixed = (cov > 0) & (cov < 1)
    assert (on[:, cov <= 0] == 0).all() and (off[1:, cov >= 1] == 0).all()  # off[0] keeps a lamp
    assert (on[1, mixed] > 0).all() and (off[1, mixed] > 0).all()  # an edge pixel has both parts


def test_shared_decodes_are_refilled_only_where_a_projector_pixel_is_one_camera_pixel():
    """At 1:1 a decode the neighbour shares is wrong and is refilled; under a coarser projector
    sharing is how the target's edge looks (one projector pixel straddles it) and is kept."""
    from engine.acquire.target import _drop_shared
    from engine.calibrate import Correspondence
    from engine.calibrate.graycode import PixelStatus

    h, w = 4, 6
    ys, xs = np.mgrid[0:h, 0:w]
    status = np.full((h, w), PixelStatus.DECODED, np.uint8)
    target = xs >= 3  # the right half; column 3 is its edge
    coarse = Correspondence(xs // 2, ys, status, (h, w // 2))  # projector column 1 lights camera columns 2 and 3
    np.testing.assert_array_equal(_drop_shared(coarse, target, 0).x, coarse.x)
    fine_x = xs.copy()
    fine_x[:, 3] = 2  # the edge column decoded onto the neighbour's projector column: wrong at 1:1
    fine = Correspondence(fine_x, ys, status, (h, w))
    dropped = _drop_shared(fine, target, 0)
    assert (dropped.x[:, 3] == -1).all() and (dropped.x[:, 4:] == xs[:, 4:]).all()


def test_the_stand_in_light_beyond_tau_is_emitted_in_a_capture_of_its_own():
    """Cutting the raised light at τ lost the stand-in where the edge is brightest (a concave corner)."""
    from engine.acquire.emission import Emitter
    from engine.calibrate import Correspondence
    from engine.calibrate.graycode import PixelStatus

    h, w = 4, 6
    ys, xs = np.mgrid[0:h, 0:w]
    corr = Correspondence(xs, ys, np.full((h, w), PixelStatus.DECODED, np.uint8), (h, w))
    direct = np.full((h, w, 3), 0.5, np.float32)
    target = xs >= 2
    wanted = np.where(target[:, :, None], np.float32([0.2, 0.25, 0.15]), 0).astype(np.float32)
    wanted[:, 2] *= 1.5  # the brightest column is the one next to the edge
    boost = np.where(xs == 2, 0.6, 0).astype(np.float32)  # ... and it stands in for the edge column 1
    emitter = Emitter(corr, direct, target, stand_in=boost)
    emissions, _ = emitter.emissions(wanted)
    assert sorted(em.name for em in emissions) == ["b", "b-over", "g", "g-over", "r", "r-over"]
    given = np.zeros((h, w, 3))
    for em in emissions:
        assert em.pattern.max() <= 1.0
        given[..., em.channels] += (direct * em.pattern[corr.y, corr.x])[..., em.channels] / em.scale
    np.testing.assert_allclose(given[target], ((1 + boost[:, :, None]) * wanted)[target], rtol=1e-5)  # none cut
    np.testing.assert_allclose((given + Emitter.shortfall(emissions))[target], wanted[target], rtol=1e-5, atol=1e-7)
    # raised light within 1 % of τ is cut (the projector's quantisation), at no capture
    assert len(Emitter(corr, direct, target, stand_in=boost * 0.01).emissions(wanted)[0]) == 3


def test_the_wall_with_its_edge_is_recolored_almost_as_well_as_its_interior(tmp_path):
    """Issue 13's edge rule against the truth at 48² (at 128² it holds within 1.5×: bench/optics.py)."""
    import cv2

    with calibrated_box(48, tmp_path) as (rig, rec, cal):
        cov, hard = rig.coverage["right_wall"], rig.targets["right_wall"]
        acq = acquire_single(rec, cal, cov, 4)
        d = acq.target.decompose(acq.observations)
        wall = cov > 0
        interior = cv2.erode((cov >= 1).astype(np.uint8), np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT) > 0
        ratio = {}
        for kappa in (KAPPA, np.array([2.0, 0.125, 8.0])):
            ours, truth = recolor(d, kappa), rig.truth.recolor([(hard, kappa)])
            ratio[kappa[2]] = relative_error(ours, truth, wall) / relative_error(ours, truth, interior)
    # measured at 48²: 1.95 and 2.96, the wall 0.14 % and 0.66 % (before D's corner bias was taken out,
    # prepare_target's pattern_bias: 1.74 and 2.23, the wall 0.24 % and 0.93 %: the interior gained more;
    # the edge's target part taken as what the neighbour's shares leave: 2.13 and 4.90); the rest is the
    # solid pixels beside the edge, whose stand-in is a pixel away
    assert ratio[0.8] < 2.1 and ratio[8.0] < 3.2, ratio
    # noise reduction (as κ_B = 8 needs on a real camera) leaves the blended edge pixels alone: filtered with
    # the neighbour's pixels they took its shares (measured at 48²: 1.26 kept, 3.87 filtered)
    assert d.blended is not None and d.blended.sum() == ((cov > 0) & (cov < 1)).sum()
    kappa = np.array([2.0, 0.125, 8.0])
    ours = recolor(denoise_components(d, acq.observations[0], radius=4), kappa)
    truth = rig.truth.recolor([(hard, kappa)])
    assert relative_error(ours, truth, wall) < 1.5 * relative_error(ours, truth, interior)
