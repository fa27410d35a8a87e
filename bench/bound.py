"""How far the realistic camera's noise lets Figs. 6 and 10 go: measured bounds and the frames it would take.

Issue 15 asks for ≤ 3 % on Fig. 6 (the Cornell box's right wall from green to blue,
κ = (2, 0.125, 8), lamp pixels excluded) on the realistic co-axial rig at 128², and, where a
number is out of reach, a measured bound and the hardware that would reach it. This script
runs the same acquisition (the wall painted as a soft mask refined from a captured
photograph, the app's Refine Edge) with more frames averaged per capture (the one hardware knob a lab
has without a new camera: frames cost time, not money) and prints, per frame count and
averaged over seeds, beside the noise-aware recolor (:mod:`engine.trust`), the plain recolor
and the naive per-pixel recolor:

- *photograph floor*: the noisy photograph times the exact ratio of the true recolor to the
  true photograph, ``I · (T_κ / T_1)``. Every recolor that writes a pixel as its photograph
  times a factor (the plain and the noise-aware recolor both do, Eq. 3–4) keeps the
  photograph's own noise scaled by that factor, so this is their error with perfectly known
  interaction shares: nothing that keeps the photograph's pixels does better on average.
- *unbiased bound, order k*: ``√(Σ Var / Σ T²)`` of the recolor of the order-k weighted (GLS)
  decomposition without constraint. With Gaussian noise the GLS estimate is efficient, so
  this is the Cramér–Rao bound on the error of any unbiased per-pixel estimate of the order-k
  recolor from these observations (the truncated tail adds its bias on top). Order 2 is small
  but biased by the tail; order 4 is the captured order.

Noise-free rows separate what noise costs from what the optics cost: the ideal camera
and projector with the realistic rig's optics (4×4 supersampled pixels, a projector at half
the camera's resolution), the wall painted as a soft or as a hard mask, and the ideal rig
(one sample per pixel, projector at the camera's resolution). Their error is the method's
systematic floor for that optics: no number of frames goes below it.

``--figure 10`` does the same for Fig. 10 (issue target ≤ 2 %): the three-target cascade
(red and blue with their fixed κ, the beige floor free), every target refined into a soft mask.

Run: .venv/bin/python bench/bound.py [--figure 6|10] [--frames 16 64 256] [--seeds 1 2 3] [--resolution 128]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from paper import KAPPA_FIG6, KAPPA_THREE, Bench, naive_per_pixel  # noqa: E402

from engine.acquire.predict import relative_error  # noqa: E402
from engine.decompose import decompose  # noqa: E402
from engine.noise import pack_covariance, unpack_covariance  # noqa: E402
from engine.recolor import recolor, recolor_variance  # noqa: E402
from engine.trust import recolor_trusted  # noqa: E402

#: The captured order of Fig. 6's and Fig. 10's rows.
ORDER = 4
#: Per figure: scene, targets in cascade order, their κ (the last one free), the issue's target.
FIGURES = {
    "6": ("cornell", ("right_wall",), (KAPPA_FIG6,), 0.03),
    "10": ("three", ("red", "blue", "beige"), KAPPA_THREE, 0.02),
}


@dataclass
class Scores:
    """One frame count's errors, one value per seed."""

    naive: list = field(default_factory=list)
    plain: list = field(default_factory=list)
    trusted: list = field(default_factory=list)
    floor: list = field(default_factory=list)
    bound2: list = field(default_factory=list)
    bound4: list = field(default_factory=list)


def unbiased_bound(observations, mask, covariance, kappa, order: int, truth, keep) -> float:
    """``√(Σ Var / Σ T²)`` over ``keep`` of the order-``order`` GLS recolor (no constraint)."""
    full = unpack_covariance(covariance)
    d = decompose(observations[:order], mask, constraint="none",
                  covariance=pack_covariance(full[:order, :order]))
    var = recolor_variance(d, kappa).astype(np.float64)
    return float(np.sqrt(var[keep].sum() / np.square(truth[keep].astype(np.float64)).sum()))


