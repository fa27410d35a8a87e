"""Real optics: a target's edge, glossy and textured scenes, against the naive and previous recolor.

Every figure of issue 13's "numbers to reach", each beside the naive per-pixel recolor and the
previous behaviour (a hard mask, emitted and decomposed as target) in the same run:

* ``cornell`` — path-traced Cornell box (``mitsuba:cornell``), the right wall painted as the
  rig's hard mask (pixels at least half wall), order 4: error over the wall *with* its edge
  pixels against its interior, for κ = (0.5, 1.2, 0.8) and the paper's (2, 0.125, 8) with
  noise reduction (before the edge blend, the edge pixels' neighbour shares fitted along the
  edge; beside it the previous behaviours, not fitted and the blended decomposition filtered),
  and the whole image against the render's own noise floor (two independent truth renders).
  "soft" refines the hard mask from the photograph (:func:`engine.edge.refine_mask`); "soft
  (true coverage)" uses the rig's exact coverage.
* ``noise`` — the same box, κ = (2, 0.125, 8): where its error comes from (noise reduction before or
  after the edge blend, the noise-aware recolor with and without the Monte Carlo variance).
* ``virtual`` — the same on the supersampled ideal virtual Cornell box (128², 4×4), the true
  coverage also without the edge's stand-in (:func:`engine.edge.stand_in`, the previous behaviour),
  and the soft masks with noise reduction (radius 4) for κ = (2, 0.125, 8).
* ``edge`` — what the edge still costs on that box (48²): oracles that re-emit the edge strip
  exactly or take the edge pixels' neighbour part from the truth.
* ``posed`` — a projector beside the camera (``projector="offset"``, 0.25 m to its right) against
  the co-axial one, on the supersampled ideal virtual wedge (24² and 48², left wall, order 4):
  with and without :func:`engine.calibrate.projector_spread` (the direct light of each
  re-emission completed where projector pixels straddle camera pixels and light edge pixels);
  then the path-traced wedge (``mitsuba:wedge``, no coat), co-axial and posed.
* ``realistic`` — the realistic demo's rig (``albedit demo --realistic``: virtual Cornell box
  128², 4×4 supersampled pixels, projector at half the camera's resolution, camera noise, 16
  frames a capture), κ = (2, 0.125, 8), noise reduction sized from the measured noise as the
  demo does: the previous behaviour (hard mask, no direct-light completion), then each change.
* ``fig13`` — the glossy-coated wedge (``mitsuba:wedge``): recolor error (κ = (1.5, 4.5, 0.5),
  order 4) over specular share × roughness against two truths — the paint under the coat
  recolored, and every interaction with the wall (gloss too) weighted by κ, as the paper's
  Fig. 13 counts interaction components — then the hard mask and a posed projector beside the
  co-axial one, and the render noise (spp) of a sharp coat. ``--fig13-coat`` (both parts): ``tinted``
  (default: the coat's specular reflectance is the paint's, so the share is the paper's specular
  albedo over the total in every channel) or ``white`` (reflectance 1: share 16 / 36 / 16 % at 0.1).
* ``fig13spp`` — Fig. 13's failing cells (specular share 0.1 at α = 0.009 and 0.05, and no coat)
  at each ``--fig13-spp-sweep``: the paper's metric beside its own Monte Carlo noise, and noise
  reduction sized from the measured noise and the noise-aware recolor beside the plain one.
* ``fig3`` — a diffuse box on a glossy floor (``mitsuba:floor``): the box's reflection.
* ``fig12`` — a textured target (``virtual:textured``, then ``mitsuba:textured`` at each
  ``--fig12-spp``), κ = (2, 0.125, 1.2), against one truth render and against the mean of
  ``--fig12-truths``; the soft mask (refined, or the true coverage: ``--fig12-masks``) plain,
  with noise reduction sized from the measured noise, and noise-aware.
* ``ratio`` — interreflection-to-direct ratio on the Cornell right wall (ceiling light, projector white):
  the virtual rig's radiosity at several patch sizes against Mitsuba's path tracer.
* ``grazing`` — the direct image D of a wall seen at a grazing angle beside concave corners (the
  checker scene's right wall, ideal co-axial rig): the checkerboards' bias against the rig's exact D,
  each acquisition again with the exact D (an oracle), the recolor with the demo's κ (the wall's blue
  albedo 0.6 × 8) and with the κ that takes the wall to the paper's blue; then the same
  checkerboards on the path-traced and the virtual Cornell box.

Errors are ‖ours − truth‖₂ / ‖truth‖₂ (the lamp's pixels left out of "image"); the Monte
Carlo noise of the truth renders is part of every mitsuba figure (the noise-floor column).

Run: nice .venv/bin/python bench/optics.py [--parts cornell virtual edge posed realistic fig13 fig13spp fig3 fig12
ratio grazing]
[--quick]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import cv2
import numpy as np

import devices
from app.model.noise import denoise_radius
from engine.acquire import CaptureSettings, Recorder, acquire_single, calibrate_rig
from engine.acquire.predict import relative_error
from engine.denoise import denoise_components
from engine.edge import blend_edges, refine_mask
from engine.recolor import recolor
from engine.trust import recolor_trusted

K1 = np.array([0.5, 1.2, 0.8])
K2 = np.array([2.0, 0.125, 8.0])


def lighting(rig):
    """The scene's natural lighting: (ambient on?, projector pattern for the photograph or None)."""
    rig.flood()
    flood = rig.projector.image
    return rig.ambient, (flood if flood.max() > 0 else None)


def interior_of(coverage):
    """Solid pixels whose 8 neighbours are solid too."""
    solid = (coverage >= 1).astype(np.uint8)
    return cv2.erode(solid, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT) > 0


class Experiment:
    """One rig, its calibration, and acquisitions of one target with several masks."""

    def __init__(self, rig, target, order, *, cal_spp=None, spp=None, frames=1):
        self.rig, self.order = rig, order
        self.hard = rig.targets[target]
        self.coverage = rig.coverage[target]
        self.ambient, self.flood = lighting(rig)
        self.rec = Recorder(rig, None, frames=frames)
        if cal_spp:
            rig.camera.spp = cal_spp
        rig.ambient = True
        t = time.perf_counter()
        self.calibration = calibrate_rig(self.rec, rig_name=rig.identity)
        self.seconds = {"calibration": time.perf_counter() - t}
        if spp:
            rig.camera.spp = spp
        rig.ambient = self.ambient
        self._acq = {}

    def acquire(self, name, mask, settings=None):
        t = time.perf_counter()
        acq = acquire_single(self.rec, self.calibration, mask, self.order, photograph_pattern=self.flood, name=name,
                             settings=settings or CaptureSettings())
        self.seconds[name] = time.perf_counter() - t
        self._acq[name] = acq
        return acq

    def truth(self, kappa):
        return self.rig.truth.recolor([(self.hard, kappa)], ambient=self.ambient, pattern=self.flood)

    def photograph(self):
        return next(iter(self._acq.values())).observations[0]


def _decomposition(acq, denoise, *, previous=""):
    """The acquisition's decomposition, noise-reduced with radius ``denoise`` (0: off) before the edge blend,
    the edge pixels' neighbour shares fitted along the edge; ``previous``: an earlier behaviour, "after" the
    blended decomposition filtered, "square" filtered before the blend but not fitted along the edge."""
    if previous == "after" and denoise:
        return denoise_components(acq.target.decompose(acq.observations), acq.observations[0], radius=denoise)
    if previous == "square" and denoise:
        t, obs = acq.target, acq.observations
        d = _unblended(t, obs)
        return blend_edges(denoise_components(d, obs[0], radius=denoise), t.coverage, obs[0], smoothed=True)[0]
    return acq.target.decompose(acq.observations, denoise=denoise)


