"""Checks and small helpers shared by the calibration modules (private)."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from engine.errors import InputError


def wh(resolution: tuple[int, int]) -> str:
    """Format an ``(H, W)`` resolution the way people say it: ``"W×H"``."""
    return f"{resolution[1]}×{resolution[0]}"


def check_resolution(name: str, resolution) -> tuple[int, int]:
    """Return ``resolution`` as a ``(H, W)`` tuple of positive ints, or raise InputError."""
    try:
        h, w = (int(v) for v in resolution)
        exact = all(float(v) == int(v) for v in resolution)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be (height, width) in pixels, got {resolution!r}") from None
    if not exact or h < 1 or w < 1:
        raise InputError(f"{name} must be (height, width), two positive integers, got {resolution!r}")
    return h, w


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


def check_positive(name: str, value) -> float:
    """Return ``value`` as a finite float > 0."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a positive number, got {value!r}") from None
    if not np.isfinite(v) or v <= 0:
        raise InputError(f"{name} must be a positive number, got {value!r}")
    return v


class Patterns(Sequence):
    """A read-only, lazily rendered sequence of projector images.

    Each item is a new float32 ``(Hp, Wp, 3)`` array in [0, 1], made when it is asked for, so a
    long sequence (42 Gray-code frames of a 1920×1080 projector would be 1.1 GB as float32)
    costs only its recipe. ``names[i]`` says what image ``i`` is, for capture logs.
    """

    def __init__(self, render: Callable[[int], np.ndarray], names: Sequence[str], resolution: tuple[int, int]):
        self._render = render
        self.names = tuple(names)
        self.resolution = resolution

    def __len__(self) -> int:
        return len(self.names)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        i = int(index)
        if i < 0:
            i += len(self)
        if not 0 <= i < len(self):
            raise IndexError(f"pattern index {index} out of range for {len(self)} patterns")
        return self._render(i)

    def __repr__(self) -> str:
        return f"Patterns({len(self)} images of {wh(self.resolution)}: {', '.join(self.names[:3])}, ...)"


def plane_to_rgb(plane: np.ndarray) -> np.ndarray:
    """Return a contiguous float32 ``(H, W, 3)`` copy of a single-channel plane."""
    out = np.empty(plane.shape + (3,), np.float32)
    out[...] = plane[..., None]
    return out
