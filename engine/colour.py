"""Colours an artist asks for, turned into κ — and the requests physics cannot honour.

A target's *direct colour* is its first interaction component ``R^0 L_d`` (paper Eq. 2)
averaged over the target: the light it reflects once, before any of its interreflections.
Recoloring multiplies it by κ exactly (Eq. 3: ``κ R^0 L_d``), so "make the target this
colour" has one answer per channel, ``κ = wanted / current``; the interreflections then
follow from the decomposition. The paper picks κ the same way in its Fig. 7 (the ratio of
the direct components of two papers).

Colours are linear RGB in the photograph's units unless said otherwise. Display colours
(hex, sRGB, CIE Lab) are decoded with colour-science to linear values that show as that
colour at display exposure 0 (the ``to_*`` functions take the display's ``exposure``).

Over 500 lines on purpose: the colour spaces, the target's colour and κ from a colour share one
white balance and one exposure rule, and the convergence limits are judged in the same terms.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from functools import cache

import numpy as np

from engine.checks import check_float_image, check_kappa
from engine.decompose import Decomposition
from engine.errors import InputError
from engine.figurate import transport_matrix

__all__ = [
    "Convergence",
    "convergence",
    "direct_colour",
    "kappa_for_albedo",
    "kappa_for_colour",
    "kappa_ceiling",
    "kappa_limit",
    "luminance_weights",
    "parse_colour",
    "pick_colour",
    "to_hex",
    "to_lab",
    "to_srgb",
]

#: Error the interactions beyond the captured order may put in the target's recolored light (relative, per
#: channel) before a recolor counts as not converged at that order (:func:`convergence`).
CONVERGENCE_THRESHOLD = 0.01
#: Standard deviations (the decomposition's covariance) that make a measured effect real: :func:`kappa_limit` fits
#: a second, slower mode only where the observations' growth rises by this many; :func:`convergence` counts the
#: last interaction only as far as it exceeds this many.
EVIDENCE = 3.0


@cache
def colour_science():
    """The ``colour`` package, imported once without its plotting-is-unavailable notice.

    colour-science warns at import time when matplotlib is missing (Albedit never plots
    with it, and the test suite turns every warning into an error), and switches numpy's
    global printing to its 1.13 style, which would change how every array prints in the
    process: the print options are restored.
    """
    printing = np.get_printoptions()
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=".*Matplotlib.*")
            import colour
    finally:
        np.set_printoptions(**printing)
    return colour


@cache
def _srgb_to_xyz() -> np.ndarray:
    """colour-science's linear sRGB → CIE XYZ matrix (its inverse goes back, exactly)."""
    return np.asarray(colour_science().RGB_COLOURSPACES["sRGB"].matrix_RGB_to_XYZ, np.float64)


def luminance_weights() -> np.ndarray:
    """(3,) Rec. 709 / sRGB luminance weights of linear R, G, B (the Y row of that matrix).

    Examples
    --------
    >>> np.round(luminance_weights(), 4).tolist()
    [0.2126, 0.7152, 0.0722]
    """
    return _srgb_to_xyz()[1].copy()

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_TRIPLE = re.compile(rf"^\s*({_NUMBER})\s*[, ]\s*({_NUMBER})\s*[, ]\s*({_NUMBER})\s*$")
_HEX = re.compile(r"^#?([0-9a-fA-F]{6}|[0-9a-fA-F]{3})$")


