"""Splitting observations into interaction components (paper Sec. 3.2).

A decomposition of order K holds, per pixel and channel, the components whose κ-weighted
sum is the recolored photograph: inside the target ``R^i L_d`` (Eq. 2-3, 6), outside it the
unreached light ``L̄_d`` and ``C R^i L_d`` (Eq. 4, 9).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from engine.checks import check_choice, check_float_image, check_kappa, check_mask, check_order, float_dtype
from engine.errors import InputError
from engine.figurate import MAX_ORDER, outside_matrix, transport_matrix
from engine.noise import packed_index
from engine.progress import Progress, ShouldStop, checkpoint, report
from engine.solve import ConeSolver, Constraint, cone_basis, solve_systems, solve_weighted

#: Pixels per tile: bounds the solver's working memory (~K·C·4·4 bytes per pixel).
TILE_PIXELS = 1 << 18


@dataclass(frozen=True, eq=False)
class Decomposition:
    """Interaction components of one target, packed for recoloring.

    Attributes
    ----------
    components : (K, H, W, C) float32
        On target pixels ``R^i L_d`` (i = 0..K-1); elsewhere ``C R^i L_d`` for
        i < K_out (zero beyond). Both families share one array because they never share a
        pixel, and recoloring weighs index i by ``κ^{i+1}`` in both (Eq. 3 and 4).
    unreached : (H, W, C) float32
        ``L̄_d``, light at non-target pixels that never touched the target (zero on target
        pixels, and everywhere when ``unreached_light`` is False).
    target : (H, W) bool
    constraint : str
        The solver's constraint mode.
    unreached_light : bool
        False when the lighting was declared projector-only (``L̄_d = 0``), which frees one
        more outside component.
    residual : (H, W) float32
        Relative fit residual ``‖A x − b‖ / ‖b‖`` per pixel over all channels; zero where
        the observations satisfy the constraints exactly.
    covariance : (K(K+1)/2, H, W, C) float32 or None
        Packed covariance (:func:`engine.noise.unpack_covariance`) of each pixel-channel's
        unknowns, in the solver's order: on the target ``R^0 L_d … R^{K-1} L_d``; off it
        ``L̄_d, C R^0 L_d … C R^{K-2} L_d`` (``C R^0 … C R^{K-1}`` without unreached light).
        None when the observations' noise was not given. Standard deviations:
        :meth:`standard_deviation`.
    blended : (H, W) bool or None
        Non-target pixels that :func:`engine.edge.blend_edges` re-packed as a mix of a soft
        mask's target part and its neighbour's (index i holds the target part's ``R^i L_d``,
        its direct light at i = 0, beside the neighbour's ``C R^i L_d``): their components
        are nothing like either side's, so a filter across pixels must keep them apart
        (:func:`engine.denoise.denoise_components`, :func:`engine.trust.prepare_trust`).
        None: no such pixel.
    observed : (K, C) float64 or None
        The observations summed over the target (Eq. 6's left side for the whole target),
        untouched by the constraint. The series' growth is read from these
        (:func:`engine.colour.kappa_limit`): the components' sums are biased up under noise,
        where the ordering constraint clips noisy components at 0 (realistic Cornell box at
        96², the demo's capture: blue observations rebuilt from them grew 12–14 % per order,
        these 2 %). Kept by noise reduction, the edge blend and filling (a filled pixel was not
        observed); None for a crop or when not known (older caches).
    """

    components: np.ndarray
    unreached: np.ndarray
    target: np.ndarray
    constraint: str = Constraint.ORDERED.value
    unreached_light: bool = True
    residual: np.ndarray | None = None
    covariance: np.ndarray | None = None
    blended: np.ndarray | None = None
    observed: np.ndarray | None = None

    def __post_init__(self) -> None:
        comps, unreached, target = self.components, self.unreached, self.target
        if not isinstance(comps, np.ndarray) or comps.dtype.kind != "f" or comps.ndim != 4:
            raise InputError(f"components must be a float array (K, H, W, C), got {_describe(comps)}")
        k, h, w, c = comps.shape
        if not 1 <= k <= MAX_ORDER or min(h, w, c) < 1:
            raise InputError(f"components must be (K, H, W, C) with K in 1..{MAX_ORDER} and H, W, C >= 1, "
                             f"got shape {comps.shape}")
        if not isinstance(unreached, np.ndarray) or unreached.dtype.kind != "f" or unreached.shape != (h, w, c):
            raise InputError(f"unreached must be a float array of shape {(h, w, c)}, got {_describe(unreached)}")
        if not isinstance(target, np.ndarray) or target.dtype != bool or target.shape != (h, w):
            raise InputError(f"target must be a bool array of shape {(h, w)}, got {_describe(target)}")
        if self.residual is not None and (not isinstance(self.residual, np.ndarray) or self.residual.shape != (h, w)):
            raise InputError(f"residual must be None or an array of shape {(h, w)}, got {_describe(self.residual)}")
        if self.blended is not None and (not isinstance(self.blended, np.ndarray) or self.blended.dtype != bool
                                         or self.blended.shape != (h, w)):
            raise InputError(f"blended must be None or a bool array of shape {(h, w)}, got {_describe(self.blended)}")
        if self.observed is not None and (not isinstance(self.observed, np.ndarray) or self.observed.shape != (k, c)
                                          or self.observed.dtype.kind != "f"):
            raise InputError(f"observed must be None or a float array of shape {(k, c)}, "
                             f"got {_describe(self.observed)}")
        check_choice("constraint", self.constraint, Constraint)
        if not isinstance(self.unreached_light, (bool, np.bool_)):
            raise InputError(f"unreached_light must be True or False, got {self.unreached_light!r}")

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The decomposition as named plain arrays (no pickle needed), e.g. for a session's cache.

        Returns
        -------
        dict
            ``components``, ``unreached``, ``target``, ``residual``, ``covariance``, ``blended`` and
            ``observed`` (when there are),
            ``flags`` ``(1,) bool`` (``unreached_light``) and ``constraint`` ``(16,) uint8``
            (the mode's name, space-padded). :meth:`from_arrays` reads it back.

        Examples
        --------
        >>> d = Decomposition(np.ones((2, 1, 2, 3), np.float32), np.zeros((1, 2, 3), np.float32),
        ...                   np.array([[True, False]]))
        >>> back = Decomposition.from_arrays(d.to_arrays())
        >>> back.order, back.constraint, bool(np.array_equal(back.target, d.target))
        (2, 'ordered', True)
        """
        arrays = {
            "components": self.components,
            "unreached": self.unreached,
            "target": self.target,
            "flags": np.array([self.unreached_light], bool),
            "constraint": np.frombuffer(str(self.constraint).encode().ljust(16), np.uint8),
        }
        if self.residual is not None:
            arrays["residual"] = self.residual
        if self.covariance is not None:
            arrays["covariance"] = self.covariance
        if self.blended is not None:
            arrays["blended"] = self.blended
        if self.observed is not None:
            arrays["observed"] = self.observed
        return arrays

    @classmethod
    def from_arrays(cls, arrays) -> Decomposition:
        """Rebuild a decomposition from :meth:`to_arrays`' output, refusing anything malformed.

        Raises
        ------
        InputError
            A missing array, a wrong dtype or shape, or non-finite components.
        """
        missing = sorted({"components", "unreached", "target", "flags", "constraint"} - set(arrays))
        if missing:
            raise InputError(f"the arrays lack {missing}; not a decomposition")
        flags, code = np.asarray(arrays["flags"]), np.asarray(arrays["constraint"])
        if flags.shape != (1,) or flags.dtype != bool or code.dtype != np.uint8 or code.ndim != 1:
            raise InputError("the arrays' flags or constraint are malformed; not a decomposition")
        try:
            constraint = bytes(code).decode("ascii").strip()
        except UnicodeDecodeError:
            raise InputError("the arrays' constraint is not a mode name; not a decomposition") from None
        d = cls(np.asarray(arrays["components"]), np.asarray(arrays["unreached"]), np.asarray(arrays["target"]),
                constraint, bool(flags[0]), None if "residual" not in arrays else np.asarray(arrays["residual"]),
                None if "covariance" not in arrays else np.asarray(arrays["covariance"]),
                None if "blended" not in arrays else np.asarray(arrays["blended"]),
                None if "observed" not in arrays else np.asarray(arrays["observed"]))
        check_float_image("components", d.components, ndim=4)
        check_float_image("unreached", d.unreached, ndim=3)
        if d.observed is not None:
            check_float_image("observed", d.observed, ndim=2)
        if d.covariance is not None:
            k = d.order
            check_float_image("covariance", d.covariance, ndim=4)
            if d.covariance.shape != (k * (k + 1) // 2,) + d.shape:
                raise InputError(f"the arrays' covariance has shape {d.covariance.shape}, not "
                                 f"{(k * (k + 1) // 2,) + d.shape}; not a decomposition")
        return d

    @property
    def order(self) -> int:
        """K, the number of inside components."""
        return int(self.components.shape[0])

    @cached_property
    def target_sums(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The target's components ``R^i L_d`` summed over its pixels, and their covariance.

        Returns
        -------
        sums : (K, C) float64
        covariance : (K, K, C) float64 or None
            Pixels taken as independent; None without :attr:`covariance`.

        Computed once (the colour checks read them at every κ: a 12 MP target's planes are
        gathered once, not per slider step).
        """
        sums = self.components[:, self.target].astype(np.float64).sum(axis=1)
        if self.covariance is None:
            return sums, None
        k = self.order
        cov = np.empty((k, k, sums.shape[1]))
        for i in range(k):
            for j in range(i, k):
                cov[i, j] = cov[j, i] = self.covariance[packed_index(i, j, k)][self.target].astype(np.float64).sum(0)
        return sums, cov

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(H, W, C)`` of the photograph."""
        _, h, w, c = self.components.shape
        return h, w, c

    @property
    def outside_order(self) -> int:
        """Number of outside components: K - 1, or K without unreached light."""
        return self.order - 1 if self.unreached_light else self.order

    @property
    def unblended_outside(self) -> np.ndarray:
        """``(H, W)`` bool: non-target pixels holding their own components only (not :attr:`blended`).

        The region a filter across pixels may mix outside the target: a blended edge pixel packs
        two surfaces' parts in the same slots and must be kept apart from it.
        """
        return ~self.target if self.blended is None else ~self.target & ~self.blended

    @property
    def inside(self) -> np.ndarray:
        """``(K, H, W, C)``: ``R^i L_d`` on target pixels, zero elsewhere (a new array)."""
        return np.where(self.target[None, :, :, None], self.components, 0).astype(self.components.dtype)

    @property
    def outside(self) -> np.ndarray:
        """``(K_out, H, W, C)``: ``C R^i L_d`` off the target, zero on it (a new array)."""
        comps = self.components[: self.outside_order]
        return np.where(self.target[None, :, :, None], 0, comps).astype(self.components.dtype)

    def crop(self, y0: int, y1: int, x0: int, x1: int) -> Decomposition:
        """The rectangle ``[y0:y1, x0:x1]`` as a decomposition of its own (views, no copy).

        Recoloring is per pixel (Eq. 3–4), so recoloring the crop equals cropping the recolor.
        """
        rows, cols = slice(y0, y1), slice(x0, x1)
        residual = None if self.residual is None else self.residual[rows, cols]
        cov = None if self.covariance is None else self.covariance[:, rows, cols]
        blended = None if self.blended is None else self.blended[rows, cols]
        return Decomposition(self.components[:, rows, cols], self.unreached[rows, cols], self.target[rows, cols],
                             self.constraint, self.unreached_light, residual, cov, blended)

    def standard_deviation(self) -> tuple[np.ndarray, np.ndarray]:
        """Standard deviation of every component and of the unreached light.

        Returns
        -------
        components : (K, H, W, C) float32
            Laid out like :attr:`components` (inside ``R^i L_d``, outside ``C R^i L_d``).
        unreached : (H, W, C) float32
            Of ``L̄_d`` (zero on the target and without unreached light).

        Raises
        ------
        InputError
            The decomposition carries no covariance (decomposed without the noise).
        """
        if self.covariance is None:
            raise InputError("this decomposition carries no covariance: decompose with covariance= "
                             "(the acquisition's Acquisition.covariance) to get standard deviations")
        k = self.order
        var = np.stack([self.covariance[packed_index(i, i, k)] for i in range(k)])
        inside = self.target[None, :, :, None]
        comps = np.where(inside, var, 0)
        unreached = np.zeros(self.shape, np.float32)
        if self.unreached_light:
            comps[: k - 1] += np.where(inside[0], 0, var[1:])
            unreached = np.where(inside[0], 0, var[0])
        else:
            comps += np.where(inside, 0, var)
        return np.sqrt(comps).astype(np.float32), np.sqrt(unreached).astype(np.float32)

    @classmethod
    def from_components(cls, inside, outside, unreached, target, *, constraint: str = "none") -> Decomposition:
        """Build a decomposition from separate inside/outside components (e.g. ground truth).

        Parameters
        ----------
        inside : (K, H, W, C) float
            ``R^i L_d``; only its target pixels are used.
        outside : (K-1 or K, H, W, C) float
            ``C R^i L_d``; only its non-target pixels are used. K components mean
            projector-only lighting (no unreached light).
        unreached : (H, W, C) float
            ``L̄_d``; only non-target pixels are used.
        target : (H, W) bool
        """
        inside = check_float_image("inside", inside, ndim=4)
        outside = check_float_image("outside", outside, ndim=4)
        unreached = check_float_image("unreached", unreached, ndim=3)
        k = inside.shape[0]
        if inside.shape[1:] != outside.shape[1:] or inside.shape[1:] != unreached.shape:
            raise InputError(
                f"inside {inside.shape}, outside {outside.shape} and unreached {unreached.shape} "
                "must share (H, W, C)"
            )
        if outside.shape[0] not in (k - 1, k):
            raise InputError(f"outside must have {k - 1} or {k} components for order {k}, got {outside.shape[0]}")
        target = check_mask("target", target, inside.shape[1:3])
        dtype = float_dtype(inside, outside, unreached)
        t = target[None, :, :, None]
        comps = np.where(t, inside, 0).astype(dtype)
        comps[: outside.shape[0]] += np.where(t, 0, outside).astype(dtype)
        with_unreached = outside.shape[0] == k - 1
        unr = np.where(t[0], 0, unreached).astype(dtype) if with_unreached else np.zeros_like(unreached, dtype)
        return cls(comps, unr, target.copy(), check_choice("constraint", constraint, Constraint), with_unreached)


def decompose(
    observations,
    target,
    *,
    constraint: str = "ordered",
    unreached_light: bool = True,
    covariance=None,
    progress: Progress | None = None,
    should_stop: ShouldStop | None = None,
) -> Decomposition:
    """Split a photograph and its re-emission captures into interaction components.

    Parameters
    ----------
    observations : (K, H, W, C) float32 or float64, linear radiance
        ``observations[0]`` is the photograph; ``observations[r]`` (r ≥ 1) the r-th
        re-emission capture with the photograph's light removed. C is 1 or 3.
    target : (H, W) bool
        The target area A in camera pixels; neither empty nor covering every pixel.
    constraint : {"ordered", "nonnegative", "none"}
        "ordered" is the paper's ``0 ≤ R^i L_d ≤ R^{i-1} L_d`` (and ``L̄_d ≥ 0``).
    unreached_light : bool
        False declares projector-only lighting (``L̄_d = 0``), which frees one more outside
        component (K instead of K-1).
    covariance : (K(K+1)/2, H, W, C) float, optional
        The observations' noise covariance per pixel and channel, packed
        (:attr:`engine.acquire.Acquisition.covariance`). Given, each pixel-channel is solved
        by generalised least squares weighted by its inverse and the result carries the
        covariance of its components (:attr:`Decomposition.covariance`).
    progress, should_stop
        Progress callback ``(step, total, message)`` and cooperative cancellation; see
        :mod:`engine.progress`. Checked between tiles.

    Returns
    -------
    Decomposition

    Raises
    ------
    InputError
        Bad shapes, dtypes, non-finite values, an order outside 1..8, an empty target or a
        target covering the whole image.
    Cancelled
        ``should_stop()`` returned True.

    Notes
    -----
    Inside the target each pixel-channel solves Eq. 6, ``obs[r] = Σ_n binom(n+r, r) R^n L_d``;
    outside it Eq. 9 with the extra unknown ``L̄_d`` present only in ``obs[0]``. Work is done
    in tiles of rows, so memory beyond the result stays bounded.

    With ``covariance`` the constrained problem is ``min (A x − b)ᵀ Σ⁻¹ (A x − b)``: the
    system is square, so where no constraint is active the estimate is the unweighted one,
    and Σ decides which way the ordering constraint moves the others where one is (a large
    noisy high-order observation no longer drags the well-measured components). The
    components' covariance is ``P_F (G_Fᵀ Σ⁻¹ G_F)⁻¹ P_Fᵀ`` for the active set F
    (``bench/solve.py`` measures the weighted solver beside the unweighted one).

    Examples
    --------
    >>> comps = np.array([1.0, 0.25], np.float32)           # R^0 L_d, R^1 L_d
    >>> obs = np.zeros((2, 1, 2, 1), np.float32)
    >>> obs[:, 0, 0, 0] = transport_matrix(2) @ comps       # a target pixel
    >>> obs[:, 0, 1, 0] = [0.5 + 0.125, 0.125]              # outside: L̄_d + C L_d, C L_d
    >>> d = decompose(obs, np.array([[True, False]]))
    >>> np.round(d.inside[:, 0, 0, 0], 6).tolist(), d.unreached[0, 1, 0].item(), d.outside[0, 0, 1, 0].item()
    ([1.0, 0.25], 0.5, 0.125)
    """
    obs = _check_observations(observations)
    k, h, w, c = obs.shape
    target = check_mask("target", target, (h, w))
    n_inside = int(np.count_nonzero(target))
    if n_inside == 0:
        raise InputError("target is empty: paint at least one pixel of the surface to recolor")
    if n_inside == h * w:
        raise InputError(
            f"target covers every pixel of the {h}x{w} image; a target is part of the photograph: "
            "leave the rest of the scene outside it"
        )
    constraint = check_choice("constraint", constraint, Constraint)
    unreached_light = bool(unreached_light)
    inside_solver = ConeSolver(transport_matrix(k), cone_basis(k, constraint))
    outside_solver = ConeSolver(
        outside_matrix(k, unreached_light=unreached_light),
        cone_basis(k, constraint, leading_free=unreached_light),
    )
    dtype = obs.dtype
    cov_in = None
    if covariance is not None:
        cov_in = check_float_image("covariance", covariance, ndim=4)
        if cov_in.shape != (k * (k + 1) // 2, h, w, c):
            raise InputError(f"covariance must have shape {(k * (k + 1) // 2, h, w, c)} (packed K(K+1)/2 planes "
                             f"per pixel-channel of the {k} observations), got {cov_in.shape}")
    components = np.zeros((k, h, w, c), dtype)
    unreached = np.zeros((h, w, c), dtype)
    residual = np.zeros((h, w), np.float32)
    cov_out = None if cov_in is None else np.zeros((k * (k + 1) // 2, h, w, c), np.float32)
    rows = max(1, TILE_PIXELS // w)
    tiles = range(0, h, rows)
    for step, y0 in enumerate(tiles):
        checkpoint(should_stop, "decomposition")
        report(progress, step, len(tiles), "decomposing")
        y1 = min(h, y0 + rows)
        _decompose_tile(obs, target, components, unreached, residual, (y0, y1), inside_solver, outside_solver,
                        unreached_light, cov_in, cov_out)
    report(progress, len(tiles), len(tiles), "decomposed")
    observed = obs[:, target].astype(np.float64).sum(axis=1)
    return Decomposition(components, unreached, target.copy(), constraint, unreached_light, residual, cov_out,
                         observed=observed)


def observe(decomposition: Decomposition, *, kappa=None, order: int | None = None) -> np.ndarray:
    """Synthesise the observations a decomposition predicts (the forward model, Eq. 6 and 9).

    Parameters
    ----------
    decomposition : Decomposition
    kappa : float or (C,) array_like, optional
        Weigh component i by ``κ^{i+1}`` first: the observations of the recolored scene,
        as used by the recolored prediction of Sec. 5.
    order : int, optional
        Number of observations to synthesise (default: the decomposition's order).

    Returns
    -------
    (order, H, W, C) float array
        ``obs[0]`` the photograph, ``obs[r]`` the r-th re-emission capture with the
        photograph's light removed.
    """
    comps = decomposition.components
    k = decomposition.order
    n_obs = k if order is None else check_order(order)
    c = comps.shape[-1]
    weights = np.ones((k, c))
    if kappa is not None:
        kap = check_kappa(kappa, c)
        weights = kap[None, :] ** np.arange(1, k + 1)[:, None]
    m = transport_matrix(max(n_obs, k))[:n_obs, :k]
    obs = np.zeros((n_obs,) + comps.shape[1:], comps.dtype)
    for r in range(n_obs):
        for n in range(k):
            # packed: inside and outside components share index n and weight κ^{n+1}
            obs[r] += (m[r, n] * weights[n]).astype(comps.dtype) * comps[n]
    obs[0] += decomposition.unreached
    return obs


def _describe(value) -> str:
    if isinstance(value, np.ndarray):
        return f"{value.dtype} array of shape {value.shape}"
    return type(value).__name__


def _check_observations(observations) -> np.ndarray:
    obs = check_float_image("observations", observations, ndim=4)
    k, h, w, c = obs.shape
    if k < 1:
        raise InputError(f"observations must hold at least the photograph (K >= 1), got K = {k} in shape {obs.shape}")
    if k > MAX_ORDER:
        raise InputError(f"observations hold K = {k} images; at most {MAX_ORDER} are supported")
    if c not in (1, 3):
        raise InputError(
            f"observations must have 1 or 3 channels in the last axis (K, H, W, C), got shape {obs.shape}"
        )
    if h == 0 or w == 0:
        raise InputError(f"observations have an empty image, shape {obs.shape}")
    return obs.astype(float_dtype(obs), copy=False)


def _decompose_tile(obs, target, components, unreached, residual, rows, inside_solver, outside_solver, unreached_light,
                    cov_in=None, cov_out=None):
    y0, y1 = rows
    k, _, w, c = obs.shape
    b = obs[:, y0:y1].reshape(k, -1)
    selector = np.repeat(~target[y0:y1].reshape(-1), c).astype(np.int8)  # 0 inside, 1 outside
    inside_rows = np.arange(k)
    # outside unknowns are (L̄_d, C R^0 L_d, ...): L̄_d goes to `unreached` (row index k)
    outside_rows = np.concatenate([[k], np.arange(k - 1)]) if unreached_light else inside_rows
    res_num = np.zeros(b.shape[1], np.float64)
    if cov_in is None:
        solve_systems(b, selector, [inside_solver, outside_solver], [inside_rows, outside_rows],
                      components[:, y0:y1].reshape(k, -1), unreached[y0:y1].reshape(-1), res_num)
    else:
        packed = cov_out[:, y0:y1].reshape(cov_out.shape[0], -1)
        out, extra = components[:, y0:y1].reshape(k, -1), unreached[y0:y1].reshape(-1)
        warm = inside_solver.basis is not None
        if warm:  # the unweighted optimum: a start that usually already has the weighted active set
            solve_systems(b, selector, [inside_solver, outside_solver], [inside_rows, outside_rows], out, extra,
                          res_num)
        solve_weighted(b, cov_in[:, y0:y1].reshape(cov_in.shape[0], -1), selector, [inside_solver, outside_solver],
                       [inside_rows, outside_rows], out, extra, packed, res_num, warm=warm)
        cov_out[:, y0:y1] = packed.reshape(cov_out[:, y0:y1].shape)
    res_den = np.einsum("ij,ij->j", b, b, dtype=np.float64)
    num = res_num.reshape(-1, c).sum(axis=1)
    den = res_den.reshape(-1, c).sum(axis=1)
    rel = np.sqrt(np.divide(num, den, out=np.zeros_like(num), where=den > 0))
    residual[y0:y1] = rel.reshape(y1 - y0, w)
