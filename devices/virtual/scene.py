"""Scenes of the virtual rig: JSON data in ``resources/scenes/``, validated on load.

A scene file is a JSON object::

    {
      "name": "wedge",
      "description": "...",
      "camera":    {"position": [x, y, z], "look_at": [x, y, z], "up": [x, y, z], "fov_deg": 40},
      "projector": {"power": [r, g, b],
                    "offset": {"position": [...], "look_at": [...], "up": [...], "fov_deg": 44}},
      "surfaces":  [{"name": "floor", "corners": [[x, y, z], x4], "albedo": [r, g, b],
                     "emission": [r, g, b], "texture": {...}}, ...],
      "boxes":     [{"name": "box", "base_center": [x, y, z], "size": [sx, sy, sz],
                     "rotation_deg": 15, "albedo": [r, g, b]}, ...],
      "targets":   {"left": [{"surface": "left_wall", "rect": [a0, b0, a1, b1]}], ...},
      "lighting":  {"ambient": false, "projector_flood": 1.0},
      "patch_size": 0.1
    }

Units are metres; y is up. ``corners`` are ``p0, p1, p2, p3`` of a planar parallelogram,
counter-clockwise seen from its front (the lit, visible side; the back side is black).
``emission`` (optional, radiance, >= 0) makes a surface an ambient light. ``texture``
(optional) varies the albedo over a surface (paper Fig. 12): ``{"pattern": "checker" |
"stripes", "cells": [nu, nv], "albedo": [r, g, b]}`` alternates the surface's albedo with
``albedo`` on an ``nu x nv`` grid of cells (stripes alternate along ``a`` only), and
``{"image": "file.png"}`` (a path relative to the scene file) multiplies the surface's albedo
by the image's values scaled to [0, 1] (image columns along ``a``, rows along ``b``, first row at
``b = 0``; grey or RGB; the values are used as they are, not sRGB-decoded). A box expands to
five outward-facing quads named ``NAME.top``, ``NAME.front`` (-z), ``NAME.back`` (+z),
``NAME.left`` (-x) and ``NAME.right`` (+x) before rotation about y. A target lists surfaces,
optionally restricted to the sub-rectangle ``[a0, b0, a1, b1]`` of local coordinates
(``a`` along ``p1 - p0``, ``b`` along ``p3 - p0``, both in [0, 1]). ``lighting`` is the
scene's natural lighting, a hint for tools: the ambient light on or off, and a uniform
projector input level (0 = projector black). ``patch_size`` (metres) sets the grid on which
indirect light is computed.

Over 500 lines on purpose: the scene file's whole schema (quads, boxes, textures, lighting) is
validated in one place, so every message about a bad scene file comes from the same rules.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from devices.virtual.geometry import Quads
from engine.errors import InputError

SCENE_DIR = Path(__file__).resolve().parents[2] / "resources" / "scenes"

#: Largest scene file read (scenes are a few kB; this keeps a wrong path such as a device from being read).
MAX_SCENE_BYTES = 16 * 1024 * 1024
#: Largest radiance a surface may emit and projector power (far beyond any camera's full scale).
MAX_RADIANCE = 1e6

_TOP_KEYS = {"name", "description", "camera", "projector", "surfaces", "boxes", "targets",
             "lighting", "patch_size"}


@dataclass(frozen=True)
class Pose:
    """A pinhole pose: centre, point looked at, up vector, vertical field of view (degrees)."""

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    up: tuple[float, float, float]
    fov_deg: float


@dataclass(frozen=True, eq=False)
class Texture:
    """Albedo that varies over one surface (the surface's ``texture`` field).

    Attributes
    ----------
    kind : {"checker", "stripes", "image"}
    cells : (nu, nv)
        Pattern cells along ``a`` and ``b`` (patterns only).
    albedo : (3,) float64
        The second albedo of a pattern (patterns only).
    image : (Hi, Wi, 3) float64 or None
        Multipliers in [0, 1], rows along ``b`` (row 0 at ``b = 0``), columns along ``a``.
    """

    kind: str
    cells: tuple[int, int] = (1, 1)
    albedo: np.ndarray | None = None
    image: np.ndarray | None = None

    def sample(self, base: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Albedo ``(N, 3)`` at local coordinates ``a``, ``b`` (N,) of a surface of albedo ``base``.

        Examples
        --------
        >>> t = Texture("checker", (2, 2), np.array([0.5, 0.5, 0.5]))
        >>> t.sample(np.array([0.1, 0.1, 0.1]), np.array([0.2, 0.7]), np.array([0.2, 0.2]))[:, 0].tolist()
        [0.1, 0.5]
        """
        a = np.clip(np.asarray(a, np.float64), 0.0, 1.0)
        b = np.clip(np.asarray(b, np.float64), 0.0, 1.0)
        if self.kind == "image":
            assert self.image is not None  # an image texture always holds its image
            hi, wi = self.image.shape[:2]
            col = np.minimum((a * wi).astype(np.int64), wi - 1)
            row = np.minimum((b * hi).astype(np.int64), hi - 1)
            return base[None, :] * self.image[row, col]
        nu, nv = self.cells
        iu = np.minimum((a * nu).astype(np.int64), nu - 1)
        iv = np.minimum((b * nv).astype(np.int64), nv - 1)
        odd = (iu + (iv if self.kind == "checker" else 0)) % 2 == 1
        assert self.albedo is not None  # a pattern always holds its second albedo
        return np.where(odd[:, None], self.albedo[None, :], base[None, :])

    def cell(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(N,) int64 id of the texel (image) or pattern cell at ``a``, ``b`` (for edge detection)."""
        a = np.clip(np.asarray(a, np.float64), 0.0, 1.0)
        b = np.clip(np.asarray(b, np.float64), 0.0, 1.0)
        if self.kind == "image":
            assert self.image is not None  # an image texture always holds its image
            nu, nv = self.image.shape[1], self.image.shape[0]
        else:
            nu, nv = self.cells
        iu = np.minimum((a * nu).astype(np.int64), nu - 1)
        iv = np.minimum((b * nv).astype(np.int64), nv - 1)
        return iv * nu + iu


@dataclass(frozen=True, eq=False)
class Scene:
    """A validated scene.

    Attributes
    ----------
    name, description : str
    quads : Quads
        All surfaces (those of boxes included), ``Q`` quads.
    names : tuple of str
        Surface names, one per quad.
    albedo : (Q, 3) float64
        Diffuse albedo per channel, in [0, 1).
    emission : (Q, 3) float64
        Emitted radiance (0 except for lights).
    camera : Pose
    projector_offset : Pose or None
        The offset projector's pose (None: the scene only supports the co-axial projector).
    projector_power : (3,) float64
        Irradiance (divided by pi) per channel of full projector white on a surface facing
        the projector on its axis at 1 m.
    targets : dict[str, list[tuple[int, tuple[float, float, float, float]]]]
        Target name -> (quad index, sub-rectangle) pieces.
    lighting : dict
        ``{"ambient": bool, "projector_flood": float}``, the scene's natural lighting.
    patch_size : float
        Edge length (m) of the patches used for indirect light.
    digest : str
        SHA-256 of the canonical JSON (and of any texture image), for caches.
    textures : dict[int, Texture]
        Quad index -> texture, for the surfaces that have one.
    """

    name: str
    description: str
    quads: Quads
    names: tuple[str, ...]
    albedo: np.ndarray
    emission: np.ndarray
    camera: Pose
    projector_offset: Pose | None
    projector_power: np.ndarray
    targets: dict[str, list[tuple[int, tuple[float, float, float, float]]]]
    lighting: dict = field(default_factory=dict)
    patch_size: float = 0.1
    digest: str = ""
    textures: dict = field(default_factory=dict)

    def albedo_at(self, quad: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Albedo ``(N, 3)`` float64 of points on quads ``quad`` (N,) at local ``a``, ``b``.

        ``quad`` may hold -1 (no surface): albedo 0 there.
        """
        quad = np.asarray(quad)
        live = quad >= 0
        out = np.where(live[:, None], self.albedo[np.maximum(quad, 0)], 0.0)
        for q, tex in self.textures.items():
            sel = np.flatnonzero(quad == q)
            if sel.size:
                out[sel] = tex.sample(self.albedo[q], np.asarray(a)[sel], np.asarray(b)[sel])
        return out


def scene_names() -> list[str]:
    """Names of the scenes shipped in ``resources/scenes`` (file names without ``.json``).

    Examples
    --------
    >>> {"cornell", "wedge", "three"} <= set(scene_names())
    True
    """
    return sorted(p.stem for p in SCENE_DIR.glob("*.json"))


def load_scene(name_or_path: str | Path) -> Scene:
    """Load and validate a scene by name (``"cornell"``) or from a JSON file path.

    Parameters
    ----------
    name_or_path : str or Path
        A name from :func:`scene_names`, or a path to a ``.json`` file.

    Returns
    -------
    Scene

    Raises
    ------
    InputError
        Unknown name, unreadable file, malformed JSON, missing field or a physically
        impossible value; the message names the field, e.g.
        ``surfaces[3].albedo must be in [0, 1), got [1.2, 0.5, 0.5]``.

    Examples
    --------
    >>> s = load_scene("wedge")
    >>> sorted(s.targets)
    ['left', 'right', 'union']
    """
    text = str(name_or_path)
    if text.endswith(".json") or "/" in text or "\\" in text:
        path = Path(text)
    else:
        path = SCENE_DIR / f"{text}.json"
        if not path.is_file():
            raise InputError(f"unknown virtual scene {text!r}; "
                             f"expected one of {scene_names()} or a path to a .json file")
    try:
        if not path.exists():
            raise InputError(f"cannot read scene file {str(path)!r}: there is no such file")
        if not path.is_file():
            why = "it is not a regular file (a device or a folder)" if path.exists() else "no such file"
            raise InputError(f"cannot read scene file {str(path)!r}: {why}")
        if path.stat().st_size > MAX_SCENE_BYTES:
            raise InputError(f"scene file {str(path)!r} is larger than {MAX_SCENE_BYTES} bytes; a scene is a few kB")
        raw = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read scene file {str(path)!r}: {exc}") from None
    try:
        data = json.loads(raw)
    except json.JSONDecodeError as exc:
        raise InputError(f"scene file {str(path)!r} is not valid JSON: {exc}") from None
    except RecursionError:
        raise InputError(f"scene file {str(path)!r} nests its JSON too deeply to be a scene") from None
    return parse_scene(data, default_name=path.stem, base_dir=path.parent)


def parse_scene(data: dict, *, default_name: str = "scene", base_dir: Path | None = None) -> Scene:
    """Validate a scene given as a parsed JSON object (see the module docstring).

    ``base_dir`` is where texture image paths are relative to (default: the scenes folder).

    Raises
    ------
    InputError
        Naming the offending field.
    """
    if not isinstance(data, dict):
        raise InputError(f"a scene must be a JSON object, got {type(data).__name__}")
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise InputError(f"unknown scene field(s) {unknown}; expected some of {sorted(_TOP_KEYS)}")
    for key in ("camera", "projector", "surfaces", "targets"):
        if key not in data:
            raise InputError(f"scene is missing the required field {key!r}")
    name = data.get("name", default_name)
    if not isinstance(name, str) or not name:
        raise InputError(f"name must be a non-empty string, got {name!r}")
    camera = _pose(data["camera"], "camera")
    proj = _obj(data["projector"], "projector", required=(), optional=("power", "offset"))
    power = _vec(proj.get("power", [1.0, 1.0, 1.0]), "projector.power", 3, lo=0.0, lo_open=True, hi=MAX_RADIANCE)
    offset = _pose(proj["offset"], "projector.offset") if "offset" in proj else None

    origins, us, vs, names, albedo, emission, paths = [], [], [], [], [], [], []
    textures, digests = {}, []
    surfaces = data["surfaces"]
    if not isinstance(surfaces, list) or not surfaces:
        raise InputError(f"surfaces must be a non-empty list, got {surfaces!r:.80}")
    for i, s in enumerate(surfaces):
        where = f"surfaces[{i}]"
        s = _obj(s, where, required=("name", "corners", "albedo"), optional=("emission", "texture"))
        corners = _corners(s["corners"], f"{where}.corners")
        origins.append(corners[0])
        us.append(corners[1] - corners[0])
        vs.append(corners[3] - corners[0])
        names.append(_name(s["name"], f"{where}.name"))
        albedo.append(_albedo(s["albedo"], f"{where}.albedo"))
        emission.append(_vec(s.get("emission", [0, 0, 0]), f"{where}.emission", 3, lo=0.0, hi=MAX_RADIANCE))
        paths.append(where)
        if "texture" in s:
            textures[i], blob = _texture(s["texture"], f"{where}.texture", base_dir or SCENE_DIR)
            digests.append(blob)
    boxes = data.get("boxes", [])
    if not isinstance(boxes, list):
        raise InputError(f"boxes must be a list, got {type(boxes).__name__}")
    for i, b in enumerate(boxes):
        where = f"boxes[{i}]"
        b = _obj(b, where, required=("name", "base_center", "size", "albedo"), optional=("rotation_deg",))
        bname = _name(b["name"], f"{where}.name")
        centre = _vec(b["base_center"], f"{where}.base_center", 3)
        size = _vec(b["size"], f"{where}.size", 3, lo=0.0, lo_open=True)
        rot = _number(b.get("rotation_deg", 0.0), f"{where}.rotation_deg")
        rho = _albedo(b["albedo"], f"{where}.albedo")
        for face, (o, u, v) in _box_faces(centre, size, rot).items():
            origins.append(o)
            us.append(u)
            vs.append(v)
            names.append(f"{bname}.{face}")
            albedo.append(rho)
            emission.append(np.zeros(3))
            paths.append(where)
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"surface names must be unique; duplicated: {dup}")
    quads = Quads(np.array(origins), np.array(us), np.array(vs))

    targets_in = data["targets"]
    if not isinstance(targets_in, dict):
        raise InputError("targets must be an object mapping target names to lists of surfaces, "
                         f"got {type(targets_in).__name__}")
    targets = {}
    for tname, pieces in targets_in.items():
        where = f"targets[{tname!r}]"
        if not isinstance(pieces, list) or not pieces:
            raise InputError(f"{where} must be a non-empty list of {{'surface': NAME}} objects, got {pieces!r:.80}")
        out = []
        for k, piece in enumerate(pieces):
            pw = f"{where}[{k}]"
            piece = _obj(piece, pw, required=("surface",), optional=("rect",))
            sname = piece["surface"]
            if sname not in names:
                raise InputError(f"{pw}.surface names unknown surface {sname!r}; known surfaces: {names}")
            rect = _vec(piece.get("rect", [0, 0, 1, 1]), f"{pw}.rect", 4, lo=0.0, hi=1.0)
            if rect[2] <= rect[0] or rect[3] <= rect[1]:
                raise InputError(f"{pw}.rect must be [a0, b0, a1, b1] with a0 < a1 and b0 < b1, got {rect.tolist()}")
            a0, b0, a1, b1 = (float(r) for r in rect)
            out.append((names.index(sname), (a0, b0, a1, b1)))
        targets[str(tname)] = out

    lighting = _obj(data.get("lighting", {}), "lighting", required=(), optional=("ambient", "projector_flood"))
    ambient = lighting.get("ambient", True)
    if not isinstance(ambient, bool):
        raise InputError(f"lighting.ambient must be true or false, got {ambient!r}")
    flood = _number(lighting.get("projector_flood", 0.0), "lighting.projector_flood")
    if not 0.0 <= flood <= 1.0:
        raise InputError(f"lighting.projector_flood must be in [0, 1], got {flood}")
    patch = _number(data.get("patch_size", 0.1), "patch_size")
    if patch <= 0:
        raise InputError(f"patch_size must be positive (metres), got {patch}")
    digest = hashlib.sha256(json.dumps([data, digests], sort_keys=True).encode()).hexdigest()
    return Scene(name=name, description=str(data.get("description", "")), quads=quads,
                 names=tuple(names), albedo=np.array(albedo), emission=np.array(emission),
                 camera=camera, projector_offset=offset, projector_power=power,
                 targets=targets, lighting={"ambient": ambient, "projector_flood": flood},
                 patch_size=patch, digest=digest, textures=textures)


def _texture(value, where: str, base_dir: Path) -> tuple[Texture, str]:
    """Parse a surface's ``texture`` field; also returns a digest of its content (for caches)."""
    if isinstance(value, dict) and "image" in value:
        value = _obj(value, where, required=("image",), optional=())
        rel = _name(value["image"], f"{where}.image")
        path = (Path(base_dir) / rel).resolve()
        import cv2

        if path.is_file() and path.stat().st_size > MAX_SCENE_BYTES:
            raise InputError(f"{where}.image: {str(path)!r} is larger than {MAX_SCENE_BYTES} bytes")
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED) if path.is_file() else None
        if img is None:
            raise InputError(f"{where}.image: cannot read image {str(path)!r} "
                             "(a PNG or TIFF file, relative to the scene file)")
        if img.dtype not in (np.uint8, np.uint16):
            raise InputError(f"{where}.image must be an 8- or 16-bit image, got {img.dtype}")
        top = 255.0 if img.dtype == np.uint8 else 65535.0
        img = img.astype(np.float64) / top
        if img.ndim == 2:
            img = np.repeat(img[:, :, None], 3, axis=2)
        elif img.shape[2] >= 3:
            img = img[:, :, 2::-1]  # OpenCV reads BGR(A)
        else:
            raise InputError(f"{where}.image must be grey or RGB, got {img.shape[2]} channels")
        blob = hashlib.sha256(np.ascontiguousarray(img).tobytes()).hexdigest()
        return Texture("image", image=np.ascontiguousarray(img)), blob
    value = _obj(value, where, required=("pattern", "cells", "albedo"), optional=())
    kind = value["pattern"]
    if kind not in ("checker", "stripes"):
        raise InputError(f"{where}.pattern must be 'checker' or 'stripes' (or give an 'image'), got {kind!r}")
    cells = value["cells"]
    if not (isinstance(cells, list) and len(cells) == 2
            and all(isinstance(c, int) and not isinstance(c, bool) and 1 <= c <= 4096 for c in cells)):
        raise InputError(f"{where}.cells must be [nu, nv], two integers in [1, 4096], got {cells!r}")
    return Texture(kind, (cells[0], cells[1]), _albedo(value["albedo"], f"{where}.albedo")), ""


