"""``albedit capture``: the observations of one target, or a cascade of several."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from app.cli._args import add_rig_options, fraction, frames, kappa, level, open_rig, order, report_session
from app.cli.main import ProgressBar
from engine.acquire import Adaptive, CaptureSettings
from engine.errors import InputError
from engine.imageio import read_mask
from engine.noise import packed_index
from engine.session import Session
from engine.session.paths import MANIFEST
from engine.trust import lamp_caution
from engine.workflow import (
    adopt_calibration,
    check_targets,
    estimated_report,
    load_compatible_calibration,
    open_session_for_rig,
    photograph_name,
    run_capture,
)


def add_arguments(parser) -> None:
    parser.add_argument("session", type=Path,
                        help="a calibrated session folder (`albedit calibrate`), or a new one with --calibration")
    parser.add_argument("--calibration", type=Path, default=None, metavar="SESSION",
                        help="re-use the calibration of another session of the same rig (refused if the rig differs)")
    add_rig_options(parser)
    parser.add_argument(
        "--target", action="append", required=True, metavar="NAME[=MASK.png]",
        help="target in cascade order (repeat for a cascade); NAME alone uses the rig's named target; a MASK "
             "image marks the target where its grey or colour is non-zero (or, with transparency, its alpha)",
    )
    parser.add_argument("--order", type=_order, default=4,
                        help="decomposition order K, or 'auto': capture until the linear prediction of the newest "
                             "image is within --threshold (one target; default %(default)s)")
    parser.add_argument("--fixed-kappa", type=kappa, action="append", default=[], metavar="R,G,B",
                        help="kappa of each target but the last, in order (fixed before capture)")
    parser.add_argument("--adaptive", choices=("brute", "linear", "span"), default="brute",
                        help="predict captures instead of taking them (Sec. 5); default %(default)s")
    parser.add_argument("--threshold", type=fraction, default=0.01,
                        help="adaptive relative-error threshold in (0, 1] (default 0.01, 1%%)")
    parser.add_argument("--frames", type=frames, default=1, help="frames averaged per capture (default %(default)s)")
    parser.add_argument("--rgb", action="store_true", help="emit all channels at once instead of one primary at a time")
    parser.add_argument("--flood", type=level, default=None, metavar="LEVEL",
                        help="light the photograph with a projector flood of this level instead of black")


def _order(text: str):
    return text if text == "auto" else order(text)


def _targets(args, rig) -> list[tuple[str, np.ndarray]]:
    out = []
    for spec in args.target:
        name, _, path = spec.partition("=")
        if path:
            mask = read_mask(path)
        elif name in rig.targets:
            mask = rig.targets[name]
        else:
            raise InputError(f"target {name!r} is not one of the rig's targets {sorted(rig.targets)}; "
                             "give NAME=MASK.png")
        out.append((name, mask))
    return out


def run(args) -> int:
    source = args.session if args.calibration is None else args.calibration
    recorded = Session.open(source) if (source / MANIFEST).is_file() else None  # else refused below, masks first
    with open_rig(args, recorded) as rig:
        targets = _targets(args, rig)
        check_targets(targets, tuple(rig.camera.resolution))  # before any folder is made or capture taken
        if args.calibration is not None:
            calibration = load_compatible_calibration(args.calibration, rig)
            session = open_session_for_rig(args.session, rig)
            adopt_calibration(session, calibration)
        else:
            session = recorded or Session.open(args.session)
            session.recover_orphans()
        report_session(session, "capture")
        flood = None
        if args.flood is not None:
            hp, wp = rig.projector.resolution
            flood = np.full((hp, wp, 3), args.flood, np.float32)
        result = run_capture(
            rig, session, targets, args.order,
            fixed_kappa=args.fixed_kappa,
            settings=CaptureSettings(per_channel=not args.rgb),
            adaptive=(Adaptive(args.adaptive, args.threshold)
                      if args.adaptive != "brute" or args.order == "auto" else None),
            photograph_pattern=flood,
            frames=args.frames,
            progress=ProgressBar(),
        )
    print(
        f"captured {', '.join(n for n, _ in targets)} at order {len(result.acquisition.observations)}: "
        f"{result.report(result.shots)}",
        file=sys.stderr,
    )
    for name, prepared in result.targets:
        print(f"{name}: {prepared.report()}", file=sys.stderr)
    acq = result.acquisition
    if acq.covariance is not None:  # each observation's predicted noise on the target
        k, t = len(acq.observations), acq.target.mask
        rel = [float(np.sqrt(acq.covariance[packed_index(i, i, k)][t].mean())
                     / max(float(np.abs(acq.observations[i][t]).mean()), 1e-30)) for i in range(k)]
        print("predicted σ on the target: " + ", ".join(f"observation {i} {r:.2%}" for i, r in enumerate(rel)),
              file=sys.stderr)
    if line := estimated_report(session):
        print(line, file=sys.stderr)
    photograph = session.read_capture(photograph_name(session, None))
    for name, mask in targets:
        if line := lamp_caution(name, photograph, mask):
            print(f"warning: {line}", file=sys.stderr)
    return 0
