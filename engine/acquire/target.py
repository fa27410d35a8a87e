"""Preparing a target for re-emission: its direct image D and the pixels that can take it.

D (Sec. 3.3) is measured with high-frequency patterns lit only inside the target's
projector footprint (Nayar et al. 2006): the direct part ``L⁺ − L⁻`` of the captures minus
the projector-black reference. Pixels where D is near zero (shadowed, grazing, unlit or not
decoded) cannot be re-emitted: they are removed from the target and reported.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine._checks import check_mask
from engine.acquire.recorder import Recorder
from engine.calibrate import Calibration, direct_image, high_frequency_patterns, projector_footprint
from engine.errors import InputError


@dataclass(frozen=True, eq=False)
class PreparedTarget:
    """A target ready for re-emission.

    Attributes
    ----------
    mask : (H, W) bool
        The emittable target: painted, decoded and with a usable D in every channel.
    unreachable : (H, W) bool
        Painted pixels that cannot be re-emitted (no correspondence, or D below the floor).
    direct : (H, W, 3) float32
        D per unit of linear projector light, per primary (zero off the target).
    """

    mask: np.ndarray
    unreachable: np.ndarray
    direct: np.ndarray

    def report(self) -> str:
        """One line for logs and dialogs."""
        painted = int(self.mask.sum() + self.unreachable.sum())
        bad = int(self.unreachable.sum())
        if not bad:
            return f"all {painted} target pixels can be re-emitted"
        return (
            f"{bad} of {painted} target pixels ({bad / max(painted, 1):.1%}) cannot be re-emitted "
            "(the projector does not reach them: shadowed, grazing or not decoded) and are left out"
        )


def prepare_target(
    recorder: Recorder,
    calibration: Calibration,
    target,
    base: np.ndarray,
    *,
    name: str = "target",
    per_channel: bool = True,
    period: int = 8,
    shifts: int = 2,
    floor: float = 0.02,
) -> PreparedTarget:
    """Measure D on a painted target and drop the pixels the projector cannot re-emit.

    Parameters
    ----------
    recorder : Recorder
    calibration : Calibration
    target : (H, W) bool
        The painted target, in camera pixels.
    base : (H, W, 3) float32
        Capture with the projector at black (removed from every pattern capture).
    name : str
        Prefix of the capture names (distinguishes targets of a cascade).
    per_channel : bool
        Measure D on each projector primary separately (needed for per-channel emission
        when the projector's primaries leak into other camera channels).
    period, shifts : int
        High-frequency pattern parameters, see :func:`engine.calibrate.high_frequency_patterns`.
    floor : float
        Pixels whose D is below ``floor`` times the target's median D (in any channel) are
        unreachable.

    Returns
    -------
    PreparedTarget

    Raises
    ------
    InputError
        The target is empty, or no pixel of it can be re-emitted.
    """
    target = check_mask("target", target, calibration.camera_resolution)
    if not target.any():
        raise InputError("target is empty: paint the surface to recolor first")
    corr = calibration.correspondence
    painted_valid = target & corr.valid
    if not painted_valid.any():
        raise InputError(
            "no pixel of the target has a projector correspondence: the projector does not reach it "
            "(check the Gray-code coverage map)"
        )
    footprint = projector_footprint(corr, target=painted_valid)
    patterns = high_frequency_patterns(calibration.projector_resolution, mask_projector=footprint, period=period, shifts=shifts)
    groups = [(c,) for c in range(3)] if per_channel else [(0, 1, 2)]
    direct = np.zeros(base.shape, np.float32)
    for channels in groups:
        label = "rgb"[channels[0]] if per_channel else "rgb"
        caps = []
        for i, pattern in enumerate(patterns):
            shown = np.zeros_like(pattern)
            shown[..., channels] = pattern[..., channels]
            if calibration.response is not None:
                shown = calibration.response.linearize(shown)
            caps.append(recorder.capture(f"{name}-direct-{label}-{i:02d}", shown, meta={"kind": "direct"}))
        sep = direct_image(np.stack(caps), ambient=base, target=painted_valid)
        direct[..., channels] = sep.direct[..., channels]
    med = np.median(direct[painted_valid], axis=0)
    usable = painted_valid & (direct >= floor * np.maximum(med, 1e-30)).all(axis=-1) & (direct > 0).all(axis=-1)
    if not usable.any():
        raise InputError("the projector's direct light on the target is too weak to measure everywhere on it")
    direct = np.where(usable[:, :, None], direct, 0).astype(np.float32)
    return PreparedTarget(usable, target & ~usable, direct)


def pattern_budget(per_channel: bool, *, shifts: int = 2) -> int:
    """Number of captures :func:`prepare_target` takes."""
    return (3 if per_channel else 1) * 2 * shifts * shifts
