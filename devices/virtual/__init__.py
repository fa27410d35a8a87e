"""The virtual rig: a simulated camera-projector pair with exact ground truth.

``devices.open_rig("virtual:cornell", ideal=True)`` opens the Cornell-like box of the paper's
Fig. 6; ``"virtual:wedge"`` (Figs. 7-9) and ``"virtual:three"`` (Fig. 10) are the others, and
``"virtual:/path/scene.json"`` opens a scene file. The scene is Lambertian and its light
transport exactly linear: direct light (an ambient area light and the projector) at pixel
resolution, indirect light through a patch radiosity solve (see :mod:`devices.virtual.setup`
and :mod:`devices.virtual.transport`). ``rig.truth`` gives noise-free photographs, recoloured
photographs and interaction components computed from the transport itself.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from devices._common import cache_folder
from devices.base import SimulatedRig
from devices.registry import Availability
from devices.virtual.camera import CameraModel, VirtualCamera
from devices.virtual.projector import ProjectorModel, VirtualProjector
from devices.virtual.render import Renderer
from devices.virtual.scene import Scene, load_scene, scene_names
from devices.virtual.setup import Geometry, Setup, load_or_build
from devices.virtual.truth import Components, Truth
from engine.checks import check_choice
from engine.errors import InputError

__all__ = ["open_rig", "recorded_options", "probe", "VirtualRig", "Truth", "Components", "CameraModel",
           "ProjectorModel", "default_cache_dir", "scene_names", "load_scene"]

_OPTIONS = ("ideal", "seed", "projector", "resolution", "projector_resolution", "ambient", "cache_dir",
            "patch_size", "supersample", "defocus", "progress")


def default_cache_dir() -> Path:
    """Per-user cache of set-ups: ``$XDG_CACHE_HOME/albedit/virtual`` (``~/.cache/...``)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "albedit" / "virtual"


class VirtualRig(SimulatedRig):
    """A :class:`devices.base.SimulatedRig` over a scene of the virtual rig.

    Attributes
    ----------
    camera : VirtualCamera
    projector : VirtualProjector
    targets : dict[str, (H, W) bool]
        The scene's named targets rasterised into camera masks (pixel centres).
    coverage : dict[str, (H, W) float32]
        Fraction of each pixel's footprint on each target (0/1 unless pixels are supersampled).
    truth : Truth
    scene : Scene
    setup : Setup
        The precomputed transport (for tests and benchmarks).
    """

    camera: VirtualCamera
    projector: VirtualProjector

    def __init__(self, name, camera, projector, *, targets, truth, renderer: Renderer, coverage=None, fingerprint=None):
        super().__init__(name, camera, projector, targets=targets, truth=truth, renderer=renderer,
                         lighting=renderer.scene.lighting, coverage=coverage, fingerprint=fingerprint)
        self.scene: Scene = renderer.scene
        self.setup: Setup = renderer.setup


def probe() -> list[Availability]:
    """Every shipped scene as ``virtual:NAME`` (always available).

    Examples
    --------
    >>> "virtual:cornell" in [a.name for a in probe()]
    True
    """
    return [Availability(f"virtual:{n}", True, "simulated rig") for n in scene_names()]


