"""The closed loop, compiled once: the linear plant, the generator side and the relays.

One engine advances N scenarios of one grid (:mod:`lfc.multiarea`; a single
area is a grid of one area and no tie-line), one after another:

* every control period ``control_period`` each area's **generator side** runs
  (:func:`generator_period`): measurement noise on ``(dw_meas, rocof_meas)``,
  the Kalman estimate (or the state as it is), the incoming command
  ``u_ref = integrator + attack on P_c``, the safety filter (any method of
  :mod:`lfc.filters`, through its compiled dispatcher), the AGC on the area
  control error (for one area the local integral controller ``d dPc/dt =
  k_i (dw_ref - dw_meas)``) and the estimator's prediction; the command is
  held until the next period;
* every plant step ``dt`` the plant advances exactly (zero-order hold) and
  each area's OF2, UF2 and ROCOF relays (:func:`lfc.relays.relay_sample`) see
  its measured signals (through noise too, with ``relay_noise``).

:func:`lfc.simulate` is N = 1 with a trace; :func:`lfc.simulate_many` is N
large with metrics only; the ANDES testbed runs :class:`GeneratorSide` (the
same :func:`generator_period`) against its own plant.  Each scenario has its own
plant, signals, noise, estimator and filter (indices into small tables), so a
batch can mix them freely.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from lfc._jit import inline, kernel
from lfc._validate import ParameterTypeError, check_index
from lfc.estimation import (KalmanFilter, check_noise_std, kf_correct, kf_predict,
                            measurement_std)
from lfc.filters.base import ACTIVE, ALARM_BITS, MAX_ABS_INPUT, MEMORY, OUTSIDE
from lfc.filters.dispatch import decide, decide_grid, grid_wide, is_grid_wide
from lfc.model import LFCParams
from lfc.multiarea import N_AREA_STATES
from lfc.relays import relay_sample
from lfc.sensor_attacks import SCALE, lag_samples
from lfc.signals import GRID, N_PARAMS, NONE, SAMPLES, STEP, Signal, value_at

#: signal channels: ACE an attack on the area control error, DW_MEAS and ROCOF_MEAS on the
#: readings of the generator side's sensors
PC, WREF, LOAD, ACE, DW_MEAS, ROCOF_MEAS = range(6)
N_CHANNELS = 6
N_KF = 6                            # largest Kalman state (5 states + the load)
N_CTRL = 15                         # trace columns per control period (see CTRL_COLUMNS)
CTRL_COLUMNS = ("u_ref", "u", "flags", "h_freq", "h_rocof", "margin_freq", "margin_rocof",
                "y_freq", "y_rocof", "detail0", "detail1", "dw_hat", "rocof_hat",
                "p_load_hat", "wref")
METRICS = ("first_trip_t", "first_trip_relay", "max_abs_dw_meas", "max_abs_rocof_meas",
           "active", "alarms", "max_abs_modification", "sum_abs_modification", "outside",
           "final_abs_dw_meas")


class Timing(NamedTuple):
    """A run's clock: ``n_steps`` plant steps of ``dt`` (s), the generator sides every
    ``ratio`` steps; ``stop_on_trip`` ends a scenario at its first trip."""

    n_steps: int
    ratio: int
    dt: float
    stop_on_trip: bool


class Plants(NamedTuple):
    """The grid's plants as the kernel reads them (every scenario runs on one)."""

    #: (n_plants, n_s, n_s), (n_plants, n_s, n_a), (n_plants, n_s, n_a): each plant
    #: discretized (:func:`lfc.multiarea.discretize_grid`: state, command, load)
    ad: np.ndarray
    bu: np.ndarray
    bl: np.ndarray
    #: (n_a, n_l): each area's sign on each tie-line (:meth:`MultiAreaParams.incidence`)
    incidence: np.ndarray
    #: (n_a,): the AGC's gains on frequency and on tie-line export times the control
    #: period (pu per pu)
    k_freq: np.ndarray
    k_tie: np.ndarray


class Rows(NamedTuple):
    """Each scenario's row: its plant, its tables' indices and its signals (N rows)."""

    #: (N,): the scenario's plant (an index into :class:`Plants`)
    plant_of: np.ndarray
    #: (N, n_a, 5): each area's Kalman filter (-1: none), noise row (-1: none),
    #: filter (-1: none), disturbance feed-forward (0/1) and anti-windup (0/1)
    index: np.ndarray
    #: (N, n_a, N_CHANNELS), (N, n_a, N_CHANNELS, N_PARAMS), (N, n_a, N_CHANNELS, 2):
    #: each area's signals (:func:`scenario_signals`)
    kinds: np.ndarray
    params: np.ndarray
    offsets: np.ndarray
    #: (N, n_a, 3): the std of the relays' own measurement noise on ``(dw_meas,
    #: rocof_meas)`` (pu, pu/s; drawn at every plant step) and, in ``[i, 0, 2]``, the
    #: scenario's seed for it
    relay_noise: np.ndarray
    #: (N, n_a, 4): each area's load that follows its frequency meter
    #: (:class:`lfc.load_attacks.FollowingLoad`: gain, limit, start, stop; gain 0: none)
    following: np.ndarray


