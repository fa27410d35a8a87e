"""Unreachable target pixels estimated from their reachable neighbours (engine.fill)."""

import numpy as np
import pytest

import devices
from engine.decompose import Decomposition, decompose, observe
from engine.errors import InputError
from engine.fill import fill_unreachable
from engine.recolor import recolor
from engine.session import Session
from engine.workflow import load_decomposition, run_calibration, run_capture


def _scene(h=40, w=50, k=4):
    """Textured target, smooth shares of light per interaction order, exact observations."""
    yy, xx = np.mgrid[0:h, 0:w] / 40.0
    albedo = np.where(((xx * 10).astype(int) + (yy * 10).astype(int)) % 2 == 0, 0.7, 0.3)[:, :, None] * [1.0, 0.8, 0.5]
    irradiance = 1.0 + 0.5 * np.sin(xx * 2)[:, :, None]
    share = np.stack([(0.5 + 0.1 * yy) * 0.45**i for i in range(k)])[..., None]  # smooth in space
    target = xx > 0.5
    comps = (share * (albedo * irradiance)[None]).astype(np.float32)
    unreached = np.where(target[:, :, None], 0, albedo * 0.3).astype(np.float32)
    return Decomposition(comps, unreached, target)


def test_holes_take_their_neighbours_shares_and_keep_the_photograph():
    truth = _scene()
    obs = observe(truth)
    holes = np.zeros_like(truth.target)
    holes[10:12, 30:32] = True  # a small cluster
    holes[25, 40] = True  # a speckle
    holes[:, -1] = True  # a rim along the image edge
    reach = truth.target & ~holes
    measured = decompose(obs, reach)
    d, filled = fill_unreachable(measured, truth.target, obs[0], radius=3)
    np.testing.assert_array_equal(filled, holes)
    np.testing.assert_array_equal(d.target, truth.target)
    assert not d.unreached[holes].any()
    np.testing.assert_allclose(recolor(d, 1.0), obs[0], rtol=1e-5, atol=1e-6)  # κ = 1: the photograph
    kappa = np.array([2.0, 0.5, 3.0])
    expected = recolor(truth, kappa)
    before = np.linalg.norm((recolor(measured, kappa) - expected)[holes]) / np.linalg.norm(expected[holes])
    after = np.linalg.norm((recolor(d, kappa) - expected)[holes]) / np.linalg.norm(expected[holes])
    assert before > 0.05 and after < 0.001, (before, after)  # the texture is kept: shares, not values, are shared
    untouched = ~holes
    np.testing.assert_array_equal(d.components[:, untouched], measured.components[:, untouched])


def test_holes_farther_than_the_radius_stay_out():
    truth = _scene()
    obs = observe(truth)
    holes = np.zeros_like(truth.target)
    holes[5:25, 30:45] = True  # a large shadow
    measured = decompose(obs, truth.target & ~holes)
    d, filled = fill_unreachable(measured, truth.target, obs[0], radius=2)
    assert filled.any() and not filled[9:21, 34:41].any()  # its core is > 2 px from any reachable pixel
    np.testing.assert_array_equal(d.target, (truth.target & ~holes) | filled)
    same, none = fill_unreachable(measured, truth.target & ~holes, obs[0])
    assert same is measured and not none.any()


def test_bad_input():
    truth = _scene()
    obs = observe(truth)
    with pytest.raises(InputError, match="painted must contain"):
        fill_unreachable(truth, np.zeros_like(truth.target), obs[0])
    with pytest.raises(InputError, match="photograph must have"):
        fill_unreachable(truth, truth.target, obs[0][:5])
    with pytest.raises(InputError, match="radius"):
        fill_unreachable(truth, truth.target, obs[0], radius=-1)
    with pytest.raises(InputError, match="Decomposition"):
        fill_unreachable(truth.components, truth.target, obs[0])


def test_offset_rig_capture_fills_what_the_projector_misses(tmp_path_factory, tmp_path):
    cache = tmp_path_factory.getbasetemp() / "fill-rig-cache"
    with devices.open_rig("virtual:cornell", ideal=True, projector="offset", resolution=(64, 64), seed=0,
                          cache_dir=cache) as rig:
        session = Session.create(tmp_path / "s", rig_name=rig.identity, camera_resolution=rig.camera.resolution,
                                 projector_resolution=rig.projector.resolution)
        run_calibration(rig, session)
        mask = rig.targets["right_wall"]
        result = run_capture(rig, session, [("right_wall", mask)], 4)
        kappa = np.array([2.0, 0.125, 8.0])
        truth = rig.truth.recolor([(mask, kappa)])
    d = load_decomposition(session)
    emittable = result.targets[-1][1].mask
    filled = d.target & ~emittable
    assert filled.any() and session.state["result"]["estimated"] == int(filled.sum())
    measured = decompose(result.acquisition.observations, emittable)
    err = lambda img: np.linalg.norm((img - truth)[filled]) / np.linalg.norm(truth[filled])  # noqa: E731
    assert err(recolor(d, kappa)) < 0.5 * err(recolor(measured, kappa))
