"""One-off set-up of the virtual rig's light transport, cached on disk.

The set-up turns a :class:`~devices.virtual.scene.Scene` and the rig's geometry options into
the arrays every capture reuses:

* **samples** — one per camera pixel (index ``i * W + j``; pixels that see no front surface
  are inert samples of albedo 0); then, when pixels are supersampled, ``s * s`` *sub-samples*
  for each *mixed* pixel — one whose 8-neighbourhood changes surface, texture cell or
  projector shadow, or whose footprint crosses a projector pixel's border (a posed
  projector's pixels straddle the camera's), so that its footprint may hold two of them (its
  centre sample is then inert and the pixel is the mean of its sub-samples, as a sensor
  averages its footprint);
  then *hidden* samples: a regular grid on every quad, kept only where the camera does not
  see the surface. Each sample has a point, a quad, local coordinates and an area.
* **patches** — each quad cut into a grid of cells about ``patch_size`` wide. The patch
  radiance is the area-weighted mean of its samples' radiance: ``B = Mavg L``.
* **form factors** — ``Gn[m, j]``: from node ``m`` (a vertex of the patch grid) to patch
  ``j``, Lambert's exact polygon form factor (clipped to the receiver's hemisphere) times the
  kernel-weighted fraction of ``VIS_SAMPLES**2`` shadow rays to points of ``j`` that are
  unblocked; a sample's form factors are the bilinear interpolation ``W`` of the four nodes
  around it, so ``G = W Gn`` is never stored densely.
* **ambient light** — the form factor of every sample to every emitting quad, with the same
  polygon formula and ``light_samples**2`` shadow rays (soft shadows at pixel resolution).
* **projector** — for every sample, the projector pixel nearest to its projection (each
  pixel sample is lit by exactly one projector pixel, so one-pixel stripes resolve), whether
  it is lit (inside the frustum, facing the projector, and for camera pixels an unblocked
  shadow ray to the projector's centre; for hidden samples, that pixel's own ray reaching the
  same quad, so a co-axial projector never lights what the camera cannot see), and the
  geometric irradiance factor ``cos(theta) / (d^2 cos^3(alpha))`` of a pinhole projector
  whose pixels all emit the same flux.

Arrays are stored as ``.npz`` (never pickle), keyed by a hash of the scene file's content,
the options that change geometry and :data:`MODEL_DIGEST` (the virtual rig's source: a cache
written by other code, even code a revert brings back, is never read); a missing or corrupt
cache file is rebuilt, and deleting the cache directory is always safe.

Over 500 lines on purpose: geometry sampling, the radiosity solve and the set-up cache are one
computation (:data:`MODEL_DIGEST` covers all three).
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from devices._common import source_digest
from devices.virtual.geometry import Quads, View, blocker_table, cast_rays, occluded, polygon_form_factor, quad_corners
from devices.virtual.scene import Scene
from engine.errors import InputError
from engine.imageio import atomic_write
from engine.progress import report

#: The virtual rig's model: a digest of this package's source (set-up, sampling, rendering).
MODEL_DIGEST = source_digest(Path(__file__).parent)
#: Most patches a scene may be cut into: their transport is dense in patches (memory ~ patches²).
MAX_PATCHES = 8000

# Shadow rays per edge of a patch (form factors) and of a light (ambient light).
VIS_SAMPLES = 3
LIGHT_SAMPLES = 4
# Hidden samples per edge of a patch.
HIDDEN_PER_PATCH = 3
# Form-factor nodes, and samples when their light is computed, on a quad's border are moved
# this far inside (local coordinates), away from edges shared with other quads.
NODE_INSET = 1e-3


@dataclass(frozen=True)
class Geometry:
    """The options that change the set-up (part of the cache key)."""

    resolution: tuple[int, int]
    projector: str
    projector_resolution: tuple[int, int]
    patch_size: float
    supersample: int = 1


@dataclass(frozen=True, eq=False)
class Setup:
    """Precomputed light-transport arrays of one scene and rig geometry.

    ``Ns`` samples (the first ``H * W`` are the camera pixels), ``P`` patches.

    Attributes
    ----------
    quad : (Ns,) int64
        Quad of each sample, -1 for pixels that see no front surface.
    a, b : (Ns,) float64
        Local coordinates of each sample on its quad.
    points : (Ns, 3) float64
        Sample positions.
    area : (Ns,) float64
        Surface area represented by each sample (m^2).
    patch : (Ns,) int64
        Patch of each sample, -1 for inert pixels.
    patch_quad : (P,) int64
        Quad of each patch.
    patch_area : (P,) float64
        Geometric area of each patch.
    patch_nu, patch_nv : (Q,) int64
        Patch grid of every quad (patch ``(i, j)`` of quad ``q`` is
        ``sum(nu * nv before q) + i * nv[q] + j``).
    mavg : (P, Ns) scipy.sparse.csr_matrix
        Area-weighted averaging: ``B = mavg @ L``.
    interp : (Ns, Nn) scipy.sparse.csr_matrix
        Bilinear interpolation of node form factors to samples (rows sum to 1).
    gn : (Nn, P) float64
        Form factors from the nodes (patch-grid vertices) to patches (rows sum to at most 1).
    light_quads : (Lq,) int64
        Emitting quads.
    light_ff : (Ns, Lq) float64
        Form factor (with visibility) from each sample to each emitting quad.
    proj_index : (Ns,) int64
        Row-major projector pixel lighting each sample (0 where unlit).
    proj_lit : (Ns,) bool
        Sample reached by the projector (in its frustum, not shadowed, facing it).
    proj_factor : (Ns,) float64
        Geometric irradiance factor ``cos(theta) / (d^2 cos^3(alpha))`` (0 where unlit).
    proj_xy : (H*W, 2) float64
        Continuous projector coordinates (x, y) of each pixel's surface point, NaN where the
        pixel sees no surface.
    pixel_quad : (H*W,) int64
        Quad seen by each pixel (front side), -1 for none.
    resolution, projector_resolution : (2,) int64
    sub_pixel : (M,) int64
        The mixed pixels, in increasing order; the sub-samples of ``sub_pixel[m]`` are
        samples ``H*W + m*S .. H*W + (m+1)*S - 1`` with ``S = supersample**2``.
    supersample : int
        Sub-samples per pixel edge (1: one sample per pixel, no mixed pixels).
    rescaled_rows : int
        Number of patch-centre form-factor rows whose sum exceeded 1 by discretisation and
        were scaled back to 1 (energy conservation); 0 for convex enclosures.
    """

    quad: np.ndarray
    a: np.ndarray
    b: np.ndarray
    points: np.ndarray
    area: np.ndarray
    patch: np.ndarray
    patch_quad: np.ndarray
    patch_area: np.ndarray
    patch_nu: np.ndarray
    patch_nv: np.ndarray
    mavg: sp.csr_matrix
    interp: sp.csr_matrix
    gn: np.ndarray
    light_quads: np.ndarray
    light_ff: np.ndarray
    proj_index: np.ndarray
    proj_lit: np.ndarray
    proj_factor: np.ndarray
    proj_xy: np.ndarray
    pixel_quad: np.ndarray
    resolution: np.ndarray
    projector_resolution: np.ndarray
    sub_pixel: np.ndarray
    supersample: int
    rescaled_rows: int

    @property
    def n_pixels(self) -> int:
        """``H * W``."""
        return int(self.resolution[0] * self.resolution[1])

    @property
    def n_visible(self) -> int:
        """Samples the camera sees: pixel centres, then the sub-samples of mixed pixels."""
        return self.n_pixels + len(self.sub_pixel) * int(self.supersample) ** 2

    def pixel_values(self, values: np.ndarray) -> np.ndarray:
        """Per-pixel ``(H*W, ...)`` values from per-sample ones: mixed pixels average their sub-samples."""
        n = self.n_pixels
        out = values[:n].copy()
        m = len(self.sub_pixel)
        if m:
            per = int(self.supersample) ** 2
            out[self.sub_pixel] = values[n:n + m * per].reshape((m, per) + values.shape[1:]).mean(axis=1)
        return out

    def sample_pixel(self) -> np.ndarray:
        """(n_visible,) int64: the camera pixel of every visible sample."""
        per = int(self.supersample) ** 2
        return np.concatenate([np.arange(self.n_pixels), np.repeat(self.sub_pixel, per)]).astype(np.int64)


def views(scene: Scene, geometry: Geometry) -> tuple[View, View]:
    """The camera and projector views of ``scene`` for ``geometry``.

    The co-axial projector shares the camera's pose and frustum (sampled at its own
    resolution); the offset projector uses the scene's ``projector.offset`` pose.
    """
    c = scene.camera
    camera = View.look_at(c.position, c.look_at, c.up, c.fov_deg, geometry.resolution)
    if geometry.projector == "coaxial":
        return camera, camera.rescaled(geometry.projector_resolution)
    p = scene.projector_offset
    assert p is not None  # open_rig refuses an offset projector on a scene without one
    return camera, View.look_at(p.position, p.look_at, p.up, p.fov_deg, geometry.projector_resolution)


def patch_grid(scene: Scene, patch_size: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Patch counts along ``u`` and ``v`` of every quad, and each quad's first patch index.

    Raises
    ------
    InputError
        More than :data:`MAX_PATCHES` patches (their transport would not fit in memory); the
        message gives the smallest patch size that fits.
    """
    fu = np.maximum(1.0, np.ceil(np.linalg.norm(scene.quads.u, axis=1) / patch_size - 1e-9))
    fv = np.maximum(1.0, np.ceil(np.linalg.norm(scene.quads.v, axis=1) / patch_size - 1e-9))
    count = float(np.sum(fu * fv))
    if count > MAX_PATCHES:
        fits = patch_size * np.sqrt(count / MAX_PATCHES)
        raise InputError(f"patch_size {patch_size:g} m cuts scene {scene.name!r} into {count:.3g} patches; at most "
                         f"{MAX_PATCHES} fit in memory: use a patch_size of at least {fits:.2g} m")
    nu, nv = fu.astype(np.int64), fv.astype(np.int64)
    offset = np.concatenate([[0], np.cumsum(nu * nv)])
    return nu, nv, offset


