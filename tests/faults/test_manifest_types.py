"""Issue 11, item 11: valid JSON of the wrong types in a manifest is refused on open, naming the field."""

from __future__ import annotations

import json

import numpy as np
import pytest

from engine import imageio
from tests.faults.conftest import refused


def _plan(m):
    return m["state"]["plan"]


def _edit(m):
    return m["state"]["edit"]


CASES = [
    (lambda m: m["state"].update(plan=[1, 2]), "state.plan must be an object"),
    (lambda m: _plan(m).pop("settings"), "state.plan.settings is missing"),
    (lambda m: _plan(m).update(adaptive={"policy": "span", "threshold": 0.05, "tolerance": 2}),
     "state.plan.adaptive.tolerance must be absent"),
    (lambda m: m["state"].update(edit="2,0.5,1"), "state.edit must be a saved edit"),
    (lambda m: _edit(m)["targets"][0].update(kappa="abc"), "state.edit.targets[0].kappa must be"),
    (lambda m: m["captures"][0]["meta"].update(exposure="1/30"), "captures[0].meta.exposure must be a number"),
    (lambda m: m["masks"]["right_wall-aeaacbac"].update(shape=[8, 8]), 'masks["right_wall-aeaacbac"].shape must be'),
    (lambda m: _plan(m).update(order="2"), "state.plan.order must be an integer in [1, 8] or 'auto'"),
    (lambda m: _plan(m).update(fixed_kappa=[[1, 1, 1]]), "state.plan.fixed_kappa must be the κ of every target"),
    (lambda m: m["state"]["result"].update(images=-1), "state.result.images must be an integer >= 0"),
    (lambda m: m["rig"].update(camera_resolution=[0, 16]), "rig.camera_resolution[0] must be an integer in"),
    (lambda m: m["captures"][1].update(saturated="no"), "captures[1].saturated must be true or false"),
    (lambda m: m["calibration"]["arrays"]["rig/black_frame"].update(dtype="|O"),
     'calibration.arrays["rig/black_frame"].dtype must be a numeric dtype'),
    (lambda m: m["state"].update(status="done"), "state.status must be one of 'capturing', 'captured'"),
    (lambda m: _edit(m)["acquisition"].update(cascade=["left_wall"]),
     "state.edit.acquisition.cascade[0] must be one of the targets"),
    (lambda m: m.update(metadata=[]), "metadata must be an object"),
    (lambda m: m.update(captures={}), "captures must be a list"),
    (lambda m: _plan(m).update(targets=[]), "state.plan.targets must be a list of target names (at least one)"),
    (lambda m: _edit(m)["acquisition"].update(denoise=10**9), "state.edit.acquisition.denoise must be an integer"),
    (lambda m: _plan(m)["settings"].update(tau=2.0), "state.plan.settings.tau must be a number in [0, 1]"),
    (lambda m: m["captures"][2].update(bytes=2**80), None),  # a size no file has: refused by the file check
]


@pytest.mark.parametrize(("change", "path"), CASES, ids=[c[1] or "bytes" for c in CASES])
@pytest.mark.parametrize("command", ["export", "recolor"])
def test_a_wrongly_typed_manifest_is_refused_naming_the_field(captured, tmp_path, albedit, tally, change, path,
                                                              command):
    manifest = captured / "manifest.json"
    data = json.loads(manifest.read_text())
    change(data)
    manifest.write_text(json.dumps(data))
    tally.injected += 1
    args = ["--kappa", "2"] if command == "recolor" else []
    line = refused(albedit, tally, command, captured, *args, "-o", tmp_path / "out.exr",
                   match=path if path is not None else "is corrupt")
    assert path is None or str(manifest) in line
    assert not (tmp_path / "out.exr").exists()


def test_a_mask_file_of_another_size_than_recorded_is_refused(captured, tmp_path, albedit, tally):
    imageio.write_image(captured / "masks" / "right_wall-aeaacbac.png", np.full((8, 8), 255, np.uint8))
    tally.injected += 1
    refused(albedit, tally, "export", captured, "-o", tmp_path / "out.exr",
            match="has shape (8, 8, 1), expected (16, 16)")
