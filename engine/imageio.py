"""Reading and writing images: EXR, TIFF, PNG (and JPEG reading) through OpenImageIO, RAW through rawpy.

Everything Albedit computes on is linear float32 radiance, so :func:`read_image` always returns
linear float32 ``(H, W, C)``:

- float files (EXR, float TIFF) are returned as stored;
- 8- and 16-bit files are scaled to [0, 1] and, when they are sRGB-encoded, decoded to linear.
  By default PNG and JPEG files and 8-bit TIFFs are taken as sRGB-encoded (that is what almost
  every tool writes), 16-bit TIFFs as linear (what RAW converters and scientific cameras
  write). ``srgb=True`` / ``srgb=False`` overrides the guess;
- camera RAW files are decoded linearly through rawpy (no gamma, no auto-brightness, no
  white balance, camera colour space), black level removed and scaled so the white level is 1,
  in the sensor's orientation (:func:`decode_raw`, the one RAW decoder of Albedit: files a
  camera backend downloads or finds in a hot folder are decoded by it too).

Every write is atomic (:func:`atomic_write`: a temporary file in the same folder, then
``os.replace``), so a crash never leaves a half-written image under the final name.
Albedit metadata (the edit: targets, κ, order, ...) is stored in the file as JSON strings in
attributes named ``"albedit:<key>"`` (and, in TIFF, in the ``ImageDescription`` tag) and read
back with :func:`read_metadata`.

:func:`to_display` is the one place that clips: it makes an 8-bit sRGB picture for a screen or
a preview PNG, and its output is never used for measurement.

Over 500 lines on purpose: reading, writing, the atomic verified write and the metadata share the
format tables and the one OpenImageIO error rule; camera RAW decoding lives in :mod:`engine.raw`.
"""

from __future__ import annotations

import errno
import json
import os
import secrets
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import OpenImageIO as oiio

from engine.checks import check_float_image
from engine.errors import InputError
from engine.raw import RAW_EXTENSIONS, decode_raw

__all__ = [
    "ImageInfo",
    "atomic_write",
    "image_info",
    "is_temp_name",
    "read_image",
    "read_mask",
    "read_metadata",
    "srgb_decode",
    "srgb_encode",
    "to_display",
    "write_image",
]

# extension -> (OpenImageIO format name, default "is sRGB-encoded" for 8-bit, for 16-bit data)
_READ_FORMATS = {
    ".exr": ("openexr", False, False),
    ".tif": ("tiff", True, False),
    ".tiff": ("tiff", True, False),
    ".png": ("png", True, True),
    ".jpg": ("jpeg", True, True),
    ".jpeg": ("jpeg", True, True),
}

# extension -> (OpenImageIO format name, allowed dtypes, default dtype)
_WRITE_FORMATS = {
    ".exr": ("openexr", ("float", "half"), "float"),
    ".tif": ("tiff", ("float", "uint16", "uint8"), "float"),
    ".tiff": ("tiff", ("float", "uint16", "uint8"), "float"),
    ".png": ("png", ("uint8", "uint16"), "uint8"),
}

_META_PREFIX = "albedit:"
_TEMP_MARK = ".tmp"


# ----------------------------------------------------------------------------- sRGB transfer


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """Apply the sRGB transfer function (IEC 61966-2-1) to linear values in [0, 1].

    Parameters
    ----------
    linear : ndarray, float
        Linear values. Nothing is clipped: values outside [0, 1] follow the curve's formula
        (negative values use the linear segment).

    Returns
    -------
    ndarray, same shape, float32 (float64 stays float64)
        sRGB-encoded values.

    Examples
    --------
    >>> srgb_encode(np.array([0.0, 0.0031308, 0.18, 1.0], np.float32)).round(4)
    array([0.    , 0.0404, 0.4614, 1.    ], dtype=float32)
    """
    x = np.asarray(linear)
    x = x.astype(np.float64 if x.dtype == np.float64 else np.float32, copy=False)
    low = x * x.dtype.type(12.92)
    high = x.dtype.type(1.055) * np.power(np.maximum(x, 0.0031308), 1 / 2.4, dtype=x.dtype) - x.dtype.type(0.055)
    return np.where(x <= 0.0031308, low, high)