def parse_colour(text: str) -> np.ndarray:
    """Read a colour written by a person and return it as linear RGB.

    Parameters
    ----------
    text : str
        One of ``"#3355cc"`` / ``"#35c"`` (sRGB hex), ``"srgb:0.2,0.33,0.8"`` (sRGB-encoded,
        0–1), ``"lab:50,10,-40"`` (CIE L*a*b*, the sRGB white), ``"linear:0.2,0.1,0.8"`` or just
        ``"0.2,0.1,0.8"`` (linear RGB, the engine's own units).

    Returns
    -------
    (3,) float64
        Linear RGB (sRGB primaries and white), non-negative.

    Raises
    ------
    InputError
        Unreadable text, sRGB values outside 0–1, or a Lab colour outside the sRGB gamut;
        the message shows the accepted forms.

    Examples
    --------
    >>> parse_colour("#ffffff").tolist()
    [1.0, 1.0, 1.0]
    >>> parse_colour("0.2, 0.1, 0.8").tolist()
    [0.2, 0.1, 0.8]
    >>> np.round(parse_colour("lab:100,0,0"), 3).tolist()
    [1.0, 1.0, 1.0]
    """
    if not isinstance(text, str):
        raise InputError(f"a colour must be text such as '#3355cc', got {type(text).__name__}")
    forms = "'#3355cc', 'srgb:0.2,0.33,0.8', 'lab:50,10,-40' or linear 'R,G,B'"
    raw = text.strip()
    space, _, body = raw.partition(":") if ":" in raw else ("", "", raw)
    space = space.strip().lower()
    hex_match = None if space else _HEX.match(body.strip())
    if hex_match is not None:
        digits = hex_match.group(1)
        if len(digits) == 3:
            digits = "".join(d * 2 for d in digits)
        encoded = np.array([int(digits[i:i + 2], 16) for i in (0, 2, 4)], np.float64) / 255.0
        return _decode_srgb(encoded)
    match = _TRIPLE.match(body)
    if match is None or space not in ("", "linear", "srgb", "lab"):
        raise InputError(f"cannot read the colour {text!r}; write {forms}")
    values = np.array([float(v) for v in match.groups()], np.float64)
    if space == "srgb":
        if np.any(values < 0) or np.any(values > 1):
            raise InputError(f"sRGB values are 0–1, got {values.tolist()} in {text!r}; "
                             "for 0–255 write hex, e.g. '#3355cc'")
        return _decode_srgb(values)
    if space == "lab":
        return _lab_to_linear(values, text)
    if np.any(values < 0):
        raise InputError(f"linear RGB values must be ≥ 0 (light is never negative), got {values.tolist()} in {text!r}")
    return values


def _decode_srgb(encoded: np.ndarray) -> np.ndarray:
    colour = colour_science()
    return np.asarray(colour.cctf_decoding(encoded, function="sRGB"), np.float64)


def _lab_to_linear(lab: np.ndarray, text: str) -> np.ndarray:
    colour = colour_science()
    if not 0 <= lab[0] <= 100:
        raise InputError(f"L* must be in 0–100, got {lab[0]} in {text!r}")
    xyz = np.asarray(colour.Lab_to_XYZ(lab, _white_xy()), np.float64)
    rgb = np.linalg.solve(_srgb_to_xyz(), xyz)
    if np.any(rgb < -1e-6):
        raise InputError(f"the Lab colour {lab.tolist()} lies outside the sRGB gamut "
                         f"(linear RGB {np.round(rgb, 4).tolist()}); "
                         "choose a less saturated colour")
    return np.maximum(rgb, 0.0)


def _white_xy() -> np.ndarray:
    """Chromaticity of linear RGB (1, 1, 1) through the sRGB matrix: Lab's reference white."""
    return np.asarray(colour_science().XYZ_to_xy(_srgb_to_xyz() @ np.ones(3)), np.float64)


def to_srgb(linear, *, exposure: float = 0.0) -> np.ndarray:
    """sRGB-encoded 0–1 values of a linear colour shown at ``exposure`` stops (clipped for display).

    Examples
    --------
    >>> np.round(to_srgb([0.18, 0.18, 0.18]), 3).tolist()
    [0.461, 0.461, 0.461]
    """
    colour = colour_science()
    lin = np.clip(_colour3("linear", linear) * 2.0 ** float(exposure), 0.0, 1.0)
    return np.asarray(colour.cctf_encoding(lin, function="sRGB"), np.float64)


def to_hex(linear, *, exposure: float = 0.0) -> str:
    """``"#rrggbb"`` of a linear colour shown at ``exposure`` stops.

    Examples
    --------
    >>> to_hex(parse_colour("#3355cc"))
    '#3355cc'
    """
    return "#" + "".join(f"{int(round(v * 255)):02x}" for v in to_srgb(linear, exposure=exposure))


