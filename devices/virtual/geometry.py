"""Geometry of the virtual rig: pinhole views, ray casting against quads, form factors.

Surfaces are planar parallelograms ("quads") given by an origin ``o`` and two edge vectors
``u``, ``v``; their front side faces ``n = normalize(u x v)``. Everything here is vectorised
numpy over many rays or point pairs at once, chunked to bound memory.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Rays and segments ignore hits closer than this (scene units) to their start or end.
_EPS = 1e-7
# Number of rays or segments processed per chunk (bounds memory to a few tens of MB).
_CHUNK = 1 << 18


@dataclass(frozen=True, eq=False)
class Quads:
    """A set of ``Q`` planar parallelograms.

    Attributes
    ----------
    origin, u, v : (Q, 3) float64
        Corner ``p0`` and the edges ``p1 - p0`` and ``p3 - p0`` (scene units).
    """

    origin: np.ndarray
    u: np.ndarray
    v: np.ndarray

    @property
    def normal(self) -> np.ndarray:
        """(Q, 3) unit front normals ``normalize(u x v)``."""
        n = np.cross(self.u, self.v)
        return n / np.linalg.norm(n, axis=1, keepdims=True)

    @property
    def area(self) -> np.ndarray:
        """(Q,) areas ``|u x v|``."""
        return np.linalg.norm(np.cross(self.u, self.v), axis=1)

    def dual(self) -> tuple[np.ndarray, np.ndarray]:
        """Dual edge vectors ``(du, dv)`` with ``(p - o) . du = a`` for ``p = o + a u + b v``."""
        n = np.cross(self.u, self.v)
        du = np.cross(self.v, n) / np.einsum("ij,ij->i", self.u, np.cross(self.v, n))[:, None]
        dv = np.cross(n, self.u) / np.einsum("ij,ij->i", self.v, np.cross(n, self.u))[:, None]
        return du, dv

    def point(self, q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Points ``o + a u + b v`` on quads ``q`` at local coordinates ``a``, ``b`` in [0, 1]."""
        return self.origin[q] + a[:, None] * self.u[q] + b[:, None] * self.v[q]

    def __len__(self) -> int:
        return len(self.origin)


@dataclass(frozen=True, eq=False)
class View:
    """A pinhole view (camera or projector).

    Pixel ``(i, j)`` (row, column) has its centre at image coordinates ``x = j``, ``y = i``.

    Attributes
    ----------
    position : (3,) float64
        Centre of projection.
    rotation : (3, 3) float64
        Rows are the view's right, down and forward axes in world coordinates.
    fx, fy : float
        Focal lengths in pixels (horizontal, vertical).
    cx, cy : float
        Principal point in pixels.
    resolution : (H, W)
    """

    position: np.ndarray
    rotation: np.ndarray
    fx: float
    fy: float
    cx: float
    cy: float
    resolution: tuple[int, int]

    @classmethod
    def look_at(cls, position, look_at, up, fov_deg: float, resolution: tuple[int, int]) -> View:
        """Build a view from a pose and a vertical field of view with square pixels.

        Examples
        --------
        >>> v = View.look_at([0, 0, 0], [0, 0, 1], [0, 1, 0], 90.0, (4, 4))
        >>> v.project(np.array([[0.0, 0.0, 1.0]]))[0][0].round(3).tolist()
        [1.5, 1.5]
        """
        h, w = resolution
        f = (h / 2.0) / np.tan(np.radians(fov_deg) / 2.0)
        return cls.with_frustum(position, look_at, up, f, f, resolution)

    @classmethod
    def with_frustum(cls, position, look_at, up, fx: float, fy: float, resolution) -> View:
        """Build a view from a pose and focal lengths (principal point at the image centre)."""
        position = np.asarray(position, np.float64)
        fwd = np.asarray(look_at, np.float64) - position
        fwd /= np.linalg.norm(fwd)
        right = np.cross(np.asarray(up, np.float64), fwd)
        right /= np.linalg.norm(right)
        down = np.cross(right, fwd)  # image rows grow downwards, away from ``up``
        rot = np.stack([right, down, fwd])
        h, w = resolution
        return cls(position, rot, float(fx), float(fy), (w - 1) / 2.0, (h - 1) / 2.0, (int(h), int(w)))

    def rescaled(self, resolution: tuple[int, int]) -> View:
        """The same pose and frustum sampled at another resolution (co-axial projector)."""
        h, w = self.resolution
        hp, wp = resolution
        return View(self.position, self.rotation, self.fx * wp / w, self.fy * hp / h,
                    (wp - 1) / 2.0, (hp - 1) / 2.0, (int(hp), int(wp)))

    def pixel_directions(self) -> np.ndarray:
        """(H*W, 3) float64 unit ray directions through pixel centres, row-major."""
        h, w = self.resolution
        y, x = np.mgrid[0:h, 0:w]
        cam = np.stack([(x.ravel() - self.cx) / self.fx, (y.ravel() - self.cy) / self.fy,
                        np.ones(h * w)], axis=1)
        d = cam @ self.rotation
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def sub_pixel_directions(self, pixels: np.ndarray, sub: int) -> np.ndarray:
        """(len(pixels) * sub**2, 3) unit ray directions through a ``sub x sub`` grid of
        points inside each of the row-major ``pixels``, pixel by pixel."""
        h, w = self.resolution
        i, j = np.divmod(np.asarray(pixels, np.int64), w)
        off = (np.arange(sub) + 0.5) / sub - 0.5
        oy, ox = np.meshgrid(off, off, indexing="ij")
        x = (j[:, None] + ox.ravel()[None, :]).ravel()
        y = (i[:, None] + oy.ravel()[None, :]).ravel()
        cam = np.stack([(x - self.cx) / self.fx, (y - self.cy) / self.fy, np.ones(x.size)], axis=1)
        d = cam @ self.rotation
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project world points.

        Parameters
        ----------
        points : (N, 3) float64

        Returns
        -------
        xy : (N, 2) float64
            Image coordinates (x = column, y = row); meaningless where ``depth <= 0``.
        depth : (N,) float64
            Distance along the forward axis.
        """
        cam = (points - self.position) @ self.rotation.T
        z = cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = self.fx * cam[:, 0] / z + self.cx
            y = self.fy * cam[:, 1] / z + self.cy
        return np.stack([x, y], axis=1), z

    def nearest_pixel(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Row-major index of the pixel nearest to each point's projection, and whether it is
        inside the frame and in front of the view."""
        xy, z = self.project(points)
        h, w = self.resolution
        ok = (z > 0) & np.all(np.isfinite(xy), axis=1)
        j = np.rint(np.where(ok, xy[:, 0], -1.0))
        i = np.rint(np.where(ok, xy[:, 1], -1.0))
        ok &= (j >= 0) & (j < w) & (i >= 0) & (i < h)
        idx = np.where(ok, i * w + j, 0).astype(np.int64)
        return idx, ok

    def pixel_solid_angle_factor(self, directions: np.ndarray) -> np.ndarray:
        """``cos^3(alpha)`` of each direction relative to the forward axis: a pixel's solid
        angle is ``cos^3(alpha) / (fx fy)``."""
        c = directions @ self.rotation[2]
        return c**3


