"""The engine's lanes: one area's scenarios advanced ``LANES`` at a time.

:func:`run_lanes` is :func:`lfc.engine.run_kernel` for the commonest batch — single-area
scenarios without relay noise whose load is a step or none — with the inner loop
over scenarios, written without branches so that LLVM advances the lanes in SIMD
registers (:mod:`lfc._jit`); its metrics are :func:`~lfc.engine.run_kernel`'s bit for
bit.  :class:`lfc.scenarios.Scenarios` picks the scenarios that run here
(:func:`lane_blocks`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from lfc._jit import choose, inline, kernel
from lfc.engine import (ACE, LOAD, N_CTRL, Channels, Controller, Estimate, Estimators,
                        FilterTables, GridView, Memory, Outputs, Plants, RelayTables, Rows,
                        SignalSamples, Timing, generator_period, scenario_tables,
                        signal_value)
from lfc.filters.base import ACTIVE, ALARM_BITS, MEMORY, OUTSIDE
from lfc.multiarea import N_AREA_STATES
from lfc.relays import TIME_TOL, relay_sample
from lfc.signals import STEP

LANES = 16      # scenarios advanced together: the inner loop's trip count, known to LLVM
LANE_MIN_FILL = 10  # scenarios of one plant a block needs to run in lanes (the break-even,
#                     measured by bench/bench_batch.py --fill); fewer run one at a time
# the rows of a block's lane array z (row r of lane l at z[r * LANES + l])
(Z_X, Z_START, Z_DUE, Z_PEAK_DW, Z_PEAK_RC, Z_FIRST_T, Z_FIRST_R, Z_ALIVE, Z_U, Z_LOAD,
 Z_ON, Z_OFF, Z_END) = (0, 5, 8, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20)
N_Z = 21


@inline
def _lane_steps(k_from: int, k_to: int, dt: float, A: np.ndarray, Bu: np.ndarray,
                Bl: np.ndarray, z: np.ndarray, w: np.ndarray, limits: np.ndarray,
                delays: np.ndarray, stop_on_trip: bool) -> None:
    """Plant steps ``k_from`` to ``k_to`` of the ``LANES`` scenarios in ``z``
    (:func:`_lane_step`), two at a time: ``z`` to ``w`` and back (``w`` is scratch of
    ``z``'s size); an odd count ends with the last step's rows copied back to ``z``."""
    for k in range(k_from, k_to - 1, 2):
        _lane_step(k, dt, A, Bu, Bl, z, w, limits, delays, stop_on_trip)
        _lane_step(k + 1, dt, A, Bu, Bl, w, z, limits, delays, stop_on_trip)
    if (k_to - k_from) % 2 == 1:
        _lane_step(k_to - 1, dt, A, Bu, Bl, z, w, limits, delays, stop_on_trip)
        for r in range(z.shape[0]):
            z[r] = w[r]


@inline
def _lane_step(k: int, dt: float, A: np.ndarray, Bu: np.ndarray, Bl: np.ndarray,
               z: np.ndarray, w: np.ndarray, limits: np.ndarray, delays: np.ndarray,
               stop_on_trip: bool) -> None:
    """Plant step ``k`` of the ``LANES`` scenarios, read from ``z``, every row
    written to ``w``: the single-area path of :func:`~lfc.engine.run_kernel` (the plant update and
    its relays without relay noise) written without branches
    (:func:`lfc._jit.choose`, every operand evaluated), so that LLVM advances the
    lanes in SIMD registers.  Each lane computes the same sums in the same order
    as that path, so its numbers are the same bit for bit; a lane whose
    ``Z_ALIVE`` is 0 (stopped at a trip, or padding) keeps its values.  Writing to
    another buffer than the one read keeps LLVM from turning the kept values into
    masked stores (:mod:`lfc._jit`)."""
    L = LANES
    lim0, lim1, lim2 = limits[0], limits[1], limits[2]
    e0, e1, e2 = delays[0] - TIME_TOL, delays[1] - TIME_TOL, delays[2] - TIME_TOL
    a00, a01, a02, a03, a04 = A[0, 0], A[0, 1], A[0, 2], A[0, 3], A[0, 4]
    a10, a11, a12, a13, a14 = A[1, 0], A[1, 1], A[1, 2], A[1, 3], A[1, 4]
    a20, a21, a22, a23, a24 = A[2, 0], A[2, 1], A[2, 2], A[2, 3], A[2, 4]
    a30, a31, a32, a33, a34 = A[3, 0], A[3, 1], A[3, 2], A[3, 3], A[3, 4]
    a40, a41, a42, a43, a44 = A[4, 0], A[4, 1], A[4, 2], A[4, 3], A[4, 4]
    b0, b1, b2, b3, b4 = Bu[0, 0], Bu[1, 0], Bu[2, 0], Bu[3, 0], Bu[4, 0]
    l0, l1, l2, l3, l4 = Bl[0, 0], Bl[1, 0], Bl[2, 0], Bl[3, 0], Bl[4, 0]
    nan = math.nan
    t, tn, done = k * dt, (k + 1) * dt, float(k + 1)
    for l in range(L):
        x0, x1, x2 = z[Z_X * L + l], z[(Z_X + 1) * L + l], z[(Z_X + 2) * L + l]
        x3, x4 = z[(Z_X + 3) * L + l], z[(Z_X + 4) * L + l]
        ua, load = z[Z_U * L + l], z[Z_LOAD * L + l]
        on, off = z[Z_ON * L + l], z[Z_OFF * L + l]
        p0 = choose((on <= t) & (t < off), load, 0.0)
        u0, u1, u2, u3, u4 = b0 * ua, b1 * ua, b2 * ua, b3 * ua, b4 * ua
        n0 = a00 * x0 + a01 * x1 + a02 * x2 + a03 * x3 + a04 * x4 + u0 + l0 * p0
        n1 = a10 * x0 + a11 * x1 + a12 * x2 + a13 * x3 + a14 * x4 + u1 + l1 * p0
        n2 = a20 * x0 + a21 * x1 + a22 * x2 + a23 * x3 + a24 * x4 + u2 + l2 * p0
        n3 = a30 * x0 + a31 * x1 + a32 * x2 + a33 * x3 + a34 * x4 + u3 + l3 * p0
        n4 = a40 * x0 + a41 * x1 + a42 * x2 + a43 * x3 + a44 * x4 + u4 + l4 * p0
        # the relays (relay_sample): a timer starts when beyond, trips after its delay
        s0, s1, s2 = z[Z_START * L + l], z[(Z_START + 1) * L + l], z[(Z_START + 2) * L + l]
        d0, d1, d2 = z[Z_DUE * L + l], z[(Z_DUE + 1) * L + l], z[(Z_DUE + 2) * L + l]
        r0 = choose(n3 > lim0, choose(s0 == s0, s0, tn), nan)
        r1 = choose(n3 < lim1, choose(s1 == s1, s1, tn), nan)
        r2 = choose(abs(n4) > lim2, choose(s2 == s2, s2, tn), nan)
        now0, now1, now2 = tn - r0 >= e0, tn - r1 >= e1, tn - r2 >= e2
        trip0, trip1, trip2 = now0 & (d0 == 0.0), now1 & (d1 == 0.0), now2 & (d2 == 0.0)
        trip = trip0 | trip1 | trip2
        alive, first_t = z[Z_ALIVE * L + l], z[Z_FIRST_T * L + l]
        go = alive != 0.0
        first = go & trip & (first_t != first_t)
        stop = go & trip & stop_on_trip
        w[Z_X * L + l] = choose(go, n0, x0)
        w[(Z_X + 1) * L + l] = choose(go, n1, x1)
        w[(Z_X + 2) * L + l] = choose(go, n2, x2)
        w[(Z_X + 3) * L + l] = choose(go, n3, x3)
        w[(Z_X + 4) * L + l] = choose(go, n4, x4)
        w[Z_START * L + l] = choose(go, r0, s0)
        w[(Z_START + 1) * L + l] = choose(go, r1, s1)
        w[(Z_START + 2) * L + l] = choose(go, r2, s2)
        w[Z_DUE * L + l] = choose(go, choose(now0, 1.0, 0.0), d0)
        w[(Z_DUE + 1) * L + l] = choose(go, choose(now1, 1.0, 0.0), d1)
        w[(Z_DUE + 2) * L + l] = choose(go, choose(now2, 1.0, 0.0), d2)
        peak_dw, peak_rc = z[Z_PEAK_DW * L + l], z[Z_PEAK_RC * L + l]
        w[Z_PEAK_DW * L + l] = choose(go, max(peak_dw, abs(n3)), peak_dw)
        w[Z_PEAK_RC * L + l] = choose(go, max(peak_rc, abs(n4)), peak_rc)
        w[Z_FIRST_T * L + l] = choose(first, tn, first_t)
        w[Z_FIRST_R * L + l] = choose(first, choose(trip0, 0.0, choose(trip1, 1.0, 2.0)),
                                      z[Z_FIRST_R * L + l])
        w[Z_END * L + l] = choose(stop, done, z[Z_END * L + l])
        w[Z_ALIVE * L + l] = choose(stop, 0.0, alive)
        w[Z_U * L + l], w[Z_LOAD * L + l], w[Z_ON * L + l], w[Z_OFF * L + l] = ua, load, on, off


class LaneWork(NamedTuple):
    """:func:`run_lanes`' scratch and the lanes' state."""

    z: np.ndarray           # (N_Z LANES,): the lanes' rows (Z_*)
    w: np.ndarray           # (N_Z LANES,): the second buffer of _lane_steps
    xs: np.ndarray          # (5,): one lane's state, for its generator side
    x_hat: np.ndarray       # (5,): the state a filter sees
    mem: np.ndarray         # (LANES, MEMORY): each lane's filter memory
    gstate: np.ndarray      # (LANES, 1): each lane's integrator (pu)
    kstate: np.ndarray      # (LANES, 2, n_kf): each lane's Kalman state
    start: np.ndarray       # (3,): the relays' timer starts at t = 0
    due: np.ndarray         # (3,): whether their trips are due at t = 0
    ctrl: np.ndarray        # (0, N_CTRL): no trace
    scratch: np.ndarray     # (1,): the load now (pu)
    seen: np.ndarray        # (LANES, n_ctrl, 2): what each lane's sensors reported

    @classmethod
    def sized(cls, n_kf: int, n_ctrl: int) -> LaneWork:
        """Zeros for Kalman filters of up to ``n_kf`` states and ``n_ctrl`` control
        samples."""
        return cls(np.zeros(N_Z * LANES), np.zeros(N_Z * LANES), np.zeros(N_AREA_STATES),
                   np.zeros(N_AREA_STATES), np.zeros((LANES, MEMORY)), np.zeros((LANES, 1)),
                   np.zeros((LANES, 2, n_kf)), np.zeros(3), np.zeros(3),
                   np.zeros((0, N_CTRL)), np.zeros(1), np.zeros((LANES, n_ctrl, 2)))


@kernel
def run_lanes(timing: Timing, plants: Plants, rows: Rows, samples: SignalSamples,
              estimators: Estimators, filters: FilterTables, relays: RelayTables,
              out: Outputs, blocks: np.ndarray, work: LaneWork) -> None:
    """:func:`~lfc.engine.run_kernel` for single-area scenarios without relay noise
    whose load is a step or none, ``LANES`` at a time: ``blocks`` (n_blocks, LANES)
    holds the scenario numbers of each block, all on one plant (-1: an empty lane).
    Each control period runs every lane's generator side
    (:func:`~lfc.engine.generator_period`, one lane after another), then
    :func:`_lane_steps` advances all lanes.  The metrics and ``ends`` equal
    :func:`~lfc.engine.run_kernel`'s bit for bit (``tests/test_lanes.py``); ``out``'s
    trace arrays are not written.  ``work`` (:class:`LaneWork`) holds the lanes' state."""
    n_steps, ratio, dt, stop_on_trip = timing
    ad, bu, bl = plants.ad, plants.bu, plants.bl
    k_freq, k_tie = plants.k_freq[0], plants.k_tie[0]
    plant_of, index, kinds, params, offsets = (rows.plant_of, rows.index, rows.kinds,
                                               rows.params, rows.offsets)
    st, sv, noise = samples
    ka, kb, kc, kg, kdim = estimators
    methods, fdata, foff = filters
    limits, delays = relays
    metrics, ends = out.metrics, out.ends
    z, w, xs, x_hat, mem, gstate, kstate, start, due, ctrl, scratch, seen = work
    L = LANES
    n_ctrl = -(-n_steps // ratio)
    empty = x_hat[:0]
    relay_sample(0.0, 0.0, 0.0, limits, delays, start, due)   # the relays' state at t = 0
    for b in range(blocks.shape[0]):
        p_i = plant_of[blocks[b, 0]]
        A, Bu, Bl = ad[p_i], bu[p_i], bl[p_i]
        z[:], mem[:], gstate[:], kstate[:] = 0.0, 0.0, 0.0, 0.0
        for l in range(L):
            i = blocks[b, l]
            for r in range(3):
                z[(Z_START + r) * L + l], z[(Z_DUE + r) * L + l] = start[r], due[r]
            z[Z_FIRST_T * L + l], z[Z_FIRST_R * L + l] = math.nan, -1.0
            z[Z_END * L + l] = float(n_steps)
            z[Z_ON * L + l], z[Z_OFF * L + l] = math.inf, math.inf
            if i < 0:
                continue
            z[Z_ALIVE * L + l] = 1.0
            if kinds[i, 0, LOAD] == STEP:
                pa = params[i, 0, LOAD]
                z[Z_LOAD * L + l], z[Z_ON * L + l], z[Z_OFF * L + l] = pa[0], pa[2], pa[3]
            met = metrics[i]
            met[:] = 0.0
            met[:, 0], met[:, 1] = math.nan, -1.0
        for j in range(n_ctrl):
            k0 = j * ratio
            t = k0 * dt
            alive = False
            for l in range(L):
                i = blocks[b, l]
                if i < 0 or z[Z_ALIVE * L + l] == 0.0:
                    continue
                alive = True
                e_i, q_i, f_i = index[i, 0, 0], index[i, 0, 1], index[i, 0, 2]
                ka_i, kb_i, kc_i, kg_i, method, fd = scenario_tables(
                    e_i, f_i, ka, kb, kc, kg, kdim, methods, fdata, foff, empty)
                for r in range(5):
                    xs[r] = z[(Z_X + r) * L + l]
                scratch[0] = signal_value(LOAD, kinds[i, 0], params[i, 0], offsets[i, 0], st, sv,
                                     t, k0)
                ace = signal_value(ACE, kinds[i, 0], params[i, 0], offsets[i, 0], st, sv, t, j)
                ua, flags, mod = generator_period(
                    j, t, xs, scratch[0] + 0.0, (noise[q_i, j, 0] if q_i >= 0 else 0.0,
                                                 noise[q_i, j, 1] if q_i >= 0 else 0.0),
                    0.0 + ace, Channels(kinds[i, 0], params[i, 0], offsets[i, 0], st, sv),
                    Estimate(e_i, ka_i, kb_i, kc_i, kg_i, kstate[l]),
                    Controller(k_freq, k_tie, index[i, 0, 3] == 1, index[i, 0, 4] == 1, method,
                               fd),
                    Memory(mem[l], gstate[l], x_hat, ctrl, seen[l]),
                    GridView(0, xs, scratch, scratch, scratch, scratch, kstate[l], scratch))
                z[Z_U * L + l] = ua
                met = metrics[i, 0]
                met[4] += (flags & ACTIVE) != 0
                met[5] += (flags & ALARM_BITS) != 0
                met[8] += (flags & OUTSIDE) != 0
                met[6] = max(met[6], mod)
                met[7] += mod
            if not alive:
                break
            _lane_steps(k0, min(k0 + ratio, n_steps), dt, A, Bu, Bl, z, w, limits, delays,
                        stop_on_trip)
        for l in range(L):
            i = blocks[b, l]
            if i < 0:
                continue
            met = metrics[i, 0]
            met[0], met[1] = z[Z_FIRST_T * L + l], z[Z_FIRST_R * L + l]
            met[2], met[3] = z[Z_PEAK_DW * L + l], z[Z_PEAK_RC * L + l]
            met[9] = abs(z[(Z_X + 3) * L + l])
            ends[i] = int(z[Z_END * L + l])



def lane_blocks(plant_of: np.ndarray, rows: np.ndarray,
                min_fill: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """``rows`` (scenario numbers) grouped by plant into blocks of ``LANES``
    (n_blocks, LANES), the last block of each plant padded with -1 if it holds at
    least ``min_fill`` rows; and the rows of the last blocks that hold fewer (a
    block costs the plant's arithmetic of all ``LANES`` lanes, whatever it holds)."""
    blocks, left = [], []
    for p in np.unique(plant_of[rows]):
        mine = rows[plant_of[rows] == p]
        full = len(mine) - len(mine) % LANES
        if len(mine) - full < min_fill:
            left.append(mine[full:])
            mine = mine[:full]
        pad = -len(mine) % LANES
        blocks.append(np.concatenate([mine, np.full(pad, -1)]).reshape(-1, LANES))
    return ((np.concatenate(blocks) if blocks else np.zeros((0, LANES))).astype(np.int64),
            (np.concatenate(left) if left else np.zeros(0)).astype(np.int64))