def to_lab(linear, *, exposure: float = 0.0) -> np.ndarray:
    """CIE L*a*b* (relative to the sRGB white, D65) of a linear colour shown at ``exposure`` stops.

    Examples
    --------
    >>> np.round(to_lab([1.0, 1.0, 1.0]), 3).tolist()
    [100.0, 0.0, 0.0]
    """
    colour = colour_science()
    xyz = _srgb_to_xyz() @ (_colour3("linear", linear) * 2.0 ** float(exposure))
    return np.asarray(colour.XYZ_to_Lab(xyz, _white_xy()), np.float64) + 0.0


def pick_colour(image, x: float, y: float, *, radius: int = 2, encoded: bool = False) -> np.ndarray:
    """An eyedropper: the mean colour of a small square around a pixel.

    Parameters
    ----------
    image : (H, W, 3) float
        Linear radiance (the photograph), or sRGB-encoded 0–1 values (a reference picture
        from elsewhere) with ``encoded=True``.
    x, y : float
        Pixel (column, row) picked; the square is clipped to the image.
    radius : int
        Half-size of the square: ``(2 radius + 1)²`` pixels averaged (noise, texture).
    encoded : bool
        Decode sRGB to linear before averaging (averaging encoded values would bias dark).

    Returns
    -------
    (3,) float64
        Linear RGB.

    Raises
    ------
    InputError
        A point outside the image, a negative radius, or a non-RGB image.

    Examples
    --------
    >>> img = np.zeros((5, 5, 3), np.float32); img[1:4, 1:4] = [0.2, 0.4, 0.6]
    >>> np.round(pick_colour(img, 2, 2, radius=1), 3).tolist()
    [0.2, 0.4, 0.6]
    """
    img = check_float_image("image", image, ndim=3)
    if img.shape[2] != 3:
        raise InputError(f"image must be RGB (H, W, 3), got shape {img.shape}")
    h, w = img.shape[:2]
    if isinstance(radius, bool) or not isinstance(radius, (int, np.integer)) or radius < 0:
        raise InputError(f"radius must be a non-negative integer (pixels), got {radius!r}")
    col, row = int(round(float(x))), int(round(float(y)))
    if not (0 <= col < w and 0 <= row < h):
        raise InputError(f"the point ({x}, {y}) is outside the {w}×{h} image")
    patch = img[max(row - radius, 0):row + radius + 1, max(col - radius, 0):col + radius + 1].astype(np.float64)
    if encoded:
        patch = _decode_srgb(np.clip(patch, 0.0, 1.0))
    return patch.reshape(-1, 3).mean(axis=0)


def direct_colour(decomposition: Decomposition, *, direct=None) -> np.ndarray:
    """The target's current colour: its direct component ``R^0 L_d`` averaged over the target.

    Parameters
    ----------
    decomposition : Decomposition
        Of the target (its ``components[0]`` on target pixels is ``R^0 L_d``).
    direct : (H, W, 3) float, optional
        The target's direct image D (projector light, :class:`engine.acquire.PreparedTarget`).
        Given, the colour is *white-balanced*: its chromaticity is D's (the projector is the
        rig's white light) and its luminance the photograph's, so the colour cast of the
        photograph's own light (a warm lamp, light bounced off a red wall) is removed.

    Returns
    -------
    (3,) float64
        Linear RGB in the photograph's units.

    Raises
    ------
    InputError
        Not a decomposition, a D of the wrong shape, or no light on the target.

    Notes
    -----
    ``R^0 L_d = ρ E₀`` (Sec. 3.1): albedo times the light that reaches the target without
    touching it, which recoloring does not change, so ``κ`` scales this colour exactly.
    ``D = ρ E_p`` with ``E_p`` the projector's (white) light, hence white balancing by D.
    The colour is relative: its scale depends on the lighting, not only on the albedo
    (:mod:`engine.albedo` gives absolute albedo when a reference was measured).

    Examples
    --------
    >>> comps = np.zeros((2, 1, 2, 3), np.float32)
    >>> comps[0, 0, 0] = [0.2, 0.4, 0.1]; comps[1, 0, 0] = 0.05
    >>> d = Decomposition(comps, np.zeros((1, 2, 3), np.float32), np.array([[True, False]]))
    >>> np.round(direct_colour(d), 3).tolist()
    [0.2, 0.4, 0.1]
    """
    if not isinstance(decomposition, Decomposition):
        raise InputError(f"decomposition must be an engine.decompose.Decomposition, got {type(decomposition).__name__}")
    target = decomposition.target
    if decomposition.shape[2] != 3:
        raise InputError(f"a colour needs 3 channels, the decomposition has {decomposition.shape[2]}")
    seen = decomposition.components[0][target].astype(np.float64).mean(axis=0)
    if float(seen @ luminance_weights()) <= 0:
        raise InputError("the target reflects no light in the photograph: its colour cannot be measured")
    if direct is None:
        return seen
    d = check_float_image("direct", direct, ndim=3)
    if d.shape != decomposition.shape:
        raise InputError(f"direct must have the photograph's shape {decomposition.shape}, got {d.shape}")
    lit = target & np.all(d > 0, axis=-1)
    if not lit.any():
        raise InputError("the direct image D is zero on the whole target: measure it (Nayar patterns) first")
    balanced = d[lit].astype(np.float64).mean(axis=0)
    return balanced * float(seen @ luminance_weights()) / float(balanced @ luminance_weights())


