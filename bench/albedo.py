"""How close Albedit's colour estimates come to the virtual rig's truth, ideal and realistic.

Cornell box (Fig. 6), right wall (0.1, 0.8, 0.1): the wall's colour as the photograph shows
it (its mean, interreflections included), its direct colour R^0 L_d, and R^0 L_d white-
balanced by the direct image D — each compared with the albedo's chromaticity; then κ for
"make it (0.2, 0.1, 0.8)" with the albedo measured against a card laid over the wall
(expected: the paper's κ = (2, 0.125, 8)); and the κ at which the wall's interreflection series
diverges, estimated from the decomposition (engine.colour.kappa_limit) against the truth's.

Checker scene, with the co-axial projector and with one beside the camera: the absolute
albedo of the panel beside the chart (in its plane: the fit's use case), of the chart's own
patches, and of the side wall (not in the chart's plane: the projector lights it
differently). Prints per-channel relative errors in %.

    python bench/albedo.py [--resolution 96] [--frames 16]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

import devices
from devices.virtual.scene import SCENE_DIR
from engine.acquire import Recorder, measure_checker, prepare_target, projector_xy
from engine.albedo import reference_scale
from engine.checker import detect_checker, reference_reflectances
from engine.colour import direct_colour, kappa_for_albedo, kappa_limit
from engine.session import Session
from engine.workflow import load_decomposition, run_calibration, run_capture

KAPPA = np.array([2.0, 0.125, 8.0])


def _session(rig, path):
    return Session.create(path, rig_name=rig.name, camera_resolution=rig.camera.resolution,
                          projector_resolution=rig.projector.resolution)


def _chroma_error(estimate, truth):
    return 100 * (estimate / estimate.sum() / (truth / truth.sum()) - 1)


def _fmt(values):
    return "(" + ", ".join(f"{v:+6.2f}" for v in values) + ") %"


def cornell(work: Path, options: dict, frames: int) -> None:
    scene = json.loads((SCENE_DIR / "cornell.json").read_text())
    card = reference_reflectances()[18]
    for s in scene["surfaces"]:
        if s["name"] == "right_wall":
            s["albedo"] = card.tolist()
    card_scene = work / "cornell_card.json"
    card_scene.write_text(json.dumps(scene))
    with devices.open_rig(f"virtual:{card_scene}", **options) as rig:
        session = _session(rig, work / "card")
        calibration = run_calibration(rig, session)
        recorder = Recorder(rig, session, frames=frames)
        photo = recorder.capture("photograph", recorder.black())
        wall = rig.targets["right_wall"]
        reference = prepare_target(recorder, calibration, wall, photo, name="card")
    scale = reference_scale(reference.direct, card, reference.mask)
    with devices.open_rig("virtual:cornell", **options) as rig:
        session = _session(rig, work / "cornell")
        run_calibration(rig, session)
        result = run_capture(rig, session, [("right_wall", wall)], 4, frames=frames)
        prepared = result.targets[0][1]
        d = load_decomposition(session)
        truth = rig.truth.albedo()[wall].mean(axis=0)
        seen = result.acquisition.observations[0][wall].astype(np.float64).mean(axis=0)
        print(f"  wall colour, chromaticity error vs its albedo {np.round(truth.astype(float), 3).tolist()}:")
        print(f"    photograph mean (interreflections in)  {_fmt(_chroma_error(seen, truth))}")
        print(f"    direct colour R^0 L_d                  {_fmt(_chroma_error(direct_colour(d), truth))}")
        balanced = direct_colour(d, direct=prepared.direct)
        print(f"    R^0 L_d white-balanced by D            {_fmt(_chroma_error(balanced, truth))}")
        terms = rig.truth.interactions(d.target, 16)[1:, d.target].astype(np.float64).sum(axis=1)
        true_limit = terms[-2] / terms[-1]  # successive interactions' ratio: the series' growth
        sums = d.components[:, d.target].astype(np.float64).sum(axis=1)
        print(f"  κ limit (divergence), order 4: {np.round(kappa_limit(d), 2).tolist()}, true "
              f"{np.round(true_limit, 2).tolist()}; the fit's last two components would say "
              f"{np.round(sums[-2] / sums[-1], 2).tolist()}")
        albedo = scale.albedo(prepared.direct, prepared.mask)
        kappa = kappa_for_albedo(albedo, [0.2, 0.1, 0.8])
        print(f"  albedo against a card over the wall      {_fmt(100 * (albedo / truth - 1))}")
        print(f"  κ for (0.2, 0.1, 0.8): {np.round(kappa, 4).tolist()}, "
              f"vs (2, 0.125, 8) {_fmt(100 * (kappa / KAPPA - 1))}")


def checker(work: Path, options: dict, frames: int) -> None:
    with devices.open_rig("virtual:checker", **options) as rig:
        session = _session(rig, work / "checker")
        calibration = run_calibration(rig, session)
        recorder = Recorder(rig, session, frames=frames)
        photo = recorder.capture("photograph", recorder.black())
        chart = measure_checker(recorder, calibration, detect_checker(photo), photo)
        print(f"  {chart.report()}")
        truth = rig.truth.albedo()
        print(f"  chart patches read back, worst          {_fmt(100 * np.abs(chart.scale.residual).max(axis=0))}")
        for name in ("panel", "right_wall"):
            mask = rig.targets[name]
            p = prepare_target(recorder, calibration, mask, photo, name=name)
            albedo, true = chart.scale.albedo(p.direct, p.mask, projector_xy(p)), truth[mask].mean(axis=0)
            print(f"  {name:10s} absolute albedo {np.round(albedo, 4).tolist()} "
                  f"vs {np.round(true.astype(float), 4).tolist()}: "
                  f"{_fmt(100 * (albedo / true - 1))}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=int, default=96, help="camera and projector side (default %(default)s)")
    parser.add_argument("--frames", type=int, default=16,
                        help="frames averaged on the realistic rig (default %(default)s)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        for ideal in (True, False):
            frames = 1 if ideal else args.frames
            options = dict(ideal=ideal, resolution=(args.resolution, args.resolution), seed=0)
            label = "ideal" if ideal else f"realistic, {frames} frames"
            work = Path(tmp) / label.split(",")[0]
            work.mkdir()
            print(f"virtual:cornell, {label}, {args.resolution}²")
            cornell(work, options, frames)
            print(f"virtual:checker, {label}, {args.resolution}²")
            checker(work, options, frames)
            print(f"virtual:checker, {label}, {args.resolution}², projector 25 cm beside the camera")
            (work / "offset").mkdir()
            checker(work / "offset", {**options, "projector": "offset"}, frames)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
