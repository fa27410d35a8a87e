"""Camera and projector noise: the variance of every capture (paper Sec. 6, Discussion).

A linear RAW camera's frame of radiance ``I`` has variance ``shot · I + read`` per channel, in
the frame's own (linear radiance) units: photon shot noise is Poisson in electrons, hence
proportional to the signal; read noise and ADC rounding are a floor (the photon transfer
curve). The two numbers depend on the exposure: with ``k`` electrons per unit radiance per
second, ``shot = 1 / (k t)`` and the read term ``r² / (k t)²`` for ``r`` electrons of read
noise, so ``shot ∝ 1/t`` and ``read ∝ 1/t²`` (read noise before the gain stage dominates on
RAW sensors; its gain dependence is neglected). Averaging ``n`` frames divides both by ``n``.

The numbers come from the backend when it knows them (``Frame.metadata["noise"]``, see
:meth:`CameraNoise.from_metadata`), otherwise from the calibration, which measures them from
repeated black and flat frames (:func:`fit_camera_noise`). A projector with ``b``-bit input
adds uniform rounding of its levels, ``(f'(p) / (2^b − 1))² / 12`` in linear light
(:func:`quantization_variance`). Every value also carries a float32 rounding floor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.checks import check_float_image
from engine.errors import InputError

#: Relative standard deviation of the float32 pipeline's rounding: captures, patterns and
#: renderers compute in float32, and a stored value carries a few units in the last place of
#: accumulated rounding (measured on the ideal virtual rig: the 6th–8th order components'
#: errors are 2.9× what one unit, 2^-23, predicts).
FLOAT32_FLOOR = 3 * float(np.finfo(np.float32).eps)


@dataclass(frozen=True)
class CameraNoise:
    """The noise of one camera at a reference exposure: ``var(I) = shot · max(I, 0) + read``.

    Attributes
    ----------
    shot : (3,) float
        Variance per unit of linear radiance (radiance units), per channel.
    read : (3,) float
        Variance at zero signal (radiance units squared), per channel.
    exposure : float
        Exposure time in seconds the two numbers hold for.
    floor : float
        Relative standard deviation added to every value (float32 rounding).

    Examples
    --------
    >>> noise = CameraNoise((1e-4,) * 3, (1e-6,) * 3, exposure=0.01)
    >>> v = noise.variance(np.full((1, 1, 3), 0.5, np.float32), floor=False)   # 1e-4 * 0.5 + 1e-6
    >>> [round(float(x), 9) for x in v[0, 0]]
    [5.1e-05, 5.1e-05, 5.1e-05]
    >>> v = noise.variance(np.full((1, 1, 3), 0.5, np.float32), exposure=0.02, frames=4, floor=False)
    >>> [round(float(x), 10) for x in v[0, 0]]                                 # twice the time, 4 frames
    [6.3125e-06, 6.3125e-06, 6.3125e-06]
    """

    shot: tuple[float, float, float]
    read: tuple[float, float, float]
    exposure: float
    floor: float = FLOAT32_FLOOR

    def __post_init__(self) -> None:
        for name in ("shot", "read"):
            value = np.broadcast_to(np.asarray(getattr(self, name), np.float64), (3,))
            if not np.all(np.isfinite(value)) or np.any(value < 0):
                raise InputError(f"camera noise {name} must be 3 finite variances >= 0, got {getattr(self, name)!r}")
            object.__setattr__(self, name, tuple(float(v) for v in value))
        if not np.isfinite(self.exposure) or self.exposure <= 0:
            raise InputError(f"camera noise exposure must be a positive number of seconds, got {self.exposure!r}")
        if not np.isfinite(self.floor) or self.floor < 0:
            raise InputError(f"camera noise floor must be a relative deviation >= 0, got {self.floor!r}")

    @classmethod
    def ideal(cls, exposure: float = 1.0) -> CameraNoise:
        """A noise-free camera: float32 rounding only."""
        return cls((0.0,) * 3, (0.0,) * 3, exposure)

    def variance(self, image, *, exposure: float | None = None, frames: int = 1, floor: bool = True) -> np.ndarray:
        """Variance of every pixel of a frame (or a mean of ``frames`` frames).

        Parameters
        ----------
        image : (H, W, 3) float
            The frame, linear radiance (its noisy values stand in for the mean).
        exposure : float, optional
            Seconds the frame was exposed (default: the reference exposure).
        frames : int
            Frames averaged into ``image``.
        floor : bool
            Add the float32 rounding floor.

        Returns
        -------
        (H, W, 3) float32
        """
        image = check_float_image("image", image, ndim=3)
        t = self.exposure if exposure is None else float(exposure)
        if not np.isfinite(t) or t <= 0:
            raise InputError(f"exposure must be a positive number of seconds, got {exposure!r}")
        if int(frames) < 1:
            raise InputError(f"frames must be >= 1, got {frames!r}")
        ratio = self.exposure / t
        shot = np.asarray(self.shot, np.float32) * np.float32(ratio / frames)
        read = np.asarray(self.read, np.float32) * np.float32(ratio * ratio / frames)
        var = np.maximum(image, 0).astype(np.float32) * shot + read
        if floor:
            var += np.square(image.astype(np.float32) * np.float32(self.floor))
        return var

    def to_dict(self) -> dict:
        """JSON form (stored with a calibration)."""
        return {"shot": list(self.shot), "read": list(self.read), "exposure": self.exposure, "floor": self.floor}

    @classmethod
    def from_dict(cls, d: dict) -> CameraNoise:
        """Inverse of :meth:`to_dict`; InputError names a missing or bad field."""
        if not isinstance(d, dict):
            raise InputError(f"camera noise must be a dict, got {type(d).__name__}")
        try:
            return cls(tuple(d["shot"]), tuple(d["read"]), float(d["exposure"]), float(d.get("floor", FLOAT32_FLOOR)))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"camera noise is incomplete or malformed ({exc}): expected shot, read and "
                             "exposure") from None

    @classmethod
    def from_metadata(cls, metadata, exposure: float) -> CameraNoise | None:
        """The noise a backend reports with its frames: ``metadata["noise"] = {"shot", "read"}``.

        Both are variances for that frame's exposure and gain, in its radiance units; None
        when the backend does not report them.
        """
        noise = (metadata or {}).get("noise") if isinstance(metadata, dict) else None
        if not isinstance(noise, dict):
            return None
        return cls.from_dict({**noise, "exposure": exposure})


def fit_camera_noise(stacks, exposure: float, *, saturated=None, bins: int = 32) -> CameraNoise:
    """Measure ``shot`` and ``read`` from repeated frames of fixed scenes (photon transfer).

    Parameters
    ----------
    stacks : sequence of (M, H, W, 3) float
        For each lighting (e.g. projector black, projector white), M ≥ 2 frames of the same
        scene taken one after the other.
    exposure : float
        Their exposure in seconds.
    saturated : (H, W) bool, optional
        Pixels to leave out (clipped in any frame).
    bins : int
        Pixels are grouped in this many bins of mean value per channel; the line is fitted
        to the bins' mean temporal variances, weighted by their pixel counts.

    Returns
    -------
    CameraNoise

    Raises
    ------
    InputError
        Fewer than 2 frames, mismatched shapes, or no spread of brightness to fit a line.

    Notes
    -----
    Each pixel's temporal variance (unbiased, M − 1 degrees of freedom) is an estimate of
    ``shot · mean + read`` free of the scene's texture. A weighted least-squares line through
    the binned points gives both numbers; a negative intercept (read noise below what the
    bins resolve) is set to zero and the slope refitted through the origin.
    """
    means, variances = [], []
    shape = None
    for i, stack in enumerate(stacks):
        s = check_float_image(f"stacks[{i}]", stack, ndim=4)
        if s.shape[0] < 2 or s.shape[-1] != 3:
            raise InputError(f"stacks[{i}] must hold at least 2 frames of (H, W, 3), got shape {s.shape}")
        if shape is not None and s.shape[1:] != shape:
            raise InputError(f"stacks[{i}] has frames of {s.shape[1:]}, the first stack {shape}")
        shape = s.shape[1:]
        means.append(s.mean(axis=0, dtype=np.float64))
        variances.append(s.var(axis=0, ddof=1, dtype=np.float64))
    if not means:
        raise InputError("stacks is empty: give repeated frames of at least one lighting")
    assert shape is not None  # set by the first stack, and there is at least one
    keep = np.ones(shape[:2], bool) if saturated is None else ~np.asarray(saturated, bool)
    mean = np.stack(means)[:, keep]  # (L, n, 3)
    var = np.stack(variances)[:, keep]
    shot, read = np.zeros(3), np.zeros(3)
    for c in range(3):
        m, v = mean[..., c].ravel(), var[..., c].ravel()
        edges = np.unique(np.quantile(m, np.linspace(0, 1, bins + 1)))
        if edges.size < 3:
            raise InputError("the repeated frames show no spread of brightness: give a dark and a bright lighting")
        idx = np.clip(np.searchsorted(edges, m, side="right") - 1, 0, len(edges) - 2)
        count = np.bincount(idx, minlength=len(edges) - 1).astype(np.float64)
        ok = count > 0
        bm = np.bincount(idx, m, minlength=len(edges) - 1)[ok] / count[ok]
        bv = np.bincount(idx, v, minlength=len(edges) - 1)[ok] / count[ok]
        w = count[ok]
        if bm.size < 2 or np.ptp(bm) <= 0:
            raise InputError("the repeated frames show no spread of brightness: give a dark and a bright lighting")
        a = np.stack([bm, np.ones_like(bm)], axis=1) * np.sqrt(w)[:, None]
        (slope, icpt), *_ = np.linalg.lstsq(a, bv * np.sqrt(w), rcond=None)
        if icpt < 0 or slope < 0:
            slope = max(float(np.sum(w * bm * bv) / max(np.sum(w * bm * bm), 1e-300)), 0.0)
            icpt = max(float(np.sum(w * (bv - slope * bm)) / np.sum(w)), 0.0)
        shot[c], read[c] = slope, icpt
    return CameraNoise((shot[0], shot[1], shot[2]), (read[0], read[1], read[2]), float(exposure))


def frame_variance(image, exposure: float, metadata, fallback: CameraNoise | None) -> np.ndarray | None:
    """Variance of a capture from what was recorded with it.

    Parameters
    ----------
    image : (H, W, 3) float
        The capture (linear radiance).
    exposure : float
        Its exposure in seconds.
    metadata : dict
        The frame's metadata: ``noise`` (backend-reported, :meth:`CameraNoise.from_metadata`,
        with its ``clip`` radiance), ``frames`` averaged, ``brackets`` (shorter exposures that
        completed clipped pixels).
    fallback : CameraNoise or None
        The calibration's measurement, used when the frame reports no noise.

    Returns
    -------
    (H, W, 3) float32 or None
        None when neither the frame nor the calibration knows the camera's noise.

    Notes
    -----
    A pixel brighter than the frame's clip level was read from the first bracket that did
    not clip it (each ``bracket_step`` times shorter, the clip level as many times higher):
    its variance is that exposure's.
    """
    meta = metadata if isinstance(metadata, dict) else {}
    model = CameraNoise.from_metadata(meta, exposure) or fallback
    if model is None:
        return None
    frames = int(meta.get("frames", 1) or 1)
    var = model.variance(image, exposure=exposure, frames=frames)
    clip = (meta.get("noise") or {}).get("clip") if isinstance(meta.get("noise"), dict) else None
    brackets = [float(b) for b in meta.get("brackets") or []]
    if clip and brackets:
        level = np.asarray(image).max(axis=-1, keepdims=True)
        done = level < clip
        for t in brackets:
            use = ~done & (level < clip * exposure / t)
            if t == brackets[-1]:
                use = ~done
            if use.any():
                var = np.where(use, model.variance(image, exposure=t, frames=frames), var)
            done = done | use
    return var


def packed_index(i: int, j: int, k: int) -> int:
    """Position of ``Cov(i, j)`` in a packed ``K(K+1)/2`` covariance (upper triangle, row-major).

    Examples
    --------
    >>> [packed_index(i, j, 3) for i in range(3) for j in range(i, 3)]
    [0, 1, 2, 3, 4, 5]
    >>> packed_index(2, 0, 3) == packed_index(0, 2, 3)
    True
    """
    if i > j:
        i, j = j, i
    return i * k - i * (i - 1) // 2 + j - i


def unpack_covariance(packed: np.ndarray) -> np.ndarray:
    """``(K(K+1)/2, ...)`` packed covariance → full symmetric ``(K, K, ...)``."""
    p = packed.shape[0]
    k = int(round((np.sqrt(8 * p + 1) - 1) / 2))
    if k * (k + 1) // 2 != p:
        raise InputError(f"a packed covariance has K(K+1)/2 planes, got {p}")
    full = np.empty((k, k) + packed.shape[1:], packed.dtype)
    for i in range(k):
        for j in range(i, k):
            full[i, j] = full[j, i] = packed[packed_index(i, j, k)]
    return full


def pack_covariance(full: np.ndarray) -> np.ndarray:
    """Inverse of :func:`unpack_covariance` (the upper triangle of ``(K, K, ...)``)."""
    k = full.shape[0]
    if full.shape[1] != k:
        raise InputError(f"a covariance must be (K, K, ...), got shape {full.shape}")
    return np.stack([full[i, j] for i in range(k) for j in range(i, k)])


def quantization_variance(inputs, response, bit_depth: int) -> np.ndarray:
    """Variance of the linear light a projector emits for ``inputs``, from its input rounding.

    Parameters
    ----------
    inputs : (..., 3) float in [0, 1]
        Projector inputs (after the inverse response).
    response : engine.calibrate.ProjectorResponse or None
        Maps inputs to linear light above black, ``f`` (None: linear).
    bit_depth : int
        Input bits; rounding to ``2^b − 1`` steps is uniform, variance ``step² / 12``.

    Returns
    -------
    (..., 3) float32
        ``(f'(p) · step)² / 12``, in fractions of full linear light.

    Examples
    --------
    >>> round(float(quantization_variance(np.full((1, 3), 0.5), None, 8)[0, 0]) * 12 * 255**2, 6)
    1.0
    """
    p = np.asarray(inputs, np.float64)
    bits = int(bit_depth)
    if bits < 1:
        raise InputError(f"bit_depth must be >= 1, got {bit_depth!r}")
    step = 1.0 / (2.0**bits - 1.0)
    if response is None:
        slope = np.ones_like(p)
    else:
        h = min(step, 1e-3)
        lo, hi = np.clip(p - h, 0, 1).astype(np.float32), np.clip(p + h, 0, 1).astype(np.float32)
        slope = (response.forward(hi).astype(np.float64) - response.forward(lo)) / np.maximum(hi - lo, 1e-12)
    return (np.square(slope * step) / 12.0).astype(np.float32)