def edge_table(exp: Experiment, variants, kappas, *, denoise_for, lamp, floor_truth=True):
    """Rows: method × κ; columns: wall with edge, interior, ratio, edge only, image, noise floor."""
    cov = exp.coverage
    wall, interior = cov > 0, interior_of(cov)
    edge = wall & ~interior
    photo = exp.photograph()
    keep = ~lamp
    rows = []
    for kappa in kappas:
        truth = exp.truth(kappa)
        floor = relative_error(exp.truth(kappa), truth, keep) if floor_truth else 0.0
        denoise = denoise_for(kappa)
        naive = np.where(exp.hard[:, :, None], photo * kappa.astype(np.float32), photo)
        results = [("naive per-pixel", naive)]
        for label, name, *previous in variants:  # ("label", "acquisition"[, an earlier behaviour: _decomposition])
            if previous and not denoise:
                continue
            results.append((label, recolor(_decomposition(exp._acq[name], denoise, previous=(previous or [""])[0]),
                                           kappa)))
        for label, img in results:
            e_wall, e_in = relative_error(img, truth, wall), relative_error(img, truth, interior)
            rows.append(
                (
                    ",".join(f"{x:g}" for x in kappa),
                    label + (f" (denoise {denoise})" if denoise and label != "naive per-pixel" else ""),
                    e_wall,
                    e_in,
                    e_wall / max(e_in, 1e-12),
                    relative_error(img, truth, edge),
                    relative_error(img, truth, keep),
                    floor,
                )
            )
    print(
        f"{'κ':>20} {'method':<48} {'wall+edge':>9} {'interior':>9} {'ratio':>6} {'edge':>8} {'image':>8} "
        f"{'noise floor':>11}"
    )
    for k, label, e_wall, e_in, ratio, e_edge, e_img, floor in rows:
        print(
            f"{str(k):>20} {label:<48} {100 * e_wall:8.2f}% {100 * e_in:8.2f}% {ratio:6.2f} {100 * e_edge:7.2f}% "
            f"{100 * e_img:7.2f}% {100 * floor:10.2f}%"
        )
    print(
        f"wall: {wall.sum()} pixels ({edge.sum()} edge: coverage < 1 or next to it), times: "
        + ", ".join(f"{k} {v:.0f} s" for k, v in exp.seconds.items()),
        flush=True,
    )
    return rows


def part_cornell(args):
    res, spp = (32, 128) if args.quick else (args.resolution or 64, args.spp)
    print(f"\n== mitsuba:cornell {res}², {spp} spp per capture, order 4, ideal camera and projector ==")
    rig = devices.open_rig(
        "mitsuba:cornell", ideal=True, resolution=(res, res), spp=spp, ambient_spp=4 * spp, truth_spp=spp
    )
    exp = Experiment(rig, "right_wall", 4, cal_spp=64, spp=spp)
    exp.acquire("hard", exp.hard)
    soft = refine_mask(exp.hard, exp.photograph())
    exp.acquire("soft", soft)
    err = np.abs(soft - exp.coverage)[(exp.coverage > 0) & (exp.coverage < 1)]
    print(f"refined coverage vs true coverage on edge pixels: mean |error| {err.mean():.3f}")
    variants = [("previous (hard mask)", "hard"), ("soft mask, refined", "soft"),
                ("soft refined, not fitted along edge", "soft", "square"),
                ("soft refined, filtered after blend", "soft", "after")]
    lamp = rig.truth.emitters()
    edge_table(exp, variants, [K1, K2], denoise_for=lambda k: 4 if np.max(k) > 2 else 0, lamp=lamp)
    if not args.quick:
        exp.acquire("true", exp.coverage)
        edge_table(exp, [("soft mask, true coverage", "true"), ("soft true, not fitted along edge", "true", "square"),
                         ("soft true, filtered after blend", "true", "after")],
                   [K1, K2], denoise_for=lambda k: 4 if np.max(k) > 2 else 0, lamp=lamp)
    rig.close()


def part_noise(args):
    """Where the path-traced Cornell box's κ_B = 8 error comes from: noise reduction and Monte Carlo variance.

    One acquisition of the right wall refined into a soft mask (as ``cornell``), recolored with
    κ = (2, 0.125, 8) several ways, each against one truth render (the ``cornell`` table's metric)
    and against the mean of six (a reference with 1/√6 of a render's noise): no noise reduction,
    the guided filter (radius 4) before the edge blend (with the edge pixels' neighbour shares fitted
    along the edge: now) and after it (before), before it
    but leaving the outside pixels (coverage 0) or everything but the target unfiltered; the
    noise-aware recolor (:mod:`engine.trust`) with each capture's Monte Carlo variance in the
    covariance (:attr:`engine.rig.Frame.variance`) and without it (the same captures read back
    from a session, which does not store it).
    """
    import tempfile
    from pathlib import Path

    from engine.session import Session

    res, spp = (32, 128) if args.quick else (args.resolution or 64, args.spp)
    print(f"\n== mitsuba:cornell {res}², {spp} spp per capture, order 4, κ = {K2.tolist()}, soft mask refined: "
          "noise reduction and Monte Carlo variance ==")
    rig = devices.open_rig(
        "mitsuba:cornell", ideal=True, resolution=(res, res), spp=spp, ambient_spp=4 * spp, truth_spp=spp
    )
    ambient, flood = lighting(rig)
    hard, cov_true = rig.targets["right_wall"], rig.coverage["right_wall"]
    with tempfile.TemporaryDirectory() as folder:
        session = Session.create(Path(folder) / "s", rig_name=rig.name, camera_resolution=rig.camera.resolution,
                                 projector_resolution=rig.projector.resolution)
        rec = Recorder(rig, session)
        rig.camera.spp, rig.ambient = 64, True
        cal = calibrate_rig(rec, rig_name=rig.identity)
        rig.camera.spp, rig.ambient = spp, ambient
        soft = refine_mask(hard, rec.capture("photograph", rec.black() if flood is None else flood))
        acq = acquire_single(rec, cal, soft, 4, photograph_pattern=flood, name="soft")
        again = Recorder(rig, session)  # every capture read back: the camera model's variance only
        unknown = acquire_single(again, cal, soft, 4, photograph_pattern=flood, name="soft")
        assert not again.taken
    truths = [rig.truth.recolor([(hard, K2)], ambient=ambient, pattern=flood) for _ in range(6)]
    reference = np.mean(truths, axis=0)
    lamp = rig.truth.emitters()
    rig.close()
    wall, interior = cov_true > 0, interior_of(cov_true)
    edge, keep = wall & ~interior, ~lamp
    t, obs = acq.target, acq.observations
    d0 = _unblended(t, obs)
    filtered = denoise_components(d0, obs[0], radius=4)

    def blended(d, unfiltered=None, along=0, smoothed=True):
        if unfiltered is not None:
            d = _keep_measured(d, d0, unfiltered)
        return recolor(blend_edges(d, t.coverage, obs[0], along=along, smoothed=smoothed)[0], K2)

    rows = [
        ("no noise reduction", blended(d0, smoothed=False)),
        ("radius 4 before the edge blend", blended(filtered)),
        ("the same, fitted along the edge (now)", blended(filtered, along=4)),
        ("radius 4 after the edge blend (before)", recolor(denoise_components(t.decompose(obs), obs[0], radius=4), K2)),
        ("radius 4 before, outside pixels unfiltered", blended(filtered, t.coverage <= 0)),
        ("radius 4 before, only the target filtered", blended(filtered, t.coverage < 1, smoothed=False)),
        ("noise-aware, Monte Carlo variance known", recolor_trusted(t.trust(obs, acq.covariance), K2).image),
        ("noise-aware, Monte Carlo variance unknown", recolor_trusted(
            unknown.target.trust(unknown.observations, unknown.covariance), K2).image),
    ]
    print(f"noise floor (one truth against the mean of the other five): image "
          f"{100 * relative_error(truths[0], np.mean(truths[1:], axis=0), keep):.2f}%")
    print(f"{'method':<44} {'against':<10} {'wall+edge':>9} {'interior':>9} {'ratio':>6} {'edge':>8} {'image':>8} "
          f"{'off wall':>8}")
    for label, img in rows:
        for name, truth in (("one truth", truths[0]), ("reference", reference)):
            e_wall, e_in = relative_error(img, truth, wall), relative_error(img, truth, interior)
            print(f"{label:<44} {name:<10} {100 * e_wall:8.2f}% {100 * e_in:8.2f}% {e_wall / max(e_in, 1e-12):6.2f} "
                  f"{100 * relative_error(img, truth, edge):7.2f}% {100 * relative_error(img, truth, keep):7.2f}% "
                  f"{100 * relative_error(img, truth, keep & ~wall):7.2f}%", flush=True)


