"""Colour crosstalk between projector primaries and camera channels (optional calibration).

A camera channel sees some light of every projector primary. Per pixel the camera colour is
``diag(ρ) · M · p`` for projector input light ``p`` (linearised), ``ρ`` the surface's per-
channel reflectance and ``M`` a 3×3 mixing matrix shared by all pixels (Nayar et al. 2003).
Normalising ``M``'s rows to sum to 1 makes projector white map to camera white, so ``ρ`` is
what the direct image D measures under white light, and ``p = M⁻¹ (I / D)`` emits ``I``.

References
----------
S. K. Nayar, H. Peri, M. D. Grossberg, P. N. Belhumeur, "A projection system with radiometric
compensation for screen imperfections", ICCV Workshop PROCAMS 2003.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.calibrate._common import Patterns
from engine.checks import check_image, check_mask, check_resolution, check_stack
from engine.errors import InputError

__all__ = ["Crosstalk", "crosstalk_patterns", "fit_crosstalk"]


def crosstalk_patterns(projector_resolution) -> Patterns:
    """Return full red, green and blue projector images (capture each, plus a black frame).

    Examples
    --------
    >>> seq = crosstalk_patterns((1, 1))
    >>> seq.names, seq[2][0, 0].tolist()
    (('primary red', 'primary green', 'primary blue'), [0.0, 0.0, 1.0])
    """
    hp, wp = check_resolution("projector_resolution", projector_resolution)

    def render(i: int) -> np.ndarray:
        img = np.zeros((hp, wp, 3), np.float32)
        img[..., i] = 1.0
        return img

    return Patterns(render, ("primary red", "primary green", "primary blue"), (hp, wp))


@dataclass(frozen=True, eq=False)
class Crosstalk:
    """Projector primaries → camera channels mixing matrix.

    Attributes
    ----------
    matrix : (3, 3) float64
        ``matrix[c, j]``: share of camera channel c's response to white that comes from
        projector primary j. Rows sum to 1; the identity means no crosstalk.
    """

    matrix: np.ndarray

    def __post_init__(self) -> None:
        m = np.asarray(self.matrix, dtype=np.float64)
        if m.shape != (3, 3) or not np.all(np.isfinite(m)):
            raise InputError(f"matrix must be a finite 3×3 array, got shape {m.shape}")
        cond = np.linalg.cond(m)
        if not np.isfinite(cond) or cond > 1e6:
            raise InputError(
                f"matrix is singular (condition number {cond:.3g}): the projector primaries are not independent "
                "in the camera; was one primary missing or all three captures the same?"
            )
        m = m.copy()
        m.flags.writeable = False
        inv = np.linalg.inv(m)
        inv.flags.writeable = False
        object.__setattr__(self, "matrix", m)
        self._inverse: np.ndarray  # declared for type checkers; set like matrix (the class is frozen)
        object.__setattr__(self, "_inverse", inv)

    @classmethod
    def none(cls) -> Crosstalk:
        """No crosstalk (identity)."""
        return cls(np.eye(3))

    def mix(self, projector_rgb) -> np.ndarray:
        """Camera colour (per unit reflectance) of projector light ``projector_rgb`` (..., 3)."""
        p = _check_rgb("projector_rgb", projector_rgb)
        return np.einsum("cj,...j->...c", self.matrix.astype(np.float32), p).astype(np.float32)

    def unmix(self, desired_camera_rgb, *, clamp: bool = True) -> tuple[np.ndarray, int]:
        """Projector light that makes the camera see ``desired_camera_rgb``.

        Parameters
        ----------
        desired_camera_rgb : (..., 3) float
            Wanted camera colour per unit reflectance (e.g. ``I / D``).
        clamp : bool
            Set negative results to 0 (a projector cannot emit negative light). The count of
            affected pixels is returned either way, so nothing is clamped silently.

        Returns
        -------
        projector_rgb : (..., 3) float32
            ``M⁻¹ · desired`` per pixel (clamped at 0 if ``clamp``).
        clamped : int
            Number of pixels (positions of ``...``) with a negative channel.

        Examples
        --------
        >>> x = Crosstalk(np.array([[0.8, 0.2, 0.0], [0.1, 0.8, 0.1], [0.0, 0.2, 0.8]]))
        >>> p, n = x.unmix([[0.8, 0.1, 0.0], [1.0, 1.0, 1.0]])
        >>> p.round(3).tolist(), n
        ([[1.0, 0.0, 0.0], [1.0, 1.0, 1.0]], 0)
        """
        d = _check_rgb("desired_camera_rgb", desired_camera_rgb)
        p = np.einsum("jc,...c->...j", self._inverse.astype(np.float32), d).astype(np.float32)
        neg = np.any(p < 0, axis=-1)
        count = int(np.count_nonzero(neg))
        if clamp and count:
            np.maximum(p, 0, out=p)
        return p, count

    def to_dict(self) -> dict:
        """JSON-ready description."""
        return {"matrix": self.matrix.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> Crosstalk:
        """Inverse of :meth:`to_dict`."""
        try:
            return cls(np.asarray(d["matrix"], dtype=np.float64))
        except (KeyError, TypeError, ValueError) as e:
            if isinstance(e, InputError):
                raise
            raise InputError(f"crosstalk: not a valid crosstalk description ({e!r})") from None


def _check_rgb(name: str, a) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float32)
    if arr.ndim == 0 or arr.shape[-1] != 3:
        raise InputError(f"{name} must have a last axis of 3 channels, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} contains NaN or inf")
    return arr


def fit_crosstalk(captures_of_primaries, *, black=None, mask=None, min_signal: float = 0.05) -> Crosstalk:
    """Measure the mixing matrix from captures of :func:`crosstalk_patterns`.

    Parameters
    ----------
    captures_of_primaries : (3, H, W, 3) float, linear radiance
        Captures of full red, green and blue, in that order.
    black : (H, W, 3) float, optional
        Capture with the projector at black (subtracted). None: a dark room with a projector
        of negligible black level.
    mask : (H, W) bool, optional
        Pixels to use (lit, diffuse, unsaturated). Default: all.
    min_signal : float
        Pixels whose response to white (sum of the three primaries) is below this fraction
        of the 99th percentile are skipped, per camera channel.

    Returns
    -------
    Crosstalk

    Raises
    ------
    InputError
        Wrong shapes; no pixel with signal; a singular matrix.

    Notes
    -----
    Per pixel and camera channel c, the responses to the primaries ``V[c, j]`` are divided by
    their sum (removing the surface reflectance ρ_c); the matrix is the per-entry median over
    pixels, rows renormalised to 1.

    Examples
    --------
    >>> m = np.array([[0.8, 0.2, 0.0], [0.1, 0.8, 0.1], [0.0, 0.2, 0.8]])
    >>> rho = np.array([0.5, 0.7, 0.2], np.float32)
    >>> caps = np.stack([np.broadcast_to(rho * m[:, j], (2, 2, 3)) for j in range(3)]).astype(np.float32)
    >>> fit_crosstalk(caps).matrix.round(3).tolist()
    [[0.8, 0.2, 0.0], [0.1, 0.8, 0.1], [0.0, 0.2, 0.8]]
    """
    caps = check_stack("captures_of_primaries", captures_of_primaries)
    if caps.shape[0] != 3:
        raise InputError(
            f"captures_of_primaries: expected 3 captures (full red, green, blue), got {caps.shape[0]}"
        )
    h, w = caps.shape[1:3]
    v = caps.astype(np.float64)
    if black is not None:
        v = v - check_image("black", black, caps.shape[1:]).astype(np.float64)
    sel = np.ones((h, w), bool) if mask is None else check_mask("mask", mask, (h, w))
    vv = v[:, sel, :]  # (j, P, c)
    total = vv.sum(axis=0)  # (P, c): response to white
    rows = []
    names = ("red", "green", "blue")
    for c in range(3):
        t = total[:, c]
        ref = np.percentile(t, 99) if t.size else 0.0
        good = t > max(min_signal * ref, 0.0)
        if ref <= 0 or not good.any():
            raise InputError(
                f"captures_of_primaries: the camera's {names[c]} channel saw no projector light: is the projector on, "
                "and the mask on lit pixels?"
            )
        rows.append(np.median(vv[:, good, c] / t[good], axis=1))
    m = np.array(rows)
    m /= m.sum(axis=1, keepdims=True)
    return Crosstalk(m)
