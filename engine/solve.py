"""Batched, per-column constrained least squares for the interaction decomposition.

Every pixel-channel of a decomposition solves the same small problem ``min ‖A x − b‖``
(A is K×K, from :mod:`engine.figurate`) with its own ``b``. The constraints of the paper
(Sec. 3.2: ``0 ≤ R^i L_d ≤ R^{i-1} L_d``; ``L̄_d ≥ 0``) describe a polyhedral cone
``x = P d, d ≥ 0`` (:func:`cone_basis`), so every constraint mode is a non-negative least
squares problem in ``d``.

Because ``A`` is shared by millions of columns, the KKT conditions of every active set can
be precomputed as one small matrix each: the optimum of a column is the active set whose
matrix maps its ``b`` to a non-negative vector (free variables ≥ 0, gradient of the fixed
ones ≥ 0). :class:`ConeSolver` tries the active sets in order of how often they win on a
sample of the data, removing solved columns as it goes, so most columns are settled by one
or two small matrix products and there is no Python loop per pixel.
"""

from __future__ import annotations

import threading
from enum import StrEnum
from itertools import combinations

import numpy as np

from engine.checks import check_choice
from engine.errors import InputError

#: numba's default threading layer (workqueue) must not launch parallel kernels from two
#: threads at once; the app runs engine work on worker threads.
_KERNEL_LOCK = threading.Lock()


class Constraint(StrEnum):
    """Feasible set of the interaction components.

    ``ordered``: ``0 ≤ x_{K-1} ≤ … ≤ x_0`` (the paper's constraint; a leading unreached
    light term is only ``≥ 0``). ``nonnegative``: every component ``≥ 0``. ``none``: plain
    linear solve.
    """

    ORDERED = "ordered"
    NONNEGATIVE = "nonnegative"
    NONE = "none"


def cone_basis(n_vars: int, constraint: str, *, leading_free: bool = False) -> np.ndarray | None:
    """Return ``P`` such that the feasible set is ``{P d : d ≥ 0}``.

    Parameters
    ----------
    n_vars : int
        Number of unknowns per column.
    constraint : {"ordered", "nonnegative", "none"}
    leading_free : bool
        If True, the first unknown (the unreached light ``L̄_d``) is only required to be
        non-negative and takes no part in the ordering of the others.

    Returns
    -------
    (n_vars, n_vars) float64 or None
        None for ``"none"`` (no constraint). For ``"ordered"`` the block over the ordered
        unknowns is upper triangular ones: ``x_i = Σ_{j ≥ i} d_j``, a cumulative sum of
        non-negative increments, which makes the ordering a plain non-negativity.

    Examples
    --------
    >>> cone_basis(3, "ordered").astype(int)
    array([[1, 1, 1],
           [0, 1, 1],
           [0, 0, 1]])
    """
    constraint = Constraint(check_choice("constraint", constraint, Constraint))
    if constraint is Constraint.NONE:
        return None
    if constraint is Constraint.NONNEGATIVE:
        return np.eye(n_vars)
    p = np.zeros((n_vars, n_vars))
    start = 1 if leading_free else 0
    if leading_free:
        p[0, 0] = 1.0
    p[start:, start:] = np.triu(np.ones((n_vars - start, n_vars - start)))
    return p


