"""Camera RAW files, decoded linearly through rawpy (LibRaw): the one RAW decoder of Albedit.

:func:`engine.imageio.read_image` reads RAW files through :func:`decode_raw`, and so do the hot
folder and tethered camera backends for the files they download: black level removed, white
level at 1.0, no gamma, no white balance, camera primaries, the sensor's orientation, and the
photosites that reached the white level flagged as saturated.
"""

from __future__ import annotations

import io
import os
from dataclasses import dataclass
from typing import Any

import numpy as np
import rawpy

from engine.errors import InputError

__all__ = ["RAW_EXTENSIONS", "RawDecode", "decode_raw", "raw_postprocess_options", "read_raw_bytes"]

#: Camera RAW extensions decoded through rawpy/LibRaw (lower case, with the dot): the one list
#: every reader of RAW files uses (read_image, the hot folder, tethered downloads, file dialogs).
RAW_EXTENSIONS = frozenset(
    ".3fr .arw .cr2 .cr3 .crw .dcr .dng .erf .iiq .k25 .kdc .mef .mos .mrw .nef .nrw .orf .pef "
    ".raf .raw .rw2 .rwl .sr2 .srf .srw .x3f".split()
)



def raw_postprocess_options() -> dict[str, Any]:
    """The rawpy ``postprocess`` options of Albedit's linear RAW decode.

    Returns
    -------
    dict
        ``gamma=(1, 1)`` (no tone curve), ``no_auto_bright=True`` (no per-frame brightening),
        ``output_bps=16``, ``output_color=rawpy.ColorSpace.raw`` (camera primaries, no matrix),
        ``user_wb=[1, 1, 1, 1]`` (no white balance), ``adjust_maximum_thr=0.0`` (LibRaw's
        default 0.75 rescales each frame by its own maximum, which breaks linearity between
        captures), ``user_flip=0`` (the sensor's orientation: a camera's orientation tag can
        change between two shots of a fixed rig, its pixel grid cannot).

    Examples
    --------
    >>> raw_postprocess_options()["adjust_maximum_thr"], raw_postprocess_options()["user_flip"]
    (0.0, 0)
    """
    return {
        "gamma": (1, 1),
        "no_auto_bright": True,
        "output_bps": 16,
        "output_color": rawpy.ColorSpace.raw,
        "user_wb": [1.0, 1.0, 1.0, 1.0],
        "adjust_maximum_thr": 0.0,
        "user_flip": 0,
    }


@dataclass(frozen=True)
class RawDecode:
    """A camera RAW file decoded linearly (see :func:`decode_raw`).

    Attributes
    ----------
    image : (H, W, 3) float32
        Camera RGB, black level removed, 1.0 = white level; no white balance, no gamma,
        sensor orientation.
    saturated : (H, W) bool
        Pixels whose photosite, or a neighbour demosaicing mixed in, reached the white level:
        their value is a lower bound.
    black_level : float
        Mean black level removed, in raw units.
    white_level : float
        The sensor's clipping level, in raw units.
    """

    image: np.ndarray
    saturated: np.ndarray
    black_level: float
    white_level: float


def _grow_3x3(mask: np.ndarray) -> np.ndarray:
    """``mask`` or any of its 8 neighbours (the pixels a demosaic mixes a photosite into)."""
    pad = np.pad(mask, 1)
    grown = np.zeros_like(mask)
    for dy in range(3):
        for dx in range(3):
            grown |= pad[dy : dy + mask.shape[0], dx : dx + mask.shape[1]]
    return grown


