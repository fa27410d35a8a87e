"""``albedit recolor``: recolor a captured session's free (last) target, write the image, save the edit.

The new look is asked for as κ, a colour, an absolute albedo (with a colour checker in the
session) or another target to match; every request goes through
:class:`engine.target_colour.TargetColour`, as in the app, so both give the same κ. A request
physics refuses (an albedo of 1 or more) writes nothing; one the captured order cannot follow
is written with a warning saying what would help.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from app.cli._args import kappa, output_image, radius
from app.model.document import Document
from app.model.files import export_image, open_document, prepare_trusted, save_document
from engine.colour import convergence, parse_colour, to_hex
from engine.errors import InputError, SessionError
from engine.recolor import recolor, recolor_variance
from engine.session import Session
from engine.target_colour import TargetColour
from engine.trust import recolor_trusted
from engine.workflow import load_decomposition, saved_checker, target_albedo, target_colour, target_direct


def add_arguments(parser) -> None:
    parser.add_argument("session", type=Path, help="a captured session folder")
    parser.add_argument("--target", default=None, help="the free (last) target of the session's plan (checked)")
    look = parser.add_mutually_exclusive_group(required=True)
    look.add_argument("--kappa", type=kappa, metavar="R,G,B", help="albedo scale of the target")
    look.add_argument("--colour", "--color", metavar="COLOUR",
                      help="the target's new colour (its paint's, white-balanced): '#3355cc', 'srgb:0.2,0.33,0.8', "
                           "'lab:50,10,-40' or linear 'R,G,B'")
    look.add_argument("--albedo", type=albedo, metavar="R,G,B",
                      help="the target's new absolute albedo, each below 1 (needs a colour checker: `albedit checker`)")
    look.add_argument("--match", metavar="TARGET",
                      help="give the target the albedo of another acquired target (the ratio of their direct "
                           "images, or of their absolute albedos with a colour checker)")
    parser.add_argument("--keep-luminance", action="store_true",
                        help="with --colour or --match: change hue and chroma only, keep the target's luminance")
    parser.add_argument("--exposure", type=float, default=0.0, metavar="STOPS",
                        help="the display exposure a --colour is meant at (default 0: '#ffffff' is linear 1)")
    parser.add_argument("-o", "--output", type=output_image, required=True, help="output image (.exr, .tif, .png)")
    parser.add_argument("--half", action="store_true", help="EXR: write half floats")
    add_denoise_option(parser)
    add_recolor_option(parser)


def albedo(text: str) -> np.ndarray:
    """Parse ``"0.2,0.1,0.8"`` (or one number for grey) into a (3,) albedo (≥ 1 is refused later, with the reason)."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) not in (1, 3) or any(not np.isfinite(v) or v < 0 for v in values):
        raise argparse.ArgumentTypeError(f"an albedo is one or three numbers in [0, 1), got {text!r}")
    return np.broadcast_to(np.asarray(values, float), (3,)).copy()


def add_denoise_option(parser) -> None:
    """``--denoise RADIUS``: guided-filter the interaction components (0 = off; default: the saved edit's)."""
    parser.add_argument("--denoise", type=radius, default=None, metavar="RADIUS",
                        help="guided-filter radius for the interaction components, 0 = off "
                             "(default: the saved edit's, else off)")


def add_recolor_option(parser) -> None:
    """``--plain`` / ``--noise-aware``: which recolor to write (default: the saved edit's; new edits: noise-aware)."""
    how = parser.add_mutually_exclusive_group()
    how.add_argument("--plain", dest="noise_aware", action="store_false", default=None,
                     help="write the plain κ-weighted sum of the components (Eq. 3-4), not the noise-aware recolor")
    how.add_argument("--noise-aware", dest="noise_aware", action="store_true", default=None,
                     help="write the noise-aware recolor (each component trusted as far as its measured noise allows; "
                          "the default for every edit saved since the choice exists)")


def choose_recolor(doc: Document, session: Session, noise_aware: bool | None, command: str) -> None:
    """Use the recolor asked for (None keeps the saved edit's) and prepare the noise-aware one's data (seconds,
    once per acquisition: cached in the session). A case that cannot be noise-aware is written plainly, with a warning.
    """
    if noise_aware is not None:
        doc.set_noise_aware(noise_aware)
    problem = prepare_trusted(doc, session)
    if problem:
        print(f"albedit {command}: warning: {problem}", file=sys.stderr)
    acq = doc.acquisition
    if doc.trusted is not None and acq.denoise:
        print(f"albedit {command}: note: noise reduction (radius {acq.denoise}) filters the plain recolor; the "
              "noise-aware one smooths each component as far as its own noise calls for (add --plain to use it)",
              file=sys.stderr)
    print(f"albedit {command}: {'noise-aware' if doc.trusted is not None else 'plain'} recolor", file=sys.stderr)


def open_edit(path: Path, command: str) -> tuple[Document, Session]:
    """The session's saved edit as a document with its decomposition (recomputed if the cache is gone)."""
    if not path.is_dir():
        raise SessionError(f"no session folder at {path}")
    doc, session, warnings = open_document(path)
    if doc.acquisition is None:
        if warnings:
            raise SessionError(f"session {path} cannot be recolored: {'; '.join(warnings)}")
        raise SessionError(f"session {path} has no acquisition to recolor: run `albedit capture` first")
    for line in warnings:
        print(f"albedit {command}: warning: {line}", file=sys.stderr)
    return doc, session


