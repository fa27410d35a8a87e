"""Projector response: flat grey ramps → a monotonic per-channel curve and its inverse LUT.

A projector emits ``L(p) = L_min + (L_max − L_min) · f(p)`` for input ``p`` in [0, 1]; ``f`` is
its response (gamma, DLP steps) with ``f(0) = 0`` and ``f(1) = 1``, and ``b = L_min / L_max`` its
black level (light at input 0 relative to full). The paper assumes a radiometrically calibrated
projector and measures its gamma curve by emitting each level (Sec. 3.3 and 6).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np
from scipy.interpolate import PchipInterpolator

from engine.calibrate._common import Patterns
from engine.checks import check_choice, check_fraction, check_image, check_images, check_mask, check_resolution
from engine.errors import InputError

__all__ = ["ProjectorResponse", "RampChannels", "fit_response", "ramp_levels", "response_patterns"]

#: Size of the fine tables that :meth:`ProjectorResponse.forward` and ``linearize`` interpolate.
FINE_GRID = 4096


class RampChannels(StrEnum):
    """How the ramp is shown: all channels together (grey) or one projector channel at a time."""

    TOGETHER = "together"
    SEPARATE = "separate"


def ramp_levels(count: int = 17, *, bit_depth: int = 8) -> np.ndarray:
    """Return ``count`` increasing projector inputs from 0 to 1 on the projector's code grid.

    Parameters
    ----------
    count : int
        Number of levels (≥ 3).
    bit_depth : int
        Projector input bits; levels are multiples of ``1 / (2**bit_depth − 1)`` so the
        projector shows exactly the level the fit assumes.

    Returns
    -------
    (count,) float64

    Examples
    --------
    >>> (ramp_levels(5) * 255).round().astype(int).tolist()
    [0, 64, 128, 191, 255]
    """
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 3:
        raise InputError(f"count must be an integer ≥ 3 (levels from black to white), got {count!r}")
    if isinstance(bit_depth, bool) or not isinstance(bit_depth, (int, np.integer)) or not 1 <= bit_depth <= 16:
        raise InputError(f"bit_depth must be an integer in 1..16, got {bit_depth!r}")
    top = 2**bit_depth - 1
    codes = np.unique(np.round(np.linspace(0, top, count)))
    if codes.size != count:
        raise InputError(f"count={count} levels do not fit in {bit_depth}-bit inputs ({top + 1} codes)")
    return codes / top


def _check_levels(levels) -> np.ndarray:
    lv = np.asarray(levels, dtype=np.float64)
    if lv.ndim != 1 or lv.size < 3:
        raise InputError(f"levels must be a 1-D list of at least 3 projector inputs, got shape {lv.shape}")
    if not np.all(np.isfinite(lv)) or lv[0] != 0 or lv[-1] != 1 or np.any(np.diff(lv) <= 0):
        raise InputError(
            f"levels must increase strictly from exactly 0 (black) to exactly 1 (white), got {np.round(lv, 4).tolist()}"
        )
    return lv


def response_patterns(levels, projector_resolution, *, channels: str = "together") -> Patterns:
    """Return the flat projector images of a response ramp.

    Parameters
    ----------
    levels : (N,) float
        Projector inputs, strictly increasing from 0 to 1 (see :func:`ramp_levels`).
    projector_resolution : (Hp, Wp)
        Projector height and width in pixels.
    channels : {"together", "separate"}
        ``"together"``: N grey images, every channel at the level. ``"separate"``: 3·N
        images, channel-major (all levels of red, then green, then blue), the other channels
        black; immune to colour crosstalk at three times the captures (the paper's choice,
        Sec. 6).

    Returns
    -------
    Patterns
        Lazy sequence of float32 ``(Hp, Wp, 3)`` images. Show them WITHOUT linearisation.

    Examples
    --------
    >>> seq = response_patterns([0, 0.5, 1], (2, 3), channels="separate")
    >>> len(seq), seq.names[4], seq[4][0, 0].tolist()
    (9, 'ramp green 0.5000', [0.0, 0.5, 0.0])
    """
    lv = _check_levels(levels)
    hp, wp = check_resolution("projector_resolution", projector_resolution)
    mode = RampChannels(check_choice("channels", channels, RampChannels))
    if mode is RampChannels.TOGETHER:
        names = [f"ramp grey {v:.4f}" for v in lv]
        recipe: list[tuple[float, int | None]] = [(v, None) for v in lv]
    else:
        names = [f"ramp {c} {v:.4f}" for c in ("red", "green", "blue") for v in lv]
        recipe = [(v, c) for c in range(3) for v in lv]

    def render(i: int) -> np.ndarray:
        v, c = recipe[i]
        img = np.zeros((hp, wp, 3), np.float32)
        if c is None:
            img[...] = v
        else:
            img[..., c] = v
        return img

    return Patterns(render, names, (hp, wp))


@dataclass(frozen=True, eq=False)
class ProjectorResponse:
    """A projector's measured response, forced monotonic, with a fine inverse table.

    Attributes
    ----------
    levels : (N,) float64
        Projector inputs of the measured table, 0 … 1.
    table : (N, 3) float64
        Per-channel response ``f`` at ``levels``: light above black relative to full, non-
        decreasing, ``f(0) = 0``, ``f(1) = 1``.
    black_level : (3,) float64
        ``b`` per camera channel: light with the projector all black relative to all white,
        ambient excluded when :func:`fit_response` was given an ambient capture (a projector
        cannot switch itself off, so :func:`engine.acquire.calibrate_rig` has none: its ``b``
        includes the room's light). This is the ``b`` of :func:`engine.calibrate.direct_image`;
        acquisition never needs it (every capture has the projector-black base removed).
    raw_table : (N, 3) float64
        The table as measured, before monotonic fitting (for plots and reports).

    Notes
    -----
    ``forward`` interpolates the table with a monotone cubic (PCHIP) sampled on a
    :data:`FINE_GRID`-point grid; ``linearize`` interpolates that fine table backwards, so
    the inverse is on a grid far finer than the measured levels.
    """

    levels: np.ndarray
    table: np.ndarray
    black_level: np.ndarray
    raw_table: np.ndarray | None = None
    _fine_inputs: np.ndarray = field(init=False, repr=False)
    _fine_light: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        lv = _check_levels(self.levels)
        t = np.asarray(self.table, dtype=np.float64)
        if t.shape != (lv.size, 3):
            raise InputError(f"table must have shape {(lv.size, 3)} (levels × channels), got {t.shape}")
        if not np.all(np.isfinite(t)) or np.any(np.diff(t, axis=0) < 0):
            raise InputError("table must be finite and non-decreasing down each channel")
        if not (np.allclose(t[0], 0) and np.allclose(t[-1], 1)):
            raise InputError(f"table must go from 0 at input 0 to 1 at input 1, got {t[0].tolist()} … {t[-1].tolist()}")
        b = check_fraction("black_level", self.black_level)
        raw = None if self.raw_table is None else np.asarray(self.raw_table, dtype=np.float64).copy()
        if raw is not None and raw.shape != t.shape:
            raise InputError(f"raw_table must have shape {t.shape}, got {raw.shape}")
        p = np.linspace(0.0, 1.0, FINE_GRID)
        light = np.empty((FINE_GRID, 3))
        for c in range(3):
            light[:, c] = np.clip(PchipInterpolator(lv, t[:, c])(p), 0.0, 1.0)
            # A strictly increasing table so the inverse is a function (flat DLP steps tie).
            light[:, c] = np.maximum.accumulate(light[:, c]) + p * 1e-9
            light[:, c] /= light[-1, c]
        for name, a in (("levels", lv.copy()), ("table", t.copy()), ("black_level", b), ("raw_table", raw)):
            if a is not None:
                a.flags.writeable = False
            object.__setattr__(self, name, a)
        object.__setattr__(self, "_fine_inputs", p)
        object.__setattr__(self, "_fine_light", light)

    @classmethod
    def linear(cls, *, black_level=0.0) -> ProjectorResponse:
        """An ideal linear projector (``f(p) = p``), e.g. the virtual rig with ``ideal=True``.

        Examples
        --------
        >>> ProjectorResponse.linear().linearize([0.25, 0.5, 1.0]).tolist()
        [0.25, 0.5, 1.0]
        """
        lv = np.linspace(0, 1, 3)
        return cls(lv, np.repeat(lv[:, None], 3, axis=1), np.broadcast_to(np.asarray(black_level, float), (3,)))

    def forward(self, inputs) -> np.ndarray:
        """Light above black, relative to full, emitted for projector ``inputs``.

        Parameters
        ----------
        inputs : (..., 3) float in [0, 1]
            Projector inputs per channel.

        Returns
        -------
        (..., 3) float32
            ``f(inputs)``; the emitted light relative to full white is ``b + (1 − b) f``.

        Examples
        --------
        >>> r = ProjectorResponse(np.linspace(0, 1, 33), np.repeat((np.linspace(0, 1, 33) ** 2.2)[:, None], 3, 1), 0.0)
        >>> r.forward([0.5, 0.5, 0.5]).astype(float).round(3).tolist()
        [0.218, 0.218, 0.218]
        """
        return self._interp("inputs", inputs, self._fine_inputs, self._fine_light)

    def linearize(self, values) -> np.ndarray:
        """Projector inputs that emit ``values`` (light above black, relative to full).

        Parameters
        ----------
        values : (..., 3) float in [0, 1]
            Desired linear light per channel; ``forward(linearize(v)) ≈ v``.

        Returns
        -------
        (..., 3) float32
            Projector inputs in [0, 1], to pass to ``Projector.show``.

        Raises
        ------
        InputError
            Values outside [0, 1] (the projector cannot emit them; scale first, Sec. 6).

        Examples
        --------
        >>> r = ProjectorResponse(np.linspace(0, 1, 33), np.repeat((np.linspace(0, 1, 33) ** 2.2)[:, None], 3, 1), 0.0)
        >>> r.linearize([0.218, 0.5, 1.0]).astype(float).round(3).tolist()
        [0.5, 0.73, 1.0]
        """
        return self._interp("values", values, self._fine_light, self._fine_inputs)

    def relative_light(self, inputs) -> np.ndarray:
        """Emitted light relative to full white, black level included: ``b + (1 − b) f``."""
        f = self.forward(inputs)
        b = self.black_level.astype(np.float32)
        return b + (1 - b) * f

    @staticmethod
    def _interp(name: str, a, xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
        arr = np.asarray(a, dtype=np.float32)
        if arr.ndim == 0 or arr.shape[-1] != 3:
            raise InputError(f"{name} must have a last axis of 3 channels, got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise InputError(f"{name} contains NaN or inf")
        lo, hi = arr.min(initial=0.0), arr.max(initial=0.0)
        if lo < 0 or hi > 1:
            n = int(np.count_nonzero((arr < 0) | (arr > 1)))
            raise InputError(
                f"{name} must lie in [0, 1] (fractions of full projector light), got {n} values in "
                f"[{lo:.4g}, {hi:.4g}]; scale the image first (paper Sec. 6: τ / max)"
            )
        out = np.empty(arr.shape, np.float32)
        for c in range(3):
            out[..., c] = np.interp(arr[..., c], xp[:, c] if xp.ndim == 2 else xp, fp[:, c] if fp.ndim == 2 else fp)
        return out

    def to_dict(self) -> dict:
        """JSON-ready description (small: the measured table, not the fine LUTs)."""
        d = {
            "levels": self.levels.tolist(),
            "table": self.table.tolist(),
            "black_level": self.black_level.tolist(),
        }
        if self.raw_table is not None:
            d["raw_table"] = self.raw_table.tolist()
        return d

    @classmethod
    def from_dict(cls, d: dict) -> ProjectorResponse:
        """Inverse of :meth:`to_dict`; validates everything."""
        try:
            return cls(np.asarray(d["levels"], float), np.asarray(d["table"], float),
                       np.asarray(d["black_level"], float), d.get("raw_table"))
        except (KeyError, TypeError, ValueError) as e:
            if isinstance(e, InputError):
                raise
            raise InputError(f"response: not a valid projector response description ({e!r})") from None


def fit_response(
    captures,
    levels,
    *,
    channels: str = "together",
    ambient=None,
    mask=None,
    min_contrast: float = 0.01,
    tolerance: float = 0.05,
) -> ProjectorResponse:
    """Fit the projector response from captures of :func:`response_patterns`.

    Parameters
    ----------
    captures : (M, H, W, 3) float or a sequence of M (H, W, 3) float, linear radiance
        One capture per pattern, in pattern order (M = N, or 3·N for ``"separate"``). A list
        is reduced one capture at a time, never stacked.
    levels : (N,) float
        The levels the patterns were made with.
    channels : {"together", "separate"}
        As given to :func:`response_patterns`.
    ambient : (H, W, 3) float, optional
        A capture with the projector switched off or its lens covered. Needed to measure the
        black level ``b`` when the room is not dark; None means no light but the projector's.
    mask : (H, W) bool, optional
        Camera pixels to use: lit by the projector, diffuse, never saturated. Default: all.
    min_contrast : float
        Smallest accepted ``(white − black) / white`` over the mask; below it the projector
        is taken to be invisible.
    tolerance : float
        Largest accepted drop of the measured curve between consecutive levels (fraction of
        full); smaller noise dips are removed by the monotonic fit.

    Returns
    -------
    ProjectorResponse

    Raises
    ------
    InputError
        Wrong counts or shapes; the camera saw no change between black and white; the curve is
        not monotonic beyond noise (captures out of order, projector not settled).

    Notes
    -----
    Per channel, ``f(p) = Σ (I_p − I_0) / Σ (I_1 − I_0)`` over the mask (a ratio of sums, so
    pixels weigh by their signal and per-pixel albedo and falloff cancel), then a weighted
    pool-adjacent-violators fit makes it non-decreasing. ``b = Σ (I_0 − A) / Σ (I_1 − A)``
    per camera channel, with ``A`` the ambient capture (in ``"separate"`` mode ``I_1`` is
    the all-black capture plus the three primaries' increments, by linearity). In
    ``"separate"`` mode the curve of projector channel c sums all camera channels, so colour
    crosstalk cannot bend it.

    Examples
    --------
    >>> lv = ramp_levels(9)
    >>> caps = np.stack([np.full((4, 4, 3), 0.02 + 0.98 * v ** 2.2, np.float32) for v in lv])
    >>> r = fit_response(caps, lv)
    >>> np.round(r.black_level, 3).tolist(), round(float(r.forward([[0.5] * 3])[0, 0]), 3)
    ([0.02, 0.02, 0.02], 0.218)
    """
    lv = _check_levels(levels)
    mode = RampChannels(check_choice("channels", channels, RampChannels))
    caps = check_images("captures", captures)
    n = lv.size
    expected = n if mode is RampChannels.TOGETHER else 3 * n
    if len(caps) != expected:
        raise InputError(
            f"captures: expected {expected} captures for {n} levels with channels={mode.value!r}, got {len(caps)}"
        )
    h, w = caps[0].shape[:2]
    sel = np.ones((h, w), bool) if mask is None else check_mask("mask", mask, (h, w))
    if not sel.any():
        raise InputError("mask selects no camera pixels; expected the projector-lit part of the scene")
    ref = np.zeros(3)
    if ambient is not None:
        ref = check_image("ambient", ambient, caps[0].shape)[sel].sum(axis=0, dtype=np.float64)
    npix = int(sel.sum())
    # Sums over the mask, (M, 3) in float64: no float32 accumulation error over megapixels.
    sums = np.stack([c[sel].sum(axis=0, dtype=np.float64) for c in caps])
    if mode is RampChannels.TOGETHER:
        curve = sums  # (N, 3): projector channel c seen in camera channel c
        black_cam, white_cam = sums[0], sums[-1]
    else:
        per = sums.reshape(3, n, 3)  # projector channel, level, camera channel
        curve = per.sum(axis=2).T  # (N, 3 projector channels): every camera channel counts
        black_cam = per[:, 0, :].mean(axis=0)  # the three all-black captures
        white_cam = black_cam + (per[:, -1, :] - per[:, 0, :]).sum(axis=0)  # linearity: R + G + B
    names = ("red", "green", "blue")
    for c in range(3):
        lo, hi = curve[0, c], curve[-1, c]
        if hi < lo:
            raise InputError(
                f"captures: the {names[c]} channel got darker from projector black to white "
                f"({hi / npix:.4g} < {lo / npix:.4g} per pixel): are the captures in pattern order?"
            )
        contrast = (hi - lo) / max(abs(hi), 1e-300)
        if contrast < min_contrast:
            raise InputError(
                f"captures: the camera saw no change between projector black and white in the {names[c]} channel "
                f"(white − black = {100 * contrast:.2f}% of white over {npix} pixels): is the projector on and "
                "pointed at the scene, the lens uncovered, and the mask on lit pixels?"
            )
    raw = (curve - curve[0]) / (curve[-1] - curve[0])
    drops = raw[:-1] - raw[1:]
    k, c = map(int, np.unravel_index(np.argmax(drops), drops.shape))
    if drops[k, c] > tolerance:
        raise InputError(
            f"captures: the measured response is not monotonic: {names[c]} light went down from "
            f"{raw[k, c]:.3f} at input {lv[k]:.3f} to {raw[k + 1, c]:.3f} at input {lv[k + 1]:.3f} "
            f"(tolerance {tolerance}): are the captures in pattern order, and did the projector settle "
            "before each capture (try a longer settle delay)?"
        )
    table = np.stack([_isotonic(raw[:, c]) for c in range(3)], axis=1)
    table = np.clip((table - table[0]) / (table[-1] - table[0]), 0.0, 1.0)
    b = (black_cam - ref) / (white_cam - ref)
    if np.any(b < -0.01) or np.any(b >= 1):
        raise InputError(
            f"ambient: the black level came out as {np.round(b, 4).tolist()}; the ambient capture must be taken with "
            "the projector off (or covered) under the same room light and exposure as the ramp"
        )
    # Noise can put a black level of ~0 slightly below zero (checked above): report it as 0.
    return ProjectorResponse(lv, table, np.maximum(b, 0.0), raw)


def _isotonic(y: np.ndarray) -> np.ndarray:
    """Least-squares non-decreasing fit (pool adjacent violators); y is short (levels)."""
    vals: list[float] = []
    counts: list[int] = []
    for v in y:
        vals.append(float(v))
        counts.append(1)
        while len(vals) > 1 and vals[-2] > vals[-1]:
            n = counts[-2] + counts[-1]
            vals[-2] = (vals[-2] * counts[-2] + vals[-1] * counts[-1]) / n
            counts[-2] = n
            vals.pop()
            counts.pop()
    return np.repeat(vals, counts)
