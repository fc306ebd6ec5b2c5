"""A safety filter with a guarantee: no command on P_c or ω_ref trips the relays.

``SafetyFilter(params, relays, method="certified")`` uses this module
(:class:`CertifiedFilter`, options as there).  The
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

``details`` of a :class:`~lfc.filters.base.FilterInfo`: the certified interval
``(lo, hi)`` (pu; ``lo > hi`` where none is certified).

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
ride through larger ones: :mod:`lfc.experiments.load_limits`.)  ``margin`` tightens both limits further, by a
fraction, for estimation error and plant–model mismatch (no guarantee then).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import solve_discrete_lyapunov

from lfc._jit import inline
from lfc._validate import check_multiple, check_nonnegative, check_positive
from lfc.filters.base import (ACTIVE, BIND_CERT, BIND_UMAX, BIND_UMIN, INVALID, OUTSIDE,
                              Backend, check_limits)
from lfc.model import LFCParams, discretize, lfc_matrices, output_matrix
from lfc.relays import RelaySettings

L1_HORIZON = 60.0  # s over which the load-to-output impulse response is summed
NUMERIC_MARGIN = 1e-6  # relative tightening that absorbs floating-point differences
# layout of the data array read by decide(): a header, then the rows and the terminal set
U_MIN, U_MAX, EQ_PER_P, EQ_HALF, RHO, A_QUAD, N_ROWS, F_LIM, R_LIM, HEAD = range(10)


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
        self.margin = float(margin)
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

    def pack(self) -> np.ndarray:
        """The data array :func:`decide` reads (layout in the module's constants)."""
        head = np.zeros(HEAD)
        head[:HEAD] = (self.u_min, self.u_max, self._eq_per_p, self._eq_half, self.rho,
                       self._a_quad, self.n_rows, self.relays.F, self.relays.rocof_limit)
        return np.concatenate([head, self._row_a, self._row_b, self._row_GT.T.ravel(),
                               self._row_l, self._E.ravel(), self._el, self._eu,
                               self._P.ravel()])


def _l1_norms(Ad: np.ndarray, bl: np.ndarray, C: np.ndarray, n: int) -> np.ndarray:
    """Sum over k of |C Ad^k bl|: the worst output deviation per pu of load deviation."""
    total, v = np.zeros(2), bl.copy()
    for _ in range(n):
        total += np.abs(C @ v)
        v = Ad @ v
    return total



class CertifiedFilter(Backend):
    """The certified filter (method ``"certified"``): clip to the certified
    interval of :class:`CertifiedSet`, or hold the last certified command.

    Parameters
    ----------
    params : LFCParams
        Design model.
    relays : RelaySettings
    period : float
        Time between calls (s); the command is held in between. Default 0.01.
    horizon : float
        Look-ahead before the terminal set (s). Default 4.
    load_bound : float
        Load deviation covered (pu), >= 0. Default 0.
    margin : float
        Extra fractional tightening of the limits, in [0, 1). Default 0.
    u_min, u_max : float
        Actuator limits (pu).
    """

    name, method_id = "certified", 1

    def __init__(self, params: LFCParams, relays: RelaySettings, *, period: float = 0.01,
                 horizon: float = 4.0, load_bound: float = 0.0, margin: float = 0.0,
                 u_min: float = -math.inf, u_max: float = math.inf) -> None:
        super().__init__(params, relays)
        check_limits(u_min, u_max)
        self.cert = CertifiedSet(params, relays, period=period, horizon=horizon,
                                 load_bound=load_bound, margin=margin, u_min=u_min,
                                 u_max=u_max)
        self.data, self.jit = self.cert.pack(), True

    def describe(self) -> str:
        c = self.cert
        return (f"SafetyFilter(method='certified', load_bound={c.load_bound}, "
                f"margin={c.margin}, u_min={c.u_min}, u_max={c.u_max})")

    def reason(self, flags: int) -> str:
        if flags & INVALID:
            return ("invalid input (non-finite state, command or load); last certified "
                    "command held")
        if flags & OUTSIDE:
            return ("no command is certified from this state (load beyond load_bound, model "
                    "or estimation error); last certified command held")
        return "command clipped to the certified interval" if flags & ACTIVE else ""

    def details(self, d0: float, d1: float, flags: int) -> dict:
        return {"interval": (d0, d1)}


@inline
def _terminal_deviation(fd: np.ndarray, t0: int, x: np.ndarray, p: float) -> tuple:
    """``e = E x + el p``: the deviation from the held command's equilibrium at the
    horizon's end, less its command part (5 values)."""
    e0, e1, e2, e3, e4 = (p * fd[t0 + 25], p * fd[t0 + 26], p * fd[t0 + 27], p * fd[t0 + 28],
                          p * fd[t0 + 29])
    for k in range(5):
        e0 += fd[t0 + k] * x[k]
        e1 += fd[t0 + 5 + k] * x[k]
        e2 += fd[t0 + 10 + k] * x[k]
        e3 += fd[t0 + 15 + k] * x[k]
        e4 += fd[t0 + 20 + k] * x[k]
    return e0, e1, e2, e3, e4


@inline
def decide(fd: np.ndarray, x: np.ndarray, u_ref: float, p: float, mem: np.ndarray) -> tuple:
    """One call of the certified filter (module docstring).

    ``fd`` is :meth:`CertifiedSet.pack`'s data, ``mem[0]`` the last certified
    command (held when none is certified).  Returns ``(u, flags, h_freq,
    h_rocof, margin_freq, margin_rocof, y_freq, y_rocof, lo, hi)``; the margins
    are the distances from ``u`` to the ends of each relay's own interval.
    """
    nan = math.nan
    valid = math.isfinite(u_ref) and math.isfinite(p)
    for v in x:
        valid = valid and math.isfinite(v)
    if not valid:
        u = mem[0]
        return u, INVALID | (ACTIVE if u != u_ref else 0), nan, nan, nan, nan, nan, nan, \
            nan, nan
    n = int(fd[N_ROWS])
    a0, b0, g0, l0 = HEAD, HEAD + n, HEAD + 2 * n, HEAD + 7 * n
    lo_f, hi_f, lo_r, hi_r = -np.inf, np.inf, -np.inf, np.inf   # per output
    for i in range(0, n, 2):                  # rows alternate: frequency, ROCOF
        s_f, s_r = 0.0, 0.0
        for k in range(5):
            s_f += fd[g0 + 5 * i + k] * x[k]
            s_r += fd[g0 + 5 * i + 5 + k] * x[k]
        s_f, s_r = s_f + p * fd[l0 + i], s_r + p * fd[l0 + i + 1]
        lo_f, hi_f = max(lo_f, fd[a0 + i] - s_f), min(hi_f, fd[b0 + i] - s_f)
        lo_r, hi_r = max(lo_r, fd[a0 + i + 1] - s_r), min(hi_r, fd[b0 + i + 1] - s_r)
    centre = fd[EQ_PER_P] * p                                # room at the equilibrium
    lo_f, hi_f = max(lo_f, centre - fd[EQ_HALF]), min(hi_f, centre + fd[EQ_HALF])
    t0 = l0 + n                                              # terminal ellipsoid
    e = _terminal_deviation(fd, t0, x, p)
    qb, qc = 0.0, -fd[RHO] ** 2
    for r in range(5):
        pe = 0.0
        for k in range(5):
            pe += fd[t0 + 35 + 5 * r + k] * e[k]
        qb += 2.0 * pe * fd[t0 + 30 + r]
        qc += pe * e[r]
    disc = qb * qb - 4 * fd[A_QUAD] * qc
    if disc >= 0:
        root = math.sqrt(disc)
        e_lo, e_hi = (-qb - root) / (2 * fd[A_QUAD]), (-qb + root) / (2 * fd[A_QUAD])
    else:
        e_lo, e_hi = np.inf, -np.inf
    lo_f, hi_f, lo_r, hi_r = max(lo_f, e_lo), min(hi_f, e_hi), max(lo_r, e_lo), min(hi_r, e_hi)
    lo = max(lo_f, lo_r, fd[U_MIN])
    hi = min(hi_f, hi_r, fd[U_MAX])
    certified = lo <= hi
    u = min(max(u_ref, lo), hi) if certified else mem[0]
    mem[0] = u
    flags = 0
    if u != u_ref:
        flags |= ACTIVE
        if certified:
            flags |= BIND_CERT
            for lim, bit in ((fd[U_MIN], BIND_UMIN), (fd[U_MAX], BIND_UMAX)):
                if math.isfinite(lim) and abs(u - lim) <= 1e-9 * (1 + abs(lim)):
                    flags |= bit
    if not certified:
        flags |= OUTSIDE
    m_f = min(u - lo_f, hi_f - u) if certified else nan
    m_r = min(u - lo_r, hi_r - u) if certified else nan
    return (u, flags, fd[F_LIM] ** 2 - x[3] ** 2, fd[R_LIM] ** 2 - x[4] ** 2, m_f, m_r, x[3],
            x[4], lo, hi)
