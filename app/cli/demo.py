"""``albedit demo``: the whole pipeline on the virtual Cornell box, scored against ground truth.

Calibrates the virtual co-axial rig — by default the same one the desktop app's demo opens
(:data:`app.model.demo.DEMO_OPTIONS`: the ideal camera and projector, where every number can
be checked exactly; ``--realistic`` adds noise, gamma, black level and an 8-bit projector) —
captures the right wall's observations, decomposes, recolors it from green to blue
(κ = (2, 0.125, 8), the paper's Fig. 6; another scene's target gets the κ that gives it the same
blue, :func:`app.model.demo.demo_kappa`) and writes the recolored EXR, a PNG preview, the
ground-truth PNG and a false-colour error image. ``--rig mitsuba:cornell`` runs the same on the
path-traced rig (Mitsuba 3; 64² by default, ``--spp`` samples per pixel per capture, one frame
per capture).

Where the rig's pixels mix surfaces (the realistic rig's supersampled pixels, the path tracer's),
the target is painted as an artist would: the scene's mask with its edge refined from a
photograph (:func:`app.model.demo.refined_target`), so only pixels wholly on the wall are
re-emitted and its edge pixels are recolored from both sides (``--edge``). The photograph is
taken in the scene's natural light: a scene lit by the projector (the wedge, the floor: the
scene's ``lighting``) is photographed under that flood, as ``albedit capture --flood`` does,
and its truth is rendered under the same flood.

The headline on stdout compares like with like: the relative error of our recolor (the
noise-aware one the app shows and exports, :mod:`engine.trust`; stderr also gives the plain one's) and of a
naive per-pixel recolor over the surfaces (the lamp in view dominates the image's norm, and a
recolor that keeps the lamp's light scores well over the whole image whatever it does to the
surfaces). Noise reduction is sized from the measured components' noise
(:func:`app.model.noise.denoise_radius`), so it never blurs noise-free data.
"""

from __future__ import annotations

import shutil
import sys
import time
from pathlib import Path

import numpy as np

from app.cli._args import frames, kappa, order, radius, resolution
from app.cli.main import ProgressBar
from app.model.demo import DEMO_OPTIONS, DEMO_ORDER, DEMO_TARGET, demo_kappa, refined_target
from app.model.files import export_image, open_document, prepare_trusted, recolored_image
from app.model.noise import SKIP_BELOW, denoise_radius
from engine.acquire import Adaptive
from engine.acquire.predict import relative_error
from engine.colour import convergence
from engine.errors import InputError, SessionError
from engine.imageio import to_display, write_image
from engine.recolor import recolor
from engine.session import Session
from engine.workflow import (
    edit_from_plan,
    estimated_report,
    noise_reduced,
    open_session_for_rig,
    run_calibration,
    run_capture,
    save_edit,
)


def _denoise(text: str):
    """'auto', or a radius in pixels (:func:`app.cli._args.radius`)."""
    return text if text == "auto" else radius(text)


def add_arguments(parser) -> None:
    parser.add_argument("-o", "--output", type=Path, default=Path("albedit-demo"),
                        help="output folder (default %(default)s)")
    parser.add_argument("--scene", default="cornell", help="virtual scene (default %(default)s)")
    parser.add_argument("--rig", default=None, metavar="NAME",
                        help="rig with ground truth to run on instead: virtual:SCENE or mitsuba:SCENE (path-traced)")
    parser.add_argument("--spp", type=int, default=256,
                        help="mitsuba rig: samples per pixel of each capture's render (default %(default)s)")
    parser.add_argument("--target", help=f"scene target to recolor (default {DEMO_TARGET}, or the scene's first "
                                          "target when it has none)")
    parser.add_argument("--kappa", type=kappa, default=None, metavar="R,G,B",
                        help="albedo scale (default: the paper's Fig. 6 blue, 2,0.125,8 on the Cornell box's green "
                             "wall; on another target the κ that gives it the same albedo, (0.2, 0.1, 0.8))")
    parser.add_argument("--order", type=order, default=DEMO_ORDER, help="decomposition order K (default %(default)s)")
    parser.add_argument("--resolution", type=resolution, default=None,
                        help="camera resolution (default 128, 64 on the mitsuba rig)")
    rig = parser.add_mutually_exclusive_group()
    rig.add_argument("--ideal", dest="ideal", action="store_true", default=DEMO_OPTIONS["ideal"],
                     help="the ideal rig: no noise, linear projector (the default, as in the desktop app's demo)")
    rig.add_argument("--realistic", dest="ideal", action="store_false",
                     help="a realistic camera (shot and read noise, clipping) and projector (gamma, 8 bits, crosstalk)")
    parser.add_argument("--projector", choices=("coaxial", "offset"), default=DEMO_OPTIONS["projector"],
                        help="projector pose: co-axial with the camera, or the scene's offset pose "
                             "(default %(default)s)")
    parser.add_argument("--adaptive", choices=("brute", "linear", "span"), default="brute")
    parser.add_argument("--frames", type=frames, default=None,
                        help="frames averaged per capture (default 1 on the ideal rig, 16 on the realistic one: "
                             "κ = 8 amplifies noise 8^i at order i; 1 on the mitsuba rig: each frame is a render)")
    parser.add_argument("--denoise", type=_denoise, default="auto", metavar="auto|RADIUS",
                        help="noise reduction: 'auto' (default) sizes the guided filter from the measured noise and "
                             "skips it on noise-free data; a radius in pixels; 0 = off")
    parser.add_argument("--edge", choices=("auto", "refine", "hard"), default="auto",
                        help="the target's edge: 'refine' refines the scene's mask from a photograph into coverage "
                             "(edge pixels recolored from both sides, only wholly covered pixels re-emitted); 'hard' "
                             "acquires the binary mask as painted; 'auto' (default): refine where pixels mix surfaces "
                             "(the realistic and the path-traced rigs), hard on the ideal rig (one point per pixel)")
    parser.add_argument("--fresh", action="store_true", help="delete the output folder's session first")