class SignalSamples(NamedTuple):
    """What the rows' signals and noise read."""

    #: every sampled signal's times (s) and values, one after another (``Rows.offsets``)
    times: np.ndarray
    values: np.ndarray
    #: (n_noise, n_ctrl, 2): the controllers' measurement noise rows (pu, pu/s)
    noise: np.ndarray


class Estimators(NamedTuple):
    """The Kalman filters' matrices, padded to the largest (:func:`scenario_tables`)."""

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    gain: np.ndarray
    #: (n_kf, 3): each one's (states, measurements, inputs)
    dims: np.ndarray


class FilterTables(NamedTuple):
    """The filters' method codes, their data one after another and each one's offset."""

    methods: np.ndarray
    data: np.ndarray
    offsets: np.ndarray


class RelayTables(NamedTuple):
    """The relays' thresholds and delays (:meth:`RelaySettings.arrays`), every area's."""

    limits: np.ndarray
    delays: np.ndarray


class Outputs(NamedTuple):
    """What the kernel writes: ``metrics`` (N, n_a, len(METRICS)), ``ends`` (N,: the
    last plant sample kept) and, when the trace arrays have rows (N = 1), every
    state ``x`` (samples, n_s), control sample ``ctrl`` (n_ctrl, n_a, N_CTRL) and
    trip ``trips`` (samples, n_a)."""

    metrics: np.ndarray
    ends: np.ndarray
    x: np.ndarray
    ctrl: np.ndarray
    trips: np.ndarray


class Work(NamedTuple):
    """:func:`run_kernel`'s scratch: the kernel allocates nothing."""

    x: np.ndarray           # (n_s,): the grid's state
    xn: np.ndarray          # (n_s,): its next value
    u: np.ndarray           # (n_a,): each area's held command (pu)
    pl: np.ndarray          # (n_a,): each area's load now (pu)
    x_hat: np.ndarray       # (5,): the state a filter sees
    mem: np.ndarray         # (n_a, MEMORY): each area's filter memory
    gstate: np.ndarray      # (n_a, 1): each area's AGC integrator (pu)
    kstate: np.ndarray      # (n_a, 2, N_KF): each area's Kalman state (prior, posterior)
    start: np.ndarray       # (n_a, 3): each relay's timer start (s; NaN: not running)
    due: np.ndarray         # (n_a, 3): whether each relay's trip is due
    ym: np.ndarray          # (6 n_a,): the grid's measurements, then innovations (a
    #                         coupled filter's grid Kalman filter)
    xe: np.ndarray          # (n_s,): the estimate of the grid's state
    sums: np.ndarray        # a coupled filter's scratch (rows_scratch entries)
    seen: np.ndarray        # (n_a, n_ctrl, 2): what each area's sensors reported

    @classmethod
    def sized(cls, n_s: int, n_a: int, n_kf: int, n_sums: int, n_ctrl: int) -> Work:
        """Zeros for a grid of ``n_s`` states and ``n_a`` areas, Kalman filters of up
        to ``n_kf`` states, ``n_sums`` entries of filter scratch and ``n_ctrl``
        control samples."""
        return cls(np.zeros(n_s), np.zeros(n_s), np.zeros(n_a), np.zeros(n_a),
                   np.zeros(N_AREA_STATES), np.zeros((n_a, MEMORY)), np.zeros((n_a, 1)),
                   np.zeros((n_a, 2, n_kf)), np.zeros((n_a, 3)), np.zeros((n_a, 3)),
                   np.zeros(6 * n_a), np.zeros(n_s), np.zeros(n_sums),
                   np.zeros((n_a, n_ctrl, 2)))


@inline
def signal_value(channel: int, kinds: np.ndarray, params: np.ndarray, offsets: np.ndarray,
            st: np.ndarray, sv: np.ndarray, t: float, index: int) -> float:
    """Value of one scenario's signal on ``channel`` at time ``t`` (grid ``index``)."""
    kind = kinds[channel]
    if kind == GRID:
        return sv[offsets[channel, 0] + index]
    return value_at(kind, params, channel, t, st, sv, offsets[channel, 0], offsets[channel, 1])


@inline
def sensor_reading(channel: int, honest: float, channels: Channels, seen: np.ndarray,
                   t: float, j: int) -> tuple:
    """What the sensor on ``channel`` (``DW_MEAS`` or ``ROCOF_MEAS``) reports at control
    sample ``j`` (time ``t``, s), and the lie: ``(report, report - honest)``.

    ``honest`` is the reading (state plus measurement noise).  A waveform on the
    channel (:mod:`lfc.signals`) is added to it; a reading transform
    (:mod:`lfc.sensor_attacks`) replaces it inside its window: ``SCALE`` reports
    ``params[0]`` times it, ``FREEZE`` and ``REPLAY`` the report ``params[5]``
    samples earlier (``seen``; the honest reading before the run's first report)."""
    kinds, params, offsets, st, sv = channels
    kind = kinds[channel]
    if kind < SCALE:                      # a waveform (lfc.signals)
        lie = signal_value(channel, kinds, params, offsets, st, sv, t, j)
        return honest + lie, lie
    if t < params[channel, 2] or t >= params[channel, 3]:
        return honest, 0.0
    if kind == SCALE:
        report = params[channel, 0] * honest
    else:
        lag = int(params[channel, 5])
        report = seen[j - lag, channel - DW_MEAS] if j >= lag else honest
    return report, report - honest


