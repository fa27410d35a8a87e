"""The manifest schema: every field of ``manifest.json``, its type and its range, checked in one place.

:func:`validate_manifest` runs on every :meth:`engine.session.Session.open` (and on every
manifest the session re-reads before changing it); :func:`validate_state` runs on every
:meth:`engine.session.Session.update`, so the session never writes what it would refuse to
read. A refusal names the field's path as it appears in the file, e.g.
``state.plan.order must be an integer in [1, 8] or 'auto', got '3'``.

The JSON state holds the acquisition plan (:func:`engine.workflow.capture_plan`), its status
and result, the saved edit (:mod:`engine.session.edit`) and the colour facts
(:mod:`engine.session.colour`); other keys are free JSON for
callers, but the known ones are checked field by field.
"""

from __future__ import annotations

from engine.figurate import MAX_ORDER
from engine.session.colour import COLOUR_SPEC
from engine.session.edit import EDIT_SPEC, LEGACY_APP_EDIT_SPEC, LEGACY_CLI_EDIT_SPEC
from engine.session.paths import NAME
from engine.session.spec import (
    ANY,
    Bool,
    Const,
    Int,
    Invalid,
    List,
    Map,
    Nullable,
    Num,
    Obj,
    OneOf,
    Str,
    join,
)

__all__ = ["FINGERPRINT", "FORMAT", "SCHEMA_VERSION", "STATE", "validate_manifest", "validate_state"]

FORMAT = "albedit-session"
#: The manifest schema this version writes and reads. Newer manifests are refused.
SCHEMA_VERSION = 1

_MAX_SIDE = 1 << 16
NAME_SPEC = Str(pattern=NAME.pattern, expected="a session file name (1-128 letters, digits, '.', '_', '-')")
_RESOLUTION = List(Int(1, _MAX_SIDE), length=2, expected="[height, width], two positive integers")
_COUNT = Int(0)
_KAPPA = List(Num(0), length=3, expected="[r, g, b], three finite albedo scales >= 0")
_DTYPE = Str(pattern=r"[<>|=][biufc](1|2|4|8|16)", expected="a numeric dtype such as '<f4' or '|b1'")

_META = Obj(
    optional={
        "exposure": Num(0),
        "gain": Num(positive=True),
        "black_level": Num(),
        "metadata": Obj(extra=ANY),
        "kind": Str(max_len=64),
        "frames": Int(1),
    },
    extra=ANY,
)

_CAPTURE = Obj(required={
    "name": NAME_SPEC,
    "file": Str(min_len=1),
    "pattern_id": Str(min_len=1, max_len=256),
    "meta": _META,
    "shape": List(Int(1, _MAX_SIDE), length=3, expected="[height, width, 3]"),
    "saturated": Bool(),
    "sha256": Str(pattern="[0-9a-f]{64}", expected="64 hexadecimal digits"),
    "bytes": _COUNT,
    "time": Str(min_len=1, max_len=64),
})

_SETTINGS = Obj(required={
    "per_channel": Bool(),
    "differences": Bool(),
    "tau": Num(0, 1, positive=True),
    "negative": Str(choices=("clamp", "split")),
}, optional={"complete_direct": Bool(), "stand_in": Bool(), "spread": Bool()})

_ADAPTIVE = Obj(required={
    "policy": Str(choices=("brute", "linear", "span")),
    "threshold": Num(0, 1, positive=True),
}, optional={"noise_band": Bool()})  # engine.acquire.Adaptive.to_dict (absent in plans saved before it)

#: The acquisition plan (:func:`engine.workflow.capture_plan`).
PLAN = Obj(required={
    "targets": List(Str(min_len=1, max_len=256), min_len=1, expected="a list of target names (at least one)"),
    "masks": List(Str(pattern="[0-9a-f]{16}", expected="a 16-digit mask digest")),
    "order": OneOf(Int(1, MAX_ORDER), Const("auto"), expected=f"an integer in [1, {MAX_ORDER}] or 'auto'"),
    "fixed_kappa": List(_KAPPA),
    "settings": _SETTINGS,
    "adaptive": Nullable(_ADAPTIVE),
    "photograph_pattern": Bool(),
})

_LOG_ENTRY = Obj(
    required={"index": _COUNT, "source": Str(choices=("photograph", "captured", "predicted")),
              "captures": List(NAME_SPEC)},
    extra=ANY,
)

#: What a finished capture reports (:func:`engine.workflow.run_capture`).
RESULT = Obj(required={
    "images": _COUNT,
    "predicted": _COUNT,
    "captures": _COUNT,
    "clamped": _COUNT,
    "unreachable": Map(Str(min_len=1, max_len=256), _COUNT),
    "estimated": _COUNT,
    "log": List(_LOG_ENTRY),
}, optional={
    "unblended": _COUNT,  # a soft mask's edge pixels left as non-target (engine.edge.unblended); absent before
})

