"""The saved edit: which targets, their masks, κ, the acquired cascade and its noise reduction.

One schema, owned by the engine and used by the app, ``albedit recolor``, ``export`` and
``demo``. It lives in the session's state under ``"edit"``::

    {"version": 2,
     "targets": [{"name": "target 1", "mask": "target_1-3f2a9c1b", "kappa": [r, g, b],
                  "colour": [r, g, b], "included": false}, ...],
     "current": "target 1",
     "photograph": "acq-photograph",
     "acquisition": {"cascade": ["floor", "target 1"], "kappas": [[...], [...]],
                     "decomposition": "<cache key>", "denoise": 0, "noise_aware": true}}

Target names are display names: any text a user can type (``"target 1"``, ``"Wand — links"``).
Their masks are stored under a safe file name derived from the name and the mask's content
(:func:`mask_name`), so every name is accepted everywhere and a save that rewrites a mask
never touches the file an older save still refers to. ``included`` is written only for a
target left out of the next acquisition (``false``; absent reads as ``true``). The cascade lists acquired targets
first to last; the last one's κ is free, the others' were fixed before capture (Sec. 4), and
``kappas`` records every cascade target's κ at acquisition. ``noise_aware`` chooses the
recolor: the noise-aware one (:mod:`engine.trust`, the default of every new acquisition) or
the plain κ-weighted sum (:func:`engine.recolor.recolor`). An edit saved before the choice
existed has no ``noise_aware`` and reads as ``false``: it exports the image it exported then.

Older sessions still open: the app's ``state["edits"]`` (version 1) is read by
:meth:`Edit.from_json` too; the command line's old ``state["edit"] = {"kappa": [...]}``
is completed from the session's plan by :func:`engine.workflow.saved_edit`.

Exported images carry the edit under one metadata key, :data:`METADATA_KEY` (the file
attribute ``albedit:edit``), in the form :func:`export_metadata` gives.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass

import numpy as np

from engine.denoise import MAX_RADIUS
from engine.errors import InputError
from engine.session.paths import NAME
from engine.session.spec import Bool, Int, Invalid, List, Nullable, Num, Obj, Spec, Str, join

__all__ = [
    "EDIT_VERSION", "METADATA_KEY", "Edit", "EditAcquisition", "EditTarget", "check_target_name",
    "export_metadata", "mask_digest", "mask_name",
]

#: Version of the saved-edit schema (1 was the app's own ``"edits"``, before the engine owned it).
EDIT_VERSION = 2
#: The metadata key of the edit in every exported image (stored as the attribute ``albedit:edit``).
METADATA_KEY = "edit"

_MAX_NAME = 256
_CONTROL = re.compile(r"[\x00-\x1f\x7f]")
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")

_TARGET_NAME = Str(min_len=1, max_len=_MAX_NAME, expected=f"a target name (1-{_MAX_NAME} characters)")
_MASK_NAME = Str(pattern=NAME.pattern, expected="a session mask name")
_KAPPA = List(Num(0), length=3, expected="[r, g, b], three finite albedo scales >= 0")
_COLOUR = List(Int(0, 255), length=3, expected="[r, g, b], three integers in [0, 255]")
_CACHE_KEY = Str(pattern=NAME.pattern, expected="a cache key")

_EDIT_FIELDS = Obj(required={
    "version": Int(EDIT_VERSION, EDIT_VERSION),
    "targets": List(Obj(required={"name": _TARGET_NAME, "mask": _MASK_NAME, "kappa": _KAPPA},
                        optional={"colour": _COLOUR, "included": Bool()})),
    "current": Nullable(_TARGET_NAME),
    "photograph": Nullable(_MASK_NAME),
    "acquisition": Nullable(Obj(required={
        "cascade": List(_TARGET_NAME, min_len=1),
        "kappas": List(_KAPPA, min_len=1),
        "decomposition": _CACHE_KEY,
        "denoise": Int(0, MAX_RADIUS),
    }, optional={"noise_aware": Bool()})),
})



class _EditSpec(Spec):
    """The edit's fields, then what ties them together (unique names, a cascade of its targets)."""

    expected = "a saved edit"

    def check(self, value, path: str) -> None:
        _EDIT_FIELDS.check(value, path)
        _check_consistent(value, path)