def srgb_decode(encoded: np.ndarray) -> np.ndarray:
    """Invert :func:`srgb_encode`: sRGB-encoded values in [0, 1] to linear.

    Parameters
    ----------
    encoded : ndarray, float
        sRGB-encoded values (e.g. an 8-bit PNG divided by 255).

    Returns
    -------
    ndarray, same shape, float32 (float64 stays float64)
        Linear values.

    Examples
    --------
    >>> srgb_decode(np.array([0.0, 0.5, 1.0], np.float32)).round(4)
    array([0.   , 0.214, 1.   ], dtype=float32)
    """
    v = np.asarray(encoded)
    v = v.astype(np.float64 if v.dtype == np.float64 else np.float32, copy=False)
    low = v / v.dtype.type(12.92)
    high = np.power((np.maximum(v, 0.04045) + v.dtype.type(0.055)) / v.dtype.type(1.055), 2.4, dtype=v.dtype)
    return np.where(v <= 0.04045, low, high)


def _display_lut() -> np.ndarray:
    levels = np.arange(65536, dtype=np.float64) / 65535.0
    return np.round(srgb_encode(levels) * 255.0).astype(np.uint8)


_DISPLAY_LUT = _display_lut()


def to_display(image: np.ndarray, *, exposure: float = 0.0) -> np.ndarray:
    """Make an 8-bit sRGB picture of linear radiance, for a screen or a preview PNG.

    Parameters
    ----------
    image : (H, W) or (H, W, C) float
        Linear radiance, finite.
    exposure : float, keyword-only
        Exposure compensation in stops: the image is multiplied by ``2**exposure`` first.

    Returns
    -------
    (H, W) or (H, W, C) uint8
        sRGB-encoded values. Radiance above 1 (after exposure) becomes 255 and below 0
        becomes 0: this clipping is deliberate and for DISPLAY ONLY. Never feed the result
        back into the engine; keep the float image for measurement.

    Raises
    ------
    InputError
        ``image`` is not a finite float array of 2 or 3 dimensions, or ``exposure`` is not finite.

    Notes
    -----
    The transfer curve is looked up in a 65536-entry table over linear [0, 1], within one
    8-bit level of the exact formula.

    Examples
    --------
    >>> to_display(np.array([[0.0, 0.18, 1.0, 4.0]], np.float32))
    array([[  0, 118, 255, 255]], dtype=uint8)
    >>> to_display(np.array([[0.09]], np.float32), exposure=1.0)
    array([[118]], dtype=uint8)
    """
    image = check_float_image("image", image, ndim=(2, 3))
    if not np.isfinite(exposure):
        raise InputError(f"exposure must be a finite number of stops, got {exposure!r}")
    scaled = image.astype(np.float32, copy=False) * np.float32(2.0**exposure * 65535.0)
    idx = np.clip(scaled, 0.0, 65535.0)
    np.rint(idx, out=idx)
    return _DISPLAY_LUT[idx.astype(np.uint16)]


# ----------------------------------------------------------------------------- atomic writes