def kappa_for_colour(current, wanted, *, keep_luminance: bool = False) -> np.ndarray:
    """κ that turns a target's current colour into the wanted one.

    Parameters
    ----------
    current : (3,) float
        The target's colour now (:func:`direct_colour`), linear, every channel > 0.
    wanted : (3,) float
        The colour asked for, linear (:func:`parse_colour`), in the same units, ≥ 0.
    keep_luminance : bool
        Change hue and chroma only: κ is scaled so the luminance (Rec. 709 weights) of the
        new colour equals the current one.

    Returns
    -------
    (3,) float64
        κ per channel.

    Raises
    ------
    InputError
        A channel of ``current`` is 0 (no scale of it makes light), or ``wanted`` is
        negative, black with ``keep_luminance``, or malformed.

    Notes
    -----
    Eq. 3: recoloring scales ``R^0 L_d`` by κ exactly, so ``κ = wanted / current``.

    Examples
    --------
    >>> kappa_for_colour([0.1, 0.8, 0.1], [0.2, 0.1, 0.8]).tolist()
    [2.0, 0.125, 8.0]
    >>> k = kappa_for_colour([0.5, 0.5, 0.5], [1.0, 0.0, 0.0], keep_luminance=True)
    >>> round(float(k @ luminance_weights() * 0.5), 6) == round(0.5 * float(luminance_weights().sum()), 6)
    True
    """
    cur = _colour3("current", current)
    want = _colour3("wanted", wanted)
    if np.any(cur <= 0):
        raise InputError(f"the target's current colour {cur.tolist()} has a black channel: no κ can make light there")
    kappa = want / cur
    if keep_luminance:
        new = float((kappa * cur) @ luminance_weights())
        if new <= 0:
            raise InputError("a black colour has no hue to keep the luminance with; switch 'keep luminance' off")
        kappa *= float(cur @ luminance_weights()) / new
    return kappa


