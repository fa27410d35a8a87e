"""Noise-aware recolor speed: what the app's preview and export pay for it, beside the plain recolor.

An order-K acquisition of a synthetic target (geometric interreflections, every observation
with its camera-noise variance) is made once: :func:`engine.trust.each_order` and
:func:`engine.trust.prepare_trust` (the one-off preparation, per acquisition; its time and peak
memory beside the same with every order's decomposition held at once), then per κ
:func:`engine.trust.recolor_trusted` at full resolution against the plain recolor of the
same acquisition (:func:`engine.recolor.recolor`, export) and its screen-sized preview
(:func:`engine.recolor.recolor_preview`, a slider event).

Run: .venv/bin/python bench/trusted.py [--size 512 512] [--order 4] [--repeats 3]
"""

from __future__ import annotations

import argparse
import time
import tracemalloc

import numpy as np

from engine.decompose import decompose
from engine.figurate import transport_matrix
from engine.noise import pack_covariance
from engine.recolor import prepare_preview, recolor, recolor_preview
from engine.trust import decompose_orders, each_order, prepare_trust, recolor_trusted

KAPPA = (2.0, 0.125, 8.0)


def acquisition(h: int, w: int, order: int, seed: int = 0):
    """Observations of a target whose components halve per interaction, with white noise of known variance."""
    rng = np.random.default_rng(seed)
    target = np.zeros((h, w), bool)
    target[h // 4: 3 * h // 4, w // 4: 3 * w // 4] = True
    y, x = np.mgrid[0:h, 0:w]
    base = (0.4 + 0.3 * np.sin(x / max(w, 1) * 3)[..., None] * np.array([1.0, 0.8, 0.6]) + 0.1 * (y / h)[..., None])
    comps = np.stack([base * 0.5**i for i in range(order)]).astype(np.float32)
    a = transport_matrix(order)
    clean = np.einsum("ij,jhwc->ihwc", a, comps)
    variance = (1e-4 * np.abs(clean) + 1e-6).astype(np.float32)
    obs = (clean + rng.normal(size=clean.shape) * np.sqrt(variance)).astype(np.float32)
    full = np.zeros((order, order) + obs.shape[1:], np.float32)
    for i in range(order):
        full[i, i] = variance[i]
    return obs, target, pack_covariance(full)


def timed(fn, repeats: int) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def measured(fn) -> tuple[float, object, int]:
    """Seconds, result and peak bytes allocated (tracemalloc) of one call."""
    tracemalloc.start()
    t0 = time.perf_counter()
    out = fn()
    seconds = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return seconds, out, peak


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, nargs=2, default=(512, 512), metavar=("H", "W"))
    parser.add_argument("--order", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--preview", type=int, nargs=2, default=(540, 960), metavar=("H", "W"),
                        help="the preview's size cap (a screen)")
    args = parser.parse_args()
    h, w = args.size
    obs, target, cov = acquisition(h, w, args.order)
    rows = slice(h // 4, h // 4 + 16)  # target and surroundings: compile the kernel before timing
    decompose(obs[:2, rows], target[rows], constraint="none", covariance=cov[:3, rows])
    t_prep, trusted, peak = measured(lambda: prepare_trust(each_order(obs, target, cov), obs[0]))
    t_list, _, peak_list = measured(lambda: prepare_trust(decompose_orders(obs, target, cov), obs[0]))
    held = obs.nbytes + cov.nbytes
    plain = decompose(obs, target, covariance=cov)
    t_first, _ = timed(lambda: recolor_trusted(trusted, KAPPA), 1)  # gathers each region's pixels once
    t_trusted, _ = timed(lambda: recolor_trusted(trusted, KAPPA), args.repeats)
    t_plain, _ = timed(lambda: recolor(plain, KAPPA), args.repeats)
    factor = max(1, int(np.ceil(max(h / args.preview[0], w / args.preview[1]))))
    pack = prepare_preview(plain, (-(-h // factor), -(-w // factor)))
    t_preview, _ = timed(lambda: recolor_preview(pack, KAPPA), max(args.repeats, 5))
    mp = h * w / 1e6
    print(f"{h}x{w} ({mp:.2f} MP), order {args.order}, kappa {KAPPA}")
    print(f"prepare (once per acquisition: each_order + prepare_trust):       {t_prep * 1e3:9.1f} ms  "
          f"peak {peak / 2**30:.2f} GiB = {peak / held:.1f}x the observations and covariance ({held / 2**30:.2f} GiB)")
    print(f"  every order held at once (decompose_orders list):              {t_list * 1e3:9.1f} ms  "
          f"peak {peak_list / 2**30:.2f} GiB = {peak_list / held:.1f}x; one at a time: {peak_list / peak:.2f}x less")
    print(f"recolor_trusted, first kappa (gathers the regions once):        {t_first * 1e3:9.1f} ms")
    print(f"recolor_trusted (per kappa, full resolution):                   {t_trusted * 1e3:9.1f} ms")
    print(f"plain recolor (per kappa, full resolution):                     {t_plain * 1e3:9.1f} ms  "
          f"trusted/plain {t_trusted / max(t_plain, 1e-9):.1f}x")
    print(f"plain preview recolor ({pack.shape[0]}x{pack.shape[1]}, a slider event):          "
          f"{t_preview * 1e3:9.2f} ms  trusted/preview {t_trusted / max(t_preview, 1e-9):.0f}x")


if __name__ == "__main__":
    main()