def atomic_write(path, writer: Callable[[Path], None], *, mode: int | None = None, exclusive: bool = False,
                 verify: Callable[[Path], None] | None = None) -> Path:
    """Write a file so that it appears under ``path`` complete or not at all.

    ``writer(temp_path)`` writes the content to a temporary file in the same folder (a hidden
    name that starts with ``"."`` and contains ``".tmp"``, keeping ``path``'s extension). The
    temporary file is flushed to disk, checked by ``verify``, its permissions set to ``mode``,
    and it is renamed over ``path`` with ``os.replace``; the folder is then flushed too. If
    anything fails, the temporary file is removed and ``path`` is left as it was.

    Parameters
    ----------
    path : str or Path
        Final file name; its folder must exist.
    writer : callable(Path) -> None
        Writes the whole file at the given temporary path.
    mode : int, optional, keyword-only
        Permission bits of the final file (e.g. ``0o444`` for a file never to be modified).
    exclusive : bool, keyword-only
        Refuse to replace an existing file: the final name is created with a hard link, which
        fails atomically if the name exists (``FileExistsError``, temporary file removed).
    verify : callable(Path) -> None, optional, keyword-only
        Reads the flushed temporary file back and raises ``OSError`` if it is not what was
        written (a full disk can truncate a file while the writer reports success).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    FileExistsError
        ``exclusive`` and ``path`` exists.
    OSError
        The write or the rename failed; ``path`` is unchanged.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     p = atomic_write(Path(d) / "a.txt", lambda t: t.write_text("hello"))
    ...     print(p.read_text(), sorted(x.name for x in Path(d).iterdir()))
    hello ['a.txt']
    """
    path = Path(path)
    temp = path.with_name(f".{path.name}.{secrets.token_hex(6)}{_TEMP_MARK}{path.suffix}")
    try:
        writer(temp)
        _fsync_file(temp)
        if verify is not None:
            verify(temp)
        if mode is not None:
            os.chmod(temp, mode)
        if exclusive:
            try:
                os.link(temp, path)
            except FileExistsError:
                raise
            except OSError:  # a file system without hard links: check, then rename
                if os.path.lexists(path):
                    raise FileExistsError(f"{path} exists") from None
                os.replace(temp, path)
            else:
                os.unlink(temp)
        else:
            os.replace(temp, path)
    except BaseException:
        try:
            os.unlink(temp)
        except FileNotFoundError:
            pass
        raise
    _fsync_dir(path.parent)
    return path


def _fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:  # some file systems refuse fsync on directories; the rename is done anyway
        pass
    finally:
        os.close(fd)


def is_temp_name(name: str) -> bool:
    """Whether a file name is the temporary file of an :func:`atomic_write` (left behind only by a killed write).

    Examples
    --------
    >>> is_temp_name(".c1.exr.0a1b2c3d4e5f.tmp.exr"), is_temp_name("c1.exr")
    (True, False)
    """
    return name.startswith(".") and _TEMP_MARK in name


# ----------------------------------------------------------------------------- reading


@dataclass(frozen=True)
class ImageInfo:
    """What a file's header says, read without decoding the pixels (see :func:`image_info`).

    Attributes
    ----------
    height, width, channels : int
    channel_names : tuple of str
    dtype : str
        Stored sample type as OpenImageIO names it (``"float"``, ``"half"``, ``"uint16"``, ``"uint8"``).
    """

    height: int
    width: int
    channels: int
    channel_names: tuple[str, ...]
    dtype: str


def _extension(path: Path) -> str:
    return path.suffix.lower()


def _check_readable(path) -> Path:
    path = Path(path)
    ext = _extension(path)
    if ext not in _READ_FORMATS and ext not in RAW_EXTENSIONS:
        raise InputError(
            f"{path}: unsupported image extension {path.suffix!r}; expected one of "
            f"{sorted(_READ_FORMATS) + sorted(RAW_EXTENSIONS)}"
        )
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if not path.is_file():
        raise InputError(f"{path}: not a regular file")
    return path


def _oiio_error(source=None) -> str:
    """OpenImageIO's error message (of ``source``, else the global one), safe to print.

    Its messages can quote bytes of a corrupt file that are not UTF-8, which the Python
    binding cannot decode: such a message is replaced by a plain description.
    """
    texts = []
    for get in ([source.geterror] if source is not None else []) + [oiio.geterror]:
        try:
            texts.append(get())
        except UnicodeDecodeError:
            texts.append("the file's header holds bytes that are not text (a corrupt or truncated file)")
    return next((t for t in texts if t), "unknown OpenImageIO error").strip()


def _input_config():
    """How every file is opened: colour channels as stored, never multiplied by alpha."""
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    return config


def _oiio_open(path: Path):
    inp = oiio.ImageInput.open(str(path), _input_config())
    if inp is None:
        raise InputError(f"{path}: cannot read image ({_oiio_error()})")
    return inp