def kappa_for_albedo(current_albedo, wanted_albedo) -> np.ndarray:
    """κ that gives the target an absolute albedo, refusing impossible ones.

    Parameters
    ----------
    current_albedo : (3,) float
        The target's measured absolute albedo (:meth:`engine.albedo.AlbedoScale.albedo`).
    wanted_albedo : (3,) float
        The albedo asked for, each channel in [0, 1).

    Returns
    -------
    (3,) float64

    Raises
    ------
    InputError
        A wanted albedo ≥ 1 (a surface cannot reflect more light than it receives; the
        interreflection series would diverge), a negative one, or a current albedo that is
        0 or ≥ 1 (the measurement is wrong: the reference was lit differently).

    Examples
    --------
    >>> kappa_for_albedo([0.1, 0.8, 0.1], [0.2, 0.1, 0.8]).tolist()
    [2.0, 0.125, 8.0]
    """
    cur = _colour3("current_albedo", current_albedo)
    want = _colour3("wanted_albedo", wanted_albedo)
    over = [f"{'RGB'[c]} = {want[c]:g}" for c in range(3) if want[c] >= 1]
    if over:
        raise InputError(f"an albedo of 1 or more ({', '.join(over)}) is impossible: "
                         "a surface cannot reflect more light "
                         "than it receives (the interreflection series would diverge); ask for less than 1")
    if np.any(cur <= 0) or np.any(cur >= 1):
        raise InputError(f"the target's measured albedo {np.round(cur, 4).tolist()} is not in (0, 1): the reference "
                         "(colour checker) was not lit like the target; "
                         "measure it beside the target, facing the same way")
    return want / cur


def kappa_limit(decomposition: Decomposition) -> np.ndarray:
    """Largest κ per channel for which the target's interreflection series still converges.

    Parameters
    ----------
    decomposition : Decomposition
        Of order K ≥ 2.

    Returns
    -------
    (3,) float64
        ``1 / λ``, with λ the estimated growth rate of the target's interactions (the spectral
        radius of its round trip through the scene); ``inf`` where nothing was measured to
        bound it (K = 1, or no interaction light).

    Notes
    -----
    ``Σ κ^{i+1} R^i L_d`` (Eq. 3) is a power series in κR; it converges while κλ < 1. The
    measured components cannot tell λ directly: a decomposition of order K is a truncated fit,
    whose last component absorbs every interaction beyond it (on the ideal Cornell wall the
    ratio of its last two components puts the green limit at 1.5 at order 4, against 5.4).
    The observations carry the whole series instead: summed over the target,
    ``obs[r] = Σ_n binom(n + r, r) S_n`` (Eq. 6), and for interactions falling as modes
    ``S_n = Σ_j a_j λ_j^n`` that is ``Σ_j a_j μ_j^{r+1}`` with ``μ_j = 1 / (1 − λ_j)``. So the
    observation sums (:attr:`Decomposition.observed`; rebuilt from the components through Eq. 6
    where not known) are fitted with two modes (Prony's method on the last four, K ≥ 4), the
    slowest giving λ; with fewer observations, or when the fit has no real mode above the last
    observations' growth, that growth itself gives λ — an underestimate, as the ratios of
    successive observations rise towards ``μ_max``. Two modes fit any four numbers, noise
    included, so with the decomposition's covariance the second is fitted only where the growth
    rises over the last four observations by :data:`EVIDENCE` of its standard deviations (sums
    over pixels taken as independent). On the ideal virtual rig at order ≥ 4 the Cornell wall's
    limits come out 1–2 % above the truth (`bench/albedo.py`, 96²). On the realistic rig two
    things had made the channels that interreflect little (ideal limits 38 and 50) look
    divergent, so the paper's κ_B = 8 "diverged": the components' sums, which the ordering
    constraint biases up under noise (clipping noisy components at 0 adds light: the blue
    observations rebuilt from them grew 3.5 % per order at 128² and 16 frames, 12–14 % in the
    demo's capture at 96²; the observations themselves grew 1.9 % at 128²), and a rise of the
    growth by 1σ fitted as a mode. Limits R, G, B at 128², 16 frames, camera-noise seeds 1 and
    2: 3.8–4.4, 6.2–6.3, 4.2–5.7 before, 44–45, 5.7–5.8, 50–52 now (ideal rig 37.9, 5.43,
    49.6); the demo at 96²: 7.7, 6.5, 5.9 before, 63, 6.7, 51 now. Physics stops
    earlier anyway: a surface's albedo stays below 1, so ``1 / albedo``
    (:func:`kappa_ceiling`, with a reference) is the tighter bound.

    Examples
    --------
    >>> comps = np.zeros((2, 1, 1, 3)); comps[0] = 0.9375; comps[1] = 0.3125   # order 2
    >>> d = Decomposition(comps, np.zeros((1, 1, 3)), np.ones((1, 1), bool))   # obs = 1.25, 1.5625 = 1.25²
    >>> kappa_limit(d).round(3).tolist()
    [5.0, 5.0, 5.0]
    """
    sums, cov = _target_sums(decomposition)
    k = sums.shape[0]
    if k < 2:
        return np.full(sums.shape[1], np.inf)
    a = transport_matrix(k)
    obs = a @ sums if decomposition.observed is None else decomposition.observed.astype(np.float64)
    obs_cov = None if cov is None else np.einsum("ri,ijc,sj->rsc", a, cov, a)
    growth = np.array([_growth(obs[:, c], None if obs_cov is None else obs_cov[..., c]) for c in range(obs.shape[1])])
    with np.errstate(divide="ignore"):
        return np.where(growth > 0, 1.0 / np.where(growth > 0, growth, 1.0), np.inf)