@inline
def agc_step(gstate: np.ndarray, k_i_period: float, wref: float, y0: float,
             k_tie_period: float, tie: float, anti_windup: bool, u_ref: float,
             u: float) -> None:
    """The AGC (or local) integrator over one control period: ``gstate[0] +=
    k_i_period (wref - y0) - k_tie_period tie`` (pu), unless ``anti_windup`` and
    the increment would widen the gap between the incoming command ``u_ref`` and
    the applied ``u`` (conditional integration).  The generator side calls it;
    so does a control centre across a network (:mod:`lfc.wire`)."""
    increment = k_i_period * (wref - y0) - k_tie_period * tie
    if not (anti_windup and increment * (u_ref - u) > 0.0):
        gstate[0] += increment


class Channels(NamedTuple):
    """One area's command channels as its generator side reads them
    (:func:`scenario_signals`): each channel's signal ``kinds``, ``params`` and
    ``offsets``, and every sampled signal's ``times`` (s) and ``values``."""

    kinds: np.ndarray
    params: np.ndarray
    offsets: np.ndarray
    times: np.ndarray
    values: np.ndarray


class Estimate(NamedTuple):
    """An area's Kalman filter: ``index`` (< 0: none, the filter reads the state as
    it is), its matrices ``a``, ``b``, ``c``, ``gain`` and its ``state`` (2, N_KF:
    prior, then posterior)."""

    index: int
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    gain: np.ndarray
    state: np.ndarray


class Controller(NamedTuple):
    """An area's AGC and safety filter: the integrator's gains on frequency and on
    tie-line export times the control period ``k_freq``, ``k_tie`` (pu per pu),
    ``feedforward`` (the filter reads the true load), ``anti_windup`` (conditional
    integration, :func:`agc_step`), the filter's ``method`` (< 0: none) and its
    packed ``data``."""

    k_freq: float
    k_tie: float
    feedforward: bool
    anti_windup: bool
    method: int
    data: np.ndarray


class Memory(NamedTuple):
    """What an area's generator side keeps between samples and writes: the filter's
    memory ``mem`` (MEMORY,), the integrator ``gstate`` (1,: pu), ``x_hat`` (5,: the
    state the filter sees), the control trace ``ctrl`` (a row of N_CTRL values per
    sample; no rows: no trace) and ``seen`` (n_ctrl, 2: what its frequency and ROCOF
    sensors reported at every sample, read by a freeze or a replay; no rows: no
    reading transform)."""

    mem: np.ndarray
    gstate: np.ndarray
    x_hat: np.ndarray
    ctrl: np.ndarray
    seen: np.ndarray


class GridView(NamedTuple):
    """What the coupled certificate (:mod:`lfc.filters.coupled`) reads of the whole
    grid at a sample: this ``area``'s index, the grid's state ``x`` (design-model
    coordinates), every area's latest command ``u`` and load ``p`` (pu), then its
    grid Kalman filter's measurements and innovations ``ym``, estimate ``xe`` and
    state ``ks`` (:class:`Work`), and the filter's scratch ``sums``."""

    area: int
    x: np.ndarray
    u: np.ndarray
    p: np.ndarray
    ym: np.ndarray
    xe: np.ndarray
    ks: np.ndarray
    sums: np.ndarray


