"""``albedit bench``: run the engine benchmarks in bench/ from a source checkout."""

from __future__ import annotations

import argparse
import runpy
import sys
from pathlib import Path

from engine.errors import InputError

NAMES = ("solve", "recolor", "rig", "preview", "paper", "graycode", "denoise", "albedo", "loopback", "session",
         "optics", "overlay", "trusted", "bound", "refine", "fill")


def add_arguments(parser) -> None:
    parser.add_argument("name", choices=NAMES, help="which benchmark")
    parser.add_argument("rest", nargs=argparse.REMAINDER, help="the benchmark's own arguments (its --help lists them)")


def run(args) -> int:
    path = Path(__file__).resolve().parents[2] / "bench" / f"{args.name}.py"
    if not path.exists():
        raise InputError(f"benchmark {args.name!r} not found at {path}: benchmarks run from a source checkout")
    sys.argv = [str(path), *args.rest]
    runpy.run_path(str(path), run_name="__main__")
    return 0
