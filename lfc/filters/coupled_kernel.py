"""The coupled certificate's compiled decision: :func:`decide` and the data it reads.

A :class:`~lfc.filters.coupled.CoupledFilter` packs its certificate
(:class:`~lfc.filters.coupled_set.CoupledSet`) into one array: a header described by
``LAYOUT`` (grid size, command range, limits, the two levels' room), then the
certificate's rows.  At each control sample :func:`decide` intersects, for the
deciding area, the interval of commands every row admits with the other areas'
commands held, and clips the incoming command to it (or holds and re-checks).
The engine calls it with the whole grid (:func:`lfc.engine.generator_period`); a
grid Kalman estimate is stepped by :func:`grid_estimate`.
"""

from __future__ import annotations

import math

import numpy as np

from lfc._jit import inline, jit, maxnum, minnum
from lfc.estimation import kf_correct, kf_predict
from lfc.filters.base import (MAX_ABS_INPUT, OUTSIDE, Layout, applied_flags, hold_invalid,
                              valid_input)
from lfc.model import STATES
from lfc.multiarea import N_AREA_STATES

DW, ROCOF = STATES.index("dw_meas"), STATES.index("rocof_meas")   # an area's measured outputs
#: header of the data array decide() reads
LAYOUT = Layout("n_s", "n_a", "n_r", "n_rows", "u_min", "u_max", "f_lim", "r_lim", "rho_new",
                "rho_held", "half_new", "half_held", "y0_f_new", "y0_r_new", "y0_f_held",
                "y0_r_held", "n_k", "lift")
(N_S, N_A, N_R, N_ROWS, U_MIN, U_MAX, F_LIM, R_LIM, RHO_NEW, RHO_HELD, HALF_NEW, HALF_HELD,
 Y0_F_NEW, Y0_R_NEW, Y0_F_HELD, Y0_R_HELD, N_K, LIFT) = LAYOUT.offsets()
HEAD = LAYOUT.size


@inline
def _valid(x: np.ndarray, u: np.ndarray, p: np.ndarray, u_ref: float) -> bool:
    """Every number of the call finite and within ``MAX_ABS_INPUT``."""
    ok = valid_input(x, u_ref, 0.0)
    for j in range(len(u)):
        ok = ok and abs(u[j]) <= MAX_ABS_INPUT and abs(p[j]) <= MAX_ABS_INPUT
    return ok


@inline
def row_intervals(fd: np.ndarray, x: np.ndarray, u: np.ndarray, p: np.ndarray, k: int,
                  sums: np.ndarray) -> tuple:
    """The rows' part of :func:`_intervals`: ``(lo_f, hi_f, lo_r, hi_r, lo_held,
    hi_held)`` over the frequency rows (even), the ROCOF rows (odd), and all rows
    at the held level.  ``sums`` (at least n_rows) is scratch: each row's output,
    summed for all rows at once one column after another (the rows are stored
    column by column), so that LLVM runs the rows in SIMD lanes; each row's sum
    takes its terms in the same order as one row at a time would (the state's,
    then each area's command and load), so the intervals are the same bit for bit
    (``tests/test_coupled.py``); ``bench/bench_coupled.py --rows`` measures it against
    one row after another."""
    inf = np.inf
    n_s, n_a, n_rows = int(fd[N_S]), int(fd[N_A]), int(fd[N_ROWS])
    col = HEAD + 2 * n_rows           # the rows' columns: bound new, bound held, then these
    for r in range(n_rows):
        sums[r] = 0.0
    for c in range(n_s):
        xc, o = x[c], col + c * n_rows
        for r in range(n_rows):
            sums[r] += fd[o + r] * xc
    for j in range(n_a):
        uj, pj = u[j], p[j]
        ou, op = col + (n_s + j) * n_rows, col + (n_s + n_a + j) * n_rows
        for r in range(n_rows):
            sums[r] += fd[ou + r] * uj + fd[op + r] * pj
    u_k, hk = u[k], col + (n_s + k) * n_rows     # area k's command, its column
    for r in range(n_rows):
        sums[r] -= fd[hk + r] * u_k   # the rest of the output, without area k's command
    lo_f, hi_f, lo_r, hi_r, lo_h, hi_h = -inf, inf, -inf, inf, -inf, inf
    for parity in range(2):           # the frequency rows (even), then ROCOF's (odd)
        lo, hi = -inf, inf
        for r in range(parity, n_rows, 2):
            s, h = sums[r], fd[hk + r]
            bn, bh = fd[HEAD + r], fd[HEAD + n_rows + r]
            if h != 0.0:
                a1, a2, c1, c2 = (-bn - s) / h, (bn - s) / h, (-bh - s) / h, (bh - s) / h
                lo_n, hi_n, lo_hh, hi_hh = min(a1, a2), max(a1, a2), min(c1, c2), max(c1, c2)
            else:
                lo_n, hi_n = (-inf, inf) if abs(s) <= bn else (inf, -inf)
                lo_hh, hi_hh = (-inf, inf) if abs(s) <= bh else (inf, -inf)
            lo, hi = maxnum(lo, lo_n), minnum(hi, hi_n)
            lo_h, hi_h = maxnum(lo_h, lo_hh), minnum(hi_h, hi_hh)
        if parity == 0:
            lo_f, hi_f = lo, hi
        else:
            lo_r, hi_r = lo, hi
    return lo_f, hi_f, lo_r, hi_r, lo_h, hi_h


