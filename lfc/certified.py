"""A safety filter with a guarantee: no command on P_c or ω_ref trips the relays.

``SafetyFilter(params, relays, method="certified")`` uses this module.  The
idea is an implicit control-invariant set with a *hold* backup law:

* A command ``u`` is **certified** at state ``x`` if applying it and holding it
  for ever keeps both measured outputs (``dw_meas``, ``rocof_meas``) inside the
  relay limits at every relay sample (``resolution``, the plant step) for all
  future time.  On the design model that is checkable exactly: the trajectory
  is affine in ``u``; over a finite ``horizon`` every sample is a pair of
  affine constraints, and at the end the deviation from the held command's
  equilibrium ``e = x_N − x_eq(u)`` must lie in an ellipsoid
  ``eᵀ P e ≤ ρ²`` that the dynamics never leave (``P`` a discrete Lyapunov
  matrix of the model) and on which the outputs stay inside the limits.  The
  equilibrium itself must sit inside the frequency limit.  Each condition is an
  interval in ``u`` (the ellipsoid a convex quadratic), so the admissible set
  is one interval and the filter is ``u_ref`` clipped to it — exact, no QP
  solver, microseconds.
* If no command is certified from the current state (only possible when an
  assumption below is broken), the filter keeps the last certified command: its
  certificate, issued when it was applied, still covers holding it.  Flagged
  ``outside`` with the reason.

**Guarantee.**  On the design model (plant = ``params``), with the exact state,
a command held between calls spaced ``period`` apart, a load deviation
``|ΔP_L(t) − p_load| ≤ load_bound`` (``p_load`` as given to the filter when
the active command was certified) and a start from a state where some command
is certified (e.g. equilibrium): the measured frequency and ROCOF never leave
``|Δω̂| ≤ F`` and ``|ROCOF| ≤ rocof_limit`` at any plant sample, whatever the
incoming commands are (OF2, UF2 and ROCOF never trip).  The load bound is
covered by tightening every limit by ``load_bound`` times the ℓ1 norm of the
load-to-output impulse response (a conservative bound: it assumes the worst
load signal for every sample at once); a ``load_bound`` for which nothing is
left is rejected at construction.  (For comparison, E12: without SCC a load
step trips a relay from 0.2229 pu on the defaults, and some governor commands
ride through larger ones: :mod:`lfc.load_limits`.)  ``margin`` tightens both limits further, by a
fraction, for estimation error and plant–model mismatch (no guarantee then).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import solve_discrete_lyapunov

from lfc._validate import check_multiple, check_nonnegative, check_positive
from lfc.model import LFCParams, discretize, lfc_matrices, output_matrix
from lfc.relays import RelaySettings

L1_HORIZON = 60.0  # s over which the load-to-output impulse response is summed
NUMERIC_MARGIN = 1e-6  # relative tightening that absorbs floating-point differences


class CertifiedSet:
    """The certified-command interval for a design model (see module docstring).

    Parameters
    ----------
    params : LFCParams
    relays : RelaySettings
    period : float
        Time between filter calls (s); the command is held in between.
    resolution : float
        Relay sampling step the limits are checked at (s); ``period`` must be a
        multiple of it.  Default 1 ms (the plant step of ``lfc.simulate``).
    horizon : float
        Look-ahead before the terminal ellipsoid (s), > 0. Default 4 s: on the
        defaults a longer one certifies no more commands (measured on states of
        attacked runs; the slowest mode decays as exp(−0.93 t)).
    load_bound : float
        Bound on the load deviation from ``p_load`` (pu), >= 0.
    margin : float
        Extra fractional tightening of both limits, in [0, 1).
    u_min, u_max : float
        Actuator limits (pu).
    """

    def __init__(self, params: LFCParams, relays: RelaySettings, *, period: float = 0.01,
                 resolution: float = 1e-3, horizon: float = 4.0, load_bound: float = 0.0,
                 margin: float = 0.0, u_min: float = -math.inf, u_max: float = math.inf) -> None:
        check_multiple("period", period, "resolution", resolution)
        check_positive("horizon", horizon)
        check_nonnegative("load_bound", load_bound)
        if not 0.0 <= margin < 1.0:
            raise ValueError(f"margin must be in [0, 1), got {margin!r}")
        self.params, self.relays, self.load_bound = params, relays, float(load_bound)
        self.u_min, self.u_max = float(u_min), float(u_max)
        Ad, Bd = discretize(params, resolution)
        C = output_matrix()
        l1 = _l1_norms(Ad, Bd[:, 1], C, int(round(L1_HORIZON / resolution)))
        base = np.array([relays.F, relays.rocof_limit]) * (1 - margin) * (1 - NUMERIC_MARGIN)
        self.limits = base - self.load_bound * l1
        if np.any(self.limits <= 0):
            most = float(np.min(base / l1))
            raise ValueError(f"load_bound must be < {most:.4g} pu for these relays: the "
                             "certificate tightens each limit by load_bound times the l1 norm "
                             "of the load-to-output response (a conservative bound), which "
                             f"leaves nothing above that; got {load_bound}")
        self._Ad, self._Bd, self.n_steps = Ad, Bd, int(math.ceil(horizon / resolution))
        Phi_n, S_n = self._horizon_rows(Ad, Bd, C, self.n_steps)
        self._terminal(params, Ad, C, Phi_n, S_n)

    def _horizon_rows(self, Ad: np.ndarray, Bd: np.ndarray, C: np.ndarray, n: int
                      ) -> tuple[np.ndarray, np.ndarray]:
        """Outputs at samples 1..n under a held u: ``y = G x + hu u + hl p`` per row.
        Returns ``Ad^n`` and ``sum_{i<n} Ad^i`` for the terminal condition."""
        G, hu, hl = np.empty((n, 2, 5)), np.empty((n, 2)), np.empty((n, 2))
        Ak, S = np.eye(5), np.zeros((5, 5))  # Ad^k and sum_{i<k} Ad^i
        for k in range(n):
            S = S + Ak
            Ak = Ad @ Ak
            G[k], hu[k], hl[k] = C @ Ak, C @ S @ Bd[:, 0], C @ S @ Bd[:, 1]
        G, hu, hl = G.reshape(-1, 5), hu.ravel(), hl.ravel()
        lim = np.tile(self.limits, n)
        if np.any(np.abs(hu) < 1e-15):
            raise ValueError("horizon too short: the command has no effect on some sample")
        # -lim <= G x + hu u + hl p <= lim  <=>  u in [lo_i, hi_i] (sign of hu decides)
        inv = 1.0 / hu
        up, dn = (lim * inv), (-lim * inv)
        self._row_a = np.minimum(up, dn)  # lo_i = a_i - (G x + hl p)/hu
        self._row_b = np.maximum(up, dn)  # hi_i = b_i - (G x + hl p)/hu
        self._row_GT = np.ascontiguousarray((G * inv[:, None]).T)  # (5, rows): fast x @ GT
        self._row_l = hl * inv
        self.n_rows = len(hu)
        return Ak, S

    def _terminal(self, params: LFCParams, Ad: np.ndarray, C: np.ndarray, Phi_n: np.ndarray,
                  S_n: np.ndarray) -> None:
        """Terminal ellipsoid around the held command's equilibrium, and the room
        that leaves the equilibrium: ``|u - eq_per_p * p| <= eq_half``."""
        A, B = lfc_matrices(params)
        self._q = -np.linalg.solve(A, B)            # x_eq = q[:, 0] u + q[:, 1] p
        # Lyapunov weight: each state scaled by its size at the limits (1 pu of power,
        # F for the frequencies, the ROCOF limit) so the ellipsoid fits the outputs' box
        scale = np.array([1.0, 1.0, self.limits[0], self.limits[0], self.limits[1]])
        self._P = solve_discrete_lyapunov(Ad.T, np.diag(scale ** -2.0))
        sigma = np.sqrt(np.einsum("ij,jk,ik->i", C, np.linalg.inv(self._P), C))
        self.rho = float(min(0.5 * self.limits[0] / sigma[0], self.limits[1] / sigma[1]))
        self._eq_room = float(self.limits[0] - self.rho * sigma[0])  # |dw_eq| allowed
        self._dw_eq = tuple(map(float, (C @ self._q)[0]))            # dw_eq per (u, p)
        g_u, g_p = self._dw_eq
        self._eq_half, self._eq_per_p = self._eq_room / abs(g_u), -g_p / g_u
        # e = x_N - x_eq = E x + eu u + el p
        self._E = Phi_n
        self._eu = S_n @ self._Bd[:, 0] - self._q[:, 0]
        self._el = S_n @ self._Bd[:, 1] - self._q[:, 1]
        self._a_quad = float(self._eu @ self._P @ self._eu)

    def interval(self, x: np.ndarray, p_load: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Certified interval [lo, hi] of commands for states ``x`` (N, 5) and
        assumed loads (N,); ``lo > hi`` where none is certified."""
        s = x @ self._row_GT + p_load[:, None] * self._row_l       # (N, rows)
        lo = np.max(self._row_a - s, axis=1)
        hi = np.min(self._row_b - s, axis=1)
        lo, hi = self._equilibrium(lo, hi, p_load)
        lo, hi = self._ellipsoid(lo, hi, x, p_load)
        return np.maximum(lo, self.u_min), np.minimum(hi, self.u_max)

    def interval_one(self, x: np.ndarray, p_load: float) -> tuple[float, float]:
        """:meth:`interval` for one state ``x`` (5,), with less numpy overhead."""
        s = x @ self._row_GT
        if p_load:
            s = s + p_load * self._row_l
        lo, hi = float(np.max(self._row_a - s)), float(np.min(self._row_b - s))
        centre = self._eq_per_p * p_load
        lo = max(lo, centre - self._eq_half, self.u_min)
        hi = min(hi, centre + self._eq_half, self.u_max)
        e0 = self._E @ x + p_load * self._el
        Pe0 = self._P @ e0
        a = self._a_quad
        b = 2.0 * float(Pe0 @ self._eu)
        c = float(Pe0 @ e0) - self.rho ** 2
        disc = b * b - 4 * a * c
        if disc < 0:
            return math.inf, -math.inf
        root = math.sqrt(disc)
        return max(lo, (-b - root) / (2 * a)), min(hi, (-b + root) / (2 * a))

    def _equilibrium(self, lo, hi, p_load):
        centre = self._eq_per_p * p_load
        return np.maximum(lo, centre - self._eq_half), np.minimum(hi, centre + self._eq_half)

    def _ellipsoid(self, lo, hi, x, p_load):
        """(e0 + eu u)ᵀ P (e0 + eu u) <= rho²: a u² + b u + c <= 0."""
        e0 = x @ self._E.T + p_load[:, None] * self._el
        Pe0 = e0 @ self._P
        a = self._a_quad
        b = 2 * Pe0 @ self._eu
        c = np.einsum("ij,ij->i", Pe0, e0) - self.rho ** 2
        disc = b * b - 4 * a * c
        root = np.sqrt(np.maximum(disc, 0.0))
        ok = disc >= 0
        return (np.where(ok, np.maximum(lo, (-b - root) / (2 * a)), np.inf),
                np.where(ok, np.minimum(hi, (-b + root) / (2 * a)), -np.inf))


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
    import cvxpy as cp

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