class ConeSolver:
    """Solve ``min ‖A x − b‖₂ s.t. x = P d, d ≥ 0`` for many columns ``b`` at once.

    Parameters
    ----------
    a : (m, n) array_like
        The shared system matrix, full column rank (m ≥ n).
    basis : (n, n) array_like or None
        The cone basis ``P`` from :func:`cone_basis`; None solves without constraints.
    tol : float or None
        Relative tolerance of the KKT sign tests, as a fraction of each column's largest
        ``|b|``. None picks 1e-6 for float32 columns and 1e-10 for float64 (measured: at
        K = 5 with 1 % noise, float32 results then agree with scipy's NNLS to 3e-6 of the
        column's scale with no fallback; 1e-5 accepts suboptimal sets, off by 8e-4).

    Notes
    -----
    For a full-column-rank ``G = A P`` the non-negative least-squares optimum is unique and
    is the only active set ``S`` satisfying, with ``d_S = G_S⁺ b`` and ``d_i = 0`` off ``S``:
    ``d_S ≥ 0`` and ``G_iᵀ (G d − b) ≥ 0`` for ``i ∉ S``. Both tests are linear in ``b`` and
    are stacked into one n×m matrix per active set, precomputed in float64.

    Examples
    --------
    >>> solver = ConeSolver(np.eye(2), np.eye(2))
    >>> solver.solve(np.array([[1.0, -1.0], [2.0, 3.0]], np.float32))
    array([[1., 0.],
           [2., 3.]], dtype=float32)
    """

    def __init__(self, a, basis=None, *, tol: float | None = None):
        a = np.asarray(a, dtype=np.float64)
        if a.ndim != 2 or a.shape[0] < a.shape[1]:
            raise InputError(f"a must be an (m, n) matrix with m >= n, got shape {a.shape}")
        self.a = a
        self.basis = None if basis is None else np.asarray(basis, dtype=np.float64)
        self.tol = None if tol is None else float(tol)
        g = a if self.basis is None else a @ self.basis
        if np.linalg.matrix_rank(g) < g.shape[1]:
            raise InputError(f"a @ basis must have full column rank {g.shape[1]}")
        self._g = g
        n = g.shape[1]
        if self.basis is None:
            self._sets = [tuple(range(n))]
        else:
            self._sets = [s for k in range(n, -1, -1) for s in combinations(range(n), k)]
        self._tests = []  # per active set: (n, m) KKT test rows, each scaled to unit l1 norm
        self._maps = []  # per active set: (n_x, |S|) map from scaled test rows of S to x
        for s in self._sets:
            test, x_map = self._kkt_matrices(list(s))
            self._tests.append(test)
            self._maps.append(x_map)
        self._kernel_arrays = self._stack_for_kernel()

    def _kkt_matrices(self, free: list[int]) -> tuple[np.ndarray, np.ndarray]:
        g = self._g
        m, n = g.shape
        rows = np.zeros((n, m))
        if free:
            pinv = np.linalg.pinv(g[:, free])  # |S| x m
            rows[free] = pinv
            projector = g[:, free] @ pinv - np.eye(m)
        else:
            projector = -np.eye(m)
        fixed = [i for i in range(n) if i not in free]
        rows[fixed] = g[:, fixed].T @ projector
        norms = np.abs(rows).sum(axis=1)
        norms[norms == 0] = 1.0
        test = rows / norms[:, None]
        basis = np.eye(n) if self.basis is None else self.basis
        x_map = basis[:, free] * norms[free][None, :]
        return test, x_map

    def solve(self, b: np.ndarray) -> np.ndarray:
        """Solve every column of ``b``.

        Parameters
        ----------
        b : (m, N) float32 or float64
            One right-hand side per column; may be a strided view.

        Returns
        -------
        (n, N) array of b's dtype
            The constrained least-squares solution ``x`` of every column.
        """
        b = np.asarray(b)
        dtype = b.dtype if b.dtype.kind == "f" else np.dtype(np.float64)
        x = np.zeros((self.a.shape[1], b.shape[1]), dtype=dtype)
        solve_systems(
            b.astype(dtype, copy=False),
            np.zeros(b.shape[1], np.int8),
            [self],
            [np.arange(self.a.shape[1])],
            x,
        )
        return x

    def kernel_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """Return ``(tests (S, n, m), maps (S, n_x, n))`` for :func:`engine._kernels.kkt_columns`."""
        return self._kernel_arrays

    def _stack_for_kernel(self) -> tuple[np.ndarray, np.ndarray]:
        n = self._g.shape[1]
        maps = np.zeros((len(self._sets), self.a.shape[1], n))
        for i, free in enumerate(self._sets):
            maps[i][:, list(free)] = self._maps[i]
        return np.stack(self._tests), maps

    def tolerance(self, dtype) -> float:
        """KKT tolerance used for columns stored as ``dtype`` (infinite: no constraint)."""
        if self.basis is None:
            return np.inf
        if self.tol is not None:
            return self.tol
        return 1e-6 if np.dtype(dtype) == np.float32 else 1e-10

    def rank_sets(self, b: np.ndarray, tol: float, *, sample: int = 2048) -> np.ndarray:
        """Order active sets by how often each is optimal on evenly spaced columns of ``b``.

        The order only decides how many trials a column needs, never its result.
        """
        count = b.shape[1]
        wins = np.zeros(len(self._sets), dtype=np.int64)
        if count:
            cols = np.unique(np.linspace(0, count - 1, min(sample, count)).astype(np.int64))
            sub = np.asarray(b[:, cols], dtype=np.float64)
            scale = np.abs(sub).max(axis=0) * tol
            unsolved = np.ones(sub.shape[1], dtype=bool)
            for i, test in enumerate(self._tests):
                ok = unsolved & ((test @ sub) >= -scale).all(axis=0)
                wins[i] = ok.sum()
                unsolved &= ~ok
        return np.argsort(-wins, kind="stable").astype(np.int64)

    def best_feasible(self, b: np.ndarray, tol: float) -> np.ndarray:
        """Fallback for columns no KKT test accepted (rounding at degenerate optima).

        Among all active sets whose free variables are non-negative (within tolerance),
        take the one of least residual; negative rounding residue is set to zero.
        """
        b64 = np.asarray(b, dtype=np.float64)
        best = np.full(b64.shape[1], np.inf)
        out = np.zeros((self.a.shape[1], b64.shape[1]))
        basis = np.eye(self._g.shape[1]) if self.basis is None else self.basis
        scale = np.abs(b64).max(axis=0) * tol
        for s in self._sets:
            free = list(s)
            if not free:
                d_free = np.zeros((0, b64.shape[1]))
            else:
                d_free = np.linalg.pinv(self._g[:, free]) @ b64
            feasible = (d_free >= -scale).all(axis=0)
            d_free = np.maximum(d_free, 0.0)
            resid = np.linalg.norm(self._g[:, free] @ d_free - b64, axis=0)
            better = feasible & (resid < best)
            best[better] = resid[better]
            out[:, better] = basis[:, free] @ d_free[:, better]
        return out