def _obj(value, where: str, *, required, optional) -> dict:
    if not isinstance(value, dict):
        raise InputError(f"{where} must be an object, got {value!r:.80}")
    for key in required:
        if key not in value:
            raise InputError(f"{where} is missing the required field {key!r}")
    unknown = sorted(set(value) - set(required) - set(optional))
    if unknown:
        raise InputError(f"{where} has unknown field(s) {unknown}; expected {sorted(set(required) | set(optional))}")
    return value


def _name(value, where: str) -> str:
    if not isinstance(value, str) or not value:
        raise InputError(f"{where} must be a non-empty string, got {value!r}")
    return value


def _number(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(_float(value)):
        raise InputError(f"{where} must be a finite number, got {value!r:.40}")
    return float(value)


def _float(value) -> float:
    try:
        return float(value)
    except OverflowError:  # an integer beyond float range (10**400)
        return float("inf")


def _vec(value, where: str, n: int, *, lo=None, hi=None, lo_open=False) -> np.ndarray:
    ok = isinstance(value, list) and len(value) == n and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    if not ok:
        raise InputError(f"{where} must be a list of {n} numbers, got {value!r:.80}")
    arr = np.array([_float(v) for v in value], np.float64)
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{where} must be finite, got {value!r:.80}")
    if lo is not None and (np.any(arr <= lo) if lo_open else np.any(arr < lo)):
        raise InputError(f"{where} must be {'>' if lo_open else '>='} {lo}, got {value}")
    if hi is not None and np.any(arr > hi):
        raise InputError(f"{where} must be <= {hi}, got {value}")
    return arr


def _albedo(value, where: str) -> np.ndarray:
    arr = _vec(value, where, 3)
    if np.any(arr < 0):
        raise InputError(f"{where} must be in [0, 1), got {value} (a negative albedo reflects negative light)")
    if np.any(arr >= 1):
        raise InputError(f"{where} must be in [0, 1), got {value} (an albedo of 1 or more creates energy)")
    return arr


def _pose(value, where: str) -> Pose:
    value = _obj(value, where, required=("position", "look_at", "fov_deg"), optional=("up",))
    pos = _vec(value["position"], f"{where}.position", 3)
    at = _vec(value["look_at"], f"{where}.look_at", 3)
    up = _vec(value.get("up", [0, 1, 0]), f"{where}.up", 3)
    fov = _number(value["fov_deg"], f"{where}.fov_deg")
    if not 0 < fov < 170:
        raise InputError(f"{where}.fov_deg must be in (0, 170) degrees, got {fov}")
    fwd = at - pos
    if np.linalg.norm(fwd) < 1e-9:
        raise InputError(f"{where}.look_at must differ from {where}.position, both are {pos.tolist()}")
    if np.linalg.norm(np.cross(fwd / np.linalg.norm(fwd), up)) < 1e-6:
        raise InputError(f"{where}.up must not be parallel to the viewing direction, got up={up.tolist()}")
    return Pose(tuple(pos), tuple(at), tuple(up), fov)


def _corners(value, where: str) -> np.ndarray:
    ok = isinstance(value, list) and len(value) == 4 and all(
        isinstance(c, list) and len(c) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in c)
        for c in value)
    if not ok:
        raise InputError(f"{where} must be a list of 4 points [x, y, z], got {value!r:.80}")
    p = np.array([[_float(x) for x in c] for c in value], np.float64)
    if not np.all(np.isfinite(p)):
        raise InputError(f"{where} must be finite, got {value!r:.80}")
    scale = max(float(np.ptp(p, axis=0).max()), 1e-12)
    u, v = p[1] - p[0], p[3] - p[0]
    area = float(np.linalg.norm(np.cross(u, v)))
    if area <= 1e-9 * scale * scale or area <= 1e-12:
        raise InputError(f"{where} is a degenerate quad (zero area): {value}")
    if abs(float(np.dot(p[2] - p[0], np.cross(u, v)))) / area > 1e-6 * scale:
        raise InputError(f"{where} is not planar: corner p2 is off the plane of p0, p1, p3: {value}")
    if np.linalg.norm(p[0] + p[2] - p[1] - p[3]) > 1e-6 * scale:
        raise InputError(f"{where} must be a parallelogram (p0 + p2 = p1 + p3), got {value}")
    return p


def _box_faces(base_center: np.ndarray, size: np.ndarray, rotation_deg: float) -> dict:
    """Five outward-facing faces (origin, u, v) of a box standing on ``base_center``."""
    sx, sy, sz = size / 2.0
    c = base_center + np.array([0.0, sy, 0.0])
    th = np.radians(rotation_deg)
    rot = np.array([[np.cos(th), 0, np.sin(th)], [0, 1, 0], [-np.sin(th), 0, np.cos(th)]])
    ex, ey, ez = rot @ np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), rot @ np.array([0, 0, 1.0])
    faces = {}
    # (normal, half-extent along normal, e1, h1, e2, h2) with e1 x e2 = normal
    spec = {
        "top": (ey, sy, ez, sz, ex, sx),
        "front": (-ez, sz, ey, sy, ex, sx),
        "back": (ez, sz, ex, sx, ey, sy),
        "left": (-ex, sx, ez, sz, ey, sy),
        "right": (ex, sx, ey, sy, ez, sz),
    }
    for face, (n, hn, e1, h1, e2, h2) in spec.items():
        centre = c + hn * n
        faces[face] = (centre - h1 * e1 - h2 * e2, 2 * h1 * e1, 2 * h2 * e2)
    return faces
