"""Validation of public inputs, in one place.

Every check raises :class:`engine.errors.InputError` with a message that names the argument,
shows what was given and says what was expected. Nothing is clipped or converted silently.
"""

from __future__ import annotations

import numpy as np

from engine.errors import InputError


def float_dtype(*arrays: np.ndarray) -> np.dtype:
    """Return the floating dtype to compute in: float64 if any input is float64, else float32.

    Examples
    --------
    >>> float_dtype(np.zeros(2, np.float32))
    dtype('float32')
    >>> float_dtype(np.zeros(2, np.float32), np.zeros(2))
    dtype('float64')
    """
    if any(a.dtype == np.float64 for a in arrays):
        return np.dtype(np.float64)
    return np.dtype(np.float32)


def check_float_image(name: str, array, *, ndim: int | tuple[int, ...]) -> np.ndarray:
    """Check that ``array`` is a finite floating-point array with ``ndim`` dimensions.

    Integer images are refused: Albedit works on linear radiance, and the scale of an
    integer image (8-bit? 16-bit? black level?) cannot be guessed.
    """
    array = np.asarray(array)
    ndims = (ndim,) if isinstance(ndim, int) else ndim
    if array.dtype.kind != "f":
        raise InputError(
            f"{name} must be a floating-point array of linear radiance, got dtype {array.dtype}; "
            "convert integer images with engine.imageio (which removes black level and scale)"
        )
    if array.ndim not in ndims:
        raise InputError(f"{name} must have {' or '.join(map(str, ndims))} dimensions, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        bad = int(np.size(array) - np.count_nonzero(np.isfinite(array)))
        raise InputError(f"{name} contains {bad} non-finite values (NaN or inf); expected finite radiance")
    return array


def check_mask(name: str, mask, shape: tuple[int, int]) -> np.ndarray:
    """Check that ``mask`` is a boolean array of ``shape`` (camera pixels)."""
    mask = np.asarray(mask)
    if mask.dtype != np.bool_:
        raise InputError(f"{name} must be a boolean mask, got dtype {mask.dtype}; use mask.astype(bool) deliberately")
    if mask.shape != tuple(shape):
        raise InputError(f"{name} must have shape {tuple(shape)} (camera pixels), got {mask.shape}")
    return mask


def check_kappa(kappa, channels: int, *, name: str = "kappa") -> np.ndarray:
    """Return ``kappa`` as a float64 array of shape ``(channels,)``.

    A scalar applies to every channel. Negative or non-finite values are refused: an albedo
    scale is a non-negative number.

    Examples
    --------
    >>> check_kappa(2, 3)
    array([2., 2., 2.])
    """
    k = np.asarray(kappa, dtype=np.float64)
    if k.ndim == 0:
        k = np.full(channels, float(k))
    if k.shape != (channels,):
        raise InputError(f"{name} must be a scalar or have one value per channel ({channels}), got shape {k.shape}")
    if not np.all(np.isfinite(k)) or np.any(k < 0):
        raise InputError(f"{name} must be finite and non-negative (an albedo scale), got {k.tolist()}")
    return k


def check_order(order: int, *, name: str = "order", minimum: int = 1) -> int:
    """Check a decomposition order K (number of interaction components)."""
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)):
        raise InputError(f"{name} must be an integer, got {order!r}")
    if order < minimum:
        raise InputError(f"{name} must be at least {minimum}, got {order}")
    return int(order)


def check_choice(name: str, value, choices) -> str:
    """Check that ``value`` is one of ``choices`` (strings or a StrEnum)."""
    allowed = [str(c) for c in choices]
    if str(value) not in allowed:
        raise InputError(f"{name} must be one of {allowed}, got {value!r}")
    return str(value)
