"""``albedit calibrate``: black frame, projector response and Gray-code correspondences."""

from __future__ import annotations

import sys
from pathlib import Path

from app.cli._args import add_rig_options, levels, open_rig, report_session
from app.cli.main import ProgressBar
from engine.session import Session
from engine.session.paths import MANIFEST
from engine.workflow import calibration_problems, open_session_for_rig, run_calibration


def add_arguments(parser) -> None:
    parser.add_argument("session", type=Path,
                        help="session folder (created if missing; an interrupted calibration resumes)")
    add_rig_options(parser)
    parser.add_argument("--levels", type=levels, default=17,
                        help="grey levels of the response ramp, 3..256 (default %(default)s)")
    parser.add_argument("--crosstalk", action="store_true",
                        help="also measure projector-primary to camera-channel crosstalk")


def run(args) -> int:
    resumed = Session.open(args.session) if (args.session / MANIFEST).exists() else None
    with open_rig(args, resumed) as rig:
        session = open_session_for_rig(args.session, rig)
        report_session(session, "calibrate")
        cal = run_calibration(rig, session, levels=args.levels, crosstalk=args.crosstalk, progress=ProgressBar())
    print(f"calibrated {rig.name} into {args.session}", file=sys.stderr)
    problems = calibration_problems(cal)
    for report in (cal.metadata.get("coverage", ""), cal.metadata.get("exposure", "")):
        if report and not any(report in what for what, _ in problems):  # a problem says it once, with its fix
            print(report, file=sys.stderr)
    for what, fix in problems:
        print(f"problem: {what}\n  fix: {fix}", file=sys.stderr)
    return 0