def decode_raw(source, *, name: str | None = None) -> RawDecode:
    """Decode a camera RAW file linearly with rawpy (LibRaw): the one RAW decoder of Albedit.

    Parameters
    ----------
    source : bytes, bytearray, memoryview, str or Path
        The complete file in memory (as downloaded from a tethered camera) or its path.
    name : str, optional, keyword-only
        How to name the data in error messages (default: the path, or ``"<RAW bytes>"``).

    Returns
    -------
    RawDecode

    Raises
    ------
    InputError
        Empty data, a missing file, or data LibRaw cannot decode (corrupt, truncated or
        unsupported); the message names the file.

    Notes
    -----
    Decoded with :func:`raw_postprocess_options`. Black and white level come from the file;
    with auto-brightening off LibRaw subtracts the per-channel black level and maps the white
    level to 65535, so dividing by 65535 puts white at 1.0. Two things are the sensor's, not
    ours: values at or above the white level come out as exactly 1.0 (flagged in
    ``saturated``), and LibRaw clips noise below the black level to 0, so very dark pixels
    carry a small positive bias.

    Examples
    --------
    >>> try:
    ...     decode_raw(b"not a raw file", name="DSC_0001.NEF")
    ... except InputError as exc:
    ...     print(str(exc).split(" (")[0])
    DSC_0001.NEF: cannot decode RAW data
    """
    data: io.BytesIO | str
    if isinstance(source, (bytes, bytearray, memoryview)):
        label = name or "<RAW bytes>"
        if len(source) == 0:
            raise InputError(f"{label}: RAW data is empty (0 bytes)")
        data = io.BytesIO(bytes(source))
    elif isinstance(source, (str, os.PathLike)):
        label = name or str(source)
        data = os.fspath(source)
    else:
        raise InputError(f"{name or 'RAW data'}: data must be bytes or a path, got {type(source).__name__}")
    try:
        with rawpy.imread(data) as raw:
            if raw.raw_type == rawpy.RawType.Stack:  # a linear DNG: values per pixel, no mosaic
                return _decode_linear(raw)
            mosaic = np.array(raw.raw_image_visible, copy=True)
            white = float(raw.white_level)
            black = float(np.mean(raw.black_level_per_channel))
            rgb = raw.postprocess(**raw_postprocess_options())
    except (rawpy.LibRawError, rawpy.NotSupportedError, ValueError, EOFError) as exc:
        raise InputError(f"{label}: cannot decode RAW data ({type(exc).__name__}: {exc})") from exc
    except OSError as exc:
        raise InputError(f"{label}: cannot read file: {exc}") from exc
    image = np.ascontiguousarray(rgb, dtype=np.float32) / np.float32(65535.0)
    saturated = np.any(rgb >= 65535, axis=2)
    if mosaic.shape == rgb.shape[:2]:  # a mosaic in the output's grid: spread clipped photosites
        clipped = mosaic >= white
        if clipped.ndim == 3:  # a linear (already demosaiced) DNG holds one value per channel
            clipped = np.any(clipped, axis=2)
        if clipped.any():
            saturated |= _grow_3x3(clipped)
    return RawDecode(image=image, saturated=saturated, black_level=black, white_level=white)


def _decode_linear(raw) -> RawDecode:
    """A linear ("stacked") DNG: three values per pixel, read as stored.

    LibRaw's ``postprocess`` scales such files by 1 / white level instead of
    1 / (white − black) (3 % low at a 14-bit camera's black level of 512) and reports no clipped
    pixel, so the values are taken from ``raw_image_visible`` with the file's own levels.
    """
    n = int(raw.num_colors)
    values = np.asarray(raw.raw_image_visible)[..., :n].astype(np.float32)
    black = np.asarray(raw.black_level_per_channel[:n], np.float32)
    white = float(raw.white_level)
    image = (values - black) / (np.float32(white) - black)
    np.maximum(image, 0.0, out=image)  # as LibRaw clips noise below black for mosaics
    saturated = np.any(values >= white, axis=2)
    return RawDecode(image=np.ascontiguousarray(image), saturated=saturated, black_level=float(black.mean()),
                     white_level=white)


def read_raw_bytes(data: bytes, *, name: str = "<RAW bytes>") -> np.ndarray:
    """Decode a camera RAW file held in memory: :func:`decode_raw`'s image.

    Parameters
    ----------
    data : bytes, bytearray or memoryview
        The complete RAW file.
    name : str, keyword-only
        How to name the data in error messages (e.g. the camera's file name).

    Returns
    -------
    (H, W, 3) float32
        Linear camera-RGB radiance, demosaiced, black level removed, white level = 1.0.

    Raises
    ------
    InputError
        Not bytes, empty data, or data LibRaw cannot decode.

    Examples
    --------
    >>> try:
    ...     read_raw_bytes(b"not a raw file", name="DSC_0001.NEF")
    ... except InputError as exc:
    ...     print(str(exc).split(" (")[0])
    DSC_0001.NEF: cannot decode RAW data
    """
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise InputError(f"{name}: data must be bytes, got {type(data).__name__}")
    return decode_raw(data, name=name).image
