"""The path-traced rig (``mitsuba:``): protocols, radiometry against the virtual rig, truth per shape.

Renders are tiny (16²–32², a few dozen samples per pixel) so the module runs in seconds.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest
from scipy.ndimage import binary_erosion

import devices
from devices.mitsuba.scene import check_coat, coated
from engine.acquire.predict import relative_error
from engine.errors import InputError

mi = pytest.importorskip("mitsuba", reason="the mitsuba extra is not installed: pip install 'albedit[mitsuba]'")

SMALL = dict(resolution=(24, 24), spp=32, ambient_spp=64, truth_spp=64, coverage_passes=32, cache_dir=False)


@pytest.fixture(scope="module")
def rig():
    with devices.open_rig("mitsuba:cornell", ideal=True, **SMALL) as r:
        yield r


@pytest.fixture(scope="module")
def virtual():
    with devices.open_rig("virtual:cornell", ideal=True, resolution=(24, 24), cache_dir=False) as r:
        yield r


def test_rig_implements_the_protocols_and_records_spp(rig):
    assert isinstance(rig.camera, devices.Camera) and isinstance(rig.projector, devices.Projector)
    frame = rig.camera.capture()
    assert frame.image.shape == (24, 24, 3) and frame.image.dtype == np.float32
    assert frame.metadata["spp"] == 32 and frame.metadata["ambient_spp"] == 64
    assert rig.projector.resolution == (24, 24)


def test_targets_and_coverage_follow_the_virtual_geometry(rig, virtual):
    for name in ("right_wall", "left_wall"):
        ours, theirs = rig.targets[name], virtual.targets[name]
        iou = (ours & theirs).sum() / (ours | theirs).sum()
        assert iou > 0.85, (name, iou)
    cov = rig.coverage["right_wall"]
    assert cov.dtype == np.float32 and cov.min() >= 0 and cov.max() <= 1
    edge = (cov > 0) & (cov < 1)
    assert edge.any() and (edge & ~rig.targets["right_wall"]).any()  # mixed pixels, as on a sensor
    lamp = rig.truth.emitters()
    assert lamp.any() and not (virtual.truth.emitters() & ~lamp).any()


def test_radiometry_matches_the_virtual_rig_on_direct_light(rig, virtual):
    """Same projector power, same albedo: the direct image agrees pixel for pixel (interior)."""
    d_mi = rig.truth.direct()
    d_v = virtual.truth.direct()
    solid = np.zeros_like(rig.targets["right_wall"])
    for name in ("right_wall", "left_wall"):
        solid |= (rig.coverage[name] == 1) & virtual.targets[name]
    ratio = np.median(d_mi[solid] / d_v[solid], axis=0)
    np.testing.assert_allclose(ratio, 1.0, atol=0.03)


def test_coaxial_projector_lights_the_same_camera_pixels(rig):
    rig.ambient = False
    try:
        pattern = np.zeros((24, 24, 3), np.float32)
        pattern[6:10, 14:18] = 1.0
        rig.projector.show(pattern)
        lit = rig.camera.capture().image.sum(axis=-1)
    finally:
        rig.ambient = True
        rig.blank()
    assert lit[6:10, 14:18].min() > 5 * np.median(lit)
    ys, xs = np.unravel_index(np.argsort(lit, axis=None)[-16:], lit.shape)
    assert set(ys) <= set(range(6, 10)) and set(xs) <= set(range(14, 18))


def test_captures_draw_new_noise_and_add_the_cached_ambient_light(rig):
    rig.projector.show(np.full((24, 24, 3), 0.5, np.float32))
    a, b = rig.camera.capture().image, rig.camera.capture().image
    rig.blank()
    dark = rig.camera.capture().image
    assert not np.array_equal(a, b)
    np.testing.assert_array_equal(dark, rig.renderer.ambient_image())
    assert abs(float(a.mean() / b.mean()) - 1) < 0.05


def test_truth_recolors_shapes_including_their_mixed_pixels(rig):
    mask = rig.targets["right_wall"]
    kappa = np.array([2.0, 0.125, 8.0])
    photo = rig.truth.photograph()
    truth = rig.truth.recolor([(mask, kappa)])
    cov = rig.coverage["right_wall"]
    solid = cov == 1
    ratio = np.median(truth[solid] / photo[solid], axis=0)
    assert ratio[1] < 0.3 and ratio[2] > 4  # green wall → blue
    edge = (cov > 0.2) & (cov < 0.8) & ~mask  # unpainted edge pixels still change (the truth is per shape)
    assert edge.any()
    assert np.median(truth[edge][:, 2] / photo[edge][:, 2]) > 1.5
    assert rig.truth.shapes_of(mask) == ["right_wall"]
    with pytest.raises(InputError, match="covers no shape"):
        rig.truth.recolor([(np.zeros_like(mask), 2.0)])


def test_truth_components_sum_to_the_recolor_truth(rig):
    mask = rig.targets["right_wall"]
    kappa = np.array([0.5, 1.5, 2.0])
    c = rig.truth.components(mask, 4)
    assert c.inside.shape == (4, 24, 24, 3) and c.order == 4
    assert not c.inside[:, ~mask].any() and not c.outside[:, mask].any() and not c.unreached[mask].any()
    wall = binary_erosion(mask, np.ones((3, 3), bool))
    first, second = c.inside[0][wall].sum(), c.inside[1][wall].sum()
    assert 0.01 * first < second < 0.5 * first  # a flat wall lights itself only through the others
    comps = c.inside + c.outside
    ours = c.unreached + sum(kappa.astype(np.float32) ** (i + 1) * comps[i] for i in range(4))
    truth = rig.truth.recolor([(mask, kappa)])
    floor = relative_error(rig.truth.recolor([(mask, kappa)]), truth)
    assert relative_error(ours, truth) < 1.5 * floor + 0.01, (relative_error(ours, truth), floor)
    assert relative_error(c.unreached + comps.sum(0), rig.truth.photograph()) < 1.5 * floor + 0.01
    with pytest.raises(InputError, match="covers no shape"):
        rig.truth.components(np.zeros_like(mask), 3)


@pytest.mark.parametrize("tint", ["white", "albedo"])
def test_truth_repaints_under_a_glossy_coat_or_scales_every_interaction(tint):
    with devices.open_rig("mitsuba:wedge", ideal=True, specular=0.3, roughness=0.3, tint=tint, **SMALL) as r:
        r.flood()
        flood = r.projector.image
        left = r.targets["left"]
        solid = binary_erosion(r.coverage["left"] == 1, np.ones((3, 3), bool))  # wholly wall, surely
        assert solid.sum() > 20
        paint = r.truth.recolor([(left, 0.0)], ambient=False, pattern=flood)
        every = r.truth.recolor([(left, 0.0)], ambient=False, pattern=flood, coat=True)
        photo = r.truth.photograph(ambient=False, pattern=flood)
        # black paint under the coat: the wall keeps its gloss (a share of its light, from the right wall)
        share = paint[solid].mean() / photo[solid].mean()
        assert 0.05 < share < 0.6, share
        assert not every[solid].any()  # no reflection off the wall at all: every path through it is gone
        assert np.median(every[~left & (photo.sum(-1) > 0)].sum(-1) / photo[~left & (photo.sum(-1) > 0)].sum(-1)) < 1
        with pytest.raises(InputError, match="coat must be True or False"):
            r.truth.recolor([(left, 2.0)], coat="yes")


def test_a_scene_lit_by_the_projector_alone_has_a_black_ambient_image():
    with devices.open_rig("mitsuba:floor", ideal=True, **SMALL) as r:
        assert not r.renderer.ambient_image().any()
        r.flood()
        assert r.camera.capture().image.mean() > 0


def test_ambient_render_is_cached_on_disk(tmp_path):
    opts = dict(SMALL, cache_dir=tmp_path, resolution=(12, 12))
    with devices.open_rig("mitsuba:cornell", ideal=True, **opts) as r1:
        first = r1.renderer.ambient_image()
    with devices.open_rig("mitsuba:cornell", ideal=True, **opts) as r2:
        again = r2.renderer.ambient_image()
        assert r2.renderer.renders == 0
    np.testing.assert_array_equal(first, again)
    assert len(list(tmp_path.glob("cornell-ambient-*.npy"))) == 1


def test_glossy_coat_is_a_parameter_and_bad_options_are_named():
    with devices.open_rig("mitsuba:wedge", ideal=True, specular=0.2, roughness=0.05, **SMALL) as r:
        assert r.renderer.materials == {"left_wall": {"specular": 0.2, "roughness": 0.05}}
        assert r.targets["left"].any()
    with pytest.raises(InputError, match="specular must be in"):
        devices.open_rig("mitsuba:wedge", specular=1.5, **SMALL)
    with pytest.raises(InputError, match="needs a rig scene with a glossy coat"):
        devices.open_rig("mitsuba:cornell", specular=0.1, **SMALL)
    with pytest.raises(InputError, match="unknown mitsuba rig option"):
        devices.open_rig("mitsuba:cornell", spp_per_pixel=3)
    with pytest.raises(InputError, match="unknown mitsuba rig scene"):
        devices.open_rig("mitsuba:nowhere")


def test_a_tinted_coat_reflects_the_paints_colour_and_bad_tints_are_named(tmp_path):
    paint = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.6, 0.2, 0.6]}}
    white = coated(paint, check_coat({"specular": 0.1, "roughness": 0.05}, "c"))
    tinted = coated(paint, check_coat({"specular": 0.1, "roughness": 0.05, "tint": "albedo"}, "c"))
    assert white["specular"]["specular_reflectance"]["value"] == [1.0, 1.0, 1.0]
    assert tinted["specular"]["specular_reflectance"]["value"] == [0.6, 0.2, 0.6]
    assert tinted["weight"] == 0.1 and tinted["diffuse"] == paint
    default = {"specular": 0.1, "roughness": 0.05}
    assert check_coat(dict(default, tint="white"), "c") == default  # the default tint is not spelt out
    with pytest.raises(InputError, match=r"c\.tint must be one of \['white', 'albedo'\], got 'gold'"):
        check_coat({"specular": 0.1, "roughness": 0.05, "tint": "gold"}, "c")
    with pytest.raises(InputError, match="tint must be one of"):
        devices.open_rig("mitsuba:wedge", tint="paint", **SMALL)
    with pytest.raises(InputError, match="optional 'tint'"):
        check_coat({"specular": 0.1, "roughness": 0.05, "shine": 1}, "c")
    (tmp_path / "checker.json").write_text(
        '{"scene": "virtual:textured", "materials": {"checker_wall": {"specular": 0.1, "roughness": 0.1, '
        '"tint": "albedo"}}}'
    )
    with pytest.raises(InputError, match=r"materials\['checker_wall'\]: tint 'albedo' needs a uniform diffuse colour"):
        devices.open_rig(f"mitsuba:{tmp_path / 'checker.json'}", **SMALL)


def test_a_tinted_coat_leaves_the_walls_colour_that_of_its_paint():
    """Direct light only (max_depth 2): a coat tinted like the paint reflects each channel in
    proportion to the paint's albedo, so the image over the albedo is grey; a white coat is not."""
    rho = np.array([0.6, 0.2, 0.6])
    grey = {}
    for tint in ("albedo", "white"):
        opts = dict(SMALL, resolution=(12, 12), max_depth=2)
        with devices.open_rig("mitsuba:wedge", ideal=True, specular=0.5, roughness=1.0, tint=tint, **opts) as r:
            r.flood()
            img = r.truth.photograph(ambient=False, pattern=r.projector.image)
            wall = (r.coverage["left"] == 1) & (img.sum(-1) > 0)
            assert wall.sum() > 10
            per = img[wall] / rho
            grey[tint] = np.abs(per / per.mean(-1, keepdims=True) - 1).max()
    assert grey["albedo"] < 1e-4, grey  # the same paths carry all three channels
    assert grey["white"] > 0.1, grey