def solve_systems(b, selector, solvers, destinations, out, extra=None, residual=None) -> None:
    """Solve each column of ``b`` with the solver ``selector`` names, writing in place.

    Parameters
    ----------
    b : (m, N) float32 or float64
        Right-hand sides (may be a strided view).
    selector : (N,) integer
        Index into ``solvers`` for each column.
    solvers : sequence of ConeSolver
        All with the same ``m`` and number of unknowns ``n_x``.
    destinations : sequence of (n_x,) int
        For each solver, the row of ``out`` receiving each unknown; ``n_x`` sends it to
        ``extra`` instead (how the unreached light leaves the packed components).
    out : (rows, N) float array, zero on entry
    extra : (N,) float array, zero on entry, optional
    residual : (N,) float64, optional
        Receives the squared fit residual ``‖A x − b‖²`` of each column.

    Notes
    -----
    The compiled kernel does the work in one pass; columns whose optimum is degenerate
    enough that rounding defeats every KKT test (rare) are finished by
    :meth:`ConeSolver.best_feasible`.
    """
    from engine._kernels import kkt_columns

    count = b.shape[1]
    nx = solvers[0].a.shape[1]
    tol = solvers[0].tolerance(b.dtype)
    if len({len(s._sets) for s in solvers}) != 1 or len({s.a.shape for s in solvers}) != 1:
        raise InputError("solvers must share their shape and constraint kind")
    arrays = [s.kernel_arrays() for s in solvers]
    tests = np.stack([t for t, _ in arrays])
    maps = np.stack([mp for _, mp in arrays])
    orders = np.stack([s.rank_sets(b[:, selector == g], tol) for g, s in enumerate(solvers)])
    dest = np.stack([np.asarray(d, np.int64) for d in destinations])
    a = np.stack([s.a for s in solvers])
    extra = np.zeros(count, out.dtype) if extra is None else extra
    res = np.zeros(count, np.float64) if residual is None else residual
    unresolved = np.zeros(count, np.bool_)
    with _KERNEL_LOCK:
        kkt_columns(b, np.asarray(selector, np.int64), tests, maps, orders, a, dest, tol, out, extra, res, unresolved)
    if unresolved.any():
        for g, solver in enumerate(solvers):
            cols = np.flatnonzero(unresolved & (selector == g))
            if cols.size == 0:
                continue
            x = solver.best_feasible(b[:, cols], tol)
            res[cols] = np.sum((solver.a @ x - b[:, cols]) ** 2, axis=0)
            for i, row in enumerate(destinations[g]):
                if row == nx:
                    extra[cols] = x[i]
                else:
                    out[row, cols] = x[i]