@inline
def _intervals(fd: np.ndarray, x: np.ndarray, u: np.ndarray, p: np.ndarray, k: int,
               sums: np.ndarray) -> tuple:
    """Area ``k``'s certified intervals for its command with the others at ``u``:
    ``(lo_f, hi_f, lo_r, hi_r, lo_held, hi_held)`` (pu; empty where ``lo > hi``),
    the first four for a new command (frequency and ROCOF rows apart, the
    equilibrium and ellipsoid in both), the last pair the held level; ``sums``
    scratch (:func:`row_intervals`)."""
    inf = np.inf
    n_s, n_a, n_r, n_rows = int(fd[N_S]), int(fd[N_A]), int(fd[N_R]), int(fd[N_ROWS])
    new_ok, held_ok = True, True
    for a in range(n_a):          # the current outputs: room for the first interval
        dw, rc = abs(x[N_AREA_STATES * a + DW]), abs(x[N_AREA_STATES * a + ROCOF])
        new_ok = new_ok and dw <= fd[Y0_F_NEW] and rc <= fd[Y0_R_NEW]
        held_ok = held_ok and dw <= fd[Y0_F_HELD] and rc <= fd[Y0_R_HELD]
    lo_f, hi_f, lo_r, hi_r, lo_h, hi_h = row_intervals(fd, x, u, p, k, sums)
    width, u_k = 2 + n_s + 2 * n_a, u[k]
    o = HEAD + n_rows * width
    w, c_k = 0.0, fd[o + k]          # the equilibrium frequency, every area's
    for j in range(n_a):
        w += fd[o + j] * u[j] + fd[o + n_a + j] * p[j]
    w -= c_k * u_k
    e0, e1 = (-fd[HALF_NEW] - w) / c_k, (fd[HALF_NEW] - w) / c_k
    g0, g1 = (-fd[HALF_HELD] - w) / c_k, (fd[HALF_HELD] - w) / c_k
    lo_e, hi_e, lo_eh, hi_eh = min(e0, e1), max(e0, e1), min(g0, g1), max(g0, g1)
    o += 2 * n_a                     # the ellipsoid: f = K'(z(T) - z_eq), |f| <= rho
    ke, keu, kel = o, o + n_r * n_s, o + n_r * n_s + n_r * n_a
    qa, qb, ff = 0.0, 0.0, 0.0
    for r in range(n_r):
        f = 0.0
        for c in range(n_s):
            f += fd[ke + r * n_s + c] * x[c]
        for j in range(n_a):
            f += fd[keu + r * n_a + j] * u[j] + fd[kel + r * n_a + j] * p[j]
        g = fd[keu + r * n_a + k]
        f -= g * u_k
        qa += g * g
        qb += 2.0 * g * f
        ff += f * f
    for held in (False, True):
        rho = fd[RHO_HELD] if held else fd[RHO_NEW]
        disc = qb * qb - 4.0 * qa * (ff - rho * rho)
        if disc < 0.0 or qa <= 0.0:
            q_lo, q_hi = (inf, -inf) if disc < 0.0 or ff > rho * rho else (-inf, inf)
        else:
            root = math.sqrt(disc)
            q_lo, q_hi = (-qb - root) / (2.0 * qa), (-qb + root) / (2.0 * qa)
        if held:
            lo_h, hi_h = max(lo_h, lo_eh, q_lo), min(hi_h, hi_eh, q_hi)
        else:
            lo_q, hi_q = max(lo_e, q_lo), min(hi_e, q_hi)
    if not new_ok:
        lo_f, hi_f, lo_r, hi_r = inf, -inf, inf, -inf
    if not held_ok:
        lo_h, hi_h = inf, -inf
    return (max(lo_f, lo_q), min(hi_f, hi_q), max(lo_r, lo_q), min(hi_r, hi_q), lo_h, hi_h)