@dataclass(frozen=True, eq=False)
class Hits:
    """First hits of rays: quad index (-1 = none), distance, local coordinates, front side."""

    quad: np.ndarray
    t: np.ndarray
    a: np.ndarray
    b: np.ndarray
    front: np.ndarray


def cast_rays(origin: np.ndarray, directions: np.ndarray, quads: Quads) -> Hits:
    """Find the first quad hit by each ray.

    Parameters
    ----------
    origin : (3,) float64
        Common ray origin (a centre of projection).
    directions : (N, 3) float64
        Unit directions.
    quads : Quads

    Returns
    -------
    Hits
        ``quad`` (N,) int64 (-1 where nothing is hit), ``t`` distance, ``a``, ``b`` local
        coordinates on the hit quad, ``front`` True where the ray meets the quad's front side.

    Examples
    --------
    >>> q = Quads(np.array([[-1.0, -1, 2]]), np.array([[2.0, 0, 0]]), np.array([[0.0, 2, 0]]))
    >>> h = cast_rays(np.zeros(3), np.array([[0.0, 0, 1], [0.0, 1, 0]]), q)
    >>> h.quad.tolist(), h.t[0].item(), h.front.tolist()
    ([0, -1], 2.0, [False, False])
    """
    n_rays = len(directions)
    best_t = np.full(n_rays, np.inf)
    best_q = np.full(n_rays, -1, np.int64)
    best_a = np.zeros(n_rays)
    best_b = np.zeros(n_rays)
    normal = quads.normal
    du, dv = quads.dual()
    for q in range(len(quads)):
        denom = directions @ normal[q]
        num = (quads.origin[q] - origin) @ normal[q]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = num / denom
        cand = np.flatnonzero((np.abs(denom) > 1e-12) & (t > _EPS) & (t < best_t))
        if cand.size == 0:
            continue
        p = origin + t[cand, None] * directions[cand] - quads.origin[q]
        a = p @ du[q]
        b = p @ dv[q]
        inside = (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1)
        sel = cand[inside]
        best_t[sel] = t[sel]
        best_q[sel] = q
        best_a[sel] = a[inside]
        best_b[sel] = b[inside]
    hit = best_q >= 0
    front = np.zeros(n_rays, bool)
    front[hit] = np.einsum("ij,ij->i", directions[hit], normal[best_q[hit]]) < 0
    return Hits(best_q, np.where(hit, best_t, np.inf), best_a, best_b, front)