def _unblended(target, observations):
    """The target's decomposition (unreachable pixels filled) before a soft mask's edge blend."""
    return replace(target, coverage=None).decompose(observations)


def _keep_measured(filtered, measured, unfiltered):
    """``filtered`` with the pixels ``unfiltered`` (H, W) bool keeping their ``measured`` components."""
    keep = unfiltered[None, :, :, None]
    return replace(filtered, components=np.where(keep, measured.components, filtered.components),
                   unreached=np.where(keep[0], measured.unreached, filtered.unreached))


def _denoised_on_target(acq, radius):
    """The acquisition's decomposition noise-reduced before the edge blend, the outside pixels (coverage 0)
    left as measured (the filter's bias there is not worth its gain on a whole-image figure)."""
    if not radius:
        return _decomposition(acq, 0)
    t, obs = acq.target, acq.observations
    d0 = _unblended(t, obs)
    d = _keep_measured(denoise_components(d0, obs[0], radius=radius), d0, t.coverage <= 0)
    return blend_edges(d, t.coverage, obs[0], smoothed=True)[0]


def part_virtual(args):
    res = args.resolution or (48 if args.quick else 128)
    print(f"\n== virtual:cornell {res}², supersampled 4×4, ideal, order 4 ==")
    rig = devices.open_rig("virtual:cornell", ideal=True, resolution=(res, res), supersample=4)
    exp = Experiment(rig, "right_wall", 4)
    exp.acquire("hard", exp.hard)
    exp.acquire("soft", refine_mask(exp.hard, exp.photograph()))
    exp.acquire("true-previous", exp.coverage, CaptureSettings(stand_in=False))
    exp.acquire("true", exp.coverage)
    edge_table(
        exp,
        [("previous (hard mask)", "hard"), ("soft mask, refined", "soft"),
         ("soft, true coverage, no stand-in", "true-previous"), ("soft mask, true coverage", "true")],
        [K1, K2],
        denoise_for=lambda k: 0,
        lamp=rig.truth.emitters(),
        floor_truth=False,
    )
    # noise reduction (which κ_B = 8 needs on a real camera) must leave the blended edge pixels alone
    edge_table(exp, [("soft mask, refined", "soft"), ("soft mask, true coverage", "true")], [K2],
               denoise_for=lambda k: 4, lamp=rig.truth.emitters(), floor_truth=False)
    rig.close()


def part_realistic(args):
    res = 64 if args.quick else 128
    print(f"\n== realistic virtual:cornell {res}² (the realistic demo's rig), 16 frames a capture, κ = {K2.tolist()}, "
          "order 4, noise reduction sized from the measured noise ==")
    rig = devices.open_rig("virtual:cornell", ideal=False, resolution=(res, res), seed=0, projector="coaxial")
    exp = Experiment(rig, "right_wall", 4, frames=16)
    exp.acquire("hard-previous", exp.hard, CaptureSettings(complete_direct=False))
    exp.acquire("hard", exp.hard)
    exp.acquire("soft-previous", refine_mask(exp.hard, exp.photograph()), CaptureSettings(complete_direct=False))
    exp.acquire("soft", refine_mask(exp.hard, exp.photograph()))
    exp.acquire("true-previous", exp.coverage, CaptureSettings(stand_in=False))
    exp.acquire("true", exp.coverage)
    truth = exp.truth(K2)
    photo = exp.photograph()
    cov = exp.coverage
    wall, interior = cov > 0, interior_of(cov)
    surfaces = ~rig.truth.emitters()
    rows = [("naive per-pixel", np.where(exp.hard[:, :, None], photo * K2.astype(np.float32), photo), 0)]
    for label, name in [("previous (hard mask)", "hard-previous"), ("hard mask + direct completion", "hard"),
                        ("soft refined, no completion", "soft-previous"),
                        ("soft refined + direct completion", "soft"),
                        ("soft true coverage, no stand-in", "true-previous"),
                        ("soft true coverage + completion", "true")]:
        acq = exp._acq[name]
        d = acq.target.decompose(acq.observations)
        size = denoise_radius(d)[0]
        rows.append((label, recolor(_decomposition(acq, size), K2), size))
        if name in ("soft", "true") and size:  # the previous behaviour: edge not fitted along the edge
            rows.append(("  the same, not fitted along edge", recolor(_decomposition(acq, size, previous="square"), K2),
                         size))
    print(f"{'method':<34} {'surfaces':>8} {'wall+edge':>9} {'interior':>9} {'ratio':>6} {'edge':>8} {'denoise':>7}")
    for label, img, size in rows:
        e_wall, e_in = relative_error(img, truth, wall), relative_error(img, truth, interior)
        print(f"{label:<34} {100 * relative_error(img, truth, surfaces):7.2f}% {100 * e_wall:8.2f}% "
              f"{100 * e_in:8.2f}% {e_wall / max(e_in, 1e-12):6.2f} "
              f"{100 * relative_error(img, truth, wall & ~interior):7.2f}% {size:7d}", flush=True)
    rig.close()


def part_edge(args):
    """What the edge still costs: oracles on the ideal supersampled box (true coverage).

    Observations: re-emitted without / with the edge's stand-in, and the whole target's (the
    edge strip re-emitted exactly, its own direct term left out, from the truth's interactions:
    what Eq. 6 and the blend assume). Edge pixels: blended as shipped, with the neighbour's part
    taken from the truth (the target's part is the rest of the pixel's decomposition, as in
    :func:`engine.edge.blend_edges`), or wholly from the truth.
    """
    from math import comb


    res, order, terms_n = args.resolution or (32 if args.quick else 48), 4, 12
    print(f"\n== the edge's cost, virtual:cornell {res}², supersampled 4×4, ideal, order {order}, true coverage; "
          "wall + edge / interior error ==")
    rig = devices.open_rig("virtual:cornell", ideal=True, resolution=(res, res), supersample=4)
    exp = Experiment(rig, "right_wall", order)
    cov, hard = exp.coverage, exp.hard
    wall, interior, edge = cov > 0, interior_of(cov), (cov > 0) & (cov < 1)
    on, off = rig.truth.interactions_by_surface(hard, terms_n, ambient=exp.ambient, pattern=exp.flood)
    total = on + off
    acq = {"no stand-in": exp.acquire("no-stand-in", cov, CaptureSettings(stand_in=False)),
           "with the stand-in": exp.acquire("stand-in", cov)}
    target = acq["with the stand-in"].target
    whole = np.array(acq["no stand-in"].observations)
    for r in range(1, order):
        whole[r] = sum(comb(n - 1 + r, r) * total[n] for n in range(1, terms_n + 1))
        whole[r] -= np.where(edge[:, :, None], sum(comb(n - 2 + r, r - 1) * on[n] for n in range(1, terms_n + 1)), 0)
    observations = {name: a.observations for name, a in acq.items()} | {"whole target's": whole}
    ys, xs = np.nonzero(edge)

    def true_neighbour(obs, kappa):
        d = _unblended(target, obs)
        out = recolor(d, kappa)
        own, neighbour = _as_neighbour(d, obs[0], ys, xs, order), _slots(off, ys, xs, order)
        part = np.maximum(own - neighbour, 0)
        out[ys, xs] = part[0] * kappa + sum(part[m + 1] * kappa ** (m + 2) for m in range(order - 1)) + sum(
            neighbour[j] * kappa**j for j in range(order))
        return out

    def true_edge(obs, kappa):
        out = recolor(target.decompose(obs), kappa)
        out[ys, xs] = sum(total[n, ys, xs] * kappa**n for n in range(terms_n + 1))
        return out

    print(f"{'observations':<18} {'κ':>12} {'blend as shipped':>20} {'neighbour from truth':>22} "
          f"{'edge px from truth':>20}")
    for kappa in (K1, K2):
        truth = exp.truth(kappa)
        for name, obs in observations.items():
            cells = []
            for img in (recolor(target.decompose(obs), kappa), true_neighbour(obs, kappa), true_edge(obs, kappa)):
                e_wall, e_in = relative_error(img, truth, wall), relative_error(img, truth, interior)
                cells.append(f"{100 * e_wall:.3f} / {100 * e_in:.3f}%")
            print(f"{name:<18} {','.join(f'{x:g}' for x in kappa):>12} {cells[0]:>20} {cells[1]:>22} {cells[2]:>20}",
                  flush=True)
    stood_in = acq["with the stand-in"].observations
    _edge_slots(_unblended(target, stood_in), stood_in[0], cov, on, off, ys, xs, order)
    solid_next = target.mask & ~interior
    print("observations 1..3 off the whole target's on the solid pixels beside the edge: " + "; ".join(
        f"{name} " + " / ".join(f"{100 * relative_error(obs[r], whole[r], solid_next):.2f}%" for r in range(1, order))
        for name, obs in observations.items() if name != "whole target's"))
    rig.close()