@inline
def grid_estimate(fd: np.ndarray, A: np.ndarray, B: np.ndarray, C: np.ndarray,
                  gain: np.ndarray, ks: np.ndarray, y: np.ndarray, scratch: np.ndarray,
                  u: np.ndarray, predict: bool, xe: np.ndarray) -> np.ndarray:
    """One step of the grid Kalman filter (:class:`~lfc.filters.coupled_set.GridKalman`, matrices ``A, B,
    C, gain``, state ``ks``: prior, then posterior) at a control sample: predict
    from the last posterior with the commands ``u`` held over the period (if
    ``predict``), correct with the measurements ``y``; writes the full state of
    the estimate into ``xe`` (every area's five states, then the line flows) and
    returns the loads' estimate (a view).  ``scratch`` holds ``len(y)`` values."""
    if predict:
        kf_predict(A, B, ks, u)
    kf_correct(gain, C, ks, y, scratch)
    n_s, n_r, n_a, o = int(fd[N_S]), int(fd[N_R]), int(fd[N_A]), int(fd[LIFT])
    for i in range(n_s):
        acc = 0.0
        for c in range(n_r):
            acc += fd[o + i * n_r + c] * ks[1, c]
        xe[i] = acc
    return ks[1, n_r:n_r + n_a]


@jit
def decide(fd: np.ndarray, x: np.ndarray, u: np.ndarray, p: np.ndarray, k: int,
           u_ref: float, mem: np.ndarray, sums: np.ndarray) -> tuple:
    """Area ``k``'s call (module docstring): the grid's state ``x`` (every area's
    five states, then the line flows; pu), every area's latest command ``u``
    (``u[k]`` is area ``k``'s, held) and load ``p`` (pu), the incoming command
    ``u_ref``; ``mem[0]`` the command area ``k`` holds; ``sums`` scratch of
    :func:`rows_scratch` entries.  Returns what
    :func:`lfc.filters.dispatch.decide` does, for area ``k``'s outputs; compiled,
    as that one is, as a function of its own that the engine's loops link."""
    if not _valid(x, u, p, u_ref):
        return hold_invalid(mem, u_ref)
    lo_f, hi_f, lo_r, hi_r, lo_h, hi_h = _intervals(fd, x, u, p, k, sums)
    lo = max(lo_f, lo_r, fd[U_MIN])
    hi = min(hi_f, hi_r, fd[U_MAX])
    certified = lo <= hi
    flags = 0
    if certified:
        v = min(max(u_ref, lo), hi)
    else:                              # hold; the vector as it is, at the held level
        v = mem[0]
        if not lo_h <= v <= hi_h:
            flags |= OUTSIDE
    mem[0] = v
    flags |= applied_flags(v, u_ref, certified, fd[U_MIN], fd[U_MAX])
    dw, rc = x[N_AREA_STATES * k + DW], x[N_AREA_STATES * k + ROCOF]
    return (v, flags, fd[F_LIM] ** 2 - dw ** 2, fd[R_LIM] ** 2 - rc ** 2,
            min(v - lo_f, hi_f - v), min(v - lo_r, hi_r - v), dw, rc, lo, hi)


@jit
def decide_once(fd: np.ndarray, x: np.ndarray, u: np.ndarray, p: np.ndarray, k: int,
                u_ref: float, mem: np.ndarray) -> tuple:
    """:func:`decide`, callable from Python (:meth:`lfc.filters.coupled.CoupledFilter.filter`)."""
    return decide(fd, x, u, p, k, u_ref, mem, np.empty(int(fd[N_ROWS])))


def rows_scratch(fd: np.ndarray) -> int:
    """How many entries of scratch :func:`decide` needs for the data ``fd``."""
    return int(fd[N_ROWS])
