"""``albedit recolor``: recolor a captured session's (last) target and write the image."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from app.cli._args import kappa
from engine.denoise import denoise_components
from engine.errors import InputError, SessionError
from engine.imageio import to_display, write_image
from engine.recolor import recolor, recolor_variance
from engine.session import Session
from engine.workflow import load_decomposition


def add_arguments(parser) -> None:
    parser.add_argument("session", type=Path, help="a captured session folder")
    parser.add_argument("--target", default=None, help="the free (last) target of the session's plan (checked)")
    parser.add_argument("--kappa", type=kappa, required=True, metavar="R,G,B", help="albedo scale of the target")
    parser.add_argument("-o", "--output", type=Path, required=True, help="output image (.exr, .tif, .png)")
    parser.add_argument("--half", action="store_true", help="EXR: write half floats")
    add_denoise_option(parser)


def add_denoise_option(parser) -> None:
    """``--denoise RADIUS``: guided-filter the interaction components (0 = off)."""
    parser.add_argument("--denoise", type=int, default=0, metavar="RADIUS",
                        help="guided-filter radius for the interaction components, 0 = off (default %(default)s)")


def denoised(session: Session, d, radius: int):
    """The decomposition with its interaction components denoised, guided by the photograph."""
    if radius <= 0:
        return d
    photo = next((session.read_capture(r.name) for r in session.captures if r.meta.get("kind") == "photograph"), None)
    if photo is None:
        raise SessionError(f"session {session.path} has no photograph capture to guide the denoising")
    return denoise_components(d, photo, radius=radius)


def decomposition_for(session: Session, target: str | None):
    """Load (or recompute through a replay rig) the session's decomposition."""
    plan = session.state.get("plan") or {}
    free = (plan.get("targets") or [None])[-1]
    if target is not None and free is not None and target != free:
        raise InputError(
            f"target {target!r} is not the free target of this session (its plan recolors {plan.get('targets')}, "
            f"and only the last, {free!r}, stays free)"
        )
    try:
        return load_decomposition(session), plan
    except SessionError:
        if not plan:
            raise
        import devices  # no cached decomposition: recompute it offline from the captures

        with devices.open_rig(f"replay:{session.path}") as rig:
            return load_decomposition(session, rig=rig), plan


def write_edit(path: Path, image, *, plan: dict, kappa_value, half: bool = False) -> None:
    """Write a recolored image with the edit recorded in its metadata."""
    edit = {"targets": plan.get("targets"), "fixed_kappa": plan.get("fixed_kappa"), "kappa": list(map(float, kappa_value)), "order": plan.get("order")}
    suffix = path.suffix.lower()
    dtype = "half" if (half and suffix == ".exr") else ("uint8" if suffix == ".png" else "float")
    write_image(path, image if dtype != "uint8" else to_display(image), dtype=dtype, metadata={"albedit.edit": edit})


def run(args) -> int:
    session = Session.open(args.session)
    d, plan = decomposition_for(session, args.target)
    out = recolor(denoised(session, d, args.denoise), args.kappa)
    write_edit(args.output, out, plan=plan, kappa_value=args.kappa, half=args.half)
    session.update(edit={"kappa": args.kappa.tolist()})
    print(f"wrote {args.output}", file=sys.stderr)
    if d.covariance is not None and args.denoise <= 0:  # the camera noise κ^(i+1) amplifies, on the target
        sigma = float(np.sqrt(recolor_variance(d, args.kappa))[d.target].mean())
        value = float(np.abs(out[d.target]).mean())
        print(f"predicted σ on the target: {sigma:.4g} (mean), {sigma / max(value, 1e-30):.1%} of its mean value",
              file=sys.stderr)
    return 0