def _as_neighbour(d, photo, ys, xs, order):
    """Edge pixels' decomposition as non-target, ``F`` (the unreached light, then ``C R^m L_d``; ``order`` slots),
    scaled to sum to the pixel's light as :func:`engine.edge.blend_edges` does: (order, N, C) float64."""
    own = np.concatenate([d.unreached[None], d.components[:order - 1]])[:, ys, xs].astype(np.float64)
    return own * (photo[ys, xs] / np.maximum(own.sum(0), 1e-30))[None]


def _slots(terms, ys, xs, order, *, first=0):
    """The truth's interactions ``terms[first:]`` at the edge pixels in ``order`` slots, the last holding the tail."""
    out = terms[first:first + order, ys, xs].astype(np.float64)
    out[order - 1] += terms[first + order:, ys, xs].sum(0)
    return out


def _edge_slots(d, photo, cov, on, off, ys, xs, order):
    """Print where the edge pixels' ``(ys, xs)`` error lies: per slot of their decomposition as non-target
    (:func:`_as_neighbour`), ``F`` against the truth's target + neighbour parts, and the strip's extrapolated
    target part against the truth's (mean over the edge pixels, % of the pixel's light, R G B)."""
    from engine.edge import _strip

    own, pixel = _as_neighbour(d, photo, ys, xs, order), photo[ys, xs].astype(np.float64)
    true_t, true_n = _slots(on, ys, xs, order, first=1), _slots(off, ys, xs, order)
    strip = _strip(d.components, d.target & (photo > 0).all(-1), cov, ys, xs)[0]

    def cell(x):
        return " ".join(f"{v:+6.2f}" for v in 100 * (x / pixel).mean(0))

    print(f"edge pixels ({len(ys)}), per slot, % of the pixel (R G B): F − truth | strip − truth's target part | "
          "truth's target part | truth's neighbour part")
    for j in range(order):
        print(f"  slot {j}: {cell(own[j] - true_t[j] - true_n[j])} | {cell(strip[j] - true_t[j])} | "
              f"{cell(true_t[j])} | {cell(true_n[j])}")


FIG13_KAPPA = np.array([1.5, 4.5, 0.5])
FIG13_TINTS = {"tinted": "albedo", "white": "white"}  # --fig13-coat -> the rig's coat tint


def part_posed(args):
    """A posed projector at a soft edge: the wedge's left wall, co-axial and posed, each way of completing."""
    print(f"\n== posed projector: virtual:wedge, supersampled 4×4, ideal, left wall, κ = {FIG13_KAPPA.tolist()}, "
          "order 4; error over wall + edge / interior / edge pixels / whole image ==")
    variants = [("true coverage", "true", None),
                ("true coverage, no stand-in", "true", CaptureSettings(stand_in=False)),
                ("refined from the photograph", "soft", None), ("hard mask", "hard", None)]
    print(f"{'res':>4} {'projector':<9} {'mask':<28} {'previous (no spread)':>34} {'now':>34}")
    for res in ((24,) if args.quick else (24, 48)):
        for pose in ("coaxial", "offset"):
            rig = devices.open_rig("virtual:wedge", ideal=True, resolution=(res, res), supersample=4, projector=pose)
            exp = Experiment(rig, "left", 4)
            truth = exp.truth(FIG13_KAPPA)
            cov = exp.coverage
            wall, interior = cov > 0, interior_of(cov)
            masks = {"true": cov, "hard": exp.hard}
            for label, kind, settings in variants:
                cells = []
                for spread in (False, True):
                    if kind == "soft" and "soft" not in masks:
                        masks["soft"] = refine_mask(exp.hard, exp.photograph())
                    base = settings or CaptureSettings()
                    acq = exp.acquire(f"{kind}-{spread}-{label}", masks[kind],
                                      CaptureSettings(stand_in=base.stand_in, spread=spread))
                    img = recolor(_decomposition(acq, 0), FIG13_KAPPA)
                    cells.append(" / ".join(f"{100 * relative_error(img, truth, m):5.2f}" for m in
                                            (wall, interior, wall & ~interior, None)) + " %")
                print(f"{res:4d} {pose:<9} {label:<28} {cells[0]:>34} {cells[1]:>34}", flush=True)
            rig.close()
    if args.quick:
        return
    print(f"-- path-traced (mitsuba:wedge 24², {args.fig13_spp} spp, no coat, true coverage): ours vs the paint truth, "
          "naive, (noise floor)")
    for pose in ("coaxial", "offset"):
        print(f"{pose:<9} {_cell(fig13_cell(0.0, 0.009, res=24, spp=args.fig13_spp, pose=pose))}", flush=True)