def load_or_build(scene: Scene, geometry: Geometry, cache_dir: Path | None, *, progress=None) -> Setup:
    """Return the set-up for ``scene`` and ``geometry``, from the cache when possible.

    The patch form factors depend only on the scene and the patch size, so they are cached
    in a file of their own and shared by every resolution and projector pose.

    Parameters
    ----------
    scene : Scene
    geometry : Geometry
    cache_dir : Path or None
        Directory of ``.npz`` cache files (created if needed); None disables caching.
    progress : callable, optional
        ``progress(step, total, message)``.

    Returns
    -------
    Setup
    """
    if cache_dir is None:
        return build(scene, geometry, progress=progress)
    common = {"scene": scene.digest, "patch_size": repr(float(geometry.patch_size)), "model": MODEL_DIGEST,
              "samples": [VIS_SAMPLES, LIGHT_SAMPLES, HIDDEN_PER_PATCH]}
    ff_key = _key(common)
    key = _key(dict(common, resolution=list(geometry.resolution), projector=geometry.projector,
                    projector_resolution=list(geometry.projector_resolution), supersample=int(geometry.supersample)))
    stem = re.sub(r"[^A-Za-z0-9_.-]", "_", scene.name)[:64]  # never a path outside cache_dir
    path = Path(cache_dir) / f"{stem}-{key}.npz"
    ff_path = Path(cache_dir) / f"{stem}-ff-{ff_key}.npz"
    cached = _load(path)
    if cached is not None:
        return cached
    ff = _load_arrays(ff_path, ("gn", "rescaled_rows"))
    setup = build(scene, geometry, progress=progress,
                  form_factors=None if ff is None else (ff["gn"], int(ff["rescaled_rows"])))
    if ff is None:
        _save_arrays(ff_path, {"gn": setup.gn, "rescaled_rows": np.array(setup.rescaled_rows)})
    _save(path, setup)
    return setup