def _growth(obs: np.ndarray, cov: np.ndarray | None = None) -> float:
    """λ of the slowest mode of observation sums ``obs[r] = Σ_j a_j μ_j^{r+1}`` (see :func:`kappa_limit`).

    ``cov``: the sums' (K, K) covariance, if known. Prony's two modes fit any four numbers, noise
    included: the second mode is taken only where the growth ``obs[r+1] / obs[r]`` rises over the
    last four by :data:`EVIDENCE` of its standard deviations.
    """
    if not np.all(np.isfinite(obs)) or obs[-2] <= 0 or obs[-1] <= obs[-2]:
        return 0.0
    floor = 1.0 - obs[-2] / obs[-1]
    if len(obs) < 4 or obs[-4] <= 0:
        return floor
    o = obs[-4:]
    if cov is not None:
        rise = o[3] / o[2] - o[1] / o[0]
        gradient = np.array([-o[1] / o[0] ** 2, 1 / o[0], -o[3] / o[2] ** 2, 1 / o[2]])
        if rise < EVIDENCE * np.sqrt(max(float(gradient @ cov[-4:, -4:] @ gradient), 0.0)):
            return floor
    system = np.array([[o[1], o[0]], [o[2], o[1]]])
    if abs(np.linalg.det(system)) <= 1e-9 * o[2] ** 2:  # one mode only: the ratio is exact
        return floor
    p, q = np.linalg.solve(system, o[2:])
    disc = p * p + 4 * q
    if disc < 0:
        return floor
    mu = (p + np.sqrt(disc)) / 2
    lam = 1.0 - 1.0 / mu if mu > 1 else 0.0
    return float(lam) if floor <= lam < 1 else floor


def kappa_ceiling(decomposition: Decomposition, albedo=None) -> np.ndarray:
    """Upper end of the κ range a control should offer, per channel (the lower end is 0).

    Parameters
    ----------
    decomposition : Decomposition
    albedo : (3,) float, optional
        The target's absolute albedo (:meth:`engine.albedo.AlbedoScale.albedo`), when a
        reference measured it.

    Returns
    -------
    (3,) float64
        With the albedo: ``1 / albedo`` (an albedo of 1 is impossible), or
        :func:`kappa_limit` if that is lower. Without: :func:`kappa_limit` (``inf`` when
        nothing bounds it: the caller keeps its own display range).

    Examples
    --------
    >>> comps = np.zeros((2, 1, 2, 3), np.float32)
    >>> comps[0, 0, 0] = 1.0; comps[1, 0, 0] = 0.1
    >>> d = Decomposition(comps, np.zeros((1, 2, 3), np.float32), np.array([[True, False]]))
    >>> kappa_ceiling(d).round(3).tolist(), kappa_ceiling(d, [0.5, 0.05, 0.2]).round(3).tolist()
    ([12.0, 12.0, 12.0], [2.0, 12.0, 5.0])
    """
    limit = kappa_limit(decomposition)
    if albedo is None:
        return limit
    rho = _colour3("albedo", albedo)
    if np.any(rho <= 0) or np.any(rho >= 1):
        raise InputError(f"albedo must be in (0, 1) in every channel, got {rho.tolist()}")
    return np.minimum(limit, 1.0 / rho)


