"""The paper's SCC written in cvxpy from its definitions: the readable reference.

Independent of :mod:`lfc.filters.paper`'s closed form: the look-ahead
matrices come from ``scipy.linalg.expm`` (not python-control), and each
constraint is the paper's own expression evaluated at the state:

* ``y = C (A_d x + B_d [u_pred; p_load])``, ``h = limit^2 - y^2``,
  ``dh/dx = -2 y C A_d``, ``B = -log(h / (1 + h))``;
* ``h > 0``: ``dB/dt - alpha / B <= 0`` with
  ``dB/dt = -(dh/dx)(A x + B [u; p_load]) / (h + h^2)`` (affine in ``u``);
* ``h <= 0`` (E9): ``dh/dt >= 0`` (``outside_rule="hold"``) or
  ``dh/dt >= alpha |h|`` (``"push"``);
* a constraint whose coefficient on ``u`` vanishes is dropped.

The QP ``min 1/2 (u - u_ref)^2`` under both constraints and the actuator limits
is solved by Clarabel, each constraint divided by its coefficient's magnitude
(a positive factor: the same constraint, well scaled, its violation in pu of
command).  If it is infeasible (E10): ``conflict="slack"`` adds slacks on those
violations with penalty ``rho/2 |s|^2``; ``"frequency"`` or
``"rocof"`` solves lexicographically: that constraint hard and the other's
violation least, then the distance to ``u_ref`` (if that constraint cannot be
met within the actuator limits, its own violation least).  The problem is DPP: built once,
its parameters set per call.
"""

from __future__ import annotations

import math

import cvxpy as cp
import numpy as np
from scipy.linalg import expm

from lfc.filters.base import CONSTRAINTS
from lfc.model import LFCParams, lfc_matrices
from lfc.relays import RelaySettings

G_EPS = 1e-12  # |d(dh/dt)/du| below which the command cannot influence a constraint
# Clarabel's default gap tolerances leave up to ~1e-4 error in u on the relaxed problems
# (a large optimal value makes a relative gap loose in u); these give <= 1e-9.
# Measured on 3,000 random states; tighter feasibility makes the relaxed problems fail.
CLARABEL_OPTS = {"tol_gap_abs": 1e-9, "tol_gap_rel": 1e-12, "tol_feas": 1e-9}


