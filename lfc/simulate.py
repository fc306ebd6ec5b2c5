"""Closed-loop simulation of the LFC plant, local controller, safety filter and relays.

Timing: the plant is advanced exactly (zero-order hold) every ``dt``; the
local controller, the network command (with any attack) and the filter run
every ``control_period`` and hold their command in between.  Relays watch the
measured signals at every plant step.  Trips are recorded and the run goes on
(as in the paper, "to show the SCC's continuity") unless ``stop_on_trip``.
:func:`simulate_area` is the engine (:mod:`lfc.engine`) with one scenario and a trace;
:func:`lfc.simulate` runs it for an ``LFCParams`` plant.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from lfc._validate import (ParameterTypeError, check_flag, check_folder, check_multiple,
                           check_positive)
from lfc.engine import CTRL_COLUMNS, N_CTRL, sample_signal
from lfc.filters import SafetyFilter, binding_names
from lfc.filters.base import (ACTIVE, ALARM_BITS, INFEASIBLE, INVALID, MAX_ABS_INPUT, OUTSIDE,
                              SOLVER_ERROR)
from lfc.model import STATES, LFCParams
from lfc.relays import RELAY_NAMES, RelaySettings, relays_or_default
from lfc.scenarios import Scenarios
from lfc.signals import Signal

__all__ = ["ALARM_COLUMNS", "METRIC_KEYS", "SimResult", "check_timing", "simulate_area"]
METRIC_KEYS = ("tripped", "first_trip_relay", "first_trip_t", "max_abs_dw_meas",
               "max_abs_rocof_meas", "scc_active_fraction", "max_abs_modification",
               "mean_abs_modification", "alarms", "final_abs_dw_meas", "outside")
"""The metrics of a run, defined once: :meth:`SimResult.metrics` and every row of
:func:`lfc.simulate_many` (the compiled loop's accumulators) have these keys."""
ALARM_COLUMNS = ("t", "u_ref", "u", "binding", "h_freq", "h_rocof", "margin_freq",
                 "margin_rocof", "infeasible", "outside", "invalid_input", "solver_error",
                 "reason")


@dataclass
class SimResult:
    """Outcome of one simulation.

    Attributes
    ----------
    trace : DataFrame
        Every plant step: ``t`` (s), ``pc_ref`` and ``pc`` (incoming and applied
        command, pu), the states ``dPg, dPm, dw, dw_meas`` (pu) and
        ``rocof_meas`` (pu/s), ``p_load`` (pu), ``wref`` (pu), ``scc_active``
        (bool) and the filter's barrier values ``h_freq`` (pu^2) and ``h_rocof``
        ((pu/s)^2) at the last control sample (NaN without a filter).
    controls : DataFrame
        Every controller sample: ``t``, ``pc_ref``, ``pc``, ``scc_active``, the
        filter's view of the state ``dw_hat``, ``rocof_hat`` and ``p_load_hat``,
        and its barrier values ``h_freq``, ``h_rocof`` (:class:`FilterInfo`).
    trips : DataFrame
        Every relay trip: ``relay`` and ``t`` (s).
    alarms : DataFrame
        Every filter alarm (an intervention or a flagged condition), columns
        ``ALARM_COLUMNS``: the paper's log for learning attacker strategies.
    settings : dict
        What the run was called with (JSON-serializable).
    line_trips : DataFrame
        Line protection operations (ANDES testbed only): ``line``, ``trip_t``
        (relay decision, s) and ``open_t`` (breaker open, s).
    """

    trace: pd.DataFrame
    controls: pd.DataFrame
    trips: pd.DataFrame
    alarms: pd.DataFrame
    settings: dict = field(default_factory=dict)
    line_trips: pd.DataFrame = field(
        default_factory=lambda: pd.DataFrame(columns=["line", "trip_t", "open_t"]))

    def metrics(self) -> dict:
        """Summary numbers (JSON-serializable), keys ``METRIC_KEYS``: the values
        of a :func:`lfc.simulate_many` row of the same scenario (where the row
        has NaN, no trip, this has None).

        ``tripped``, ``first_trip_relay``, ``first_trip_t`` (s): the first relay
        trip; ``max_abs_dw_meas`` (pu), ``max_abs_rocof_meas`` (pu/s) over the
        trace, ``final_abs_dw_meas`` (pu) at its end; ``scc_active_fraction``
        and ``max_abs_modification``, ``mean_abs_modification`` (pu,
        ``|pc - pc_ref|``) over the control samples (0 where ``pc_ref`` is
        non-finite or beyond ``MAX_ABS_INPUT``: invalid input, held); ``alarms`` (control
        samples that alarmed), ``outside`` (of them, flagged ``outside``).
        """
        first = self.first_trip or {"relay": None, "t": None}
        ref = self.controls["pc_ref"]
        mod = (self.controls["pc"] - ref).abs().where(ref.abs() <= MAX_ABS_INPUT, 0.0)
        return {
            "tripped": bool(len(self.trips) > 0),
            "first_trip_relay": first["relay"],
            "first_trip_t": first["t"],
            "max_abs_dw_meas": float(self.trace["dw_meas"].abs().max()),
            "max_abs_rocof_meas": float(self.trace["rocof_meas"].abs().max()),
            "scc_active_fraction": float(self.controls["scc_active"].mean()),
            "max_abs_modification": float(mod.max()) if len(mod) else 0.0,
            "mean_abs_modification": float(mod.mean()) if len(mod) else 0.0,
            "alarms": int(len(self.alarms)),
            "final_abs_dw_meas": float(abs(self.trace["dw_meas"].iat[-1])),
            "outside": int(self.alarms["outside"].sum()),
        }

    @property
    def areas(self) -> tuple[SimResult]:
        """``(self,)``: an area is a grid of one area, so code written for a grid's
        result (:class:`~lfc.simulate_multiarea.MultiAreaResult`) reads an area's."""
        return (self,)

    def table(self) -> pd.DataFrame:
        """The metrics as :func:`lfc.simulate_many` rows (:func:`metrics_table`): one
        row, ``area`` 0, as a grid's result gives one per area."""
        return metrics_table([self.metrics()])

    @property
    def first_trip(self) -> dict | None:
        """The first relay trip, ``{"relay": name, "t": s}``, or None."""
        if not len(self.trips):
            return None
        row = self.trips.sort_values("t", kind="stable").iloc[0]
        return {"relay": str(row["relay"]), "t": float(row["t"])}

    def save(self, directory: str | Path) -> Path:
        """Write ``trace.csv``, ``controls.csv``, ``trips.csv``, ``alarms.csv``,
        ``line_trips.csv``, ``metrics.json`` and ``settings.json`` into
        ``directory`` (created)."""
        out = check_folder("directory", directory)
        out.mkdir(parents=True, exist_ok=True)
        for name in ("trace", "controls", "trips", "alarms", "line_trips"):
            getattr(self, name).to_csv(out / f"{name}.csv", index=False)
        (out / "metrics.json").write_text(json.dumps(self.metrics(), indent=2))
        (out / "settings.json").write_text(json.dumps(self.settings, indent=2, default=str))
        return out


def metrics_table(per_area: list[dict]) -> pd.DataFrame:
    """Each area's :meth:`SimResult.metrics` as rows: ``area`` then ``METRIC_KEYS``,
    as :func:`lfc.simulate_many` gives them (where no relay tripped,
    ``first_trip_relay`` None and ``first_trip_t`` NaN)."""
    table = pd.DataFrame([{"area": a, **m} for a, m in enumerate(per_area)],
                         columns=["area", *METRIC_KEYS])
    table["first_trip_t"] = table["first_trip_t"].astype(float)
    table["first_trip_relay"] = table["first_trip_relay"].astype(object).where(
        table["tripped"].astype(bool), None)
    return table


MAX_STEPS = 10**7   # plant steps in one single-area run (2.8 h at 1 ms)
#: values a run's trace may hold: a single area's at MAX_STEPS (5 states and an
#: area's trip column per step, N_CTRL columns per 10 ms control period): about a
#: gigabyte with the frames built from it.  A grid's longest run is shorter.
MAX_TRACE_VALUES = MAX_STEPS * (5 + 1 + N_CTRL / 10)


def check_timing(duration: float, dt: float, control_period: float, n_areas: int = 1,
                 n_states: int = 5) -> int:
    """Validate a run's timing (s): ``duration`` and ``control_period`` whole
    multiples of ``dt``, and a trace (``n_states`` values and ``n_areas`` trip
    columns per plant step, ``N_CTRL`` columns per area and control period) of at
    most ``MAX_TRACE_VALUES`` values, checked before anything is allocated; return
    plant steps per control period."""
    for name, value in (("duration", duration), ("dt", dt), ("control_period", control_period)):
        check_positive(name, value)
    per_step = n_states + n_areas + n_areas * N_CTRL * dt / max(control_period, dt)
    longest = MAX_TRACE_VALUES / per_step * dt           # s
    if duration > longest:
        raise ValueError(f"duration / dt = {duration / dt:.3g} plant steps is more than one "
                         f"run holds: its trace ({n_areas} area(s), {n_states} states) would "
                         f"take about {duration / dt * per_step * 8 / 1e9:.3g} GB; lower "
                         f"duration (at most {longest:.6g} s at dt = {dt} s) or raise dt")
    if duration < dt * (1 - 1e-9):
        raise ValueError(f"duration must be at least one plant step (dt = {dt} s), "
                         f"got {duration!r}")
    if not dt <= control_period <= max(duration, dt):
        raise ValueError(f"control_period must lie in [dt, duration] = [{dt}, {duration}] s, "
                         f"got {control_period!r}")
    ratio = check_multiple("control_period", control_period, "dt", dt)
    check_multiple("duration", duration, "dt", dt)     # else the run ends off the asked time
    return ratio


def simulate_area(params: LFCParams, *, duration: float, pc_attack: Signal | None = None,
             wref_attack: Signal | None = None, load: Signal | None = None,
             scc: SafetyFilter | None = None, relays: RelaySettings | None = None,
             estimator=None, noise_std: tuple[float, float] = (0.0, 0.0), seed: int = 0,
             dt: float = 1e-3, control_period: float = 0.01, stop_on_trip: bool = False,
             load_feedforward: bool = False, relay_noise: bool = False,
             anti_windup: bool = False) -> SimResult:
    """Simulate the closed loop from equilibrium.

    Parameters
    ----------
    params : LFCParams
        Plant (and local controller) parameters.
    duration : float
        Simulated time (s), > 0.
    pc_attack : callable, optional
        Added to the governor command dPc that arrives from the network (pu);
        a :class:`~lfc.signals.Signal` or any callable of time.
    wref_attack : callable, optional
        Corrupts the frequency reference dw_ref of the local integral
        controller ``d dPc/dt = k_i (dw_ref - dw_meas)`` (pu).
    load : callable, optional
        Load change dPL (pu).
    scc : SafetyFilter, optional
        The safety filter; None runs without one.
    relays : RelaySettings, optional
        Default IEEE 1547 Cat. III.
    estimator : None, "kalman" or KalmanFilter
        None gives the filter the true state; "kalman" a Kalman filter's estimate
        (its measurement-noise model taken from ``noise_std`` where > 0).
    noise_std : (float, float)
        Std of white noise on the controller's ``dw_meas`` (pu) and
        ``rocof_meas`` (pu/s) readings.
    seed : int
        Seed of the noise generators, in [0, 2**32) (the relays' noise keeps 32 bits).
    dt : float
        Plant step (s). Default 1 ms.
    control_period : float
        Controller/filter period (s), an integer multiple of ``dt``. Default 10 ms.
    stop_on_trip : bool
        End the run at the first relay trip.
    load_feedforward : bool
        Give the filter the true dPL (an idealized load measurement) instead of 0
        (E7: dPL is not measured at the generator); needs ``scc`` and
        ``estimator=None`` (else ``ValueError``: it would have no effect).
    relay_noise : bool
        The relays read ``dw_meas`` and ``rocof_meas`` through white noise of
        std ``noise_std`` too, drawn independently at every plant step (seeded
        by ``seed``); default False: the relays see the noise-free signals.
        ``trace`` and the metrics keep the noise-free signals.
    anti_windup : bool
        While the filter's command differs from the incoming one, the local
        integrator does not integrate in the direction that widens the
        difference (conditional integration), so it cannot wind up behind a
        held command.  Default False: the paper's loop, where it winds up.

    Returns
    -------
    SimResult
    """
    check_timing(duration, dt, control_period)
    if scc is not None and not isinstance(scc, SafetyFilter):
        raise ParameterTypeError(f"scc must be a SafetyFilter or None, got {scc!r}")
    relays = relays_or_default(relays)
    check_flag("load_feedforward", load_feedforward)   # the engine calls it feedforward
    if load_feedforward and (scc is None or estimator is not None):
        raise ValueError("load_feedforward=True gives the filter the true load in place of "
                         "an estimate: it needs scc and estimator=None (it would have no "
                         "effect here)")
    sc = Scenarios(params, duration=duration, dt=dt, control_period=control_period,
                   relays=relays)
    sc.add(attacks={0: {"pc": pc_attack, "wref": wref_attack}}, loads={0: load},
           filters={0: scc}, estimator=estimator, noise_std=noise_std, seed=seed,
           feedforward=load_feedforward, relay_noise=relay_noise, anti_windup=anti_windup)
    run = sc.run(trace=True, stop_on_trip=stop_on_trip)
    end = int(run.ends[0])
    t = sc.t[:end + 1]
    trace = pd.DataFrame({"t": t})
    for i, name in enumerate(STATES):
        trace[name] = run.x[:end + 1, i]
    trace["p_load"] = sample_signal(load, t, "load")
    bits = run.trips[:end + 1, 0]
    trips = pd.DataFrame([(RELAY_NAMES[r], float(t[k])) for k in np.flatnonzero(bits)
                          for r in range(3) if bits[k] >> r & 1], columns=["relay", "t"])
    settings = {"params": vars(params), "relays": vars(relays), "duration": duration,
                "dt": dt, "control_period": control_period, "seed": seed,
                "noise_std": list(noise_std), "scc": repr(scc), "estimator": repr(estimator),
                "pc_attack": repr(pc_attack), "wref_attack": repr(wref_attack),
                "load": repr(load), "stop_on_trip": stop_on_trip,
                "load_feedforward": load_feedforward, "anti_windup": anti_windup}
    return result(trace, sc.tc, run.ctrl[:, 0], trips, scc, settings)


def result(trace: pd.DataFrame, tc: np.ndarray, ctrl: np.ndarray, trips: pd.DataFrame,
           scc: SafetyFilter | None, settings: dict,
           line_trips: pd.DataFrame | None = None) -> SimResult:
    """A :class:`SimResult` from a trace (``t``, states, ``p_load``), the control
    samples ``tc`` (s) and their generator-side rows ``ctrl`` (``CTRL_COLUMNS``;
    rows not reached are NaN), and the trips.  Adds ``pc_ref``, ``pc``,
    ``wref`` and ``scc_active`` (held values) to the trace and builds the
    controls and the alarm log."""
    t_end = float(trace["t"].iat[-1])
    n = int(np.searchsorted(tc, t_end + 1e-9, side="right"))
    n = min(n, int(np.sum(~np.isnan(ctrl[:, CTRL_COLUMNS.index("flags")]))))  # u_ref may be NaN
    c = pd.DataFrame(ctrl[:n], columns=list(CTRL_COLUMNS))
    flags = c["flags"].to_numpy().astype(np.int64)
    active = (flags & ACTIVE) != 0
    held = np.clip(np.searchsorted(tc, trace["t"].to_numpy() + 1e-9, side="right") - 1, 0,
                   max(n - 1, 0))
    trace.insert(1, "pc_ref", c["u_ref"].to_numpy()[held])
    trace.insert(2, "pc", c["u"].to_numpy()[held])
    trace["wref"] = c["wref"].to_numpy()[held]
    trace["scc_active"] = active[held]
    trace["h_freq"] = c["h_freq"].to_numpy()[held]
    trace["h_rocof"] = c["h_rocof"].to_numpy()[held]
    controls = pd.DataFrame({"t": tc[:n], "pc_ref": c["u_ref"], "pc": c["u"],
                             "scc_active": active, "dw_hat": c["dw_hat"],
                             "rocof_hat": c["rocof_hat"], "p_load_hat": c["p_load_hat"],
                             "h_freq": c["h_freq"], "h_rocof": c["h_rocof"]})
    alarm = (flags & ALARM_BITS) != 0
    a = c[alarm]
    fa = flags[alarm]
    explain = scc.reason if scc is not None else (lambda f: "")
    distinct, which = np.unique(fa, return_inverse=True)     # a few flag values, many rows
    binding = np.array([";".join(binding_names(f)) if f & ACTIVE else "" for f in distinct],
                       dtype=object)
    reason = np.array([explain(int(f)) for f in distinct], dtype=object)
    alarms = pd.DataFrame({
        "t": tc[:n][alarm], "u_ref": a["u_ref"], "u": a["u"], "binding": binding[which],
        "h_freq": a["h_freq"], "h_rocof": a["h_rocof"], "margin_freq": a["margin_freq"],
        "margin_rocof": a["margin_rocof"], "infeasible": (fa & INFEASIBLE) != 0,
        "outside": (fa & OUTSIDE) != 0, "invalid_input": (fa & INVALID) != 0,
        "solver_error": (fa & SOLVER_ERROR) != 0, "reason": reason[which]},
        columns=list(ALARM_COLUMNS)).reset_index(drop=True)
    return SimResult(trace, controls, trips, alarms, settings,
                     line_trips if line_trips is not None else
                     pd.DataFrame(columns=["line", "trip_t", "open_t"]))