@dataclass(frozen=True)
class Convergence:
    """How much of a recolor the captured order may be missing.

    Attributes
    ----------
    share : (3,) float64
        Per channel, the last interaction component's share of the target's recolored light
        ``κ^K Σ R^{K-1} L_d / Σ_i κ^{i+1} Σ R^i L_d`` (as far as it is not noise).
    ratio : (3,) float64
        κ times the growth rate of the last interactions (``κ / kappa_limit``); ≥ 1 means
        the series diverges.
    error : (3,) float64
        The predicted relative error of the target's recolored light from the interactions
        beyond the order (:func:`convergence`); inf where the series diverges.
    threshold : float
    order : int
    """

    share: np.ndarray
    ratio: np.ndarray
    error: np.ndarray
    threshold: float
    order: int

    @property
    def converged(self) -> bool:
        """The predicted truncation error is below the threshold in every channel and the series converges."""
        return bool(np.all(self.error <= self.threshold) and np.all(self.ratio < 1))

    def message(self) -> str:
        """One line for a status bar or stderr: empty when converged, else what is wrong and what helps.

        Examples
        --------
        >>> c = Convergence(share=np.zeros(3), ratio=np.array([0.5, 3.0, 1.6e29]), error=np.full(3, np.inf),
        ...                 threshold=0.01, order=4)
        >>> c.message().split("(")[1]  # a limit near 0 gives an absurd ratio: capped
        'κ is over 100× the limit); ask for a smaller change'
        """
        if self.converged:
            return ""
        c = int(np.argmax(self.ratio)) if np.any(self.ratio >= 1) else int(np.argmax(self.error))
        channel = "RGB"[c]
        if self.ratio[c] >= 1:
            times = f"{self.ratio[c]:.2f}×" if self.ratio[c] < 100 else "over 100×"  # the limit can be near 0
            return (f"κ diverges in {channel}: the target would reflect more light than it receives round its "
                    f"interreflections (κ is {times} the limit); ask for a smaller change")
        return (f"the recolor has not converged at order {self.order}: the interactions beyond it would change the "
                f"target's light by about {self.error[c]:.1%} in {channel} (above {self.threshold:.0%}); "
                "capture a higher order or ask for a smaller change")


