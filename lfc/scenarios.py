"""A batch of scenarios of one grid, as the engine's tables: :class:`Scenarios`.

Add scenarios one by one (each checked as it is added: its plant, attacks, loads,
filters, estimator, noise and flags), then :meth:`Scenarios.run` packs them into
the kernel's named tables (:mod:`lfc.engine`: :class:`~lfc.engine.Plants`,
:class:`~lfc.engine.Rows`, ...) and runs them — the lanes (:mod:`lfc.lanes`) where
they allow it, the reference kernel (:func:`lfc.engine.run_kernel`) for the rest.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lfc._validate import ParameterTypeError, check_flag, check_seed
from lfc.engine import (LOAD, METRICS, N_CHANNELS, N_CTRL, N_KF, Estimators, FilterTables,
                        Outputs, Plants, RelayTables, Rows, Samples, Timing, Work,
                        check_area_keys, check_attacks, check_coupled, check_load_measured,
                        check_noise, make_estimator, make_noise, run_kernel, scenario_signals)
from lfc.filters import SafetyFilter
from lfc.filters.coupled import CoupledFilter
from lfc.filters.dispatch import GRID_WIDE, scratch_size
from lfc.lanes import LANE_MIN_FILL, LaneWork, lane_blocks, run_lanes
from lfc.model import LFCParams
from lfc.multiarea import N_AREA_STATES, MultiAreaParams, as_grid, discretize_grid
from lfc.relays import RelaySettings
from lfc.signals import N_PARAMS, NONE, STEP


class _Table:
    """Distinct items (plants, filters, ...) and each scenario's index into them."""

    def __init__(self) -> None:
        self.items: list = []
        self._keys: dict = {}

    def index(self, key, make) -> int:
        """The number of the item ``key`` names, made by ``make()`` the first time
        (if ``make`` raises, nothing is kept)."""
        if key not in self._keys:
            item = make()
            self._keys[key] = len(self.items)
            self.items.append(item)
        return self._keys[key]


@dataclass
class Run:
    """What :meth:`Scenarios.run` returns: per-scenario and area ``metrics`` (N,
    n_areas, len(METRICS)) and ``ends`` (N,: last plant sample kept), and for a
    traced run (N = 1) every state ``x`` (samples, n_states), control sample
    ``ctrl`` (periods, n_areas, N_CTRL) and relay trip bits ``trips`` (samples,
    n_areas)."""

    metrics: np.ndarray
    ends: np.ndarray
    x: np.ndarray
    ctrl: np.ndarray
    trips: np.ndarray



