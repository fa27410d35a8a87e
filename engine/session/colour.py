"""The colour facts of a session: the colour checker that calibrated it and each target's direct image D.

A ColorChecker measured in the scene (:func:`engine.acquire.measure_checker`) turns a target's
D into its absolute albedo (:mod:`engine.albedo`). The session keeps what that needs:

- the checker measurement, in the session's state under ``"colour"``::

      {"version": 1,
       "checker": {"corners": [[x, y], [x, y], [x, y], [x, y]], "source": "detected",
                   "captures": "checker-3f2a9c1b", "sensitivities": "Nikon 5100 (NPL)",
                   "illuminant": "D65", "scale": [r, g, b], "plane": [a, b, c],
                   "patch_direct": [[r, g, b] or null, ... 24], "residual": [[r, g, b] or null, ... 24],
                   "used": [true, ... 24]}}

  ``corners`` are the chart's patch-area corners in camera pixels (dark skin, bluish green,
  black, white), ``captures`` the prefix of its pattern captures in the session, ``scale``
  the direct light per unit albedo ``E_p`` per channel, ``plane`` the projector's light over
  the chart's plane (null: uniform), ``patch_direct`` each patch's mean D (null: not
  measured), ``residual`` each patch's relative misfit, ``used`` the patches the fit kept;
- each measured target's D, a calibration array ``colour/direct-<digest>``
  (:func:`direct_array`), keyed by the :func:`engine.session.edit.mask_digest` of the painted
  pixels it was measured on, so renaming a target keeps it. D is in the same units as the
  checker's, which is what makes the ratio an albedo.

Older sessions have neither; older versions of Albedit ignore both (the state's unknown keys
are free, calibration array groups are free).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from engine.albedo import AlbedoScale
from engine.checker import PATCHES, Checker
from engine.errors import InputError
from engine.session.paths import NAME
from engine.session.spec import Bool, Const, Invalid, List, Nullable, Num, Obj, Str

__all__ = ["COLOUR_GROUP", "COLOUR_SPEC", "COLOUR_VERSION", "CheckerRecord", "direct_array"]

#: Version of the state's ``"colour"`` entry.
COLOUR_VERSION = 1
#: Calibration-array group holding the colour facts' arrays (kept when the rig is recalibrated).
COLOUR_GROUP = "colour"

_XY = List(Num(), length=2, expected="[x, y] in camera pixels")
_RGB = List(Num(), length=3, expected="[r, g, b], three finite numbers")
_POSITIVE_RGB = List(Num(positive=True), length=3, expected="[r, g, b], three positive numbers")
_PER_PATCH = List(Nullable(_RGB), length=PATCHES, expected=f"a list of {PATCHES} [r, g, b] (or null)")

CHECKER_SPEC = Obj(required={
    "corners": List(_XY, length=4, expected="4 corners [x, y]: dark skin, bluish green, black, white"),
    "source": Str(choices=("detected", "manual")),
    "captures": Str(pattern=NAME.pattern, expected="a capture-name prefix"),
    "sensitivities": Str(min_len=1, max_len=128),
    "illuminant": Str(min_len=1, max_len=64),
    "scale": _POSITIVE_RGB,
    "plane": Nullable(_RGB),
    "patch_direct": _PER_PATCH,
    "residual": _PER_PATCH,
    "used": List(Bool(), length=PATCHES, expected=f"a list of {PATCHES} true/false"),
})

#: The schema of ``state["colour"]`` (checked by :data:`engine.session.schema.STATE`).
COLOUR_SPEC = Obj(required={"version": Const(COLOUR_VERSION), "checker": Nullable(CHECKER_SPEC)})

_DIGEST = re.compile(r"[0-9a-f]{16}")


def direct_array(digest: str) -> str:
    """Name (in :data:`COLOUR_GROUP`) of the D measured on the painted pixels with this mask digest.

    Examples
    --------
    >>> direct_array("7ea7187532e1d4da")
    'direct-7ea7187532e1d4da'
    """
    if not isinstance(digest, str) or not _DIGEST.fullmatch(digest):
        raise InputError(f"digest must be the 16 hexadecimal digits of mask_digest(), got {digest!r}")
    return f"direct-{digest}"


def _rows(values: np.ndarray) -> list:
    return [None if not np.all(np.isfinite(row)) else [float(v) for v in row] for row in np.asarray(values, float)]


def _array(rows: list) -> np.ndarray:
    return np.array([[np.nan] * 3 if row is None else row for row in rows], np.float64)


@dataclass(frozen=True, eq=False)
class CheckerRecord:
    """A colour-checker measurement as a session keeps it.

    Attributes
    ----------
    checker : Checker
        Where the chart is in the camera image.
    captures : str
        Prefix of the chart's pattern captures in the session.
    sensitivities, illuminant : str
        What the reference reflectances were integrated with (:func:`engine.checker.reference_reflectances`).
    scale : AlbedoScale
        The fit: per-channel ``E_p``, the projector's light over the chart's plane, the
        per-patch residuals and the patches used.
    patch_direct : (24, 3) float64
        Each patch's mean D (NaN: not measured).
    """

    checker: Checker
    captures: str
    sensitivities: str
    illuminant: str
    scale: AlbedoScale
    patch_direct: np.ndarray

    def to_json(self) -> dict:
        """The JSON form stored under ``state["colour"]["checker"]``."""
        s = self.scale
        return {
            "corners": [[float(x), float(y)] for x, y in self.checker.corners],
            "source": self.checker.source,
            "captures": self.captures,
            "sensitivities": self.sensitivities,
            "illuminant": self.illuminant,
            "scale": [float(v) for v in s.scale],
            "plane": None if s.plane is None else [float(v) for v in s.plane],
            "patch_direct": _rows(self.patch_direct),
            "residual": _rows(s.residual),
            "used": [bool(u) for u in s.used],
        }

    @classmethod
    def from_json(cls, data, shape: tuple[int, int], where: str = "state.colour.checker") -> CheckerRecord:
        """Read a stored measurement placed in a camera image of ``shape`` ``(H, W)``.

        Raises
        ------
        InputError
            A field does not fit the schema (the message names its path), or a corner lies
            outside the camera image.
        """
        try:
            CHECKER_SPEC.check(data, where)
        except Invalid as exc:
            raise InputError(str(exc)) from None
        corners = np.array(data["corners"], np.float64)
        h, w = shape
        if np.any(corners < -0.5) or np.any(corners > [w - 0.5, h - 0.5]):
            raise InputError(f"{where}.corners {corners.tolist()} lie outside the {w}×{h} camera image")
        scale = AlbedoScale(np.array(data["scale"], np.float64), residual=_array(data["residual"]),
                            used=np.array(data["used"], bool), source="checker",
                            plane=None if data["plane"] is None else np.array(data["plane"], np.float64))
        return cls(Checker(corners, (int(h), int(w)), data["source"]), data["captures"], data["sensitivities"],
                   data["illuminant"], scale, _array(data["patch_direct"]))

    def report(self) -> str:
        """One line: how the chart was placed and how well its patches fit the published reflectances."""
        used = int(self.scale.used.sum())
        return (f"colour checker ({self.checker.source}): {used} of {PATCHES} patches fit the published reflectances "
                f"to {self.scale.rms_residual:.1%} rms")