def solve_weighted(b, covariance, selector, solvers, destinations, out, extra, covariance_out, residual, *,
                   warm: bool = False) -> None:
    """Generalised least squares of each column, weighted by its own noise covariance.

    Parameters
    ----------
    b : (m, N) float32 or float64
        Right-hand sides.
    covariance : (m(m+1)/2, N) float
        Each column's noise covariance, packed (:func:`engine.noise.packed_index`).
    selector, solvers, destinations, out, extra
        As in :func:`solve_systems`.
    covariance_out : (n(n+1)/2, N) float32
        Receives the packed covariance of each column's unknowns, in the solver's order.
    residual : (N,) float64
        Receives the unweighted ``‖A x − b‖²``.
    warm : bool
        ``out``/``extra`` already hold the unweighted constrained optimum
        (:func:`solve_systems`): start the active-set search there.

    Notes
    -----
    Each column minimises ``(A x − b)ᵀ Σ⁻¹ (A x − b)`` over ``x = P d, d ≥ 0`` (no
    constraint for ``"none"``). A is square, so a column whose unconstrained solution
    ``(A P)⁻¹ b`` is feasible keeps it whatever Σ (within the KKT tolerance of
    :meth:`ConeSolver.tolerance`); the others are whitened by the Cholesky factor of their Σ
    and solved by Lawson–Hanson active sets. The covariance of ``x`` is that of the final active set's weighted solve,
    ``P_F (G_Fᵀ Σ⁻¹ G_F)⁻¹ P_Fᵀ`` — the estimate's spread when that set stays the optimum.
    For a square ``A`` without an active constraint the estimate is ``A⁻¹ b`` whatever Σ.
    """
    from engine._kernels import gls_columns

    if len({s.a.shape for s in solvers}) != 1 or solvers[0].a.shape[0] != solvers[0].a.shape[1]:
        raise InputError("solvers must share one square shape")
    n = solvers[0].a.shape[1]
    a = np.stack([s.a for s in solvers])
    basis = np.stack([np.eye(n) if s.basis is None else s.basis for s in solvers])
    inverse = np.stack([np.linalg.inv(s.a @ p) for s, p in zip(solvers, basis, strict=True)])
    ainv = np.stack([np.linalg.inv(s.a) for s in solvers])
    pinv = np.stack([np.linalg.inv(p) for p in basis])
    constrained = np.array([s.basis is not None for s in solvers])
    dest = np.stack([np.asarray(d, np.int64) for d in destinations])
    tol = solvers[0].tolerance(b.dtype)
    with _KERNEL_LOCK:
        gls_columns(b, covariance, np.asarray(selector, np.int64), a, basis, inverse, ainv, pinv, constrained, dest,
                    tol if np.isfinite(tol) else 0.0, out, extra, covariance_out, residual, bool(warm))
