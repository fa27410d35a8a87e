"""Scenes of the path-traced rig: a Mitsuba 3 scene plus a small JSON naming its targets.

A rig file (``resources/mitsuba/NAME.json``, or any path) is a JSON object::

    {
      "name": "wedge",
      "description": "...",
      "scene": "virtual:wedge",            # or "scene.xml", relative to this file
      "targets": {"left": ["left_wall"]},  # target name -> shape ids (optional for virtual: scenes)
      "materials": {"left_wall": {"specular": 0.05, "roughness": 0.1}},   # glossy coats (virtual: scenes)
      "projector": {"power": [r, g, b], "offset": {"position": [...], "look_at": [...],
                    "up": [...], "fov_deg": 40}}                          # XML scenes only
    }

``"virtual:NAME"`` builds the Mitsuba scene from a virtual-rig scene (same geometry, albedo,
textures, lights, camera and offset projector pose; its box faces become shapes
``box_front`` ...; its whole-surface targets are the default targets). An XML scene brings
its own sensor (the camera), its emitters (the light that is not the projector) and its
shapes (their BSDFs too: ``materials`` is refused there); the projector is added by the rig.
A glossy coat replaces a shape's diffuse BSDF by
``(1 - specular) * diffuse + specular * (a rough conductor of GGX roughness alpha)``: the
diffuse and specular weights sum to 1. The conductor's reflectance is the coat's ``"tint"``:
``"white"`` (the default: reflectance 1) or ``"albedo"`` (the shape's diffuse reflectance,
which must be one uniform colour). Only a tinted coat makes ``specular`` the paper's Fig. 13
"specular albedo as a share of the total albedo" in every channel; a white coat over a diffuse
albedo rho has the share ``s / (s + (1 - s) * rho)`` (s = 0.1 over the wedge's (0.6, 0.2, 0.6)
paint: 16 / 36 / 16 %)::

    "materials": {"left_wall": {"specular": 0.1, "roughness": 0.05, "tint": "albedo"}}
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from engine.errors import InputError

RIG_DIR = Path(__file__).resolve().parents[2] / "resources" / "mitsuba"

_TOP_KEYS = {"name", "description", "scene", "targets", "materials", "projector"}


@dataclass(frozen=True, eq=False)
class RigScene:
    """A validated rig file.

    Attributes
    ----------
    name, description : str
    scene : str
        ``"virtual:NAME"`` or an absolute path to a Mitsuba XML file.
    targets : dict[str, list[str]]
        Target name -> shape ids.
    materials : dict[str, dict]
        Shape id -> ``{"specular": s, "roughness": alpha}``.
    power : (3,) float64 or None
        Projector power (XML scenes; virtual scenes take the virtual scene's).
    offset : dict or None
        The offset projector's pose (XML scenes).
    digest : str
        SHA-256 of the rig file and the scene it names (for caches).
    """

    name: str
    description: str
    scene: str
    targets: dict
    materials: dict = field(default_factory=dict)
    power: np.ndarray | None = None
    offset: dict | None = None
    digest: str = ""


def rig_names() -> list[str]:
    """Names of the rig files shipped in ``resources/mitsuba``.

    Examples
    --------
    >>> "cornell" in rig_names()
    True
    """
    return sorted(p.stem for p in RIG_DIR.glob("*.json"))


def load_rig_scene(name_or_path: str | Path) -> RigScene:
    """Load and validate a rig file by name (``"cornell"``) or path.

    Raises
    ------
    InputError
        Unknown name, unreadable or malformed file, or a field with a bad value (named).

    Examples
    --------
    >>> load_rig_scene("cornell").targets["right_wall"]
    ['right_wall']
    """
    text = str(name_or_path)
    if text.endswith(".json") or "/" in text or "\\" in text:
        path = Path(text)
    else:
        path = RIG_DIR / f"{text}.json"
        if not path.is_file():
            raise InputError(
                f"unknown mitsuba rig scene {text!r}; expected one of {rig_names()} or a path to a .json file"
            )
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(f"cannot read mitsuba rig file {str(path)!r}: {exc}") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"mitsuba rig file {str(path)!r} is not valid JSON: {exc}") from None
    if not isinstance(data, dict):
        raise InputError(f"a mitsuba rig file must be a JSON object, got {type(data).__name__}")
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise InputError(f"unknown field(s) {unknown} in {path.name}; expected some of {sorted(_TOP_KEYS)}")
    if "scene" not in data or not isinstance(data["scene"], str) or not data["scene"]:
        raise InputError(f'{path.name} must name its scene: "scene": "virtual:NAME" or a Mitsuba .xml file')
    scene = data["scene"]
    blobs = [json.dumps(data, sort_keys=True)]
    if scene.startswith("virtual:"):
        from devices.virtual.scene import load_scene

        virtual = load_scene(scene.partition(":")[2])
        blobs.append(virtual.digest)
        default_targets = _virtual_targets(virtual)
    else:
        xml = (path.parent / scene).resolve()
        if not xml.is_file():
            raise InputError(f"{path.name}: scene file {str(xml)!r} does not exist")
        blobs.append(hashlib.sha256(xml.read_bytes()).hexdigest())
        scene = str(xml)
        default_targets = {}
    targets = data.get("targets", default_targets)
    if not isinstance(targets, dict) or not targets:
        raise InputError(f"{path.name}: targets must map target names to lists of shape ids, got {targets!r:.80}")
    for tname, ids in targets.items():
        if not isinstance(ids, list) or not ids or not all(isinstance(i, str) and i for i in ids):
            raise InputError(f"{path.name}: targets[{tname!r}] must be a non-empty list of shape ids, got {ids!r:.80}")
    materials = data.get("materials", {})
    if not isinstance(materials, dict):
        raise InputError(f"{path.name}: materials must map shape ids to {{'specular': s, 'roughness': alpha}}")
    for sid, m in materials.items():
        check_coat(m, f"materials[{sid!r}]")
    if materials and not scene.startswith("virtual:"):  # the XML's own BSDFs would be used, silently
        raise InputError(f"{path.name}: materials (glossy coats) apply to virtual: scenes only; give the shapes of "
                         f"{data['scene']!r} their BSDFs in the XML")
    proj = data.get("projector", {})
    if not isinstance(proj, dict) or sorted(set(proj) - {"power", "offset"}):
        raise InputError(f"{path.name}: projector must be an object with optional 'power' and 'offset'")
    power = proj.get("power")
    if power is not None:
        power = np.asarray(power, np.float64)
        if power.shape != (3,) or not np.all(np.isfinite(power)) or np.any(power <= 0):
            raise InputError(f"{path.name}: projector.power must be three positive numbers, got {proj['power']!r}")
    return RigScene(
        name=str(data.get("name", path.stem)),
        description=str(data.get("description", "")),
        scene=scene,
        targets={str(k): list(v) for k, v in targets.items()},
        materials={str(k): dict(v) for k, v in materials.items()},
        power=power,
        offset=proj.get("offset"),
        digest=hashlib.sha256("\n".join(blobs).encode()).hexdigest(),
    )


TINTS = ("white", "albedo")


def check_coat(coat, where: str) -> dict:
    """Validate a glossy coat ``{"specular": s in [0, 1], "roughness": alpha in (0, 1]}`` with an
    optional ``"tint"`` in :data:`TINTS` (see the module docstring).

    Returns the coat with float weights; ``"tint"`` is kept only when it is not the default white.

    Raises
    ------
    InputError
        A missing or unknown key, a weight out of range, an unknown tint.

    Examples
    --------
    >>> check_coat({"specular": 0.1, "roughness": 0.05, "tint": "white"}, "coat")
    {'specular': 0.1, 'roughness': 0.05}
    """
    if (
        not isinstance(coat, dict)
        or not {"roughness", "specular"} <= set(coat)
        or not set(coat) <= {"roughness", "specular", "tint"}
    ):
        raise InputError(f"{where} must be {{'specular': s, 'roughness': alpha}} (optional 'tint'), got {coat!r:.80}")
    tint = coat.get("tint", "white")
    if tint not in TINTS:
        raise InputError(f"{where}.tint must be one of {list(TINTS)}, got {tint!r:.40}")
    s, r = coat["specular"], coat["roughness"]
    for name, v, lo_open in (("specular", s, False), ("roughness", r, True)):
        if (
            isinstance(v, bool)
            or not isinstance(v, (int, float))
            or not np.isfinite(v)
            or not ((0 < v) if lo_open else (0 <= v))
            or v > 1
        ):
            raise InputError(f"{where}.{name} must be in {'(0' if lo_open else '[0'}, 1], got {v!r}")
    out = {"specular": float(s), "roughness": float(r)}
    return out if tint == "white" else dict(out, tint=tint)


def shape_id(surface_name: str) -> str:
    """Mitsuba shape id of a virtual-scene surface (``.`` is reserved in Mitsuba ids).

    Examples
    --------
    >>> shape_id("short_box.front")
    'short_box_front'
    """
    return surface_name.replace(".", "_")


def _virtual_targets(scene) -> dict:
    out = {}
    for tname, pieces in scene.targets.items():
        if all(rect == (0.0, 0.0, 1.0, 1.0) for _, rect in pieces):
            out[tname] = [shape_id(scene.names[q]) for q, _ in pieces]
    return out


def _mirror():
    """Mitsuba's image x axis runs opposite to the virtual rig's: mirror the views."""
    import mitsuba as mi

    return mi.ScalarTransform4f().scale([-1.0, 1.0, 1.0])


def look_at(pose: dict | object, *, mirror: bool):
    """A Mitsuba ``to_world`` for a pinhole pose (``position``, ``look_at``, ``up``)."""
    import mitsuba as mi

    get: Callable[..., Any] = pose.get if isinstance(pose, dict) else lambda k, d=None: getattr(pose, k, d)
    tw = mi.ScalarTransform4f().look_at(
        origin=[float(x) for x in get("position")],
        target=[float(x) for x in get("look_at")],
        up=[float(x) for x in get("up", (0, 1, 0))],
    )
    return tw @ _mirror() if mirror else tw


def coated(diffuse: dict, coat: dict, where: str = "coat") -> dict:
    """A diffuse BSDF dict with a glossy coat (see the module docstring).

    Raises
    ------
    InputError
        A coat tinted like the albedo over a textured diffuse reflectance.
    """
    spec = {"type": "rgb", "value": [1.0, 1.0, 1.0]}
    if coat.get("tint", "white") == "albedo":
        if diffuse["reflectance"]["type"] != "rgb":
            raise InputError(f"{where}: tint 'albedo' needs a uniform diffuse colour, but the shape is textured")
        spec = dict(diffuse["reflectance"], value=list(diffuse["reflectance"]["value"]))
    return {
        "type": "blendbsdf",
        "weight": float(coat["specular"]),
        "diffuse": diffuse,
        "specular": {
            "type": "roughconductor",
            "distribution": "ggx",
            "alpha": float(coat["roughness"]),
            "material": "none",
            "specular_reflectance": spec,
        },
    }


def _quad_transform(o, u, v):
    import mitsuba as mi

    n = np.cross(u, v)
    n = n / np.linalg.norm(n)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = u / 2, v / 2, n, o + u / 2 + v / 2
    return mi.ScalarTransform4f(m.tolist())


def _reflectance(scene, q: int) -> dict:
    """Diffuse reflectance of virtual quad ``q``: a constant, or a bitmap of its texture."""
    import mitsuba as mi

    tex = scene.textures.get(q)
    if tex is None:
        return {"type": "rgb", "value": [float(x) for x in scene.albedo[q]]}
    if tex.kind == "image":
        hi, wi = tex.image.shape[:2]
    else:
        wi, hi = tex.cells
    # texel centres in (a, b); Mitsuba's rectangle uv has v running against b (bitmap row 0 at b = 1)
    a, b = np.meshgrid((np.arange(wi) + 0.5) / wi, (np.arange(hi) + 0.5) / hi)
    rho = tex.sample(scene.albedo[q], a.ravel(), b.ravel()).reshape(hi, wi, 3)[::-1]
    return {
        "type": "bitmap",
        "bitmap": mi.Bitmap(np.ascontiguousarray(rho, np.float32)),
        "raw": True,
        "filter_type": "nearest",
        "wrap_mode": "clamp",
    }


def virtual_scene_dict(scene, materials: dict) -> dict:
    """Shapes and lights of a virtual-rig scene as a Mitsuba scene dict (no sensor, no projector)."""
    out = {}
    q = scene.quads
    for i, name in enumerate(scene.names):
        sid = shape_id(name)
        bsdf = {"type": "diffuse", "reflectance": _reflectance(scene, i)}
        if sid in materials:
            bsdf = coated(bsdf, materials[sid], f"materials[{sid!r}]")
        shape = {"type": "rectangle", "to_world": _quad_transform(q.origin[i], q.u[i], q.v[i]), "bsdf": bsdf}
        if np.any(scene.emission[i] > 0):
            shape["emitter"] = {
                "type": "area",
                "radiance": {"type": "rgb", "value": [float(x) for x in scene.emission[i]]},
            }
        out[sid] = shape
    unknown = sorted(set(materials) - set(out))
    if unknown:
        raise InputError(f"materials name unknown shape(s) {unknown}; shapes: {sorted(out)}")
    return out