def _key(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True).encode()).hexdigest()[:24]


def _save_arrays(path: Path, arrays: dict) -> None:
    """Write ``arrays`` to ``path`` atomically (:func:`engine.imageio.atomic_write`); failures only cost time."""
    arrays = dict(arrays, model=np.array(MODEL_DIGEST))

    def writer(temp: Path) -> None:
        with open(temp, "wb") as fh:
            np.savez(fh, **arrays)

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(path, writer)
    except OSError:
        pass


def _load_arrays(path: Path, names) -> dict | None:
    """Read arrays saved by :func:`_save_arrays`; None if missing, corrupt or outdated."""
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["model"]) != MODEL_DIGEST:
                return None
            return {n: z[n] for n in names}
    except Exception:  # corrupt, truncated or foreign file: rebuild
        return None


def patch_to_patch(scene: Scene, setup: Setup, *, per_edge: int = 4) -> np.ndarray:
    """Patch-to-patch form factors ``F[i, j]`` of the model's point-to-patch form factors.

    ``F[i, j]`` is the mean, over a ``per_edge x per_edge`` grid of points on patch ``i``, of
    the interpolated form factor to patch ``j`` (the ``G`` every sample uses). With exact
    form factors ``A_i F_ij = A_j F_ji`` (reciprocity) and rows sum to at most 1.

    Parameters
    ----------
    scene : Scene
    setup : Setup
        Built for ``scene``.
    per_edge : int
        Integration points per patch edge.

    Returns
    -------
    (P, P) float64
    """
    quads = scene.quads
    nu, nv, offset = _grid_of(setup, len(quads))
    q_parts, a_parts, b_parts, p_parts = [], [], [], []
    for q in range(len(quads)):
        gu, gv = nu[q] * per_edge, nv[q] * per_edge
        a, b = np.meshgrid((np.arange(gu) + 0.5) / gu, (np.arange(gv) + 0.5) / gv, indexing="ij")
        q_parts.append(np.full(a.size, q))
        a_parts.append(a.ravel())
        b_parts.append(b.ravel())
        patch_u, patch_v = np.arange(gu) // per_edge, np.arange(gv) // per_edge
        p_parts.append((offset[q] + patch_u[:, None] * nv[q] + patch_v[None, :]).ravel())
    qs, aa, bb, pp = map(np.concatenate, (q_parts, a_parts, b_parts, p_parts))
    node_offset = np.concatenate([[0], np.cumsum((nu + 1) * (nv + 1))])
    w = _interpolation(aa, bb, qs, np.ones(len(qs), bool), nu, nv, node_offset, setup.gn.shape[0])
    n_p = len(setup.patch_area)
    avg = sp.csr_matrix((np.full(len(pp), 1.0 / per_edge**2), (pp, np.arange(len(pp)))), shape=(n_p, len(pp)))
    return np.asarray(avg @ (w @ setup.gn))


