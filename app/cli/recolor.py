"""``albedit recolor``: recolor a captured session's free (last) target, write the image, save the edit."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from app.cli._args import kappa, radius
from app.model.document import Document
from app.model.files import export_image, open_document, save_document
from engine.errors import InputError, SessionError
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
    """``--denoise RADIUS``: guided-filter the interaction components (0 = off; default: the saved edit's)."""
    parser.add_argument("--denoise", type=radius, default=None, metavar="RADIUS",
                        help="guided-filter radius for the interaction components, 0 = off "
                             "(default: the saved edit's, else off)")


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


def write(doc: Document, path: Path, *, half: bool) -> None:
    """Export the document's recolored image (float EXR or TIFF, half EXR, or 8-bit sRGB PNG) with its edit."""
    suffix = path.suffix.lower()
    dtype = "half" if (half and suffix == ".exr") else ("uint8" if suffix == ".png" else "float")
    export_image(doc, path, dtype=dtype)


def run(args) -> int:
    doc, session = open_edit(args.session, "recolor")
    free = doc.target(doc.acquisition.cascade[-1])
    if args.target is not None and args.target != free.name:
        cascade = [doc.target(u).name for u in doc.acquisition.cascade]
        raise InputError(f"target {args.target!r} is not the free target of this session (its cascade is {cascade}, "
                         f"and only the last, {free.name!r}, stays free)")
    doc.set_kappa(free.uid, args.kappa)
    set_noise_reduction(doc, session, args.denoise)
    write(doc, args.output, half=args.half)
    print(f"wrote {args.output}", file=sys.stderr)
    d = doc.acquisition.decomposition
    if d.covariance is not None:  # the camera noise κ^(i+1) amplifies, on the target
        sigma = float(np.sqrt(recolor_variance(d, args.kappa))[d.target].mean())
        value = float(np.abs(recolor(d, args.kappa)[d.target]).mean())
        print(f"predicted σ on the target: {sigma:.4g} (mean), {sigma / max(value, 1e-30):.1%} of its mean value",
              file=sys.stderr)
    try:
        save_document(doc, session)
    except SessionError as exc:
        print(f"albedit recolor: warning: the edit was not saved in the session ({exc}); {args.output} is complete",
              file=sys.stderr)
    return 0