def _l1_norms(Ad: np.ndarray, bl: np.ndarray, C: np.ndarray, n: int) -> np.ndarray:
    """Sum over k of |C Ad^k bl|: the worst output deviation per pu of load deviation."""
    total, v = np.zeros(2), bl.copy()
    for _ in range(n):
        total += np.abs(C @ v)
        v = Ad @ v
    return total


class CertifiedFilter:
    """The filter around :class:`CertifiedSet`: clip to the certified interval,
    or hold the last certified command.  Used through
    ``SafetyFilter(..., method="certified")``; stateful (the held command),
    :meth:`reset` before a new run.

    ``FilterInfo`` fields: ``y_*`` and ``h_*`` describe the current measured
    outputs; ``margin_freq``/``margin_rocof`` are ``u − lo`` and ``hi − u``, the
    distances (pu) from the applied command to the certified interval's ends;
    ``binding`` is ``("certified",)`` (plus ``u_min``/``u_max``) when clipped;
    ``outside`` means no command was certified and the last one is held.
    """

    def __init__(self, cert: CertifiedSet) -> None:
        self.cert = cert
        self.reset()

    def reset(self) -> None:
        """Forget the held command (a run starts at equilibrium with u = 0)."""
        self._u_prev = 0.0
        self._u_prev_batch = None

    def filter(self, x: list[float], u_ref: float, p_load: float = 0.0):
        """One command (see ``SafetyFilter.filter``); ``x`` has 5 entries."""
        from lfc.cbf import FilterInfo
        u_ref, p_load = float(u_ref), float(p_load)
        valid = all(map(math.isfinite, x)) and math.isfinite(u_ref) and math.isfinite(p_load)
        lo, hi = self.cert.interval_one(np.asarray(x, float), p_load) if valid \
            else (math.inf, -math.inf)
        certified = lo <= hi
        u = min(max(u_ref, lo), hi) if certified else self._u_prev
        self._u_prev = u
        active = u != u_ref
        lims = (self.cert.relays.F, self.cert.relays.rocof_limit)
        nan = math.nan
        h = (lims[0] ** 2 - x[3] ** 2, lims[1] ** 2 - x[4] ** 2) if valid else (nan, nan)
        return u, FilterInfo(
            u_ref=u_ref, u=u, active=active, infeasible=False,
            outside=valid and not certified, invalid_input=not valid, solver_error=False,
            h_freq=h[0], h_rocof=h[1], margin_freq=u - lo if certified else nan,
            margin_rocof=hi - u if certified else nan,
            y_freq=x[3] if valid else nan, y_rocof=x[4] if valid else nan,
            binding=self._binding(u, active, certified),
            reason=self._reason(active, certified, valid))

    def filter_batch(self, x: np.ndarray, u_ref: np.ndarray, p_load: np.ndarray | None = None
                     ) -> tuple[np.ndarray, dict]:
        x = np.asarray(x, float).reshape(-1, 5)
        u_ref = np.asarray(u_ref, float).reshape(-1)
        p_load = np.zeros_like(u_ref) if p_load is None else np.asarray(p_load, float)
        if self._u_prev_batch is None or len(self._u_prev_batch) != len(u_ref):
            self._u_prev_batch = np.zeros(len(u_ref))
        u_prev, cert = self._u_prev_batch, self.cert
        valid = np.isfinite(x).all(axis=1) & np.isfinite(u_ref) & np.isfinite(p_load)
        xs, ps = np.where(valid[:, None], x, 0.0), np.where(valid, p_load, 0.0)
        lo, hi = cert.interval(xs, ps)
        certified = valid & (lo <= hi)
        ref = np.where(np.isfinite(u_ref), u_ref, u_prev)
        u = np.where(certified, np.clip(ref, lo, np.maximum(lo, hi)), u_prev)
        self._u_prev_batch = u.copy()
        lims = np.array([cert.relays.F, cert.relays.rocof_limit])
        return u, {"active": u != u_ref, "infeasible": np.zeros(len(u), bool),
                   "outside": valid & ~certified, "invalid_input": ~valid,
                   "h": np.where(valid[:, None], lims ** 2 - xs[:, 3:5] ** 2, np.nan),
                   "margin": np.where(certified[:, None], np.column_stack([u - lo, hi - u]),
                                      np.nan)}

    def _binding(self, u: float, active: bool, certified: bool) -> tuple[str, ...]:
        if not (active and certified):
            return ()
        names = ["certified"]
        names += [n for n, lim in (("u_min", self.cert.u_min), ("u_max", self.cert.u_max))
                  if math.isfinite(lim) and abs(u - lim) <= 1e-9 * (1 + abs(lim))]
        return tuple(names)

    @staticmethod
    def _reason(active: bool, certified: bool, valid: bool) -> str:
        if not valid:
            return "invalid input (non-finite state, command or load); last certified command held"
        if not certified:
            return ("no command is certified from this state (load beyond load_bound, model "
                    "or estimation error); last certified command held")
        return "command clipped to the certified interval" if active else ""
