"""Ground truth of the path-traced rig: the scene re-rendered with targets' reflectance scaled.

The truth is per *shape*: a mask stands for the shapes it covers (at least half of a shape's
visible footprint painted), and recoloring scales those shapes' diffuse reflectance wherever
they are seen — in mixed edge pixels, in reflections on a glossy floor, and where the mask
was not painted. Truth renders carry Monte Carlo noise at ``truth_spp`` samples per pixel;
each call draws new seeds, so two calls give two independent renders (their difference is
the render's own noise floor). The interaction components come from renders with the
shapes' whole BSDF scaled, on one sample sequence (:meth:`Truth.components`).
"""

from __future__ import annotations

import numpy as np

from devices.mitsuba.render import TRUTH_SEEDS, Renderer, mitsuba
from devices.virtual.camera import CameraModel
from devices.virtual.projector import ProjectorModel, check_pattern
from devices.virtual.truth import Components
from engine.checks import check_kappa_pairs, check_mask, check_order
from engine.errors import InputError


class Truth:
    """Ground truth of a mitsuba rig (``rig.truth``).

    Parameters
    ----------
    renderer : Renderer
    projector_model : ProjectorModel
    camera_model : CameraModel
    coverage : (S, H, W) float32
        Footprint fraction of each shape in each pixel (:meth:`Renderer.coverage`).

    Attributes
    ----------
    projector_model, camera_model
        The devices' true models.
    shape_ids : list of str
    spp : int
        Samples per pixel of every truth render.
    """

    def __init__(
        self, renderer: Renderer, projector_model: ProjectorModel, camera_model: CameraModel, coverage: np.ndarray
    ):
        self._r = renderer
        self.projector_model = projector_model
        self.camera_model = camera_model
        self.shape = renderer.shape
        self.shape_ids = list(renderer.shape_ids)
        self.spp = renderer.truth_spp
        self._coverage = coverage
        self._calls = 0

    def _emitted(self, pattern):
        if pattern is None:
            pattern = np.zeros(self._r.projector_resolution + (3,), np.float32)
        pattern = check_pattern(pattern, self._r.projector_resolution, name="pattern")
        return self.projector_model.emit(pattern)

    def _render(self, ambient: bool, pattern) -> np.ndarray:
        if not isinstance(ambient, (bool, np.bool_)):
            raise InputError(f"ambient must be True or False, got {ambient!r}")
        self._calls += 1
        return self._r.render_lights(
            ambient=bool(ambient),
            emitted=self._emitted(pattern),
            spp=self.spp,
            seed=TRUTH_SEEDS + self._calls,
            what=f"rendering ground truth ({self.spp} spp)",
        )

    def shapes_of(self, mask: np.ndarray) -> list[str]:
        """Shapes a camera mask stands for: those with at least half their visible footprint in it."""
        mask = check_mask("mask", mask, self.shape)
        seen = self._coverage.sum(axis=(1, 2))
        inside = (self._coverage * mask[None]).sum(axis=(1, 2))
        return [sid for sid, s, i in zip(self.shape_ids, seen, inside, strict=True) if s > 0 and i >= 0.5 * s]

    def coverage(self, mask: np.ndarray) -> np.ndarray:
        """(H, W) float32 fraction of each pixel's footprint on the shapes ``mask`` stands for."""
        ids = set(self.shapes_of(mask))
        sel = [k for k, sid in enumerate(self.shape_ids) if sid in ids]
        return self._coverage[sel].sum(axis=0) if sel else np.zeros(self.shape, np.float32)

    def photograph(self, *, ambient: bool = True, pattern: np.ndarray | None = None) -> np.ndarray:
        """A render of the scene at ``spp`` (ambient light on or off, projector input ``pattern``).

        Returns
        -------
        (H, W, 3) float32
        """
        return self._render(ambient, pattern)

    def recolor(
        self, pairs, *, ambient: bool = True, pattern: np.ndarray | None = None, coat: bool = False
    ) -> np.ndarray:
        """The scene re-rendered with the diffuse reflectance of each mask's shapes scaled by its κ.

        Parameters
        ----------
        pairs : sequence of (mask, kappa)
            ``mask`` (H, W) bool, ``kappa`` scalar or (3,); kappas of shapes in several masks
            multiply.
        ambient, pattern
            As :meth:`photograph`.
        coat : bool, default False
            Scale a glossy coat's specular reflectance too, so that every light path is
            weighted by κ to the power of its reflections off the shapes, glossy or diffuse:
            the recolor of the interaction components the paper counts for its Fig. 13 (a
            path tracer tagging every interaction with the target). False (the default) is
            the physical repaint: the paint under the coat changes, its gloss does not.

        Returns
        -------
        (H, W, 3) float32

        Raises
        ------
        InputError
            Bad masks or kappas, or a mask that covers no shape.
        """
        if not isinstance(coat, (bool, np.bool_)):
            raise InputError(f"coat must be True or False, got {coat!r}")
        factors: dict[str, np.ndarray] = {}
        for k, (mask, kappa) in enumerate(check_kappa_pairs(pairs, self.shape)):
            ids = self.shapes_of(mask)
            if not ids:
                raise InputError(f"pairs[{k}] mask covers no shape (at least half of a shape's visible pixels)")
            for sid in ids:
                factors[sid] = factors.get(sid, np.ones(3)) * kappa
        with self._r.scaled(factors, coat=bool(coat)):
            return self._render(ambient, pattern)

    def direct(self, mask: np.ndarray | None = None) -> np.ndarray:
        """The direct image D: one bounce of full linear projector white, ambient off (at ``spp``)."""
        mi = mitsuba()
        self._calls += 1
        ones = np.ones(self._r.projector_resolution + (3,), np.float32)
        d = self._r.render_lights(
            ambient=False,
            emitted=ones,
            spp=self.spp,
            seed=TRUTH_SEEDS + self._calls,
            integrator=mi.load_dict({"type": "path", "max_depth": 2}),
        )
        if mask is not None:
            mask = check_mask("mask", mask, self.shape)
            d = np.where(mask[..., None], d, 0).astype(np.float32)
        return d

    def emitters(self) -> np.ndarray:
        """(H, W) bool: pixels that see a light source directly (any part of their footprint)."""
        lamps = [k for k, s in enumerate(self._r.scene.shapes()) if s.emitter() is not None]
        return np.any(self._coverage[lamps] > 0, axis=0) if lamps else np.zeros(self.shape, bool)

    def components(
        self, mask: np.ndarray, order: int, *, ambient: bool = True, pattern: np.ndarray | None = None
    ) -> Components:
        """The interaction components of the shapes ``mask`` stands for, every interaction counted.

        Parameters
        ----------
        mask : (H, W) bool
            Target pixels; the shapes are those of :meth:`shapes_of`.
        order : int
            K, the number of components (>= 1).
        ambient, pattern
            As :meth:`photograph`.

        Returns
        -------
        devices.virtual.truth.Components
            ``inside[i]`` on the mask and ``outside[i]`` off it: light that reflected exactly
            i + 1 times off the shapes (``R^i L_d``, ``C R^i L_d``); ``unreached`` off the
            mask: light that never touched them (``L̄_d``).

        Notes
        -----
        A reflection off a glossy coat counts as an interaction, as in the paper's Fig. 13 (a
        path tracer tagging every interaction with the target). Each path's contribution is
        ``t^n`` times its value when the shapes' whole BSDF is scaled by ``t`` (n: its
        reflections off them), so with Russian roulette off and the *same* sample sequence
        for every render, the render is exactly a polynomial in ``t`` pixel by pixel. K + 2
        renders at ``t`` in [0.25, 2.2] give its coefficients up to degree K + 1 (the last
        absorbs the higher orders, which are many decades below at these ``t``); the
        components carry the Monte Carlo noise of one render at ``spp``.
        """
        mi = mitsuba()
        order = check_order(order)
        mask = check_mask("mask", mask, self.shape)
        ids = self.shapes_of(mask)
        if not ids:
            raise InputError("mask covers no shape (at least half of a shape's visible pixels)")
        if not isinstance(ambient, (bool, np.bool_)):
            raise InputError(f"ambient must be True or False, got {ambient!r}")
        emitted = self._emitted(pattern)
        depth = self._r.max_depth
        no_roulette = mi.load_dict({"type": "path", "max_depth": depth, "rr_depth": depth + 1})
        self._calls += 1
        seed = TRUTH_SEEDS + self._calls  # one sample sequence for every t
        ts = np.linspace(0.25, 2.2, order + 2)
        renders = []
        for t in ts:
            with self._r.scaled({sid: np.full(3, t) for sid in ids}, coat=True):
                img = self._r.render_lights(ambient=bool(ambient), emitted=emitted, spp=self.spp, seed=seed,
                                            integrator=no_roulette)
            renders.append(img.astype(np.float64))
        stack = np.stack(renders).reshape(len(ts), -1)
        coef = np.linalg.solve(np.vander(ts, len(ts), increasing=True), stack).reshape((len(ts),) + renders[0].shape)
        terms = np.maximum(coef[: order + 1], 0)  # every path adds a non-negative amount: below 0 is rounding
        m = mask[None, ..., None]
        return Components(
            inside=np.where(m, terms[1:], 0).astype(np.float32),
            outside=np.where(m, 0, terms[1:]).astype(np.float32),
            unreached=np.where(mask[..., None], 0, terms[0]).astype(np.float32),
            target=mask.copy(),
            order=order,
        )