def image_info(path) -> ImageInfo:
    """Read an image file's header: size, channels and stored sample type.

    Parameters
    ----------
    path : str or Path
        An EXR, TIFF, PNG or JPEG file (RAW files are refused: their size is known only after
        decoding).

    Returns
    -------
    ImageInfo

    Raises
    ------
    InputError
        Missing, unreadable or unsupported file.
    """
    path = _check_readable(path)
    if _extension(path) in RAW_EXTENSIONS:
        raise InputError(f"{path}: image_info reads EXR/TIFF/PNG/JPEG headers, not RAW files; use read_image")
    inp = _oiio_open(path)
    try:
        spec = inp.spec()
        return ImageInfo(spec.height, spec.width, spec.nchannels, tuple(spec.channelnames), str(spec.format))
    finally:
        inp.close()


def read_image(path, *, srgb: bool | None = None) -> np.ndarray:
    """Read an image file as linear float32 radiance.

    Parameters
    ----------
    path : str or Path
        ``.exr``, ``.tif``/``.tiff``, ``.png``, ``.jpg``/``.jpeg``, or a camera RAW file
        (any of :data:`RAW_EXTENSIONS`).
    srgb : bool or None, keyword-only
        Whether the stored values are sRGB-encoded and must be decoded to linear.
        ``None`` (default) decides by format: PNG, JPEG and 8-bit TIFF are sRGB-encoded;
        16-bit TIFF, float TIFF and EXR are linear. Alpha channels are never decoded. Must not
        be ``True`` for RAW files (always linear).

    Returns
    -------
    (H, W, C) float32
        Linear values; C is the file's channel count (1 for grey, 3 for RGB, 4 with alpha).
        Integer files are scaled to [0, 1] (65535 → 1.0). Float files are returned as stored.

    Raises
    ------
    InputError
        Missing file, unsupported extension, unreadable or corrupt file — including one the
        decoder read with a warning (a truncated JPEG) and one holding non-finite values (a
        damaged float TIFF or EXR) — the message names the path and the problem.

    Notes
    -----
    RAW files are decoded by :func:`decode_raw` (sensor orientation).

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = write_image(Path(d) / "grey.png", np.full((2, 2, 3), 0.214, np.float32), dtype="uint16")
    ...     print(read_image(Path(d) / "grey.png")[0, 0].round(3))
    [0.214 0.214 0.214]
    """
    path = _check_readable(path)
    ext = _extension(path)
    if ext in RAW_EXTENSIONS:
        if srgb:
            raise InputError(f"{path}: srgb=True makes no sense for a RAW file, which is decoded linearly")
        return decode_raw(path).image
    inp = _oiio_open(path)
    try:
        spec = inp.spec()
        if spec.deep:
            raise InputError(f"{path}: deep images are not supported")
        pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
        if pixels is None or inp.has_error:  # a decoder may return pixels and still report damage
            raise InputError(f"{path}: corrupt or truncated image ({_oiio_error(inp)}); refusing to use it")
        stored = str(spec.format)
        alpha = spec.alpha_channel
    finally:
        inp.close()
    image = np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)
    if not np.all(np.isfinite(image)):
        bad = int(image.size - np.count_nonzero(np.isfinite(image)))
        raise InputError(f"{path}: {bad} values are not finite (NaN or inf): a corrupt file, or not linear radiance; "
                         "refusing to use it")
    if srgb is None:
        _, srgb8, srgb16 = _READ_FORMATS[ext]
        if stored in ("float", "half", "double"):
            srgb = False
        elif stored in ("uint8", "int8"):
            srgb = srgb8
        else:
            srgb = srgb16
    if srgb:
        color = [c for c in range(image.shape[2]) if c != alpha]
        image[..., color] = srgb_decode(image[..., color])
    return np.ascontiguousarray(image)


