"""The virtual ColorChecker scene: its file is its definition, its patches colour-science's chart."""

import json

import numpy as np

import devices
from devices.virtual.checker_scene import checker_scene
from devices.virtual.scene import SCENE_DIR, load_scene
from engine.checker import detect_checker, reference_reflectances, sample_patches


def _albedos(scene: dict) -> np.ndarray:
    return np.array([s["albedo"] for s in scene["surfaces"]], np.float64)


def test_the_scene_file_is_generated_from_its_definition():
    stored, made = json.loads((SCENE_DIR / "checker.json").read_text()), checker_scene()
    # the albedos come from colour-science's spectra through numpy's sums: equal to the last bits or two,
    # which differ between numpy builds (a fresh environment's numpy 2.4 moved some by 1 ulp)
    np.testing.assert_allclose(_albedos(stored), _albedos(made), rtol=1e-12, atol=0)
    for s in stored["surfaces"] + made["surfaces"]:
        del s["albedo"]
    assert stored == made


def test_patch_albedos_are_the_reference_reflectances():
    scene = load_scene("checker")
    rho = np.array([scene.albedo[scene.names.index(f"patch_{i + 1:02d}")] for i in range(24)])
    np.testing.assert_allclose(rho, reference_reflectances(), rtol=1e-12, atol=0)  # to the last bits (above)


def test_the_chart_is_found_in_the_virtual_photograph(tmp_path):
    with devices.open_rig("virtual:checker", ideal=True, resolution=(64, 64), cache_dir=tmp_path) as rig:
        photo = rig.truth.photograph()
        found = detect_checker(photo)
        masks = found.patch_masks()
        assert masks.sum(axis=(1, 2)).min() >= 4
        assert not (masks.any(axis=0) & ~rig.targets["checker"]).any()
        albedo, _ = sample_patches(rig.truth.albedo(), found)
        np.testing.assert_allclose(albedo, reference_reflectances(), rtol=1e-6)
