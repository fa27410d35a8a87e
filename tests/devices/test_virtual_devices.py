"""Virtual rig: camera and projector models, geometry of the projector, caching."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from devices.base import Frame
from devices.virtual import open_rig
from devices.virtual.camera import CameraModel
from devices.virtual.projector import ProjectorModel
from devices.virtual.scene import SCENE_DIR
from engine.errors import InputError


@pytest.fixture(scope="session")
def cache(tmp_path_factory):
    """One set-up cache for the whole session (the same path in every virtual-rig test file)."""
    return tmp_path_factory.getbasetemp() / "virtual-cache"


# --- camera model -------------------------------------------------------------------------

def test_shot_and_read_noise_statistics_follow_the_sensor_model():
    model = CameraModel.realistic()
    rng = np.random.default_rng(0)
    levels = np.array([0.0, 0.05, 0.2, 0.6, 1.2])
    radiance = np.repeat(levels, 20000 * 3).reshape(len(levels), 20000, 3)
    t, g = 1 / 30, 1.0
    raw, sat = model.expose(radiance, t, g, rng)
    img = model.develop(raw, t, g).astype(np.float64)
    assert not sat.any()
    kt = model.electrons_per_radiance * t
    for k, level in enumerate(levels):
        mean, var = img[k].mean(), img[k].var()
        expected_var = level / kt + (model.read_noise / kt) ** 2 + (model.electrons_per_dn / kt) ** 2 / 12
        assert abs(mean - level) < 4 * np.sqrt(expected_var / img[k].size) + 1e-12
        assert var == pytest.approx(expected_var, rel=0.05)
    # photon noise dominates at high signal: variance grows linearly with the signal
    assert img[4].var() / img[3].var() == pytest.approx(1.2 / 0.6, rel=0.08)


def test_black_level_gain_and_exposure_scale_the_raw_values_not_the_image():
    model = CameraModel.realistic()
    rng = np.random.default_rng(1)
    dark, _ = model.expose(np.zeros((200, 200, 3)), 1 / 30, 1.0, rng)
    assert dark.mean() == pytest.approx(model.black_level, abs=0.1)
    assert np.all(dark == np.rint(dark))
    radiance = np.full((200, 200, 3), 0.3)
    means = {}
    for t, g in [(1 / 60, 1.0), (1 / 30, 1.0), (1 / 60, 2.0), (1 / 120, 4.0)]:
        raw, _ = model.expose(radiance, t, g, rng)
        assert (raw.mean() - model.black_level) == pytest.approx(0.3 * t * g * model.calibration, rel=0.01)
        means[(t, g)] = model.develop(raw, t, g).mean()
    for m in means.values():
        assert m == pytest.approx(0.3, rel=0.003)


def test_clipping_sets_the_saturation_mask():
    model = CameraModel.realistic()
    radiance = np.zeros((2, 2, 3))
    radiance[0, 0, 1] = 100.0  # far above full well at 1/30 s
    radiance[1, 1] = 0.1
    raw, sat = model.expose(radiance, 1 / 30, 1.0, np.random.default_rng(2))
    np.testing.assert_array_equal(sat, [[True, False], [False, False]])
    assert raw[0, 0, 1] <= model.white_level
    clip_radiance = model.develop(raw, 1 / 30, 1.0)[0, 0, 1]
    assert clip_radiance < 100.0  # a lower bound only
    # ADC clipping at high gain also counts
    raw, sat = model.expose(np.full((1, 1, 3), 1.4), 1 / 30, 8.0, np.random.default_rng(2))
    assert sat.all() and raw.max() == model.white_level


def test_ideal_camera_returns_the_radiance_exactly():
    model = CameraModel.perfect()
    radiance = np.random.default_rng(3).uniform(0, 50, (8, 8, 3)).astype(np.float32)
    raw, sat = model.expose(radiance, 1 / 1000, 3.0, None)
    assert not sat.any()
    np.testing.assert_allclose(model.develop(raw, 1 / 1000, 3.0), radiance, rtol=1e-6)


def test_rig_camera_frames_noise_seeding_and_settings(cache):
    rig = open_rig("wedge", resolution=(32, 32), cache_dir=cache, seed=7)
    rig.flood()
    f = rig.camera.capture()
    assert isinstance(f, Frame) and f.image.dtype == np.float32 and f.image.shape == (32, 32, 3)
    assert f.exposure == rig.camera.exposure and f.gain == 1.0 and f.black_level == 512.0
    assert f.metadata["device"] == "virtual:wedge" and f.metadata["ideal"] is False
    truth = rig.truth.photograph(ambient=False, pattern=np.ones(rig.projector.resolution + (3,), np.float32))
    # unbiased: the mean of many frames is the noise-free radiance (through the real projector model)
    frames = np.stack([rig.camera.capture().image for _ in range(24)]).astype(np.float64)
    lit = truth.mean(axis=-1) > 0.05
    rel = np.abs(frames.mean(axis=0) - truth)[lit] / truth[lit]
    assert np.median(rel) < 0.01
    assert frames.std(axis=0)[lit].mean() > 0  # noisy
    # seeded: the same seed reproduces the frames, another seed does not; global RNG untouched
    state = np.random.get_state()[1].copy()
    twin = open_rig("wedge", resolution=(32, 32), cache_dir=cache, seed=7)
    twin.flood()
    np.testing.assert_array_equal(twin.camera.capture().image, f.image)
    other = open_rig("wedge", resolution=(32, 32), cache_dir=cache, seed=8)
    other.flood()
    assert np.any(other.camera.capture().image != f.image)
    np.testing.assert_array_equal(np.random.get_state()[1], state)
    # settings are validated when set
    with pytest.raises(InputError, match=r"exposure must be a number of seconds in \(0, 3600\]"):
        rig.camera.exposure = 0
    with pytest.raises(InputError, match=r"gain must be a number in \[1, 1024\]"):
        rig.camera.gain = 0.5
    rig.camera.exposure, rig.camera.gain = 1 / 120, 2.0
    assert rig.camera.capture().exposure == 1 / 120


def test_exposure_changes_noise_not_the_image(cache):
    rig = open_rig("wedge", resolution=(48, 48), cache_dir=cache, seed=3)
    rig.flood()
    lit = rig.targets["union"]
    rig.camera.exposure = 1 / 30
    long = rig.camera.capture()
    rig.camera.exposure = 1 / 480
    short = rig.camera.capture()
    assert not long.saturated[lit].any()
    assert long.image[lit].mean() == pytest.approx(short.image[lit].mean(), rel=0.01)
    # the short exposure collects 16x fewer photons: 4x the noise
    truth = rig.truth.photograph(ambient=False, pattern=np.ones(rig.projector.resolution + (3,), np.float32))
    ratio = (short.image - truth)[lit].std() / (long.image - truth)[lit].std()
    assert ratio == pytest.approx(4.0, rel=0.15)
    # too long an exposure clips, and says so
    rig.camera.exposure = 1.0
    over = rig.camera.capture()
    assert over.saturated[lit].all()
    assert over.image[lit].mean() < 0.5 * long.image[lit].mean()


def test_saturated_pixels_of_the_rig(cache):
    rig = open_rig("cornell", resolution=(48, 48), cache_dir=cache)
    f = rig.camera.capture()
    m = rig.truth.camera_model
    full = m.full_well / (m.electrons_per_radiance * f.exposure)  # radiance that fills a pixel's well
    peak = rig.truth.photograph().max(axis=-1)
    light = peak > 1.1 * full  # the ceiling light itself (its edge pixels are mixed: partly lamp)
    assert light.any()
    assert f.saturated[light].all() and not f.saturated[peak < 0.9 * full].any()


# --- projector model ----------------------------------------------------------------------

def test_projector_response_gamma_black_level_quantisation_and_crosstalk():
    m = ProjectorModel.realistic()
    ramp = np.linspace(0, 1, 256, dtype=np.float32)
    img = np.stack([ramp, ramp, ramp], axis=-1)[None]  # (1, 256, 3)
    prim = m.primaries(img)[0].astype(np.float64)
    expected = m.black_level + (1 - m.black_level) * ramp[:, None].astype(np.float64) ** m.gamma
    np.testing.assert_allclose(prim, expected, rtol=1e-6)
    assert prim[0, 0] == pytest.approx(0.003)  # black level when showing 0
    # 8-bit quantisation: inputs within one level give the same light; 256 distinct outputs
    a = m.emit(np.full((1, 1, 3), 0.5, np.float32))
    b = m.emit(np.full((1, 1, 3), 0.5 + 0.4 / 255, np.float32))
    np.testing.assert_array_equal(a, b)
    fine = np.linspace(0, 1, 5000, dtype=np.float32)
    assert len(np.unique(m.primaries(np.stack([fine] * 3, -1))[:, 0])) == 256
    # crosstalk: pure red also lights the other camera channels
    red = m.emit(np.array([[[1.0, 0.0, 0.0]]], np.float32))[0, 0].astype(np.float64)
    p = np.array([1.0, m.black_level, m.black_level])
    np.testing.assert_allclose(red, m.crosstalk @ p, rtol=1e-6)
    assert red[1] > 0.03 and red[2] > 0.005


def test_ideal_projector_emits_its_input():
    m = ProjectorModel.perfect()
    x = np.random.default_rng(0).uniform(0, 1, (4, 5, 3)).astype(np.float32)
    np.testing.assert_array_equal(m.emit(x), x)
    np.testing.assert_array_equal(m.emit(np.zeros((2, 2, 3), np.float32)), 0)


@pytest.mark.parametrize("bad, message", [
    (np.full((16, 16, 3), 1.5, np.float32), r"image values must be in \[0, 1\].*max 1\.5"),
    (np.full((16, 16, 3), -0.1, np.float32), r"image values must be in \[0, 1\].*min -0\.1"),
    (np.zeros((16, 8, 3), np.float32), r"image must have shape \(16, 16, 3\)"),
    (np.zeros((16, 16), np.float32), r"image must have 3 dimensions"),
    (np.zeros((16, 16, 3), np.uint8), r"image must be a floating-point array"),
    (np.full((16, 16, 3), np.nan, np.float32), r"non-finite"),
])
def test_projector_refuses_bad_images(cache, bad, message):
    rig = open_rig("wedge", resolution=(16, 16), projector_resolution=(16, 16), cache_dir=cache, patch_size=0.3)
    with pytest.raises(InputError, match=message):
        rig.projector.show(bad)


def test_rig_projector_model_is_exposed_as_ground_truth(cache):
    real = open_rig("wedge", resolution=(16, 16), cache_dir=cache, patch_size=0.3)
    assert real.truth.projector_model is real.projector.model and not real.truth.projector_model.ideal
    np.testing.assert_allclose(real.truth.projector_model.gamma, [2.2, 2.25, 2.15])
    ideal = open_rig("wedge", ideal=True, resolution=(16, 16), cache_dir=cache, patch_size=0.3)
    assert ideal.truth.projector_model.ideal and ideal.truth.camera_model.ideal
    # projector black leaks light on a real rig, never on the ideal one
    assert real.truth.photograph(ambient=False).max() > 0
    assert ideal.truth.photograph(ambient=False).max() == 0


def test_close_leaves_the_projector_black(cache):
    with open_rig("wedge", resolution=(16, 16), cache_dir=cache, patch_size=0.3) as rig:
        rig.projector.show(np.ones(rig.projector.resolution + (3,), np.float32))
    assert rig.closed
    np.testing.assert_array_equal(rig.projector.image, 0)


# --- projector geometry ---------------------------------------------------------------------

def test_coaxial_correspondence_is_the_identity(cache):
    rig = open_rig("cornell", ideal=True, resolution=(48, 48), cache_dir=cache)
    xy, lit = rig.truth.correspondence()
    assert xy.dtype == np.float32 and lit.all()
    yy, xx = np.mgrid[0:48, 0:48]
    np.testing.assert_allclose(xy[..., 0], xx, atol=1e-3)
    np.testing.assert_allclose(xy[..., 1], yy, atol=1e-3)


def test_coaxial_projector_at_another_resolution(cache):
    rig = open_rig("cornell", ideal=True, resolution=(48, 48), projector_resolution=(24, 32), cache_dir=cache)
    assert rig.projector.resolution == (24, 32)
    xy, lit = rig.truth.correspondence()
    yy, xx = np.mgrid[0:48, 0:48]
    np.testing.assert_allclose(xy[..., 0], (xx + 0.5) * 32 / 48 - 0.5, atol=1e-3)
    np.testing.assert_allclose(xy[..., 1], (yy + 0.5) * 24 / 48 - 0.5, atol=1e-3)
    # lighting projector pixel (row 10, column 20) lights the camera pixels mapped to it
    p = np.zeros((24, 32, 3), np.float32)
    p[10, 20] = 1
    rig.ambient = False
    rig.projector.show(p)
    img = rig.camera.capture().image.sum(axis=-1)
    hit = (np.rint(xy[..., 0]) == 20) & (np.rint(xy[..., 1]) == 10)
    assert hit.sum() >= 2
    assert img[hit].min() > 20 * img[~hit].max()


def test_offset_projector_leaves_shadows(cache):
    rig = open_rig("cornell", ideal=True, resolution=(64, 64), projector="offset", cache_dir=cache)
    xy, lit = rig.truth.correspondence()
    surface = np.isfinite(xy[..., 0])
    assert surface.all()
    assert 0.6 < lit.mean() < 0.99  # boxes cast projector shadows
    assert np.all((xy[lit] >= -0.5) & (xy[lit] < 63.5))
    d = rig.truth.direct()
    assert np.all(d[~lit] == 0) and np.all(d[lit].max(axis=-1) > 0)
    # a flood lights exactly the lit pixels directly: shadowed pixels get indirect light only
    rig.ambient = False
    rig.projector.show(np.ones((64, 64, 3), np.float32))
    img = rig.camera.capture().image.mean(axis=-1)
    assert np.median(img[lit]) > 3 * np.median(img[~lit])
    # the correspondence is not the identity
    yy, xx = np.mgrid[0:64, 0:64]
    assert np.abs(xy[..., 0] - xx)[lit].mean() > 1


@pytest.mark.parametrize("projector", ["coaxial", "offset"])
def test_one_pixel_stripe_resolves(cache, projector):
    rig = open_rig("wedge", ideal=True, resolution=(64, 64), projector=projector, cache_dir=cache)
    xy, lit = rig.truth.correspondence()
    column = 30
    p = np.zeros((64, 64, 3), np.float32)
    p[:, column] = 1
    rig.projector.show(p)
    img = rig.camera.capture().image.mean(axis=-1) - rig.truth.photograph(ambient=True).mean(axis=-1)
    on = lit & (np.rint(xy[..., 0]) == column)
    off = lit & (np.abs(np.rint(xy[..., 0]) - column) >= 1)
    assert on.sum() >= 20
    assert img[on].min() > 10 * np.median(img[off])
    if projector == "coaxial":
        np.testing.assert_array_equal(on, lit & (np.arange(64) == column)[None, :])


def test_nayar_checkerboard_separates_the_direct_image(cache):
    """With 1-pixel checkers, max - min of two complementary shots is the direct image."""
    rig = open_rig("wedge", ideal=True, resolution=(64, 64), cache_dir=cache, ambient=False)
    yy, xx = np.mgrid[0:64, 0:64]
    checker = ((yy + xx) % 2).astype(np.float32)[..., None].repeat(3, axis=-1)
    shots = []
    for p in (checker, 1 - checker):
        rig.projector.show(p)
        shots.append(rig.camera.capture().image.astype(np.float64))
    direct = np.abs(shots[0] - shots[1])
    d = rig.truth.direct().astype(np.float64)
    lit = d.min(axis=-1) > 0
    rel = np.abs(direct - d)[lit] / d[lit]
    assert np.median(rel) < 0.02
    assert np.quantile(rel, 0.9) < 0.1


# --- caching --------------------------------------------------------------------------------

def test_setup_cache_is_reused_and_a_corrupt_cache_is_rebuilt(tmp_path):
    first = open_rig("wedge", ideal=True, resolution=(20, 24), cache_dir=tmp_path, patch_size=0.3)
    files = sorted(p.name for p in tmp_path.glob("*.npz"))
    assert len(files) == 2 and any("-ff-" in f for f in files)  # set-up + shared form factors
    again = open_rig("wedge", ideal=True, resolution=(20, 24), cache_dir=tmp_path, patch_size=0.3)
    np.testing.assert_array_equal(again.setup.gn, first.setup.gn)
    np.testing.assert_array_equal(again.truth.photograph(), first.truth.photograph())
    for p in tmp_path.glob("*.npz"):
        p.write_bytes(b"not a zip file")
    rebuilt = open_rig("wedge", ideal=True, resolution=(20, 24), cache_dir=tmp_path, patch_size=0.3)
    np.testing.assert_array_equal(rebuilt.truth.photograph(), first.truth.photograph())
    with np.load(next(tmp_path.glob("wedge-ff-*.npz")), allow_pickle=False) as z:
        assert "gn" in z
    # another resolution reuses the form factors (same file set plus one set-up)
    open_rig("wedge", ideal=True, resolution=(16, 16), cache_dir=tmp_path, patch_size=0.3)
    assert len(list(tmp_path.glob("*.npz"))) == 3
    assert not list(tmp_path.glob("*.tmp"))


def test_no_cache_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    open_rig("wedge", ideal=True, resolution=(16, 16), cache_dir=False, patch_size=0.3)
    assert not (tmp_path / "xdg").exists()
    open_rig("wedge", ideal=True, resolution=(16, 16), patch_size=0.3)
    assert list((tmp_path / "xdg" / "albedit" / "virtual").glob("*.npz"))


def test_cache_files_stay_inside_the_cache_dir(tmp_path):
    data = json.loads((SCENE_DIR / "wedge.json").read_text())
    data["name"] = "../../escape"
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps(data))
    open_rig(str(scene), resolution=(8, 8), cache_dir=tmp_path / "cache", patch_size=0.4)
    written = [p for p in tmp_path.rglob("*.npz")]
    assert len(written) == 2 and all(p.parent == tmp_path / "cache" for p in written)


def test_emitters_are_the_pixels_that_see_the_lamp(cache):
    with open_rig("cornell", ideal=True, resolution=(48, 48), cache_dir=cache) as rig:
        lamp = rig.truth.emitters()
        photo = rig.truth.photograph().max(axis=-1)
        assert 0 < lamp.sum() < 0.05 * lamp.size
        assert photo[lamp].min() > 2 * photo[~lamp].max()  # brighter than any lit surface
    with open_rig("wedge", ideal=True, resolution=(32, 32), cache_dir=cache) as rig:
        assert not rig.truth.emitters().any()  # the wedge is lit by the projector's flood only


def test_setup_cache_written_by_other_code_is_never_read(tmp_path, monkeypatch):
    """A cache is keyed by the rig's source, not a version number a revert could bring back."""
    import devices.virtual.setup as setup_module
    from devices._common import source_digest

    assert setup_module.MODEL_DIGEST == source_digest(Path(setup_module.__file__).parent)
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "a.py").write_text("x = 1\n")
    before = source_digest(tmp_path / "pkg")
    (tmp_path / "pkg" / "a.py").write_text("x = 2\n")
    assert source_digest(tmp_path / "pkg") != before
    cache = tmp_path / "cache"
    open_rig("wedge", ideal=True, resolution=(16, 16), cache_dir=cache, patch_size=0.3)
    assert len(list(cache.glob("*.npz"))) == 2
    monkeypatch.setattr(setup_module, "MODEL_DIGEST", "0" * 16)  # other code: its own files
    open_rig("wedge", ideal=True, resolution=(16, 16), cache_dir=cache, patch_size=0.3)
    assert len(list(cache.glob("*.npz"))) == 4
