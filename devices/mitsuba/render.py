"""Path-traced radiance of a rig scene: Mitsuba 3 (``scalar_rgb``) behind the virtual camera.

One Mitsuba scene holds the rig's shapes, the light that is not the projector ("ambient":
every emitter of the scene file) and a ``projector`` emitter whose irradiance bitmap is the
projector's emitted light. Light transport is linear, so a capture is the ambient image —
rendered once at ``ambient_spp`` and cached on disk — plus a projector-only render at
``spp`` samples per pixel with the ambient emitters switched off; each render draws a new
seed, so no two captures share their Monte Carlo noise, as no two photographs share their
photon noise. Pixels average their footprint (box filter): edge pixels are mixed, as on a
sensor.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from devices._common import source_digest
from engine.errors import InputError
from engine.progress import report

# Samples per pixel per Mitsuba call (progress is reported between calls).
CHUNK_SPP = 256
#: What a cached ambient image means: a digest of this package's source.
MODEL_DIGEST = source_digest(Path(__file__).parent)
# Seeds of truth renders start here (captures count up from the rig's seed).
TRUTH_SEEDS = 1 << 30


def mitsuba():
    """The ``mitsuba`` module with the ``scalar_rgb`` variant set (the only one used here).

    Raises
    ------
    InputError
        Mitsuba is not installed (says how to install it).
    """
    try:
        import mitsuba as mi
    except ImportError:
        raise InputError("the mitsuba rig needs Mitsuba 3: pip install 'albedit[mitsuba]'") from None
    if mi.variant() != "scalar_rgb":
        mi.set_variant("scalar_rgb")  # the llvm_* variants crash on some LLVM builds
    return mi


class Renderer:
    """Renders the rig scene for the virtual camera model (``render(emitted)``, ``shape``, ``ambient``).

    Parameters
    ----------
    rig_scene : devices.mitsuba.scene.RigScene
    resolution, projector_resolution : (H, W), (Hp, Wp)
    projector : {"coaxial", "offset"}
    spp : int
        Samples per pixel of each projector render (each capture).
    ambient_spp : int
        Samples per pixel of the cached ambient image.
    truth_spp : int
        Samples per pixel of ground-truth renders.
    max_depth : int
        Longest path (Mitsuba's ``path`` integrator, Russian roulette from depth 5).
    materials : dict
        Shape id -> glossy coat (see :mod:`devices.mitsuba.scene`).
    cache_dir : Path or None
    progress : callable, optional

    Attributes
    ----------
    shape : (H, W)
    ambient : bool
        Whether captures see the ambient light (the rig's switch).
    shape_ids : list of str
        Mitsuba shapes in the order of their ``shape_index``.
    """

    def __init__(
        self,
        rig_scene,
        resolution,
        projector_resolution,
        *,
        projector: str = "coaxial",
        spp: int = 256,
        ambient_spp: int = 4096,
        truth_spp: int = 1024,
        max_depth: int = 32,
        materials=None,
        cache_dir: Path | None = None,
        progress=None,
        seed: int = 0,
    ):
        mi = mitsuba()
        self.rig_scene = rig_scene
        self.shape = (int(resolution[0]), int(resolution[1]))
        self.projector_resolution = (int(projector_resolution[0]), int(projector_resolution[1]))
        self.spp, self.ambient_spp, self.truth_spp = int(spp), int(ambient_spp), int(truth_spp)
        self.max_depth = int(max_depth)
        self.materials = dict(rig_scene.materials if materials is None else materials)
        self.ambient = True
        self.renders = 0
        self._seed = int(seed) * 1_000_003
        self._cache_dir = cache_dir
        self._progress = progress
        d, self.power, self.has_offset = self._scene_dict(mi, projector)
        self.scene = mi.load_dict(d, optimize=False)  # keep every shape (optimize merges look-alikes)
        self.params = mi.traverse(self.scene)
        self.shape_ids = [s.id() for s in self.scene.shapes()]
        self._emitter_keys = self._ambient_keys()
        self._saved = {k: self._get(k) for k in self._emitter_keys}
        self._ambient_image: np.ndarray | None = None
        self.last_variance: np.ndarray | None = None  # of the last render()'s projector light
        self._lights: tuple[bool, str | None] | None = None  # (ambient on, hash of the emitted pattern)

    # --- building -------------------------------------------------------------------------
    def _scene_dict(self, mi, projector: str):
        rs = self.rig_scene
        h, w = self.shape
        hp, wp = self.projector_resolution
        film = {"type": "hdrfilm", "width": w, "height": h, "rfilter": {"type": "box"}, "pixel_format": "rgb"}
        sampler = {"type": "independent", "sample_count": CHUNK_SPP}
        d = {"type": "scene", "integrator": {"type": "path", "max_depth": self.max_depth}}
        if rs.scene.startswith("virtual:"):
            from devices.mitsuba.scene import look_at, virtual_scene_dict
            from devices.virtual.scene import load_scene

            vs = load_scene(rs.scene.partition(":")[2])
            d.update(virtual_scene_dict(vs, self.materials))
            cam = look_at(vs.camera, mirror=True)
            fov, axis = vs.camera.fov_deg, "y"
            power = rs.power if rs.power is not None else vs.projector_power
            offset = (
                None
                if vs.projector_offset is None
                else (look_at(vs.projector_offset, mirror=True), vs.projector_offset.fov_deg)
            )
        else:
            loaded = mi.load_file(rs.scene, optimize=False)
            if not loaded.sensors():
                raise InputError(f"scene {rs.scene!r} has no sensor: the rig's camera is the scene's first sensor")
            sensor = loaded.sensors()[0]
            cam = sensor.world_transform()
            fov = float(mi.traverse(sensor)["x_fov"])
            axis = "x"
            ids = set()
            for i, s in enumerate(loaded.shapes()):
                key = s.id() or f"shape_{i}"
                ids.add(key)
                d[key] = s
            for i, e in enumerate(loaded.emitters()):
                if e.get_shape() is None:
                    d[f"emitter_{i}"] = e
            missing = sorted({i for ids_ in rs.targets.values() for i in ids_} - ids)
            if missing:
                raise InputError(f"targets name shape id(s) {missing} not in {rs.scene!r}; its shapes: {sorted(ids)}")
            power = rs.power if rs.power is not None else np.ones(3)
            offset = None
            if rs.offset is not None:
                from devices.mitsuba.scene import look_at

                offset = (look_at(rs.offset, mirror=False), float(rs.offset["fov_deg"]))
        d["sensor"] = {
            "type": "perspective",
            "fov": float(fov),
            "fov_axis": axis,
            "to_world": cam,
            "film": film,
            "sampler": sampler,
        }
        if projector == "offset":
            if offset is None:
                raise InputError(f"scene {rs.name!r} has no offset projector pose; use projector='coaxial'")
            p_world, p_fov, p_axis = offset[0], offset[1], "y"
        else:
            p_world, p_fov, p_axis = cam, fov, axis
        pattern = np.ones((hp, wp, 3), np.float32)
        d["projector"] = {
            "type": "projector",
            "fov": float(p_fov),
            "fov_axis": p_axis,
            "to_world": p_world,
            "scale": 1.0,
            "irradiance": {"type": "bitmap", "bitmap": mi.Bitmap(pattern), "raw": True, "filter_type": "nearest"},
        }
        return d, np.asarray(power, np.float64), offset is not None

    def _ambient_keys(self) -> list[str]:
        """Parameters that switch the scene's own emitters off (radiance, intensity, scale, weight)."""
        mi = mitsuba()
        prefixes = [
            k[: -len(".sampling_weight")]
            for k in self.params.keys()
            if k.endswith(".sampling_weight")
            and isinstance(self.params.properties[k][2], mi.Emitter)
            and not k.startswith("projector.")
        ]
        keys = []
        for p in prefixes:
            mine = [
                k
                for k in self.params.keys()
                if k.startswith(p + ".")
                and (
                    k.endswith(".value")
                    or k.endswith(".scale")
                    or k.endswith(".sampling_weight")
                    or k.endswith(".data")
                )
            ]
            if not any(not k.endswith(".sampling_weight") for k in mine):
                raise InputError(f"emitter {p!r} has no radiance, intensity or scale parameter the rig can switch off")
            keys += mine
        return keys

    def _get(self, key):
        v = self.params[key]
        return float(v) if isinstance(v, (int, float)) else type(v)(v)

    # --- lights ---------------------------------------------------------------------------
    def _set_lights(self, ambient: bool, emitted: np.ndarray | None) -> None:
        mi = mitsuba()
        state = (
            bool(ambient),
            None if emitted is None else hashlib.sha1(np.ascontiguousarray(emitted).tobytes()).hexdigest(),
        )
        if state == self._lights:
            return
        for k in self._emitter_keys:
            v = self._saved[k]
            self.params[k] = v if ambient else (0.0 if isinstance(v, float) else v * 0)
        on = emitted is not None
        if on:
            e = np.asarray(emitted, np.float32)
            self.params["projector.irradiance.data"] = mi.TensorXf(
                np.ascontiguousarray(e * self.power.astype(np.float32))
            )
        self.params["projector.scale"] = 1.0 if on else 0.0
        self.params["projector.sampling_weight"] = 1.0 if on else 0.0
        self.params.update()
        self._lights = state

    def _render(self, spp: int, seed: int, *, what: str = "", integrator=None) -> np.ndarray:
        mi = mitsuba()
        out = np.zeros(self.shape + (3,), np.float64)
        done = 0
        while done < spp:
            n = min(CHUNK_SPP, spp - done)
            img = np.asarray(
                mi.render(self.scene, spp=n, seed=(seed * 4099 + done) & 0xFFFFFFFF, integrator=integrator), np.float64
            )
            out += img[..., :3] * n
            done += n
            if what:
                report(self._progress, done, spp, what)
        self.renders += 1
        return (out / spp).astype(np.float32)

    def _next_seed(self) -> int:
        self._seed += 1
        return self._seed

    def render_lights(
        self, *, ambient: bool, emitted: np.ndarray | None, spp: int, seed: int, what: str = "", integrator=None
    ) -> np.ndarray:
        """One render of the scene under these lights (zeros if there is no light)."""
        ambient = ambient and bool(self._emitter_keys)  # a scene lit by the projector alone has none
        if not ambient and (emitted is None or not np.any(emitted > 0)):
            return np.zeros(self.shape + (3,), np.float32)
        self._set_lights(ambient, None if emitted is None or not np.any(emitted > 0) else emitted)
        return self._render(spp, seed, what=what, integrator=integrator)

    # --- what the camera sees -------------------------------------------------------------
    def ambient_image(self) -> np.ndarray:
        """The ambient light alone, at ``ambient_spp`` (rendered once, cached on disk)."""
        if self._ambient_image is None:
            path = self._cache_path()
            img = _load(path) if path is not None else None
            if img is None or img.shape != self.shape + (3,):
                img = self.render_lights(
                    ambient=True,
                    emitted=None,
                    spp=self.ambient_spp,
                    seed=12345,
                    what=f"rendering the ambient light once ({self.ambient_spp} spp)",
                )
                if path is not None:
                    _save(path, img)
            self._ambient_image = img
        return self._ambient_image

    def _cache_path(self) -> Path | None:
        if self._cache_dir is None:
            return None
        mi = mitsuba()
        key = json.dumps(
            {
                "scene": self.rig_scene.digest,
                "res": self.shape,
                "spp": self.ambient_spp,
                "depth": self.max_depth,
                "materials": self.materials,
                "model": MODEL_DIGEST,
                "mitsuba": mi.__version__,
            },
            sort_keys=True,
        )
        stem = "".join(c if c.isalnum() or c in "-_" else "_" for c in self.rig_scene.name)[:64]
        return Path(self._cache_dir) / f"{stem}-ambient-{hashlib.sha256(key.encode()).hexdigest()[:24]}.npy"

    def render(self, emitted: np.ndarray | None, *, ambient: bool | None = None, dtype=np.float32) -> np.ndarray:
        """Radiance seen by the camera: cached ambient (if on) + a projector render at ``spp``.

        Parameters
        ----------
        emitted : (Hp, Wp, 3) float or None
            Linear light the projector emits (relative to full white).
        ambient : bool, optional
            Defaults to :attr:`ambient`.

        Returns
        -------
        (H, W, 3) ``dtype``

        Notes
        -----
        The projector render is two independent renders of ``spp / 2`` samples each, averaged
        (the same samples as one render of ``spp``); :attr:`last_variance` is the Monte Carlo
        variance of their mean estimated from their difference, ``(a − b)² n m / spp²`` for
        halves of ``n`` and ``m`` samples (an unbiased estimate, one degree of freedom per
        pixel; None at ``spp`` = 1). The cached ambient image's own noise is not included:
        every capture shares it, so it cancels in the differences acquisition takes.
        """
        ambient = self.ambient if ambient is None else ambient
        n = self.spp // 2
        if n >= 1:  # two independent halves: their mean is the render, their difference its noise
            m = self.spp - n
            a = self.render_lights(ambient=False, emitted=emitted, spp=n, seed=self._next_seed())
            b = self.render_lights(ambient=False, emitted=emitted, spp=m, seed=self._next_seed())
            img = (a * np.float32(n / self.spp) + b * np.float32(m / self.spp)).astype(np.float32)
            diff = a.astype(np.float64) - b
            self.last_variance = (diff * diff * (n * m / self.spp**2)).astype(np.float32)
        else:
            img = self.render_lights(ambient=False, emitted=emitted, spp=self.spp, seed=self._next_seed())
            self.last_variance = None
        if ambient:
            img = img + self.ambient_image()
        return img.astype(dtype)

    # --- ground truth helpers -------------------------------------------------------------
    def coverage(self, passes: int = 256) -> np.ndarray:
        """Fraction of each pixel's footprint on each shape, ``(S, H, W)`` float32.

        Counted from ``passes`` renders of one sample per pixel through the shape-index AOV.
        """
        mi = mitsuba()
        aov = mi.load_dict({"type": "aov", "aovs": "s:shape_index,d:depth"})
        counts = np.zeros((len(self.shape_ids),) + self.shape, np.float64)
        n = len(self.shape_ids)
        for p in range(passes):
            img = np.asarray(mi.render(self.scene, spp=1, seed=TRUTH_SEEDS + 7919 * p, integrator=aov))
            idx = np.rint(img[..., 0]).astype(np.int64) - 1  # the AOV counts shapes from 1
            hit = (img[..., 1] > 0) & (idx >= 0) & (idx < n)
            ys, xs = np.nonzero(hit)
            np.add.at(counts, (idx[ys, xs], ys, xs), 1.0)
        return (counts / passes).astype(np.float32)

    @contextmanager
    def scaled(self, factors: dict, *, coat: bool = False):
        """Temporarily scale the diffuse reflectance of shapes: ``{shape_id: (3,) kappa}``.

        With ``coat`` a glossy coat's specular reflectance is scaled too: the whole BSDF, so
        every reflection off the shape is weighted by κ.
        """
        changed = {}
        try:
            for sid, k in factors.items():
                keys = [
                    key
                    for key in self.params.keys()
                    if key.startswith(f"{sid}.bsdf.")
                    and (key.endswith("reflectance.value") or key.endswith("reflectance.data"))
                    and (coat or "specular_reflectance" not in key)
                ]
                if not keys:
                    raise InputError(f"shape {sid!r} has no diffuse reflectance to scale")
                for key in keys:
                    old = self.params[key]
                    changed[key] = type(old)(old)
                    arr = np.asarray(old, np.float64)
                    kk = np.asarray(k, np.float64)
                    self.params[key] = (
                        type(old)((arr * kk).astype(np.float32)) if arr.ndim > 1 else type(old)(*(arr * kk))
                    )
            self.params.update()
            self._lights = None
            yield
        finally:
            for key, old in changed.items():
                self.params[key] = old
            if changed:
                self.params.update()
            self._lights = None


def _save(path: Path, img: np.ndarray) -> None:
    """Write ``img`` atomically; a failure only costs a re-render next time."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as fh:
                np.save(fh, img, allow_pickle=False)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    except OSError:
        pass


def _load(path: Path) -> np.ndarray | None:
    if not path.is_file():
        return None
    try:
        img = np.load(path, allow_pickle=False)
    except Exception:  # corrupt or foreign file: render again
        return None
    return img if img.dtype == np.float32 and img.ndim == 3 and np.all(np.isfinite(img)) else None