class PaperQP:
    """The SCC's QP for one design model and reading (see module docstring).

    Parameters
    ----------
    params : LFCParams
    relays : RelaySettings
    alpha, Ts : float
        Barrier gain (1/s) and look-ahead (s).
    outside_rule, conflict : str
        The readings of E9 and E10 (as in :class:`lfc.SafetyFilter`).
    slack_weight : float
        ``rho`` of ``conflict="slack"`` (pu^-2).
    u_min, u_max : float
        Actuator limits (pu).
    """

    def __init__(self, params: LFCParams, relays: RelaySettings, *, alpha: float, Ts: float,
                 outside_rule: str, conflict: str, slack_weight: float,
                 u_min: float = -math.inf, u_max: float = math.inf) -> None:
        self.alpha, self.outside_rule, self.conflict = alpha, outside_rule, conflict
        self.A, self.B = lfc_matrices(params)
        n = self.A.shape[0]
        M = expm(np.block([[self.A, self.B], [np.zeros((2, n + 2))]]) * Ts)
        self.Ad, self.Bd = M[:n, :n], M[:n, n:]
        self.C = np.zeros((2, n))
        self.C[0, 3] = self.C[1, 4] = 1.0     # dw_meas, rocof_meas
        self.limits = np.array([relays.F, relays.rocof_limit])
        self.u = cp.Variable()
        self.s = cp.Variable(2, nonneg=True)
        self.u_ref = cp.Parameter()
        self.c0, self.c1 = cp.Parameter(2), cp.Parameter(2)
        self.cap = cp.Parameter(nonneg=True)
        limits = [self.u >= u_min] if math.isfinite(u_min) else []
        limits += [self.u <= u_max] if math.isfinite(u_max) else []
        row = [self.c0[i] + self.c1[i] * self.u for i in range(2)]
        dist = 0.5 * cp.square(self.u - self.u_ref)
        self.hard = cp.Problem(cp.Minimize(dist), [r <= 0 for r in row] + limits)
        self.soft = cp.Problem(cp.Minimize(dist + 0.5 * slack_weight * cp.sum_squares(self.s)),
                               [r <= self.s[i] for i, r in enumerate(row)] + limits)
        # lexicographic stages (conflict "frequency"/"rocof"): constraint p first, then o
        p = CONSTRAINTS.index(conflict) if conflict in CONSTRAINTS else 0
        o = 1 - p
        relax_o = [row[p] <= 0, row[o] <= self.s[o]] + limits
        relax_p = [row[p] <= self.s[p]] + limits
        self.lexi = [(cp.Problem(cp.Minimize(cp.square(self.s[o])), relax_o),
                      cp.Problem(cp.Minimize(dist), relax_o + [self.s[o] <= self.cap]), o),
                     (cp.Problem(cp.Minimize(cp.square(self.s[p])), relax_p),
                      cp.Problem(cp.Minimize(dist), relax_p + [self.s[p] <= self.cap]), p)]

    def constraints(self, x: np.ndarray, u_pred: float, p_load: float
                    ) -> tuple[np.ndarray, np.ndarray]:
        """``(c0, c1)``: constraint ``i`` reads ``c0[i] + c1[i] u <= 0`` (zeros when
        the command cannot influence it)."""
        y = self.C @ (self.Ad @ x + self.Bd @ np.array([u_pred, p_load]))
        h = self.limits ** 2 - y ** 2
        dh_dx = -2 * y[:, None] * (self.C @ self.Ad)
        free = dh_dx @ (self.A @ x + self.B[:, 1] * p_load)   # dh/dt at u = 0
        per_u = dh_dx @ self.B[:, 0]                           # d(dh/dt)/du
        c0, c1 = np.zeros(2), np.zeros(2)
        for i in range(2):
            if abs(per_u[i]) <= G_EPS:
                continue
            if h[i] > 0:   # dB/dt - alpha / B <= 0
                barrier = -math.log(h[i] / (1 + h[i]))
                c0[i] = -free[i] / (h[i] + h[i] ** 2) - self.alpha / barrier
                c1[i] = -per_u[i] / (h[i] + h[i] ** 2)
            else:          # -dh/dt - gamma <= 0, gamma = 0 (hold) or alpha h (push)
                gamma = self.alpha * h[i] if self.outside_rule == "push" else 0.0
                c0[i], c1[i] = -free[i] - gamma, -per_u[i]
        return c0, c1

    def solve(self, x: np.ndarray, u_ref: float, p_load: float = 0.0,
              u_pred: float | None = None) -> float:
        """The SCC's command (pu) at state ``x``; ``u_pred`` is the command held in
        the prediction (default ``u_ref``).  Raises ``RuntimeError`` if Clarabel
        does not solve."""
        c0, c1 = self.constraints(np.asarray(x, float), u_ref if u_pred is None else u_pred,
                                  p_load)
        scale = np.where(c1 != 0, np.abs(c1), 1.0)
        self.u_ref.value, self.c0.value, self.c1.value = float(u_ref), c0 / scale, c1 / scale
        _solve(self.hard)
        if self.hard.status not in (cp.INFEASIBLE, cp.INFEASIBLE_INACCURATE):
            return _value(self.hard, self.u)
        if self.conflict == "slack":
            _solve(self.soft)
            return _value(self.soft, self.u)
        for least, closest, i in self.lexi:   # p met and o least; else p least
            _solve(least)
            if least.status in (cp.INFEASIBLE, cp.INFEASIBLE_INACCURATE):
                continue
            _value(least, self.u)
            self.cap.value = float(self.s.value[i]) * (1 + 1e-9) + 1e-12
            _solve(closest)
            return _value(closest, self.u)
        raise RuntimeError("no command meets the actuator limits")


def _solve(problem: cp.Problem) -> None:
    problem.solve(solver=cp.CLARABEL, **CLARABEL_OPTS)


def _value(problem: cp.Problem, u: cp.Variable) -> float:
    if problem.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or u.value is None:
        raise RuntimeError(f"Clarabel returned status {problem.status!r}")
    return float(u.value)
