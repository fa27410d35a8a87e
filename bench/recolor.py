"""Recolor speed: Albedit's tiled, threaded Horner pass against the obvious numpy sum.

Full-resolution recolor of a K = 5 decomposition (default 24 megapixels, RGB) and the live
preview path (a 1280x720 pre-packed copy), each compared with the direct expression
``L̄_d + Σ κ^{i+1} c_i`` evaluated with whole-image numpy temporaries; and the one-off
packing of that preview copy (area averaging) against a padded reshape-and-sum.

Run: .venv/bin/python bench/recolor.py [--megapixels 24]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from engine.decompose import Decomposition
from engine.recolor import prepare_preview, recolor, recolor_preview


def naive(d, kappa):
    out = d.unreached.copy()
    for i in range(d.order):
        out = out + (np.asarray(kappa, np.float32) ** (i + 1)) * d.components[i]
    return out


def padded_area_average(array, factor):
    """The obvious block mean of axes 1 and 2: pad to whole blocks, reshape, sum, divide by counts."""
    k, h, w, c = array.shape
    hh, ww = -(-h // factor), -(-w // factor)
    padded = np.pad(array, [(0, 0), (0, hh * factor - h), (0, ww * factor - w), (0, 0)])
    total = padded.reshape(k, hh, factor, ww, factor, c).sum(axis=(2, 4))
    counts = np.pad(np.ones((h, w), np.float32), [(0, hh * factor - h), (0, ww * factor - w)])
    return total / counts.reshape(hh, factor, ww, factor).sum(axis=(1, 3))[None, :, :, None]


def best_of(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times), float(np.percentile(times, 95))


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--megapixels", type=float, default=24.0)
    parser.add_argument("--order", type=int, default=5)
    args = parser.parse_args()
    h = 4000
    w = int(args.megapixels * 1e6 / h)
    rng = np.random.default_rng(0)
    comps = rng.random((args.order, h, w, 3), dtype=np.float32)
    d = Decomposition(comps, rng.random((h, w, 3), dtype=np.float32), rng.random((h, w)) > 0.5)
    kappa = (2.0, 0.125, 8.0)
    ours, _ = best_of(lambda: recolor(d, kappa), 3)
    ref, _ = best_of(lambda: naive(d, kappa), 2)
    print(f"full resolution {h}x{w} RGB ({h * w / 1e6:.0f} MP), K = {args.order}")
    print(f"{'':>22} {'albedit':>9} {'numpy sum':>10} {'ratio':>6}")
    print(f"{'recolor, s':>22} {ours:>9.3f} {ref:>10.3f} {ref / ours:>5.1f}x")
    pack = prepare_preview(d, (720, 1280))
    small = pack.decomposition
    factor = -(-h // pack.shape[0])
    pr_ours, _ = best_of(lambda: prepare_preview(d, (720, 1280)), 2)
    pr_ref, _ = best_of(lambda: padded_area_average(d.components, factor), 1)
    print(f"{'pack preview, s':>22} {pr_ours:>9.3f} {pr_ref:>10.3f} {pr_ref / pr_ours:>5.1f}x   "
          "(numpy: padded reshape-sum)")
    p_ours, p95 = best_of(lambda: recolor_preview(pack, kappa), 50)
    p_ref, _ = best_of(lambda: naive(small, kappa), 20)
    label = "preview " + "x".join(map(str, pack.shape)) + ", ms"
    print(f"{label:>22} {p_ours * 1e3:>9.2f} {p_ref * 1e3:>10.2f} {p_ref / p_ours:>5.1f}x   (p95 {p95 * 1e3:.2f} ms)")


if __name__ == "__main__":
    main()
