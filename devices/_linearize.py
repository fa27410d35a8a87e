"""From display-encoded camera codes to linear radiance: response curves.

A camera backend never passes gamma-encoded values on (DESIGN.md, "Devices"). Webcams and
8-bit files are linearised through a :class:`ResponseCurve` (supplied, or measured with OpenCV's
Debevec calibration). RAW files are decoded by :func:`engine.raw.decode_raw`, and clipped
frames are completed from shorter exposures by the acquisition Recorder
(``engine.acquire.recorder``), the one HDR merge.
"""

from __future__ import annotations

import numpy as np

from engine.errors import InputError

#: code values at or above this fraction of full scale count as clipped (254/255)
SATURATION_FRACTION = 254.0 / 255.0


class ResponseCurve:
    """A camera response: code value -> linear relative radiance, per channel.

    Parameters
    ----------
    lut : (levels,) or (levels, 3) array_like of float
        Linear radiance for each code value 0 .. levels-1; non-decreasing, finite, >= 0.
        One column is used for all three channels.
    name : str
        How it was obtained, recorded in frame metadata ("srgb", "gamma 2.2", "debevec", ...).

    Notes
    -----
    Codes from a source of a different bit depth are mapped by their fraction of full scale and
    interpolated linearly in the table.

    Examples
    --------
    >>> curve = ResponseCurve.from_gamma(2.0, levels=256)
    >>> codes = np.array([[[0, 128, 255]]], np.uint8)
    >>> np.round(curve.apply(codes), 4)
    array([[[0.   , 0.252, 1.   ]]], dtype=float32)
    """

    def __init__(self, lut, *, name: str = "lut"):
        table = np.asarray(lut, dtype=np.float64)
        if table.ndim == 1:
            table = np.repeat(table[:, None], 3, axis=1)
        if table.ndim != 2 or table.shape[1] != 3 or table.shape[0] < 2:
            raise InputError("response lut must have shape (levels,) or (levels, 3) with levels >= 2, "
                             f"got {np.shape(lut)}")
        if not np.all(np.isfinite(table)) or np.any(table < 0):
            raise InputError("response lut must be finite and non-negative (linear radiance per code value)")
        if np.any(np.diff(table, axis=0) < 0):
            raise InputError("response lut must be non-decreasing in the code value; make it monotonic first")
        if table[-1].max() <= 0:
            raise InputError("response lut is zero everywhere; expected radiance rising with the code value")
        self.lut = table / table[-1].max()  # 1.0 = the top code of the brightest channel
        self.name = str(name)

    @property
    def levels(self) -> int:
        """Number of code values the table covers (256 for 8-bit)."""
        return int(self.lut.shape[0])

    @classmethod
    def from_gamma(cls, gamma: float, *, levels: int = 256) -> ResponseCurve:
        """A power law: radiance = (code / (levels-1)) ** gamma."""
        g = float(gamma)
        if not (np.isfinite(g) and g > 0):
            raise InputError(f"gamma must be a positive number, got {gamma!r}")
        x = np.linspace(0.0, 1.0, int(levels))
        return cls(x**g, name=f"gamma {g:g}")

    @classmethod
    def srgb(cls, *, levels: int = 256) -> ResponseCurve:
        """The sRGB transfer function (IEC 61966-2-1), the usual webcam encoding."""
        x = np.linspace(0.0, 1.0, int(levels))
        lin = np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)
        return cls(lin, name="srgb")

    @classmethod
    def linear(cls, *, levels: int = 65536) -> ResponseCurve:
        """Codes already proportional to radiance (RAW-like 16-bit data)."""
        return cls(np.linspace(0.0, 1.0, int(levels)), name="linear")

    def apply(self, codes: np.ndarray) -> np.ndarray:
        """Linearise integer codes ``(H, W, 3)`` to float32 relative radiance (1.0 = top code).

        Raises
        ------
        InputError
            ``codes`` is not an unsigned integer (H, W, 3) array.
        """
        codes = np.asarray(codes)
        if codes.dtype.kind != "u" or codes.ndim != 3 or codes.shape[2] != 3:
            raise InputError(f"codes must be an unsigned-integer (H, W, 3) image, got {codes.dtype} {codes.shape}")
        full = np.iinfo(codes.dtype).max
        if full + 1 == self.levels:
            out = self.lut[codes, np.arange(3)]
        else:  # another bit depth: map by fraction of full scale
            grid = np.linspace(0.0, 1.0, self.levels)
            frac = codes.astype(np.float64) / full
            out = np.stack([np.interp(frac[..., c], grid, self.lut[:, c]) for c in range(3)], axis=-1)
        return out.astype(np.float32)

    def __repr__(self) -> str:
        return f"ResponseCurve({self.name!r}, levels={self.levels})"


