"""The figurate-number transport matrices of Eq. 6 and Eq. 9.

Re-emitting the observed target radiance r times multiplies the interaction components by
figurate numbers: ``obs[r] = Σ_n M[r, n] R^n L_d`` with ``M[r, n] = binom(n + r, r)``
(paper, Eq. 6, Table 1 and Appendix A, Eq. 22). Outside the target the same numbers weigh
``C R^n L_d``, and the unreached light ``L̄_d`` appears only in the photograph (Eq. 9).
"""

from __future__ import annotations

from math import comb

import numpy as np

from engine.checks import check_order
from engine.errors import InputError

#: Highest order accepted anywhere: cond(M) grows ~13x per order (K = 8: 2e7), beyond which
#: float32 observations carry no information about the last components.
MAX_ORDER = 8


def transport_matrix(order: int) -> np.ndarray:
    """Return the K×K matrix relating observations to inside components (Eq. 6).

    Parameters
    ----------
    order : int
        K, the number of interaction components (1 ≤ K ≤ 8).

    Returns
    -------
    (K, K) float64
        ``M[r, n] = binom(n + r, r)``: row r is the r-th re-emission ``T^{r+1} L_d``,
        column n the component ``R^n L_d``.

    Notes
    -----
    The paper's Table 1 labels its rows T^1, T^2, T^2, T^3, T^4; the rows are T^1 … T^5.

    Examples
    --------
    >>> transport_matrix(3).astype(int)
    array([[1, 1, 1],
           [1, 2, 3],
           [1, 3, 6]])
    """
    k = _check(order)
    return np.array([[comb(n + r, r) for n in range(k)] for r in range(k)], dtype=np.float64)


def outside_matrix(order: int, *, unreached_light: bool = True) -> np.ndarray:
    """Return the K×K matrix relating observations to outside unknowns (Eq. 9).

    Parameters
    ----------
    order : int
        K, the number of observations.
    unreached_light : bool
        If True the unknowns are ``(L̄_d, C R^0 L_d, …, C R^{K-2} L_d)``: the first column
        is ``(1, 0, …, 0)`` because only the photograph contains ``L̄_d``. If False
        (projector-only lighting, ``L̄_d = 0``) the unknowns are ``C R^0 L_d … C R^{K-1} L_d``
        and the matrix equals :func:`transport_matrix`.

    Returns
    -------
    (K, K) float64

    Examples
    --------
    >>> outside_matrix(3).astype(int)
    array([[1, 1, 1],
           [0, 1, 2],
           [0, 1, 3]])
    """
    k = _check(order)
    m = transport_matrix(k)
    if not unreached_light:
        return m
    out = np.zeros((k, k))
    out[0, 0] = 1.0
    out[:, 1:] = m[:, : k - 1]
    return out


def _check(order: int) -> int:
    k = check_order(order)
    if k > MAX_ORDER:
        raise InputError(
            f"order must be at most {MAX_ORDER}, got {k}: the transport matrix's condition number "
            "grows ~13x per order and float32 observations cannot resolve more components"
        )
    return k
