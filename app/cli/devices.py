"""``albedit devices``: what rigs this machine can open, and a one-frame health check."""

from __future__ import annotations

import sys


def add_arguments(parser) -> None:
    parser.add_argument("--check", metavar="RIG", default=None, help="open RIG and take one frame")


def run(args) -> int:
    import devices

    print("Rigs (--rig NAME):")
    for entry in devices.available():
        print(f"  {entry}")
    print("Projectors (projector=NAME for a camera rig; the default is the second screen):")
    for entry in devices.available_projectors():
        print(f"  {entry}")
    if args.check:
        from devices.health import check_rig

        print(check_rig(args.check), file=sys.stderr)
    return 0
