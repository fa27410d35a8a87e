"""``albedit export``: write a session's saved edit (its free target's kappa) as an image."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from app.cli.recolor import add_denoise_option, decomposition_for, denoised, write_edit
from engine.errors import SessionError
from engine.recolor import recolor
from engine.session import Session


def add_arguments(parser) -> None:
    parser.add_argument("session", type=Path, help="a captured session folder with a saved edit")
    parser.add_argument("-o", "--output", type=Path, required=True, help="output image (.exr, .tif, .png)")
    parser.add_argument("--half", action="store_true", help="EXR: write half floats")
    add_denoise_option(parser)


def run(args) -> int:
    session = Session.open(args.session)
    edit = session.state.get("edit")
    if not edit or "kappa" not in edit:
        raise SessionError(f"session {args.session} has no saved edit: use `albedit recolor` or save from the app")
    d, plan = decomposition_for(session, None)
    kappa = np.asarray(edit["kappa"], float)
    write_edit(args.output, recolor(denoised(session, d, args.denoise), kappa), plan=plan, kappa_value=kappa, half=args.half)
    print(f"wrote {args.output}", file=sys.stderr)
    return 0
