"""The virtual rig's optics: supersampled (mixed) pixels, projector defocus, 2:1 resolutions, textures."""

from __future__ import annotations

import json

import numpy as np
import pytest

from devices.virtual import open_rig
from devices.virtual.scene import SCENE_DIR, load_scene
from engine.errors import InputError


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("virtual-optics-cache")


def _area_average(img, f):
    h, w = img.shape[:2]
    return img.reshape(h // f, f, w // f, f, -1).mean(axis=(1, 3))


def test_supersampled_pixels_average_their_footprint(cache):
    coarse = open_rig("cornell", ideal=True, resolution=(24, 24), supersample=4, cache_dir=cache)
    fine = open_rig("cornell", ideal=True, resolution=(96, 96), supersample=1, cache_dir=cache)
    cov = coarse.coverage["right_wall"]
    mixed = (cov > 0) & (cov < 1)
    assert mixed.any() and len(coarse.setup.sub_pixel) > mixed.sum()
    # coverage is the fraction of the footprint on the wall: the fine rig's centres, area-averaged
    np.testing.assert_allclose(
        cov, _area_average(fine.targets["right_wall"][..., None].astype(float), 4)[..., 0], atol=0.13
    )
    # direct light of a mixed pixel is the mean over its footprint
    d_coarse, d_fine = coarse.truth.direct(), _area_average(fine.truth.direct(), 4)
    rel = np.abs(d_coarse - d_fine).sum(-1) / np.maximum(d_fine.sum(-1), 1e-6)
    assert np.median(rel[mixed]) < 0.1
    # without supersampling there are no mixed pixels
    plain = open_rig("cornell", ideal=True, resolution=(24, 24), cache_dir=cache)
    assert len(plain.setup.sub_pixel) == 0
    assert set(np.unique(plain.coverage["right_wall"])) <= {0.0, 1.0}


def test_truth_recolors_the_surface_in_mixed_pixels_too(cache):
    rig = open_rig("cornell", ideal=True, resolution=(24, 24), supersample=4, cache_dir=cache)
    mask = rig.targets["right_wall"]
    photo = rig.truth.photograph()
    np.testing.assert_allclose(rig.truth.recolor([(mask, 1.0)]), photo, rtol=1e-5, atol=1e-7)
    blue = rig.truth.recolor([(mask, (2.0, 0.125, 8.0))])
    cov = rig.truth.coverage(mask)
    np.testing.assert_allclose(cov, rig.coverage["right_wall"], atol=1e-6)
    edge = (cov > 0.3) & (cov < 1) & ~mask  # not painted, but partly wall
    assert edge.any()
    assert (blue[edge][:, 2] > 1.5 * photo[edge][:, 2]).all()
    comps = rig.truth.components(mask, 6)
    total = comps.inside.sum(0) + comps.outside.sum(0) + comps.unreached
    far = ~np.asarray(__import__("cv2").dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8)), bool)
    np.testing.assert_allclose(total[far], photo[far], rtol=2e-3, atol=1e-5)


def test_realistic_rig_defaults_to_a_coarser_projector_and_supersampling(cache):
    rig = open_rig("wedge", resolution=(32, 48), cache_dir=cache, patch_size=0.3)
    assert rig.projector.resolution == (16, 24) and rig.setup.supersample == 4
    ideal = open_rig("wedge", ideal=True, resolution=(32, 48), cache_dir=cache, patch_size=0.3)
    assert ideal.projector.resolution == (32, 48) and ideal.setup.supersample == 1
    with pytest.raises(InputError, match="supersample must be an integer"):
        open_rig("wedge", supersample=0, cache_dir=cache)
    with pytest.raises(InputError, match="defocus must be a blur"):
        open_rig("wedge", defocus=-1, cache_dir=cache)


def test_projector_defocus_blurs_a_line(cache):
    def line(defocus):
        rig = open_rig("wedge", ideal=True, resolution=(32, 32), defocus=defocus, cache_dir=cache, ambient=False)
        pattern = np.zeros((32, 32, 3), np.float32)
        pattern[:, 8] = 1.0  # on the left wall, away from the corner
        return rig.truth.photograph(ambient=False, pattern=pattern).sum(axis=-1)

    sharp, soft = line(0.0), line(1.0)
    rows = sharp[:, 8] > 0
    # in focus, only interreflected light reaches the pixels beside the line; defocused, direct light does
    assert (soft[rows][:, 7] > 2 * sharp[rows][:, 7]).all()
    assert soft[rows][:, 8].mean() < 0.6 * sharp[rows][:, 8].mean()


def _scene_with_texture(tmp_path, texture):
    data = json.loads((SCENE_DIR / "wedge.json").read_text())
    data["surfaces"][1]["texture"] = texture
    path = tmp_path / "textured.json"
    path.write_text(json.dumps(data))
    return path


def test_textured_albedo_on_a_quad(tmp_path, cache):
    path = _scene_with_texture(tmp_path, {"pattern": "checker", "cells": [4, 3], "albedo": [0.2, 0.2, 0.7]})
    scene = load_scene(path)
    a = np.array([0.1, 0.3, 0.1])
    b = np.array([0.1, 0.1, 0.5])
    np.testing.assert_allclose(
        scene.albedo_at(np.array([1, 1, 1]), a, b), [[0.4, 0.7, 0.8], [0.2, 0.2, 0.7], [0.2, 0.2, 0.7]]
    )
    rig = open_rig(str(path), ideal=True, resolution=(32, 32), supersample=2, cache_dir=cache, patch_size=0.3)
    albedo = rig.truth.albedo()[rig.targets["right"]]
    assert np.isclose(albedo, [0.2, 0.2, 0.7], atol=1e-6).all(axis=-1).any()
    assert np.isclose(albedo, [0.4, 0.7, 0.8], atol=1e-6).all(axis=-1).any()
    assert len(rig.setup.sub_pixel) > 0  # texture cell boundaries are mixed pixels


def test_image_texture_and_bad_textures(tmp_path):
    import cv2

    img = np.zeros((2, 4), np.uint8)
    img[:, 2:] = 255
    cv2.imwrite(str(tmp_path / "half.png"), img)
    scene = load_scene(_scene_with_texture(tmp_path, {"image": "half.png"}))
    got = scene.albedo_at(np.array([1, 1]), np.array([0.2, 0.8]), np.array([0.5, 0.5]))
    np.testing.assert_allclose(got, [[0, 0, 0], [0.4, 0.7, 0.8]])
    with pytest.raises(InputError, match=r"surfaces\[1\].texture.image: cannot read image"):
        load_scene(_scene_with_texture(tmp_path, {"image": "missing.png"}))
    with pytest.raises(InputError, match=r"pattern must be 'checker' or 'stripes'"):
        load_scene(_scene_with_texture(tmp_path, {"pattern": "dots", "cells": [2, 2], "albedo": [0.1, 0.1, 0.1]}))
    with pytest.raises(InputError, match=r"texture.albedo must be in \[0, 1\)"):
        load_scene(_scene_with_texture(tmp_path, {"pattern": "checker", "cells": [2, 2], "albedo": [1.1, 0.1, 0.1]}))