def score(frames: int, seed: int, resolution, *, figure: str = "6", edge: str = "refine", ideal: bool = False,
          **options) -> Scores:
    """Fig. ``figure`` at ``frames`` frames per capture with camera-noise ``seed``, every target
    painted as ``edge`` says (``Bench.painted``; ``options``: the rig's).

    For a cascade (Fig. 10) the photograph floor and the naive recolor use a captured
    photograph (the last target's ``observations[0]`` has the earlier targets recolored), and
    the unbiased bounds are those of the last target's recolor from its observations' covariance
    (which carries the earlier targets' recolor noise).
    """
    scene, names, kappas, _ = FIGURES[figure]
    kappa = kappas[-1]
    s = Scores()
    with Bench(scene, ideal=ideal, resolution=resolution, frames=frames, seed=seed, **options) as b:
        pairs = list(zip(names, kappas, strict=True))
        truth, keep = b.truth(pairs), ~b.lamp
        clean = b.photograph()
        result = b.acquire(list(names), ORDER, fixed_kappa=list(kappas[:-1]), edge=edge)
        acq = result.acquisition
        obs, mask = acq.observations, acq.target.mask
        photo = obs[0] if len(names) == 1 else b.capture_photograph()
        s.naive.append(relative_error(naive_per_pixel(photo, [(b.mask(n), k) for n, k in pairs]), truth, keep))
        s.plain.append(relative_error(recolor(acq.target.decompose(obs), kappa), truth, keep))
        s.trusted.append(relative_error(recolor_trusted(acq.target.trust(obs, acq.covariance), kappa).image,
                                        truth, keep))
        ratio = np.divide(truth, clean, out=np.zeros_like(truth), where=clean > 0)
        s.floor.append(relative_error(photo * ratio, truth, keep))
        s.bound2.append(unbiased_bound(obs, mask, acq.covariance, kappa, 2, truth, keep))
        s.bound4.append(unbiased_bound(obs, mask, acq.covariance, kappa, ORDER, truth, keep))
    return s


def _pct(values) -> str:
    return f"{100 * float(np.mean(values)):.2f} %"


def table(results: dict) -> str:
    """Markdown table: one row per frame count (or noise-free rig), seed means."""
    lines = ["| frames per capture | naive | plain, order 4 | noise-aware | photograph floor "
             "| unbiased bound, order 2 | unbiased bound, order 4 |",
             "|---|---|---|---|---|---|---|"]
    for frames, s in results.items():
        lines.append(f"| {frames} | {_pct(s.naive)} | {_pct(s.plain)} | {_pct(s.trusted)} | {_pct(s.floor)} "
                     f"| {_pct(s.bound2)} | {_pct(s.bound4)} |")
    return "\n".join(lines)


def frames_needed(results: dict[int, Scores], target: float) -> str:
    """The frame count at which the noise-aware error would reach ``target``, by a power law
    fitted to the measured frame counts (error ∝ frames^slope)."""
    f = np.array(sorted(k for k in results if isinstance(k, int)), float)
    e = np.array([np.mean(results[int(x)].trusted) for x in f])
    if len(f) < 2:
        return "one frame count: no fit"
    slope, icept = np.polyfit(np.log(f), np.log(e), 1)
    if slope >= 0:
        return f"the noise-aware error does not fall with frames (slope {slope:.2f}): more frames will not reach it"
    need = float(np.exp((np.log(target) - icept) / slope))
    return (f"noise-aware error ∝ frames^{slope:.2f}: {100 * target:.0f} % at ≈ {need:.0f} frames per capture "
            f"(measured {', '.join(str(int(x)) for x in f)})")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, nargs="+", default=[16, 64, 256])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--resolution", type=int, default=128)
    parser.add_argument("--figure", choices=sorted(FIGURES), default="6",
                        help="6: the Cornell box's wall; 10: the three-target cascade")
    args = parser.parse_args(argv)
    fig = args.figure
    start = time.perf_counter()
    results: dict = {}
    for frames in args.frames:
        for seed in args.seeds:
            one = score(frames, seed, (args.resolution, args.resolution), figure=fig)
            total = results.setdefault(frames, Scores())
            for name in vars(total):
                getattr(total, name).extend(getattr(one, name))
            print(f"frames {frames} seed {seed}: noise-aware {_pct(one.trusted)}, floor {_pct(one.floor)}, "
                  f"bound(4) {_pct(one.bound4)}", flush=True)
    res = (args.resolution, args.resolution)
    half = (args.resolution // 2, args.resolution // 2)
    for edge in ("refine", "hard"):
        results[f"noise-free, realistic optics, {edge} mask"] = score(1, 0, res, figure=fig, edge=edge, ideal=True,
                                                                     supersample=4, projector_resolution=half)
    results["noise-free, ideal rig, hard mask"] = score(1, 0, res, figure=fig, edge="hard", ideal=True)
    _, names, kappas, target = FIGURES[fig]
    print()
    print(f"Fig. {fig}, realistic co-axial rig, {args.resolution}², κ = "
          f"{', '.join(f'{n} {k}' for n, k in zip(names, kappas, strict=True))}, lamp excluded, "
          f"seeds {args.seeds} ({time.perf_counter() - start:.0f} s)")
    print(table(results))
    print(frames_needed(results, target))


if __name__ == "__main__":
    main()