def convergence(decomposition: Decomposition, kappa, *, threshold: float = CONVERGENCE_THRESHOLD) -> Convergence:
    """Measure whether recoloring with ``kappa`` has converged at the decomposition's order.

    Parameters
    ----------
    decomposition : Decomposition
    kappa : float or (3,) float
    threshold : float
        Largest acceptable predicted error of the target's recolored light from the
        interactions beyond the order (default 1 %).

    Returns
    -------
    Convergence

    Notes
    -----
    The last of the K components holds every interaction from K − 1 on (the components sum
    to the photograph), and Eq. 3 scales all of them by κ^K. Interaction K − 1 + j should
    have been scaled by κ^{K+j}: the recolor misses ``Σ_{j≥1} κ^K (κ^j − 1) R^{K−1+j} L_d``.
    For a tail that falls geometrically with the target's growth rate λ (the spectral radius
    :func:`kappa_limit` estimates) the last component is ``R^{K−1} L_d / (1 − λ)`` and the
    miss is the last term times ``λ (κ − 1) / (1 − κλ)``: its share of the recolored light
    times that factor is :attr:`Convergence.error`. So κ = 1 misses nothing (the recolor is
    the photograph), κ close to 1 almost nothing, and the miss grows without bound as κλ
    nears 1 (beyond, the series diverges). The last term's share alone, the rule before,
    warned at order 2 of a 13 % "last interaction" for κ = 1.02 on the ideal Cornell wall,
    whose recolor is within 0.05 % of the truth there. Against that wall's exact components
    (32², orders 2–4, κ from 0.5 to 8) the predicted miss is 0.7–0.9× the true error: λ read
    from a few observations is an underestimate (:func:`kappa_limit`), and so is the miss.

    The terms are the target's sums ``A⁻¹`` of the observed sums (:attr:`Decomposition.observed`)
    when known: the components' own sums are biased up by the constraint's clipping of noise.
    With the decomposition's covariance the last term counts only as far as it exceeds
    :data:`EVIDENCE` of its standard deviations: on the realistic demo (96²) its blue, clipped
    noise times κ^4 = 4096, read 56 % of the wall's recolored light, and the app told the
    artist to capture a higher order for the paper's κ_B = 8. Nor does it count beyond any
    term before it (each by as much as its noise allows): ``R^{i+1} L_d = R (R^i L_d)`` and
    the target sends back to itself less light than it receives (its albedo times the part of
    its view it fills), so a convergent series' terms shrink, and a last term larger than one
    before it is an error of the measurement, which a higher order would not remove (realistic
    demo, 64², 16 frames: blue sums −0.013 ± 0.002 then +0.0048 ± 0.0005 read "not converged,
    7.9 %"). (The sums are of pixel radiance, not power: a strongly foreshortened target bends
    that bound by its pixels' footprints.)

    Examples
    --------
    >>> comps = np.zeros((2, 1, 2, 3), np.float32)
    >>> comps[0, 0, 0] = 1.0; comps[1, 0, 0] = 0.25   # order 2: the last term lumps 0.2 + 0.04 + ... (λ = 0.2)
    >>> d = Decomposition(comps, np.zeros((1, 2, 3), np.float32), np.array([[True, False]]))
    >>> convergence(d, 1.0).converged
    True
    >>> c = convergence(d, 1.5)   # λ read from two observations: 1/6, an underestimate (the exact miss: 3.9 %)
    >>> round(float(c.share[0]), 3), round(float(c.error[0]), 3), c.converged
    (0.273, 0.03, False)
    >>> convergence(d, 1.05).converged   # the same last term, a small change: 0.2 % missed
    True
    """
    if not isinstance(threshold, (int, float)) or not 0 < threshold < 1:
        raise InputError(f"threshold must be a fraction in (0, 1), got {threshold!r}")
    sums, cov = _target_sums(decomposition)
    k = sums.shape[0]
    if decomposition.observed is not None:  # the constraint clips noisy components at 0: a bias up
        sums = np.linalg.solve(transport_matrix(k), decomposition.observed.astype(np.float64))
    sd = np.zeros_like(sums) if cov is None else np.sqrt(np.maximum(np.einsum("iic->ic", cov), 0))
    last = sums[-1] - EVIDENCE * sd[-1]
    if k > 1:  # no term of a convergent series exceeds one before it (below): not truncation
        last = np.minimum(last, (sums[:-1] + EVIDENCE * sd[:-1]).min(axis=0))
    last = last if cov is None else np.maximum(last, 0)
    kap = check_kappa(kappa, sums.shape[1])
    weights = kap[None, :] ** np.arange(1, k + 1)[:, None]
    total = (weights * sums).sum(axis=0)
    growth = 1.0 / kappa_limit(decomposition)  # λ; 0 where nothing bounds it
    ratio = kap * growth
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.where(total > 0, weights[-1] * last / np.where(total > 0, total, 1.0), 0.0)
        miss = np.maximum(share, 0.0) * growth * np.abs(kap - 1.0) / np.where(ratio < 1, 1.0 - ratio, 1.0)
    error = np.where(ratio < 1, miss, np.inf)
    return Convergence(share, np.nan_to_num(ratio, nan=0.0), error, float(threshold), k)


def _target_sums(decomposition: Decomposition) -> tuple[np.ndarray, np.ndarray | None]:
    """:attr:`Decomposition.target_sums`, refusing anything but a decomposition."""
    if not isinstance(decomposition, Decomposition):
        raise InputError(f"decomposition must be an engine.decompose.Decomposition, got {type(decomposition).__name__}")
    return decomposition.target_sums


def _colour3(name: str, value) -> np.ndarray:
    arr = np.asarray(value, np.float64)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise InputError(f"{name} must be 3 finite numbers (R, G, B), got {np.asarray(value).tolist()!r:.80}")
    if np.any(arr < 0):
        raise InputError(f"{name} must be ≥ 0 in every channel, got {arr.tolist()}")
    return arr