def open_rig(arg: str, **options) -> VirtualRig:
    """Open a virtual rig on a scene.

    Parameters
    ----------
    arg : str
        Scene name (``"cornell"``, ``"wedge"``, ``"three"``) or path to a scene ``.json``.
    ideal : bool, default False
        Turn every imperfection off: no noise, linear projector response, no black levels,
        no quantisation, identity crosstalk (the camera still clips, at 1e12 electrons).
    seed : int, numpy.random.Generator or None, default 0
        Seed of the camera's noise generator (None: fresh entropy).
    projector : {"coaxial", "offset"}, default "coaxial"
        Co-axial: the projector shares the camera's pose and frustum (identity
        correspondences at equal resolution, the paper's simulations). Offset: the scene's
        ``projector.offset`` pose (needs calibration; some pixels are shadowed or unlit).
    resolution : (H, W), default (256, 256)
        Camera resolution.
    projector_resolution : (Hp, Wp), default ``resolution`` (ideal) or half of it (realistic)
        A real projector has fewer pixels than the camera that watches it.
    supersample : int, default 1 (ideal) or 4 (realistic)
        Sub-samples per pixel edge on pixels whose footprint may hold two surfaces, texture
        cells or shadow states: edges are mixed as on a sensor (1: one point per pixel).
    defocus : float, default 0
        Projector blur on the surfaces, the standard deviation in projector pixels.
    ambient : bool, default True
        Ambient light on at start (``rig.ambient`` switches it later).
    cache_dir : str, Path, None or False, default None
        Where set-ups are cached (None: :func:`default_cache_dir`; False: no cache).
    patch_size : float, optional
        Override the scene's patch size (metres) of the indirect-light grid.
    progress : callable, optional
        ``progress(step, total, message)`` during set-up.

    Returns
    -------
    VirtualRig

    Raises
    ------
    InputError
        Unknown scene, invalid scene file or bad option.

    Examples
    --------
    >>> with open_rig("wedge", ideal=True, resolution=(16, 16), cache_dir=False, patch_size=0.3) as rig:
    ...     frame = rig.camera.capture()
    >>> frame.image.shape, frame.image.dtype
    ((16, 16, 3), dtype('float32'))
    """
    unknown = sorted(set(options) - set(_OPTIONS))
    if unknown:
        raise InputError(f"unknown virtual rig option(s) {unknown}; expected some of {list(_OPTIONS)}")
    scene = load_scene(arg) if arg else _no_scene()
    ideal = _flag(options.get("ideal", False), "ideal")
    ambient = _flag(options.get("ambient", True), "ambient")
    seed = options.get("seed", 0)
    if not (seed is None or isinstance(seed, np.random.Generator)
            or (isinstance(seed, (int, np.integer)) and not isinstance(seed, bool) and seed >= 0)):
        raise InputError(f"seed must be a non-negative int, a numpy Generator or None, got {seed!r}")
    kind = check_choice("projector", options.get("projector", "coaxial"), ["coaxial", "offset"])
    if kind == "offset" and scene.projector_offset is None:
        raise InputError(f"scene {scene.name!r} has no projector.offset pose; use projector='coaxial'")
    res = _resolution(options.get("resolution", (256, 256)), "resolution")
    half = res if ideal else (max(4, res[0] // 2), max(4, res[1] // 2))
    pres = _resolution(options.get("projector_resolution", half), "projector_resolution")
    sub = options.get("supersample", 1 if ideal else 4)
    if isinstance(sub, bool) or not isinstance(sub, (int, np.integer)) or not 1 <= sub <= 16:
        raise InputError(f"supersample must be an integer in [1, 16] (sub-samples per pixel edge), got {sub!r}")
    defocus = options.get("defocus", 0.0)
    if (isinstance(defocus, bool) or not isinstance(defocus, (int, float)) or not np.isfinite(defocus)
            or not 0 <= defocus <= 64):
        raise InputError(f"defocus must be a blur in [0, 64] projector pixels, got {defocus!r}")
    patch = options.get("patch_size", None)
    if patch is None:
        patch = scene.patch_size
    elif isinstance(patch, bool) or not isinstance(patch, (int, float)) or not np.isfinite(patch) or patch <= 0:
        raise InputError(f"patch_size must be a positive number of metres, got {patch!r}")
    cache = cache_folder(options.get("cache_dir", None), default_cache_dir)

    geometry = Geometry(res, kind, pres, float(patch), int(sub))
    setup = load_or_build(scene, geometry, None if cache is None else Path(cache),
                          progress=options.get("progress"))
    renderer = Renderer(scene, setup, defocus=float(defocus))
    renderer.ambient = ambient
    pmodel = ProjectorModel.perfect() if ideal else ProjectorModel.realistic()
    cmodel = CameraModel.perfect() if ideal else CameraModel.realistic()
    projector = VirtualProjector(pmodel, pres)
    name = f"virtual:{arg}"
    camera = VirtualCamera(renderer, projector, cmodel, np.random.default_rng(seed), name)
    truth = Truth(renderer, pmodel, cmodel, pres)
    fingerprint = {"scene": scene.digest, "projector pose": kind, "ideal": ideal, "patch size": float(patch),
                   "supersample": int(sub), "defocus": float(defocus)}
    return VirtualRig(name, camera, projector, targets=target_masks(scene, setup), truth=truth, renderer=renderer,
                      coverage=target_coverage(scene, setup), fingerprint=fingerprint)


def recorded_options(fingerprint: dict | None, camera_resolution, projector_resolution) -> dict:
    """The :func:`open_rig` options that open the set-up a calibration was made with.

    Parameters
    ----------
    fingerprint : dict or None
        The rig's fingerprint as a session recorded it (:attr:`VirtualRig.fingerprint`); None
        (a session from before fingerprints) gives the resolutions only.
    camera_resolution, projector_resolution : (H, W)
        The session's camera and projector resolutions.

    Returns
    -------
    dict
        ``resolution``, ``projector_resolution`` and, when recorded, ``ideal``, ``projector``
        (the pose), ``supersample``, ``defocus`` and ``patch_size``: what the fingerprint
        compares, so the rig they open matches the calibration. The noise seed is not part of it.

    Examples
    --------
    >>> recorded_options({"ideal": True, "projector pose": "offset"}, (32, 32), (16, 16))
    {'resolution': (32, 32), 'projector_resolution': (16, 16), 'ideal': True, 'projector': 'offset'}
    """
    options: dict = {"resolution": tuple(int(v) for v in camera_resolution),
                     "projector_resolution": tuple(int(v) for v in projector_resolution)}
    names = {"ideal": "ideal", "projector pose": "projector", "supersample": "supersample",
             "defocus": "defocus", "patch size": "patch_size"}
    for recorded, option in names.items():
        if fingerprint is not None and recorded in fingerprint:
            options[option] = fingerprint[recorded]
    return options


def _on_target(pieces, quad, a, b) -> np.ndarray:
    m = np.zeros(len(quad), bool)
    for q, (a0, b0, a1, b1) in pieces:
        m |= (quad == q) & (a >= a0) & (a <= a1) & (b >= b0) & (b <= b1)
    return m


def target_masks(scene: Scene, setup: Setup) -> dict[str, np.ndarray]:
    """Rasterise the scene's targets into camera masks ``{name: (H, W) bool}`` (pixel centres)."""
    h, w = (int(x) for x in setup.resolution)
    n = h * w
    quad, a, b = setup.pixel_quad, setup.a[:n], setup.b[:n]
    return {name: _on_target(pieces, quad, a, b).reshape(h, w) for name, pieces in scene.targets.items()}


def target_coverage(scene: Scene, setup: Setup) -> dict[str, np.ndarray]:
    """Fraction of each pixel's footprint on each named target ``{name: (H, W) float32}``."""
    h, w = (int(x) for x in setup.resolution)
    n, vis = h * w, setup.n_visible
    quad = np.concatenate([setup.pixel_quad, setup.quad[n:vis]])
    a, b = setup.a[:vis], setup.b[:vis]
    return {name: setup.pixel_values(_on_target(pieces, quad, a, b).astype(np.float32)).reshape(h, w)
            for name, pieces in scene.targets.items()}


def _no_scene():
    raise InputError(f"virtual rig needs a scene: 'virtual:NAME' with NAME one of {scene_names()}, "
                     "or 'virtual:/path/scene.json'")


def _flag(value, name: str) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise InputError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def _resolution(value, name: str) -> tuple[int, int]:
    try:
        h, w = value
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a pair (H, W) of pixel counts, got {value!r}") from None
    for v in (h, w):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 4 <= v <= 16384:
            raise InputError(f"{name} must be a pair (H, W) of integers in [4, 16384], got {value!r}")
    return int(h), int(w)
