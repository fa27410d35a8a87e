"""Absolute albedo: the scale between a target's direct image D and what it reflects.

``D = ρ E_p`` (Sec. 3.3): albedo times the projector's light on the surface. A reference of
known reflectance lit like the target fixes ``E_p`` per channel, and then ``ρ = D / E_p``.
Two references:

- a ColorChecker beside the target, in the same plane: one scale per channel fitted to its
  24 patches, times the way the projector's light varies over that plane
  (:func:`fit_albedo_scale`);
- a card of known reflectance laid over the target (the paper's Fig. 7 swaps papers the same
  way): a scale per pixel (:func:`reference_scale`), exact whatever the geometry.

Without a reference, only relative colours are known (:func:`engine.colour.direct_colour`):
a surface's absolute albedo cannot be told from light that is brighter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.checks import check_float_image, check_mask
from engine.errors import InputError

__all__ = ["AlbedoScale", "fit_albedo_scale", "reference_scale"]

#: A patch whose D departs from the fit by more than this (relative) is left out of it.
OUTLIER = 0.10
#: Patches needed for a fit.
MIN_PATCHES = 6


@dataclass(frozen=True, eq=False)
class AlbedoScale:
    """Direct light per unit albedo, per channel (or per pixel and channel).

    Attributes
    ----------
    scale : (3,) or (H, W, 3) float64
        ``E_p``: D of a perfectly white surface where the reference was.
    valid : (H, W) bool or None
        For a per-pixel scale, the pixels it covers.
    residual : (N, 3) float64 or None
        Per reference patch and channel, ``D / (scale ρ) − 1`` (a checker fit's quality).
    used : (N,) bool or None
        Patches the fit kept (the rest were missing or outliers).
    source : str
        ``"checker"`` or ``"reference"``.
    plane : (3,) float64 or None
        The projector's light over the chart's plane, ``f(x, y) = (a + b x + c y)³`` in
        projector pixels, 1 at the chart's centre (None: taken as uniform).
    """

    scale: np.ndarray
    valid: np.ndarray | None = None
    residual: np.ndarray | None = None
    used: np.ndarray | None = None
    source: str = "checker"
    plane: np.ndarray | None = None

    def light(self, projector_xy) -> np.ndarray:
        """``f``: the projector's light at projector pixels ``(..., 2)`` relative to the chart's centre."""
        xy = np.asarray(projector_xy, np.float64)
        if self.plane is None:
            return np.ones(xy.shape[:-1])
        return _plane_light(self.plane, xy)

    @property
    def rms_residual(self) -> float:
        """Root-mean-square relative residual of the kept patches (0 for a per-pixel reference)."""
        if self.residual is None or self.used is None:
            return 0.0
        return float(np.sqrt(np.mean(self.residual[self.used] ** 2)))

    def albedo(self, direct, target, projector_xy=None) -> np.ndarray:
        """The target's absolute albedo.

        Parameters
        ----------
        direct : (H, W, 3) float
            The target's direct image D, in the same units as the reference's.
        target : (H, W) bool
            Target pixels; those where D is 0 (not measured) are skipped, and for a
            per-pixel reference those it does not cover.
        projector_xy : (H, W, 2) float, optional
            Projector pixel (x, y) of each camera pixel (the target's correspondence); needed
            when the fit modelled the projector's light over the chart's plane.

        Returns
        -------
        (3,) float64
            ``mean D / (scale f)`` over the target (per-pixel scale: mean of ``D / scale``).

        Raises
        ------
        InputError
            Shapes disagree, or no target pixel has both D and a scale.

        Examples
        --------
        >>> s = AlbedoScale(np.array([2.0, 4.0, 1.0]))
        >>> d = np.full((1, 2, 3), [1.0, 1.0, 0.5])
        >>> s.albedo(d, np.array([[True, True]])).tolist()
        [0.5, 0.25, 0.5]
        """
        d = check_float_image("direct", direct, ndim=3)
        t = check_mask("target", target, d.shape[:2])
        use = t & np.all(d > 0, axis=-1)
        if self.valid is not None:
            if self.valid.shape != t.shape:
                raise InputError(f"the reference covers a {self.valid.shape} image, the target is {t.shape}")
            use &= self.valid
        if not use.any():
            where = " under the reference card" if self.valid is not None else ""
            raise InputError(f"no target pixel has a measured D{where}")
        if self.scale.ndim == 1 and self.plane is None:
            return d[use].astype(np.float64).mean(axis=0) / self.scale
        if self.scale.ndim == 1:
            if projector_xy is None:
                raise InputError("this albedo scale models the projector's light over the chart's plane: "
                                 "give the target's projector coordinates (its correspondence)")
            xy = np.asarray(projector_xy, np.float64)
            if xy.shape != t.shape + (2,):
                raise InputError(f"projector_xy must be (H, W, 2) = {t.shape + (2,)}, got {xy.shape}")
            return (d[use].astype(np.float64) / self.light(xy[use])[:, None]).mean(axis=0) / self.scale
        return (d[use].astype(np.float64) / self.scale[use]).mean(axis=0)


def fit_albedo_scale(patch_direct, reflectances, *, patch_xy=None, outlier: float = OUTLIER) -> AlbedoScale:
    """Fit D = scale · ρ per channel over a chart's patches.

    Parameters
    ----------
    patch_direct : (N, 3) float
        Each patch's mean D (:func:`engine.checker.sample_patches` of the chart's direct
        image); NaN for a patch that was not measured.
    reflectances : (N, 3) float
        The patches' albedo (:func:`engine.checker.reference_reflectances`).
    patch_xy : (N, 2) float, optional
        Projector pixel (x, y) of each patch's centre. Given, the projector's light over the
        chart's plane is fitted too (``D = scale · ρ · f(x, y)``); else it is taken as uniform.
    outlier : float
        Patches off the first fit by more than this relative amount in any channel (a
        misplaced corner, a specular glint, a shadow) are dropped and the fit repeated once.

    Returns
    -------
    AlbedoScale
        ``source == "checker"``, with the per-patch residuals.

    Raises
    ------
    InputError
        Shapes disagree, or fewer than 6 usable patches.

    Notes
    -----
    Least squares through the origin per channel, ``s = Σ D ρ f / Σ (ρ f)²``: bright patches
    (best measured) weigh most. A pinhole projector's light on a plane is
    ``cos θ / (d² cos³ α) = h / z³`` (θ incidence, α off-axis angle, h the projector's distance
    to the plane, z depth along its axis), and ``1 / z`` is affine in projector pixels on a
    plane: so ``(D / ρ)^{1/3}`` is affine in ``(x, y)`` over the chart, fitted by least
    squares on the patches. A target in the chart's plane then gets its own light, even from
    a projector beside the camera; one elsewhere does not (its chromaticity stays right).
    The residual says how well the model holds.

    Examples
    --------
    >>> rho = np.linspace(0.05, 0.9, 8)[:, None].repeat(3, 1)
    >>> s = fit_albedo_scale(rho * [2.0, 3.0, 4.0], rho)
    >>> np.round(s.scale, 6).tolist(), s.rms_residual
    ([2.0, 3.0, 4.0], 0.0)
    """
    d = np.asarray(patch_direct, np.float64)
    rho = np.asarray(reflectances, np.float64)
    if d.ndim != 2 or d.shape[1] != 3 or rho.shape != d.shape:
        raise InputError(f"patch_direct {d.shape} and reflectances {rho.shape} must both be (N, 3)")
    if not np.all(np.isfinite(rho)) or np.any(rho <= 0) or np.any(rho >= 1):
        raise InputError("reflectances must be finite and in (0, 1)")
    xy = None
    if patch_xy is not None:
        xy = np.asarray(patch_xy, np.float64)
        if xy.shape != (len(d), 2):
            raise InputError(f"patch_xy must be ({len(d)}, 2) projector pixels, got {xy.shape}")
    used = np.all(np.isfinite(d), axis=1) & np.all(d > 0, axis=1)
    if xy is not None:
        used &= np.all(np.isfinite(xy), axis=1)
    scale, plane = _fit(d, rho, xy, used)
    for _ in range(3):
        residual = d / (scale * rho * _light(plane, xy, len(d))[:, None]) - 1
        keep = used & np.all(np.abs(np.nan_to_num(residual, nan=np.inf)) <= outlier, axis=1)
        if keep.sum() < MIN_PATCHES or np.array_equal(keep, used):
            break
        used = keep
        scale, plane = _fit(d, rho, xy, used)
    residual = d / (scale * rho * _light(plane, xy, len(d))[:, None]) - 1
    return AlbedoScale(scale, residual=residual, used=used, source="checker", plane=plane)


def _fit(d: np.ndarray, rho: np.ndarray, xy: np.ndarray | None, used: np.ndarray):
    """Per-channel scale and (if ``xy``) the light's plane, from the ``used`` patches."""
    if used.sum() < MIN_PATCHES:
        raise InputError(f"only {int(used.sum())} checker patches have a measured D; at least {MIN_PATCHES} are "
                         "needed: is the chart lit by the projector and placed correctly?")
    plane = None
    if xy is not None:
        cube = np.cbrt((d[used] / rho[used]).mean(axis=1))
        design = np.c_[np.ones(int(used.sum())), xy[used]]
        coef, *_ = np.linalg.lstsq(design, cube, rcond=None)
        centre = xy[used].mean(axis=0)
        norm = coef[0] + coef[1:] @ centre  # f = 1 at the chart's centre
        if norm <= 0:
            raise InputError("the chart's direct light does not fit a projector lighting a plane; "
                             "check the corners, or that the chart is flat")
        plane = coef / norm
    f = _light(plane, xy, len(d))[used, None]
    return (d[used] * rho[used] * f).sum(axis=0) / ((rho[used] * f) ** 2).sum(axis=0), plane


def _light(plane: np.ndarray | None, xy: np.ndarray | None, n: int) -> np.ndarray:
    if plane is None or xy is None:
        return np.ones(n)
    return _plane_light(plane, xy)


def _plane_light(plane: np.ndarray, xy: np.ndarray) -> np.ndarray:
    return np.maximum(plane[0] + xy[..., 0] * plane[1] + xy[..., 1] * plane[2], 0.0) ** 3


def reference_scale(direct_reference, reflectance, covered) -> AlbedoScale:
    """The per-pixel scale from a card of known reflectance laid over the target.

    Parameters
    ----------
    direct_reference : (H, W, 3) float
        D measured with the card in place (same rig, same pixels as the target's D).
    reflectance : (3,) float
        The card's albedo per camera channel, in (0, 1).
    covered : (H, W) bool
        Pixels the card covers.

    Returns
    -------
    AlbedoScale
        ``scale = D_card / ρ_card`` on covered pixels where D was measured, ``source ==
        "reference"``.

    Notes
    -----
    The same pixel under the same projector sees the card and the target with the same
    ``E_p``, so ``ρ = ρ_card D / D_card`` holds per pixel for any geometry; the paper's
    Fig. 7 computes κ as this ratio between two papers.

    Examples
    --------
    >>> card = np.full((1, 2, 3), 1.8)
    >>> s = reference_scale(card, [0.9, 0.9, 0.9], np.array([[True, True]]))
    >>> s.albedo(np.full((1, 2, 3), 0.2), np.array([[True, True]])).round(6).tolist()
    [0.1, 0.1, 0.1]
    """
    d = check_float_image("direct_reference", direct_reference, ndim=3)
    cov = check_mask("covered", covered, d.shape[:2])
    rho = np.asarray(reflectance, np.float64)
    if rho.shape != (3,) or not np.all(np.isfinite(rho)) or np.any(rho <= 0) or np.any(rho >= 1):
        raise InputError(f"reflectance must be 3 numbers in (0, 1), got {np.asarray(reflectance).tolist()!r:.80}")
    if d.shape[2] != 3:
        raise InputError(f"direct_reference must have 3 channels, got shape {d.shape}")
    valid = cov & np.all(d > 0, axis=-1)
    if not valid.any():
        raise InputError("the reference card has no measured D: is it lit by the projector?")
    scale = np.where(valid[..., None], d.astype(np.float64) / rho, 0.0)
    return AlbedoScale(scale, valid=valid, source="reference")
