"""Camera↔projector correspondences from Gray-code structured light.

The projector shows a Gray-code sequence (column bits, then row bits, most significant first,
each as a [pattern, inverse] pair) followed by a white and a black frame;
:func:`decode_gray_code` turns the captures into the projector pixel seen by every camera
pixel, with OpenCV's per-pixel rule but vectorised over the whole image.

Two codes (:data:`GRAY_CODES`):

* ``"gray"`` — OpenCV's ``structured_light.GrayCodePattern`` images as they are. Its most
  significant bits light half the scene at once, and where a surface sees a brightly lit
  other surface more than its own projector pixel (a grazing wall at a concave corner) the
  interreflected light flips those bits: the pixel decodes to a projector pixel several
  pixels off, and light re-emitted there lands on the wrong surface.
* ``"xor"`` (the default) — every bit above the second least significant is shown XOR-ed
  with that bit's stripes (period 8 projector pixels), so every pattern is high-frequency
  and the global light a pixel receives is about the same under a pattern and its inverse;
  decoding XORs the bits back. Same number of images, same decode-quality checks. On the
  ideal virtual Cornell box at 80² (the back wall/right wall corner falls on the
  most significant column bit's edge) the Gray code left 139 target pixels undecoded and
  74 wrongly decoded (the recolor: 91.7 % error); this code decodes all of them right (0.20 %).

References
----------
S. Inokuchi, K. Sato, F. Matsuda, "Range imaging system for 3-D object recognition", ICPR 1984
(cited by the paper, Sec. 6, for its correspondences).
M. Gupta, A. Agrawal, A. Veeraraghavan, S. G. Narasimhan, "Structured light 3D scanning in the
presence of global illumination", CVPR 2011 (the XOR-04 code).

Over 500 lines on purpose: pattern generation, decoding and the decode-quality checks of one
code must agree bit for bit, so they live together.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import cv2
import numpy as np

from engine.calibrate._common import Patterns, plane_to_rgb, wh
from engine.checks import check_resolution
from engine.errors import AlbeditError, InputError

__all__ = [
    "GRAY_CODES",
    "Correspondence",
    "PixelStatus",
    "decode_gray_code",
    "gray_code_bits",
    "gray_code_patterns",
]

#: Float thresholds are fractions of the captures' full scale (see :func:`decode_gray_code`).
FLOAT_THRESHOLD = 0.02
FLOAT_SHADOW_THRESHOLD = 0.02
#: Float captures with white/black: a bit is trusted when its pair differs by this fraction of
#: the pixel's largest pair difference (its direct projector light: grazing or far surfaces
#: get little of it but decode as well as any other, and global light does not count), and
#: pixels are lit above these fractions of full scale.
FLOAT_RELATIVE_THRESHOLD = 0.1
FLOAT_FLOOR = 0.002
FLOAT_SHADOW_FLOOR = 0.005
#: OpenCV's defaults for 8-bit captures (whiteThreshold, blackThreshold).
UINT8_THRESHOLD = 5
UINT8_SHADOW_THRESHOLD = 40
#: The ``"xor"`` code's base bit is trusted when its pair differs by this fraction of the
#: pixel's largest pair difference: where it is unsure (a camera pixel across one of its stripe
#: edges) every bit above it would flip and the pixel decode far off. Measured on a blurred,
#: noisy 8-bit render (tests/engine/test_calibrate_graycode.py): 149 pixels off by more than one
#: projector pixel at the plain threshold, 8 (as many as the Gray code) at 0.2, with 11 % fewer
#: pixels decoded than the Gray code (47.6 against 53.5 % of that render).
XOR_BASE_RELATIVE_THRESHOLD = 0.2
#: The codes :func:`gray_code_patterns` shows and :func:`decode_gray_code` reads (module docstring).
GRAY_CODES = ("xor", "gray")


class PixelStatus(IntEnum):
    """Why a camera pixel has (or lacks) a projector pixel."""

    DECODED = 0
    #: The projector does not light it: white − black below the shadow threshold.
    UNLIT = 1
    #: Some pattern pair differed by less than the threshold (edge, blur, noise, dark surface).
    LOW_CONTRAST = 2
    #: The decoded code is beyond the projector's width or height (noise or indirect light).
    OUT_OF_RANGE = 3


def gray_code_bits(projector_resolution) -> tuple[int, int]:
    """Return the number of column and row bits for a projector, as OpenCV counts them.

    Parameters
    ----------
    projector_resolution : (Hp, Wp)
        Projector height and width in pixels.

    Returns
    -------
    (int, int)
        ``ceil(log2 Wp)`` column bits and ``ceil(log2 Hp)`` row bits; the sequence holds
        ``2 · (column bits + row bits)`` pattern images.

    Examples
    --------
    >>> gray_code_bits((768, 1024))
    (10, 10)
    """
    hp, wp = check_resolution("projector_resolution", projector_resolution)
    if hp < 2 or wp < 2:
        raise InputError(f"projector_resolution must be at least 2×2 pixels for Gray code, got {wh((hp, wp))}")
    return (wp - 1).bit_length(), (hp - 1).bit_length()


def gray_code_patterns(projector_resolution, *, code: str = "xor") -> Patterns:
    """Return the projector images of the Gray-code sequence, then white, then black.

    Parameters
    ----------
    projector_resolution : (Hp, Wp)
        Projector height and width in pixels.
    code : {"xor", "gray"}
        ``"gray"``: OpenCV's images as they are; ``"xor"``: the bits above the second least
        significant XOR-ed with it, robust to interreflections (module docstring).

    Returns
    -------
    Patterns
        A lazy sequence of ``2 · bits + 2`` float32 ``(Hp, Wp, 3)`` images in [0, 1]: the
        pattern pairs in OpenCV's order (column bits then row bits, most significant first,
        each as pattern then inverse), then all-white, then all-black. Show them through the
        projector as they are (values 0 and 1 need no linearisation).

    Notes
    -----
    The Gray-code images come from ``cv2.structured_light.GrayCodePattern.create(Wp, Hp).generate()``.

    Examples
    --------
    >>> seq = gray_code_patterns((6, 10), code="gray")
    >>> len(seq), seq[0].shape, seq.names[-2:]
    (16, (6, 10, 3), ('white', 'black'))
    >>> seq[0][0, :, 0].astype(int).tolist()
    [0, 0, 0, 0, 0, 0, 0, 0, 1, 1]
    >>> gray_code_patterns((6, 10))[0][0, :, 0].astype(int).tolist()  # XOR-ed with bit 2's stripes
    [0, 0, 1, 1, 1, 1, 0, 0, 1, 1]
    """
    hp, wp = check_resolution("projector_resolution", projector_resolution)
    _check_code(code)
    ncol, nrow = gray_code_bits((hp, wp))
    ok, planes = _gray_code_pattern(wp, hp).generate()
    if not ok or len(planes) != 2 * (ncol + nrow):  # pragma: no cover - OpenCV contract
        raise RuntimeError(f"OpenCV generated {len(planes)} Gray-code images, expected {2 * (ncol + nrow)}")
    planes = [np.asarray(p, dtype=np.uint8) for p in planes]
    if code == "xor":
        for first, nbits in ((0, ncol), (ncol, nrow)):
            base = _xor_base(nbits)
            if base is None:
                continue
            for k in range(2 * first, 2 * (first + base)):  # both images of each pair
                planes[k] = planes[k] ^ planes[2 * (first + base)]
    names = [
        f"{code} {axis} bit {k}{' inverse' if inv else ''}"
        for axis, n in (("x", ncol), ("y", nrow))
        for k in range(n)
        for inv in (False, True)
    ] + ["white", "black"]

    def render(i: int) -> np.ndarray:
        if i < len(planes):
            return plane_to_rgb(planes[i] * np.float32(1 / 255))
        return np.full((hp, wp, 3), 1.0 if i == len(planes) else 0.0, np.float32)

    return Patterns(render, names, (hp, wp))


def _xor_base(nbits: int) -> int | None:
    """Index (most significant first) of the bit the ``"xor"`` code XORs the higher bits with.

    The second least significant: stripes 4 projector pixels wide, wider than the least
    significant bit's 2 so defocus blurs them less (Gupta et al.'s XOR-04). None for an axis
    of fewer than 3 bits, whose patterns are high-frequency already.
    """
    return nbits - 2 if nbits >= 3 else None


def _check_code(code) -> None:
    if code not in GRAY_CODES:
        raise InputError(f"code must be one of {', '.join(map(repr, GRAY_CODES))}, got {code!r}")


@dataclass(frozen=True, eq=False)
class Correspondence:
    """The projector pixel seen by every camera pixel.

    Attributes
    ----------
    x, y : (H, W) int32
        Projector column and row per camera pixel; −1 where ``status`` is not DECODED.
    status : (H, W) uint8
        :class:`PixelStatus` code per camera pixel.
    projector_resolution : (Hp, Wp)
        The projector the codes refer to.
    """

    x: np.ndarray
    y: np.ndarray
    status: np.ndarray
    projector_resolution: tuple[int, int]

    def __post_init__(self) -> None:
        res = check_resolution("projector_resolution", self.projector_resolution)
        object.__setattr__(self, "projector_resolution", res)
        x, y, s = (np.asarray(a) for a in (self.x, self.y, self.status))
        if x.ndim != 2 or x.shape != y.shape or x.shape != s.shape:
            raise InputError(
                f"x, y and status must be (H, W) arrays of one shape, got {x.shape}, {y.shape}, {s.shape}"
            )
        if x.dtype.kind not in "iu" or y.dtype.kind not in "iu" or s.dtype.kind not in "iu":
            raise InputError(f"x, y and status must be integer arrays, got {x.dtype}, {y.dtype}, {s.dtype}")
        if s.size and (s.min() < 0 or s.max() > max(PixelStatus)):
            top = int(max(PixelStatus))
            raise InputError(f"status must hold PixelStatus codes 0..{top}, got {s.min()}..{s.max()}")
        ok = s == PixelStatus.DECODED
        hp, wp = res
        if np.any(ok & ((x < 0) | (x >= wp) | (y < 0) | (y >= hp))):
            raise InputError(f"decoded x, y must lie inside the {wh(res)} projector")
        x = np.where(ok, x, -1).astype(np.int32)
        y = np.where(ok, y, -1).astype(np.int32)
        for name, a in (("x", x), ("y", y), ("status", s.astype(np.uint8))):
            a.flags.writeable = False
            object.__setattr__(self, name, a)

    @classmethod
    def _trusted(cls, x, y, status, projector_resolution) -> Correspondence:
        """Wrap arrays already known to be consistent (−1 where undecoded), without copies."""
        self = object.__new__(cls)
        for name, a in (("x", x), ("y", y), ("status", status)):
            a.flags.writeable = False
            object.__setattr__(self, name, a)
        object.__setattr__(self, "projector_resolution", tuple(projector_resolution))
        return self

    @classmethod
    def from_maps(cls, x, y, valid, projector_resolution) -> Correspondence:
        """Build a correspondence from integer maps and a validity mask (invalid = UNLIT).

        Examples
        --------
        >>> c = Correspondence.from_maps(np.array([[0, 1]]), np.array([[0, 0]]), np.array([[True, False]]), (1, 2))
        >>> c.x.tolist(), c.valid.tolist()
        ([[0, -1]], [[True, False]])
        """
        valid = np.asarray(valid)
        if valid.dtype != np.bool_:
            raise InputError(f"valid must be a boolean mask, got dtype {valid.dtype}")
        status = np.where(valid, PixelStatus.DECODED, PixelStatus.UNLIT).astype(np.uint8)
        return cls(np.asarray(x), np.asarray(y), status, projector_resolution)

    @classmethod
    def identity(cls, camera_resolution) -> Correspondence:
        """The co-axial rig of the paper's simulations: camera pixel (u, v) sees projector (u, v).

        Examples
        --------
        >>> Correspondence.identity((2, 3)).x.tolist()
        [[0, 1, 2], [0, 1, 2]]
        """
        h, w = check_resolution("camera_resolution", camera_resolution)
        y, x = np.indices((h, w), dtype=np.int32)
        return cls(x, y, np.zeros((h, w), np.uint8), (h, w))

    @property
    def camera_resolution(self) -> tuple[int, int]:
        """``(H, W)`` of the camera."""
        return self.x.shape

    @property
    def valid(self) -> np.ndarray:
        """(H, W) bool: camera pixels with a projector pixel."""
        return self.status == PixelStatus.DECODED

    def missing(self, target=None) -> np.ndarray:
        """(H, W) bool: camera pixels (of ``target`` if given) without a projector pixel.

        The projector cannot light these pixels, so light cannot be re-emitted onto them.
        """
        miss = ~self.valid
        if target is not None:
            from engine.checks import check_mask

            miss &= check_mask("target", target, self.camera_resolution)
        return miss

    def counts(self, target=None) -> dict[str, int]:
        """Number of camera pixels (of ``target`` if given) per :class:`PixelStatus` name."""
        s = self.status
        if target is not None:
            from engine.checks import check_mask

            s = s[check_mask("target", target, self.camera_resolution)]
        n = np.bincount(s.ravel(), minlength=len(PixelStatus))
        return {p.name.lower(): int(n[p]) for p in PixelStatus}

    def summary(self, target=None) -> str:
        """Plain-words account of undecoded camera pixels (of ``target`` if given).

        Examples
        --------
        >>> Correspondence.identity((2, 2)).summary()
        'all 4 camera pixels decoded'
        """
        c = self.counts(target)
        total = sum(c.values())
        where = "target pixels" if target is not None else "camera pixels"
        bad = total - c["decoded"]
        if bad == 0:
            return f"all {total} {where} decoded"
        parts = [
            f"{c['unlit']} unlit (projector shadow or no surface)" if c["unlit"] else "",
            f"{c['low_contrast']} low contrast" if c["low_contrast"] else "",
            f"{c['out_of_range']} outside the projector's range" if c["out_of_range"] else "",
        ]
        share = 100 * bad / max(total, 1)
        return f"{bad} of {total} {where} ({share:.1f}%) undecoded: " + ", ".join(p for p in parts if p)


def _as_grey(name: str, image, shape=None) -> np.ndarray:
    a = np.asarray(image)
    if a.dtype.kind not in "uif":
        raise InputError(f"{name} must be a numeric image, got dtype {a.dtype}")
    if a.ndim == 3 and a.shape[-1] == 3:
        a = a.mean(axis=-1, dtype=np.float32)
    elif a.ndim != 2:
        raise InputError(f"{name} must be grey (H, W) or RGB (H, W, 3), got shape {a.shape}")
    if shape is not None and a.shape != shape:
        raise InputError(
            f"{name} has shape {a.shape[:2]}, but the first pattern capture has {shape}: all captures must match"
        )
    return a


def decode_gray_code(
    images,
    projector_resolution,
    *,
    white=None,
    black=None,
    threshold: float | None = None,
    shadow_threshold: float | None = None,
    code: str = "xor",
) -> Correspondence:
    """Decode Gray-code captures into the projector pixel seen by every camera pixel.

    Parameters
    ----------
    images : sequence of (H, W) or (H, W, 3) images, uint8, uint16 or float
        The captures of :func:`gray_code_patterns`, in OpenCV's order: ``2 · bits`` pattern
        images, optionally followed by the white and black captures (``2 · bits + 2``). RGB
        captures are averaged over channels. A stacked array ``(N, H, W[, 3])`` is accepted.
    projector_resolution : (Hp, Wp)
        The projector that showed the patterns.
    white, black : image, optional
        Captures of the all-white and all-black frames (or the last two ``images``). When
        given, pixels with ``white − black ≤ shadow_threshold`` are UNLIT.
    threshold : float, optional
        A bit is trusted when ``|pattern − inverse| ≥ threshold`` (OpenCV's whiteThreshold),
        in image units. Float captures with white and black, by default: per pixel,
        ``max(0.002 × full scale, 0.1 × the pixel's largest pair difference)`` — contrast is
        judged against the pixel's own direct projector light, so dim grazing surfaces decode
        and global light does not count; unlit below
        ``0.005 ×`` full scale. Otherwise: 5 for uint8 (OpenCV's default), 5·257 for uint16, and for
        float ``0.02 ×`` the projector's full scale: the 99.9th percentile of ``white − black``
        (or of the first pattern pair's difference), so that a lamp or a bright ambient-lit
        area in view does not set the scale.
    shadow_threshold : float, optional
        Default: 40 for uint8 (OpenCV's blackThreshold), 40·257 for uint16, ``0.02 ×`` full
        scale for float (40/255 of a gamma-encoded 8-bit image is ~2 % in linear light).
    code : {"xor", "gray"}
        The code :func:`gray_code_patterns` showed.

    Returns
    -------
    Correspondence
        ``x``, ``y`` int32 (H, W) projector column and row (−1 where undecoded) and a
        per-pixel :class:`PixelStatus`; ``.valid`` is the mask of decoded pixels.

    Raises
    ------
    InputError
        Wrong number of images for the projector, mismatched shapes, bad dtypes.

    Notes
    -----
    Same rule as ``cv2.structured_light.GrayCodePattern.getProjPixel`` per pixel: bit = pattern
    > inverse; invalid if any pair differs by less than ``threshold``; Gray → binary by a
    cumulative XOR, most significant bit first; invalid if ``x ≥ Wp`` or ``y ≥ Hp``. OpenCV
    ignores shadow masks; this function applies one when white and black are given. Unlike
    ``getProjPixel`` it reads uint16 and float captures correctly, and costs one pass of a few
    array operations per bit instead of a Python call per pixel. The ``"xor"`` code XORs each
    bit above the base (:func:`_xor_base`) with the base bit before the Gray → binary step.

    Examples
    --------
    >>> seq = gray_code_patterns((4, 8))
    >>> caps = [(p[..., 0] * 200 + 20).astype(np.uint8) for p in seq]  # a co-axial camera
    >>> c = decode_gray_code(caps, (4, 8))
    >>> c.x[0].tolist(), c.y[:, 0].tolist(), c.summary()
    ([0, 1, 2, 3, 4, 5, 6, 7], [0, 1, 2, 3], 'all 32 camera pixels decoded')
    """
    hp, wp = check_resolution("projector_resolution", projector_resolution)
    _check_code(code)
    ncol, nrow = gray_code_bits((hp, wp))
    npat = 2 * (ncol + nrow)
    if isinstance(images, np.ndarray):
        images = list(images) if images.ndim >= 3 else [images]
    else:
        try:
            images = list(images)
        except TypeError:
            raise InputError(f"images must be a sequence of captures, got {type(images).__name__}") from None
    if len(images) == npat + 2:
        if white is not None or black is not None:
            raise InputError(
                f"images holds {npat + 2} captures (patterns + white + black) and white/black were given too; "
                f"pass either {npat} pattern captures with white= and black=, or all {npat + 2}"
            )
        images, white, black = images[:npat], images[npat], images[npat + 1]
    elif len(images) != npat:
        raise InputError(
            f"images: expected {npat} images for a {wh((hp, wp))} projector ({npat // 2} pattern pairs: "
            f"{ncol} column and {nrow} row bits), or {npat + 2} with the white and black captures last; "
            f"got {len(images)}"
        )
    if (white is None) != (black is None):
        raise InputError("white and black must be given together (the shadow mask needs both), got only one")

    first = np.asarray(images[0])
    dtypes = {np.asarray(im).dtype for im in images}
    if len(dtypes) > 1:
        raise InputError(f"images must share one dtype, got {sorted(map(str, dtypes))}")
    kind = first.dtype
    grey = [_as_grey(f"images[{i}]", im) for i, im in enumerate(images[:1])]
    shape = grey[0].shape
    grey += [_as_grey(f"images[{i}]", im, shape) for i, im in enumerate(images[1:], start=1)]
    if kind.kind == "f" and not all(np.all(np.isfinite(g)) for g in grey):
        raise InputError("images contain NaN or inf; expected finite captures")
    wb = None
    if white is not None:
        wb = (_as_grey("white", white, shape), _as_grey("black", black, shape))

    # Defaults follow OpenCV for integer captures and a fraction of full scale for float ones.
    t_def: float
    s_def: float
    if kind == np.uint8:
        scale, t_def, s_def = 1.0, UINT8_THRESHOLD, UINT8_SHADOW_THRESHOLD
    elif kind == np.uint16:
        scale, t_def, s_def = 257.0, UINT8_THRESHOLD, UINT8_SHADOW_THRESHOLD
    else:
        # the projector's own contribution: a lamp in view must not set the scale
        ref = (wb[0] - wb[1]) if wb is not None else np.abs(grey[0] - grey[1])
        scale = float(np.percentile(ref, 99.9)) if ref.size else 0.0
        t_def, s_def = FLOAT_THRESHOLD, FLOAT_SHADOW_THRESHOLD
        if wb is not None:
            t_def, s_def = FLOAT_FLOOR, FLOAT_SHADOW_FLOOR
    thr: float | np.ndarray = t_def * scale if threshold is None else float(threshold)
    sthr = s_def * scale if shadow_threshold is None else float(shadow_threshold)
    if not np.isfinite(thr) or thr < 0:
        raise InputError(f"threshold must be a finite number ≥ 0 in image units, got {threshold!r}")
    if not np.isfinite(sthr):
        raise InputError(f"shadow_threshold must be a finite number in image units, got {shadow_threshold!r}")

    relative = threshold is None and kind.kind == "f" and wb is not None
    if relative or code == "xor":
        best = np.zeros(shape, np.float64 if grey[0].dtype == np.float64 else np.float32)
        for k in range(npat // 2):
            np.maximum(best, np.abs(np.subtract(grey[2 * k], grey[2 * k + 1], dtype=best.dtype)), out=best)
    if relative:
        thr = np.maximum(thr, FLOAT_RELATIVE_THRESHOLD * best).astype(grey[0].dtype)
    ok = np.ones(shape, np.bool_)
    bit = np.empty(shape, np.bool_)
    base_bit = np.empty(shape, np.bool_)
    binary = np.empty(shape, np.bool_)
    coords = []
    for first_bit, nbits in ((0, ncol), (ncol, nrow)):
        value = np.zeros(shape, np.uint16 if nbits <= 16 else np.uint32)
        binary[...] = False
        base = _xor_base(nbits) if code == "xor" else None
        if base is not None:  # a wrong base bit flips every bit above it: ask more of its contrast
            kb = first_bit + base
            _pair(grey[2 * kb], grey[2 * kb + 1], np.maximum(thr, XOR_BASE_RELATIVE_THRESHOLD * best), base_bit, ok)
        for k in range(first_bit, first_bit + nbits):
            if base is not None and k == first_bit + base:
                bit[...] = base_bit  # read above, with its stricter threshold
            else:
                _pair(grey[2 * k], grey[2 * k + 1], thr, bit, ok)
            if base is not None and k < first_bit + base:
                np.logical_xor(bit, base_bit, out=bit)  # the shown pattern was the bit XOR the base
            np.logical_xor(binary, bit, out=binary)  # Gray → binary, most significant bit first
            np.add(value, value, out=value)  # value <<= 1
            np.bitwise_or(value, binary, out=value)
        coords.append(value)
    x, y = coords

    # Branch-free status and masking (boolean indexing is slow on ragged masks).
    in_range = (x < wp) & (y < hp)
    status = np.multiply(~ok, np.uint8(PixelStatus.LOW_CONTRAST), dtype=np.uint8)
    status += np.multiply(ok & ~in_range, np.uint8(PixelStatus.OUT_OF_RANGE), dtype=np.uint8)
    if wb is not None:
        lit = np.subtract(wb[0], wb[1], dtype=np.float64 if wb[0].dtype.itemsize > 4 else np.float32) > sthr
        status *= lit
        status += np.multiply(~lit, np.uint8(PixelStatus.UNLIT), dtype=np.uint8)
    good = (status == 0).view(np.uint8)
    x = x.astype(np.int32)
    y = y.astype(np.int32)
    for a in (x, y):  # a ← a where good else −1
        a += 1
        a *= good
        a -= 1
    return Correspondence._trusted(x, y, status, (hp, wp))


def _pair(pos: np.ndarray, neg: np.ndarray, thr, bit: np.ndarray, ok: np.ndarray) -> None:
    """bit ← pos > neg; ok &= |pos − neg| ≥ thr, thr a scalar or per pixel (in place; exact for integer captures)."""
    if pos.dtype.kind in "ui" and pos.dtype.itemsize == 1:
        diff = np.subtract(pos, neg, dtype=np.int16)
    elif pos.dtype == np.float64 or (pos.dtype.kind in "ui" and pos.dtype.itemsize > 2):
        diff = np.subtract(pos, neg, dtype=np.float64)
    else:
        diff = np.subtract(pos, neg, dtype=np.float32)
    np.greater(diff, 0, out=bit)
    np.abs(diff, out=diff)
    ok &= diff >= thr


def fill_correspondence(
    correspondence: Correspondence, target, *, radius: int = 4, tolerance: float = 2.0, passes: int = 3
) -> tuple[Correspondence, np.ndarray]:
    """Repair a target's correspondences: drop outliers, fill holes from local plane fits.

    Gray code fails where interreflections cancel or flip a bit (concave corners) or at
    grazing angles, yet on a smooth surface the projector position is a smooth function of the
    camera position. First, each decoded target pixel is compared with the least-squares plane
    ``x = a + b u + c v`` (and ``y``) through its decoded target neighbours within ``radius``,
    itself left out; one further than ``tolerance`` projector pixels is a wrong decode. Then
    each undecoded or rejected target pixel with at least six good neighbours gets the rounded
    value of their plane at its position.

    Parameters
    ----------
    correspondence : Correspondence
    target : (H, W) bool
        Only pixels of the target are checked and filled, only from pixels of the target.
    radius : int
        Half-size of the square neighbourhood, in camera pixels.
    tolerance : float
        Largest accepted distance, in projector pixels, between a decoded position and its
        neighbours' plane.
    passes : int
        Filled pixels count as neighbours in the next pass: a hole wider than the window fills
        from its rim inwards (under a posed projector most camera pixels straddle two projector
        pixels, and those split near half and half do not decode: whole patches of them).

    Returns
    -------
    filled : Correspondence
        Repaired pixels are marked DECODED; rejected ones that could not be filled, LOW_CONTRAST.
    mask : (H, W) bool
        The pixels whose projector position was interpolated.

    Examples
    --------
    >>> c = Correspondence.identity((5, 5))
    >>> status = c.status.copy()
    >>> status[2, 2] = PixelStatus.LOW_CONTRAST
    >>> x = c.x.copy()
    >>> x[1, 1] = 4  # a wrong decode
    >>> f, m = fill_correspondence(Correspondence(x, c.y, status, (5, 5)), np.ones((5, 5), bool))
    >>> int(f.x[2, 2]), int(f.x[1, 1]), int(m.sum())
    (2, 1, 2)
    """
    target = np.asarray(target, bool)
    if target.shape != correspondence.camera_resolution:
        raise InputError(f"target must have shape {correspondence.camera_resolution}, got {target.shape}")
    good = correspondence.valid & target
    if not good.any():
        return correspondence, np.zeros_like(target)
    x = correspondence.x.astype(np.float64)
    y = correspondence.y.astype(np.float64)
    px, py, ok = _plane_fit(good, (x, y), radius, leave_one_out=True)
    outlier = good & ok & (np.hypot(px - x, py - y) > tolerance)
    good &= ~outlier
    hp, wp = correspondence.projector_resolution
    fill = np.zeros_like(target)
    out_x, out_y = correspondence.x.astype(np.int32), correspondence.y.astype(np.int32)
    for _ in range(int(passes)):  # a wide hole fills from its rim inwards
        px, py, ok = _plane_fit(good, (x, y), radius, leave_one_out=False)
        fx, fy = np.rint(px), np.rint(py)
        new = target & ~good & ok & (fx >= 0) & (fx < wp) & (fy >= 0) & (fy < hp)
        if not new.any():
            break
        out_x = np.where(new, fx, out_x).astype(np.int32)
        out_y = np.where(new, fy, out_y).astype(np.int32)
        x, y = np.where(new, fx, x), np.where(new, fy, y)
        fill |= new
        good |= new
    status = correspondence.status.copy()
    status[outlier] = PixelStatus.LOW_CONTRAST
    status[fill] = PixelStatus.DECODED
    decoded = status == PixelStatus.DECODED
    out_x[~decoded] = -1
    out_y[~decoded] = -1
    return Correspondence(out_x, out_y, status, correspondence.projector_resolution), fill


def _plane_fit(good: np.ndarray, values, radius: int, *, leave_one_out: bool):
    """Per pixel, the local least-squares plane through ``values`` at ``good`` neighbours.

    Returns the planes' values at each pixel and where the fit is determined (at least six
    neighbours, not collinear).
    """
    import cv2

    h, w = good.shape
    v, u = np.indices((h, w), dtype=np.float64)
    wgt = good.astype(np.float64)
    k = (2 * radius + 1, 2 * radius + 1)

    def box(a):
        total = cv2.boxFilter(a, -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT)
        return total - a if leave_one_out else total

    # coordinates relative to each pixel keep the normal equations well conditioned
    s1, su, sv = box(wgt), box(wgt * u), box(wgt * v)
    suu, suv, svv = box(wgt * u * u), box(wgt * u * v), box(wgt * v * v)
    ata = np.stack([np.stack([s1, su, sv], -1), np.stack([su, suu, suv], -1), np.stack([sv, suv, svv], -1)], -2)
    det = np.linalg.det(ata)
    ok = (s1 >= 6) & (np.abs(det) > 1e-9 * np.maximum(s1, 1) ** 3)
    safe = np.where(ok[..., None, None], ata, np.eye(3))
    pos = np.stack([np.ones((h, w)), u, v], -1)
    out = []
    for val in values:
        val = np.where(good, val, 0.0)
        rhs = np.stack([box(wgt * val), box(wgt * val * u), box(wgt * val * v)], -1)
        coef = np.linalg.solve(safe, rhs[..., None])[..., 0]
        out.append((coef * pos).sum(-1))
    return out[0], out[1], ok


def _gray_code_pattern(wp: int, hp: int):
    """OpenCV's Gray-code generator, or a plain error when the contrib build was replaced."""
    structured_light = getattr(cv2, "structured_light", None)
    if structured_light is None or not hasattr(structured_light, "GrayCodePattern"):
        raise AlbeditError(
            f"OpenCV {cv2.__version__} has no structured_light module: another package replaced the contrib "
            "build; run `pip uninstall -y opencv-python opencv-python-headless` and "
            "`pip install --force-reinstall --no-deps opencv-contrib-python-headless`"
        )
    return structured_light.GrayCodePattern.create(wp, hp)
