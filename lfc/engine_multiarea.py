"""The closed loop of an interconnected grid, compiled: every area's generator
side, the coupled plant and every area's relays.

The same pieces as :mod:`lfc.engine`, per area: every control period each area
runs :func:`lfc.engine.generator_period` (its noise, Kalman estimate, filter and
AGC on its ACE, the net disturbance ``dP_L + dP_tie`` as the load it may be
given); every plant step the coupled plant (:mod:`lfc.multiarea`) advances
exactly and each area's OF2, UF2 and ROCOF relays see its measured signals.
N scenarios run one after another, each with its own signals, noise,
estimators and filters per area.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lfc._jit import kernel
from lfc.engine import (ACE, LOAD, METRICS, N_CTRL, N_KF, _kalman_tables,
                        _lowest_bit, _signal, _Table, check_noise, generator_period,
                        filter_tables, make_estimator, make_noise, scenario_signals,
                        scenario_tables, signal_tables)
from lfc.filters import SafetyFilter
from lfc.filters.base import ACTIVE, ALARM_BITS, MEMORY, OUTSIDE
from lfc.multiarea import N_AREA_STATES, MultiAreaParams, discretize_multiarea
from lfc.relays import RelaySettings, relay_sample

CHANNELS = ("pc", "wref", "ace")   # what an attacker may corrupt in an area


@kernel
def _run_multi(n_steps: int, ratio: int, dt: float, ad: np.ndarray, bu: np.ndarray,
               bl: np.ndarray, inc: np.ndarray, k_freq: np.ndarray, k_tie: np.ndarray,
               index: np.ndarray, kinds: np.ndarray, params: np.ndarray, offsets: np.ndarray,
               st: np.ndarray, sv: np.ndarray, noise: np.ndarray, ka: np.ndarray,
               kb: np.ndarray, kc: np.ndarray, kg: np.ndarray, kdim: np.ndarray,
               methods: np.ndarray, fdata: np.ndarray, foff: np.ndarray, limits: np.ndarray,
               delays: np.ndarray, stop_on_trip: bool, metrics: np.ndarray,
               trace_x: np.ndarray, trace_ctrl: np.ndarray, trace_trips: np.ndarray,
               ends: np.ndarray, x: np.ndarray, xn: np.ndarray, u: np.ndarray,
               pl: np.ndarray, x_hat: np.ndarray, mem: np.ndarray, gstate: np.ndarray,
               kstate: np.ndarray, start: np.ndarray, due: np.ndarray) -> None:
    """Advance every scenario from equilibrium for ``n_steps`` plant steps.

    ``index`` (N, n_areas, 4): each area's Kalman filter (-1: none), noise row
    (-1: none), filter (-1: none) and disturbance feed-forward (0/1).
    ``k_freq``, ``k_tie`` are the AGC gains times the control period.  Writes
    ``metrics`` (N, n_areas, len(METRICS)); with trace rows (N = 1) every state,
    control sample (n_ctrl, n_areas, N_CTRL) and trip (samples, n_areas).
    The arrays after ``ends`` are scratch space: the kernel allocates nothing.
    """
    n_ctrl = -(-n_steps // ratio)
    n_a, n_s, n_l = inc.shape[0], ad.shape[0], inc.shape[1]
    m = N_AREA_STATES
    empty = x_hat[:0]
    for i in range(index.shape[0]):
        x[:], mem[:], gstate[:], kstate[:], due[:] = 0.0, 0.0, 0.0, 0.0, 0.0
        start[:] = np.nan
        met = metrics[i]
        met[:] = 0.0
        met[:, 0], met[:, 1] = np.nan, -1.0
        end, stopped = n_steps, False
        for a in range(n_a):
            trips = relay_sample(0.0, 0.0, 0.0, limits, delays, start[a], due[a])
            if trace_x.shape[0]:
                trace_trips[0, a] = trips
        for j in range(n_ctrl):
            k0 = j * ratio
            t = k0 * dt
            for a in range(n_a):
                e_i, q_i, f_i, ff = index[i, a, 0], index[i, a, 1], index[i, a, 2], \
                    index[i, a, 3]
                kinds_a, params_a, offsets_a = kinds[i, a], params[i, a], offsets[i, a]
                ka_a, kb_a, kc_a, kg_a, method, fd = scenario_tables(
                    e_i, f_i, ka, kb, kc, kg, kdim, methods, fdata, foff, empty)
                tie = 0.0
                for line in range(n_l):
                    tie += inc[a, line] * x[m * n_a + line]
                load = _signal(LOAD, kinds_a, params_a, offsets_a, st, sv, t, k0)
                ace = _signal(ACE, kinds_a, params_a, offsets_a, st, sv, t, j)
                ua, flags, mod = generator_period(
                    j, t, x[m * a:m * (a + 1)], load + tie,
                    noise[q_i, j, 0] if q_i >= 0 else 0.0,
                    noise[q_i, j, 1] if q_i >= 0 else 0.0, kinds_a, params_a, offsets_a, st,
                    sv, k_freq[a], e_i, ka_a, kb_a, kc_a, kg_a, kstate[a], ff == 1, method, fd,
                    mem[a], gstate[a], x_hat, trace_ctrl[:, a, :], tie + ace, k_tie[a])
                u[a] = ua
                met[a, 4] += (flags & ACTIVE) != 0
                met[a, 5] += (flags & ALARM_BITS) != 0
                met[a, 8] += (flags & OUTSIDE) != 0
                met[a, 6] = max(met[a, 6], mod)
                met[a, 7] += mod
            for k in range(k0, min(k0 + ratio, n_steps)):
                for a in range(n_a):
                    pl[a] = _signal(LOAD, kinds[i, a], params[i, a], offsets[i, a], st, sv,
                                    k * dt, k)
                for r in range(n_s):
                    s = 0.0
                    for c in range(n_s):
                        s += ad[r, c] * x[c]
                    for a in range(n_a):          # the single-area engine's order of sums
                        s += bu[r, a] * u[a]
                    for a in range(n_a):
                        s += bl[r, a] * pl[a]
                    xn[r] = s
                for r in range(n_s):
                    x[r] = xn[r]
                    if trace_x.shape[0]:
                        trace_x[k + 1, r] = xn[r]
                for a in range(n_a):
                    dw, rc = x[m * a + 3], x[m * a + 4]
                    trips = relay_sample((k + 1) * dt, dw, rc, limits, delays, start[a], due[a])
                    if trace_x.shape[0]:
                        trace_trips[k + 1, a] = trips
                    met[a, 2] = max(met[a, 2], abs(dw))
                    met[a, 3] = max(met[a, 3], abs(rc))
                    if trips and math.isnan(met[a, 0]):
                        met[a, 0], met[a, 1] = (k + 1) * dt, float(_lowest_bit(trips))
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


@dataclass
class MultiRun:
    """What :meth:`MultiAreaScenarios.run` returns: ``metrics`` (N, n_areas,
    len(METRICS)), ``ends`` (N,) and, for a traced run, ``x`` (samples,
    n_states), ``ctrl`` (periods, n_areas, N_CTRL) and ``trips`` (samples, n_areas)."""

    metrics: np.ndarray
    ends: np.ndarray
    x: np.ndarray
    ctrl: np.ndarray
    trips: np.ndarray


def check_area_keys(mapping: dict | None, n_areas: int, name: str) -> dict:
    """``mapping`` (None: empty) with every key an area index in ``[0, n_areas)``."""
    mapping = {} if mapping is None else mapping
    if not isinstance(mapping, dict):
        raise ValueError(f"{name} must be a dict {{area: ...}}, got {mapping!r}")
    for key in mapping:
        if not (isinstance(key, (int, np.integer)) and 0 <= key < n_areas):
            raise ValueError(f"{name} has key {key!r}; areas are 0 to {n_areas - 1}")
    return mapping


def check_attacks(attacks: dict | None, n_areas: int) -> dict:
    """``attacks`` (None: empty) as :func:`check_area_keys` checks it, each value
    a dict whose keys are among ``CHANNELS``."""
    attacks = check_area_keys(attacks, n_areas, "attacks")
    for a, channels in attacks.items():
        if not isinstance(channels, dict) or set(channels) - set(CHANNELS):
            raise ValueError(f"attacks[{a}] must be a dict with keys among {CHANNELS}, "
                             f"got {channels!r}")
    return attacks


class MultiAreaScenarios:
    """Scenarios of one interconnected grid: add them one by one, then :meth:`run`.

    Parameters
    ----------
    params : MultiAreaParams
    duration, dt, control_period : float
        Simulated time, plant step and controller period (s); checked by the caller.
    relays : RelaySettings
        The same settings in every area.
    """

    def __init__(self, params: MultiAreaParams, *, duration: float, dt: float,
                 control_period: float, relays: RelaySettings) -> None:
        self.params, self.dt, self.relays = params, float(dt), relays
        self.ratio = int(round(control_period / dt))
        self.n_steps = int(round(duration / dt))
        self.n_ctrl = -(-self.n_steps // self.ratio)
        self.period = self.ratio * self.dt
        self.t = np.arange(self.n_steps + 1) * self.dt
        self.tc = np.arange(self.n_ctrl) * self.period
        self._kf, self._filters = _Table(), _Table()
        self._rows: list[list[tuple]] = []
        self._noise: list[np.ndarray] = []
        self._sig: list[tuple] = []
        self._st: list[np.ndarray] = []
        self._sv: list[np.ndarray] = []
        self._n_samples = 0

    def add(self, *, attacks: dict | None = None, loads: dict | None = None,
            filters: dict | None = None, estimator=None,
            noise_std: tuple[float, float] = (0.0, 0.0), seed: int = 0,
            feedforward: bool = True) -> int:
        """One scenario (arguments as in :func:`lfc.simulate_multiarea`, filters
        already built).  Returns its row number."""
        n = self.params.n_areas
        attacks = check_attacks(attacks, n)
        loads = check_area_keys(loads, n, "loads")
        filters = check_area_keys(filters, n, "filters")
        noisy = check_noise(noise_std)
        row = []
        for a, area in enumerate(self.params.areas):
            channels = attacks.get(a, {})
            scc = filters.get(a)
            if scc is not None and not isinstance(scc, SafetyFilter):
                raise ValueError(f"filters[{a}] must be a SafetyFilter or None, got {scc!r}")
            kf = make_estimator(estimator, area, self.period, noise_std)
            e_i = -1 if kf is None else self._kf.index(
                id(kf) if not isinstance(estimator, str) else (a, tuple(noise_std)), lambda: kf)
            if noisy:
                own = seed if a == 0 else (seed, a)
                self._noise.append(make_noise(noise_std, self.n_ctrl, own))
            f_i = -1 if scc is None else self._filters.index(id(scc), lambda: scc)
            kinds, params, offsets, st, sv = scenario_signals(
                channels.get("pc"), channels.get("wref"), loads.get(a), self.tc, self.t,
                channels.get("ace"))
            self._sig.append((kinds, params, offsets + np.array([self._n_samples, 0])))
            self._st.append(st)
            self._sv.append(sv)
            self._n_samples += len(st)
            row.append((e_i, len(self._noise) - 1 if noisy else -1, f_i, int(feedforward)))
        self._rows.append(row)
        return len(self._rows) - 1

    def run(self, *, trace: bool = False, stop_on_trip: bool = False) -> MultiRun:
        """Run every scenario added; ``trace`` keeps everything (one scenario only)."""
        p, n = self.params, len(self._rows)
        n_a = p.n_areas
        kinds, params, offsets, st, sv = signal_tables(self._sig, self._st, self._sv, (n, n_a))
        ad, bu, bl = discretize_multiarea(p, self.dt)
        k_freq, k_tie = p.agc_gains()
        ka, kb, kc, kg, kdim = _kalman_tables(self._kf.items)
        methods, fdata, foff = filter_tables(self._filters.items)
        noise = np.array(self._noise) if self._noise else np.zeros((1, self.n_ctrl, 2))
        limits, delays = self.relays.arrays()
        metrics = np.zeros((n, n_a, len(METRICS)))
        ends = np.zeros(n, np.int64)
        rows = (self.n_steps + 1) if trace else 0
        tx, tt = np.zeros((rows, p.n_states)), np.zeros((rows, n_a), np.int64)
        tc = np.full((self.n_ctrl if trace else 0, n_a, N_CTRL), np.nan)
        _run_multi(self.n_steps, self.ratio, self.dt, ad, bu, bl, p.incidence(),
                   k_freq * self.period, k_tie * self.period,
                   np.array(self._rows, np.int64).reshape(n, n_a, 4), kinds, params, offsets,
                   st, sv, noise, ka, kb, kc, kg, kdim, methods, fdata, foff, limits, delays,
                   stop_on_trip, metrics, tx, tc, tt, ends, np.zeros(p.n_states),
                   np.zeros(p.n_states), np.zeros(n_a), np.zeros(n_a), np.zeros(5),
                   np.zeros((n_a, MEMORY)), np.zeros((n_a, 1)), np.zeros((n_a, 2, N_KF)),
                   np.zeros((n_a, 3)), np.zeros((n_a, 3)))
        return MultiRun(metrics, ends, tx, tc, tt)
