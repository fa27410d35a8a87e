"""Argument parsing helpers shared by the headless subcommands."""

from __future__ import annotations

import argparse

import numpy as np


def kappa(text: str) -> np.ndarray:
    """Parse ``"2"`` or ``"2,0.125,8"`` into a (3,) albedo scale."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"kappa must be a number or R,G,B numbers, got {text!r}") from None
    if len(values) not in (1, 3) or any(not np.isfinite(v) or v < 0 for v in values):
        raise argparse.ArgumentTypeError(f"kappa must be one or three non-negative numbers, got {text!r}")
    return np.broadcast_to(np.asarray(values, float), (3,)).copy()


def resolution(text: str) -> tuple[int, int]:
    """Parse ``"256"`` or ``"240x320"`` (H x W)."""
    try:
        parts = [int(v) for v in text.lower().split("x")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"resolution must be N or HxW, got {text!r}") from None
    if len(parts) == 1:
        parts = parts * 2
    if len(parts) != 2 or min(parts) < 8:
        raise argparse.ArgumentTypeError(f"resolution must be N or HxW with sides >= 8, got {text!r}")
    return parts[0], parts[1]


def add_rig_options(parser) -> None:
    """``--rig NAME`` and the virtual rig's options."""
    parser.add_argument("--rig", default="virtual:cornell", help="rig to open (see `albedit devices`); default %(default)s")
    parser.add_argument("--ideal", action="store_true", help="virtual rig: no noise, linear projector")
    parser.add_argument("--resolution", type=resolution, default=None, help="virtual rig camera resolution, N or HxW")
    parser.add_argument("--projector", choices=("coaxial", "offset"), default=None, help="virtual rig projector pose")
    parser.add_argument("--seed", type=int, default=None, help="virtual rig noise seed")


def open_rig(args):
    """Open the rig named by ``--rig`` with the virtual options that were given."""
    import devices

    options = {}
    if args.rig.startswith("virtual:"):
        for key in ("ideal", "resolution", "projector", "seed"):
            value = getattr(args, key, None)
            if value not in (None, False):
                options[key] = value
    return devices.open_rig(args.rig, **options)
