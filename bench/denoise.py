"""Noise reduction speed: engine.denoise against calling OpenCV's guided filter per input.

``engine.denoise.denoise_components`` guided-filters every interaction component, per channel,
inside and outside the target. The obvious implementation calls
``cv2.ximgproc.guidedFilter`` twice per (component, channel, region) — the filtered
component and the region's normalisation — recomputing the guide's statistics each time and
filtering the whole image for a small target. Albedit computes each guide's statistics once,
shares the normalisation, works in the region's bounding box and runs channels in parallel.

Run: .venv/bin/python bench/denoise.py [--height 2160 --width 3840 --order 4]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine.decompose import Decomposition  # noqa: E402
from engine.denoise import denoise_components  # noqa: E402


def per_input(d: Decomposition, photo: np.ndarray, radius: int = 4, eps: float = 1e-3) -> np.ndarray:
    """The filtered components, one OpenCV guided filter call per input and normalisation."""
    guide = np.log(np.maximum(photo, 1e-6 * float(photo.max()))).astype(np.float32)
    out = d.components.copy()
    for i in range(d.order):
        regions = ([d.target] if i >= 1 else []) + ([~d.target] if i < d.outside_order else [])
        for region in regions:
            w = region.astype(np.float32)
            for ch in range(3):
                g = guide[..., ch] * w
                num = cv2.ximgproc.guidedFilter(g, d.components[i, ..., ch] * w, radius, eps)
                den = cv2.ximgproc.guidedFilter(g, w, radius, eps)
                out[i, ..., ch] = np.where(region & (den > 1e-3), num / np.maximum(den, 1e-3), out[i, ..., ch])
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--height", type=int, default=2160)
    p.add_argument("--width", type=int, default=3840)
    p.add_argument("--order", type=int, default=4)
    a = p.parse_args(argv)
    rng = np.random.default_rng(0)
    h, w, k = a.height, a.width, a.order
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    base = np.stack([0.5 + 0.3 * np.sin(xx / 97), 0.5 + 0.3 * np.cos(yy / 71), 0.5 + 0.2 * np.sin((xx + yy) / 53)], -1)
    comps = np.stack([base * np.float32(0.45**i) + rng.random((h, w, 3), dtype=np.float32) * np.float32(0.01 * 0.45**i)
                      for i in range(k)])
    target = (xx > w * 0.6) & (yy > h * 0.2) & (yy < h * 0.8)
    d = Decomposition(comps, np.where(target[..., None], 0, base * np.float32(0.8)).astype(np.float32), target)
    photo = comps.sum(axis=0) + d.unreached
    t = time.perf_counter()
    ours = denoise_components(d, photo)
    t_ours = time.perf_counter() - t
    t = time.perf_counter()
    ref = per_input(d, photo)
    t_ref = time.perf_counter() - t
    agree = float(np.abs(ours.components[1:] - ref[1:]).max() / np.abs(ref).max())
    print(f"denoise {h}x{w} RGB, K = {k}, target {100 * target.mean():.0f} % of the image")
    print(f"{'':>24} {'albedit':>9} {'per input':>10} {'ratio':>6}")
    print(f"{'denoise_components, s':>24} {t_ours:>9.2f} {t_ref:>10.2f} {t_ref / t_ours:>5.1f}x   "
          f"(largest difference {agree:.1e} of the peak)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
