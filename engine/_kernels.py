"""Compiled kernel of the batched KKT active-set solver (see :mod:`engine.solve`).

One pass over the columns: for each column, try the precomputed active-set tests in the
given order (float64 arithmetic whatever the storage dtype), write the solution straight
into its destination rows and accumulate the squared fit residual. numba is used because
the numpy formulation spends most of its time in reductions and compaction between
trials (bench/solve.py measures both).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(parallel=True, cache=True, nogil=True)
def kkt_columns(b, selector, tests, maps, orders, a, dest, tol, out, extra, residual, unresolved):  # pragma: no cover - compiled
    """Solve every column of ``b`` (m, N) with the system ``selector[j]``.

    tests (G, S, n, m), maps (G, S, nx, n), orders (G, S), a (G, m, nx) are float64/int64;
    ``dest[g, i]`` is the output row of unknown i (``nx`` meaning ``extra``). ``out``
    (rows, N) and ``extra`` (N,) are zero on entry. ``residual`` (N,) receives
    ‖A x − b‖²; ``unresolved[j]`` is set where no test accepted the column.
    """
    m, count = b.shape
    n_sets = orders.shape[1]
    n = tests.shape[2]
    nx = maps.shape[2]
    chunk = 4096
    for c in prange((count + chunk - 1) // chunk):
        col = np.empty(m)
        y = np.empty(n)
        x = np.empty(nx)
        for j in range(c * chunk, min(count, (c + 1) * chunk)):
            _solve_column(b, j, selector[j], tests, maps, orders, a, dest, tol, out, extra, residual, unresolved, col, y, x, n_sets)


@njit(cache=True, inline="always")
def _solve_column(b, j, g, tests, maps, orders, a, dest, tol, out, extra, residual, unresolved, col, y, x, n_sets):  # pragma: no cover - compiled
    m = col.shape[0]
    n = y.shape[0]
    nx = x.shape[0]
    scale = 0.0
    for r in range(m):
        col[r] = b[r, j]
        if abs(col[r]) > scale:
            scale = abs(col[r])
    thr = -tol * scale
    found = False
    for t in range(n_sets):
        s = orders[g, t]
        ok = True
        for i in range(n):
            acc = 0.0
            for r in range(m):
                acc += tests[g, s, i, r] * col[r]
            if acc < thr:
                ok = False
                break
            y[i] = acc
        if ok:
            for i in range(nx):
                acc = 0.0
                for q in range(n):
                    acc += maps[g, s, i, q] * y[q]
                x[i] = acc
            found = True
            break
    if not found:
        unresolved[j] = True
        return
    res = 0.0
    for r in range(m):
        acc = -col[r]
        for i in range(nx):
            acc += a[g, r, i] * x[i]
        res += acc * acc
    residual[j] = res
    for i in range(nx):
        d = dest[g, i]
        if d == nx:
            extra[j] = x[i]
        else:
            out[d, j] = x[i]
