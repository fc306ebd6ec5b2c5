"""The certified filter written in cvxpy from its definition: the readable reference.

Independent of :class:`lfc.filters.certified.CertifiedSet`'s packed rows and
compiled code: for each certified plant, the held trajectory's outputs are
computed at the certificate's sample times from ``scipy.linalg.expm``, and the
certified command is the one closest to ``u_ref`` under the definition's
constraints (solved by Clarabel).  The bounds themselves (the tightened limits,
the terminal ellipsoid) are :class:`CertifiedSet`'s.
"""

from __future__ import annotations

import math

import cvxpy as cp
import numpy as np
from scipy.linalg import expm

from lfc.filters.certified import CertifiedSet
from lfc.model import lfc_matrices, output_matrix


def cvxpy_certified(cert: CertifiedSet, x: np.ndarray, u_ref: float, p_load: float = 0.0,
                    level: str = "new") -> float | None:
    """The certified command as a cvxpy problem (Clarabel): the readable reference.

    ``min (u − u_ref)²`` subject to, for every plant of ``cert``: both held
    outputs ``C e^{At}(x − x_eq) + C x_eq`` (``x_eq = −A⁻¹B [u; p]``) within the
    level's bound at every sample time, the equilibrium's frequency within its
    room, the deviation at the horizon in the terminal ellipsoid; and the
    actuator limits.  Returns None when no command is certified (including when
    the current outputs are already too close to the limits).  Slow (a problem
    per call).
    """
    x = np.asarray(x, float)
    C = output_matrix()
    u = cp.Variable()
    cons = [u >= cert.u_min] if math.isfinite(cert.u_min) else []
    cons += [u <= cert.u_max] if math.isfinite(cert.u_max) else []
    for block in cert.blocks:
        if np.any(np.abs(C @ x) > block.y0[level]):
            return None
        A, B = lfc_matrices(block.plant)
        q = -np.linalg.solve(A, B)
        x_eq = q[:, 0] * u + q[:, 1] * p_load
        # the held outputs y(t) = C e^{At} x + C (I − e^{At}) x_eq at every sample time,
        # affine in u: y(t) = free(t) + per_u(t) u, one row per time, scaled by the bound
        E = np.array([expm(A * t) for t in block.times])
        gain = np.einsum("ij,tjk->tik", C, np.eye(5) - E)
        free = np.einsum("ij,tjk,k->ti", C, E, x) + gain @ q[:, 1] * p_load
        bound = np.asarray(block.bounds[level])
        cons.append(cp.abs(free / bound + (gain @ q[:, 0] / bound) * u) <= 1)
        dw_u, dw_p = (C @ q)[0]
        cons.append(cp.abs(dw_u * u + dw_p * p_load) <= block.eq_half[level] * abs(dw_u))
        e = expm(A * block.times[-1]) @ (x - x_eq)          # e'Pe <= rho^2 as a second-order cone
        cons.append(cp.norm(np.linalg.cholesky(block.P).T @ e) <= block.rho[level])
    prob = cp.Problem(cp.Minimize(cp.square(u - u_ref)), cons)
    prob.solve(solver=cp.CLARABEL, tol_gap_abs=1e-10, tol_gap_rel=1e-12, tol_feas=1e-10)
    return float(u.value) if prob.status == cp.OPTIMAL else None