def occluded(start: np.ndarray, end: np.ndarray, quads: Quads, *, group: np.ndarray | None = None,
             blockers: np.ndarray | None = None) -> np.ndarray:
    """Whether the open segments ``start -> end`` cross any quad.

    A segment is blocked by a quad when its end points lie strictly on opposite sides of the
    quad's plane and the crossing is inside the quad, so a segment that starts or ends on a
    surface is never blocked by that surface.

    Parameters
    ----------
    start, end : (N, 3) float64
    quads : Quads
    group : (N,) int, optional
        A group id per segment (e.g. the pair of quads it joins) ...
    blockers : (G, Q) bool, optional
        ... and which quads can possibly block segments of each group (see
        :func:`blocker_table`). Without them every quad is tested.

    Returns
    -------
    (N,) bool

    Examples
    --------
    >>> q = Quads(np.array([[-1.0, -1, 1]]), np.array([[2.0, 0, 0]]), np.array([[0.0, 2, 0]]))
    >>> occluded(np.zeros((2, 3)), np.array([[0.0, 0, 2], [5.0, 0, 2]]), q).tolist()
    [True, False]
    >>> occluded(np.zeros((2, 3)), np.array([[0.0, 0, 2], [5.0, 0, 2]]), q, group=np.array([0, 1])).tolist()
    [True, False]
    """
    n = len(start)
    out = np.zeros(n, bool)
    if group is None or blockers is None:
        _occluded_by(start, end, quads, np.arange(len(quads)), out, np.arange(n))
        return out
    order = np.argsort(group, kind="stable")
    bounds = np.flatnonzero(np.diff(group[order])) + 1
    for idx in np.split(order, bounds):
        if idx.size:
            cols = np.flatnonzero(blockers[group[idx[0]]])
            if cols.size:
                _occluded_by(start, end, quads, cols, out, idx)
    return out


