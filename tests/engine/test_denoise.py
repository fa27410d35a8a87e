import numpy as np
import pytest

from engine.decompose import Decomposition, decompose, observe
from engine.denoise import denoise_components
from engine.errors import InputError
from engine.recolor import recolor


def _scene(seed=0, noise=0.005, constraint="none"):
    """Textured surfaces lit by smooth interreflections; noisy observations through Eq. 6/9."""
    rng = np.random.default_rng(seed)
    h, w = 64, 80
    yy, xx = np.mgrid[0:h, 0:w] / 64.0
    albedo = np.where((xx * 4).astype(int) % 2 == 0, 0.7, 0.25)[:, :, None] * np.array([1.0, 0.8, 0.6])
    target = xx > 0.6
    irr = [np.exp(-0.5 * ((xx - 0.5) ** 2 + (yy - 0.4) ** 2) / 0.3) * 0.4**i for i in range(4)]
    clean = np.stack([albedo * irr_i[:, :, None] for irr_i in irr]).astype(np.float32)
    unreached = np.where(target[:, :, None], 0, albedo * 0.5).astype(np.float32)
    truth = Decomposition(clean, unreached, target)
    obs = observe(truth)
    obs += rng.normal(0, noise, obs.shape).astype(np.float32) * obs.max(axis=(1, 2, 3), keepdims=True)
    return truth, decompose(obs, target, constraint=constraint), obs[0]


@pytest.mark.parametrize("constraint, gain", [("none", 0.5), ("ordered", 1.0)])
def test_denoising_removes_noise_and_keeps_the_photograph(constraint, gain):
    # measured: unconstrained 17.0 % -> 4.7 % (kappa (2, .5, 3)) and 31.9 % -> 11.1 % (kappa 4);
    # the ordered constraint already removes much of the noise, denoising still helps a little
    truth, noisy, photo = _scene(constraint=constraint)
    out = denoise_components(noisy, photo)
    for kappa in (np.array([2.0, 0.5, 3.0]), 4.0):
        reference = recolor(truth, kappa)
        before = np.linalg.norm(recolor(noisy, kappa) - reference)
        after = np.linalg.norm(recolor(out, kappa) - reference)
        assert after < gain * before, (kappa, before, after)
    # the per-pixel sum is unchanged: recolor at kappa = 1 is the same image
    np.testing.assert_allclose(recolor(out, 1.0), recolor(noisy, 1.0), atol=1e-5)
    # texture survives: the albedo edges are still sharp in the denoised first interaction
    col = out.components[1, 20, :48, 0]
    assert np.abs(np.diff(col)).max() > 0.5 * np.abs(np.diff(truth.components[1, 20, :48, 0])).max()


def test_projector_only_decompositions_keep_their_sum():
    truth, noisy, photo = _scene(1)
    d = Decomposition(noisy.components, np.zeros_like(noisy.unreached), noisy.target, unreached_light=False)
    out = denoise_components(d, photo)
    np.testing.assert_allclose(recolor(out, 1.0), recolor(d, 1.0), atol=1e-5)
    assert not out.unreached.any()


def test_bad_arguments():
    truth, d, photo = _scene()
    with pytest.raises(InputError, match="shape"):
        denoise_components(d, photo[:10])
    with pytest.raises(InputError, match="radius"):
        denoise_components(d, photo, radius=0)
    with pytest.raises(InputError, match="Decomposition"):
        denoise_components(d.components, photo)


def test_progress_and_cancel_leave_the_input_alone():
    from engine.errors import Cancelled

    truth, d, photo = _scene(2)
    before = d.components.copy()
    steps = []
    denoise_components(d, photo, progress=lambda i, n, msg: steps.append((i, n)))
    assert steps[0] == (0, 6) and steps[-1] == (6, 6)  # inside and outside × 3 channels
    with pytest.raises(Cancelled):
        denoise_components(d, photo, should_stop=lambda: True)
    np.testing.assert_array_equal(d.components, before)


def test_small_target_is_filtered_in_its_window_exactly_as_in_the_whole_image():
    truth, d, photo = _scene(4)
    small = np.zeros_like(d.target)
    small[20:30, 50:60] = True
    sub = Decomposition(d.components, np.where(small[:, :, None], 0, d.unreached), small)
    out = denoise_components(sub, photo, radius=3)
    # the same target in a larger canvas of zeros (its window then sits inside the image)
    def pad(a, axes):
        return np.pad(a, [(0, 0)] * axes[0] + [(8, 8), (8, 8)] + [(0, 0)] * axes[1], mode="edge")

    big = Decomposition(pad(sub.components, (1, 1)), pad(sub.unreached, (0, 1)), pad(small, (0, 0)))
    out_big = denoise_components(big, pad(photo, (0, 1)), radius=3)
    np.testing.assert_allclose(out_big.components[:, 8:-8, 8:-8][:, small], out.components[:, small],
                               rtol=1e-5, atol=1e-6)


def test_blended_edge_pixels_are_neither_filtered_nor_read():
    """A soft mask's blended edge pixels pack two surfaces' parts in other slots than their neighbours'."""
    from dataclasses import replace

    truth, noisy, photo = _scene(2)
    edge = np.zeros(noisy.target.shape, bool)
    edge[:, 38] = True  # the column beside the target (columns 39.. here)
    assert not (edge & noisy.target).any()
    spiked = noisy.components.copy()
    spiked[:, edge] *= 50.0  # packed otherwise: nothing like the neighbour's components
    d = replace(noisy, components=spiked, blended=edge)
    out = denoise_components(d, photo)
    np.testing.assert_array_equal(out.components[:, edge], spiked[:, edge])
    np.testing.assert_array_equal(out.unreached[edge], d.unreached[edge])
    np.testing.assert_array_equal(out.blended, edge)
    clean = denoise_components(replace(noisy, blended=edge), photo)  # the spikes never leak into other pixels
    np.testing.assert_allclose(out.components[:, ~edge], clean.components[:, ~edge], rtol=1e-5, atol=1e-6)
