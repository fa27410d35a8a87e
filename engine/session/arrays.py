"""Calibration arrays on disk: finite float32 images as EXR (viewable anywhere), the rest as ``.npy``.

Both read back exactly (same dtype and shape); ``.npy`` files are never unpickled.
"""

from __future__ import annotations

import errno
from pathlib import Path

import numpy as np

from engine import imageio
from engine.errors import InputError

__all__ = ["check_storable", "read_array", "suffix_for", "write_array"]


def check_storable(what: str, array) -> np.ndarray:
    """Return ``array`` as an ndarray if it is numeric or bool (storable without pickle), else InputError."""
    array = np.asarray(array)
    if array.dtype.hasobject or array.dtype.kind not in "biufc":
        raise InputError(f"{what} has dtype {array.dtype}; only numeric and bool arrays are stored")
    return array


def suffix_for(array: np.ndarray) -> str:
    """``".exr"`` for finite float32 ``(H, W)`` or ``(H, W, C≤4)`` images, ``".npy"`` for everything else."""
    as_image = (
        array.dtype == np.float32
        and array.size > 0
        and (array.ndim == 2 or (array.ndim == 3 and 1 <= array.shape[2] <= 4))
        and bool(np.all(np.isfinite(array)))
    )
    return ".exr" if as_image else ".npy"


def write_array(file: Path, array: np.ndarray) -> None:
    """Write ``array`` atomically to ``file`` (its suffix from :func:`suffix_for`).

    Raises
    ------
    InputError, OSError
        The write failed; ``file`` is unchanged.
    """
    if file.suffix == ".exr":
        imageio.write_image(file, array, dtype="float")
        return

    def writer(temp: Path) -> None:
        with open(temp, "wb") as fh:
            np.save(fh, array, allow_pickle=False)

    def verify(temp: Path) -> None:
        try:
            back = np.load(temp, allow_pickle=False)
        except (ValueError, EOFError) as exc:
            raise OSError(errno.EIO, f"the array written does not read back ({exc})") from exc
        if back.dtype != array.dtype or not np.array_equal(back, array, equal_nan=array.dtype.kind in "fc"):
            raise OSError(errno.EIO, "the array written does not read back as written")

    imageio.atomic_write(file, writer, verify=verify)


def read_array(file: Path, shape: tuple[int, ...], dtype: np.dtype) -> np.ndarray:
    """Read an array written by :func:`write_array`, checking it is ``dtype`` of ``shape``.

    Raises
    ------
    InputError, OSError, ValueError, EOFError
        Unreadable, needing pickle, or of another dtype or shape (the message says which).
    """
    if file.suffix == ".npy":
        array = np.load(file, allow_pickle=False)
    else:
        array = imageio.read_image(file, srgb=False)
        if array.size == int(np.prod(shape)):
            array = array.reshape(shape)
    if array.shape != tuple(shape) or array.dtype != dtype:
        raise ValueError(f"it holds {array.dtype}{array.shape}, the manifest says {dtype}{tuple(shape)}")
    return array
