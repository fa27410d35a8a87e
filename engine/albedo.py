"""Absolute albedo: the scale between a target's direct image D and what it reflects.

``D = ρ E_p`` (Sec. 3.3): albedo times the projector's light on the surface. A reference of
known reflectance lit like the target fixes ``E_p`` per channel, and then ``ρ = D / E_p``.
Two references:

- a ColorChecker beside the target, facing the projector the same way: one scale per
  channel fitted to its 24 patches (:func:`fit_albedo_scale`);
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
    """

    scale: np.ndarray
    valid: np.ndarray | None = None
    residual: np.ndarray | None = None
    used: np.ndarray | None = None
    source: str = "checker"

    @property
    def rms_residual(self) -> float:
        """Root-mean-square relative residual of the kept patches (0 for a per-pixel reference)."""
        if self.residual is None or self.used is None:
            return 0.0
        return float(np.sqrt(np.mean(self.residual[self.used] ** 2)))

    def albedo(self, direct, target) -> np.ndarray:
        """The target's absolute albedo.

        Parameters
        ----------
        direct : (H, W, 3) float
            The target's direct image D, in the same units as the reference's.
        target : (H, W) bool
            Target pixels; those where D is 0 (not measured) are skipped, and for a
            per-pixel reference those it does not cover.

        Returns
        -------
        (3,) float64
            ``mean D / scale`` over the target (per-pixel scale: mean of ``D / scale``).

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
        if self.scale.ndim == 1:
            return d[use].astype(np.float64).mean(axis=0) / self.scale
        return (d[use].astype(np.float64) / self.scale[use]).mean(axis=0)


def fit_albedo_scale(patch_direct, reflectances, *, outlier: float = OUTLIER) -> AlbedoScale:
    """Fit D = scale · ρ per channel over a chart's patches.

    Parameters
    ----------
    patch_direct : (N, 3) float
        Each patch's mean D (:func:`engine.checker.sample_patches` of the chart's direct
        image); NaN for a patch that was not measured.
    reflectances : (N, 3) float
        The patches' albedo (:func:`engine.checker.reference_reflectances`).
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
    Least squares through the origin per channel, ``s = Σ D ρ / Σ ρ²``: bright patches
    (best measured) weigh most. The fit assumes the chart is evenly lit by the projector;
    its residual says how far that holds.

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
    used = np.all(np.isfinite(d), axis=1) & np.all(d > 0, axis=1)
    scale = _fit(d, rho, used)
    for _ in range(2):
        residual = d / (scale * rho) - 1
        keep = used & np.all(np.abs(np.nan_to_num(residual, nan=np.inf)) <= outlier, axis=1)
        if keep.sum() < MIN_PATCHES or np.array_equal(keep, used):
            break
        used = keep
        scale = _fit(d, rho, used)
    residual = d / (scale * rho) - 1
    return AlbedoScale(scale, residual=residual, used=used, source="checker")


def _fit(d: np.ndarray, rho: np.ndarray, used: np.ndarray) -> np.ndarray:
    if used.sum() < MIN_PATCHES:
        raise InputError(f"only {int(used.sum())} checker patches have a measured D; at least {MIN_PATCHES} are "
                         "needed: is the chart lit by the projector and placed correctly?")
    return (d[used] * rho[used]).sum(axis=0) / (rho[used] ** 2).sum(axis=0)


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
