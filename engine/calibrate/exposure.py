"""Black/ambient frames and exposure checks, in plain words.

Every acquisition subtracts a reference capture (the paper subtracts I_0, Sec. 3.3) and relies
on linear, unclipped captures: these helpers average reference frames and say whether a
capture is usable before hours are spent on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.checks import check_fraction, check_image, check_images, check_mask, check_positive
from engine.errors import InputError

__all__ = ["AutoExposure", "ExposureReport", "black_frame", "exposure_report", "projector_lit"]


def black_frame(captures) -> np.ndarray:
    """Average captures of the same still light (e.g. projector black) into one frame.

    Parameters
    ----------
    captures : (N, H, W, 3) float or a sequence of (H, W, 3) float
        Linear radiance; N ≥ 1.

    Returns
    -------
    (H, W, 3) float32
        The mean (noise down by √N). Not clipped: noise may leave small negative values.

    Examples
    --------
    >>> black_frame([np.zeros((1, 1, 3), np.float32), np.full((1, 1, 3), 2, np.float32)])[0, 0].tolist()
    [1.0, 1.0, 1.0]
    """
    caps = check_images("captures", captures)
    total = np.zeros(caps[0].shape, np.float64)
    for c in caps:
        total += c
    return (total / len(caps)).astype(np.float32)


@dataclass(frozen=True)
class ExposureReport:
    """How usable one capture is.

    Attributes
    ----------
    pixels : int
        Pixels judged (the target's, or all).
    saturated_fraction : float or None
        Fraction clipped in any channel; None when saturation could not be checked.
    underexposed_fraction : float
        Fraction whose brightest channel is below ``low × full scale``.
    ambient_fraction : float or None
        Median over pixels of black / image (light that is not the projector's), when a black
        frame was given.
    ok : bool
        Within all limits.
    verdict : str
        ``"ok"``, ``"over-exposed"``, ``"under-exposed"``, ``"over- and under-exposed"``,
        ``"too much ambient light"`` or ``"no pixels"``.
    message : str
        The verdict with numbers and what to do, in plain words.
    """

    pixels: int
    saturated_fraction: float | None
    underexposed_fraction: float
    ambient_fraction: float | None
    ok: bool
    verdict: str
    message: str

    def __str__(self) -> str:
        return self.message


def exposure_report(
    image,
    *,
    target=None,
    saturated=None,
    full_scale: float | None = None,
    low: float = 0.02,
    black=None,
    max_saturated: float = 0.001,
    max_underexposed: float = 0.05,
    max_ambient: float = 0.5,
    label: str | None = None,
) -> ExposureReport:
    """Judge a capture: how much of it is clipped, how much is too dark, how much is ambient.

    Parameters
    ----------
    image : (H, W, 3) float, linear radiance
        Usually a capture under projector white.
    target : (H, W) bool, optional
        Judge only these pixels.
    saturated : (H, W) bool, optional
        Clipped pixels (``Frame.saturated``).
    full_scale : float, optional
        Radiance at which the camera clips (``Frame.full_scale``). Without ``saturated``, pixels
        at or above it count as saturated. Default (and for ``inf``, a camera that does not
        clip): the brightest value of the judged pixels, so under-exposure is then judged
        relative to the brightest pixel.
    low : float
        A pixel is under-exposed when its brightest channel is below ``low × full_scale``.
    black : (H, W, 3) float, optional
        A capture with the projector at black (see :func:`black_frame`): reports how much of
        the image is ambient light.
    max_saturated, max_underexposed, max_ambient : float
        Limits for an ``ok`` verdict (fractions).
    label : str, optional
        What the judged pixels are called in the message (default "target pixels" with a
        target, "pixels" without).

    Returns
    -------
    ExposureReport

    Examples
    --------
    >>> img = np.full((10, 10, 3), 0.5, np.float32); img[0, :3] = 0.001
    >>> sat = np.zeros((10, 10), bool); sat[9, 9] = True
    >>> r = exposure_report(img, saturated=sat, full_scale=1.0)
    >>> r.verdict, r.saturated_fraction, r.underexposed_fraction
    ('over-exposed', 0.01, 0.03)
    >>> print(r.message.split("; ")[1])
    shorten the exposure or lower the gain
    """
    img = check_image("image", image)
    h, w = img.shape[:2]
    sel = np.ones((h, w), bool) if target is None else check_mask("target", target, (h, w))
    low = float(check_fraction("low", low, channels=1)[0])
    limits = {n: float(check_fraction(n, v, channels=1, upper_open=False)[0])
              for n, v in (("max_saturated", max_saturated), ("max_underexposed", max_underexposed),
                           ("max_ambient", max_ambient))}
    n = int(sel.sum())
    if n == 0:
        return ExposureReport(0, None, 0.0, None, False, "no pixels", "no pixels to judge: the target is empty")
    peak = img[sel].max(axis=-1)  # brightest channel per judged pixel
    no_clip = full_scale is not None and np.isposinf(full_scale)
    if full_scale is None or no_clip:
        scale = float(peak.max())
    else:
        scale = check_positive("full_scale", full_scale)
    sat_frac: float | None
    if no_clip:
        sat_frac = 0.0
    elif saturated is not None:
        sat = check_mask("saturated", saturated, (h, w))[sel]
        sat_frac = float(sat.mean())
    elif full_scale is not None:
        sat_frac = float(np.mean(peak >= scale))
    else:
        sat_frac = None
    under = float(np.mean(peak < low * scale)) if scale > 0 else 1.0
    amb = None
    if black is not None:
        blk = check_image("black", black, img.shape)[sel].max(axis=-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(peak > 0, blk / peak, 1.0)
        amb = float(np.median(ratio))

    over_bad = sat_frac is not None and sat_frac > limits["max_saturated"]
    under_bad = under > limits["max_underexposed"]
    amb_bad = amb is not None and amb > limits["max_ambient"]
    what = label or ("target pixels" if target is not None else "pixels")
    if no_clip:
        sat_txt = f"the camera does not clip ({n} {what} judged; any exposure gives the same radiance)"
    elif sat_frac is None:
        sat_txt = "saturation not checked (no saturation mask or full scale)"
    else:
        sat_txt = f"{100 * sat_frac:.1f}% of {n} {what} saturated"
    of = "of the brightest" if no_clip else "of full scale"
    facts = f"{sat_txt}, {100 * under:.1f}% under-exposed (below {100 * low:.0f}% {of})"
    if amb is not None:
        facts += f", ambient light {100 * amb:.0f}% of the image"
    if over_bad and under_bad:
        verdict = "over- and under-exposed"
        advice = "the scene's range exceeds the camera's: use two exposures or even out the lighting"
    elif over_bad:
        verdict, advice = "over-exposed", "shorten the exposure or lower the gain"
    elif under_bad:
        verdict = "under-exposed"
        advice = "lengthen the exposure or raise the gain (or check the mask is on lit pixels)"
    elif amb_bad:
        verdict = "too much ambient light"
        advice = "darken the room: ambient light costs dynamic range and adds noise"
    else:
        verdict, advice = "ok", ""
    message = f"{verdict}: {facts}" + (f"; {advice}" if advice else "")
    return ExposureReport(n, sat_frac, under, amb, verdict == "ok", verdict, message)


def projector_lit(white, black, *, min_fraction: float = 0.005) -> np.ndarray | None:
    """Pixels whose light under projector white is mostly the projector's, not ambient.

    What calibration measures is projector light, so exposure is judged there: a lamp or a
    window in view (bright under projector black too) may clip without harm.

    Parameters
    ----------
    white, black : (H, W, 3) float
        Linear radiance under projector white and black (any exposures: radiance does not
        depend on them).
    min_fraction : float
        Below this fraction of the frame, the mask is not trusted (too dark, or everything
        clipped in both) and None is returned: judge the whole frame.

    Returns
    -------
    (H, W) bool or None

    Examples
    --------
    >>> black = np.zeros((2, 2, 3), np.float32); black[0, 0] = 10.0  # a lamp
    >>> white = black + 1.0
    >>> projector_lit(white, black, min_fraction=0.1).tolist()
    [[False, True], [True, True]]
    """
    w = check_image("white", white)
    b = check_image("black", black, w.shape).max(axis=-1)
    lit = (w.max(axis=-1) - b) > b
    return lit if lit.mean() >= min_fraction else None


@dataclass
class AutoExposure:
    """Find the exposure that puts a capture's bright end just below clipping, frame by frame.

    Radiance (``Frame.image``) does not depend on the exposure, but the radiance at which the
    camera clips does: it is ``c / exposure`` for a constant ``c`` of the camera and gain.
    When the frame says where it clips (``Frame.full_scale``), ``c`` is known at once and the
    stepper jumps to the exposure that puts the ``percentile``-th brightest judged pixel at
    ``headroom`` of full scale; a camera that does not clip (``full_scale`` infinite) is
    settled as it is, since any exposure gives the same radiance. Otherwise nothing in a frame
    says where clipping is until something clips, so the stepper lengthens the exposure by
    ``step_factor`` while nothing clips, shortens it by ``step_factor`` while too much clips,
    and once it has seen clipped pixels (whose radiance is the clip level, a lower bound of it
    where only some channels clipped — the smallest one is taken) it computes ``c`` and jumps.
    Callers bound the number of frames (a camera that never clips and never says so would be
    lengthened for ever).

    Parameters
    ----------
    headroom : float
        Wanted level of the bright end, as a fraction of full scale.
    percentile : float
        Which pixel is the bright end (a few specular or lamp pixels may clip).
    max_saturated : float
        Largest clipped fraction of the judged pixels that is accepted.
    step_factor : float
        Factor of the blind steps, before the clip level is known.
    tolerance : float
        Settled when the wanted exposure is within this factor of the frame's (DSLR shutter
        speeds come in thirds of a stop: 2^(1/3) ≈ 1.26).

    Examples
    --------
    >>> auto = AutoExposure()
    >>> img = np.full((100, 100, 3), 2.0, np.float32); sat = np.zeros((100, 100), bool)
    >>> auto.step(img, sat, exposure=0.01)  # nothing clips: no clip level known yet, brighten
    0.04
    >>> sat[0, 0] = True; img[0, 0] = 5.0  # a lamp pixel: at 1/25 s the camera clips at radiance 5
    >>> round(auto.step(img, sat, exposure=0.04), 4)  # put radiance 2 at 0.8 × clip
    0.08
    >>> auto.step(img, np.zeros((100, 100), bool), exposure=0.08) is None  # settled
    True
    >>> round(AutoExposure().step(img, np.zeros((100, 100), bool), exposure=0.01, full_scale=20.0), 4)
    0.08
    >>> AutoExposure().step(img, np.zeros((100, 100), bool), exposure=0.01, full_scale=np.inf) is None
    True
    """

    headroom: float = 0.8
    percentile: float = 99.9
    max_saturated: float = 0.001
    step_factor: float = 4.0
    tolerance: float = 1.26
    clip_constant: float | None = None  # radiance at clipping × exposure, once seen

    def step(self, image, saturated, *, exposure: float, target=None, full_scale: float | None = None) -> float | None:
        """The next exposure to try after a frame taken at ``exposure``, or None when settled.

        Parameters
        ----------
        image : (H, W, 3) float
            The frame's linear radiance (``Frame.image``), under the light to expose for.
        saturated : (H, W) bool
            ``Frame.saturated``.
        exposure : float
            The exposure the frame was actually taken at (``Frame.exposure``, seconds).
        target : (H, W) bool, optional
            Judge only these pixels.
        full_scale : float, optional
            ``Frame.full_scale``: the radiance at which this frame clips, when known (``inf``:
            the camera does not clip).

        Raises
        ------
        InputError
            Bad shapes, a non-positive exposure or full scale, or nothing to judge.
        """
        img = check_image("image", image)
        h, w = img.shape[:2]
        sat = check_mask("saturated", saturated, (h, w))
        sel = np.ones((h, w), bool) if target is None else check_mask("target", target, (h, w))
        exposure = check_positive("exposure", exposure)
        if not sel.any():
            raise InputError("target is empty: nothing to expose for")
        if full_scale is not None:
            if np.isposinf(full_scale):
                return None  # a camera that does not clip: every exposure gives the same radiance
            self.clip_constant = check_positive("full_scale", full_scale) * exposure
        elif sat.any():
            self.clip_constant = float(img[sat].max(axis=-1).min()) * exposure
        if float(sat[sel].mean()) > self.max_saturated:
            return exposure / self.step_factor
        if self.clip_constant is None:
            return exposure * self.step_factor
        bright = float(np.percentile(img[sel].max(axis=-1), self.percentile))
        if bright <= 0:
            return exposure * self.step_factor
        wanted = self.headroom * self.clip_constant / bright
        if max(wanted / exposure, exposure / wanted) < self.tolerance:
            return None
        return wanted
