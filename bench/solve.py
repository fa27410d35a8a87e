"""Decomposition speed: Albedit's compiled KKT solver against the obvious alternatives.

Prints, for K = 3..6, noise-free and with 1 % noise: throughput of engine.decompose, of a
vectorised-numpy version of the same active-set method (no compiled kernel), and of
scipy.optimize.nnls called once per pixel-channel on the same reparametrised problem (on a
subsample), with ratios. Then the weighted (GLS) decomposition — each pixel-channel whitened
by its own noise covariance — beside the unweighted one on the same noisy stacks, and the
noise-aware recolor's preparation (engine.trust). Then one full 24-megapixel RGB K = 5 stack
with 1 % noise: wall time and peak memory (tracemalloc) relative to the input stack.

Run: .venv/bin/python bench/solve.py [--full-mp 24] [--skip-full]
"""

from __future__ import annotations

import argparse
import time
import tracemalloc

import numpy as np
from scipy.optimize import nnls

from engine.decompose import decompose
from engine.figurate import transport_matrix
from engine.solve import ConeSolver, cone_basis


def synthetic_stack(order, h, w, *, noise, rng):
    """A (K, H, W, 3) float32 stack from decaying components, target = centre half."""
    c = 3
    base = rng.uniform(0.2, 1.0, (h, w, c)).astype(np.float32)
    comps = np.empty((order, h, w, c), np.float32)
    comps[0] = base
    for i in range(1, order):
        comps[i] = comps[i - 1] * rng.uniform(0.05, 0.4, (h, w, c)).astype(np.float32)
    m = transport_matrix(order).astype(np.float32)
    obs = np.tensordot(m, comps, axes=1)
    del comps
    if noise:
        for r in range(order):
            obs[r] += rng.standard_normal((h, w, c), dtype=np.float32) * (noise * obs[0])
    target = np.zeros((h, w), bool)
    target[h // 4 : 3 * h // 4, w // 4 : 3 * w // 4] = True
    return obs, target


def numpy_active_set(a, basis, b, tol=1e-6):
    """The same KKT enumeration in vectorised numpy: one matrix product per active set,
    solved columns removed between trials (what Albedit did before the compiled kernel)."""
    solver = ConeSolver(a, basis)
    tests, maps = solver.kernel_arrays()
    order = solver.rank_sets(b, tol)
    x = np.zeros((a.shape[1], b.shape[1]), b.dtype)
    remaining = np.arange(b.shape[1])
    rest = b
    for s in order:
        if remaining.size == 0:
            break
        y = tests[s].astype(b.dtype) @ rest
        ok = (y >= -tol * np.abs(rest).max(axis=0)).all(axis=0)
        x[:, remaining[ok]] = maps[s].astype(b.dtype) @ y[:, ok]
        remaining, rest = remaining[~ok], rest[:, ~ok]
    return x


def scipy_per_column(a, basis, b):
    g = a @ basis
    out = np.empty((a.shape[1], b.shape[1]))
    for j in range(b.shape[1]):
        d, _ = nnls(g, b[:, j].astype(np.float64), maxiter=50 * g.shape[1])
        out[:, j] = basis @ d
    return out


def rate(seconds, count):
    return count / seconds / 1e6


def table(h, w, sub):
    rng = np.random.default_rng(0)
    print(f"\nthroughput on {h}x{w} RGB ({h * w * 3 / 1e6:.1f} M pixel-channels); scipy on {sub} columns")
    print(f"{'K':>2} {'noise':>6} | {'albedit M/s':>11} {'numpy M/s':>10} {'scipy M/s':>10} "
          f"| {'vs numpy':>8} {'vs scipy':>8}")
    decompose(*synthetic_stack(3, 8, 8, noise=0.01, rng=rng))  # compile the kernel once
    for order in (3, 4, 5, 6):
        for noise in (0.0, 0.01):
            obs, target = synthetic_stack(order, h, w, noise=noise, rng=rng)
            t0 = time.perf_counter()
            decompose(obs, target)
            ours = rate(time.perf_counter() - t0, obs[0].size)
            b = obs.reshape(order, -1)
            a, basis = transport_matrix(order), cone_basis(order, "ordered")
            t0 = time.perf_counter()
            numpy_active_set(a, basis, b)
            vec = rate(time.perf_counter() - t0, b.shape[1])
            cols = b[:, :: max(1, b.shape[1] // sub)][:, :sub]
            t0 = time.perf_counter()
            scipy_per_column(a, basis, cols)
            ref = rate(time.perf_counter() - t0, cols.shape[1])
            print(f"{order:>2} {noise:>6.0%} | {ours:>11.2f} {vec:>10.2f} {ref:>10.3f} "
                  f"| {ours / vec:>7.1f}x {ours / ref:>7.0f}x")


def weighted_table(h, w):
    """GLS (per-column covariance) beside the unweighted solver, and the noise-aware preparation."""
    from engine.noise import pack_covariance
    from engine.trust import decompose_orders, prepare_trust, recolor_trusted

    rng = np.random.default_rng(2)
    print(f"\nweighted decomposition on {h}x{w} RGB, 1 % noise, covariance diagonal per pixel-channel")
    print(f"{'K':>2} | {'unweighted M/s':>14} {'GLS M/s':>8} | {'GLS time ratio':>16} "
          f"| {'unconstrained: unweighted M/s':>29} {'GLS M/s':>8} {'time ratio':>10} {'I/O ratio':>9} "
          f"| {'noise-aware prep s':>18} {'recolor s':>9}")
    small, target = synthetic_stack(3, 8, 8, noise=0.01, rng=rng)
    decompose(small, target, covariance=np.full((6,) + small.shape[1:], 1e-4, np.float32))  # compile once
    for order in (3, 4, 5, 6):
        obs, target = synthetic_stack(order, h, w, noise=0.01, rng=rng)
        full_cov = np.zeros((order, order) + obs.shape[1:], np.float32)
        for r in range(order):
            full_cov[r, r] = np.square(0.01 * obs[0])
        cov = pack_covariance(full_cov)
        del full_cov
        t0 = time.perf_counter()
        decompose(obs, target)
        plain = rate(time.perf_counter() - t0, obs[0].size)
        t0 = time.perf_counter()
        decompose(obs, target, covariance=cov)
        gls = rate(time.perf_counter() - t0, obs[0].size)
        t0 = time.perf_counter()
        decompose(obs, target, constraint="none")
        plain_none = rate(time.perf_counter() - t0, obs[0].size)
        t0 = time.perf_counter()
        decompose(obs, target, constraint="none", covariance=cov)
        gls_none = rate(time.perf_counter() - t0, obs[0].size)
        # bytes each solve must read and write per pixel-channel: K observations in, K components
        # out; GLS adds K(K+1)/2 covariance planes in and as many out (the floor of its time ratio
        # where memory bandwidth bounds both)
        io = (2 * order + order * (order + 1)) / (2 * order)
        t0 = time.perf_counter()
        trusted = prepare_trust(decompose_orders(obs, target, cov), obs[0])
        prep = time.perf_counter() - t0
        t0 = time.perf_counter()
        recolor_trusted(trusted, (2.0, 0.125, 8.0))
        rec = time.perf_counter() - t0
        print(f"{order:>2} | {plain:>14.2f} {gls:>8.2f} | {plain / gls:>15.1f}x | {plain_none:>29.2f} {gls_none:>8.2f} "
              f"{plain_none / gls_none:>9.1f}x {io:>8.1f}x | {prep:>18.1f} {rec:>9.2f}")


def full(megapixels):
    h = 4000
    w = int(megapixels * 1e6 / h)
    rng = np.random.default_rng(1)
    obs, target = synthetic_stack(5, h, w, noise=0.01, rng=rng)
    tracemalloc.start()
    t0 = time.perf_counter()
    d = decompose(obs, target)
    seconds = time.perf_counter() - t0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    from engine.recolor import recolor

    t0 = time.perf_counter()
    recolor(d, (2.0, 0.125, 8.0))
    rec = time.perf_counter() - t0
    print(f"\nfull {h}x{w} RGB ({h * w / 1e6:.0f} MP), K = 5, 1 % noise:")
    print(f"  decompose {seconds:.1f} s = {rate(seconds, obs[0].size):.2f} M pixel-channels/s")
    print(f"  peak memory allocated during decompose {peak / 2**30:.2f} GiB "
          f"= {peak / obs.nbytes:.2f} x the input stack ({obs.nbytes / 2**30:.2f} GiB)")
    print(f"  recolor {rec:.2f} s")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, nargs=2, default=(1000, 1000), metavar=("H", "W"))
    parser.add_argument("--scipy-columns", type=int, default=3000)
    parser.add_argument("--full-mp", type=float, default=24.0)
    parser.add_argument("--skip-full", action="store_true")
    args = parser.parse_args()
    table(*args.size, args.scipy_columns)
    weighted_table(*args.size)
    if not args.skip_full:
        full(args.full_mp)


if __name__ == "__main__":
    main()
