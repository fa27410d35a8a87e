"""Validation of public inputs, in one place, for the engine, the devices and the app.

Every check raises :class:`engine.errors.InputError` with a message that names the argument,
shows what was given and says what was expected. Nothing is clipped or converted silently.
"""

from __future__ import annotations

from typing import Literal, overload

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



def check_kappa_pairs(pairs, shape: tuple[int, int]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Check ``(mask, kappa)`` pairs: (H, W) bool masks of ``shape`` and (3,) kappas.

    Raises
    ------
    InputError
        An item that is not a pair, a bad mask or a bad kappa (the message names its index).
    """
    out = []
    for k, pair in enumerate(pairs):
        try:
            mask, kappa = pair
        except (TypeError, ValueError):
            raise InputError(f"pairs[{k}] must be a (mask, kappa) pair, got {type(pair).__name__}") from None
        out.append((check_mask(f"pairs[{k}] mask", mask, shape), check_kappa(kappa, 3, name=f"pairs[{k}] kappa")))
    return out

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


def check_resolution(name: str, resolution, *, maximum: int = 1 << 16) -> tuple[int, int]:
    """Return ``resolution`` as a ``(H, W)`` tuple of positive ints, or raise InputError.

    Integer-valued floats are accepted (``(480.0, 640.0)``); booleans, fractions, non-finite
    values and sides above ``maximum`` are refused.

    Examples
    --------
    >>> check_resolution("camera_resolution", (480.0, 640))
    (480, 640)
    """
    try:
        h, w = resolution
        values = [float(h), float(w)]
    except (TypeError, ValueError):
        raise InputError(f"{name} must be (height, width) in pixels, got {resolution!r}") from None
    if (
        any(isinstance(v, bool) for v in (h, w))
        or not all(np.isfinite(v) and v == int(v) and 1 <= v for v in values)
    ):
        raise InputError(f"{name} must be two positive integers (height, width), got {resolution!r}")
    if max(values) > maximum:
        raise InputError(f"{name} must be at most {maximum} pixels a side, got {resolution!r}")
    return int(values[0]), int(values[1])


def check_stack(name: str, images, *, min_count: int = 1) -> np.ndarray:
    """Return ``images`` as a finite floating ``(N, H, W, 3)`` array (a view when possible).

    A list of same-shaped ``(H, W, 3)`` images is stacked; integer images are refused.
    """
    if isinstance(images, np.ndarray):
        stack = images
    else:
        try:
            items = [np.asarray(im) for im in images]
        except TypeError:
            raise InputError(f"{name} must be a sequence of (H, W, 3) images, got {type(images).__name__}") from None
        shapes = {im.shape for im in items}
        if len(shapes) > 1:
            raise InputError(f"{name}: all images must have the same shape, got shapes {sorted(shapes)}")
        if not items:
            raise InputError(f"{name} is empty; expected at least {min_count} images of shape (H, W, 3)")
        stack = np.stack(items)
    if stack.ndim != 4 or stack.shape[-1] != 3:
        raise InputError(f"{name} must be images of shape (H, W, 3) (stacked: (N, H, W, 3)), got {stack.shape}")
    if stack.dtype.kind != "f":
        raise InputError(
            f"{name} must be floating-point linear radiance, got dtype {stack.dtype}; "
            "convert integer captures with engine.imageio (which removes black level and scale)"
        )
    if stack.shape[0] < min_count:
        raise InputError(f"{name} must hold at least {min_count} images, got {stack.shape[0]}")
    if not np.all(np.isfinite(stack)):
        bad = int(stack.size - np.count_nonzero(np.isfinite(stack)))
        raise InputError(f"{name} contains {bad} non-finite values (NaN or inf); expected finite radiance")
    return stack


def check_images(name: str, images, *, min_count: int = 1) -> list[np.ndarray]:
    """Return ``images`` as a list of finite floating ``(H, W, 3)`` arrays of one shape.

    Nothing is stacked or copied (a stacked ``(N, H, W, 3)`` array gives views), so callers
    can reduce captures one at a time with bounded memory.
    """
    if isinstance(images, np.ndarray):
        if images.ndim != 4:
            raise InputError(f"{name} must be images of shape (H, W, 3) (stacked: (N, H, W, 3)), got {images.shape}")
        items = list(images)
    else:
        try:
            items = [np.asarray(im) for im in images]
        except TypeError:
            raise InputError(f"{name} must be a sequence of (H, W, 3) images, got {type(images).__name__}") from None
    if len(items) < min_count:
        raise InputError(f"{name} must hold at least {min_count} images, got {len(items)}")
    shape = items[0].shape
    for i, im in enumerate(items):
        if im.shape != shape:
            raise InputError(f"{name}: all images must have the same shape, got {shape} and {im.shape} (image {i})")
        if im.ndim != 3 or im.shape[-1] != 3:
            raise InputError(f"{name} must be images of shape (H, W, 3), got {im.shape}")
        if im.dtype.kind != "f":
            raise InputError(
                f"{name} must be floating-point linear radiance, got dtype {im.dtype}; "
                "convert integer captures with engine.imageio (which removes black level and scale)"
            )
        if not np.all(np.isfinite(im)):
            bad = int(im.size - np.count_nonzero(np.isfinite(im)))
            raise InputError(f"{name}[{i}] contains {bad} non-finite values (NaN or inf); expected finite radiance")
    return items


def check_image(name: str, image, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """Return a finite floating ``(H, W, 3)`` image, optionally of exactly ``shape``."""
    image = np.asarray(image)
    if image.dtype.kind != "f":
        raise InputError(f"{name} must be floating-point linear radiance, got dtype {image.dtype}")
    if image.ndim != 3 or image.shape[-1] != 3:
        raise InputError(f"{name} must have shape (H, W, 3), got {image.shape}")
    if shape is not None and image.shape != tuple(shape):
        raise InputError(f"{name} must have shape {tuple(shape)} like the captures, got {image.shape}")
    if not np.all(np.isfinite(image)):
        raise InputError(f"{name} contains non-finite values (NaN or inf); expected finite radiance")
    return image


def check_fraction(name: str, value, *, channels: int = 3, upper_open: bool = True) -> np.ndarray:
    """Return a scalar or per-channel fraction in [0, 1) as a float64 ``(channels,)`` array."""
    b = np.asarray(value, dtype=np.float64)
    if b.ndim == 0:
        b = np.full(channels, float(b))
    if b.shape != (channels,):
        raise InputError(f"{name} must be a scalar or one value per channel ({channels}), got shape {b.shape}")
    if not np.all(np.isfinite(b)) or np.any(b < 0) or (np.any(b >= 1) if upper_open else np.any(b > 1)):
        bound = "[0, 1)" if upper_open else "[0, 1]"
        raise InputError(f"{name} must be in {bound}, got {b.tolist()}")
    return b


@overload
def check_positive(name: str, value, *, allow_none: Literal[False] = False) -> float: ...


@overload
def check_positive(name: str, value, *, allow_none: bool) -> float | None: ...


def check_positive(name: str, value, *, allow_none: bool = False) -> float | None:
    """Return ``value`` as a finite float > 0 (an exposure, a timeout, a gain).

    Examples
    --------
    >>> check_positive("exposure", "0.5")
    0.5
    >>> check_positive("timeout", None, allow_none=True) is None
    True
    """
    if value is None and allow_none:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a positive number, got {value!r}") from None
    if not np.isfinite(v) or v <= 0:
        raise InputError(f"{name} must be a positive number (finite, > 0), got {value!r}")
    return v