#: The saved edit's schema (used by the manifest schema for ``state.edit``).
EDIT_SPEC = _EditSpec()

#: What ``albedit recolor`` wrote before the engine owned the edit: the free target's κ only.
LEGACY_CLI_EDIT_SPEC = Obj(required={"kappa": _KAPPA})

#: What the app wrote under ``state["edits"]`` before the engine owned the edit (version 1).
LEGACY_APP_EDIT_SPEC = Obj(
    required={"targets": List(Obj(required={"name": _TARGET_NAME, "mask": _MASK_NAME},
                                  optional={"kappa": _KAPPA, "colour": _COLOUR}))},
    optional={
        "version": Int(1, 1),
        "photograph": Nullable(_MASK_NAME),
        "current": Nullable(_TARGET_NAME),
        "acquisition": Obj(
            required={"key": _CACHE_KEY, "cascade": List(_TARGET_NAME, min_len=1)},
            optional={"kappas": List(_KAPPA), "constraint": Str(max_len=32), "unreached_light": Bool(),
                      "denoise": Int(0, MAX_RADIUS)},
        ),
    },
)


def check_target_name(name) -> str:
    """Return a target's display name if it is one a user could type, else raise InputError.

    Any text of 1 to 256 characters that is not only spaces and holds no control characters
    (line breaks, tabs) is a valid name.

    Examples
    --------
    >>> check_target_name("target 1"), check_target_name("Wand — links")
    ('target 1', 'Wand — links')
    """
    if not isinstance(name, str) or not name.strip() or len(name) > _MAX_NAME or _CONTROL.search(name):
        raise InputError(
            f"a target name must be 1-{_MAX_NAME} characters of text without line breaks or tabs, got {name!r}"
        )
    return name


def mask_digest(mask) -> str:
    """A 16-digit content digest of a mask (the acquisition plan records these).

    A ``(H, W) bool`` mask, or a soft mask (float coverage, :mod:`engine.edge`): one with
    coverage strictly between 0 and 1 hashes its float32 values, one of 0 and 1 only hashes
    as the boolean mask it is.

    Examples
    --------
    >>> mask_digest(np.eye(3, dtype=bool)), mask_digest(np.eye(3, dtype=np.float32))
    ('7ea7187532e1d4da', '7ea7187532e1d4da')
    >>> mask_digest(np.eye(3, dtype=np.float32) * 0.5)
    'f6fce89bcf4bb698'
    """
    arr = np.asarray(mask)
    if arr.dtype.kind == "f" and ((arr > 0) & (arr < 1)).any():
        data = b"coverage" + np.ascontiguousarray(arr, np.float32).tobytes()
    else:
        data = np.packbits(arr.astype(bool) if arr.dtype.kind != "f" else arr >= 1).tobytes()
    return hashlib.sha256(data).hexdigest()[:16]


def mask_name(target: str, digest: str) -> str:
    """The session mask name of target ``target`` whose mask has :func:`mask_digest` ``digest``.

    The one rule from display names to file names: the name's letters, digits and ``._-``
    (other runs of characters become ``_``), then the first 8 digits of the mask's digest. Two
    targets share a mask name only if they have the same pixels, so sharing the file is harmless.

    Examples
    --------
    >>> mask_name("target 1", "7ea7187532e1d4da"), mask_name("Wand — links", "7ea7187532e1d4da")
    ('target_1-7ea71875', 'Wand_links-7ea71875')
    """
    check_target_name(target)
    if not isinstance(digest, str) or not re.fullmatch(r"[0-9a-f]{8,64}", digest):
        raise InputError(f"digest must be hexadecimal digits from mask_digest(), got {digest!r}")
    slug = _UNSAFE.sub("_", target).strip("._-")[:64] or "target"
    return f"{slug}-{digest[:8]}"


