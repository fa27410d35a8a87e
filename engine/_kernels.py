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
def kkt_columns(  # pragma: no cover - compiled
    b, selector, tests, maps, orders, a, dest, tol, out, extra, residual, unresolved
):
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
            _solve_column(
                b, j, selector[j], tests, maps, orders, a, dest, tol, out, extra, residual, unresolved,
                col, y, x, n_sets,
            )


@njit(cache=True, inline="always")
def _solve_column(  # pragma: no cover - compiled
    b, j, g, tests, maps, orders, a, dest, tol, out, extra, residual, unresolved, col, y, x, n_sets
):
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
def gls_columns(b, cov, selector, a, basis, inverse, ainv, pinv, constrained, dest, tol, out, extra, cov_out,
                residual, warm):  # pragma: no cover - compiled
    """Weighted least squares of every column of ``b`` (m, N), ``x = P d`` with ``d ≥ 0``.

    ``cov`` (m(m+1)/2, N) is each column's packed noise covariance (upper triangle, row
    major); ``a`` (G, m, n), ``basis`` (G, n, n), ``inverse`` (G, n, m) = ``(A P)⁻¹`` and
    ``constrained`` (G,) describe the systems ``selector`` picks from (square: m = n), with
    ``ainv`` = A⁻¹ and ``pinv`` = P⁻¹. A column whose unconstrained solution is feasible
    keeps it (weights cannot move a square system's exact fit), its covariance
    ``A⁻¹ Σ A⁻ᵀ``; the others are whitened by the Cholesky factor of their covariance and
    solved by Lawson–Hanson active sets with Householder QR (float64 arithmetic), started
    from the unweighted solution already in ``out``/``extra`` when ``warm``.
    ``out``/``extra`` receive ``x`` through ``dest`` as in :func:`kkt_columns`, ``cov_out``
    (n(n+1)/2, N) the packed covariance of ``x`` given the active set, ``residual`` the
    unweighted ``‖A x − b‖²``.
    """
    m, count = b.shape
    n = a.shape[2]
    chunk = 1024
    for c in prange((count + chunk - 1) // chunk):
        sig = np.empty((m, m))
        lw = np.empty((m, m))
        g = np.empty((m, n))
        h = np.empty(m)
        col = np.empty(m)
        d = np.empty(n)
        s_ = np.empty(n)
        w = np.empty(n)
        free = np.empty(n, np.bool_)
        rinv = np.empty((n, n))
        q = np.empty((m, n))
        y = np.empty(m)
        v = np.empty(m)
        rr = np.empty((n, n))
        x = np.empty(n)
        t = np.empty((n, n))
        for j in range(c * chunk, min(count, (c + 1) * chunk)):
            _gls_column(b, cov, j, selector[j], a, basis, inverse, ainv, pinv, constrained, dest, tol, out, extra,
                        cov_out, residual, warm, sig, lw, g, h, col, d, s_, w, free, rinv, q, y, v, rr, x, t)


@njit(cache=True)
def _gls_column(b, cov, j, s, a, basis, inverse, ainv, pinv, constrained, dest, tol, out, extra, cov_out, residual,
                warm, sig, lw, g, h, col, d, s_, w, free, rinv, q, y, v, rr, x, t):  # pragma: no cover - compiled
    m = lw.shape[0]
    n = d.shape[0]
    p = 0
    scale = 0.0
    for r in range(m):
        col[r] = b[r, j]
        if abs(col[r]) > scale:
            scale = abs(col[r])
        for k in range(r, m):
            sig[r, k] = cov[p, j]
            sig[k, r] = cov[p, j]
            p += 1
    # unconstrained solution d = (A P)⁻¹ b: feasible columns are done (Σ cannot move them)
    feasible = True
    for k in range(n):
        acc = 0.0
        for r in range(m):
            acc += inverse[s, k, r] * col[r]
        d[k] = acc
        if constrained[s] and acc < -tol * scale:
            feasible = False
    if feasible:
        _map(ainv[s], col, sig, x, t, cov_out, j)  # x = A⁻¹ b, Cov x = A⁻¹ Σ A⁻ᵀ
        _write(j, s, a, dest, out, extra, residual, x, col)
        return
    # Cholesky of the column's covariance (a relative ridge keeps it positive definite)
    top = 0.0
    for r in range(m):
        for k in range(m):
            lw[r, k] = sig[r, k]
        if lw[r, r] > top:
            top = lw[r, r]
    ridge = top * 1e-12 + 1e-300
    for r in range(m):
        lw[r, r] += ridge
    for r in range(m):
        acc = lw[r, r]
        for k in range(r):
            acc -= lw[r, k] * lw[r, k]
        diag = np.sqrt(max(acc, ridge))
        lw[r, r] = diag
        for i in range(r + 1, m):
            acc = lw[i, r]
            for k in range(r):
                acc -= lw[i, k] * lw[r, k]
            lw[i, r] = acc / diag
    # whitened system: g = L⁻¹ A P, h = L⁻¹ b (forward substitution)
    for r in range(m):
        acc = col[r]
        for k in range(r):
            acc -= lw[r, k] * h[k]
        h[r] = acc / lw[r, r]
        for k in range(n):
            ap = 0.0
            for i in range(n):
                ap += a[s, r, i] * basis[s, i, k]
            acc = ap
            for q2 in range(r):
                acc -= lw[r, q2] * g[q2, k]
            g[r, k] = acc / lw[r, r]
    if warm:  # start from the unweighted optimum already written for this column
        for k in range(n):
            x[k] = extra[j] if dest[s, k] == n else out[dest[s, k], j]
        for k in range(n):
            acc = 0.0
            for i in range(n):
                acc += pinv[s, k, i] * x[i]
            d[k] = acc if acc > 0.0 else 0.0
    else:  # the unconstrained solution's positive part
        for k in range(n):
            if d[k] < 0.0:
                d[k] = 0.0
    _nnls(g, h, d, s_, w, free, rinv, q, y, v, rr, tol)
    # covariance of d on the free set: R⁻¹ R⁻ᵀ (zero along the fixed increments)
    nf = 0
    for k in range(n):
        if free[k]:
            nf += 1
    for i in range(n):
        for k in range(n):
            rr[i, k] = 0.0
    fi = 0
    for i in range(n):
        if not free[i]:
            continue
        fk = 0
        for k in range(n):
            if not free[k]:
                continue
            acc = 0.0
            for r in range(max(fi, fk), nf):
                acc += rinv[fi, r] * rinv[fk, r]
            rr[i, k] = acc
            fk += 1
        fi += 1
    _finish(j, s, a, basis, dest, out, extra, cov_out, residual, d, rr, x, t, col)


@njit(cache=True)
def _finish(j, s, a, basis, dest, out, extra, cov_out, residual, d, cd, x, t, col):  # pragma: no cover - compiled
    """x = P d and its packed covariance P cov(d) Pᵀ, then :func:`_write`."""
    _map(basis[s], d, cd, x, t, cov_out, j)
    _write(j, s, a, dest, out, extra, residual, x, col)


@njit(cache=True)
def _map(mat, vec, cov, x, t, cov_out, j):  # pragma: no cover - compiled
    """``x = mat vec`` and column ``j`` of ``cov_out`` = the packed upper triangle of
    ``mat cov matᵀ`` (``t`` receives ``mat cov``): a linear map of an estimate and its covariance."""
    n, m = mat.shape
    for i in range(n):
        acc = 0.0
        for r in range(m):
            acc += mat[i, r] * vec[r]
        x[i] = acc
        for r in range(m):
            acc = 0.0
            for q2 in range(m):
                acc += mat[i, q2] * cov[q2, r]
            t[i, r] = acc
    p = 0
    for i in range(n):
        for k in range(i, n):
            acc = 0.0
            for r in range(m):
                acc += t[i, r] * mat[k, r]
            cov_out[p, j] = acc
            p += 1


@njit(cache=True)
def _write(j, s, a, dest, out, extra, residual, x, col):  # pragma: no cover - compiled
    """Residual ``‖A x − b‖²`` and ``x`` written through ``dest``."""
    n = x.shape[0]
    m = col.shape[0]
    res = 0.0
    for r in range(m):
        acc = -col[r]
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
def _lstsq_free(g, h, free, d, rinv, q, y, v, rr):  # pragma: no cover - compiled
    """Least squares of ``g[:, free] y = h`` by Householder QR; ``d`` = y on free, 0 elsewhere.

    ``rinv[:nf, :nf]`` receives R⁻¹ (upper triangular) of the free columns' QR.
    """
    m, n = g.shape
    nf = 0
    for k in range(n):
        if free[k]:
            for r in range(m):
                q[r, nf] = g[r, k]
            nf += 1
    for r in range(m):
        y[r] = h[r]
    for k in range(nf):
        norm = 0.0
        for r in range(k, m):
            norm += q[r, k] * q[r, k]
        norm = np.sqrt(norm)
        alpha = -norm if q[k, k] >= 0 else norm
        for r in range(m):
            v[r] = q[r, k] if r >= k else 0.0
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
        for c2 in range(nf):
            rr[k, c2] = q[k, c2] if c2 >= k else 0.0
    for k in range(nf - 1, -1, -1):
        diag = rr[k, k]
        if diag == 0.0:
            diag = 1e-300
        for c2 in range(nf):
            rinv[k, c2] = 0.0
        rinv[k, k] = 1.0 / diag
        for c2 in range(k + 1, nf):
            acc = 0.0
            for i in range(k + 1, c2 + 1):
                acc += rr[k, i] * rinv[i, c2]
            rinv[k, c2] = -acc / diag
    col = 0
    for k in range(n):
        if free[k]:
            acc = 0.0
            for i in range(col, nf):
                acc += rinv[col, i] * y[i]
            d[k] = acc
            col += 1
        else:
            d[k] = 0.0


@njit(cache=True)
def _settle(g, h, d, s, free, rinv, q, y, v, rr):  # pragma: no cover - compiled
    """The inner loop of Lawson–Hanson: solve on the passive (free) set; while that solution
    leaves it, step from ``d`` toward it as far as stays feasible and drop the variables that
    reach zero. Ends with ``d`` the feasible solution on the final free set (0 elsewhere).

    Returns True when ``s`` and ``rinv`` hold the least-squares solve of that final free set
    (so :func:`_nnls` need not factor it again)."""
    n = g.shape[1]
    for _inner in range(3 * n + 3):
        anyfree = False
        for k in range(n):
            anyfree = anyfree or free[k]
        if not anyfree:
            return False
        _lstsq_free(g, h, free, s, rinv, q, y, v, rr)
        ok = True
        for k in range(n):
            if free[k] and s[k] <= 0:
                ok = False
        if ok:
            for k in range(n):
                d[k] = s[k]
            return True
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
    return False


@njit(cache=True)
def _nnls(g, h, d, s, w, free, rinv, q, y, v, rr, tol):  # pragma: no cover - compiled
    """Lawson–Hanson non-negative least squares of ``g d = h`` (n ≤ a few dozen).

    Starts from the feasible ``d`` given (its support the passive set): a good start —
    the unweighted solution's positive part — settles most columns in one or two solves.
    """
    m, n = g.shape
    for k in range(n):
        free[k] = d[k] > 0.0
        if not free[k]:
            d[k] = 0.0
    current = _settle(g, h, d, s, free, rinv, q, y, v, rr)  # the starting passive set first
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
        for r in range(m):
            res = h[r]
            for i in range(n):
                res -= g[r, i] * d[i]
            y[r] = res
        best, arg = thresh, -1
        for k in range(n):
            acc = 0.0
            for r in range(m):
                acc += g[r, k] * y[r]
            w[k] = acc
            if not free[k] and acc > best:
                best, arg = acc, k
        if arg < 0:
            break
        free[arg] = True
        current = _settle(g, h, d, s, free, rinv, q, y, v, rr)
    # R⁻¹ of the final free set (the covariance's factor), d on it: already there when the last
    # settle ended on a solve of that set (most columns: one factorisation instead of two)
    if not current:
        _lstsq_free(g, h, free, s, rinv, q, y, v, rr)
    for k in range(n):
        d[k] = s[k] if free[k] and s[k] > 0 else 0.0
