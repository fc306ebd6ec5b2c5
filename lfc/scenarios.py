"""A batch of scenarios of one grid, as the engine's tables: :class:`Scenarios`.

Add scenarios one by one (each checked as it is added: its plant, attacks, loads,
filters, estimator, noise and flags), then :meth:`Scenarios.run` packs them into
the kernel's named tables (:mod:`lfc.engine`: :class:`~lfc.engine.Plants`,
:class:`~lfc.engine.Rows`, ...) and runs them — the lanes (:mod:`lfc.lanes`) where
they allow it, the reference kernel (:func:`lfc.engine.run_kernel`) for the rest.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from numbers import Integral

import numpy as np

from lfc._validate import ParameterTypeError, check_flag, check_seed
from lfc.engine import (CHANNELS, DW_MEAS, LOAD, METRICS, N_CHANNELS, N_CTRL, N_KF,
                        ROCOF_MEAS, SENSOR_CHANNELS, Estimators, FilterTables, Outputs,
                        Plants, RelayTables, Rows, SignalSamples, Timing, Work,
                        check_area_keys, check_load_measured, check_noise, make_estimator,
                        make_noise, run_kernel, scenario_signals)
from lfc.sensor_attacks import FREEZE, REPLAY
from lfc.filters import SafetyFilter
from lfc.filters.coupled import CoupledFilter, check_coupled
from lfc.filters.dispatch import grid_wide_methods, scratch_size
from lfc.lanes import LANE_MIN_FILL, LaneWork, lane_blocks, run_lanes
from lfc.load_attacks import NO_FOLLOWING, FollowingLoad
from lfc.model import LFCParams
from lfc.multiarea import N_AREA_STATES, MultiAreaParams, as_grid, discretize_grid
from lfc.relays import RelaySettings
from lfc.sensors import Redundant, with_sensors
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
        self._following: list[list[tuple]] = []
        #: each scenario's alarm-log rows of its areas' redundant sensors, {area: rows}
        self.sensor_alarms: list[dict] = []
        self._sig: list[tuple] = []
        self._st: list[np.ndarray] = []
        self._sv: list[np.ndarray] = []
        self._n_samples = 0

    def add(self, scenario: Scenario | None = None, **keywords) -> int:
        """One scenario, a :class:`Scenario` or its fields as keywords; returns its row
        number.  Area ``a > 0`` draws its noise from ``(seed, a)``; the scenario's
        ``plant`` (default the design model) must have the design's areas and
        tie-lines.  ``ValueError`` naming what is wrong, before anything is kept."""
        grid = self.grid
        n = grid.n_areas
        if scenario is None:            # the areas' range first, then the rest, once
            fields = keywords
        elif keywords:
            raise ValueError(f"give a Scenario or its fields, not both (got {sorted(keywords)})")
        elif not isinstance(scenario, Scenario):
            raise ParameterTypeError(f"scenario must be a Scenario, got "
                                     f"{type(scenario).__name__}")
        else:
            fields = vars(scenario)
        check_area_keys(fields.get("attacks"), n, "attacks")   # the rest: Scenario's own
        check_area_keys(fields.get("loads"), n, "loads")
        check_area_keys(fields.get("filters"), n, "filters")
        check_area_keys(fields.get("following_loads"), n, "following_loads")
        check_area_keys(fields.get("sensors"), n, "sensors")
        scenario = Scenario(**keywords) if scenario is None else scenario
        attacks, loads, filters = scenario.attacks, scenario.loads, scenario.filters
        estimator, noise_std, seed = scenario.estimator, scenario.noise_std, scenario.seed
        feedforward, anti_windup = bool(scenario.feedforward), scenario.anti_windup
        relay_noise, noisy = scenario.relay_noise, any(s > 0 for s in scenario.noise_std)
        plant = grid if scenario.plant is None else as_grid(scenario.plant)
        if plant.n_areas != n or len(plant.tie) != len(grid.tie):
            raise ValueError(f"plant must have the design's {n} area(s) and {len(grid.tie)} "
                             f"tie-line(s), got {plant!r}")
        attacks, logs = with_sensors(scenario.sensors, attacks, self.tc, seed)
        check_coupled(filters, grid, estimator, noise_std)
        check_sensed(attacks, filters, estimator)     # the redundant sensors' median too
        check_load_measured(filters, estimator, feedforward)
        p_i = self._plants.index(plant, lambda: discretize_grid(plant, self.dt))
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
                channels.get("ace"), channels.get("dw_meas"), channels.get("rocof_meas"))
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
        self.sensor_alarms.append(logs)
        self._relay_noise.append([(*(noise_std if relay_noise else (0.0, 0.0)), seed)] * n)
        self._following.append([scenario.following_loads[a].row()
                                if a in scenario.following_loads else NO_FOLLOWING
                                for a in range(n)])
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
        (no relay noise, a step load or none, no following load, not the coupled
        filter) run
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
                    np.array(self._relay_noise, float).reshape(n, n_a, 3),
                    np.array(self._following, float).reshape(n, n_a, 4))
        samples = SignalSamples(st, sv, np.array(self._noise) if self._noise
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
        # what the sensors reported is kept only for a freeze or a replay to read back
        reports = self.n_ctrl if np.isin(kinds[:, :, (DW_MEAS, ROCOF_MEAS)],
                                         (FREEZE, REPLAY)).any() else 0
        rest = np.arange(n)
        if lanes and not trace and n_a == 1 and n_s == N_AREA_STATES:
            f_i = rows.index[:, 0, 2]
            fit = ((rows.relay_noise[:, 0, 0] == 0.0) & (rows.relay_noise[:, 0, 1] == 0.0)
                   & np.isin(kinds[:, 0, LOAD], (STEP, NONE)) & (rows.following[:, 0, 0] == 0.0)
                   & ((f_i < 0)
                      | ~np.isin(filters.methods[np.maximum(f_i, 0)], grid_wide_methods())))
            blocks, left = lane_blocks(rows.plant_of, np.flatnonzero(fit), LANE_MIN_FILL)
            run_lanes(timing, plants, rows, samples, estimators, filters, relays, out, blocks,
                      LaneWork.sized(estimators.a.shape[1], reports))
            rest = np.sort(np.concatenate([np.flatnonzero(~fit), left]))
        if len(rest):
            rest = slice(None) if len(rest) == n else rest   # all of them: views, no copies
            mine = Rows(*(column[rest] for column in rows))
            part = Outputs(out.metrics[rest], out.ends[rest], *out[2:])
            n_sums = max((scratch_size(f) for f in self._filters.items), default=0)
            run_kernel(timing, plants, mine, samples, estimators, filters, relays, part,
                       Work.sized(n_s, n_a, estimators.a.shape[1], n_sums, reports))
            out.metrics[rest], out.ends[rest] = part.metrics, part.ends
        metrics, ends = out.metrics, out.ends
        alarms = METRICS.index("alarms")
        for i, logs in enumerate(self.sensor_alarms):     # rows up to the run's end
            for a, log in logs.items():
                metrics[i, a, alarms] += np.count_nonzero(log.t <= self.t[ends[i]] + 1e-9)
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


def check_sensed(attacks: dict, filters: dict, estimator) -> None:
    """``ValueError`` for an attack on an area's sensors (``dw_meas``, ``rocof_meas``)
    with a coupled filter on the exact grid state: it reads every area's state from the
    plant, not from the sensors, so the attack would not reach it (give it its grid
    Kalman filter, ``estimator="kalman"``, which reads the sensors)."""
    sensed = sorted(a for a, channels in attacks.items()
                    if any(channels.get(c) is not None for c in SENSOR_CHANNELS))
    coupled = any(isinstance(f, CoupledFilter) or f == "coupled" for f in filters.values())
    if sensed and coupled and estimator is None:
        raise ValueError(f"attacks on the sensors of area(s) {sensed} with a coupled filter "
                         f"on the exact grid state: it reads the plant, not the sensors; "
                         f"give estimator='kalman' (its grid Kalman filter reads them)")


# -- one scenario --------------------------------------------------------------------------
#: the keywords of a scenario in an area's form (lfc.simulate of an LFCParams or a microgrid)
AREA_KEYS = ("pc_attack", "wref_attack", "load", "scc", "estimator", "noise_std", "seed",
             "load_feedforward", "relay_noise", "anti_windup", "dw_meas_attack",
             "rocof_meas_attack", "following_load", "sensors")
#: the keywords of a scenario in a grid's form (lfc.simulate of a MultiAreaParams or a grid)
GRID_KEYS = ("attacks", "loads", "filters", "estimator", "noise_std", "seed", "feedforward",
             "relay_noise", "anti_windup", "following_loads", "sensors")



@dataclass(frozen=True)
class Scenario:
    """One scenario of any plant: what reaches each area's generator side and how it
    measures, checked once when made.

    A single area is area 0 of a grid of one area: :meth:`for_area` takes
    :func:`lfc.simulate`'s keywords of an area, :func:`lfc.tables.table_scenarios` a
    scenario table's rows (:func:`lfc.tables.scenario_row` writes one back), and
    ``lfc.simulate(plant, scenario)`` and ``lfc.simulate_many(plant, scenarios)`` run
    it on any plant (:meth:`keywords` gives the plant's form).

    Parameters
    ----------
    attacks : dict, optional
        ``{area: {"pc" | "wref" | "ace" | "dw_meas" | "rocof_meas": signal}}``: the
        attacker's additions to the command that reaches the area (pu), to its
        frequency reference (pu), to the tie-line term of its area control error (pu),
        and to what its generator side's frequency (pu) and ROCOF (pu/s) sensors read
        (the AGC, the Kalman filter and, with the exact state, the filter read them;
        the relays read the plant); a :class:`~lfc.signals.Signal` or any callable of
        time (s).
    loads : dict, optional
        ``{area: signal}``: each area's load change (pu).
    filters : dict, optional
        ``{area: filter}``: a built filter (:class:`~lfc.filters.SafetyFilter`, a
        grid's :class:`~lfc.filters.coupled.CoupledFilter`) or, on a grid, a kind
        :func:`lfc.filters.build` builds by name (``"certified"``, ``"coupled"``, ...).
    estimator : None, "kalman" or KalmanFilter
        What the filters see: the true state (None) or a Kalman estimate.
    noise_std : (float, float)
        Std of the white noise on each controller's ``dw_meas`` (pu) and
        ``rocof_meas`` (pu/s) readings, each 0 or in :data:`lfc.estimation.STD`.
    seed : int
        Seed of the noise, in [0, 2**32).
    feedforward : bool or None
        Give each filter its area's true disturbance; None (default) is the plant's
        default (an area: no; a grid: its net disturbance, load plus export).
    relay_noise : bool
        The relays read through the noise too (needs ``noise_std`` > 0).
    anti_windup : bool
        Conditional integration of the AGC behind a held command.
    following_loads : dict, optional
        ``{area: FollowingLoad}``: a dynamic load-altering attack in the area, a
        botnet's load that follows the area's frequency meter
        (:class:`lfc.load_attacks.FollowingLoad`), added to its load; linear plants
        only.
    sensors : dict, optional
        ``{area: Redundant}``: the area's frequency and ROCOF readings come from
        redundant sensors, some of which may lie (:class:`lfc.sensors.Redundant`:
        the median is what its AGC, Kalman filter and filter read; the alarm log names
        each reading found a lie).  Not with an attack on the area's sensor channels
        (the liars are the sensors' attackers) nor with ``noise_std`` (the array's
        noise is the sensors' noise).
    plant : LFCParams or MultiAreaParams, optional
        The plant this scenario runs on when not the one given (a scenario table's
        ``M``, ``D``, ... columns; the filters and the AGC keep the given one as their
        design model); :func:`lfc.simulate_many` of a linear plant only.

    Raises
    ------
    ValueError
        Naming the field, for a value out of its range or of the wrong shape.
    """

    attacks: dict = field(default_factory=dict)
    loads: dict = field(default_factory=dict)
    filters: dict = field(default_factory=dict)
    estimator: object = None
    noise_std: tuple[float, float] = (0.0, 0.0)
    seed: int = 0
    feedforward: bool | None = None
    relay_noise: bool = False
    anti_windup: bool = False
    following_loads: dict = field(default_factory=dict)
    sensors: dict = field(default_factory=dict)
    plant: LFCParams | MultiAreaParams | None = None

    def __post_init__(self) -> None:
        attacks = _areas("attacks", self.attacks)
        for a, channels in attacks.items():
            if not isinstance(channels, dict) or set(channels) - set(CHANNELS):
                error = ValueError if isinstance(channels, dict) else ParameterTypeError
                raise error(f"attacks[{a}] must be a dict with keys among {CHANNELS}, got "
                            f"{channels!r:.80}")
        loads = _areas("loads", self.loads)     # signals: checked where they are sampled
        object.__setattr__(self, "attacks", {a: dict(c) for a, c in attacks.items()})
        object.__setattr__(self, "loads", loads)
        object.__setattr__(self, "filters", _areas("filters", self.filters))
        following = _areas("following_loads", self.following_loads)
        for a, load in following.items():
            if not isinstance(load, FollowingLoad):
                raise ParameterTypeError(f"following_loads[{a}] must be a FollowingLoad "
                                         f"(lfc.load_attacks), got {load!r:.80}")
        object.__setattr__(self, "following_loads", following)
        sensors = _areas("sensors", self.sensors)
        for a, red in sensors.items():
            if not isinstance(red, Redundant):
                raise ParameterTypeError(f"sensors[{a}] must be a Redundant (lfc.sensors), "
                                         f"got {red!r:.80}")
            taken = [c for c in SENSOR_CHANNELS if attacks.get(a, {}).get(c) is not None]
            if taken:
                raise ValueError(f"attacks[{a}] on {taken} and sensors[{a}]: the redundant "
                                 f"sensors' lies are their attacks (Redundant(lies={{sensor: "
                                 f"{{channel: signal}}}}))")
        object.__setattr__(self, "sensors", sensors)
        noisy = check_noise(self.noise_std)
        if sensors and noisy:
            raise ValueError("noise_std > 0 with sensors: the redundant sensors' noise is "
                             "their array's (Redundant.noise, drawn within its bound)")
        object.__setattr__(self, "noise_std", tuple(float(s) for s in self.noise_std))
        object.__setattr__(self, "seed", check_seed("seed", self.seed))
        if self.feedforward is not None:
            object.__setattr__(self, "feedforward", check_flag("feedforward", self.feedforward))
        object.__setattr__(self, "relay_noise", check_flag("relay_noise", self.relay_noise))
        object.__setattr__(self, "anti_windup", check_flag("anti_windup", self.anti_windup))
        if self.relay_noise and not noisy:
            raise ValueError("relay_noise=True needs noise_std > 0 (the relays' measurement "
                             "noise)")
        if self.plant is not None and not isinstance(self.plant, (LFCParams, MultiAreaParams)):
            raise ParameterTypeError(f"plant must be an LFCParams, a MultiAreaParams or None, "
                                     f"got {type(self.plant).__name__}")

    @classmethod
    def for_area(cls, *, pc_attack=None, wref_attack=None, load=None, scc=None,
                 estimator=None, noise_std: tuple[float, float] = (0.0, 0.0), seed: int = 0,
                 load_feedforward: bool = False, relay_noise: bool = False,
                 anti_windup: bool = False, dw_meas_attack=None,
                 rocof_meas_attack=None, following_load=None, sensors=None) -> Scenario:
        """The scenario of one area from :func:`lfc.simulate`'s keywords of an area."""
        channels = {k: v for k, v in zip(("pc", "wref", *SENSOR_CHANNELS),
                                         (pc_attack, wref_attack, dw_meas_attack,
                                          rocof_meas_attack)) if v is not None}
        return cls(attacks={0: channels} if channels else {},
                   loads={} if load is None else {0: load},
                   filters={} if scc is None else {0: scc}, estimator=estimator,
                   noise_std=noise_std, seed=seed, feedforward=load_feedforward,
                   relay_noise=relay_noise, anti_windup=anti_windup,
                   following_loads={} if following_load is None else {0: following_load},
                   sensors={} if sensors is None else {0: sensors})

    def keywords(self, form: str) -> dict:
        """The scenario as :func:`lfc.simulate`'s keywords of a plant of ``form``:
        ``"area"`` (``pc_attack``, ``scc``, ...: ``AREA_KEYS``) or ``"grid"``
        (``attacks``, ``filters``, ...: ``GRID_KEYS``); ``feedforward`` None and
        ``relay_noise`` False are left to the plant (the ANDES plants' relays read no
        noise).  ``ValueError`` for an area if it names an area but 0, an ``ace``
        attack (an area has no tie-line) or a filter given by kind."""
        if form == "grid":
            kw = {k: getattr(self, k) for k in GRID_KEYS}
            return {k: v for k, v in kw.items()
                    if not (k == "feedforward" and v is None or k == "relay_noise" and not v
                            or k in ("following_loads", "sensors") and not v)}
        if form != "area":
            raise ValueError(f"form must be 'area' or 'grid', got {form!r:.40}")
        for name in ("attacks", "loads", "filters", "following_loads", "sensors"):
            if set(getattr(self, name)) - {0}:
                raise ValueError(f"{name}: a single area is area 0, got areas "
                                 f"{sorted(getattr(self, name))}")
        channels = self.attacks.get(0, {})
        if "ace" in channels:
            raise ValueError("attacks[0]['ace']: a single area has no tie-line (its area "
                             "control error is its frequency)")
        scc = self.filters.get(0)
        if isinstance(scc, str):
            raise ValueError(f"filters[0]={scc!r}: a single area takes a built filter "
                             f"(lfc.SafetyFilter(params, method={scc!r}))")
        kw = {"pc_attack": channels.get("pc"), "wref_attack": channels.get("wref"),
              "load": self.loads.get(0), "scc": scc, "estimator": self.estimator,
              "noise_std": self.noise_std, "seed": self.seed,
              "load_feedforward": bool(self.feedforward), "anti_windup": self.anti_windup}
        kw.update({f"{c}_attack": channels[c] for c in SENSOR_CHANNELS if c in channels})
        if 0 in self.following_loads:
            kw["following_load"] = self.following_loads[0]
        if 0 in self.sensors:
            kw["sensors"] = self.sensors[0]
        return {**kw, "relay_noise": True} if self.relay_noise else kw


def _areas(name: str, mapping) -> dict:
    """``mapping`` (None: empty) as a dict whose keys are area indices (ints >= 0)."""
    mapping = {} if mapping is None else mapping
    if not isinstance(mapping, dict):
        raise ParameterTypeError(f"{name} must be a dict {{area: ...}}, got {mapping!r:.80}")
    for key in mapping:
        if isinstance(key, bool) or not isinstance(key, Integral) or key < 0:
            raise ValueError(f"a key of {name} must be an area index (an int >= 0), got "
                             f"{key!r:.40}")
    return {int(k): v for k, v in mapping.items() if v is not None}


def grid_scenarios(scenarios) -> object:
    """A grid's ``simulate_many`` scenarios with every :class:`Scenario` in it as its
    grid keywords (:meth:`Scenario.keywords`); anything else as it is (checked by the
    grid's runner).  ``ValueError`` for a scenario with its own plant."""
    if not isinstance(scenarios, list):
        return scenarios
    for i, s in enumerate(scenarios):
        if isinstance(s, Scenario) and s.plant is not None:
            raise ValueError(f"scenarios[{i}].plant: a grid's scenarios run on the plant "
                             f"given (a scenario's own plant is an area table's M, D, ...)")
    return [s.keywords("grid") if isinstance(s, Scenario) else s for s in scenarios]
