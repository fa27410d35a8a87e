"""Ground truth of the virtual rig, exact within its light-transport model.

Everything here comes from the transport itself (:mod:`devices.virtual.transport`), never
from the paper's measurement method, so the method can be checked against it.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from devices.virtual.camera import CameraModel
from devices.virtual.projector import ProjectorModel, check_pattern
from devices.virtual.render import Renderer
from devices.virtual.transport import Resolvent, interactions
from engine.checks import check_kappa_pairs, check_mask, check_order
from engine.errors import InputError


@dataclass(frozen=True, eq=False)
class Components:
    """Ground-truth interaction components of one target (paper Eqs. 2-4).

    Attributes
    ----------
    inside : (K, H, W, 3) float32
        ``R^i L_d`` for i = 0..K-1 on target pixels (0 elsewhere): light that reflected
        exactly i + 1 times on the target.
    outside : (K, H, W, 3) float32
        ``C R^i L_d`` for i = 0..K-1 on the other pixels (0 on the target). The engine's
        decomposition estimates K-1 of them (K when the unreached light is known to be 0).
    unreached : (H, W, 3) float32
        ``L̄_d``: light at non-target pixels that never touched the target.
    target : (H, W) bool
    order : int
        K.
    """

    inside: np.ndarray
    outside: np.ndarray
    unreached: np.ndarray
    target: np.ndarray
    order: int


class Truth:
    """Ground truth of a virtual rig (``rig.truth``).

    Parameters
    ----------
    renderer : Renderer
    projector_model : ProjectorModel
    camera_model : CameraModel
    projector_resolution : (Hp, Wp)

    Attributes
    ----------
    projector_model : ProjectorModel
        The projector's true response (gamma, black level, crosstalk) for calibration tests.
    camera_model : CameraModel
        The camera's true scale and noise.
    scene : devices.virtual.scene.Scene

    Notes
    -----
    All radiance is computed in float64 and returned as float32. ``ambient`` switches the
    scene's ambient light; ``pattern`` is a projector input image passed through the same
    projector model as :meth:`VirtualProjector.show` (None = projector showing black, which
    still leaks its black level unless the rig is ideal).
    """

    def __init__(self, renderer: Renderer, projector_model: ProjectorModel, camera_model: CameraModel,
                 projector_resolution: tuple[int, int]):
        self._r = renderer
        self.projector_model = projector_model
        self.camera_model = camera_model
        self.scene = renderer.scene
        hp, wp = projector_resolution
        self._proj_res = (hp, wp)
        self.shape = renderer.shape

    # --- helpers --------------------------------------------------------------------------
    def _light(self, ambient: bool, pattern) -> np.ndarray:
        if not isinstance(ambient, (bool, np.bool_)):
            raise InputError(f"ambient must be True or False, got {ambient!r}")
        if pattern is None:
            pattern = np.zeros(self._proj_res + (3,), np.float32)
        pattern = check_pattern(pattern, self._proj_res, name="pattern")
        return self._r.direct_light(self.projector_model.emit(pattern), ambient=bool(ambient), dtype=np.float64)

    def _pixels_to_samples(self, mask: np.ndarray) -> np.ndarray:
        """The surface a camera mask stands for, as samples.

        Pixel centres follow the mask. The sub-samples of a mixed pixel in or next to the
        mask follow the *surfaces* the mask covers — quads with at least half of their
        (unmixed) pixels painted — so that a target's edge is recolored where the target is,
        whether or not the artist painted the mixed pixel, as on a real object. A quad with no
        unmixed pixel (under a posed projector nearly every pixel is mixed) counts the pixels
        whose centre it holds.
        """
        s = self._r.setup
        n = self._r.n_pixels
        sel = np.zeros(len(self._r.rho), bool)
        flat = mask.ravel()
        sel[:n] = flat
        if len(s.sub_pixel):
            pq = np.where(s.quad[:n] >= 0, s.quad[:n], -1)  # unmixed pixels' quads
            nq = len(self.scene.quads)
            seen = np.bincount(pq[pq >= 0], minlength=nq)
            painted = np.bincount(pq[(pq >= 0) & flat], minlength=nq)
            centre = np.asarray(s.pixel_quad)[:n]  # the quad at each pixel's centre, mixed or not
            seen_c = np.bincount(centre[centre >= 0], minlength=nq)
            painted_c = np.bincount(centre[(centre >= 0) & flat], minlength=nq)
            painted = np.where(seen > 0, painted, painted_c)
            seen = np.where(seen > 0, seen, seen_c)
            owned = (seen > 0) & (painted >= 0.5 * seen)
            near = cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8)).ravel() > 0
            vis = s.n_visible
            sq = s.quad[n:vis]
            sel[n:vis] = near[s.sample_pixel()[n:]] & (sq >= 0) & owned[np.maximum(sq, 0)]
        return sel

    def coverage(self, mask: np.ndarray) -> np.ndarray:
        """(H, W) float32: fraction of each pixel's footprint on the surface ``mask`` stands for.

        1/0 on unmixed pixels (the mask itself); the fraction of sub-samples on the mask's
        surfaces on mixed pixels (see :meth:`recolor`).
        """
        mask = check_mask("mask", mask, self.shape)
        sel = self._pixels_to_samples(mask)[:self._r.setup.n_visible].astype(np.float64)[:, None]
        return self._r.setup.pixel_values(sel)[:, 0].reshape(self.shape).astype(np.float32)

    def _image(self, radiance: np.ndarray, ambient: bool) -> np.ndarray:
        return self._r.to_image(radiance, ambient=bool(ambient)).astype(np.float32)

    # --- public ---------------------------------------------------------------------------
    def photograph(self, *, ambient: bool = True, pattern: np.ndarray | None = None) -> np.ndarray:
        """Noise-free radiance of the scene.

        Parameters
        ----------
        ambient : bool
            Ambient light on.
        pattern : (Hp, Wp, 3) float in [0, 1], optional
            Projector input (None = black).

        Returns
        -------
        (H, W, 3) float32
        """
        e = self._light(ambient, pattern)
        return self._image(self._r.base.solve(e), ambient)

    def recolor(self, pairs, *, ambient: bool = True, pattern: np.ndarray | None = None) -> np.ndarray:
        """The photograph after scaling the albedo seen by each mask by its kappa.

        Parameters
        ----------
        pairs : sequence of (mask, kappa)
            ``mask`` (H, W) bool camera pixels, ``kappa`` scalar or (3,). Where masks overlap
            their kappas multiply. Only the camera-visible surface is recoloured (hidden parts
            of the same surface keep their albedo), as in the paper. On a supersampled rig a
            mask also recolors the part of its surfaces seen in mixed pixels next to it.
        ambient, pattern
            As :meth:`photograph`.

        Returns
        -------
        (H, W, 3) float32

        Raises
        ------
        InputError
            Bad masks or kappas, or kappas so large that the scene would amplify light
            (the interaction series diverges; no physical solution).
        """
        e = self._light(ambient, pattern)
        scale = np.ones_like(self._r.rho)
        for mask, kappa in check_kappa_pairs(pairs, self.shape):
            scale[self._pixels_to_samples(mask)] *= kappa
        rho = self._r.rho * scale
        out = Resolvent(self._r.setup, rho).solve(e)
        if out.size and out.min() < -1e-9 * max(float(np.abs(out).max()), 1e-30):
            raise InputError("these kappas make the target reflect more light than it receives "
                             "round its interreflections (the interaction series diverges); use smaller kappas")
        return self._image(out, ambient)

    def interactions(self, mask: np.ndarray, n_terms: int, *, ambient: bool = True,
                     pattern: np.ndarray | None = None) -> np.ndarray:
        """Radiance split by the number of reflections on the target.

        Parameters
        ----------
        mask : (H, W) bool
            Target pixels (set A).
        n_terms : int
            Highest number of interactions (>= 0).
        ambient, pattern
            As :meth:`photograph`.

        Returns
        -------
        (n_terms + 1, H, W, 3) float32
            ``L_n``: radiance of all paths that reflected exactly n times on the target, so
            ``sum_n kappa**n L_n`` tends to ``recolor([(mask, kappa)])``. Lights seen directly
            are in ``L_0``.
        """
        mask = check_mask("mask", mask, self.shape)
        n_terms = check_order(n_terms, name="n_terms", minimum=0)
        e = self._light(ambient, pattern)
        terms = interactions(self._r.setup, self._r.rho, self._pixels_to_samples(mask), e, n_terms)
        out = np.empty((n_terms + 1,) + self.shape + (3,), np.float32)
        out[0] = self._image(terms[0], ambient)
        for n in range(1, n_terms + 1):
            out[n] = self._r.to_image(terms[n], ambient=False)
        return out

    def interactions_by_surface(self, mask: np.ndarray, n_terms: int, *, ambient: bool = True,
                                pattern: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`interactions` split into the light of the target's surfaces and of the rest.

        Returns
        -------
        on, off : (n_terms + 1, H, W, 3) float32
            Per pixel, the part of ``L_n`` its sub-samples on the surfaces ``mask`` stands for
            carry (divided by all its sub-samples: ``on + off`` is :meth:`interactions`), and
            the rest's. On a mixed pixel of the target's edge, ``on`` is the target part of the
            pixel and ``off`` the neighbour's; lights seen directly are in ``off[0]``.
        """
        mask = check_mask("mask", mask, self.shape)
        n_terms = check_order(n_terms, name="n_terms", minimum=0)
        e = self._light(ambient, pattern)
        sel = self._pixels_to_samples(mask)
        terms = interactions(self._r.setup, self._r.rho, sel, e, n_terms)
        on = np.empty((n_terms + 1,) + self.shape + (3,), np.float32)
        off = np.empty_like(on)
        for n in range(n_terms + 1):
            on[n] = self._r.to_image(terms[n] * sel[:, None], ambient=False)
            off[n] = self._r.to_image(terms[n] * ~sel[:, None], ambient=bool(ambient) and n == 0)
        return on, off

    def components(self, mask: np.ndarray, order: int, *, ambient: bool = True,
                   pattern: np.ndarray | None = None) -> Components:
        """The interaction components the paper's decomposition estimates.

        Parameters
        ----------
        mask : (H, W) bool
            Target pixels.
        order : int
            K, the number of components (>= 1).
        ambient, pattern
            As :meth:`photograph`.

        Returns
        -------
        Components
            ``inside[i] = L_{i+1}`` on the mask (``R^i L_d``), ``outside[i] = L_{i+1}`` off
            it (``C R^i L_d``), ``unreached = L_0`` off it (``L̄_d``), i = 0..K-1.
            Emission seen on target pixels (a light inside the mask) is not represented.
        """
        order = check_order(order)
        terms = self.interactions(mask, order, ambient=ambient, pattern=pattern)
        m = mask[None, ..., None]
        return Components(inside=np.where(m, terms[1:], 0).astype(np.float32),
                          outside=np.where(m, 0, terms[1:]).astype(np.float32),
                          unreached=np.where(mask[..., None], 0, terms[0]).astype(np.float32),
                          target=mask.copy(), order=order)

    def direct(self, mask: np.ndarray | None = None) -> np.ndarray:
        """The direct image D: direct outgoing radiance per unit of linear projector output.

        Parameters
        ----------
        mask : (H, W) bool, optional
            Restrict to these pixels (0 elsewhere).

        Returns
        -------
        (H, W, 3) float32
            ``albedo * projector irradiance`` for full linear output of each primary
            (response, black level and crosstalk excluded), 0 where the projector cannot
            reach the pixel's surface point (outside its frustum or shadowed).

        Notes
        -----
        Paper Sec. 3.3: emitting ``L`` gives ``L_d = D L`` on the target, so emitting
        ``I / D`` (through the inverse response) makes the target's outgoing radiance ``I``.
        """
        ones = np.ones(self._proj_res + (3,))
        e = self._r.direct_light(ones, ambient=False, dtype=np.float64)
        d = self._r.to_image(self._r.rho * e, ambient=False)
        if mask is not None:
            mask = check_mask("mask", mask, self.shape)
            d = np.where(mask[..., None], d, 0.0)
        return d.astype(np.float32)

    def correspondence(self) -> tuple[np.ndarray, np.ndarray]:
        """Where each camera pixel's surface point falls in the projector.

        Returns
        -------
        proj_xy : (H, W, 2) float32
            Projector pixel coordinates (x = column, y = row, pixel centres at integers) of
            the pixel's surface point; NaN where the pixel sees no surface.
        lit : (H, W) bool
            The point is inside the projector's frustum, faces it and is not shadowed (a
            mixed pixel: at least half of its footprint is).
        """
        s = self._r.setup
        xy = s.proj_xy.reshape(self.shape + (2,)).astype(np.float32)
        lit = s.pixel_values(s.proj_lit[:s.n_visible].astype(np.float32)).reshape(self.shape) >= 0.5
        return xy, lit

    def emitters(self) -> np.ndarray:
        """(H, W) bool: pixels that see a light source (a lamp) directly.

        Their radiance dwarfs every diffuse surface's, so a relative error over the whole
        image mostly measures the lamp (which any method reproduces exactly); accuracy
        figures are also given with these pixels left out.
        """
        return (self._r.emission[:self._r.n_pixels] > 0).any(axis=-1).reshape(self.shape)

    def albedo(self) -> np.ndarray:
        """(H, W, 3) float32 albedo of the surface seen at each pixel (0 where none)."""
        return self._r.to_image(self._r.rho, ambient=False).astype(np.float32)
