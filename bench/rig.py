"""Virtual rig speed: set-up and capture, against the obvious alternatives.

Prints a table for the Cornell scene at 256² and 512²:

* set-up of the realistic rig (mixed pixels supersampled 4×4, projector at half the camera's
  resolution), cold (nothing cached) — against one sample per pixel —, cold with the scene's
  form factors already cached (a new resolution or projector pose), and cached;
* per-pixel form factors — the obvious alternative to interpolating node form factors —
  timed on a random subset of pixels and extrapolated to all of them;
* one capture (ideal and realistic camera), against re-solving the radiosity system per
  capture (factorising it again, as a renderer without pre-factoring would) and against
  gathering bounce by bounce until converged (Jacobi iteration to 1e-6).

Run: .venv/bin/python bench/rig.py [--sizes 256 512] [--scene cornell]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from functools import partial
from pathlib import Path

import numpy as np

from devices.virtual import open_rig
from devices.virtual.geometry import blocker_table, polygon_form_factor
from devices.virtual.setup import _patch_corners, _sub_points, _visibility
from devices.virtual.transport import Resolvent, gather


def _timed(fn, repeat=1):
    best = np.inf
    out = None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def _median_time(fn, repeat):
    fn()
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times))


def per_pixel_form_factors(rig, n_pixels: int, rng) -> float:
    """Seconds to compute exact form factors (with visibility) from ``n_pixels`` pixel samples
    to every patch: the alternative to node interpolation."""
    s, scene = rig.setup, rig.scene
    quads = scene.quads
    normal = quads.normal
    corners = _patch_corners(quads, s.patch_nu, s.patch_nv)
    centres = corners.mean(axis=1)
    subs = _sub_points(corners, 3)
    blockers = blocker_table(quads)
    live = np.flatnonzero(s.quad[:s.n_pixels] >= 0)
    pick = rng.choice(live, size=min(n_pixels, live.size), replace=False)
    n_p = len(corners)
    t = time.perf_counter()
    for k in range(0, len(pick), 64):
        rows = pick[k:k + 64]
        r, c = np.repeat(rows, n_p), np.tile(np.arange(n_p), len(rows))
        keep = (s.quad[r] != s.patch_quad[c]) & (
            np.einsum("ij,ij->i", s.points[r] - centres[c], normal[s.patch_quad[c]]) > 0)
        r, c = r[keep], c[keep]
        f = polygon_form_factor(s.points[r], normal[s.quad[r]], corners[c])
        pos = f > 0
        r, c = r[pos], c[pos]
        _visibility(s.points[r], normal[s.quad[r]], subs[c], normal[s.patch_quad[c]], quads,
                    s.quad[r] * len(quads) + s.patch_quad[c], blockers)
    return time.perf_counter() - t


def jacobi(rig, e, tol=1e-6, max_iter=500):
    """L <- rho (E + G Mavg L) until the update is below ``tol`` of the radiance."""
    rho = rig._renderer.rho.astype(e.dtype)
    lo = rho * e
    out = lo
    for _ in range(max_iter):
        nxt = lo + rho * gather(rig.setup, out).astype(e.dtype)
        if np.abs(nxt - out).max() <= tol * np.abs(nxt).max():
            return nxt
        out = nxt
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[256, 512])
    ap.add_argument("--scene", default="cornell")
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for size in args.sizes:
            res = (size, size)
            fresh = Path(tmp) / f"fresh{size}"
            t_cold, _ = _timed(partial(open_rig, args.scene, resolution=res, cache_dir=fresh))
            t_cold1, _ = _timed(partial(open_rig, args.scene, resolution=res, cache_dir=Path(tmp) / f"one{size}",
                                        supersample=1))
            shared = Path(tmp) / "shared"
            open_rig(args.scene, resolution=(32, 32), cache_dir=shared)  # caches the form factors
            t_ff, _ = _timed(partial(open_rig, args.scene, resolution=res, cache_dir=shared))
            t_cached, rig = _timed(partial(open_rig, args.scene, resolution=res, cache_dir=shared), repeat=3)
            n_sub = 1000
            t_sub = per_pixel_form_factors(rig, n_sub, rng)
            n_live = int((rig.setup.quad[:rig.setup.n_pixels] >= 0).sum())
            t_pp = t_sub * n_live / n_sub
            rows.append((f"set-up {size}²: cold (nothing cached)", t_cold, None, None))
            rows.append(("  alt: cold, one sample per pixel (supersample=1)", t_cold1, t_cold1 / t_cold,
                         "alt / cold set-up"))
            rows.append((f"set-up {size}²: form factors cached", t_ff, None, None))
            rows.append((f"set-up {size}²: cached", t_cached, None, None))
            rows.append((f"  alt: per-pixel form factors (extrap. from {n_sub} px)", t_pp, t_pp / t_cold,
                         "alt / cold set-up"))

            for ideal in (True, False):
                r = open_rig(args.scene, resolution=res, cache_dir=shared, ideal=ideal)
                r.projector.show(rng.uniform(0, 1, r.projector.resolution + (3,)).astype(np.float32))
                t_cap = _median_time(r.camera.capture, args.repeat)
                rows.append((f"capture {size}² ({'ideal' if ideal else 'realistic'} camera)", t_cap, None, None))
            pattern = rng.uniform(0, 1, rig.projector.resolution + (3,)).astype(np.float32)
            ren = rig._renderer
            rig.projector.show(pattern)
            e = ren.direct_light(rig.projector.emitted, ambient=True)
            t_solve = _median_time(partial(ren.base.solve, e), args.repeat)
            t_refactor = _median_time(lambda rig=rig, ren=ren, e=e: Resolvent(rig.setup, ren.rho).solve(e),
                                      max(2, args.repeat // 2))
            t_jacobi = _median_time(partial(jacobi, rig, e), max(2, args.repeat // 2))
            err = np.abs(jacobi(rig, e) - ren.base.solve(e)).max() / np.abs(ren.base.solve(e)).max()
            rows.append((f"  transport solve {size}² (pre-factored)", t_solve, None, None))
            rows.append(("  alt: re-factor per capture", t_refactor, t_refactor / t_solve, "alt / pre-factored"))
            rows.append((f"  alt: bounce iteration to 1e-6 (err {err:.1e})", t_jacobi, t_jacobi / t_solve,
                         "alt / pre-factored"))
            s = rig.setup
            rows.append((f"  ({s.n_pixels} pixels, {s.n_visible - s.n_pixels} sub-samples of "
                         f"{len(s.sub_pixel)} mixed pixels, {len(s.quad) - s.n_visible} hidden samples, "
                         f"{s.mavg.shape[0]} patches, {s.gn.shape[0]} nodes)", None, None, None))
    print(f"{'':60s} {'time':>10s} {'ratio':>8s}")
    for name, t, ratio, what in rows:
        ts = "" if t is None else (f"{t * 1e3:8.1f} ms" if t < 1 else f"{t:8.2f} s ")
        rs = "" if ratio is None else f"{ratio:7.1f}x  ({what})"
        print(f"{name:60s} {ts:>10s} {rs}")


if __name__ == "__main__":
    main()
