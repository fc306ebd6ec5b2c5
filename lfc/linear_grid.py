"""Closed-loop simulation of an interconnected grid with a safety filter at every area.

:func:`simulate_grid_linear` (what :func:`lfc.simulate` runs for a
``MultiAreaParams`` plant) is one scenario with a trace (the engine,
:mod:`lfc.engine`); :func:`simulate_grid_table` many, metrics
only.  With one area and no tie-line both are :func:`lfc.simulate` exactly.

**What a certified filter at every area guarantees.**  ``filters={i:
"certified"}`` builds :func:`area_filter`: the single-area certified filter
(:mod:`lfc.filters.certified`) of area ``i``'s own model, given the area's net
disturbance ``w_i = dP_L,i + dP_tie,i`` at each control sample
(``feedforward=True``; the tie-line export is metered at the area's
boundary) and declared a ``load_bound`` that covers how far ``w_i`` may move
within one control period (``load_kind="period"``: the held command is
re-certified at every call).  Proven (per area, no communication between the
filters): while (a) the plant of area ``i`` is its design model, (b) its filter
knows the area's state and ``w_i`` at each control sample, and (c) ``w_i``
moves by at most ``load_bound`` within any control period, area ``i``'s OF2,
UF2 and ROCOF relays cannot trip — at any instant before the first control
sample at which its filter flags ``outside`` — whatever commands, frequency
references and ACE signals an attacker sends, to one area or to several at
once.  The proof is the single-area one applied on each control period: the
command applied at a sample is certified (new, or the held one re-checked) for
the current state and ``w_i``, and on that period the true ``w_i`` is within
the bound of it.  (c) holds for the tie-line part by the default bound,
``control_period * sum_j T_ij * 2 F`` (both areas' frequencies within the
relay band ``F``), and fails for a load step larger than the bound, as in
one area.  No bound on ``w_i`` itself is assumed: the certificate holds for any
constant load (:mod:`lfc.filters.certified`), so the filters keep certifying
however large the tie-line flow grows (``tests/test_proven_recovery.py``:
opposite ACE biases of ±3 pu, after which AGC restores frequency and schedule).

``filters={i: "coupled"}`` at every area is the other way: one certificate on
the coupled model, each filter reading the grid's state, the tie-line flows part
of the prediction (:mod:`lfc.filters.coupled`, ``docs/coupled-certificate.md``).
``filters={i: "contract"}`` at every area is the decentralized one: each area
keeps its command in a box and certifies against its neighbours' boxes, reading
nothing (:mod:`lfc.filters.contract`).

Measured, not proven: what happens after an ``outside`` flag.  The held
command was certified for the net disturbance of an earlier sample; while it
is held the tie-line flow can drift by more than ``load_bound`` although it
moves little in each period, and the re-check then fails.  On the two-area
preset no filter flags ``outside`` on the attacks of ``tests/test_multiarea.py``;
on the three-area preset a 1 pu, 0.5 Hz sinusoid on the light area does (at a
few samples, no trip), a lightly damped area (damping ratio 0.03) flags it
for seconds, and on Kundur's two-area model as fitted to ANDES (a stiff tie,
T = 98 pu) a −2.5 pu ACE bias makes one area flag it for about 3 s of
samples (no trip).  ``outside`` is in the metrics and the alarm log;
:meth:`Result.disturbance_step` measures assumption (c) on a run.
A stiff tie also widens the default bound: for the default area (M 4 s)
behind T = 98 pu it leaves the certificate nothing, and ``"certified"``
raises ``ValueError`` saying so.  With measurement noise and each area's
Kalman filter (assumption (b) then rests on the estimate's declared error
bound), the filters with ``noise_std`` declared flag ``outside`` on the
two-area preset under a 1 pu, 0.5 Hz sinusoid: the single-area Kalman
filter's error bound does not cover the tie-line flow's inter-area swing
(no trip over 40 measured attacks; ``tests/test_multiarea.py``).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pandas as pd

from lfc._validate import ParameterTypeError, check_count
from lfc.engine import METRICS, check_area_keys, sample_signal
from lfc.estimation import check_noise_std
from lfc.filters import SafetyFilter, build
from lfc.filters.coupled import CoupledFilter
from lfc.linear_area import check_timing
from lfc.load_attacks import DW_MEAS
from lfc.multiarea import N_AREA_STATES, MultiAreaParams
from lfc.relays import RELAY_NAMES, RelaySettings, relays_or_default
from lfc.result import METRIC_KEYS, Result, grid_result
from lfc.run import Runner, register
from lfc.scenarios import Scenarios, grid_scenarios
from lfc.tables import metrics_frame

__all__ = ["area_filter", "grid_results", "results_table", "simulate_grid_linear",
           "simulate_grid_table"]


def area_filter(params: MultiAreaParams, area: int,
                kind: str | SafetyFilter | CoupledFilter | None, relays: RelaySettings,
                control_period: float, noise_std: tuple[float, float] | None = None
                ) -> SafetyFilter | CoupledFilter | None:
    """The filter of ``area`` as a grid's ``filters`` gives it: a filter as given,
    None, or one built by name (:func:`lfc.filters.build`: ``"paper"``,
    ``"certified"`` with the tie-line ``load_bound`` of
    :func:`lfc.filters.bounds.tie_step_bound` and the grid's command range,
    ``"contract"``, ``"coupled"``; ``noise_std``: the coupled certificate's
    estimate noise)."""
    if kind is None or isinstance(kind, (SafetyFilter, CoupledFilter)):
        return kind
    return build(kind, params, area, relays, control_period=control_period,
                 noise_std=noise_std)


def estimate_noise(estimator: object, noise_std) -> tuple[float, float] | None:
    """The measurement noise ``"coupled"`` (:func:`area_filter`) is built for: with
    ``estimator="kalman"``, ``noise_std`` (checked; its grid Kalman estimate),
    else None (the exact state)."""
    if isinstance(estimator, str) and estimator == "kalman":
        return tuple(check_noise_std("noise_std", noise_std))
    return None


def simulate_grid_linear(params: MultiAreaParams, *, duration: float,
                       attacks: dict | None = None, loads: dict | None = None,
                       filters: dict | None = None, relays: RelaySettings | None = None,
                       estimator=None, noise_std: tuple[float, float] = (0.0, 0.0),
                       seed: int = 0, dt: float = 1e-3, control_period: float = 0.01,
                       stop_on_trip: bool = False, feedforward: bool = True,
                       relay_noise: bool = False, anti_windup: bool = False,
                       following_loads: dict | None = None,
                       sensors: dict | None = None) -> Result:
    """Simulate an interconnected grid from equilibrium.

    Parameters
    ----------
    params : MultiAreaParams
    duration : float
        Simulated time (s), > 0.
    attacks : dict, optional
        ``{area: {"pc" | "wref" | "ace": signal}}``: added to the command the
        area's generator receives (pu), to its frequency reference (pu), or to
        the ACE its AGC integrates (pu); signals as in :func:`lfc.simulate`.
    loads : dict, optional
        ``{area: signal}``: the area's load change (pu).
    filters : dict, optional
        ``{area: "paper" | "certified" | "coupled" | filter}`` (:func:`area_filter`);
        areas not named run without a filter.
    relays : RelaySettings, optional
        The same settings in every area (default IEEE 1547 Cat. III).
    estimator, noise_std, seed, dt, control_period, stop_on_trip
        As in :func:`lfc.simulate`, per area (area ``a > 0`` draws its noise
        from ``(seed, a)``); ``stop_on_trip`` ends the run at the first trip in
        any area.
    feedforward : bool
        With ``estimator=None``, give each filter its area's net disturbance
        ``dP_L + dP_tie`` (default; the tie-line export is metered at the
        area's boundary); False gives 0, as :func:`lfc.simulate` does by
        default.
    relay_noise : bool
        Every area's relays read through white noise of std ``noise_std``, as
        in :func:`lfc.simulate` (one generator seeded by ``seed`` draws for the
        areas in turn at every plant step).
    anti_windup : bool
        Each area's AGC integrator does not integrate in the direction that
        widens the gap between its command and what the area's filter applies
        (conditional integration, as in :func:`lfc.simulate`).  Default False.
    following_loads : dict, optional
        ``{area: FollowingLoad}``: a dynamic load-altering attack in the area
        (:class:`lfc.load_attacks.FollowingLoad`), added to its load (the trace's
        ``p_load`` holds both).
    sensors : dict, optional
        ``{area: Redundant}``: the area's redundant frequency and ROCOF sensors, some
        of which may lie (:class:`lfc.sensors.Redundant`; as in :func:`lfc.simulate`;
        the alarm log names each reading found a lie).

    Returns
    -------
    Result
    """
    if not isinstance(params, MultiAreaParams):
        raise ParameterTypeError(f"params must be a MultiAreaParams, got "
                                 f"{type(params).__name__}")
    check_timing(duration, dt, control_period, params.n_areas, params.n_states)
    relays = relays_or_default(relays)
    filters = check_area_keys(filters, params.n_areas, "filters")
    estimate = estimate_noise(estimator, noise_std)
    built = {a: area_filter(params, a, f, relays, control_period, estimate)
             for a, f in filters.items()}
    sc = Scenarios(params, duration=duration, dt=dt, control_period=control_period,
                   relays=relays)
    following_loads = check_area_keys(following_loads, params.n_areas, "following_loads")
    sc.add(attacks=attacks, loads=loads, filters=built, estimator=estimator,
           noise_std=noise_std, seed=seed, feedforward=feedforward, relay_noise=relay_noise,
           anti_windup=anti_windup, following_loads=following_loads, sensors=sensors)
    run = sc.run(trace=True, stop_on_trip=stop_on_trip)
    end = int(run.ends[0])
    t = sc.t[:end + 1]
    m, n_a = N_AREA_STATES, params.n_areas
    states = run.x[:end + 1, :m * n_a].reshape(end + 1, n_a, m)
    tie = run.x[:end + 1, m * n_a:] @ params.incidence().T     # (samples, areas)
    loads = loads or {}
    p_load = np.column_stack([sample_signal(loads.get(a), t, f"loads[{a}]") for a in range(n_a)])
    for a, follower in following_loads.items():
        p_load[:, a] += follower.load(t, states[:, a, DW_MEAS])
    trips = [pd.DataFrame([(RELAY_NAMES[r], float(t[k])) for k in
                           np.flatnonzero(run.trips[:end + 1, a])
                           for r in range(3) if run.trips[k, a] >> r & 1], columns=["relay", "t"])
             for a in range(n_a)]
    settings = {"params": repr(params), "relays": vars(relays), "duration": duration,
                "dt": dt, "control_period": control_period, "seed": seed,
                "noise_std": list(noise_std), "estimator": repr(estimator),
                "attacks": repr(attacks), "loads": repr(loads),
                "filters": {a: repr(f) for a, f in built.items()},
                "stop_on_trip": stop_on_trip, "feedforward": feedforward,
                "anti_windup": anti_windup,
                "relay_noise": relay_noise,
                **({"following_loads": repr(following_loads)} if following_loads else {}),
                **({"sensors": repr(sensors)} if sensors else {})}
    return grid_result(params, t, states, p_load, tie, trips, sc.tc,
                       [run.ctrl[:, a] for a in range(n_a)], built,
                       settings).with_alarms(sc.sensor_alarms[0])


#: the keys of a grid scenario (the keywords of :func:`simulate_grid_linear` it sets)
SCENARIO_KEYS = ("attacks", "loads", "filters", "estimator", "noise_std", "seed", "feedforward",
                 "relay_noise", "anti_windup", "following_loads", "sensors")


def check_grid_scenarios(scenarios: object) -> None:
    """``TypeError`` unless ``scenarios`` is a list of dicts, ``ValueError`` if it is
    empty or a dict has a key not among ``SCENARIO_KEYS``."""
    if not isinstance(scenarios, (list, tuple)) or not scenarios:
        error = ValueError if isinstance(scenarios, (list, tuple)) else ParameterTypeError
        raise error(f"scenarios must be a non-empty list of dicts, got {scenarios!r:.80}")
    for k, s in enumerate(scenarios):
        if not isinstance(s, dict) or set(s) - set(SCENARIO_KEYS):
            error = ValueError if isinstance(s, dict) else ParameterTypeError
            raise error(f"scenarios[{k}] must be a dict with keys among "
                        f"{sorted(SCENARIO_KEYS)}, got {s!r:.200}")


def grid_results(params: MultiAreaParams, scenarios: list[dict], *, duration: float,
                 relays: RelaySettings | None = None, dt: float = 1e-3,
                 control_period: float = 0.01, jobs: int = 2) -> list[Result]:
    """Each scenario (a dict of ``SCENARIO_KEYS``) run by :func:`simulate_grid_linear`
    with its trace, in ``jobs`` threads (the compiled loop runs without the GIL);
    the results in the scenarios' order, whose ``metrics()`` are the rows
    :func:`simulate_grid_table` gives.  ``simulate_many(grid, scenarios,
    keep="results")``."""
    check_timing(duration, dt, control_period, params.n_areas, params.n_states)
    check_count("jobs", jobs)
    check_grid_scenarios(scenarios)

    def run(s: dict) -> Result:
        return simulate_grid_linear(params, duration=duration, relays=relays, dt=dt,
                                    control_period=control_period, **s)

    with ThreadPoolExecutor(max_workers=min(jobs, len(scenarios))) as pool:
        return list(pool.map(run, scenarios))


def results_table(results: list[Result]) -> pd.DataFrame:
    """The metrics of grid results as :func:`simulate_grid_table` returns them: one
    row per scenario and area, ``scenario``, ``area`` and ``METRIC_KEYS``."""
    return pd.DataFrame([{"scenario": i, "area": a, **m} for i, r in enumerate(results)
                         for a, m in r.metrics().items()],
                        columns=["scenario", "area", *METRIC_KEYS])


def simulate_grid_table(params: MultiAreaParams, scenarios: list[dict], *,
                             duration: float, relays: RelaySettings | None = None,
                             dt: float = 1e-3, control_period: float = 0.01,
                             jobs: int = 2) -> pd.DataFrame:
    """Simulate many multi-area scenarios; metrics only.

    Parameters
    ----------
    params : MultiAreaParams
    scenarios : list of dict
        Each with any of the keyword arguments ``attacks``, ``loads``,
        ``filters``, ``estimator``, ``noise_std``, ``seed``, ``feedforward``,
        ``relay_noise``, ``anti_windup``, ``following_loads``, ``sensors`` of
        :func:`simulate_grid_linear` (filters named by kind are built once).
    duration, relays, dt, control_period
        As in :func:`simulate_grid_linear`.
    jobs : int
        Threads (the compiled loop runs without the GIL), >= 1.

    Returns
    -------
    DataFrame
        One row per scenario and area: ``scenario``, ``area`` and the metrics
        :data:`lfc.result.METRIC_KEYS` (the keys of
        ``simulate(...).metrics()[area]``, with the same values).
    """
    check_timing(duration, dt, control_period)
    check_count("jobs", jobs)
    check_grid_scenarios(scenarios)
    relays = relays_or_default(relays)
    cache: dict = {}
    rows = []
    for k, s in enumerate(scenarios):
        filters = check_area_keys(s.get("filters"), params.n_areas, f"scenarios[{k}].filters")
        built = {}
        estimate = estimate_noise(s.get("estimator"), s.get("noise_std", (0.0, 0.0)))
        for a, f in filters.items():
            key = (a, f if isinstance(f, str) else id(f), estimate)
            if key not in cache:
                cache[key] = area_filter(params, a, f, relays, control_period, estimate)
            built[a] = cache[key]
        rows.append({"feedforward": True, **s, "filters": built})
    n_a = params.n_areas

    def run(part: list[dict]) -> tuple[np.ndarray, int]:
        sc = Scenarios(params, duration=duration, dt=dt, control_period=control_period,
                       relays=relays)
        for s in part:
            sc.add(**s)
        return sc.run().metrics, sc.n_ctrl

    parts = [rows[i::jobs] for i in range(min(jobs, len(rows)))]
    with ThreadPoolExecutor(max_workers=len(parts)) as pool:
        done = list(pool.map(run, parts))
    metrics = np.zeros((len(rows), n_a, len(METRICS)))
    for i, (m, _) in enumerate(done):
        metrics[i::jobs] = m
    n_ctrl = done[0][1]
    flat = metrics.reshape(len(rows) * n_a, len(METRICS))
    out = metrics_frame(flat, n_ctrl, pd.RangeIndex(len(flat)))
    out.insert(0, "area", np.tile(np.arange(n_a), len(rows)))
    out.insert(0, "scenario", np.repeat(np.arange(len(rows)), n_a))
    return out


# -- the grid's runner (lfc.run): simulate and simulate_many of a MultiAreaParams ----------
def _simulate(plant: MultiAreaParams, *, duration: float, design=None, **scenario):
    return simulate_grid_linear(plant, duration=duration, **scenario)


def _simulate_many(plant: MultiAreaParams, scenarios: list[dict], *, duration: float,
                   design=None, keep: str = "metrics", **kwargs):
    scenarios = grid_scenarios(scenarios)
    shared = {k: kwargs.pop(k) for k in SCENARIO_KEYS if k in kwargs}
    if shared:                                   # keywords every scenario shares
        check_grid_scenarios(scenarios)
        scenarios = [{**shared, **s} for s in scenarios]
    run = simulate_grid_table if keep == "metrics" else grid_results
    return run(plant, scenarios, duration=duration, **kwargs)


register(MultiAreaParams, Runner("grid", "grid", "a MultiAreaParams", _simulate, _simulate_many))
