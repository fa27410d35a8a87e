"""Virtual rig: scene files, their validation, rig options and the registry route."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

import devices
from devices.virtual import open_rig, probe
from devices.virtual.scene import SCENE_DIR, load_scene, parse_scene, scene_names
from engine.errors import InputError


@pytest.fixture(scope="session")
def cache(tmp_path_factory):
    """One set-up cache for the whole session (the same path in every virtual-rig test file)."""
    return tmp_path_factory.getbasetemp() / "virtual-cache"


@pytest.fixture
def wedge_json():
    return json.loads((SCENE_DIR / "wedge.json").read_text())


def test_shipped_scenes_load_with_their_targets():
    assert {"cornell", "wedge", "three"} <= set(scene_names())
    cornell = load_scene("cornell")
    right = cornell.names.index("right_wall")
    np.testing.assert_array_equal(cornell.albedo[right], [0.1, 0.8, 0.1])
    assert cornell.targets["right_wall"] == [(right, (0.0, 0.0, 1.0, 1.0))]
    assert np.any(cornell.emission > 0)  # a ceiling light
    wedge = load_scene("wedge")
    np.testing.assert_array_equal(wedge.albedo[wedge.names.index("left_wall")], [0.6, 0.2, 0.6])
    np.testing.assert_array_equal(wedge.albedo[wedge.names.index("right_wall")], [0.4, 0.7, 0.8])
    assert sorted(wedge.targets) == ["left", "right", "union"]
    assert wedge.lighting == {"ambient": False, "projector_flood": 1.0}
    three = load_scene("three")
    assert sorted(three.targets) == ["beige", "blue", "red"]
    # red and blue are coplanar, beige is on another plane
    n = three.quads.normal
    red, blue, beige = (three.names.index(k) for k in ("red", "blue", "beige"))
    np.testing.assert_allclose(n[red], n[blue])
    assert abs(np.dot(three.quads.origin[blue] - three.quads.origin[red], n[red])) < 1e-12
    assert abs(np.dot(n[red], n[beige])) < 0.99


def test_every_scene_albedo_is_physical_and_quads_face_the_camera_side():
    for name in scene_names():
        s = load_scene(name)
        assert np.all((s.albedo >= 0) & (s.albedo < 1))
        assert np.all(s.quads.area > 0)


def _write(tmp_path, data) -> str:
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(data))
    return str(path)


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d["surfaces"][0].__setitem__("albedo", [1.2, 0.5, 0.5]),
     r"surfaces\[0\]\.albedo must be in \[0, 1\), got \[1\.2, 0\.5, 0\.5\]"),
    (lambda d: d["surfaces"][2].__setitem__("albedo", [0.5, -0.1, 0.5]), r"surfaces\[2\]\.albedo must be in \[0, 1\)"),
    (lambda d: d["surfaces"][1].__setitem__("albedo", [0.5, 0.5]),
     r"surfaces\[1\]\.albedo must be a list of 3 numbers"),
    (lambda d: d["surfaces"][1].__setitem__("corners", [[0, 0, 0], [1, 0, 0], [2, 0, 0], [1, 0, 0]]),
     r"surfaces\[1\]\.corners is a degenerate quad \(zero area\)"),
    (lambda d: d["surfaces"][2].__setitem__("corners", [[0, 0, 0], [0, 0, 1], [1, 0.3, 1], [1, 0, 0]]),
     r"surfaces\[2\]\.corners is not planar"),
    (lambda d: d["surfaces"][2].__setitem__("corners", [[0, 0, 0], [0, 0, 1], [2, 0, 1], [1, 0, 0]]),
     r"surfaces\[2\]\.corners must be a parallelogram"),
    (lambda d: d["surfaces"][3].__setitem__("emission", [1, -1, 1]), r"surfaces\[3\]\.emission must be >= 0"),
    (lambda d: d["surfaces"][1].pop("albedo"), r"surfaces\[1\] is missing the required field 'albedo'"),
    (lambda d: d.pop("camera"), r"scene is missing the required field 'camera'"),
    (lambda d: d["camera"].__setitem__("fov_deg", 0), r"camera\.fov_deg must be in \(0, 170\)"),
    (lambda d: d["camera"].__setitem__("look_at", d["camera"]["position"]), r"camera\.look_at must differ"),
    (lambda d: d["targets"]["left"][0].__setitem__("surface", "ceiling"),
     r"targets\['left'\]\[0\]\.surface names unknown surface 'ceiling'"),
    (lambda d: d["targets"]["left"][0].__setitem__("rect", [0.5, 0, 0.2, 1]), r"a0 < a1"),
    (lambda d: d["surfaces"][1].__setitem__("name", "left_wall"), r"surface names must be unique"),
    (lambda d: d.__setitem__("colour", "red"), r"unknown scene field\(s\) \['colour'\]"),
    (lambda d: d.__setitem__("patch_size", -1), r"patch_size must be positive"),
    (lambda d: d["lighting"].__setitem__("projector_flood", 2.0), r"lighting\.projector_flood must be in \[0, 1\]"),
])
def test_malformed_scenes_are_refused_naming_the_field(tmp_path, wedge_json, mutate, message):
    data = copy.deepcopy(wedge_json)
    mutate(data)
    with pytest.raises(InputError, match=message):
        load_scene(_write(tmp_path, data))


def test_malformed_scene_is_refused_through_open_rig(tmp_path, wedge_json, cache):
    wedge_json["surfaces"][0]["albedo"] = [1.0, 0.2, 0.2]
    with pytest.raises(InputError, match=r"surfaces\[0\]\.albedo must be in \[0, 1\)"):
        devices.open_rig("virtual:" + _write(tmp_path, wedge_json), cache_dir=cache)


def test_scene_file_that_is_not_json_is_refused(tmp_path):
    path = tmp_path / "broken.json"
    path.write_text("{ not json")
    with pytest.raises(InputError, match="is not valid JSON"):
        load_scene(str(path))
    with pytest.raises(InputError, match="cannot read scene file"):
        load_scene(str(tmp_path / "missing.json"))
    with pytest.raises(InputError, match="a scene must be a JSON object"):
        parse_scene([1, 2, 3])


def test_valid_scene_file_opens_as_a_rig(tmp_path, wedge_json, cache):
    wedge_json["name"] = "my_wedge"
    with devices.open_rig("virtual:" + _write(tmp_path, wedge_json), ideal=True, resolution=(16, 16),
                          cache_dir=cache, patch_size=0.3) as rig:
        assert rig.scene.name == "my_wedge"
        assert rig.camera.capture().image.shape == (16, 16, 3)


def test_unknown_scene_and_missing_scene_name():
    with pytest.raises(InputError, match=r"unknown virtual scene 'nope'; expected one of \[.*'cornell'"):
        devices.open_rig("virtual:nope")
    with pytest.raises(InputError, match="virtual rig needs a scene"):
        devices.open_rig("virtual:")


@pytest.mark.parametrize("options, message", [
    ({"colour": 1}, r"unknown virtual rig option\(s\) \['colour'\]"),
    ({"projector": "sideways"}, r"projector must be one of \['coaxial', 'offset'\], got 'sideways'"),
    ({"resolution": (0, 10)}, r"resolution must be a pair \(H, W\) of integers in \[4, 16384\]"),
    ({"resolution": "big"}, r"resolution must be a pair \(H, W\)"),
    ({"projector_resolution": (10.5, 10)}, r"projector_resolution must be a pair"),
    ({"seed": -1}, r"seed must be a non-negative int"),
    ({"seed": 1.5}, r"seed must be a non-negative int"),
    ({"ideal": "yes"}, r"ideal must be True or False, got 'yes'"),
    ({"ambient": 1}, r"ambient must be True or False"),
    ({"patch_size": 0}, r"patch_size must be a positive number"),
    ({"cache_dir": 3}, r"cache_dir must be a path, None or False"),
])
def test_bad_options_are_refused(options, message):
    with pytest.raises(InputError, match=message):
        open_rig("wedge", **options)


def test_probe_lists_every_scene_and_the_registry_opens_them(cache):
    listed = {a.name: a for a in probe()}
    for name in scene_names():
        assert listed[f"virtual:{name}"].ok
    rig = devices.open_rig("virtual:three", ideal=True, resolution=(24, 32), cache_dir=cache, patch_size=0.25)
    assert rig.name == "virtual:three"
    assert rig.camera.resolution == (24, 32) and rig.projector.resolution == (24, 32)
    assert isinstance(rig, devices.Rig)
    assert isinstance(rig.camera, devices.Camera) and isinstance(rig.projector, devices.Projector)


def test_targets_are_camera_masks_of_their_surfaces(cache):
    rig = open_rig("wedge", ideal=True, resolution=(48, 48), cache_dir=cache)
    t = rig.targets
    assert set(t) == {"left", "right", "union"}
    for m in t.values():
        assert m.shape == (48, 48) and m.dtype == bool and m.sum() > 100
    np.testing.assert_array_equal(t["union"], t["left"] | t["right"])
    assert not np.any(t["left"] & t["right"])
    # the left wall's pixels see albedo (0.6, 0.2, 0.6)
    np.testing.assert_allclose(rig.truth.albedo()[t["left"]], np.tile([0.6, 0.2, 0.6], (t["left"].sum(), 1)),
                               rtol=1e-6)
    three = open_rig("three", ideal=True, resolution=(48, 48), cache_dir=cache)
    red, blue, beige = (three.targets[k] for k in ("red", "blue", "beige"))
    assert red.sum() > 100 and blue.sum() > 100 and beige.sum() > 100
    assert not np.any((red & blue) | (red & beige) | (blue & beige))


def test_sub_rectangle_target(tmp_path, wedge_json, cache):
    wedge_json["targets"]["patch"] = [{"surface": "left_wall", "rect": [0.25, 0.25, 0.75, 0.75]}]
    rig = open_rig(_write(tmp_path, wedge_json), ideal=True, resolution=(48, 48), cache_dir=cache, patch_size=0.3)
    sub, full = rig.targets["patch"], rig.targets["left"]
    assert sub.sum() > 20
    assert np.all(full[sub]) and sub.sum() < 0.5 * full.sum()


def test_natural_lighting_of_the_wedge_is_the_projector_flood(cache):
    rig = open_rig("wedge", ideal=True, resolution=(32, 32), cache_dir=cache)
    rig.flood()
    assert rig.ambient is False
    np.testing.assert_array_equal(rig.projector.image, np.ones((32, 32, 3), np.float32))
    img = rig.camera.capture().image
    np.testing.assert_allclose(img, rig.truth.photograph(ambient=False, pattern=np.ones((32, 32, 3), np.float32)),
                               rtol=1e-5, atol=1e-7)
    assert img[rig.targets["union"]].min() > 0


def test_cold_set_up_reports_progress(tmp_path):
    calls = []
    open_rig("wedge", resolution=(16, 16), cache_dir=tmp_path, patch_size=0.3,
             progress=lambda step, total, message: calls.append((step, total, message)))
    assert calls[0][0] == 0 and calls[-1][0] == calls[-1][1] and len(calls) >= 4
    assert all(isinstance(m, str) and m for _, _, m in calls)
    calls.clear()
    open_rig("wedge", resolution=(16, 16), cache_dir=tmp_path, patch_size=0.3,
             progress=lambda *a: calls.append(a))
    assert calls == []  # cached: no work to report
