"""Argument parsing helpers shared by the headless subcommands."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

#: The rig a command opens when neither ``--rig`` nor the session names one.
DEFAULT_RIG = "virtual:cornell"


def kappa(text: str) -> np.ndarray:
    """Parse ``"2"`` or ``"2,0.125,8"`` into a (3,) albedo scale."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"kappa must be a number or R,G,B numbers, got {text!r}") from None
    if len(values) not in (1, 3) or any(not np.isfinite(v) or v < 0 for v in values):
        raise argparse.ArgumentTypeError(f"kappa must be one or three non-negative numbers, got {text!r}")
    return np.broadcast_to(np.asarray(values, float), (3,)).copy()


def _integer(text: str, what: str, lo: int, hi: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} must be an integer in {lo}..{hi}, got {text!r}") from None
    if not lo <= value <= hi:
        raise argparse.ArgumentTypeError(f"{what} must be an integer in {lo}..{hi}, got {text!r}")
    return value


def frames(text: str) -> int:
    """Frames averaged per capture: 1..:data:`engine.workflow.MAX_FRAMES`."""
    from engine.workflow import MAX_FRAMES

    return _integer(text, "frames", 1, MAX_FRAMES)


def radius(text: str) -> int:
    """A noise-reduction radius in pixels: 0 (off) .. :data:`engine.denoise.MAX_RADIUS`."""
    from engine.denoise import MAX_RADIUS

    return _integer(text, "the denoise radius", 0, MAX_RADIUS)


def order(text: str) -> int:
    """A decomposition order K: 1..:data:`engine.figurate.MAX_ORDER`."""
    from engine.figurate import MAX_ORDER

    return _integer(text, "order", 1, MAX_ORDER)


def levels(text: str) -> int:
    """Grey levels of the projector response ramp: 3..256 (an 8-bit projector has 256)."""
    return _integer(text, "levels", 3, 256)


def fraction(text: str) -> float:
    """A relative error in (0, 1]: ``"0.05"`` (5 %)."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not np.isfinite(value) or not 0 < value <= 1:
        raise argparse.ArgumentTypeError(f"threshold must be a relative error in (0, 1] (0.05 is 5 %), got {text!r}")
    return value


def level(text: str) -> float:
    """A projector level in [0, 1] (1 is full white)."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0 <= value <= 1:
        raise argparse.ArgumentTypeError(f"a projector level must be in 0..1 (1 is full white), got {text!r}")
    return value


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


def output_image(text: str) -> Path:
    """Parse ``-o PATH``: an image format Albedit exports, in a folder that exists (checked before any work)."""
    from app.model.files import EXPORT_FORMATS

    path = Path(text)
    if path.suffix.lower() not in EXPORT_FORMATS:
        raise argparse.ArgumentTypeError(f"output must end in one of {sorted(EXPORT_FORMATS)}, got {text!r}")
    if not path.parent.is_dir():
        raise argparse.ArgumentTypeError(f"no folder {str(path.parent)!r} to write {path.name!r} into")
    return path


def add_rig_options(parser) -> None:
    """``--rig NAME`` and the virtual rig's options."""
    parser.add_argument("--rig", default=None,
                        help=f"rig to open (see `albedit devices`); default: the session's rig, else {DEFAULT_RIG}")
    parser.add_argument("--ideal", action="store_true", help="virtual rig: no noise, linear projector")
    parser.add_argument("--resolution", type=resolution, default=None, help="virtual rig camera resolution, N or HxW")
    parser.add_argument("--projector", choices=("coaxial", "offset"), default=None, help="virtual rig projector pose")
    parser.add_argument("--seed", type=int, default=None, help="virtual rig noise seed")


def open_rig(args, recorded=None):
    """Open the rig named by ``--rig`` with the virtual options that were given.

    Parameters
    ----------
    args : argparse.Namespace
        The command's arguments (:func:`add_rig_options`).
    recorded : engine.session.Session, optional
        The calibrated session the rig is opened for: without ``--rig`` its rig is opened, and
        a virtual rig's set-up options not given on the command line (resolutions, ideal,
        projector pose, supersampling, ...) are the ones it was calibrated with.
    """
    import devices
    from devices.virtual import recorded_options

    name = args.rig or (recorded.rig_name if recorded is not None else DEFAULT_RIG)
    options = {}
    if name.startswith("virtual:"):
        if recorded is not None and recorded.rig_name == name:
            options = recorded_options(recorded.fingerprint, recorded.camera_resolution,
                                       recorded.projector_resolution)
            if args.resolution is not None:
                options.pop("projector_resolution")  # a new camera resolution brings its own projector's
        for key in ("ideal", "resolution", "projector", "seed"):
            value = getattr(args, key, None)
            if value not in (None, False):
                options[key] = value
    return devices.open_rig(name, **options)


def report_session(session, command: str) -> None:
    """Say on stderr what opening the session repaired: temporary files removed, unreadable captures set aside."""
    import sys

    for rel in session.removed:
        print(f"albedit {command}: note: removed {rel}, left by a write that was killed", file=sys.stderr)
    for old, new, why in session.quarantined:
        print(f"albedit {command}: note: {old} could not be read ({why}); moved to {new}, it is taken again",
              file=sys.stderr)