def response_curve(spec, *, levels: int) -> ResponseCurve:
    """Build a :class:`ResponseCurve` from a user option.

    Parameters
    ----------
    spec : ResponseCurve, "srgb", "linear", float gamma, "gamma:2.2", or a LUT array
        What the user passed as ``response=``.
    levels : int
        Code values of the source (256 for 8-bit, 65536 for 16-bit); used by named curves.

    Examples
    --------
    >>> response_curve("gamma:2.2", levels=256).name
    'gamma 2.2'
    >>> response_curve(1.8, levels=1024).levels
    1024
    """
    if isinstance(spec, ResponseCurve):
        return spec
    if isinstance(spec, str):
        s = spec.strip().lower()
        if s == "srgb":
            return ResponseCurve.srgb(levels=levels)
        if s == "linear":
            return ResponseCurve.linear(levels=levels)
        if s.startswith("gamma"):
            try:
                return ResponseCurve.from_gamma(float(s[5:].lstrip(":= ")), levels=levels)
            except ValueError:
                pass
        raise InputError(f"response must be 'srgb', 'linear', 'gamma:G', a number (gamma) or a LUT array, got {spec!r}")
    if isinstance(spec, (int, float, np.integer, np.floating)) and not isinstance(spec, bool):
        return ResponseCurve.from_gamma(float(spec), levels=levels)
    if spec is None:
        raise InputError("response must be given (e.g. 'srgb', 'linear' or a gamma value), got None")
    return ResponseCurve(spec)


def calibrate_response(images, exposures, *, samples: int = 70, smoothness: float = 10.0) -> ResponseCurve:
    """Measure an 8-bit camera response from a bracketed set, with OpenCV's Debevec method.

    Parameters
    ----------
    images : sequence of (H, W, 3) uint8
        The same static scene at different exposures (at least 2; 5+ spanning 8+ stops is better).
    exposures : sequence of float
        Exposure time of each image in seconds.
    samples : int
        Pixel locations sampled by the solver (``cv2.createCalibrateDebevec``).
    smoothness : float
        Weight of the smoothness term (OpenCV's ``lambda``).

    Returns
    -------
    ResponseCurve
        ``name="debevec"``; each channel fixed at its own mid code (Debevec's g(128) = 0), so the
        three channels' relative scale (white balance) is not measured.

    Raises
    ------
    InputError
        Fewer than two images, shapes differ, not uint8, or exposures not positive.

    References
    ----------
    P. E. Debevec and J. Malik, "Recovering high dynamic range radiance maps from photographs",
    SIGGRAPH 1997.
    """
    import cv2

    imgs = [np.ascontiguousarray(im) for im in images]
    times = np.asarray(exposures, dtype=np.float32)
    if len(imgs) < 2 or times.shape != (len(imgs),):
        raise InputError("need at least 2 images and one exposure per image, "
                         f"got {len(imgs)} images and {times.shape} exposures")
    if any(im.dtype != np.uint8 or im.ndim != 3 or im.shape != imgs[0].shape or im.shape[2] != 3 for im in imgs):
        raise InputError("images must all be uint8 (H, W, 3) of one shape, "
                         f"got {[(im.dtype.name, im.shape) for im in imgs]}")
    if not np.all(np.isfinite(times)) or np.any(times <= 0):
        raise InputError(f"exposures must be positive seconds, got {times.tolist()}")
    cal = cv2.createCalibrateDebevec(samples=int(samples), lambda_=float(smoothness), random=False)
    resp = cal.process(imgs, times).reshape(256, 3).astype(np.float64)
    resp = np.maximum.accumulate(np.maximum(resp, 0.0), axis=0)
    return ResponseCurve(resp, name="debevec")
