"""The path-traced rig: Mitsuba 3 scenes behind the virtual rig's camera and projector models.

``devices.open_rig("mitsuba:cornell")`` opens the paper's Fig. 6 box (the geometry of
``virtual:cornell``) path-traced by Mitsuba 3; ``mitsuba:wedge`` (Figs. 8 and 13: a glossy
coat on the left wall, ``specular=``, ``roughness=`` and ``tint=`` set it), ``mitsuba:floor``
(Figs. 3 and 11: a diffuse box on a glossy floor) and ``mitsuba:textured`` (Fig. 12) are the others;
``"mitsuba:/path/rig.json"`` opens a rig file naming any Mitsuba scene and its targets (see
:mod:`devices.mitsuba.scene`). Unlike the virtual rig, materials need not be Lambertian,
pixels average their whole footprint (edges are mixed) and the truth is per shape
(:mod:`devices.mitsuba.truth`). Needs the optional extra: ``pip install 'albedit[mitsuba]'``.
"""

from __future__ import annotations

import json
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from devices._common import cache_folder
from devices.base import Frame, SimulatedRig
from devices.registry import Availability
from devices.virtual.camera import CameraModel, VirtualCamera
from devices.virtual.projector import ProjectorModel, VirtualProjector
from engine.checks import check_choice, check_resolution
from engine.errors import InputError

__all__ = ["open_rig", "probe", "MitsubaRig", "MitsubaCamera", "default_cache_dir"]

_OPTIONS = (
    "ideal",
    "seed",
    "projector",
    "resolution",
    "projector_resolution",
    "ambient",
    "cache_dir",
    "spp",
    "ambient_spp",
    "truth_spp",
    "max_depth",
    "specular",
    "roughness",
    "tint",
    "coverage_passes",
    "progress",
)


def default_cache_dir() -> Path:
    """Per-user cache of ambient renders: ``$XDG_CACHE_HOME/albedit/mitsuba``."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "albedit" / "mitsuba"


def probe() -> list[Availability]:
    """Every shipped rig file as ``mitsuba:NAME``, or why the backend is unavailable."""
    try:
        import mitsuba  # noqa: F401
    except ImportError:
        return [Availability("mitsuba:", False, "Mitsuba 3 is not installed: pip install 'albedit[mitsuba]'")]
    from devices.mitsuba.scene import rig_names

    return [Availability(f"mitsuba:{n}", True, "path-traced rig (Mitsuba 3, scalar_rgb)") for n in rig_names()]


class MitsubaCamera(VirtualCamera):
    """The virtual camera's sensor model (noise, black level, ADC, clipping) on a path-traced render.

    Frames also record ``spp``, the samples per pixel of the projector render, and carry its
    Monte Carlo variance as :attr:`engine.rig.Frame.variance` (from two half-sample renders,
    :meth:`devices.mitsuba.render.Renderer.render`), which acquisition adds to the camera
    model's: the noise-aware recolor then weighs render noise as it weighs photon noise.
    """

    def capture(self) -> Frame:
        """Take one frame: the cached ambient render plus a fresh projector render, then the sensor."""
        frame = super().capture()
        frame.metadata["spp"] = self._renderer.spp
        frame.metadata["ambient_spp"] = self._renderer.ambient_spp
        return replace(frame, variance=self._renderer.last_variance)

    @property
    def spp(self) -> int:
        """Samples per pixel of each capture's projector render (settable)."""
        return self._renderer.spp

    @spp.setter
    def spp(self, value: int) -> None:
        self._renderer.spp = _positive_int(value, "spp")


class MitsubaRig(SimulatedRig):
    """A :class:`devices.base.SimulatedRig` over a Mitsuba scene.

    Attributes
    ----------
    targets : dict[str, (H, W) bool]
        Pixels with at least half their footprint on each target's shapes.
    coverage : dict[str, (H, W) float32]
        Footprint fraction of each target's shapes in every pixel (the soft mask a perfect
        matting would give).
    truth : devices.mitsuba.truth.Truth
    renderer : devices.mitsuba.render.Renderer
    """


