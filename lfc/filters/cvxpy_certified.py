"""The certified filter written in cvxpy from its definition: the readable reference.

Independent of :class:`lfc.filters.certified.CertifiedSet`'s precomputed rows:
the model's free and unit-command responses are simulated sample by sample,
and the certified command is the one closest to ``u_ref`` under the
definition's constraints (solved by Clarabel).
"""

from __future__ import annotations

import math

import cvxpy as cp
import numpy as np

from lfc.filters.certified import CertifiedSet
from lfc.model import output_matrix


def cvxpy_certified(cert: CertifiedSet, x: np.ndarray, u_ref: float,
                    p_load: float = 0.0) -> float | None:
    """The certified command as a cvxpy problem (Clarabel): the readable reference.

    Written from the definition, independently of :class:`CertifiedSet`'s
    precomputed rows: simulate the model's free and unit-command responses
    sample by sample, then ``min (u − u_ref)²`` subject to both outputs within
    the limits at every sample, the held command's equilibrium within its
    room, the terminal deviation in the ellipsoid and the actuator limits.
    Returns None when no command is certified.  Slow (a problem per call).
    """
    C, Bd = output_matrix(), cert._Bd
    free, unit = np.empty((cert.n_steps, 5)), np.empty((cert.n_steps, 5))
    xf, xu = np.asarray(x, float), np.zeros(5)
    for k in range(cert.n_steps):
        xf = cert._Ad @ xf + Bd[:, 1] * p_load
        xu = cert._Ad @ xu + Bd[:, 0]
        free[k], unit[k] = xf, xu
    u = cp.Variable()
    y = free @ C.T + cp.reshape(u * (unit @ C.T).ravel(), (cert.n_steps, 2), order="C")
    e = xf + u * xu - (cert._q[:, 0] * u + cert._q[:, 1] * p_load)
    g_u, g_p = cert._dw_eq
    cons = [cp.abs(y) <= np.tile(cert.limits, (cert.n_steps, 1)),
            cp.abs(g_u * u + g_p * p_load) <= cert._eq_room,
            cp.quad_form(e, cert._P) <= cert.rho ** 2]
    cons += [u >= cert.u_min] if math.isfinite(cert.u_min) else []
    cons += [u <= cert.u_max] if math.isfinite(cert.u_max) else []
    prob = cp.Problem(cp.Minimize(cp.square(u - u_ref)), cons)
    prob.solve(solver=cp.CLARABEL, tol_gap_abs=1e-10, tol_gap_rel=1e-12, tol_feas=1e-10)
    return float(u.value) if prob.status == cp.OPTIMAL else None