class Scenarios:
    """Scenarios of one grid for the engine: add them one by one, then :meth:`run`.

    Parameters
    ----------
    design : LFCParams or MultiAreaParams
        The design model: a single area (a grid of one area, no tie-line) or an
        interconnected grid.  It gives the AGC (for one area: the local integral
        controller, gain ``k_i``), the model of each area's ``"kalman"``
        estimator (filters carry their own) and the plant of scenarios added
        without one.
    duration, dt, control_period : float
        Simulated time, plant step and controller period (s); checked by the caller.
    relays : RelaySettings
        The same settings in every area.
    """

    def __init__(self, design: LFCParams | MultiAreaParams, *, duration: float, dt: float,
                 control_period: float, relays: RelaySettings) -> None:
        if not isinstance(relays, RelaySettings):
            raise ParameterTypeError(f"relays must be a RelaySettings, got {relays!r}")
        self.design, self.dt, self.relays = design, float(dt), relays
        self.grid = as_grid(design)
        self.ratio = int(round(control_period / dt))
        self.n_steps = int(round(duration / dt))
        self.n_ctrl = -(-self.n_steps // self.ratio)
        self.period = self.ratio * self.dt
        self.t = np.arange(self.n_steps + 1) * self.dt
        self.tc = np.arange(self.n_ctrl) * self.period
        self._plants, self._kf, self._filters = _Table(), _Table(), _Table()
        self._plant_of: list[int] = []
        self._rows: list[list[tuple]] = []
        self._noise: list[np.ndarray] = []
        self._relay_noise: list[list[tuple]] = []
        self._sig: list[tuple] = []
        self._st: list[np.ndarray] = []
        self._sv: list[np.ndarray] = []
        self._n_samples = 0

    def add(self, *, plant: LFCParams | MultiAreaParams | None = None,
            attacks: dict | None = None, loads: dict | None = None,
            filters: dict | None = None, estimator=None,
            noise_std: tuple[float, float] = (0.0, 0.0), seed: int = 0,
            feedforward: bool = False, relay_noise: bool = False,
            anti_windup: bool = False) -> int:
        """One scenario; returns its row number.

        ``attacks`` (``{area: {"pc" | "wref" | "ace": signal}}``), ``loads``
        (``{area: signal}``), ``filters`` (``{area: SafetyFilter}``, built),
        ``estimator``, ``noise_std``, ``seed`` (area ``a > 0`` draws from ``(seed,
        a)``), ``feedforward`` (the filter is given the area's net disturbance),
        ``anti_windup`` (:func:`~lfc.engine.generator_period`) and ``relay_noise`` as in
        :func:`lfc.simulate` (a grid) and
        :func:`lfc.simulate`; ``plant`` (default the design model) is the grid
        the scenario runs on, with the design's areas and tie-lines.
        """
        grid = self.grid
        n = grid.n_areas
        plant = grid if plant is None else as_grid(plant)
        if plant.n_areas != n or len(plant.tie) != len(grid.tie):
            raise ValueError(f"plant must have the design's {n} area(s) and {len(grid.tie)} "
                             f"tie-line(s), got {plant!r}")
        p_i = self._plants.index(plant, lambda: discretize_grid(plant, self.dt))
        attacks = check_attacks(attacks, n)
        loads = check_area_keys(loads, n, "loads")
        filters = check_area_keys(filters, n, "filters")
        noisy = check_noise(noise_std)
        seed = check_seed("seed", seed)
        feedforward = check_flag("feedforward", feedforward)
        anti_windup = check_flag("anti_windup", anti_windup)
        relay_noise = check_flag("relay_noise", relay_noise)
        if relay_noise and not noisy:
            raise ValueError("relay_noise=True needs noise_std > 0 (the relays' measurement "
                             "noise)")
        check_coupled(filters, grid, estimator, noise_std)
        check_load_measured(filters, estimator, feedforward)
        f_is = [-1 if filters.get(a) is None else self._filters.index(
            id(filters[a]), lambda: self._checked(a, filters[a])) for a in range(n)]
        row, noise, sig, n_samples = [], [], [], self._n_samples   # kept once all areas pass
        for a, area in enumerate(grid.areas):
            channels = attacks.get(a, {})
            scc = filters.get(a)
            if isinstance(scc, CoupledFilter):
                kf = scc.kalman
                e_i = -1 if kf is None else self._kf.index(id(kf), lambda: kf)
            elif isinstance(estimator, str) and estimator == "kalman":   # one per area and noise
                e_i = self._kf.index((a, tuple(noise_std)), lambda: make_estimator(
                    estimator, area, self.period, noise_std))   # its gain takes milliseconds
            else:
                kf = make_estimator(estimator, area, self.period, noise_std)
                e_i = -1 if kf is None else self._kf.index(id(kf), lambda: kf)
            if noisy:
                noise.append(make_noise(noise_std, self.n_ctrl, seed if a == 0 else (seed, a)))
            kinds, params, offsets, st, sv = scenario_signals(
                channels.get("pc"), channels.get("wref"), loads.get(a), self.tc, self.t,
                channels.get("ace"))
            offsets[:, 0] += n_samples                # into this run's sample arrays
            sig.append(((kinds, params, offsets), st, sv))
            n_samples += len(st)
            row.append((e_i, len(self._noise) + len(noise) - 1 if noisy else -1, f_is[a],
                        int(feedforward), int(anti_windup)))
        self._noise += noise
        for area_sig, st, sv in sig:
            self._sig.append(area_sig)
            self._st.append(st)
            self._sv.append(sv)
        self._n_samples = n_samples
        self._rows.append(row)
        self._plant_of.append(p_i)
        self._relay_noise.append([(*(noise_std if relay_noise else (0.0, 0.0)), seed)] * n)
        return len(self._rows) - 1

    def _checked(self, a: int, scc) -> SafetyFilter | CoupledFilter:
        """``scc``, the filter of area ``a``, once checked: its type, its relays
        (the simulation's) and its control period (once per distinct filter)."""
        if not isinstance(scc, (SafetyFilter, CoupledFilter)):
            raise ValueError(f"filters[{a}] must be a SafetyFilter, a CoupledFilter or "
                             f"None, got {scc!r}")
        if not np.array_equal(scc.relays.arrays()[0], self.relays.arrays()[0]):
            raise ValueError(f"the filter of area {a} keeps the safe set of {scc.relays} "
                             f"but the simulation's relays are {self.relays}: a trip "
                             f"would go unflagged; build it with the same thresholds")
        scc.check_period(self.period)
        return scc

    def run(self, *, trace: bool = False, stop_on_trip: bool = False,
            lanes: bool = True) -> Run:
        """Run every scenario added; ``trace`` keeps everything (one scenario only).

        With ``lanes`` (untraced single-area runs), the scenarios that allow it
        (no relay noise, a step load or none, not the coupled filter) run
        ``LANES`` at a time in SIMD registers (:func:`lfc.lanes.run_lanes`), a block per
        plant, the others one at a time (:func:`lfc.engine.run_kernel`, the reference), as do a
        plant's last few (fewer than ``LANE_MIN_FILL`` in its last block: a
        block pays for all its lanes); the metrics are the same bit for bit
        either way.

        Raises ``ValueError`` naming the scenarios whose state became non-finite
        (a signal that is finite as specified but not where it is evaluated);
        their metrics would otherwise read as a quiet run."""
        stop_on_trip = check_flag("stop_on_trip", stop_on_trip)
        grid, n = self.grid, len(self._rows)
        n_a, n_s = grid.n_areas, grid.n_states
        kinds, params, offsets, st, sv = signal_tables(self._sig, self._st, self._sv, (n, n_a))
        items = self._plants.items
        k_freq, k_tie = grid.agc_gains()
        plants = Plants(np.array([p[0] for p in items]), np.array([p[1] for p in items]),
                        np.array([p[2] for p in items]), grid.incidence(),
                        k_freq * self.period, k_tie * self.period)
        rows = Rows(np.array(self._plant_of, np.int64),
                    np.array(self._rows, np.int64).reshape(n, n_a, 5), kinds, params, offsets,
                    np.array(self._relay_noise, float).reshape(n, n_a, 3))
        samples = Samples(st, sv, np.array(self._noise) if self._noise
                          else np.zeros((1, self.n_ctrl, 2)))
        estimators = kalman_tables(self._kf.items)
        filters = filter_tables(self._filters.items)
        relays = RelayTables(*self.relays.arrays())
        timing = Timing(self.n_steps, self.ratio, self.dt, stop_on_trip)
        n_trace = (self.n_steps + 1) if trace else 0
        out = Outputs(np.zeros((n, n_a, len(METRICS))), np.zeros(n, np.int64),
                      np.zeros((n_trace, n_s)),
                      np.full((self.n_ctrl if trace else 0, n_a, N_CTRL), np.nan),
                      np.zeros((n_trace, n_a), np.int64))
        rest = np.arange(n)
        if lanes and not trace and n_a == 1 and n_s == N_AREA_STATES:
            f_i = rows.index[:, 0, 2]
            fit = ((rows.relay_noise[:, 0, 0] == 0.0) & (rows.relay_noise[:, 0, 1] == 0.0)
                   & np.isin(kinds[:, 0, LOAD], (STEP, NONE))
                   & ((f_i < 0) | ~np.isin(filters.methods[np.maximum(f_i, 0)], GRID_WIDE)))
            blocks, left = lane_blocks(rows.plant_of, np.flatnonzero(fit), LANE_MIN_FILL)
            run_lanes(timing, plants, rows, samples, estimators, filters, relays, out, blocks,
                      LaneWork.sized(estimators.a.shape[1]))
            rest = np.sort(np.concatenate([np.flatnonzero(~fit), left]))
        if len(rest):
            rest = slice(None) if len(rest) == n else rest   # all of them: views, no copies
            mine = Rows(*(column[rest] for column in rows))
            part = Outputs(out.metrics[rest], out.ends[rest], *out[2:])
            n_sums = max((scratch_size(f) for f in self._filters.items), default=0)
            run_kernel(timing, plants, mine, samples, estimators, filters, relays, part,
                       Work.sized(n_s, n_a, estimators.a.shape[1], n_sums))
            out.metrics[rest], out.ends[rest] = part.metrics, part.ends
        metrics, ends = out.metrics, out.ends
        final = metrics[:, :, METRICS.index("final_abs_dw_meas")]
        bad = np.flatnonzero(~np.all(np.isfinite(final), axis=1))
        if len(bad):
            raise ValueError(f"scenario(s) {bad[:5].tolist()} became non-finite: an attack or "
                             f"load signal (pc_attack, wref_attack, load) gives a non-finite "
                             f"value where it is evaluated (e.g. Samples times closer than a "
                             f"float resolves, or a frequency so high its phase overflows), "
                             f"or the plant itself diverges (gains such as k_agc or the bias "
                             f"so far apart that the discretized loop is unstable)")
        return Run(metrics, ends, out.x, out.ctrl, out.trips)



def signal_tables(sig: list[tuple], st: list[np.ndarray], sv: list[np.ndarray],
                  shape: tuple[int, ...]) -> tuple:
    """The signals of :func:`scenario_signals`, one per generator side, as the
    engine's arrays ``(kinds, params, offsets, sample times, sample values)``,
    the first three shaped ``shape + (N_CHANNELS, ...)``."""
    kinds = np.array([s[0] for s in sig], np.int64).reshape(*shape, N_CHANNELS)
    params = np.array([s[1] for s in sig]).reshape(*shape, N_CHANNELS, N_PARAMS)
    offsets = np.array([s[2] for s in sig], np.int64).reshape(*shape, N_CHANNELS, 2)
    return (kinds, params, offsets, np.concatenate(st) if st else np.zeros(0),
            np.concatenate(sv) if sv else np.zeros(0))


def filter_tables(filters: list[SafetyFilter]) -> FilterTables:
    """The filters' method ids, their data one after another and each one's
    offset into it, as :func:`lfc.engine.scenario_tables` reads them."""
    methods = np.array([f.method_id for f in filters] or [0], np.int64)
    data = [f.data for f in filters]
    foff = np.concatenate([[0], np.cumsum([len(d) for d in data])]).astype(np.int64)
    return FilterTables(methods, np.concatenate(data) if data else np.zeros(0), foff)


def kalman_tables(filters: list) -> Estimators:
    """The Kalman filters' matrices (each area's :class:`KalmanFilter`, or a
    coupled filter's :class:`~lfc.filters.coupled_set.GridKalman`), padded to the
    largest (``dims[i]``: states, measurements, inputs)."""
    m = max(len(filters), 1)
    n, n_y, n_u = (max([getattr(kf, d) for kf in filters], default=1)
                   for d in ("n", "n_y", "n_u"))
    n = max(n, N_KF)
    ka, kb = np.zeros((m, n, n)), np.zeros((m, n, n_u))
    kc, kg = np.zeros((m, n_y, n)), np.zeros((m, n, n_y))
    kdim = np.zeros((m, 3), np.int64)
    for i, kf in enumerate(filters):
        a, y, b = kf.n, kf.n_y, kf.n_u
        ka[i, :a, :a], kb[i, :a, :b], kc[i, :y, :a], kg[i, :a, :y] = kf.A, kf.B, kf.C, kf.gain
        kdim[i] = a, y, b
    return Estimators(ka, kb, kc, kg, kdim)