#: The session's JSON state: known keys checked, others free.
STATE = Obj(
    optional={
        "plan": PLAN,
        "status": Str(choices=("capturing", "captured")),
        "result": RESULT,
        "edit": OneOf(EDIT_SPEC, LEGACY_CLI_EDIT_SPEC, expected="a saved edit"),
        "edits": LEGACY_APP_EDIT_SPEC,
        "photograph": NAME_SPEC,
        "order": Int(1),
        "colour": COLOUR_SPEC,
    },
    extra=ANY,
)

#: What a rig's calibration depends on (:attr:`engine.rig.RigLike.fingerprint`): named plain values.
_PLAIN = OneOf(Str(max_len=1024), Num(), Bool(), expected="a string, number or boolean")
FINGERPRINT = Map(Str(min_len=1, max_len=64), OneOf(_PLAIN, List(_PLAIN, max_len=64),
                                                   expected="a string, number, boolean or a list of them"))

_MASK = Obj(required={"file": Str(min_len=1), "shape": _RESOLUTION}, optional={"soft": Bool()})
_ARRAY_KEY = Str(pattern=f"{NAME.pattern}/{NAME.pattern}", expected="'group/name'")
_ARRAY = Obj(required={"file": Str(min_len=1), "shape": List(Int(0)), "dtype": _DTYPE})

MANIFEST = Obj(required={
    "format": Const(FORMAT),
    "schema_version": Int(),
    "created": Str(max_len=64),
    "rig": Obj(required={"name": Str(min_len=1, max_len=1024), "camera_resolution": _RESOLUTION,
                         "projector_resolution": _RESOLUTION}, optional={"fingerprint": FINGERPRINT}),
    "metadata": Obj(extra=ANY),
    "state": STATE,
    "masks": Map(NAME_SPEC, _MASK),
    "calibration": Obj(required={"data": Obj(extra=ANY), "arrays": Map(_ARRAY_KEY, _ARRAY)}),
    "captures": List(_CAPTURE),
})


def validate_state(state) -> None:
    """Check the JSON state (known keys field by field); :class:`Invalid` naming the path under ``state``."""
    STATE.check(state, "state")
    plan = state.get("plan")
    if plan is not None:
        n = len(plan["targets"])
        if len(set(plan["targets"])) != n:
            raise Invalid("state.plan.targets", "a list of distinct names", plan["targets"])
        if len(plan["masks"]) != n:
            raise Invalid("state.plan.masks", f"one digest per target ({n})", plan["masks"])
        if len(plan["fixed_kappa"]) != n - 1:
            raise Invalid("state.plan.fixed_kappa", f"the κ of every target but the last ({n - 1})",
                          plan["fixed_kappa"])


def validate_manifest(manifest) -> None:
    """Check a parsed ``manifest.json`` against the schema, field by field.

    Raises
    ------
    Invalid
        The first field that does not fit, named by its path (``captures[3].meta.exposure``).
        The format and schema version are checked first: a manifest of a newer Albedit is
        reported as such, not as a list of unknown fields.
    """
    if not isinstance(manifest, dict):
        raise Invalid("the manifest", "a JSON object", type(manifest).__name__)
    if manifest.get("format") != FORMAT:
        raise Invalid("format", f"{FORMAT!r} (not an Albedit session manifest)", manifest.get("format"))
    version = manifest.get("schema_version")
    if isinstance(version, bool) or not isinstance(version, int):
        raise Invalid("schema_version", "an integer", version)
    if version > SCHEMA_VERSION:
        raise Invalid("schema_version", str(SCHEMA_VERSION), version, message=(
            f"schema_version {version}, newer than this Albedit reads ({SCHEMA_VERSION}); upgrade Albedit"))
    if version != SCHEMA_VERSION:
        raise Invalid("schema_version", str(SCHEMA_VERSION), version, message=(
            f"unknown schema_version {version} (this Albedit reads {SCHEMA_VERSION})"))
    MANIFEST.check(manifest, "")
    validate_state(manifest["state"])
    camera = manifest["rig"]["camera_resolution"]
    names = set()
    for i, entry in enumerate(manifest["captures"]):
        path = join("captures", i)
        if entry["shape"] != [*camera, 3]:
            raise Invalid(f"{path}.shape", f"[{camera[0]}, {camera[1]}, 3] (the camera resolution)", entry["shape"])
        if entry["name"] in names:
            raise Invalid(f"{path}.name", "unique", entry["name"], message=f"{path} repeats the name {entry['name']!r}")
        names.add(entry["name"])
    for name, entry in manifest["masks"].items():
        if entry["shape"] != camera:
            raise Invalid(join("masks", name) + ".shape", f"{camera} (the camera resolution)", entry["shape"])