def _grid_of(setup: Setup, n_quads: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Patch counts (nu, nv) and offsets of every quad, read back from a set-up."""
    return (setup.patch_nu.astype(np.int64), setup.patch_nv.astype(np.int64),
            np.concatenate([[0], np.cumsum(setup.patch_nu * setup.patch_nv)]).astype(np.int64))


def _save(path: Path, setup: Setup) -> None:
    arrays = {}
    for f in fields(Setup):
        value = getattr(setup, f.name)
        if sp.issparse(value):
            arrays[f"{f.name}__data"] = value.data
            arrays[f"{f.name}__indices"] = value.indices
            arrays[f"{f.name}__indptr"] = value.indptr
            arrays[f"{f.name}__shape"] = np.array(value.shape)
        else:
            arrays[f.name] = np.asarray(value)
    _save_arrays(path, arrays)


def _load(path: Path) -> Setup | None:
    names = []
    for f in fields(Setup):
        if f.name in ("mavg", "interp"):
            names += [f"{f.name}__data", f"{f.name}__indices", f"{f.name}__indptr", f"{f.name}__shape"]
        else:
            names.append(f.name)
    z = _load_arrays(path, names)
    if z is None:
        return None
    try:
        kw = {}
        for f in fields(Setup):
            if f.name in ("mavg", "interp"):
                shape = tuple(int(x) for x in z[f"{f.name}__shape"])
                kw[f.name] = sp.csr_matrix((z[f"{f.name}__data"], z[f"{f.name}__indices"], z[f"{f.name}__indptr"]),
                                           shape=shape)
            else:
                kw[f.name] = z[f.name]
        kw["rescaled_rows"] = int(kw["rescaled_rows"])
        kw["supersample"] = int(kw["supersample"])
        return Setup(**kw)
    except Exception:  # inconsistent arrays: rebuild
        return None


def build(scene: Scene, geometry: Geometry, *, progress=None, form_factors=None) -> Setup:
    """Compute the set-up (no cache). See the module docstring for the model.

    Parameters
    ----------
    scene : Scene
    geometry : Geometry
    progress : callable, optional
        ``progress(step, total, message)``.
    form_factors : (gn, rescaled_rows), optional
        Patch form factors computed before for the same scene and patch size.

    Returns
    -------
    Setup
    """
    quads = scene.quads
    normal = quads.normal
    camera, projector = views(scene, geometry)
    h, w = geometry.resolution
    steps = 4
    report(progress, 0, steps, "casting camera rays")

    # --- camera pixels -------------------------------------------------------------------
    dirs = camera.pixel_directions()
    hits = cast_rays(camera.position, dirs, quads)
    pix_ok = (hits.quad >= 0) & hits.front
    pixel_quad = np.where(pix_ok, hits.quad, -1)
    t = np.where(pix_ok, hits.t, 0.0)
    pix_points = camera.position + t[:, None] * dirs
    cos_view = np.abs(np.einsum("ij,ij->i", dirs, normal[np.maximum(pixel_quad, 0)]))
    omega = camera.pixel_solid_angle_factor(dirs) / (camera.fx * camera.fy)
    pix_area = np.where(pix_ok, omega * t**2 / np.maximum(cos_view, 1e-3), 0.0)
    pix_a, pix_b = np.where(pix_ok, hits.a, 0.0), np.where(pix_ok, hits.b, 0.0)

    # --- mixed pixels and their sub-samples -------------------------------------------------
    sub = int(geometry.supersample)
    per = sub * sub
    if sub > 1:
        mixed = _mixed_pixels(scene, camera, projector, pixel_quad, pix_a, pix_b, pix_points, (h, w))
        sdirs = camera.sub_pixel_directions(mixed, sub)
        shits = cast_rays(camera.position, sdirs, quads)
        s_ok = (shits.quad >= 0) & shits.front
        s_quad = np.where(s_ok, shits.quad, -1)
        s_t = np.where(s_ok, shits.t, 0.0)
        s_points = camera.position + s_t[:, None] * sdirs
        s_cos = np.abs(np.einsum("ij,ij->i", sdirs, normal[np.maximum(s_quad, 0)]))
        s_omega = camera.pixel_solid_angle_factor(sdirs) / (camera.fx * camera.fy * per)
        s_area = np.where(s_ok, s_omega * s_t**2 / np.maximum(s_cos, 1e-3), 0.0)
        s_a, s_b = np.where(s_ok, shits.a, 0.0), np.where(s_ok, shits.b, 0.0)
    else:
        mixed = np.zeros(0, np.int64)
        s_quad, s_points, s_area = np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0)
        s_a = s_b = np.zeros(0)
    # a mixed pixel's centre sample is inert: its sub-samples stand for it
    centre_quad = pixel_quad.copy()
    centre_quad[mixed] = -1
    n_vis = h * w + len(s_quad)

    # --- hidden samples ------------------------------------------------------------------
    nu, nv, offset = patch_grid(scene, geometry.patch_size)
    q_parts, a_parts, b_parts, area_parts = [], [], [], []
    for q in range(len(quads)):
        gu, gv = nu[q] * HIDDEN_PER_PATCH, nv[q] * HIDDEN_PER_PATCH
        a, b = np.meshgrid((np.arange(gu) + 0.5) / gu, (np.arange(gv) + 0.5) / gv, indexing="ij")
        q_parts.append(np.full(a.size, q))
        a_parts.append(a.ravel())
        b_parts.append(b.ravel())
        area_parts.append(np.full(a.size, quads.area[q] / (gu * gv)))
    hq, ha, hb, harea = map(np.concatenate, (q_parts, a_parts, b_parts, area_parts))
    hpoints = quads.point(hq, ha, hb)
    seen = _seen_by(camera, pixel_quad, hpoints, hq, normal)
    seen_pixel, _ = camera.nearest_pixel(hpoints[seen])
    seen_patch = offset[hq[seen]] + (np.minimum((ha[seen] * nu[hq[seen]]).astype(np.int64), nu[hq[seen]] - 1)
                                     * nv[hq[seen]] + np.minimum((hb[seen] * nv[hq[seen]]).astype(np.int64),
                                                                 nv[hq[seen]] - 1))
    seen_area = harea[seen]
    keep = ~seen
    hq, ha, hb, harea, hpoints = hq[keep], ha[keep], hb[keep], harea[keep], hpoints[keep]

    quad = np.concatenate([centre_quad, s_quad, hq])
    a = np.concatenate([pix_a, s_a, ha])
    b = np.concatenate([pix_b, s_b, hb])
    points = np.concatenate([pix_points, s_points, hpoints])
    area = np.concatenate([np.where(centre_quad >= 0, pix_area, 0.0), s_area, harea])
    live = quad >= 0
    qs = np.maximum(quad, 0)
    n_samples = len(quad)

    # --- patches, averaging and interpolation ---------------------------------------------
    pu = np.minimum((a * nu[qs]).astype(np.int64), nu[qs] - 1)
    pv = np.minimum((b * nv[qs]).astype(np.int64), nv[qs] - 1)
    patch = np.where(live, offset[qs] + pu * nv[qs] + pv, -1)
    n_patches = int(offset[-1])
    patch_quad = np.repeat(np.arange(len(quads)), nu * nv)
    patch_area = quads.area[patch_quad] / (nu * nv)[patch_quad]
    rows = np.flatnonzero(live)
    cols_patch, weights = patch[rows], area[rows]
    # a patch seen by the camera but too thin to contain a pixel's sample takes the radiance
    # of the pixels that see it (their samples lie on the same quad, just beside it)
    empty = np.bincount(cols_patch, minlength=n_patches) == 0
    extra = empty[seen_patch]
    rows = np.concatenate([rows, seen_pixel[extra]])
    cols_patch = np.concatenate([cols_patch, seen_patch[extra]])
    weights = np.concatenate([weights, seen_area[extra]])
    wsum = np.bincount(cols_patch, weights=weights, minlength=n_patches)
    mavg = sp.csr_matrix((weights / wsum[cols_patch], (cols_patch, rows)), shape=(n_patches, n_samples))
    nodes, node_quad, node_offset = _node_grid(quads, nu, nv)
    interp = _interpolation(a, b, qs, live, nu, nv, node_offset, len(nodes))

    report(progress, 1, steps, "form factors between patches")
    if form_factors is not None and form_factors[0].shape == (len(nodes), n_patches):
        gn, rescaled = form_factors
    else:
        gn = _patch_form_factors(quads, nodes, node_quad, patch_quad, nu, nv)
        sums = gn.sum(axis=1)
        over = sums > 1.0 + 1e-9
        gn[over] /= sums[over, None]
        rescaled = int(over.sum())

    report(progress, 2, steps, "ambient light")
    light_quads = np.flatnonzero(np.any(scene.emission > 0, axis=1))
    light_ff = np.zeros((n_samples, len(light_quads)))
    for k, lq in enumerate(light_quads):
        sel = np.flatnonzero(live & (quad != lq))
        # evaluate a hair inside the sample's quad: a point exactly on an edge shared with the
        # light would make the polygon formula singular
        inner = quads.point(quad[sel], np.clip(a[sel], NODE_INSET, 1 - NODE_INSET),
                            np.clip(b[sel], NODE_INSET, 1 - NODE_INSET))
        light_ff[sel, k] = _form_factor_to_quad(inner, normal[quad[sel]], quad[sel], quads, int(lq), LIGHT_SAMPLES)

    report(progress, 3, steps, "projector")
    pdirs = projector.pixel_directions()
    phits = cast_rays(projector.position, pdirs, quads)
    proj_pixel_quad = np.where((phits.quad >= 0) & phits.front, phits.quad, -1)
    # camera pixels: lit by their nearest projector pixel unless a shadow ray to the
    # projector is blocked; hidden samples: only where that pixel's own ray reaches their
    # quad (so a co-axial projector never lights what the camera cannot see)
    proj_index, inside = projector.nearest_pixel(points)
    facing = np.einsum("ij,ij->i", projector.position - points, normal[qs]) > 0
    lit = inside & facing & live
    cand = np.flatnonzero(lit[:n_vis])
    lit[cand] = ~occluded(points[cand], np.broadcast_to(projector.position, (cand.size, 3)), quads)
    lit[n_vis:] &= _seen_by(projector, proj_pixel_quad, points[n_vis:], quad[n_vis:], normal)
    to_p = projector.position - points
    dist = np.linalg.norm(to_p, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_in = np.einsum("ij,ij->i", to_p, normal[qs]) / dist
        cos_axis = -np.einsum("ij,j->i", to_p, projector.rotation[2]) / dist
        factor = cos_in / (dist**2 * cos_axis**3)
    proj_factor = np.where(lit, factor, 0.0)
    proj_index = np.where(lit, proj_index, 0)
    xy, z = projector.project(pix_points)
    proj_xy = np.where((pix_ok & (z > 0))[:, None], xy, np.nan)

    report(progress, steps, steps, "set-up done")
    return Setup(quad=quad, a=a, b=b, points=points, area=area, patch=patch,
                 patch_quad=patch_quad, patch_area=patch_area, patch_nu=nu, patch_nv=nv, mavg=mavg, interp=interp,
                 gn=gn,
                 light_quads=light_quads, light_ff=light_ff, proj_index=proj_index, proj_lit=lit,
                 proj_factor=proj_factor, proj_xy=proj_xy, pixel_quad=pixel_quad,
                 resolution=np.array(geometry.resolution), projector_resolution=np.array(geometry.projector_resolution),
                 sub_pixel=mixed.astype(np.int64), supersample=sub, rescaled_rows=rescaled)


def _mixed_pixels(scene: Scene, camera: View, projector: View, pixel_quad, a, b, points, shape) -> np.ndarray:
    """Pixels whose footprint may hold two surfaces, texture cells, projector shadow states or projector pixels.

    A pixel is mixed when a pixel of its 8-neighbourhood (itself included) differs from it
    in the quad seen, the texture cell seen, or whether an unblocked ray reaches the
    projector from the pixel's centre point; or when its footprint, mapped into the projector
    through the centre points of its neighbours on the same quad, crosses a projector pixel's
    border (a co-axial projector at the camera's resolution, or at half of it, never does).
    """
    h, w = shape
    n = h * w
    cell = np.full(n, -1, np.int64)
    for q, tex in scene.textures.items():
        sel = np.flatnonzero(pixel_quad == q)
        cell[sel] = tex.cell(a[sel], b[sel])
    normal = scene.quads.normal
    qs = np.maximum(pixel_quad, 0)
    _, inside = projector.nearest_pixel(points)
    facing = np.einsum("ij,ij->i", projector.position - points, normal[qs]) > 0
    lit = inside & facing & (pixel_quad >= 0)
    cand = np.flatnonzero(lit)
    lit[cand] = ~occluded(points[cand], np.broadcast_to(projector.position, (cand.size, 3)), scene.quads)
    out = _straddles(projector, points, pixel_quad, inside, (h, w))
    for key in (pixel_quad, cell, lit.astype(np.int64)):
        k = np.pad(key.reshape(h, w), 1, mode="edge")
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                out |= k[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] != k[1:1 + h, 1:1 + w]
    return np.flatnonzero(out.ravel())


def _straddles(projector: View, points, pixel_quad, inside, shape) -> np.ndarray:
    """(H, W) bool: pixels whose footprint crosses a projector pixel's border.

    The footprint's corners are the centre's projector position plus or minus half the
    position's steps to the neighbouring pixels on the same quad (central differences, one-sided
    at a quad's border), shrunk by 0.1 % so that a footprint whose border lies on a projector
    pixel's (co-axial projectors) does not count.
    """
    h, w = shape
    xy = projector.project(points)[0].reshape(h, w, 2)
    quad = pixel_quad.reshape(h, w)
    ok = (inside & (pixel_quad >= 0)).reshape(h, w)
    half = []
    for axis in (0, 1):  # rows, columns
        fwd, back = np.zeros((h, w, 2)), np.zeros((h, w, 2))
        n_f, n_b = np.zeros((h, w), bool), np.zeros((h, w), bool)
        lo = (slice(None, -1), slice(None)) if axis == 0 else (slice(None), slice(None, -1))
        hi = (slice(1, None), slice(None)) if axis == 0 else (slice(None), slice(1, None))
        same = ok[lo] & ok[hi] & (quad[lo] == quad[hi])
        step = np.where(same[..., None], xy[hi] - xy[lo], 0.0)
        fwd[lo], n_f[lo] = step, same
        back[hi], n_b[hi] = step, same
        count = n_f.astype(np.float64) + n_b
        half.append(0.5 * (fwd + back) / np.maximum(count, 1)[..., None])
    out = np.zeros((h, w), bool)
    own = np.rint(xy)
    for sv in (-1, 1):
        for su in (-1, 1):
            corner = xy + 0.999 * (sv * half[0] + su * half[1])
            out |= (np.rint(corner) != own).any(axis=-1)
    return out & ok


def _seen_by(view: View, pixel_quad: np.ndarray, points: np.ndarray, quad: np.ndarray,
             normal: np.ndarray) -> np.ndarray:
    """Whether each point (on ``quad``) is what its nearest pixel of ``view`` sees.

    A pixel's ray and a point projecting into that pixel meet the same plane within the
    pixel's footprint, so "the pixel sees the same quad, from the front" is pixel-resolution
    visibility (a shadow map without depth bias problems).
    """
    idx, inside = view.nearest_pixel(points)
    q = np.maximum(quad, 0)
    facing = np.einsum("ij,ij->i", view.position - points, normal[q]) > 0
    return inside & facing & (quad >= 0) & (pixel_quad[idx] == quad)


def _node_grid(quads: Quads, nu, nv) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Form-factor nodes at the patch-grid vertices of every quad.

    Returns
    -------
    points : (Nn, 3)
        Node positions, moved inside their quad by ``NODE_INSET`` (local units) so that no
        node lies on an edge shared with another quad (where the polygon formula is singular).
    node_quad : (Nn,) int64
    node_offset : (Q + 1,) int64
        First node of each quad; node ``(i, j)`` of quad ``q`` is ``node_offset[q] + i * (nv + 1) + j``.
    """
    q_parts, a_parts, b_parts = [], [], []
    for q in range(len(quads)):
        a, b = np.meshgrid(np.arange(nu[q] + 1) / nu[q], np.arange(nv[q] + 1) / nv[q], indexing="ij")
        q_parts.append(np.full(a.size, q))
        a_parts.append(np.clip(a.ravel(), NODE_INSET, 1 - NODE_INSET))
        b_parts.append(np.clip(b.ravel(), NODE_INSET, 1 - NODE_INSET))
    qs, aa, bb = map(np.concatenate, (q_parts, a_parts, b_parts))
    offset = np.concatenate([[0], np.cumsum((nu + 1) * (nv + 1))])
    return quads.point(qs, aa, bb), qs, offset


def _interpolation(a, b, q, live, nu, nv, node_offset, n_nodes) -> sp.csr_matrix:
    """Bilinear weights from the four nodes around each sample (rows sum to 1, 0 if inert)."""
    col_parts, val_parts = [], []
    parts = []
    for coord, n in ((a, nu[q]), (b, nv[q])):
        f = np.clip(coord, 0.0, 1.0) * n
        i0 = np.minimum(np.floor(f).astype(np.int64), n - 1)
        parts.append((i0, f - i0))
    (u0, fu), (v0, fv) = parts
    base = node_offset[q]
    stride = nv[q] + 1
    for ui, wu in ((u0, 1 - fu), (u0 + 1, fu)):
        for vi, wv in ((v0, 1 - fv), (v0 + 1, fv)):
            col_parts.append(base + ui * stride + vi)
            val_parts.append(wu * wv)
    rows = np.tile(np.arange(len(a)), 4)
    vals = np.concatenate(val_parts) * np.tile(live, 4)
    cols = np.where(np.tile(live, 4), np.concatenate(col_parts), 0)
    m = sp.coo_matrix((vals, (rows, cols)), shape=(len(a), n_nodes)).tocsr()
    m.eliminate_zeros()
    return m


def _patch_corners(quads: Quads, nu, nv) -> np.ndarray:
    """(P, 4, 3) corners of every patch, counter-clockwise from the front."""
    out = []
    for q in range(len(quads)):
        i, j = np.meshgrid(np.arange(nu[q]), np.arange(nv[q]), indexing="ij")
        i, j = i.ravel()[:, None], j.ravel()[:, None]
        du, dv = quads.u[q] / nu[q], quads.v[q] / nv[q]
        o = quads.origin[q] + i * du + j * dv
        out.append(np.stack([o, o + du, o + du + dv, o + dv], axis=1))
    return np.concatenate(out)


def _sub_points(corners: np.ndarray, m: int) -> np.ndarray:
    """(N, m*m, 3) points at the centres of an m x m grid on each parallelogram."""
    s = (np.arange(m) + 0.5) / m
    a, b = (g.ravel() for g in np.meshgrid(s, s, indexing="ij"))
    o = corners[:, 0]
    u = corners[:, 1] - o
    v = corners[:, 3] - o
    return o[:, None] + a[None, :, None] * u[:, None] + b[None, :, None] * v[:, None]


def _visibility(x: np.ndarray, nx: np.ndarray, sub: np.ndarray, ne: np.ndarray, quads: Quads,
                group: np.ndarray, blockers: np.ndarray) -> np.ndarray:
    """Kernel-weighted fraction of unblocked segments from points ``x`` to ``sub`` points
    (``group``: quad-pair id of each point, ``blockers``: :func:`blocker_table`)."""
    n, m = sub.shape[:2]
    d = sub - x[:, None]
    r2 = np.einsum("nki,nki->nk", d, d)
    wk = (np.maximum(np.einsum("nki,ni->nk", d, nx), 0) * np.maximum(-np.einsum("nki,ni->nk", d, ne), 0)
          / np.maximum(r2, 1e-30) ** 2)
    blocked = occluded(np.repeat(x, m, axis=0), sub.reshape(-1, 3), quads,
                       group=np.repeat(group, m), blockers=blockers).reshape(n, m)
    tot = wk.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        vis = np.where(tot > 0, (wk * ~blocked).sum(axis=1) / tot, (~blocked).mean(axis=1))
    return vis


def _patch_form_factors(quads: Quads, nodes, node_quad, patch_quad, nu, nv) -> np.ndarray:
    """Gn[m, j]: polygon form factor from node m to patch j, times its visibility fraction."""
    normal = quads.normal
    corners = _patch_corners(quads, nu, nv)
    centres = corners.mean(axis=1)
    subs = _sub_points(corners, VIS_SAMPLES)
    blockers = blocker_table(quads)
    n_n, n_p = len(nodes), len(corners)
    gn = np.zeros((n_n, n_p))
    step = max(1, (1 << 16) // max(n_p, 1))
    cols = np.arange(n_p)
    for lo in range(0, n_n, step):
        rows = np.arange(lo, min(lo + step, n_n))
        r, c = np.repeat(rows, n_p), np.tile(cols, len(rows))
        keep = node_quad[r] != patch_quad[c]
        keep &= np.einsum("ij,ij->i", nodes[r] - centres[c], normal[patch_quad[c]]) > 0
        r, c = r[keep], c[keep]
        f = polygon_form_factor(nodes[r], normal[node_quad[r]], corners[c])
        pos = f > 0
        r, c, f = r[pos], c[pos], f[pos]
        vis = _visibility(nodes[r], normal[node_quad[r]], subs[c], normal[patch_quad[c]], quads,
                          node_quad[r] * len(quads) + patch_quad[c], blockers)
        gn[r, c] = f * vis
    return gn


def _form_factor_to_quad(x: np.ndarray, nx: np.ndarray, xq: np.ndarray, quads: Quads, q: int, m: int) -> np.ndarray:
    """Form factor with visibility from points ``x`` (normals ``nx``, on quads ``xq``) to quad ``q``."""
    out = np.zeros(len(x))
    blockers = blocker_table(quads)
    corners = quad_corners(quads, np.array([q]))
    sub = _sub_points(corners, m)[0]
    nq = quads.normal[q]
    step = 1 << 15
    for lo in range(0, len(x), step):
        xs, ns, qs = x[lo:lo + step], nx[lo:lo + step], xq[lo:lo + step]
        facing = (xs - quads.origin[q]) @ nq > 0
        f = np.zeros(len(xs))
        idx = np.flatnonzero(facing)
        if idx.size:
            f[idx] = polygon_form_factor(xs[idx], ns[idx], np.broadcast_to(corners, (idx.size, 4, 3)))
        idx = np.flatnonzero(f > 0)
        if idx.size:
            subs = np.broadcast_to(sub, (idx.size,) + sub.shape)
            f[idx] *= _visibility(xs[idx], ns[idx], subs, np.broadcast_to(nq, (idx.size, 3)), quads,
                                  qs[idx] * len(quads) + q, blockers)
        out[lo:lo + step] = f
    return out