def _occluded_by(start, end, quads: Quads, cols: np.ndarray, out: np.ndarray, idx: np.ndarray) -> None:
    """Set ``out[idx]`` where segments ``idx`` cross one of the quads ``cols``.

    Dense over (segments, quads): plane distances and in-plane coordinates of both end
    points come from small matrix products, the crossing point's coordinates by linear
    interpolation between them.
    """
    normal = quads.normal[cols]
    du, dv = quads.dual()
    # rows: normal, du, dv of each quad; offsets: their dot products with the quad origin
    basis = np.concatenate([normal, du[cols], dv[cols]])
    offs = np.einsum("ij,ij->i", basis, np.tile(quads.origin[cols], (3, 1)))
    k = len(cols)
    chunk = max(1, 65536 // k)
    bx, by, bz = (basis[:, i:i + 1] for i in range(3))
    offs = offs[:, None]
    for lo in range(0, len(idx), chunk):
        sel = idx[lo:lo + chunk]
        # (3k, n) layout, explicit products: a BLAS call on inner size 3 is slow (and
        # multi-threaded BLAS stalls on a busy machine)
        s = start[sel].T
        e = end[sel].T
        ps = bx * s[0] + by * s[1] + bz * s[2] - offs
        pe = bx * e[0] + by * e[1] + bz * e[2] - offs
        ds, de = ps[:k], pe[:k]
        cross = ((ds > _EPS) & (de < -_EPS)) | ((ds < -_EPS) & (de > _EPS))
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ds / (ds - de)
            a = ps[k:2 * k] + t * (pe[k:2 * k] - ps[k:2 * k])
            b = ps[2 * k:] + t * (pe[2 * k:] - ps[2 * k:])
        hit = cross & (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1)
        out[sel[hit.any(axis=0)]] = True


def blocker_table(quads: Quads) -> np.ndarray:
    """Which quads can block segments joining two quads.

    Returns
    -------
    (Q * Q, Q) bool
        Row ``a * Q + b``, column ``c``: some segment from quad ``a`` to quad ``b`` may cross
        quad ``c``. False when all corners of ``a`` and ``b`` lie on one closed side of
        ``c``'s plane (then no such segment crosses it), or when ``c`` is ``a`` or ``b``.

    Examples
    --------
    >>> q = Quads(np.zeros((2, 3)) + [[0, 0, 0], [0, 0, 1]], np.array([[1.0, 0, 0]] * 2),
    ...           np.array([[0.0, 1, 0]] * 2))
    >>> blocker_table(q).any()
    np.False_
    """
    nq = len(quads)
    corners = quad_corners(quads)
    normal = quads.normal
    # d[c, a, k]: signed distance of corner k of quad a to the plane of quad c
    d = np.einsum("akj,cj->cak", corners, normal) - np.einsum("cj,cj->c", quads.origin, normal)[:, None, None]
    scale = max(float(np.ptp(corners.reshape(-1, 3), axis=0).max()), 1.0)
    pos = np.any(d > 1e-9 * scale, axis=2)  # (c, a)
    neg = np.any(d < -1e-9 * scale, axis=2)
    table = (pos[:, :, None] | pos[:, None, :]) & (neg[:, :, None] | neg[:, None, :])  # (c, a, b)
    idx = np.arange(nq)
    table[idx, idx, :] = False
    table[idx, :, idx] = False
    return table.transpose(1, 2, 0).reshape(nq * nq, nq)


def _edge_terms(x: np.ndarray, n: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Contour-integral term ``angle(Ra, Rb) * n . unit(Ra x Rb)`` of edges ``a -> b``."""
    ra = a - x
    rb = b - x
    c = np.cross(ra, rb)
    cn = np.linalg.norm(c, axis=-1)
    ang = np.arctan2(cn, np.einsum("...i,...i->...", ra, rb))
    with np.errstate(divide="ignore", invalid="ignore"):
        term = ang * np.einsum("...i,...i->...", c, n) / cn
    scale = np.linalg.norm(ra, axis=-1) * np.linalg.norm(rb, axis=-1)
    return np.where(cn > 1e-12 * scale, term, 0.0)


def polygon_form_factor(x: np.ndarray, n: np.ndarray, verts: np.ndarray) -> np.ndarray:
    """Unoccluded form factor from differential areas to convex one-sided quads.

    Lambert's contour integral ``F = -1/(2 pi) sum_edges angle_i n . unit(R_i x R_i+1)``
    over the quad clipped to the hemisphere above each point (vertices ordered
    counter-clockwise seen from the quad's front). Quads seen from behind give 0.

    Parameters
    ----------
    x : (N, 3) float64
        Receiving points.
    n : (N, 3) float64
        Unit normals of the receivers.
    verts : (N, 4, 3) float64
        Emitting quads' corners ``p0, p1, p2, p3``.

    Returns
    -------
    (N,) float64
        Form factors in [0, 1] (the fraction of the receiver's cosine-weighted hemisphere
        covered by the quad, including the 1/pi).

    Notes
    -----
    The result is exact (up to rounding) for a convex polygon; a closed enclosure of quads
    therefore sums to 1 from any interior point, which the tests check.

    Examples
    --------
    >>> sq = np.array([[[-1e3, -1e3, 1], [-1e3, 1e3, 1], [1e3, 1e3, 1], [1e3, -1e3, 1]]])
    >>> float(polygon_form_factor(np.zeros((1, 3)), np.array([[0, 0, 1.0]]), sq)[0].round(4))
    1.0
    """
    x = x[:, None, :]
    nn = n[:, None, :]
    d = np.einsum("nki,nki->nk", verts - x, np.broadcast_to(nn, verts.shape))
    above = d >= 0
    total = np.zeros(len(verts))
    exit_pt = np.zeros((len(verts), 3))
    entry_pt = np.zeros((len(verts), 3))
    has_exit = np.zeros(len(verts), bool)
    for k in range(4):
        va = verts[:, k]
        vb = verts[:, (k + 1) % 4]
        da = d[:, k]
        db = d[:, (k + 1) % 4]
        aa = above[:, k]
        ab = above[:, (k + 1) % 4]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(aa != ab, da / (da - db), 0.0)
        cross_pt = va + s[:, None] * (vb - va)
        start = np.where(aa[:, None], va, cross_pt)
        end = np.where(ab[:, None], vb, cross_pt)
        keep = aa | ab
        total += np.where(keep, _edge_terms(x[:, 0], n, start, end), 0.0)
        ex = aa & ~ab
        en = ~aa & ab
        exit_pt[ex] = cross_pt[ex]
        has_exit |= ex
        entry_pt[en] = cross_pt[en]
    # the clipped polygon runs along the horizon from the exit crossing to the entry crossing
    horizon = _edge_terms(x[:, 0], n, exit_pt, entry_pt)
    total += np.where(has_exit, horizon, 0.0)
    return np.clip(-total / (2 * np.pi), 0.0, 1.0)


def quad_corners(quads: Quads, idx: np.ndarray | None = None) -> np.ndarray:
    """(Q, 4, 3) corners ``o, o+u, o+u+v, o+v`` of (a selection of) quads."""
    o, u, v = quads.origin, quads.u, quads.v
    if idx is not None:
        o, u, v = o[idx], u[idx], v[idx]
    return np.stack([o, o + u, o + u + v, o + v], axis=1)