@dataclass(frozen=True)
class EditTarget:
    """One target of a saved edit.

    Attributes
    ----------
    name : str
        Display name (any text, see :func:`check_target_name`).
    mask : str
        Name of the session mask holding its pixels (see :func:`mask_name`).
    kappa : (3,) tuple of float
        Albedo scale per channel.
    colour : (3,) tuple of int or None
        Overlay colour in the app.
    included : bool
        Whether the next acquisition measures it (False: painted for reference, left out).
    """

    name: str
    mask: str
    kappa: tuple[float, float, float] = (1.0, 1.0, 1.0)
    colour: tuple[int, int, int] | None = None
    included: bool = True


@dataclass(frozen=True)
class EditAcquisition:
    """The acquired cascade of a saved edit.

    Attributes
    ----------
    cascade : tuple of str
        Target names, first acquired to last; the last one's κ stays free.
    kappas : tuple of (3,) tuple of float
        Each cascade target's κ: the earlier ones' at acquisition (they shaped the emitted light),
        the last one's as edited (its target's κ).
    decomposition : str
        Session cache key of the last target's decomposition.
    denoise : int
        Noise-reduction radius in pixels (0: off), see :func:`engine.denoise.denoise_components`;
        it filters the plain recolor's decomposition.
    noise_aware : bool
        Recolor with :func:`engine.trust.recolor_trusted` (True) or plainly with
        :func:`engine.recolor.recolor` (False: also what edits saved before the choice read as).
    """

    cascade: tuple[str, ...]
    kappas: tuple[tuple[float, float, float], ...]
    decomposition: str
    denoise: int = 0
    noise_aware: bool = False


@dataclass(frozen=True)
class Edit:
    """A saved edit (see the module docstring for its JSON form).

    Attributes
    ----------
    targets : tuple of EditTarget
        In the app's list order.
    acquisition : EditAcquisition or None
    current : str or None
        The target selected in the app.
    photograph : str or None
        The capture the edit recolors (None: the session's photograph).
    """

    targets: tuple[EditTarget, ...] = ()
    acquisition: EditAcquisition | None = None
    current: str | None = None
    photograph: str | None = None

    def __post_init__(self) -> None:
        try:
            EDIT_SPEC.check(self.to_json(), "edit")
        except Invalid as exc:
            raise InputError(str(exc)) from None

    def target(self, name: str) -> EditTarget:
        """The target called ``name``; InputError if there is none."""
        for t in self.targets:
            if t.name == name:
                return t
        raise InputError(f"the edit has no target named {name!r}; it has {[t.name for t in self.targets]}")

    @property
    def kappa(self) -> tuple[float, float, float]:
        """κ the decomposition is recolored with: the last cascade target's (ones without an acquisition)."""
        if self.acquisition is None:
            return (1.0, 1.0, 1.0)
        return self.target(self.acquisition.cascade[-1]).kappa

    def to_json(self) -> dict:
        """The JSON form stored in the session's state."""
        acq = self.acquisition
        return {
            "version": EDIT_VERSION,
            "targets": [
                {"name": t.name, "mask": t.mask, "kappa": [float(k) for k in t.kappa],
                 **({} if t.colour is None else {"colour": [int(c) for c in t.colour]}),
                 **({} if t.included else {"included": False})}
                for t in self.targets
            ],
            "current": self.current,
            "photograph": self.photograph,
            "acquisition": None if acq is None else {
                "cascade": list(acq.cascade),
                "kappas": [[float(k) for k in kap] for kap in acq.kappas],
                "decomposition": acq.decomposition,
                "denoise": int(acq.denoise),
                "noise_aware": bool(acq.noise_aware),
            },
        }

    @classmethod
    def from_json(cls, data, where: str = "state.edit") -> Edit:
        """Read a saved edit: this schema, or the app's version 1 (``state["edits"]``).

        Raises
        ------
        InputError
            A field does not fit the schema (the message names its path under ``where``).
        """
        try:
            if isinstance(data, dict) and data.get("version", 1) == 1 and "targets" in data:
                LEGACY_APP_EDIT_SPEC.check(data, where)
                data = _from_version_1(data)
            EDIT_SPEC.check(data, where)
        except Invalid as exc:
            raise InputError(str(exc)) from None
        acq = data["acquisition"]
        return cls(
            targets=tuple(EditTarget(t["name"], t["mask"], tuple(t["kappa"]),
                                     None if "colour" not in t else tuple(t["colour"]), bool(t.get("included", True)))
                          for t in data["targets"]),
            acquisition=None if acq is None else EditAcquisition(
                tuple(acq["cascade"]), tuple(tuple(k) for k in acq["kappas"]), acq["decomposition"], acq["denoise"],
                bool(acq.get("noise_aware", False))),
            current=data["current"],
            photograph=data["photograph"],
        )


