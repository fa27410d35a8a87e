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


@njit(parallel=True, cache=True, nogil=True)
def gls_columns(b, cov, selector, a, basis, constrained, dest, tol, out, extra, cov_out, residual):  # pragma: no cover - compiled
    """Weighted least squares of every column of ``b`` (m, N), ``x = P d`` with ``d ≥ 0``.

    ``cov`` (m(m+1)/2, N) is each column's packed noise covariance (upper triangle, row
    major); ``a`` (G, m, n), ``basis`` (G, n, n) and ``constrained`` (G,) describe the
    systems ``selector`` picks from. Each column is whitened by the Cholesky factor of its
    covariance and solved by Lawson–Hanson active sets with Householder QR (float64
    arithmetic). ``out``/``extra`` receive ``x`` through ``dest`` as in :func:`kkt_columns`,
    ``cov_out`` (n(n+1)/2, N) the packed covariance of ``x`` given the active set, and
    ``residual`` the unweighted ``‖A x − b‖²``.
    """
    m, count = b.shape
    n = a.shape[2]
    chunk = 1024
    for c in prange((count + chunk - 1) // chunk):
        lw = np.empty((m, m))
        g = np.empty((m, n))
        h = np.empty(m)
        d = np.empty(n)
        free = np.empty(n, np.bool_)
        rinv = np.empty((n, n))
        for j in range(c * chunk, min(count, (c + 1) * chunk)):
            _gls_column(b, cov, j, selector[j], a, basis, constrained, dest, tol, out, extra, cov_out, residual,
                        lw, g, h, d, free, rinv)


@njit(cache=True)
def _gls_column(b, cov, j, s, a, basis, constrained, dest, tol, out, extra, cov_out, residual,
                lw, g, h, d, free, rinv):  # pragma: no cover - compiled
    m = lw.shape[0]
    n = d.shape[0]
    # Cholesky of the column's covariance (a relative ridge keeps it positive definite)
    p = 0
    top = 0.0
    for r in range(m):
        for q in range(r, m):
            lw[r, q] = cov[p, j]
            lw[q, r] = cov[p, j]
            p += 1
        if lw[r, r] > top:
            top = lw[r, r]
    ridge = top * 1e-12 + 1e-300
    for r in range(m):
        lw[r, r] += ridge
    for r in range(m):
        acc = lw[r, r]
        for q in range(r):
            acc -= lw[r, q] * lw[r, q]
        diag = np.sqrt(max(acc, ridge))
        lw[r, r] = diag
        for i in range(r + 1, m):
            acc = lw[i, r]
            for q in range(r):
                acc -= lw[i, q] * lw[r, q]
            lw[i, r] = acc / diag
    # whitened system: g = L⁻¹ A P, h = L⁻¹ b (forward substitution)
    for r in range(m):
        acc = b[r, j]
        for q in range(r):
            acc -= lw[r, q] * h[q]
        h[r] = acc / lw[r, r]
        for k in range(n):
            ap = 0.0
            for i in range(n):
                ap += a[s, r, i] * basis[s, i, k]
            acc = ap
            for q in range(r):
                acc -= lw[r, q] * g[q, k]
            g[r, k] = acc / lw[r, r]
    if constrained[s]:
        _nnls(g, h, d, free, rinv, tol)
    else:
        for k in range(n):
            free[k] = True
        _lstsq_free(g, h, free, d, rinv)
    # x = P d, its covariance P_F (R_F^T R_F)^-1 P_F^T = P_F R⁻¹ R⁻ᵀ P_F^T
    nf = 0
    for k in range(n):
        if free[k]:
            nf += 1
    x = np.zeros(n)
    for i in range(n):
        acc = 0.0
        for k in range(n):
            acc += basis[s, i, k] * d[k]
        x[i] = acc
    pf = np.zeros((n, nf))
    col = 0
    for k in range(n):
        if free[k]:
            for i in range(n):
                pf[i, col] = basis[s, i, k]
            col += 1
    t = np.zeros((n, nf))  # P_F R⁻¹
    for i in range(n):
        for q in range(nf):
            acc = 0.0
            for r in range(q + 1):
                acc += pf[i, r] * rinv[r, q]
            t[i, q] = acc
    p = 0
    for i in range(n):
        for k in range(i, n):
            acc = 0.0
            for q in range(nf):
                acc += t[i, q] * t[k, q]
            cov_out[p, j] = acc
            p += 1
    res = 0.0
    for r in range(m):
        acc = -b[r, j]
        for i in range(n):
            acc += a[s, r, i] * x[i]
        res += acc * acc
    residual[j] = res
    for i in range(n):
        row = dest[s, i]
        if row == n:
            extra[j] = x[i]
        else:
            out[row, j] = x[i]


@njit(cache=True)
def _lstsq_free(g, h, free, d, rinv):  # pragma: no cover - compiled
    """Least squares of ``g[:, free] y = h`` by Householder QR; ``d`` = y on free, 0 elsewhere.

    ``rinv[:nf, :nf]`` receives R⁻¹ (upper triangular) of the free columns' QR.
    """
    m, n = g.shape
    nf = 0
    for k in range(n):
        if free[k]:
            nf += 1
    q = np.empty((m, nf))
    col = 0
    for k in range(n):
        if free[k]:
            for r in range(m):
                q[r, col] = g[r, k]
            col += 1
    y = h.copy()
    rr = np.zeros((nf, nf))
    for k in range(nf):
        norm = 0.0
        for r in range(k, m):
            norm += q[r, k] * q[r, k]
        norm = np.sqrt(norm)
        alpha = -norm if q[k, k] >= 0 else norm
        v = np.zeros(m)
        for r in range(k, m):
            v[r] = q[r, k]
        v[k] -= alpha
        vv = 0.0
        for r in range(k, m):
            vv += v[r] * v[r]
        if vv > 0:
            for c2 in range(k, nf):
                dot = 0.0
                for r in range(k, m):
                    dot += v[r] * q[r, c2]
                f = 2.0 * dot / vv
                for r in range(k, m):
                    q[r, c2] -= f * v[r]
            dot = 0.0
            for r in range(k, m):
                dot += v[r] * y[r]
            f = 2.0 * dot / vv
            for r in range(k, m):
                y[r] -= f * v[r]
        for c2 in range(k, nf):
            rr[k, c2] = q[k, c2]
    for r in range(nf):
        for c2 in range(nf):
            rinv[r, c2] = 0.0
    for k in range(nf - 1, -1, -1):
        diag = rr[k, k]
        if diag == 0.0:
            diag = 1e-300
        rinv[k, k] = 1.0 / diag
        for c2 in range(k + 1, nf):
            acc = 0.0
            for i in range(k + 1, c2 + 1):
                acc += rr[k, i] * rinv[i, c2]
            rinv[k, c2] = -acc / diag
    sol = np.zeros(nf)
    for k in range(nf):
        acc = 0.0
        for i in range(k, nf):
            acc += rinv[k, i] * y[i]
        sol[k] = acc
    col = 0
    for k in range(n):
        if free[k]:
            d[k] = sol[col]
            col += 1
        else:
            d[k] = 0.0


@njit(cache=True)
def _nnls(g, h, d, free, rinv, tol):  # pragma: no cover - compiled
    """Lawson–Hanson non-negative least squares of ``g d = h`` (n ≤ a few dozen)."""
    m, n = g.shape
    for k in range(n):
        d[k] = 0.0
        free[k] = False
    s = np.empty(n)
    w = np.empty(n)
    scale = 0.0
    for r in range(m):
        scale += h[r] * h[r]
    gnorm = 0.0
    for r in range(m):
        for k in range(n):
            gnorm = max(gnorm, abs(g[r, k]))
    thresh = tol * np.sqrt(scale) * gnorm + 1e-300
    for _ in range(3 * n + 3):
        # gradient w = gᵀ (h − g d)
        best, arg = thresh, -1
        for k in range(n):
            acc = 0.0
            for r in range(m):
                res = h[r]
                for i in range(n):
                    res -= g[r, i] * d[i]
                acc += g[r, k] * res
            w[k] = acc
            if not free[k] and acc > best:
                best, arg = acc, k
        if arg < 0:
            break
        free[arg] = True
        for _inner in range(3 * n + 3):
            _lstsq_free(g, h, free, s, rinv)
            ok = True
            for k in range(n):
                if free[k] and s[k] <= 0:
                    ok = False
            if ok:
                for k in range(n):
                    d[k] = s[k]
                break
            alpha = 1.0
            for k in range(n):
                if free[k] and s[k] <= 0:
                    step = d[k] / (d[k] - s[k]) if d[k] - s[k] != 0 else 0.0
                    if step < alpha:
                        alpha = step
            for k in range(n):
                d[k] = d[k] + alpha * (s[k] - d[k]) if free[k] else 0.0
                if free[k] and d[k] <= 0:
                    free[k] = False
                    d[k] = 0.0
    # rinv of the final free set (the covariance's factor)
    _lstsq_free(g, h, free, s, rinv)
    for k in range(n):
        d[k] = s[k] if free[k] and s[k] > 0 else 0.0
