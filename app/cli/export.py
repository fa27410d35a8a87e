"""``albedit export``: write a session's saved edit as an image, as the app's File ▸ Export does."""

from __future__ import annotations

import sys
from pathlib import Path

from app.cli._args import output_image
from app.cli.recolor import (
    add_denoise_option,
    add_recolor_option,
    choose_recolor,
    open_edit,
    output_dtype,
    set_noise_reduction,
)
from app.model.files import export_image
from engine.errors import SessionError


def add_arguments(parser) -> None:
    parser.add_argument("session", type=Path, help="a captured session folder with a saved edit")
    parser.add_argument("-o", "--output", type=output_image, required=True, help="output image (.exr, .tif, .png)")
    parser.add_argument("--half", action="store_true", help="EXR: write half floats")
    add_denoise_option(parser)
    add_recolor_option(parser)


def run(args) -> int:
    dtype = output_dtype(args.output, args.half)
    doc, session = open_edit(args.session, "export")
    state = session.state
    if "edit" not in state and "edits" not in state:
        raise SessionError(f"session {args.session} has no saved edit: use `albedit recolor` or save from the app")
    set_noise_reduction(doc, session, args.denoise)
    choose_recolor(doc, session, args.noise_aware, "export")
    export_image(doc, args.output, dtype=dtype)
    print(f"wrote {args.output}", file=sys.stderr)
    return 0