def read_mask(path) -> np.ndarray:
    """Read a target mask painted in another program as ``(H, W) bool``.

    The stored values are used as they are (no sRGB decoding: a 50 % grey is "painted"). A
    pixel is in the mask when its luminance is non-zero — any grey or colour channel above 0 —
    or, for a file with an alpha channel that is transparent somewhere, when its alpha is
    non-zero (an alpha-only mask, whatever its colour channels hold).

    Parameters
    ----------
    path : str or Path
        A PNG, TIFF, EXR or JPEG file (not RAW).

    Returns
    -------
    (H, W) bool

    Raises
    ------
    InputError
        Unreadable, unsupported or corrupt file (see :func:`read_image`).

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     grey = np.full((1, 3), 128, np.uint8); grey[0, 0] = 0
    ...     _ = write_image(Path(d) / "m.png", grey)
    ...     print(read_mask(Path(d) / "m.png").tolist())
    [[False, True, True]]
    """
    path = _check_readable(path)
    if _extension(path) in RAW_EXTENSIONS:
        raise InputError(f"{path}: a mask must be a PNG, TIFF, EXR or JPEG image, not a camera RAW file")
    pixels = read_image(path, srgb=False)
    alpha = _alpha_index(path, pixels.shape[2])
    if alpha is not None and (pixels[..., alpha] < 1).any():
        return pixels[..., alpha] > 0
    colour = [c for c in range(pixels.shape[2]) if c != alpha]
    return np.any(pixels[..., colour] > 0, axis=2)


def _alpha_index(path: Path, channels: int) -> int | None:
    inp = _oiio_open(path)
    try:
        index = inp.spec().alpha_channel
    finally:
        inp.close()
    if 0 <= index < channels:
        return index
    return {2: 1, 4: 3}.get(channels)


def read_metadata(path) -> dict[str, Any]:
    """Read the Albedit metadata stored in an image by :func:`write_image`.

    Parameters
    ----------
    path : str or Path
        An image file.

    Returns
    -------
    dict
        ``{key: value}`` with values decoded from JSON; empty if the file has none (RAW files
        and files written by other tools).

    Raises
    ------
    InputError
        Missing, unreadable or unsupported file, or an ``albedit:`` attribute that is not
        valid JSON.
    """
    path = _check_readable(path)
    if _extension(path) in RAW_EXTENSIONS:
        return {}
    inp = _oiio_open(path)
    try:
        spec = inp.spec()
        attributes = {p.name: p.value for p in spec.extra_attribs}
    finally:
        inp.close()
    texts: dict[str, str] = {}
    description = attributes.get("ImageDescription")
    if isinstance(description, str) and description.startswith('{"albedit"'):
        try:
            texts.update(json.loads(description)["albedit"])
        except (ValueError, KeyError, TypeError) as exc:
            raise InputError(f"{path}: corrupt Albedit metadata in ImageDescription: {exc}") from exc
    for key, value in attributes.items():
        if key.startswith(_META_PREFIX) and isinstance(value, str):
            texts[key[len(_META_PREFIX) :]] = value
    out = {}
    for key, text in texts.items():
        try:
            out[key] = json.loads(text)
        except ValueError as exc:
            raise InputError(f"{path}: Albedit metadata {key!r} is not valid JSON: {exc}") from exc
    return out


# ----------------------------------------------------------------------------- writing