def test_any_mitsuba_xml_scene_with_a_targets_file(tmp_path):
    (tmp_path / "box.xml").write_text("""<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="50"/>
    <transform name="to_world"><lookat origin="0,0,-3" target="0,0,0" up="0,1,0"/></transform></sensor>
  <shape type="rectangle" id="wall"><bsdf type="diffuse"><rgb name="reflectance" value="0.2,0.6,0.3"/></bsdf></shape>
  <shape type="rectangle" id="floor">
    <transform name="to_world"><rotate x="1" angle="-90"/><translate y="-1" z="-1"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.7"/></bsdf></shape>
  <emitter type="point"><point name="position" x="0" y="2" z="-2"/><rgb name="intensity" value="5"/></emitter>
</scene>""")
    (tmp_path / "box.json").write_text('{"scene": "box.xml", "targets": {"wall": ["wall"]}}')
    with devices.open_rig(f"mitsuba:{tmp_path / 'box.json'}", ideal=True, **SMALL) as r:
        assert r.targets["wall"].sum() > 50
        lamp_only = r.camera.capture().image
        r.ambient = False
        assert r.camera.capture().image.max() == 0  # the point light is the only ambient light
        r.ambient = True
        r.projector.show(np.ones((24, 24, 3), np.float32))
        assert r.camera.capture().image.mean() > lamp_only.mean()
    (tmp_path / "bad.json").write_text('{"scene": "box.xml", "targets": {"wall": ["nope"]}}')
    with pytest.raises(InputError, match="not in"):
        devices.open_rig(f"mitsuba:{tmp_path / 'bad.json'}", **SMALL)
    # a coat named for an XML scene would not be applied: refused, not ignored
    (tmp_path / "coat.json").write_text('{"scene": "box.xml", "targets": {"wall": ["wall"]}, '
                                        '"materials": {"wall": {"specular": 0.1, "roughness": 0.05}}}')
    with pytest.raises(InputError, match="apply to virtual: scenes only"):
        devices.open_rig(f"mitsuba:{tmp_path / 'coat.json'}", **SMALL)


def test_available_lists_the_rig_or_says_how_to_install_it(monkeypatch):
    names = {a.name: a for a in devices.available()}
    assert names["mitsuba:cornell"].ok
    monkeypatch.setitem(sys.modules, "mitsuba", None)
    from devices import mitsuba as backend

    (entry,) = backend.probe()
    assert not entry.ok and "pip install 'albedit[mitsuba]'" in entry.reason
