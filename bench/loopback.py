"""The loopback bench against the virtual rig: the same calibration and capture, the same scene.

``loopback:SCENE`` drives the real projector window (on a 1024x768 HDMI-1 beside a 1920x1080
panel, Qt's offscreen platform) and the real hot-folder camera, whose files a bench camera
writes from the virtual scene lit by the screen (devices/loopback.py). ``virtual:SCENE`` is the
same scene, camera and projector resolution, sensor and noise seed, with no window and no files.
Both are calibrated and captured (one target, order K) into fresh sessions; printed: captures,
seconds per capture, undecoded camera pixels, and the recoloured image's relative error against
ground truth over all pixels and over the surfaces (without the lamp, which the virtual rig
brackets to its true radiance and a fixed-exposure camera's files clip), with loopback/virtual
ratios.

Run: .venv/bin/python bench/loopback.py [--scene cornell] [--target right_wall] [--order 3]
     [--kappa 1.5,0.8,1.2] [--format tiff|dng|exr]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

CAMERA, PROJECTOR = (48, 64), (768, 1024)


def _run(name, options, session_path, target, order):
    import devices
    from engine.workflow import load_calibration, load_decomposition, open_session_for_rig, run_calibration, run_capture

    with devices.open_rig(name, **options) as rig:
        session = open_session_for_rig(session_path, rig)
        start = time.perf_counter()
        run_calibration(rig, session)
        run_capture(rig, session, [(target, rig.targets[target])], order)
        seconds = time.perf_counter() - start
    calibration = load_calibration(session)
    return {
        "captures": len(session.captures),
        "seconds": seconds,
        "undecoded": 1.0 - float(calibration.correspondence.valid.mean()),
        "decomposition": load_decomposition(session),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="cornell")
    ap.add_argument("--target", default="right_wall")
    ap.add_argument("--order", type=int, default=3)
    ap.add_argument("--kappa", default="1.5,0.8,1.2")
    ap.add_argument("--format", default="tiff", choices=("tiff", "dng", "exr"))
    args = ap.parse_args()
    kappa = np.array([float(v) for v in args.kappa.split(",")])

    from devices.loopback import offscreen_platform

    work = Path(tempfile.mkdtemp(prefix="albedit-bench-loopback-"))
    os.environ["QT_QPA_PLATFORM"] = offscreen_platform(work)  # the bench's two screens, before Qt starts
    import devices
    from engine.acquire.predict import relative_error
    from engine.recolor import recolor

    cache = work / "cache"
    shared = {"cache_dir": cache, "seed": 0}
    results = {
        "loopback": _run(f"loopback:{args.scene}", {**shared, "file_format": args.format}, work / "loopback",
                         args.target, args.order),
        "virtual": _run(f"virtual:{args.scene}",
                        {**shared, "resolution": CAMERA, "projector_resolution": PROJECTOR, "supersample": 1},
                        work / "virtual", args.target, args.order),
    }
    scene = f"virtual:{args.scene}"
    with devices.open_rig(scene, resolution=CAMERA, projector_resolution=PROJECTOR, supersample=1,
                          cache_dir=cache) as rig:
        mask = rig.targets[args.target]
        truth = rig.truth.recolor([(mask, kappa)])
        surfaces = ~rig.truth.emitters()
    for r in results.values():
        ours = recolor(r["decomposition"], kappa)
        r["error"], r["error_surfaces"] = relative_error(ours, truth), relative_error(ours, truth, surfaces)
    lo, vi = results["loopback"], results["virtual"]
    print(f"{args.scene}, target {args.target}, order {args.order}, kappa {args.kappa}, "
          f"camera {CAMERA[1]}x{CAMERA[0]}, "
          f"projector {PROJECTOR[1]}x{PROJECTOR[0]}, loopback files {args.format}")
    print(f"{'':28}{'loopback':>12}{'virtual':>12}{'ratio':>10}")
    rows = [
        ("captures", "captures", "{:.0f}"),
        ("seconds per capture", None, "{:.3f}"),
        ("undecoded camera pixels", "undecoded", "{:.1%}"),
        ("error, all pixels", "error", "{:.2%}"),
        ("error, surfaces (no lamp)", "error_surfaces", "{:.2%}"),
    ]
    for label, key, fmt in rows:
        a, b = (lo[key], vi[key]) if key else (lo["seconds"] / lo["captures"], vi["seconds"] / vi["captures"])
        print(f"{label:28}{fmt.format(a):>12}{fmt.format(b):>12}{a / b if b else float('nan'):>9.2f}x")


if __name__ == "__main__":
    main()