@inline
def generator_period(j: int, t: float, x: np.ndarray, p_true: float, noise: tuple,
                     tie: float, channels: Channels, estimate: Estimate,
                     controller: Controller, memory: Memory, grid: GridView) -> tuple:
    """The generator side at control sample ``j`` (time ``t``, s) of one scenario.

    ``x`` is the plant's state in design-model coordinates and ``p_true`` the true
    load (pu); ``noise`` the measurement noise of this sample on ``(dw_meas,
    rocof_meas)`` (pu, pu/s).  A sensor attack (channels ``DW_MEAS``, ``ROCOF_MEAS``)
    is added to both readings wherever the generator side reads them: the AGC's
    integrator, the Kalman filter and, with the exact state, the filter's state (the
    relays read the plant).
    In an interconnected grid (:mod:`lfc.multiarea`) ``p_true`` is the area's net
    disturbance (load plus tie-line export) and the integrator is the area's AGC:
    ``gstate[0] += k_freq (wref - dw_meas) - k_tie tie`` with ``tie`` the measured
    tie-line export plus any ACE attack (0 and 0 for one area).
    With ``controller.anti_windup`` the integrator does not move while the filter's
    command differs from the incoming one in the direction the increment would widen
    (conditional integration): it cannot wind up behind a held command.
    A grid-wide filter (:func:`lfc.filters.dispatch.decide_grid`: the coupled
    certificate) reads the whole grid instead (``grid``; another method ignores it).
    ``estimate.index`` >= 0 selects the Kalman filter.  Writes ``memory``
    (:class:`Memory`; ``ctrl[j]`` if ``ctrl`` has rows) and returns ``(u, flags,
    |u - u_ref|)``.
    """
    kinds, params, offsets, st, sv = channels
    est, ka, kb, kc, kg, kstate = estimate
    k_i_period, k_tie_period, feedforward, anti_windup, method, fd = controller
    mem, gstate, x_hat, ctrl, seen = memory
    noise0, noise1 = noise
    y0, lie0 = sensor_reading(DW_MEAS, x[3] + noise0, channels, seen, t, j)
    y1, lie1 = sensor_reading(ROCOF_MEAS, x[4] + noise1, channels, seen, t, j)
    if seen.shape[0]:
        seen[j, 0], seen[j, 1] = y0, y1
    if est >= 0 and not grid_wide(method):
        n = ka.shape[0]
        kf_correct(kg, kc, kstate, (y0, y1), x_hat)     # x_hat: scratch until below
        for r in range(5):
            x_hat[r] = kstate[1, r]
        p_hat = kstate[1, 5] if n == N_KF else 0.0
    else:
        for r in range(5):
            x_hat[r] = x[r]
        x_hat[3] += lie0
        x_hat[4] += lie1
        p_hat = p_true if feedforward else 0.0
    u_ref = gstate[0] + signal_value(PC, kinds, params, offsets, st, sv, t, j)
    wref = signal_value(WREF, kinds, params, offsets, st, sv, t, j)
    nan = math.nan
    if grid_wide(method):
        u, flags, h0, h1, m0, m1, q0, q1, d0, d1, p_hat = decide_grid(
            method, fd, grid, estimate, j == 0, u_ref, mem, x_hat)
    elif method >= 0:
        u, flags, h0, h1, m0, m1, q0, q1, d0, d1 = decide(method, fd, x_hat, u_ref, p_hat, mem)
    else:
        u, flags, h0, h1, m0, m1, q0, q1, d0, d1 = u_ref, 0, nan, nan, nan, nan, nan, nan, \
            nan, nan
    agc_step(gstate, k_i_period, wref, y0, k_tie_period, tie, anti_windup, u_ref, u)
    if est >= 0 and not grid_wide(method):
        kf_predict(ka, kb, kstate, (u,))
    if ctrl.shape[0]:
        vals = (u_ref, u, float(flags), h0, h1, m0, m1, q0, q1, d0, d1, x_hat[3], x_hat[4],
                p_hat, wref)
        for c in range(N_CTRL):
            ctrl[j, c] = vals[c]
    # the modification of a command the filter could read (a non-finite command or one
    # beyond MAX_ABS_INPUT is invalid input, held, not modified: it counts 0)
    return u, flags, abs(u - u_ref) if abs(u_ref) <= MAX_ABS_INPUT else 0.0


@inline
def scenario_tables(e_i: int, f_i: int, ka: np.ndarray, kb: np.ndarray, kc: np.ndarray,
                    kg: np.ndarray, kdim: np.ndarray, methods: np.ndarray, fdata: np.ndarray,
                    foff: np.ndarray, empty: np.ndarray) -> tuple:
    """One generator side's Kalman matrices ``(A, B, C, gain)`` (empty without
    one, ``e_i`` < 0), filter method (-1 without one, ``f_i`` < 0) and filter
    data, as views into the engine's tables."""
    n_kf, n_y, n_u = (kdim[e_i, 0], kdim[e_i, 1], kdim[e_i, 2]) if e_i >= 0 else (0, 0, 0)
    ka_i = ka[e_i, :n_kf, :n_kf] if e_i >= 0 else ka[0, :0, :0]
    kb_i = kb[e_i, :n_kf, :n_u] if e_i >= 0 else kb[0, :0, :0]
    kc_i = kc[e_i, :n_y, :n_kf] if e_i >= 0 else kc[0, :0, :0]
    kg_i = kg[e_i, :n_kf, :n_y] if e_i >= 0 else kg[0, :0, :0]
    method = methods[f_i] if f_i >= 0 else -1
    fd = fdata[foff[f_i]:foff[f_i + 1]] if f_i >= 0 else empty
    return ka_i, kb_i, kc_i, kg_i, method, fd


@inline
def _load(kind: int, value: float, on: float, off: float, kinds: np.ndarray,
          params: np.ndarray, offsets: np.ndarray, st: np.ndarray, sv: np.ndarray, t: float,
          index: int) -> float:
    """The load (pu) of one area at plant step ``index`` (time ``t``, s), of kind
    ``kind``; a step (``value`` pu from ``on`` to ``off`` s, the common case of
    every map) is evaluated here directly."""
    if kind == STEP:
        return value if on <= t < off else 0.0
    if kind == NONE:
        return 0.0
    return signal_value(LOAD, kinds, params, offsets, st, sv, t, index)


@inline
def _following(row: np.ndarray, dw_meas: float, t: float) -> float:
    """The load (pu) a :class:`lfc.load_attacks.FollowingLoad` ``row`` (gain, limit,
    start, stop) switches at time ``t`` (s) for the meter reading ``dw_meas`` (pu)."""
    if not row[2] <= t < row[3]:
        return 0.0
    return min(max(-row[0] * dw_meas, -row[1]), row[1])