def _from_version_1(data: dict) -> dict:
    acq = data.get("acquisition")
    kappas = {t["name"]: t.get("kappa", [1.0, 1.0, 1.0]) for t in data["targets"]}
    return {
        "version": EDIT_VERSION,
        "targets": [{"name": t["name"], "mask": t["mask"], "kappa": t.get("kappa", [1.0, 1.0, 1.0]),
                     **({"colour": t["colour"]} if "colour" in t else {})} for t in data["targets"]],
        "current": data.get("current"),
        "photograph": data.get("photograph"),
        "acquisition": None if acq is None else {
            "cascade": acq["cascade"],
            "kappas": acq.get("kappas") or [kappas.get(n, [1.0, 1.0, 1.0]) for n in acq["cascade"]],
            "decomposition": acq["key"],
            "denoise": acq.get("denoise", 0),
        },
    }


def _check_consistent(data: dict, where: str) -> None:
    names = [t["name"] for t in data["targets"]]
    for i, name in enumerate(names):
        if name in names[:i]:
            raise Invalid(join(where, "targets") + f"[{i}].name", "unique", name,
                          message=f"{where}.targets[{i}] repeats the target name {name!r}")
        try:
            check_target_name(name)
        except InputError:
            raise Invalid(join(where, "targets") + f"[{i}].name", "a name without line breaks or tabs", name) from None
    if data["current"] is not None and data["current"] not in names:
        raise Invalid(f"{where}.current", f"null or one of the targets {names}", data["current"])
    acq = data["acquisition"]
    if acq is not None:
        for i, name in enumerate(acq["cascade"]):
            if name not in names:
                raise Invalid(f"{where}.acquisition.cascade[{i}]", f"one of the targets {names}", name)
        if len(set(acq["cascade"])) != len(acq["cascade"]):
            raise Invalid(f"{where}.acquisition.cascade", "a list of distinct target names", acq["cascade"])
        if len(acq["kappas"]) != len(acq["cascade"]):
            raise Invalid(f"{where}.acquisition.kappas", f"one κ per cascade target ({len(acq['cascade'])})",
                          acq["kappas"])


def export_metadata(edit: Edit, *, source: str, pixels: dict[str, int], order: int | None,
                    constraint: str | None, recolor: str | None = None) -> dict:
    """The edit as an exported image carries it under :data:`METADATA_KEY`.

    Parameters
    ----------
    edit : Edit
    source : str
        Where the photograph came from: the session's rig name or the image file.
    pixels : dict of str to int
        Painted pixels per target name.
    order : int or None
        K of the decomposition recolored (None: nothing acquired).
    constraint : str or None
        The decomposition's constraint mode.
    recolor : str or None
        The recolor the image was made with: ``"noise-aware"``, ``"plain"`` (None: nothing acquired).

    Returns
    -------
    dict
        ``{"version", "source", "targets": [{"name", "kappa", "pixels", "cascade_position",
        "acquired"}], "cascade", "kappa", "order", "constraint", "denoise", "recolor"}``; exporters add
        ``"display"`` (8-bit files) or ``"linear"`` (float and 16-bit files).
    """
    cascade = [] if edit.acquisition is None else list(edit.acquisition.cascade)
    return {
        "version": EDIT_VERSION,
        "source": str(source),
        "targets": [
            {"name": t.name, "kappa": [float(k) for k in t.kappa], "pixels": int(pixels.get(t.name, 0)),
             "cascade_position": i + 1, "acquired": t.name in cascade}
            for i, t in enumerate(edit.targets)
        ],
        "cascade": cascade,
        "kappa": [float(k) for k in edit.kappa],
        "order": None if order is None else int(order),
        "constraint": None if constraint is None else str(constraint),
        "denoise": 0 if edit.acquisition is None else int(edit.acquisition.denoise),
        "recolor": None if recolor is None else str(recolor),
    }