def fig13_cell(share, alpha, *, res, spp, pose="coaxial", soft=True, calibrations=None, components=False,
               extra=False, coat="tinted"):
    """One coat of the wedge's left wall: our recolor against the two truths, the naive one, the noise.

    ``coat`` is ``"tinted"`` (specular reflectance = the paint's: ``share`` is the paper's specular
    share of the total albedo in every channel) or ``"white"`` (share 16 / 36 / 16 % at 0.1).

    Returns a dict of relative errors (fractions): ``paint`` (truth: the diffuse reflectance under
    the coat scaled by κ, the physical repaint), ``every`` (truth: the coat's gloss scaled too,
    every interaction with the wall weighted by κ as in the paper's Fig. 13 components),
    ``naive`` (against ``paint``), ``floor`` (two independent ``paint`` truth renders), and
    ``paint_wall`` / ``paint_rest`` / ``every_wall`` / ``every_rest`` on the left wall (any
    coverage) and off it. ``soft`` acquires the rig's true coverage of the wall; else its hard mask.
    ``components`` adds ``paper``: the paper's Fig. 13 metric — per interaction component, the
    mean absolute error over the truth component's peak (its 99th percentile: Monte Carlo
    fireflies are no peak; :meth:`devices.mitsuba.truth.Truth.components`, rendered at ``spp``),
    averaged over the four. ``extra`` (with ``components``) adds ``paper_floor`` (the metric of a
    second truth components render against the first: the metric's own Monte Carlo noise at
    ``spp``; ``floor_each`` and ``paper_each`` per component), ``paper_ref`` (ours against the
    mean of the two renders), ``radius`` (noise reduction sized from the measured noise,
    :func:`app.model.noise.denoise_radius`, as the app and ``albedit demo`` size it) with
    ``paper_dn`` / ``paint_dn`` / ``every_dn`` (the same, noise-reduced with that radius; the
    metric against the first render), ``paper_w`` (the decomposition weighted by the captures'
    covariance, Monte Carlo variance included), and ``paint_trust`` / ``every_trust`` (the
    noise-aware recolor, :mod:`engine.trust`, with each capture's Monte Carlo variance in its
    covariance).
    """
    rig = devices.open_rig("mitsuba:wedge", ideal=True, resolution=(res, res), spp=spp, truth_spp=4 * spp,
                           specular=share, roughness=alpha, tint=FIG13_TINTS[coat], projector=pose)
    ambient, flood = lighting(rig)
    rec = Recorder(rig, None)
    calibrations = {} if calibrations is None else calibrations
    if pose not in calibrations:  # the coat does not move the geometry: calibrate once per pose
        calibrations[pose] = calibrate_rig(rec, rig_name=rig.identity)
    hard, cov = rig.targets["left"], rig.coverage["left"]
    acq = acquire_single(rec, calibrations[pose], cov if soft else hard, 4, photograph_pattern=flood)
    d = acq.target.decompose(acq.observations)
    ours = recolor(d, FIG13_KAPPA)
    pair = [(hard, FIG13_KAPPA)]
    paint = rig.truth.recolor(pair, ambient=ambient, pattern=flood)
    every = rig.truth.recolor(pair, ambient=ambient, pattern=flood, coat=True) if share > 0 else paint
    photo = acq.observations[0]
    naive = np.where(hard[:, :, None], photo * FIG13_KAPPA.astype(np.float32), photo)
    wall = cov > 0
    out = {
        "paint": relative_error(ours, paint),
        "every": relative_error(ours, every),
        "naive": relative_error(naive, paint),
        "floor": relative_error(rig.truth.recolor(pair, ambient=ambient, pattern=flood), paint),
    }
    for name, truth in (("paint", paint), ("every", every)):
        out[name + "_wall"] = relative_error(ours, truth, wall)
        out[name + "_rest"] = relative_error(ours, truth, ~wall)
    if components:  # the paper's metric: mean |error| of each component over its peak, averaged over K
        rig.truth.spp = spp
        c = rig.truth.components(hard, 4, ambient=ambient, pattern=flood)
        true = c.inside + c.outside
        peaks = [np.percentile(true[i], 99) for i in range(4)]  # a firefly is no peak
        out["paper"] = _paper_metric(d.components, true, peaks)
        if extra:
            c2 = rig.truth.components(hard, 4, ambient=ambient, pattern=flood)
            true2 = c2.inside + c2.outside
            out["paper_floor"] = _paper_metric(true2, true, peaks)
            out["paper_ref"] = _paper_metric(d.components, (true + true2) / 2, peaks)
            out["paper_each"] = _paper_metric(d.components, true, peaks, each=True)
            out["floor_each"] = _paper_metric(true2, true, peaks, each=True)
            size = denoise_radius(d)[0]
            dn = acq.target.decompose(acq.observations, denoise=size) if size else d
            out["radius"] = size
            out["paper_dn"] = _paper_metric(dn.components, true, peaks)
            weighted = acq.target.decompose(acq.observations, covariance=acq.covariance)
            out["paper_w"] = _paper_metric(weighted.components, true, peaks)
            for name, img in (("dn", recolor(dn, FIG13_KAPPA)), ("trust", recolor_trusted(
                    acq.target.trust(acq.observations, acq.covariance), FIG13_KAPPA).image)):
                out["paint_" + name] = relative_error(img, paint)
                out["every_" + name] = relative_error(img, every)
    rig.close()
    return out


def _paper_metric(components, true, peaks, *, each=False):
    """The paper's Fig. 13 metric: mean |error| of each component over the truth's peak, averaged
    (``each``: the list of the components' own)."""
    per = [float(np.abs(components[i] - true[i]).mean() / peaks[i]) for i in range(len(peaks))]
    return per if each else float(np.mean(per))


def _cell(e) -> str:
    paper = f" [{100 * e['paper']:4.2f}]" if "paper" in e else ""
    return f"{100 * e['paint']:5.1f} {100 * e['every']:5.1f} {100 * e['naive']:5.1f} ({100 * e['floor']:4.1f}){paper}"


def _fig13_coat(args) -> str:
    """Print and return ``--fig13-coat``."""
    if args.fig13_coat == "tinted":
        print("coat: tinted (specular reflectance = the paint's (0.6, 0.2, 0.6): the share is the paper's, specular "
              "albedo over the total, in every channel)")
    else:
        print("coat: white (specular reflectance 1 over the (0.6, 0.2, 0.6) paint: share s / (s + (1 - s) ρ) of the "
              "total albedo, 16 / 36 / 16 % at s = 0.1; not the paper's definition)")
    return args.fig13_coat