@inline
def _watch(met: np.ndarray, t: float, dw: float, rc: float, noisy: bool, r0: float, r1: float,
           relays: RelayTables, start: np.ndarray, due: np.ndarray, peak_dw: float,
           peak_rc: float) -> tuple:
    """One area's relays at plant sample time ``t`` (s): the measured ``dw`` (pu)
    and ROCOF (pu/s), read through white noise of std ``r0``, ``r1`` if ``noisy``.
    Records the area's first trip in its metrics ``met`` and returns ``(trip
    bits, peak |dw|, peak |ROCOF|)`` updated from ``peak_dw``, ``peak_rc``."""
    if noisy:
        n0 = np.random.standard_normal()
        n1 = np.random.standard_normal()
        trips = relay_sample(t, dw + r0 * n0, rc + r1 * n1, relays.limits, relays.delays, start,
                             due)
    else:
        trips = relay_sample(t, dw, rc, relays.limits, relays.delays, start, due)
    if trips and math.isnan(met[0]):
        met[0], met[1] = t, float(_lowest_bit(trips))
    return trips, max(peak_dw, abs(dw)), max(peak_rc, abs(rc))


@kernel
def run_kernel(timing: Timing, plants: Plants, rows: Rows, samples: SignalSamples,
               estimators: Estimators, filters: FilterTables, relays: RelayTables,
               out: Outputs, work: Work) -> None:
    """Advance every scenario of one grid from equilibrium (:class:`Timing`).

    The grid has ``n_a = plants.incidence.shape[0]`` areas and
    ``plants.incidence.shape[1]`` tie-lines (:mod:`lfc.multiarea`; one area and no
    line is the single-area model).  Each of the N ``rows`` runs on its plant
    with its signals, estimator and filter (indices into ``estimators`` and
    ``filters``); the relays are ``relays`` in every area.  Writes ``out``
    (:class:`Outputs`; a trace when its trace arrays have rows, N = 1); ``work``
    is scratch (:class:`Work`).

    One area of five states (the single-area model) takes a path that keeps the
    state in registers for a control period; it computes the same sums in the
    same order as the general path.
    """
    n_steps, ratio, dt, stop_on_trip = timing
    ad, bu, bl, inc, k_freq, k_tie = plants
    plant_of, index, kinds, params, offsets, relay_noise, following = rows
    st, sv, noise = samples
    ka, kb, kc, kg, kdim = estimators
    methods, fdata, foff = filters
    limits, delays = relays
    metrics, ends, trace_x, trace_ctrl, trace_trips = out
    x, xn, u, pl, x_hat, mem, gstate, kstate, start, due, ym, xe, sums, seen = work
    n_ctrl = -(-n_steps // ratio)
    n_a, n_l, n_s = inc.shape[0], inc.shape[1], ad.shape[1]
    m = N_AREA_STATES
    single = n_a == 1 and n_s == N_AREA_STATES
    traced = trace_x.shape[0] > 0
    empty = x_hat[:0]
    x_0, ks_0, mem_0, gs_0, ctrl_0 = x[:m], kstate[0], mem[0], gstate[0], trace_ctrl[:, 0, :]
    for i in range(index.shape[0]):
        p_i = plant_of[i]
        A, Bu, Bl = ad[p_i], bu[p_i], bl[p_i]
        x[:], mem[:], gstate[:], kstate[:], due[:], u[:] = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        start[:] = np.nan
        met = metrics[i]
        met[:] = 0.0
        met[:, 0], met[:, 1] = np.nan, -1.0
        end, stopped = n_steps, False
        rn = relay_noise[i]
        for a in range(n_a):
            if rn[a, 0] > 0.0 or rn[a, 1] > 0.0:
                np.random.seed(int(rn[0, 2]))
                break
        for a in range(n_a):
            trips = relay_sample(0.0, 0.0, 0.0, limits, delays, start[a], due[a])
            if traced:
                trace_trips[0, a] = trips
        # area 0's tables, looked up once per scenario (the other areas' every period)
        kinds0, params0, offsets0 = kinds[i, 0], params[i, 0], offsets[i, 0]
        ka0, kb0, kc0, kg0, method0, fd0 = scenario_tables(
            index[i, 0, 0], index[i, 0, 2], ka, kb, kc, kg, kdim, methods, fdata, foff, empty)
        # what the single-area path reads every plant step, once per scenario
        r0, r1 = rn[0, 0], rn[0, 1]
        noisy = r0 > 0.0 or r1 > 0.0
        met0, start0, due0 = met[0], start[0], due[0]
        kind, value, on, off = kinds0[LOAD], params0[LOAD, 0], params0[LOAD, 2], \
            params0[LOAD, 3]
        fol, fol0 = following[i], following[i, 0]
        follows = False
        for a in range(n_a):
            follows = follows or fol[a, 0] != 0.0
        for j in range(n_ctrl):
            k0 = j * ratio
            t = k0 * dt
            for a in range(n_a):     # every area's load now (the coupled filter reads all)
                pl[a] = signal_value(LOAD, kinds[i, a], params[i, a], offsets[i, a], st, sv, t, k0)
                if follows:
                    pl[a] += _following(fol[a], x[m * a + 3], t)
            if grid_wide(method0) and index[i, 0, 0] >= 0:   # what its estimator measures
                for a in range(n_a):
                    q_a = index[i, a, 1]
                    sensors = Channels(kinds[i, a], params[i, a], offsets[i, a], st, sv)
                    ym[2 * a] = sensor_reading(
                        DW_MEAS, x[m * a + 3] + (noise[q_a, j, 0] if q_a >= 0 else 0.0),
                        sensors, seen[a], t, j)[0]
                    ym[2 * a + 1] = sensor_reading(
                        ROCOF_MEAS, x[m * a + 4] + (noise[q_a, j, 1] if q_a >= 0 else 0.0),
                        sensors, seen[a], t, j)[0]
                    s = 0.0
                    for line in range(n_l):
                        s += inc[a, line] * x[m * n_a + line]
                    ym[2 * n_a + a] = s
            for a in range(n_a):
                e_i, q_i, f_i, ff = index[i, a, 0], index[i, a, 1], index[i, a, 2], \
                    index[i, a, 3]
                aw = index[i, a, 4] == 1
                if a == 0:
                    kinds_a, params_a, offsets_a = kinds0, params0, offsets0
                    ka_a, kb_a, kc_a, kg_a, method, fd = ka0, kb0, kc0, kg0, method0, fd0
                    x_a, ks_a, mem_a, gs_a, ctrl_a = x_0, ks_0, mem_0, gs_0, ctrl_0
                else:
                    kinds_a, params_a, offsets_a = kinds[i, a], params[i, a], offsets[i, a]
                    ka_a, kb_a, kc_a, kg_a, method, fd = scenario_tables(
                        e_i, f_i, ka, kb, kc, kg, kdim, methods, fdata, foff, empty)
                    x_a, ks_a, mem_a, gs_a = x[m * a:m * (a + 1)], kstate[a], mem[a], gstate[a]
                    ctrl_a = trace_ctrl[:, a, :]
                tie = 0.0
                for line in range(n_l):
                    tie += inc[a, line] * x[m * n_a + line]
                ace = signal_value(ACE, kinds_a, params_a, offsets_a, st, sv, t, j)
                ua, flags, mod = generator_period(
                    j, t, x_a, pl[a] + tie, (noise[q_i, j, 0] if q_i >= 0 else 0.0,
                                             noise[q_i, j, 1] if q_i >= 0 else 0.0),
                    tie + ace, Channels(kinds_a, params_a, offsets_a, st, sv),
                    Estimate(e_i, ka_a, kb_a, kc_a, kg_a, ks_a),
                    Controller(k_freq[a], k_tie[a], ff == 1, aw, method, fd),
                    Memory(mem_a, gs_a, x_hat, ctrl_a, seen[a]),
                    GridView(a, x, u, pl, ym, xe, ks_0, sums))
                u[a] = ua
                met[a, 4] += (flags & ACTIVE) != 0
                met[a, 5] += (flags & ALARM_BITS) != 0
                met[a, 8] += (flags & OUTSIDE) != 0
                met[a, 6] = max(met[a, 6], mod)
                met[a, 7] += mod
            if single:       # one area of five states: the state in registers
                ua = u[0]
                x0, x1, x2, x3, x4 = x[0], x[1], x[2], x[3], x[4]
                peak_dw, peak_rc = met[0, 2], met[0, 3]
                u0, u1, u2, u3, u4 = Bu[0, 0] * ua, Bu[1, 0] * ua, Bu[2, 0] * ua, \
                    Bu[3, 0] * ua, Bu[4, 0] * ua          # the command's terms, held
                for k in range(k0, min(k0 + ratio, n_steps)):
                    p0 = _load(kind, value, on, off, kinds0, params0, offsets0, st, sv, k * dt, k)
                    if follows:
                        p0 += _following(fol0, x3, k * dt)
                    n0 = A[0, 0] * x0 + A[0, 1] * x1 + A[0, 2] * x2 + A[0, 3] * x3 \
                        + A[0, 4] * x4 + u0 + Bl[0, 0] * p0
                    n1 = A[1, 0] * x0 + A[1, 1] * x1 + A[1, 2] * x2 + A[1, 3] * x3 \
                        + A[1, 4] * x4 + u1 + Bl[1, 0] * p0
                    n2 = A[2, 0] * x0 + A[2, 1] * x1 + A[2, 2] * x2 + A[2, 3] * x3 \
                        + A[2, 4] * x4 + u2 + Bl[2, 0] * p0
                    n3 = A[3, 0] * x0 + A[3, 1] * x1 + A[3, 2] * x2 + A[3, 3] * x3 \
                        + A[3, 4] * x4 + u3 + Bl[3, 0] * p0
                    n4 = A[4, 0] * x0 + A[4, 1] * x1 + A[4, 2] * x2 + A[4, 3] * x3 \
                        + A[4, 4] * x4 + u4 + Bl[4, 0] * p0
                    x0, x1, x2, x3, x4 = n0, n1, n2, n3, n4
                    trips, peak_dw, peak_rc = _watch(met0, (k + 1) * dt, x3, x4, noisy, r0, r1,
                                                     relays, start0, due0, peak_dw, peak_rc)
                    if traced:
                        trace_x[k + 1, 0], trace_x[k + 1, 1], trace_x[k + 1, 2] = x0, x1, x2
                        trace_x[k + 1, 3], trace_x[k + 1, 4] = x3, x4
                        trace_trips[k + 1, 0] = trips
                    if trips and stop_on_trip:
                        end, stopped = k + 1, True
                        break
                x[0], x[1], x[2], x[3], x[4] = x0, x1, x2, x3, x4
                met[0, 2], met[0, 3] = peak_dw, peak_rc
            else:
                for k in range(k0, min(k0 + ratio, n_steps)):
                    for a in range(n_a):
                        pa = params[i, a]
                        pl[a] = _load(kinds[i, a, LOAD], pa[LOAD, 0], pa[LOAD, 2], pa[LOAD, 3],
                                      kinds[i, a], pa, offsets[i, a], st, sv, k * dt, k)
                        if follows:
                            pl[a] += _following(fol[a], x[m * a + 3], k * dt)
                    for r in range(n_s):
                        s = 0.0
                        for c in range(n_s):
                            s += A[r, c] * x[c]
                        for a in range(n_a):
                            s += Bu[r, a] * u[a]
                        for a in range(n_a):
                            s += Bl[r, a] * pl[a]
                        xn[r] = s
                    for r in range(n_s):
                        x[r] = xn[r]
                        if traced:
                            trace_x[k + 1, r] = xn[r]
                    for a in range(n_a):
                        trips, met[a, 2], met[a, 3] = _watch(
                            met[a], (k + 1) * dt, x[m * a + 3], x[m * a + 4],
                            rn[a, 0] > 0.0 or rn[a, 1] > 0.0, rn[a, 0], rn[a, 1], relays,
                            start[a], due[a], met[a, 2], met[a, 3])
                        if traced:
                            trace_trips[k + 1, a] = trips
                        if trips and stop_on_trip:
                            stopped = True
                    if stopped:
                        end = k + 1
                        break
            if stopped:
                break
        for a in range(n_a):
            met[a, 9] = abs(x[m * a + 3])
        ends[i] = end


@inline
def _lowest_bit(bits: int) -> int:
    r = 0
    while not (bits >> r) & 1:
        r += 1
    return r


# -- the Python side: scenario tables, a run, the testbed's generator side ---------------
def check_noise(noise_std: tuple[float, float]) -> bool:
    """Raise unless ``noise_std`` is a pair (dw_meas, rocof_meas) of values 0 or
    in :data:`lfc.estimation.STD` (pu, pu/s); return whether there is any noise."""
    return any(s > 0 for s in check_noise_std("noise_std", noise_std))


def make_noise(noise_std: tuple[float, float], n: int, seed: int | tuple[int, ...]
               ) -> np.ndarray:
    """Seeded white noise for ``n`` controller readings of (dw_meas, rocof_meas):
    shape (n, 2), std ``noise_std`` (pu, pu/s), checked by :func:`check_noise`;
    ``seed`` an int or a tuple of ints (the area ``a > 0`` of a multi-area
    scenario uses ``(seed, a)``, area 0 ``seed``)."""
    check_noise(noise_std)
    return np.random.default_rng(list(seed) if isinstance(seed, tuple) else seed)\
        .standard_normal((n, 2)) * np.asarray(noise_std, float)


def make_estimator(estimator: object, params: LFCParams, control_period: float,
                   noise_std: tuple[float, float]) -> KalmanFilter | None:
    """None, a fresh Kalman filter for ``"kalman"`` (its measurement noise taken
    from ``noise_std`` where > 0), or the given one (its period checked)."""
    if estimator is None:
        return None
    if isinstance(estimator, str) and estimator == "kalman":
        return KalmanFilter(params, control_period, meas_std=measurement_std(noise_std))
    if isinstance(estimator, KalmanFilter):
        if not math.isclose(estimator.period, control_period):
            raise ValueError(f"estimator.period ({estimator.period}) must equal "
                             f"control_period ({control_period})")
        return estimator
    error = ValueError if isinstance(estimator, str) else ParameterTypeError
    raise error(f"estimator must be None, 'kalman' or a KalmanFilter, got {estimator!r:.80}")


def sample_signal(signal, t: np.ndarray, name: str) -> np.ndarray:
    """Evaluate an attack or load signal at times ``t`` (s); zeros for None.

    Raises ``ValueError`` naming ``name`` if it is not callable or returns
    non-finite values.
    """
    if signal is None:
        return np.zeros_like(t)
    if not callable(signal):
        raise ValueError(f"{name} must be a callable of time (see lfc.signals), got {signal!r}")
    raw = np.asarray(signal(t))
    if raw.dtype.kind not in "iuf":
        raise ParameterTypeError(f"{name} must return real numbers (pu), got dtype {raw.dtype}")
    try:
        values = np.broadcast_to(raw.astype(float), t.shape).copy()
    except ValueError:
        raise ValueError(f"{name} must return one value per time (shape {t.shape}), got shape "
                         f"{raw.shape}") from None
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{name} returned non-finite values")
    return values


_NO_SAMPLES = np.zeros(0)   # a scenario without sampled signals (empty: nothing to write)


def scenario_signals(pc_attack, wref_attack, load, tc: np.ndarray, t: np.ndarray,
                     ace_attack=None, dw_meas_attack=None, rocof_meas_attack=None) -> tuple:
    """One scenario's (or area's) signals as the engine reads them: ``(kinds (6,),
    params (6, 6), offsets (6, 2), sample times, sample values)``, channels
    ``PC, WREF, LOAD, ACE, DW_MEAS, ROCOF_MEAS``.  A :class:`~lfc.signals.Signal` is passed as its
    spec (a reading transform of :mod:`lfc.sensor_attacks` on a sensor's channel
    only, its lag in control samples); any other callable is sampled on its grid
    (control samples ``tc`` for the attacks, plant samples ``t`` for the load)."""
    kinds, params = np.zeros(N_CHANNELS, np.int64), np.zeros((N_CHANNELS, N_PARAMS))
    offsets, st, sv, n = np.zeros((N_CHANNELS, 2), np.int64), [], [], 0
    for c, (signal, name, grid) in enumerate(((pc_attack, "pc_attack", tc),
                                             (wref_attack, "wref_attack", tc),
                                             (load, "load", t),
                                             (ace_attack, "ace_attack", tc),
                                             (dw_meas_attack, "dw_meas_attack", tc),
                                             (rocof_meas_attack, "rocof_meas_attack", tc))):
        if signal is None:                                    # kind NONE: zero, no samples
            offsets[c, 0] = n
            continue
        if (isinstance(signal, Signal) and type(signal).spec is Signal.spec
                and type(signal).__call__ is Signal.__call__):
            raise ParameterTypeError(f"{name}: {type(signal).__name__} is a Signal without a "
                                     f"spec() for the engine, and not a callable of time; give "
                                     f"it one of the two")
        if isinstance(signal, Signal) and type(signal).spec is not Signal.spec:
            kinds[c], params[c], times, values = signal.spec()
            if kinds[c] >= SCALE:                             # lfc.sensor_attacks
                if c < DW_MEAS:
                    raise ValueError(f"{name}: a {type(signal).__name__} transforms what a "
                                     f"sensor reads; give it as dw_meas_attack or "
                                     f"rocof_meas_attack")
                params[c, 5] = lag_samples(kinds[c], params[c, 5],
                                           tc[1] - tc[0] if len(tc) > 1 else math.inf)
            if kinds[c] != SAMPLES:                           # a closed form: no samples
                offsets[c, 0] = n
                continue
        else:
            values = sample_signal(signal, grid, name)
            kinds[c], times = GRID, np.zeros(len(values))
        offsets[c] = (n, len(times))
        st.append(np.asarray(times, float))
        sv.append(np.asarray(values, float))
        n += len(times)
    if not st:
        return kinds, params, offsets, _NO_SAMPLES, _NO_SAMPLES
    return kinds, params, offsets, np.concatenate(st), np.concatenate(sv)


#: what the generator side's frequency and ROCOF sensors read (an attack adds to it)
SENSOR_CHANNELS = ("dw_meas", "rocof_meas")
#: what an attacker may corrupt in an area: the command, the frequency reference, the ACE,
#: and what the sensors read
CHANNELS = ("pc", "wref", "ace", *SENSOR_CHANNELS)


def check_area_keys(mapping: dict | None, n_areas: int, name: str) -> dict:
    """``mapping`` (None: empty) with every key an area index in ``[0, n_areas)``."""
    mapping = {} if mapping is None else mapping
    if not isinstance(mapping, dict):
        raise ValueError(f"{name} must be a dict {{area: ...}}, got {mapping!r}")
    for key in mapping:
        check_index(f"a key of {name} (an area)", key, n_areas)
    return mapping


def check_attacks(attacks: dict | None, n_areas: int) -> dict:
    """``attacks`` (None: empty) as :func:`check_area_keys` checks it, each value
    a dict whose keys are among ``CHANNELS``."""
    attacks = check_area_keys(attacks, n_areas, "attacks")
    for a, channels in attacks.items():
        if not isinstance(channels, dict) or set(channels) - set(CHANNELS):
            error = ValueError if isinstance(channels, dict) else ParameterTypeError
            raise error(f"attacks[{a}] must be a dict with keys among {CHANNELS}, "
                             f"got {channels!r}")
    return attacks


def check_load_measured(filters: dict, estimator, feedforward: bool) -> None:
    """``ValueError`` if a filter whose hold is proven period by period
    (``recheck_bound`` > 0: :mod:`lfc.filters.certified`, :mod:`lfc.filters.coupled`)
    is given neither the load (``feedforward``, :func:`lfc.simulate`'s
    ``load_feedforward``) nor an estimate of it (an estimator): its re-check would
    take the load for 0 whatever it did, and the period-by-period guarantee assumes
    the load it is given is the load.  A coupled filter always reads every area's
    load (the grid's)."""
    if feedforward or estimator is not None:
        return
    for a, scc in filters.items():
        if is_grid_wide(scc):
            continue
        bound = getattr(getattr(scc, "options", None), "recheck_bound", 0.0)
        if bound > 0:
            where = "" if a is None else f" of area {a}"
            raise ValueError(f"the filter{where} has recheck_bound={bound:g} pu, whose "
                             f"period-by-period hold needs the load measured: give "
                             f"load_feedforward=True (feedforward=True for a grid), an "
                             f"estimator, or build the filter with recheck_bound=0")
