"""What a load step can do to the relays, and what a governor could do about it (E12).

Right after a load step ΔP_L the *true* ROCOF is ΔP_L / M (the governor acts
through its own lags).  The relay, however, reads the *measured* ROCOF, lagged by τ_ν, whose
peak is lower (≈ 0.9 ΔP_L / M on the defaults), and a governor that acts
within that lag can keep it lower still.  Two numbers make that precise:

* :func:`no_scc_threshold`: the smallest load step that trips a relay in the
  closed loop without SCC (local integral control only);
* :func:`governor_ride_through`: for a given step, the smallest peak of the
  measured outputs (relative to the relay settings) that *any* governor command
  sequence within ``±u_bound`` can achieve — a linear program over one command
  per control period, reacting one period after the step (severity ≤ 1: the
  step can be ridden through).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.optimize import linprog

from lfc._validate import (ParameterTypeError, check_finite, check_integer, check_multiple,
                           check_nonnegative, check_positive, check_range)
from lfc.model import LFCParams, discretize
from lfc.relays import RelaySettings, relays_or_default
from lfc.signals import Step
from lfc.run import simulate


def no_scc_threshold(params: LFCParams, relays: RelaySettings, *, tol: float = 1e-4,
                     duration: float = 5.0) -> float:
    """Smallest load step (pu, within ``tol``) that trips a relay without SCC.

    Bisection on :func:`lfc.simulate` (a step at 1 s, ``duration`` > 1 s), between
    0 and ``2 M × rocof_limit`` (a step that large always trips); ``tol`` in
    [1e-9, 1] pu.
    """
    if not isinstance(params, LFCParams):
        raise ParameterTypeError(f"params must be an LFCParams, got {params!r:.80}")
    relays = relays_or_default(relays)
    check_range("tol", tol, 1e-9, 1.0, closed=True)
    check_positive("duration", duration)
    if duration <= 1.0:
        raise ValueError(f"duration must be > 1 s (the step lands at 1 s), got {duration!r}")
    lo, hi = 0.0, 2 * params.M * relays.rocof_limit
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        run = simulate(params, duration=duration, load=Step(mid, 1.0), relays=relays,
                       stop_on_trip=True)
        lo, hi = (lo, mid) if run.metrics()["tripped"] else (mid, hi)
    return hi


@dataclass(frozen=True)
class RideThrough:
    """Result of :func:`governor_ride_through`.

    Attributes
    ----------
    step : float
        Load step (pu).
    u_bound : float
        Bound on the command (pu).
    severity : float
        Smallest achievable ``max(|Δω̂| / F, |ROCOF| / rocof_limit)`` over the
        horizon; ≤ 1 means the step can be ridden through.
    t : ndarray
        Command times (s after the step).
    commands : ndarray
        The command sequence that achieves it (pu), one per control period.
    """

    step: float
    u_bound: float
    severity: float
    t: np.ndarray
    commands: np.ndarray

    @property
    def rides_through(self) -> bool:
        """True if some bounded command keeps both outputs inside the settings."""
        return self.severity <= 1.0


def governor_ride_through(params: LFCParams, relays: RelaySettings, step: float, *,
                          u_bound: float, horizon: float = 3.0, settle: float = 0.5,
                          delay_periods: int = 1, dt: float = 1e-3,
                          control_period: float = 0.01) -> RideThrough:
    """The best any governor command within ``±u_bound`` can do against a load step.

    From equilibrium a step ``step`` (pu) arrives at t = 0; the command is 0 for
    the first ``delay_periods`` control periods (the governor has not seen the
    step yet), then free within ``±u_bound``, held over each period, and equal to
    ``step`` (its steady state) for the last ``settle`` s of ``horizon``.  A
    linear program (HiGHS) over the commands and the plant states at every
    ``dt`` minimizes the peak of both measured outputs relative to the relay
    settings.

    Returns
    -------
    RideThrough
    """
    if not isinstance(params, LFCParams):
        raise ParameterTypeError(f"params must be an LFCParams, got {params!r:.80}")
    relays = relays_or_default(relays)
    check_finite("step", step)
    check_positive("u_bound", u_bound)
    ratio = check_multiple("control_period", control_period, "dt", dt)
    periods = check_multiple("horizon", horizon, "control_period", control_period)
    check_nonnegative("settle", settle)
    check_integer("delay_periods", delay_periods)
    if settle >= horizon or delay_periods >= periods:
        raise ValueError(f"settle ({settle} s) and delay_periods ({delay_periods}) must leave "
                         f"free commands within horizon ({horizon} s, {periods} periods)")
    Ad, Bd = discretize(params, dt)
    n = Ad.shape[0]
    steps = periods * ratio
    nu, nx = periods, steps * n
    # equalities x[k+1] - Ad x[k] - Bd_u u[k // ratio] = Bd_L step, x[0] = 0
    eye = sparse.identity(steps * n, format="csr")
    shift = sparse.kron(sparse.eye(steps, k=-1), sparse.csr_matrix(Ad), format="csr")
    hold = sparse.kron(sparse.kron(sparse.identity(periods), np.ones((ratio, 1))),
                       sparse.csr_matrix(Bd[:, :1]), format="csr")
    a_eq = sparse.hstack([-hold, eye - shift, sparse.csr_matrix((nx, 1))], format="csr")
    b_eq = np.tile(Bd[:, 1] * step, steps)
    # |dw_meas[k]| <= rho F and |rocof_meas[k]| <= rho rocof_limit, k = 1..steps
    pick = sparse.kron(sparse.identity(steps), sparse.csr_matrix(
        np.eye(n)[[3, 4]]), format="csr")
    limits = np.tile([relays.F, relays.rocof_limit], steps)[:, None]
    outputs = sparse.hstack([sparse.csr_matrix((2 * steps, nu)), pick,
                             sparse.csr_matrix(-limits)], format="csr")
    flipped = sparse.hstack([sparse.csr_matrix((2 * steps, nu)), -pick,
                             sparse.csr_matrix(-limits)], format="csr")
    a_ub = sparse.vstack([outputs, flipped], format="csr")
    bounds = [(-u_bound, u_bound)] * periods + [(None, None)] * nx + [(0, None)]
    for j in range(min(delay_periods, periods)):
        bounds[j] = (0.0, 0.0)
    for j in range(max(periods - int(round(settle / control_period)), 0), periods):
        bounds[j] = (step, step) if abs(step) <= u_bound else bounds[j]
    cost = np.zeros(nu + nx + 1)
    cost[-1] = 1.0
    res = linprog(cost, A_ub=a_ub, b_ub=np.zeros(4 * steps), A_eq=a_eq, b_eq=b_eq,
                  bounds=bounds, method="highs")
    if res.status != 0:
        raise RuntimeError(f"the ride-through LP did not solve: {res.message}")
    return RideThrough(step=float(step), u_bound=float(u_bound), severity=float(res.x[-1]),
                       t=np.arange(periods) * control_period, commands=res.x[:periods])
