"""Refining a hard mask into coverage (:func:`engine.edge.refine_mask`): accuracy against the rigs' truth, and cost.

Accuracy: the summed squared coverage error over the image against the rig's exact coverage, for the
artist's hard mask as painted and for the refined mask, on the ideal supersampled virtual rigs
(``virtual:cornell``'s right wall: concave corners and an occluder; ``virtual:textured``'s checker wall),
the realistic virtual rig's one noisy frame, and the path-traced rigs (``--mitsuba``).
Cost: seconds and peak traced memory on a synthetic 12-megapixel photograph whose mask has a long,
wavy outline (~600 000 boundary pixels).

Run: nice .venv/bin/python bench/refine.py [--mitsuba] [--quick]
"""

from __future__ import annotations

import argparse
import time
import tracemalloc

import numpy as np

import devices
from engine.acquire import Recorder
from engine.edge import refine_mask

CASES = [("cornell", "right_wall"), ("textured", "checker_wall")]


def photograph(rig) -> np.ndarray:
    """One capture under the scene's own lighting (the projector's flood where the scene has one)."""
    rig.flood()
    flood = rig.projector.image
    rec = Recorder(rig, None)
    return rec.capture("photograph", flood if flood.max() > 0 else rec.black())


def accuracy(args) -> None:
    res = 48 if args.quick else 128
    rows = [(f"virtual:{s}", t, dict(ideal=True, resolution=(res, res), supersample=4)) for s, t in CASES]
    rows += [(f"virtual:{s}", t, dict(resolution=(res, res), supersample=4, seed=3)) for s, t in CASES]
    if args.mitsuba:
        spp = 64 if args.quick else 1024
        rows += [("mitsuba:cornell", "right_wall", dict(ideal=True, resolution=(64, 64), spp=spp)),
                 ("mitsuba:textured", "checker_wall", dict(ideal=True, resolution=(48, 48), spp=spp))]
    print("summed squared coverage error against the rig's exact coverage (mixed pixels: mean |error|)")
    print(f"{'rig':<18} {'target':<13} {'options':<44} {'hard mask':>16} {'refined':>16} {'ratio':>6}")
    for name, target, options in rows:
        with devices.open_rig(name, **options) as rig:
            hard, cov = rig.targets[target], rig.coverage[target]
            soft = refine_mask(hard, photograph(rig))
        mixed = (cov > 0) & (cov < 1)
        e_hard, e_soft = ((hard - cov) ** 2).sum(), ((soft - cov) ** 2).sum()
        cells = [f"{e:.3f} ({np.abs(m - cov)[mixed].mean():.3f})" for e, m in ((e_hard, hard), (e_soft, soft))]
        opts = ", ".join(f"{k}={v}" for k, v in options.items())
        print(f"{name:<18} {target:<13} {opts:<44} {cells[0]:>16} {cells[1]:>16} {e_hard / e_soft:5.1f}x", flush=True)


def cost(args) -> None:
    h, w = (750, 1000) if args.quick else (3000, 4000)
    yy, xx = np.mgrid[:h, :w]
    mask = (xx - w / 2) ** 2 / (0.375 * w) ** 2 + (yy - h / 2) ** 2 / (h / 3) ** 2 < 1
    mask |= ((np.sin(xx / 7.0) + np.sin(yy / 5.0)) > 1.2) & (np.abs(xx - w / 2) < 0.45 * w)
    noise = np.random.default_rng(0).uniform(0.0, 0.1, (h, w, 3))
    photo = (noise + np.where(mask[..., None], [0.2, 0.6, 0.1], [0.7, 0.6, 0.5])).astype(np.float32)
    tracemalloc.start()
    t = time.perf_counter()
    refine_mask(mask, photo)
    seconds, peak = time.perf_counter() - t, tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    print(f"\ncost: {h}×{w} photograph, {h * w / 1e6:.0f} MP: {seconds:.1f} s, peak traced memory {peak / 1e9:.2f} GB "
          f"(the photograph itself {photo.nbytes / 1e9:.2f} GB)")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--mitsuba", action="store_true", help="also the path-traced rigs (1024 spp; slow)")
    parser.add_argument("--quick", action="store_true", help="small images (a smoke run, not the figures)")
    args = parser.parse_args(argv)
    accuracy(args)
    cost(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