def part_fig13(args):
    res, spp = (24, 64) if args.quick else (24, args.fig13_spp)
    shares = [0.0, 0.1] if args.quick else [0.0, 0.03, 0.1, 0.3]
    rough = [0.009, 1.0] if args.quick else [0.009, 0.05, 0.3, 1.0]
    print(f"\n== Fig. 13: mitsuba:wedge {res}², {spp} spp per capture ({4 * spp} for the truth), left wall glossy, "
          f"κ = {FIG13_KAPPA.tolist()}, order 4, ideal ==")
    print("relative error of the recolored image, %: ours vs the paint truth (diffuse reflectance under the coat "
          "scaled), ours vs the every-interaction truth (gloss scaled too: the paper's components), naive vs paint, "
          "(noise floor: two paint truth renders), [the paper's metric: mean |error| of each of the 4 components over "
          "its peak, averaged]")
    coat = _fig13_coat(args)
    cals: dict = {}
    cells = {}
    print("-- co-axial projector, target = the rig's true coverage of the wall (no seam); rows: specular share, "
          "columns: GGX roughness")
    print(f"{'share':>6} " + " ".join(f"{'α = ' + str(r):>31}" for r in rough))
    for s in shares:
        row = []
        for r in rough:
            if s == 0 and r != rough[0]:
                cells[s, r] = cells[s, rough[0]]  # no coat: the same scene
            else:
                cells[s, r] = fig13_cell(s, r, res=res, spp=spp, calibrations=cals, coat=coat, components=True)
            row.append(_cell(cells[s, r]))
        print(f"{s:6.3f} " + " ".join(f"{c:>31}" for c in row), flush=True)

    print("-- the same with the hard mask (the previous bench: its seam at the wall's edge) and with the posed "
          "projector (projector='offset': 0.25 m right of the camera)")
    print(f"{'share':>6} {'α':>6} {'co-axial, soft':>31} {'co-axial, hard mask':>24} {'posed, soft':>24}")
    for s, r in [(0.0, rough[0]), (0.1, rough[0]), (0.1, rough[-1])]:
        hard = fig13_cell(s, r, res=res, spp=spp, soft=False, calibrations=cals, coat=coat)
        posed = fig13_cell(s, r, res=res, spp=spp, pose="offset", calibrations=cals, coat=coat)
        print(f"{s:6.3f} {r:6.3f} {_cell(cells[s, r]):>31} {_cell(hard):>24} {_cell(posed):>24}", flush=True)

    print(f"-- render noise: share 0.1, α = {rough[0]}, co-axial, soft; error on the wall / off it, %")
    print(f"{'spp':>6} {'paint':>6} {'wall':>6} {'rest':>6} {'every':>6} {'wall':>6} {'rest':>6} {'naive':>6} "
          f"{'floor':>6}")
    for n in [spp // 8, spp, 2 * spp]:
        e = (cells[0.1, rough[0]] if n == spp
             else fig13_cell(0.1, rough[0], res=res, spp=n, calibrations=cals, coat=coat))
        print(f"{n:6d} " + " ".join(f"{100 * e[k]:6.1f}" for k in ("paint", "paint_wall", "paint_rest", "every",
                                                                    "every_wall", "every_rest", "naive", "floor")),
              flush=True)


def part_fig13_samples(args):
    """Fig. 13's cells ``--fig13-cells`` (by default its failing ones: no coat and s = 0.1 at α = 0.009 and 0.05)
    at each ``--fig13-spp-sweep`` (captures; the recolor's truths at 4×, the components at the same spp)."""
    res = 24
    sweep = [64, 128] if args.quick else args.fig13_spp_sweep
    print(f"\n== Fig. 13 against samples: mitsuba:wedge {res}², left wall glossy, κ = {FIG13_KAPPA.tolist()}, "
          "order 4, ideal, co-axial, true coverage ==")
    print("the paper's metric (mean |error| of each component over its peak, averaged over the 4), %: ours against "
          "one truth components render, against the mean of two, the metric of one truth render against the other "
          "(its own noise), ours noise-reduced with the measured radius r, ours weighted by the captures' covariance "
          "(w); then the recolor's error, %: ours / "
          "noise-reduced / noise-aware (Monte Carlo variance) against the every-interaction truth, and against paint; "
          "naive; (two paint truths)")
    coat = _fig13_coat(args)
    print(f"{'s':>5} {'α':>6} {'spp':>5} {'paper':>6} {'ref':>6} {'floor':>6} {'r':>2} {'dn':>6} {'w':>6} | "
          f"{'every':>6} {'dn':>6} {'trust':>6} | {'paint':>6} {'dn':>6} {'trust':>6} | {'naive':>6} {'(floor)':>7} "
          f"{'time':>6}")
    cals: dict = {}
    for share, alpha in args.fig13_cells:
        for spp in sweep:
            t = time.perf_counter()
            e = fig13_cell(share, alpha, res=res, spp=spp, calibrations=cals, coat=coat, components=True, extra=True)
            print(f"{share:5.2f} {alpha:6.3f} {spp:5d} "
                  + " ".join(f"{100 * e[k]:6.2f}" for k in ("paper", "paper_ref", "paper_floor"))
                  + f" {e['radius']:2d} {100 * e['paper_dn']:6.2f} {100 * e['paper_w']:6.2f} | "
                  + " ".join(f"{100 * e[k]:6.2f}" for k in ("every", "every_dn", "every_trust")) + " | "
                  + " ".join(f"{100 * e[k]:6.2f}" for k in ("paint", "paint_dn", "paint_trust"))
                  + f" | {100 * e['naive']:6.2f} ({100 * e['floor']:5.2f}) {time.perf_counter() - t:5.0f}s", flush=True)
            print(f"{'':18} per component, ours / floor: " + ", ".join(
                f"{100 * a:.2f} / {100 * b:.2f}" for a, b in zip(e["paper_each"], e["floor_each"], strict=True)),
                flush=True)


def _share_alpha(text: str) -> tuple[float, float]:
    """``--fig13-cells``' ``SHARE:ALPHA``, e.g. ``0.03:0.009``, as two floats."""
    try:
        share, alpha = (float(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected SHARE:ALPHA such as 0.03:0.009, got {text!r}") from None
    return share, alpha


def part_fig3(args):
    res, spp = (32, 128) if args.quick else (48, 1024)
    kappa = np.array([1.3, 0.6, 0.2])
    print(f"\n== Figs. 3/11: mitsuba:floor {res}², {spp} spp, box on a glossy floor, κ = {kappa.tolist()}, order 3 ==")
    rig = devices.open_rig("mitsuba:floor", ideal=True, resolution=(res, res), spp=spp, truth_spp=spp)
    exp = Experiment(rig, "box", 3, cal_spp=64, spp=spp)
    exp.acquire("hard", exp.hard)
    exp.acquire("soft", refine_mask(exp.hard, exp.photograph()))
    truth, truth2 = exp.truth(kappa), exp.truth(kappa)
    photo = exp.photograph()
    box = exp.coverage > 0
    change = np.abs(truth - rig.truth.photograph(ambient=exp.ambient, pattern=exp.flood)).sum(-1)
    reflection = ~box & (change > 0.05 * np.maximum(photo.sum(-1), 1e-6)) & (np.arange(res)[:, None] > res // 2)
    naive = np.where(exp.hard[:, :, None], photo * kappa.astype(np.float32), photo)
    rows = [
        ("naive per-pixel", naive),
        ("previous (hard mask)", recolor(_decomposition(exp._acq["hard"], 0), kappa)),
        ("soft mask, refined", recolor(_decomposition(exp._acq["soft"], 0), kappa)),
    ]
    print(
        f"{'method':<24} {'image':>8} {'box':>8} {'reflection':>10}   (noise floor: image "
        f"{100 * relative_error(truth2, truth):.2f}%, "
        f"reflection {100 * relative_error(truth2, truth, reflection):.2f}%;"
        f" {reflection.sum()} reflection pixels)"
    )
    for label, img in rows:
        print(
            f"{label:<24} {100 * relative_error(img, truth):7.2f}% {100 * relative_error(img, truth, box):7.2f}% "
            f"{100 * relative_error(img, truth, reflection):9.2f}%",
            flush=True,
        )
    rig.close()


FIG12_KAPPA = np.array([2.0, 0.125, 1.2])


def _edge_share(img, truth, region, edge) -> float:
    """Fraction of the squared error over ``region`` that the ``edge`` pixels carry."""
    err = ((np.asarray(img, np.float64) - truth) ** 2).sum(-1)
    return float(err[edge & region].sum() / max(err[region].sum(), 1e-30))


def part_fig12(args):
    """Fig. 12, a textured target: the ideal virtual rig, then the path-traced one at each ``--fig12-spp``.

    Path-traced, every recolor is measured against one truth render (the previous table's
    metric) and against the mean of ``--fig12-truths`` truth renders at the captures' spp (a
    reference with 1/√n of a render's noise; its own residual noise printed from the
    difference of its two halves). Variants: naive, the previous behaviour (hard mask), the
    soft mask refined from the photograph without noise reduction, with noise reduction sized
    from the measured noise as the app and ``albedit demo`` size it
    (:func:`app.model.noise.denoise_radius`; on every pixel, on the wall only, and on the
    decomposition weighted by the captures' covariance as the app decomposes), and the
    noise-aware recolor (:mod:`engine.trust`)
    with each capture's Monte Carlo variance (:attr:`engine.rig.Frame.variance`) in its
    covariance.
    """
    _fig12_virtual(args)
    kappa = FIG12_KAPPA
    res = 32 if args.quick else 48
    for spp in [128] if args.quick else args.fig12_spp:
        rig = devices.open_rig(
            "mitsuba:textured", ideal=True, resolution=(res, res), spp=spp, ambient_spp=4 * spp, truth_spp=spp
        )
        print(f"\n== Fig. 12: mitsuba:textured {res}², {spp} spp (captures and truth), textured target, "
              f"κ = {kappa.tolist()}, order 4 ==")
        exp = Experiment(rig, "checker_wall", 4, cal_spp=64, spp=spp)
        if "hard" in args.fig12_masks:
            exp.acquire("hard", exp.hard)
        if "soft" in args.fig12_masks:
            photo = exp.photograph() if exp._acq else exp.rec.capture(
                "photograph", exp.rec.black() if exp.flood is None else exp.flood)
            exp.acquire("soft", refine_mask(exp.hard, photo))
        if "true" in args.fig12_masks:
            exp.acquire("true", exp.coverage)
        _fig12_table(exp, kappa, args.fig12_truths, ~rig.truth.emitters())
        rig.close()


def _fig12_virtual(args) -> None:
    """Fig. 12 on the ideal supersampled virtual rig: which pixels carry the wall's error."""
    kappa = FIG12_KAPPA
    res = 48 if args.quick else 128
    rig = devices.open_rig("virtual:textured", ideal=True, resolution=(res, res), supersample=4)
    exp = Experiment(rig, "checker_wall", 4)
    print(f"\n== Fig. 12: virtual:textured {res}², supersampled 4×4, textured target, κ = {kappa.tolist()}, "
          "order 4 ==")
    exp.acquire("hard", exp.hard)
    refined = refine_mask(exp.hard, exp.photograph())
    exp.acquire("soft", refined)
    exp.acquire("true", exp.coverage)
    edge_table(exp, [("previous (hard mask)", "hard"), ("soft mask, refined", "soft"),
                     ("soft mask, true coverage", "true")], [kappa],
               denoise_for=lambda k: 0, lamp=rig.truth.emitters(), floor_truth=False)
    truth, cov = exp.truth(kappa), exp.coverage
    wall, interior = cov > 0, interior_of(cov)
    edge, keep = wall & ~interior, ~rig.truth.emitters()
    mixed = (cov > 0) & (cov < 1)
    print(f"refined coverage vs true on mixed pixels: mean |error| {np.abs(refined - cov)[mixed].mean():.3f}")
    for name in ("soft", "true"):
        img = recolor(_decomposition(exp._acq[name], 0), kappa)
        print(f"{name}: the edge pixels ({edge.sum()} of the wall's {wall.sum()}, {mixed.sum()} of them mixed) carry "
              f"{100 * _edge_share(img, truth, wall, edge):.1f}% of the wall's squared error; mixed pixels alone "
              f"{100 * relative_error(img, truth, mixed):.2f}%, solid edge pixels "
              f"{100 * relative_error(img, truth, edge & ~mixed):.2f}%; the paper's figure is the whole image: "
              f"{100 * relative_error(img, truth, keep):.2f}%", flush=True)
    rig.close()


def _fig12_table(exp: Experiment, kappa, n_truths: int, keep) -> None:
    cov = exp.coverage
    wall, interior = cov > 0, interior_of(cov)
    edge = wall & ~interior
    regions = {"wall+edge": wall, "interior": interior, "edge": edge, "image": keep}
    t = time.perf_counter()
    truths = [exp.truth(kappa) for _ in range(n_truths)]
    exp.seconds[f"{n_truths} truths"] = time.perf_counter() - t
    reference = np.mean(truths, axis=0)
    half = n_truths // 2
    first, second = np.mean(truths[:half], axis=0), np.mean(truths[half:2 * half], axis=0)
    print("noise: one truth render against another (the previous table's floor) / the reference's own "
          f"(mean of {n_truths}; half the difference of its halves' means):")
    print("  " + ", ".join(f"{name} {100 * relative_error(truths[1], truths[0], m):.2f} / "
                           f"{100 * relative_error(first, second, m) / 2:.2f}%" for name, m in regions.items()))
    photo = exp.photograph()
    rows = [("naive per-pixel", np.where(exp.hard[:, :, None], photo * kappa.astype(np.float32), photo))]
    if "hard" in exp._acq:
        rows.append(("previous (hard mask)", recolor(_decomposition(exp._acq["hard"], 0), kappa)))
    for name, mask in (("soft", "refined"), ("true", "true coverage")):
        if name not in exp._acq:
            continue
        acq = exp._acq[name]
        d = acq.target.decompose(acq.observations)
        size, noise = denoise_radius(d)
        print(f"{mask}: components' measured noise {noise:.3f} → noise-reduction radius {size} "
              "(app.model.noise.denoise_radius)")
        rows += [
            (f"soft {mask}", recolor(d, kappa)),
            (f"{mask}, denoise {size} (measured)", recolor(_decomposition(acq, size), kappa)),
            (f"{mask}, denoise {size}, wall only", recolor(_denoised_on_target(acq, size), kappa)),
            (f"{mask}, weighted, denoise {size} (app)", recolor(
                acq.target.decompose(acq.observations, covariance=acq.covariance, denoise=size), kappa)),
            (f"{mask}, noise-aware (MC variance)", recolor_trusted(
                acq.target.trust(acq.observations, acq.covariance), kappa).image),
        ]
    print(f"{'method':<40} {'against':<10} " + " ".join(f"{name:>9}" for name in regions)
          + "  (edge pixels' share of the image's squared error)")
    for label, img in rows:
        for name, truth in (("one truth", truths[0]), ("reference", reference)):
            print(f"{label:<40} {name:<10} "
                  + " ".join(f"{100 * relative_error(img, truth, m):8.2f}%" for m in regions.values())
                  + f"  ({100 * _edge_share(img, truth, keep, edge):.0f}%)", flush=True)
    print(f"wall: {wall.sum()} pixels ({edge.sum()} edge), times: "
          + ", ".join(f"{k} {v:.0f} s" for k, v in exp.seconds.items()), flush=True)


def part_ratio(args):
    """Indirect / direct light on the right wall's solid pixels, per channel, under the ceiling
    light alone and under projector white alone."""
    res, spp = (32, 256) if args.quick else (64, 4096)
    print(f"\n== interreflection-to-direct ratio, Cornell right wall (solid pixels), {res}² ==")
    rig = devices.open_rig("mitsuba:cornell", ideal=True, resolution=(res, res), ambient_spp=spp, truth_spp=spp)
    import mitsuba as mi  # its variant is set now

    depth2 = mi.load_dict({"type": "path", "max_depth": 2})
    wall = interior_of(rig.coverage["right_wall"])
    white = np.ones(rig.projector.resolution + (3,), np.float32)
    mi_ratio = {}
    for light, (ambient, emitted) in {"ceiling light": (True, None), "projector white": (False, white)}.items():
        full = rig.renderer.render_lights(ambient=ambient, emitted=emitted, spp=spp, seed=98)
        direct = rig.renderer.render_lights(ambient=ambient, emitted=emitted, spp=spp, seed=99, integrator=depth2)
        mi_ratio[light] = (full - direct)[wall].sum(0) / direct[wall].sum(0)
    rig.close()
    print(f"{'rig':<30} {'light':<16} {'R':>7} {'G':>7} {'B':>7} {'vs mitsuba (G)':>15} {'set-up':>8}")
    for light, ratio in mi_ratio.items():
        print(f"{'mitsuba, ' + str(spp) + ' spp':<30} {light:<16} " + " ".join(f"{x:7.4f}" for x in ratio))
    for patch in [0.2, 0.1] if args.quick else [0.2, 0.1, 0.0834]:
        t = time.perf_counter()
        v = devices.open_rig("virtual:cornell", ideal=True, resolution=(res, res), patch_size=patch, cache_dir=False)
        setup = time.perf_counter() - t
        r = v.renderer
        for light, (ambient, emitted) in {"ceiling light": (True, None), "projector white": (False, white)}.items():
            e = r.direct_light(emitted, ambient=ambient, dtype=np.float64)
            direct = r.to_image(r.rho * e, ambient=ambient)
            full = v.truth.photograph(ambient=ambient, pattern=emitted)
            ratio = (full - direct)[wall].sum(0) / direct[wall].sum(0)
            print(
                f"{'virtual, patches ' + str(patch) + ' m':<30} {light:<16} "
                + " ".join(f"{x:7.4f}" for x in ratio)
                + f" {100 * (ratio[1] / mi_ratio[light][1] - 1):+14.1f}% {setup:7.1f} s",
                flush=True,
            )
        v.close()


#: The paper's Fig. 6 blue (albedo): ``grazing`` recolors each wall to it, as the demo's κ does the Cornell green.
PAPER_BLUE = np.array([0.2, 0.1, 0.8])


def checker_direct_error(rig, target, channel):
    """D of ``target``'s solid pixels from the engine's checkerboards, relative to the rig's exact D.

    The estimator of :func:`engine.acquire.prepare_target` (the mean of the captures whose 3×3
    projector neighbourhood was all lit minus that of those where it was all unlit), on one
    primary, through ``rig.truth`` so that a virtual and a path-traced rig are measured alike;
    co-axial rig with the projector at the camera's resolution (projector pixel = camera pixel).
    Returns the (H, W) relative error (0 off the measured pixels) and those pixels.
    """
    from engine.calibrate import high_frequency_patterns

    solid = rig.coverage[target] >= 1
    kernel = np.ones((3, 3), np.uint8)
    total = {True: np.zeros(solid.shape), False: np.zeros(solid.shape)}
    count = {True: np.zeros(solid.shape), False: np.zeros(solid.shape)}
    for pattern in high_frequency_patterns(solid.shape, mask_projector=solid):
        shown = np.zeros(pattern.shape, np.float32)
        shown[..., channel] = pattern[..., channel]
        on = pattern[..., channel] > 0.5
        states = {True: cv2.erode((on | ~solid).astype(np.uint8), kernel, borderType=cv2.BORDER_REPLICATE) > 0,
                  False: cv2.dilate(on.astype(np.uint8), kernel, borderType=cv2.BORDER_REPLICATE) == 0}
        capture = rig.truth.photograph(ambient=False, pattern=shown)[..., channel]
        for state, where in states.items():
            total[state] += np.where(where, capture, 0)
            count[state] += where
    measured = solid & (count[True] > 0) & (count[False] > 0)
    d = total[True] / np.maximum(count[True], 1) - total[False] / np.maximum(count[False], 1)
    exact = rig.truth.direct()[..., channel]
    return np.where(measured, d / np.where(measured, exact, 1) - 1, 0), measured


def part_grazing(args):
    """The direct image D on a wall beside concave corners and seen at a grazing angle: its bias, what κ makes of it.

    Ideal co-axial rig, one sample a pixel. D is measured as shipped (checkerboards of 4×4
    projector pixels, :func:`engine.calibrate.high_frequency_patterns`) and compared with the
    rig's exact D (``truth.direct``); each acquisition is repeated with the exact D put in its
    place (an oracle). R^1 L_d: the first interreflection component against ``truth.components``
    on the target. Recolor: whole image without the lamp, with the demo's κ = (2, 0.125, 8) and with
    the κ that takes the wall to the paper's blue (the demo's κ on the Cornell box's green wall).
    """
    from engine.acquire.target import prepare_target

    # (scene, target, camera pixels a side, checkerboard period, radiosity patch size in m: None = the scene's)
    cases = [("checker", "right_wall", 48, 8, None), ("checker", "right_wall", 48, 6, None),
             ("checker", "panel", 48, 8, None), ("cornell", "right_wall", 48, 8, None)]
    if not args.quick:  # finer light transport (a 4-minute set-up the first time), and finer pixels
        cases[2:2] = [("checker", "right_wall", 48, 8, 0.05), ("checker", "right_wall", 96, 8, None)]
    print("\n== grazing wall: D from the checkerboards vs the exact D, ideal co-axial virtual rig; "
          "errors measured D / exact D ==")
    print(f"{'scene':<8} {'target':<11} {'res':>4} {'patches':>7} {'squares':>7} {'D err rms / max':>16} "
          f"{'R^1 L_d (K=6)':>15} {'κ=(2,.125,8) K=4':>17} {'K=6':>15} {'κ → blue':>20} {'K=6':>15}")
    for scene, target, res, period, patch in cases:
        rig = devices.open_rig(f"virtual:{scene}", ideal=True, resolution=(res, res),
                               **({} if patch is None else {"patch_size": patch}))
        exp = Experiment(rig, target, 6)
        base = exp.rec.capture(f"{target}-black", exp.rec.black())
        shifts = 2 if period == 8 else 3
        measured = prepare_target(exp.rec, exp.calibration, exp.hard, base, period=period, shifts=shifts)
        mask = measured.mask
        exact_d = np.where(mask[:, :, None], rig.truth.direct(mask), 0).astype(np.float32)
        exact = replace(measured, direct=exact_d)
        rel = (measured.direct[mask] / exact_d[mask] - 1).ravel()
        comps = rig.truth.components(exp.hard, 2, ambient=exp.ambient, pattern=exp.flood)
        blue = PAPER_BLUE / rig.truth.albedo()[exp.hard].mean(axis=0)
        lamp = rig.truth.emitters()
        truths = {"demo": exp.truth(K2), "blue": exp.truth(blue)}
        cells = {}
        for order in (4, 6):
            for label, prepared in (("measured", measured), ("exact", exact)):
                acq = acquire_single(exp.rec, exp.calibration, exp.hard, order, photograph_pattern=exp.flood,
                                     prepared=prepared, name=f"{label}-{order}")
                d = acq.target.decompose(acq.observations)
                if order == 6:
                    cells["r1", label] = relative_error(d.components[1], comps.inside[1], exp.hard)
                    cells["blue", label] = relative_error(recolor(d, blue), truths["blue"], ~lamp)
                cells[f"demo{order}", label] = relative_error(recolor(d, K2), truths["demo"], ~lamp)

        def pair(key, cells=cells):
            return f"{100 * cells[key, 'measured']:5.2f} / {100 * cells[key, 'exact']:4.2f}%"

        kappa = ",".join(f"{x:.2g}" for x in blue)
        patches = f"{rig.scene.patch_size:g} m" if patch is None else f"{patch:g} m"
        print(f"{scene:<8} {target:<11} {res:4d} {patches:>7} {period // 2:>5} px "
              f"{100 * np.sqrt(np.mean(rel**2)):6.2f} / {100 * np.abs(rel).max():4.2f}% {pair('r1'):>15} "
              f"{pair('demo4'):>17} {pair('demo6'):>15} {'(' + kappa + ')':>20} {pair('blue'):>15}", flush=True)
        rig.close()
    if args.quick:
        return
    try:
        import mitsuba  # noqa: F401  (the optional extra)
    except ImportError:
        print("(path-traced check skipped: the mitsuba extra is not installed)")
        return
    spp = 1024
    print(f"-- the same checkerboards on the path-traced Cornell box (mitsuba:cornell 48², {spp} spp a capture) and "
          "the virtual one: D's relative error on the right wall's solid pixels, green (the wall's colour)")
    maps = {}
    for name in ("virtual:cornell", "mitsuba:cornell"):
        extra = {"spp": spp, "ambient_spp": spp, "truth_spp": spp} if name.startswith("mitsuba") else {}
        rig = devices.open_rig(name, ideal=True, resolution=(48, 48), **extra)
        maps[name] = checker_direct_error(rig, "right_wall", 1)
        rig.close()
    (v, v_ok), (m, m_ok) = maps["virtual:cornell"], maps["mitsuba:cornell"]
    both = v_ok & m_ok
    worst = both & (np.abs(v) >= np.percentile(np.abs(v[both]), 90))  # where the virtual rig's bias is largest
    for name, (rel, ok) in maps.items():
        print(f"{name:<16} rms {100 * np.sqrt(np.mean(rel[ok] ** 2)):5.2f} %, "
              f"max {100 * np.abs(rel[ok]).max():5.2f} %, on the virtual rig's worst decile "
              f"(signed as the virtual bias) {100 * np.mean((np.sign(v) * rel)[worst]):5.2f} %")
    corr = np.corrcoef(v[both], m[both])[0, 1]
    print(f"correlation of the two maps over {int(both.sum())} pixels: {corr:.2f}", flush=True)


PARTS = {
    "ratio": part_ratio,
    "cornell": part_cornell,
    "noise": part_noise,
    "virtual": part_virtual,
    "edge": part_edge,
    "posed": part_posed,
    "realistic": part_realistic,
    "fig13": part_fig13,
    "fig13spp": part_fig13_samples,
    "fig3": part_fig3,
    "fig12": part_fig12,
    "grazing": part_grazing,
}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--parts", nargs="+", choices=sorted(PARTS), default=["virtual", "cornell", "fig12", "fig3", "fig13"]
    )
    parser.add_argument("--quick", action="store_true", help="tiny renders (a smoke run, not the figures)")
    parser.add_argument("--resolution", type=int, default=None,
                        help="camera pixels a side for cornell (default 64), virtual (128) and edge (48)")
    parser.add_argument("--spp", type=int, default=1024)
    parser.add_argument("--fig13-spp", type=int, default=512, help="samples per pixel of fig13's captures")
    parser.add_argument("--fig13-coat", choices=sorted(FIG13_TINTS), default="tinted",
                        help="fig13/fig13spp's coat: tinted like the paint (the paper's specular share of the total "
                             "albedo) or white (the share 16/36/16 %% at s = 0.1)")
    parser.add_argument("--fig13-cells", type=_share_alpha, nargs="+", metavar="SHARE:ALPHA",
                        default=[(0.0, 0.009), (0.1, 0.009), (0.1, 0.05)],
                        help="fig13spp's cells: specular share and GGX roughness, e.g. 0.03:0.009")
    parser.add_argument("--fig13-spp-sweep", type=int, nargs="+", default=[512, 2048, 4096],
                        help="samples per pixel of fig13spp's captures, one cell each")
    parser.add_argument("--fig12-spp", type=int, nargs="+", default=[1024],
                        help="samples per pixel of fig12's path-traced captures and truth, one run each")
    parser.add_argument("--fig12-masks", nargs="+", choices=["hard", "soft", "true"], default=["hard", "soft"],
                        help="fig12's path-traced acquisitions: hard mask (the previous behaviour), soft mask "
                             "refined from the photograph, the rig's true coverage")
    parser.add_argument("--fig12-truths", type=int, default=8,
                        help="truth renders averaged into fig12's reference (even)")
    args = parser.parse_args(argv)
    for part in args.parts:
        t = time.perf_counter()
        PARTS[part](args)
        print(f"({part}: {time.perf_counter() - t:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
