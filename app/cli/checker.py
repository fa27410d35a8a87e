"""``albedit checker``: measure a ColorChecker in a session's scene, for absolute albedo."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from app.cli._args import add_rig_options, frames, open_rig, report_session
from app.cli.main import ProgressBar
from engine.errors import InputError
from engine.session import Session
from engine.workflow import run_checker, saved_edit, target_albedo


def corners(text: str) -> np.ndarray:
    """Parse ``"x,y x,y x,y x,y"`` (or ``;``-separated) into (4, 2) corners."""
    try:
        points = [[float(v) for v in pair.split(",")] for pair in text.replace(";", " ").split()]
    except ValueError:
        points = []
    if len(points) != 4 or any(len(p) != 2 or not all(np.isfinite(p)) for p in points):
        raise argparse.ArgumentTypeError(
            f"corners are four x,y camera pixels (dark skin, bluish green, black, white), e.g. "
            f"'10,12 70,12 70,52 10,52'; got {text!r}")
    return np.asarray(points, np.float64)


def add_arguments(parser) -> None:
    parser.add_argument("session", type=Path, help="a calibrated session folder (`albedit calibrate`)")
    add_rig_options(parser)
    parser.add_argument("--corners", type=corners, default=None, metavar="'X,Y X,Y X,Y X,Y'",
                        help="place the chart by hand: its patch area's corners at dark skin, bluish green, black "
                             "and white, in camera pixels (default: detected)")
    parser.add_argument("--frames", type=frames, default=1, help="frames averaged per capture (default %(default)s)")


def run(args) -> int:
    if not args.session.is_dir():
        raise InputError(f"no session folder at {args.session}")
    session = Session.open(args.session)
    session.recover_orphans()
    report_session(session, "checker")
    with open_rig(args, session) as rig:
        record = run_checker(rig, session, corners=args.corners, frames=args.frames, progress=ProgressBar())
    placed = " ".join(f"{x:.1f},{y:.1f}" for x, y in record.checker.corners)
    print(record.report(), file=sys.stderr)
    print(f"corners (dark skin, bluish green, black, white): {placed}", file=sys.stderr)
    edit = saved_edit(session)
    for target in () if edit is None else edit.targets:
        try:
            value = target_albedo(session, session.read_mask(target.mask))
        except InputError as exc:
            print(f"{target.name}: {exc}", file=sys.stderr)
            continue
        print(f"{target.name}: absolute albedo ({', '.join(f'{v:.3f}' for v in value)})", file=sys.stderr)
    return 0
