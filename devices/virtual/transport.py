"""Linear light transport of the virtual rig: direct light, indirect light, interactions.

The model (see :mod:`devices.virtual.setup` for the arrays): every sample ``s`` has an
albedo ``rho_s`` (per channel, < 1) and receives direct light ``E_s`` (irradiance / pi, from
the ambient light and the projector). Its reflected radiance is::

    L = rho * (E + G Mavg L),      G = W Gn   (interpolated point-to-patch form factors)

solved through the patch level: with ``B = Mavg L``, ``(I - Mavg diag(rho) W Gn) B =
Mavg (rho E)``, a small dense system factored once per albedo set, then
``L = rho * (E + W Gn B)``. Everything is linear in ``E``; albedo < 1 and form-factor rows
summing to at most 1 make it energy conserving.

Interaction series for a target set A of samples (``rho = rho_out + rho_A``), with
``S = (I - rho_out G Mavg)^-1``::

    L_0 = S(rho_out E)
    L_1 = S(rho_A (E + G Mavg L_0))
    L_n = S(rho_A G Mavg L_{n-1}),  n >= 2

``L_n`` is the radiance of all paths that reflected exactly n times on A, so
``sum_n kappa^n L_n`` is the solution with ``rho_A`` scaled by ``kappa``.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from devices.virtual.setup import Setup


class Resolvent:
    """``x -> (I - rho G Mavg)^-1 x`` for one albedo set, factored once.

    Parameters
    ----------
    setup : Setup
    rho : (Ns, 3) float64
        Per-sample albedo.

    Notes
    -----
    ``y = x + rho G Mavg y``; with ``b = Mavg y``: ``(I - Mavg diag(rho) W Gn) b = Mavg x``
    and ``y = x + rho (W Gn b)``. One LU factorisation of the ``P x P`` matrix per channel.
    """

    def __init__(self, setup: Setup, rho: np.ndarray):
        self.setup = setup
        self.rho = np.asarray(rho, np.float64)
        n_p = setup.mavg.shape[0]
        eye = np.eye(n_p)
        self._lu = []
        for c in range(self.rho.shape[1]):
            a = (setup.mavg @ sp.diags(self.rho[:, c]) @ setup.interp).toarray()
            self._lu.append(sla.lu_factor(eye - a @ setup.gn, check_finite=False))
        self._rho32 = self.rho.astype(np.float32)
        self._interp32 = setup.interp.astype(np.float32)
        self._mavg32 = setup.mavg.astype(np.float32)

    def patch_radiance(self, x: np.ndarray) -> np.ndarray:
        """Patch radiance ``b = Mavg y`` of the solution ``y`` for source ``x`` (Ns, C)."""
        mavg = self._mavg32 if x.dtype == np.float32 else self.setup.mavg
        rhs = np.asarray(mavg @ x, np.float64)
        return np.stack([sla.lu_solve(self._lu[c], rhs[:, c], check_finite=False)
                         for c in range(rhs.shape[1])], axis=1)

    def apply(self, x: np.ndarray) -> np.ndarray:
        """Solve ``y = x + rho G Mavg y``.

        Parameters
        ----------
        x : (Ns, 3) float32 or float64

        Returns
        -------
        (Ns, 3), dtype of ``x``
        """
        b = self.setup.gn @ self.patch_radiance(x)
        out: np.ndarray
        rho: np.ndarray
        if x.dtype == np.float32:
            out, rho = self._interp32 @ b.astype(np.float32), self._rho32
        else:
            out, rho = self.setup.interp @ b, self.rho
        out *= rho
        out += x
        return out

    def solve(self, e: np.ndarray) -> np.ndarray:
        """Reflected radiance ``L = rho (E + G Mavg L)`` for direct light ``E`` (Ns, 3)."""
        rho = self._rho32 if e.dtype == np.float32 else self.rho
        return self.apply(rho * e)


def gather(setup: Setup, x: np.ndarray) -> np.ndarray:
    """Indirect irradiance ``G Mavg x`` (divided by pi) at every sample from radiance ``x``."""
    b = np.asarray(setup.mavg @ x, np.float64)
    return setup.interp @ (setup.gn @ b)


def interactions(setup: Setup, rho: np.ndarray, target: np.ndarray, e: np.ndarray, n_terms: int) -> np.ndarray:
    """Radiance split by the number of reflections on a target set of samples.

    Parameters
    ----------
    setup : Setup
    rho : (Ns, 3) float64
        Albedo.
    target : (Ns,) bool
        Samples of the target set A.
    e : (Ns, 3) float64
        Direct light (irradiance / pi).
    n_terms : int
        Highest number of interactions returned.

    Returns
    -------
    (n_terms + 1, Ns, 3) float64
        ``L_0 .. L_n_terms`` (see the module docstring).
    """
    rho_a = rho * target[:, None]
    rho_out = rho - rho_a
    s = Resolvent(setup, rho_out)
    out = np.empty((n_terms + 1,) + e.shape)
    out[0] = s.apply(rho_out * e)
    if n_terms >= 1:
        out[1] = s.apply(rho_a * (e + gather(setup, out[0])))
    for n in range(2, n_terms + 1):
        out[n] = s.apply(rho_a * gather(setup, out[n - 1]))
    return out