def set_noise_reduction(doc: Document, session: Session, denoise: int | None) -> None:
    """Use the noise-reduction radius asked for (None keeps the saved edit's)."""
    acq = doc.acquisition
    if denoise is None or denoise == acq.denoise:
        return
    filtered = None if denoise == 0 else load_decomposition(session, acq.key, denoise=denoise)
    doc.set_noise_reduction(denoise, filtered)


def output_dtype(path: Path, half: bool) -> str:
    """The sample type written to ``path``: float EXR or TIFF, half EXR (``--half``), 8-bit sRGB PNG.

    Raises
    ------
    InputError
        ``--half`` for a file that is not an EXR (checked before any work).
    """
    suffix = path.suffix.lower()
    if half and suffix != ".exr":
        raise InputError(f"--half writes half floats, which only EXR holds; {path.name!r} is not an .exr")
    return "half" if half else ("uint8" if suffix == ".png" else "float")


def requested_kappa(args, doc: Document, session: Session) -> tuple[np.ndarray, TargetColour | None]:
    """κ of the free target for the request in ``args``, and what is known of its colour (None for
    a plain ``--kappa`` in a session without a colour checker: only convergence can be judged)."""
    free = doc.target(doc.acquisition.cascade[-1])
    colour_asked = args.kappa is None
    if args.keep_luminance and args.colour is None and args.match is None:
        raise InputError("--keep-luminance changes the hue of a --colour or --match request only; κ and an "
                         "absolute --albedo are exact")
    if not np.isfinite(args.exposure):
        raise InputError(f"--exposure must be a finite number of stops, got {args.exposure!r}")
    wanted = None if args.colour is None else parse_colour(args.colour) / 2.0 ** args.exposure
    if not colour_asked and saved_checker(session) is None:
        return args.kappa, None
    mask = doc.acquisition.masks[-1]
    colour = target_colour(session, doc.acquisition.raw, mask)
    if args.kappa is not None:
        return args.kappa, colour
    if wanted is not None:
        return colour.for_colour(wanted, keep_luminance=args.keep_luminance), colour
    if args.albedo is not None:
        return colour.for_albedo(args.albedo), colour
    other = _other_target(doc, args.match, free.name)
    direct = target_direct(session, other.mask)
    try:
        other_albedo = target_albedo(session, other.mask, direct)
    except InputError:
        other_albedo = None
    them = TargetColour(None, direct=direct, albedo=other_albedo)
    return colour.to_match(them, keep_luminance=args.keep_luminance), colour


def _other_target(doc: Document, name: str, free: str):
    if name == free:
        raise InputError(f"--match names the target being recolored, {free!r}; name another target")
    try:
        return doc.by_name(name)
    except InputError:
        others = [t.name for t in doc.targets if t.name != free]
        raise InputError(f"--match {name!r}: the session has no such target; its other targets are {others}") from None


def describe(name: str, kappa: np.ndarray, colour: TargetColour | None, exposure: float) -> list[str]:
    """What the request became: κ, the colour before and after, the albedo when known."""
    k = ", ".join(f"{v:.4g}" for v in kappa)
    lines = [f"{name}: κ = ({k})"]
    if colour is not None:
        before, after = (to_hex(c, exposure=exposure) for c in (colour.current, colour.colour(kappa)))
        lines[0] += f", colour {before} → {after}"
        if colour.albedo is not None:
            before = ", ".join(f"{v:.3f}" for v in colour.albedo)
            after = ", ".join(f"{v:.3f}" for v in colour.new_albedo(kappa))
            lines.append(f"{name}: albedo ({before}) → ({after})")
    return lines


def run(args) -> int:
    dtype = output_dtype(args.output, args.half)
    doc, session = open_edit(args.session, "recolor")
    free = doc.target(doc.acquisition.cascade[-1])
    if args.target is not None and args.target != free.name:
        cascade = [doc.target(u).name for u in doc.acquisition.cascade]
        raise InputError(f"target {args.target!r} is not the free target of this session (its cascade is {cascade}, "
                         f"and only the last, {free.name!r}, stays free)")
    new, colour = requested_kappa(args, doc, session)
    warning = convergence(doc.acquisition.raw, new).message() if colour is None else colour.check(new)
    for line in describe(free.name, new, colour, args.exposure):
        print(line, file=sys.stderr)
    if warning:
        print(f"albedit recolor: warning: {warning}", file=sys.stderr)
    doc.set_kappa(free.uid, new)
    set_noise_reduction(doc, session, args.denoise)
    choose_recolor(doc, session, args.noise_aware, "recolor")
    export_image(doc, args.output, dtype=dtype)
    print(f"wrote {args.output}", file=sys.stderr)
    d = doc.acquisition.decomposition
    if doc.trusted is not None:  # the noise-aware recolor's own prediction: noise and the bias it leaves
        done = recolor_trusted(doc.trusted, new)
        sigma = float(done.sigma[doc.trusted.target].mean())
        value = float(np.abs(done.image[doc.trusted.target]).mean())
        print(f"predicted σ on the target: {sigma:.4g} (mean), {sigma / max(value, 1e-30):.1%} of its mean value",
              file=sys.stderr)
    elif d.covariance is not None:  # the camera noise κ^(i+1) amplifies, on the target
        sigma = float(np.sqrt(recolor_variance(d, new))[d.target].mean())
        value = float(np.abs(recolor(d, new)[d.target]).mean())
        print(f"predicted σ on the target: {sigma:.4g} (mean), {sigma / max(value, 1e-30):.1%} of its mean value",
              file=sys.stderr)
    try:
        save_document(doc, session)
    except SessionError as exc:
        print(f"albedit recolor: warning: the edit was not saved in the session ({exc}); {args.output} is complete",
              file=sys.stderr)
    return 0
