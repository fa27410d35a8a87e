import numpy as np
import pytest

from engine.decompose import Decomposition, decompose
from engine.errors import InputError
from engine.recolor import prepare_preview, recolor, recolor_preview


def _naive(d, kappa):
    kappa = np.broadcast_to(np.asarray(kappa, np.float64), (d.components.shape[-1],))
    out = d.unreached.astype(np.float64).copy()
    for i in range(d.order):
        out += kappa ** (i + 1) * d.components[i]
    return out


@pytest.mark.parametrize("kappa", [0.0, 0.1, 1.0, 2.0, (2.0, 0.125, 8.0)])
@pytest.mark.parametrize("shape", [(1, 1, 3), (37, 53, 3), (300, 200, 1)])
def test_horner_matches_the_naive_sum(kappa, shape):
    rng = np.random.default_rng(0)
    k = 5
    d = Decomposition(
        rng.random((k,) + shape, dtype=np.float32),
        rng.random(shape, dtype=np.float32),
        rng.random(shape[:2]) > 0.5,
    )
    if shape[-1] == 1 and np.ndim(kappa):
        kappa = kappa[0]
    out = recolor(d, kappa)
    assert out.dtype == np.float32 and out.shape == shape
    ref = _naive(d, kappa)
    np.testing.assert_allclose(out, ref, rtol=2e-6, atol=1e-6 * ref.max())


def test_kappa_one_reproduces_the_photograph(stack):
    obs, *_, target = stack(4, seed=4)
    d = decompose(obs, target)
    np.testing.assert_allclose(recolor(d, 1.0), obs[0], rtol=1e-5, atol=1e-6)


def test_kappa_zero_leaves_only_unreached_light(stack):
    obs, inside, outside, unreached, target = stack(3, seed=6)
    d = decompose(obs, target)
    out = recolor(d, 0.0)
    assert not out[target].any()
    np.testing.assert_allclose(out[~target], unreached[~target], atol=1e-5)


def test_preview_is_the_area_average_of_the_full_recolor():
    rng = np.random.default_rng(3)
    k, h, w = 4, 97, 130
    d = Decomposition(rng.random((k, h, w, 3), dtype=np.float32), rng.random((h, w, 3), dtype=np.float32),
                      rng.random((h, w)) > 0.3)
    kappa = np.array([0.5, 1.5, 3.0])
    pack = prepare_preview(d, (40, 40))
    small = recolor_preview(pack, kappa)
    # factor 4 = ceil(130 / 40)
    assert small.shape == (25, 33, 3) and pack.scale[0] == pytest.approx(97 / 25)
    full = recolor(d, kappa)
    np.testing.assert_allclose(small[3, 5], full[12:16, 20:24].mean(axis=(0, 1)), rtol=1e-5)
    # the ragged last block averages only the pixels that exist
    np.testing.assert_allclose(small[-1, -1], full[96:, 128:].mean(axis=(0, 1)), rtol=1e-5)
    assert prepare_preview(d, (500, 500)).decomposition is d


def test_recoloring_a_crop_is_cropping_the_recolor():
    rng = np.random.default_rng(5)
    k, h, w = 3, 40, 50
    d = Decomposition(rng.random((k, h, w, 3), dtype=np.float32), rng.random((h, w, 3), dtype=np.float32),
                      rng.random((h, w)) > 0.5, residual=rng.random((h, w), dtype=np.float32))
    crop = d.crop(7, 31, 12, 13)
    assert np.shares_memory(crop.components, d.components)  # a view: the detail preview copies nothing twice
    np.testing.assert_array_equal(crop.residual, d.residual[7:31, 12:13])
    np.testing.assert_array_equal(recolor(crop, (0.3, 2.0, 5.0)), recolor(d, (0.3, 2.0, 5.0))[7:31, 12:13])


@pytest.mark.parametrize(
    "kappa, match",
    [(-1.0, "non-negative"), ((1.0, 2.0), "one value per channel"), (np.nan, "finite"), ((1, 1, -0.1), "non-negative")],
)
def test_bad_kappa(kappa, match):
    d = Decomposition(np.ones((2, 2, 2, 3), np.float32), np.zeros((2, 2, 3), np.float32), np.eye(2, dtype=bool))
    with pytest.raises(InputError, match=match):
        recolor(d, kappa)


def test_bad_arguments():
    with pytest.raises(InputError, match="Decomposition"):
        recolor(np.ones((2, 2, 3)), 1.0)
    d = Decomposition(np.ones((2, 2, 2, 3), np.float32), np.zeros((2, 2, 3), np.float32), np.eye(2, dtype=bool))
    with pytest.raises(InputError, match="shape"):
        prepare_preview(d, (0, 10))