def open_rig(arg: str, **options) -> MitsubaRig:
    """Open a path-traced rig.

    Parameters
    ----------
    arg : str
        Rig name (``"cornell"``, ``"wedge"``, ``"floor"``, ``"textured"``) or a rig ``.json`` path.
    ideal : bool, default False
        Ideal camera and projector models (the renders still carry Monte Carlo noise).
    seed : int, default 0
        Seeds the camera noise and the renders' sample sequences.
    projector : {"coaxial", "offset"}, default "coaxial"
    resolution : (H, W), default (64, 64)
    projector_resolution : (Hp, Wp), default = ``resolution``
    ambient : bool, default True
    cache_dir : path, None or False
        Where the ambient render is cached (None: :func:`default_cache_dir`; False: no cache).
    spp : int, default 256
        Samples per pixel of each capture's projector render.
    ambient_spp : int, default 4096
        Samples per pixel of the ambient render (once).
    truth_spp : int, default 1024
        Samples per pixel of every ground-truth render.
    max_depth : int, default 32
        Longest light path.
    specular, roughness : float, optional
        Override the glossy coat(s) named in the rig file (share of specular reflection in
        [0, 1], GGX roughness in (0, 1]).
    tint : {"white", "albedo"}, optional
        Override the coats' specular reflectance: white, or the shape's diffuse colour (then
        ``specular`` is the paper's Fig. 13 share of the total albedo; see
        :mod:`devices.mitsuba.scene`).
    coverage_passes : int, default 256
        One-sample renders counting each shape's footprint per pixel (targets, coverage).
    progress : callable, optional
        ``progress(step, total, message)`` while rendering the ambient light.

    Raises
    ------
    InputError
        Mitsuba missing, unknown scene, bad option.

    Examples
    --------
    >>> import pytest; _ = pytest.importorskip("mitsuba")
    >>> with open_rig("cornell", ideal=True, resolution=(8, 8), spp=4, ambient_spp=4, cache_dir=False,
    ...               coverage_passes=4) as rig:
    ...     rig.camera.capture().image.shape
    (8, 8, 3)
    """
    from devices.mitsuba.render import Renderer, mitsuba
    from devices.mitsuba.scene import check_coat, load_rig_scene
    from devices.mitsuba.truth import Truth

    unknown = sorted(set(options) - set(_OPTIONS))
    if unknown:
        raise InputError(f"unknown mitsuba rig option(s) {unknown}; expected some of {list(_OPTIONS)}")
    mitsuba()
    if not arg:
        from devices.mitsuba.scene import rig_names

        raise InputError(
            f"mitsuba rig needs a scene: 'mitsuba:NAME' with NAME one of {rig_names()}, or a rig .json path"
        )
    rig_scene = load_rig_scene(arg)
    ideal = _flag(options.get("ideal", False), "ideal")
    ambient = _flag(options.get("ambient", True), "ambient")
    seed = options.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"seed must be a non-negative int, got {seed!r}")
    kind = check_choice("projector", options.get("projector", "coaxial"), ["coaxial", "offset"])
    res = check_resolution("resolution", options.get("resolution", (64, 64)), maximum=4096)
    pres = check_resolution("projector_resolution", options.get("projector_resolution", res), maximum=4096)
    spp = _positive_int(options.get("spp", 256), "spp")
    ambient_spp = _positive_int(options.get("ambient_spp", 4096), "ambient_spp")
    truth_spp = _positive_int(options.get("truth_spp", 1024), "truth_spp")
    depth = _positive_int(options.get("max_depth", 32), "max_depth")
    passes = _positive_int(options.get("coverage_passes", 256), "coverage_passes")
    materials = dict(rig_scene.materials)
    for key in ("specular", "roughness", "tint"):
        if key in options:
            if not materials:
                raise InputError(f"{key}= needs a rig scene with a glossy coat; {rig_scene.name!r} has none")
            materials = {sid: check_coat(dict(m, **{key: options[key]}), key) for sid, m in materials.items()}
    cache = cache_folder(options.get("cache_dir", None), default_cache_dir)

    renderer = Renderer(
        rig_scene,
        res,
        pres,
        projector=kind,
        spp=spp,
        ambient_spp=ambient_spp,
        truth_spp=truth_spp,
        max_depth=depth,
        materials=materials,
        cache_dir=None if cache is None else Path(cache),
        progress=options.get("progress"),
        seed=int(seed),
    )
    renderer.ambient = ambient
    coverage_all = renderer.coverage(passes)
    pmodel = ProjectorModel.perfect() if ideal else ProjectorModel.realistic()
    cmodel = CameraModel.perfect() if ideal else CameraModel.realistic()
    projector = VirtualProjector(pmodel, pres)
    name = f"mitsuba:{arg}"
    camera = MitsubaCamera(renderer, projector, cmodel, np.random.default_rng(seed), name)
    truth = Truth(renderer, pmodel, cmodel, coverage_all)
    coverage, targets = {}, {}
    for tname, ids in rig_scene.targets.items():
        sel = [renderer.shape_ids.index(i) for i in ids if i in renderer.shape_ids]
        if len(sel) != len(ids):
            missing = sorted(set(ids) - set(renderer.shape_ids))
            raise InputError(f"target {tname!r} names shape(s) {missing} that the scene does not have")
        coverage[tname] = coverage_all[sel].sum(axis=0)
        targets[tname] = coverage[tname] >= 0.5
    lighting = _lighting(rig_scene)
    fingerprint = {"scene": rig_scene.digest, "projector pose": kind, "ideal": ideal,
                   "materials": json.dumps(materials, sort_keys=True)}
    return MitsubaRig(
        name,
        camera,
        projector,
        targets=targets,
        coverage=coverage,
        truth=truth,
        renderer=renderer,
        lighting=lighting,
        fingerprint=fingerprint,
    )


def _lighting(rig_scene) -> dict:
    if rig_scene.scene.startswith("virtual:"):
        from devices.virtual.scene import load_scene

        return dict(load_scene(rig_scene.scene.partition(":")[2]).lighting)
    return {"ambient": True, "projector_flood": 0.0}


def _flag(value, name: str) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise InputError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def _positive_int(value, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 1 <= value <= 1 << 20:
        raise InputError(f"{name} must be a positive integer, got {value!r}")
    return int(value)