def _metadata_texts(path: Path, metadata: dict | None) -> dict[str, str]:
    if metadata is None:
        return {}
    if not isinstance(metadata, dict):
        raise InputError(f"{path}: metadata must be a dict of JSON-serialisable values, got {type(metadata).__name__}")
    texts = {}
    for key, value in metadata.items():
        if not isinstance(key, str) or not key or not all(c.isalnum() or c in "_.-" for c in key):
            raise InputError(f"{path}: metadata key {key!r} must be a non-empty string of letters, digits, "
                             "'_', '.', '-'")
        try:
            texts[key] = json.dumps(value, ensure_ascii=False, allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise InputError(f"{path}: metadata {key!r} is not JSON-serialisable ({exc})") from exc
    return texts


def write_image(
    path,
    image: np.ndarray,
    *,
    dtype: str | None = None,
    srgb: bool | None = None,
    metadata: dict | None = None,
    channel_names: Sequence[str] | None = None,
    mode: int | None = None,
    exclusive: bool = False,
) -> Path:
    """Write an image atomically: EXR (float/half), TIFF (float/16-bit/8-bit) or PNG (8/16-bit).

    Parameters
    ----------
    path : str or Path
        Destination; the extension chooses the format (``.exr``, ``.tif``/``.tiff``, ``.png``).
        Its folder must exist. An existing file is replaced atomically.
    image : (H, W) or (H, W, C) array, C in 1..4
        Float: linear radiance, finite. An integer array (uint8/uint16, e.g. the output of
        :func:`to_display`) is written verbatim to an integer file of the same dtype: its
        encoding is the caller's.
    dtype : {"float", "half", "uint16", "uint8"}, optional, keyword-only
        Stored sample type. Default: the integer array's own dtype; otherwise ``"float"`` for
        EXR and TIFF, ``"uint8"`` for PNG. EXR takes float/half; TIFF float/uint16/uint8;
        PNG uint8/uint16.
    srgb : bool, optional, keyword-only
        Whether a float image written to an integer file is sRGB-encoded first. Default: the
        guess :func:`read_image` makes, so a round trip is faithful: PNG (8 and 16-bit) and
        8-bit TIFF yes (for display), 16-bit TIFF no (stays linear). Ignored for float files.
    metadata : dict, optional, keyword-only
        JSON-serialisable values (e.g. ``{"edit": {"targets": [...], "kappa": [...], "order": 4}}``),
        stored as string attributes ``"albedit:<key>"``; read back with :func:`read_metadata`.
    channel_names : sequence of str, optional, keyword-only
        Names of the channels (default R, G, B, A / Y).
    mode : int, optional, keyword-only
        Permission bits of the new file (``0o444``: read-only), set before it appears.
    exclusive : bool, keyword-only
        Never replace an existing file (see :func:`atomic_write`).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    FileExistsError
        ``exclusive`` and ``path`` exists (nothing written).
    InputError
        Unsupported extension or dtype for it, bad shape, non-finite values, a float image
        outside [0, 1] for an integer file (nothing is clipped: scale it first, or use
        :func:`to_display` for a display picture, which clips deliberately), metadata that is
        not JSON, or the write itself failed (then ``path`` is unchanged).

    Notes
    -----
    Half floats keep about 3 significant digits (relative error ≤ 2**-11) and overflow above
    65504: radiance above that is refused for ``dtype="half"``.

    Examples
    --------
    >>> import tempfile
    >>> img = np.array([[[0.5, 2.0, 1e-3]]], np.float32)
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = write_image(Path(d) / "x.exr", img, metadata={"order": 4})
    ...     print(np.array_equal(read_image(Path(d) / "x.exr"), img), read_metadata(Path(d) / "x.exr"))
    True {'order': 4}
    """
    path = Path(path)
    ext = _extension(path)
    if ext not in _WRITE_FORMATS:
        raise InputError(f"{path}: cannot write extension {path.suffix!r}; expected one of {sorted(_WRITE_FORMATS)}")
    fmt_name, allowed, default_dtype = _WRITE_FORMATS[ext]
    array = np.asarray(image)
    if array.ndim == 2:
        array = array[..., None]
    if array.ndim != 3 or not 1 <= array.shape[2] <= 4 or array.shape[0] < 1 or array.shape[1] < 1:
        raise InputError(f"{path}: image must have shape (H, W) or (H, W, C) with C in 1..4, got {np.shape(image)}")
    height, width, channels = array.shape
    integer_input = array.dtype in (np.uint8, np.uint16)
    if not integer_input and array.dtype.kind != "f":
        raise InputError(
            f"{path}: image must be float (linear radiance) or uint8/uint16 (already encoded), got dtype {array.dtype}"
        )
    if dtype is None:
        dtype = str(array.dtype) if integer_input else default_dtype
    if dtype not in allowed:
        raise InputError(f"{path}: dtype for {ext} files must be one of {list(allowed)}, got {dtype!r}")
    if integer_input:
        if str(array.dtype) != dtype:
            raise InputError(
                f"{path}: a {array.dtype} image is written verbatim and needs dtype={str(array.dtype)!r}, "
                f"got {dtype!r}; "
                "pass a float image to convert"
            )
        pixels = np.ascontiguousarray(array)
    else:
        if not np.all(np.isfinite(array)):
            bad = int(array.size - np.count_nonzero(np.isfinite(array)))
            raise InputError(f"{path}: image contains {bad} non-finite values (NaN or inf); refusing to write")
        pixels = np.ascontiguousarray(array, dtype=np.float32)
        if dtype == "half" and np.abs(pixels).max() > 65504.0:
            raise InputError(f"{path}: values up to {np.abs(pixels).max():g} overflow half floats (max 65504); "
                             "use dtype='float'")
        if dtype in ("uint8", "uint16"):
            lo, hi = float(pixels.min()), float(pixels.max())
            if lo < 0.0 or hi > 1.0:
                raise InputError(
                    f"{path}: a {dtype} file holds [0, 1], but the image spans [{lo:g}, {hi:g}]; scale it first, "
                    "or write to_display(image, exposure=...) which clips deliberately for display"
                )
            if srgb is None:  # the same guess read_image makes, so a round trip is faithful
                _, srgb8, srgb16 = _READ_FORMATS[ext]
                srgb = srgb8 if dtype == "uint8" else srgb16
            if srgb:
                alpha = 3 if channels == 4 else None
                color = [c for c in range(channels) if c != alpha]
                pixels = pixels.copy()
                pixels[..., color] = srgb_encode(pixels[..., color])
            scale = 255.0 if dtype == "uint8" else 65535.0
            pixels = np.rint(pixels * np.float32(scale)).astype(dtype)
    texts = _metadata_texts(path, metadata)

    spec = oiio.ImageSpec(width, height, channels, dtype)
    if channel_names is not None:
        names = tuple(str(n) for n in channel_names)
        if len(names) != channels:
            raise InputError(f"{path}: channel_names has {len(names)} names for {channels} channels")
        spec.channelnames = names
        spec.alpha_channel = names.index("A") if "A" in names else -1
    elif channels == 2:
        spec.alpha_channel = -1
    spec.attribute("oiio:UnassociatedAlpha", 1)
    if ext == ".exr":
        spec.attribute("compression", "zip")
    for key, text in texts.items():
        spec.attribute(_META_PREFIX + key, text)
    if ext in (".tif", ".tiff"):
        spec.attribute("compression", "zip")
        if texts:
            spec.attribute("ImageDescription", json.dumps({"albedit": texts}, ensure_ascii=False))

    def _write(temp: Path) -> None:
        out = oiio.ImageOutput.create(fmt_name)
        if out is None:
            raise OSError(f"no OpenImageIO writer for {fmt_name} ({_oiio_error()})")
        if not out.open(str(temp), spec):
            raise OSError(_oiio_error(out))
        ok = out.write_image(pixels)
        err = _oiio_error(out) if not ok else ""
        closed = out.close()
        if not ok or not closed:
            raise OSError(err or _oiio_error(out))

    def _verify(temp: Path) -> None:
        _check_written(temp, pixels, dtype, metadata)

    try:
        atomic_write(path, _write, mode=mode, exclusive=exclusive, verify=_verify)
    except FileExistsError:
        raise
    except OSError as exc:
        raise InputError(f"{path}: cannot write image ({exc}); the previous file, if any, is unchanged") from exc
    return path


def _check_written(temp: Path, pixels: np.ndarray, dtype: str, metadata: dict | None) -> None:
    """Read a written image back: OSError unless its pixels and metadata are exactly what was written."""
    inp = oiio.ImageInput.open(str(temp), _input_config())
    if inp is None:
        raise OSError(errno.EIO, f"the image written does not read back ({_oiio_error()})")
    try:
        spec = inp.spec()
        back = inp.read_image(0, 0, 0, spec.nchannels, dtype)
        failed = back is None or inp.has_error
    finally:
        inp.close()
    expected = pixels.astype(np.float16) if dtype == "half" else pixels
    if failed or back is None or np.shape(back) != expected.shape or not np.array_equal(back, expected):
        raise OSError(errno.EIO, "the image written does not read back as written (a full disk, or a failing one)")
    if metadata and read_metadata(temp) != json.loads(json.dumps(metadata)):
        raise OSError(errno.EIO, "the image written does not read back with its metadata")