def error_image(ours: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, float]:
    """False-colour |ours − truth| (inferno, scaled to its 99th percentile) and that scale."""
    import cv2

    diff = np.linalg.norm(ours - truth, axis=-1)
    scale = float(np.percentile(diff, 99)) or 1.0
    grey = np.clip(diff / scale * 255, 0, 255).astype(np.uint8)
    return cv2.applyColorMap(grey, cv2.COLORMAP_INFERNO)[..., ::-1].copy(), scale


def _demo_session(path: Path, rig) -> Session:
    """The demo's session at ``path`` for ``rig``: created, or reused only if made with the same set-up.

    A session of another set-up (projector pose, camera model, resolution, scene) would have its
    captures scored against this set-up's truth: the co-axial captures reused for ``--projector
    offset`` scored 0.14 % where a fresh offset run scores 1.40 %. A demo session too old to
    record its set-up is refused as well (demo sessions are cheap to make again), and so is one
    of a scene lit by the projector made before the demo lit such scenes by it (its calibration
    saw the scene's other lamp, its photographs projector black).
    """
    try:
        session = open_session_for_rig(path, rig, demo=True, natural_light=True)
    except SessionError as exc:
        raise InputError(f"{exc}, or add --fresh to replace it") from None
    lit_otherwise = rig.lighting["projector_flood"] > 0 and not session.metadata.get("natural_light")
    if session.fingerprint is None or lit_otherwise:
        raise InputError(f"{path} holds a demo session too old to record its set-up"
                         f"{' and light' if lit_otherwise else ''}: add --fresh to replace it, or choose another "
                         "--output")
    return session


