"""Measuring a ColorChecker's direct light: the absolute albedo scale of a rig's scene.

The chart's patches are measured like any target (:func:`engine.acquire.prepare_target`:
Nayar high-frequency patterns on their projector footprint), so their D and a target's D
share units, and the fit of D against the published reflectances gives ``E_p`` per channel
(:func:`engine.albedo.fit_albedo_scale`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.acquire.recorder import Recorder
from engine.acquire.target import PreparedTarget, prepare_target
from engine.albedo import AlbedoScale, fit_albedo_scale
from engine.calibrate import Calibration
from engine.checker import Checker, reference_reflectances, sample_patches


@dataclass(frozen=True, eq=False)
class CheckerMeasurement:
    """What measuring a chart produced.

    Attributes
    ----------
    checker : Checker
    patch_direct : (24, 3) float64
        Each patch's mean D (NaN where none of its pixels could be measured).
    scale : AlbedoScale
        The fit of ``patch_direct`` against the reference reflectances, with the projector's
        light over the chart's plane (pass a target's projector coordinates to
        :meth:`AlbedoScale.albedo`, e.g. :func:`projector_xy` of its PreparedTarget).
    prepared : PreparedTarget
        The chart measured as a target (its D image and emittable pixels).
    """

    checker: Checker
    patch_direct: np.ndarray
    scale: AlbedoScale
    prepared: PreparedTarget

    def report(self) -> str:
        """One line: the fit's quality and the patches it used."""
        used = int(self.scale.used.sum()) if self.scale.used is not None else 0
        return (f"colour checker ({self.checker.source}): {used} of {len(self.patch_direct)} patches fit the published "
                f"reflectances to {self.scale.rms_residual:.1%} rms")


def projector_xy(prepared: PreparedTarget) -> np.ndarray:
    """(H, W, 2) float64: the projector pixel (x, y) of each camera pixel of a prepared target."""
    corr = prepared.correspondence
    return np.stack([corr.x, corr.y], axis=-1).astype(np.float64)


def measure_checker(recorder: Recorder, calibration: Calibration, checker: Checker, base: np.ndarray, *,
                    name: str = "checker", sensitivities: str | None = None) -> CheckerMeasurement:
    """Measure D on a chart's patches and fit the rig's absolute albedo scale.

    Parameters
    ----------
    recorder : Recorder
    calibration : Calibration
    checker : Checker
        Where the chart is (:func:`engine.checker.detect_checker` or manual corners).
    base : (H, W, 3) float32
        Capture with the projector at black (the photograph), removed from each pattern.
    name : str
        Capture-name prefix.
    sensitivities : str, optional
        Camera spectral sensitivities for the reference reflectances (default: the virtual
        rig's, see :func:`engine.checker.reference_reflectances`).

    Returns
    -------
    CheckerMeasurement

    Raises
    ------
    InputError
        The projector reaches none of the chart, or fewer than 6 patches were measured.
    """
    prepared = prepare_target(recorder, calibration, checker.mask(), base, name=name, spread=False)
    patch_direct, _ = sample_patches(prepared.direct, checker, valid=prepared.mask)
    patch_xy, _ = sample_patches(projector_xy(prepared), checker, valid=prepared.mask)
    rho = reference_reflectances() if sensitivities is None else reference_reflectances(sensitivities)
    scale = fit_albedo_scale(patch_direct, rho, patch_xy=patch_xy)
    return CheckerMeasurement(checker, patch_direct, scale, prepared)