def run(args) -> int:
    import devices

    out: Path = args.output
    session_path = out / "session"
    if args.fresh and session_path.exists():
        shutil.rmtree(session_path)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot use {out} as the output folder: {exc.strerror or exc}") from None
    name = args.rig or f"virtual:{args.scene}"
    backend, _, scene = name.partition(":")
    if backend not in ("virtual", "mitsuba"):
        raise InputError(f"--rig must be a rig with ground truth, virtual:SCENE or mitsuba:SCENE, got {name!r}")
    path_traced = backend == "mitsuba"
    frames = args.frames if args.frames is not None else (1 if args.ideal or path_traced else 16)
    options = dict(ideal=args.ideal, resolution=args.resolution or ((64, 64) if path_traced else (128, 128)),
                   seed=DEMO_OPTIONS["seed"], projector=args.projector)
    if path_traced:
        if args.spp < 1:
            raise InputError(f"--spp must be >= 1, got {args.spp}")
        options.update(spp=args.spp, progress=ProgressBar())
    t0 = time.monotonic()
    with devices.open_rig(name, **options) as rig:
        target = args.target or (DEMO_TARGET if DEMO_TARGET in rig.targets else sorted(rig.targets)[0])
        if target not in rig.targets:
            raise InputError(f"scene {scene!r} has no target {target!r}; it has {sorted(rig.targets)}")
        mask = rig.targets[target]
        if args.kappa is None:
            args.kappa = demo_kappa(rig, mask)
        session = _demo_session(session_path, rig)
        # the scene in its natural light, from calibration on: its lamps, or a projector flood (Figs. 3, 8, 11)
        rig.ambient, level = rig.lighting["ambient"], rig.lighting["projector_flood"]
        flood = np.full((*rig.projector.resolution, 3), level, np.float32) if level > 0 else None
        if flood is not None:
            print(f"the scene is lit by the projector: the photograph is taken under a flood of {level:g}",
                  file=sys.stderr)
        kind = ("ideal" if args.ideal else "realistic") + (" path-traced" if path_traced else "")
        print(f"calibrating {rig.name} ({kind}, {args.projector}) ...", file=sys.stderr)
        run_calibration(rig, session, progress=ProgressBar())
        print(f"capturing target {target!r} at order {args.order}, {frames} frame(s) per capture, to recolor it "
              f"with κ = ({', '.join(f'{k:g}' for k in args.kappa)}) ...", file=sys.stderr)
        refine = args.edge == "refine" or (args.edge == "auto" and (path_traced or not args.ideal))
        painted = refined_target(rig, session, mask, frames=frames, pattern=flood) if refine else mask
        result = run_capture(
            rig, session, [(target, painted)], args.order,
            adaptive=None if args.adaptive == "brute" else Adaptive(args.adaptive),
            photograph_pattern=flood,
            frames=frames,
            progress=ProgressBar(),
        )
        truth = rig.truth.recolor([(mask, args.kappa)], ambient=rig.ambient, pattern=flood)
        photo = result.acquisition.observations[0]  # as captured: the naive recolor starts from what we start from
        surfaces = ~rig.truth.emitters()  # the lamp dwarfs every surface: score without it
        lamp = not surfaces.all()
    d = result.decomposition
    raw = recolor(d, args.kappa)
    unconverged = convergence(d, args.kappa).message()  # as `albedit recolor` and the app warn
    if unconverged:
        print(f"albedit demo: warning: {unconverged}", file=sys.stderr)
    size, noise = denoise_radius(d)
    if args.denoise != "auto":
        size = int(args.denoise)
    if size > 0:
        d = noise_reduced(session, result.key, d, size)
    plain = recolor(d, args.kappa)
    naive = np.where(mask[:, :, None], photo * args.kappa.astype(np.float32), photo)
    save_edit(session, edit_from_plan(session, args.kappa, denoise=size))
    doc = open_document(session_path)[0]
    problem = prepare_trusted(doc, session, progress=ProgressBar())  # the noise-aware recolor, as the app shows it
    if problem:
        print(f"albedit demo: warning: {problem}", file=sys.stderr)
    ours = recolored_image(doc)
    export_image(doc, out / "recolored.exr", dtype="float")  # the edit in its metadata
    err = {name: (relative_error(img, truth, surfaces), relative_error(img, truth))
           for name, img in (("ours", ours), ("plain", plain), ("raw", raw), ("naive", naive))}
    write_image(out / "recolored.png", to_display(ours))
    write_image(out / "photograph.png", to_display(photo))
    write_image(out / "truth.png", to_display(truth))
    err_img, scale = error_image(ours, truth)
    write_image(out / "error.png", err_img)
    estimated = estimated_report(session)
    if args.denoise == "auto" and np.isnan(noise):
        denoised = ("off: the components' noise cannot be measured (fewer than 16 target pixels inside its edge, or "
                    "order 1)")
    elif args.denoise == "auto" and size == 0:
        denoised = f"off: the components' noise is {100 * noise:.2g} % of their level, below {100 * SKIP_BELOW:.0f} %"
    elif args.denoise == "auto":
        denoised = (f"radius {size} (chosen from the components' noise, {100 * noise:.2g} % of their level); "
                    f"without it {100 * err['raw'][0]:.2f} %")
    else:
        denoised = f"radius {size} (asked for)" if size else "off (asked for)"
    print(
        f"{result.targets[0][1].report()}\n" + (f"{estimated}\n" if estimated else "") +
        f"images: {result.report(result.shots)}\n"
        f"noise reduction (plain recolor): {denoised}\n"
        f"recolor: {'noise-aware' if doc.trusted is not None else 'plain'}; the plain recolor scores "
        f"{100 * err['plain'][0]:.2f} % on the surfaces\n"
        f"over the whole image{' (the lamp in view dominates the norm)' if lamp else ''}: "
        f"Albedit {100 * err['ours'][1]:.2f} %, naive {100 * err['naive'][1]:.2f} %\n"
        f"error.png: |ours - truth|, white = {scale:.3g} (99th percentile)\n"
        f"wrote {out}/recolored.exr, recolored.png, photograph.png, truth.png, error.png "
        f"in {time.monotonic() - t0:.0f} s",
        file=sys.stderr,
    )
    gain = float(np.max(np.maximum(args.kappa, 1.0))) ** d.order
    if err["ours"][0] > err["naive"][0] and gain > 100 and not args.ideal:
        print(f"hint: κ^K = {gain:.0f} multiplies the camera noise of the last interaction component; average more "
              f"frames (--frames), denoise more (--denoise) or lower the order (--order 2)", file=sys.stderr)
    print(f"relative error vs ground truth on the surfaces ({kind} rig{', the lamp left out' if lamp else ''}): "
          f"Albedit {100 * err['ours'][0]:.2f} %, naive per-pixel recolor {100 * err['naive'][0]:.2f} %")
    return 0
