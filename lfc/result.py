"""What a run returns: :class:`Result`, one type for every plant.

A run of one area (the linear model, the ANDES microgrid) and a run of a grid (the linear
grid, Kundur's and the IEEE 39-bus system on ANDES) return the same type.  A grid of one
area is an area: an area's result is its own only area (``result.areas == (result,)``),
and a grid's ``areas`` are each area's result, as the area would report it.  The metrics
are defined once (``METRIC_KEYS``): :meth:`Result.table` is the result's
:func:`lfc.simulate_many` rows, one per area, on every plant.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from lfc._validate import check_folder, check_index, check_positive
from lfc.engine import CTRL_COLUMNS
from lfc.filters import SafetyFilter, binding_names
from lfc.filters.base import (ACTIVE, ALARM_BITS, INFEASIBLE, INVALID, MAX_ABS_INPUT, OUTSIDE,
                              SOLVER_ERROR)
from lfc.model import STATES
from lfc.multiarea import MultiAreaParams

__all__ = ["ALARM_COLUMNS", "METRIC_KEYS", "Result", "area_result", "grid_result",
           "metrics_table"]
METRIC_KEYS = ("tripped", "first_trip_relay", "first_trip_t", "max_abs_dw_meas",
               "max_abs_rocof_meas", "scc_active_fraction", "max_abs_modification",
               "mean_abs_modification", "alarms", "final_abs_dw_meas", "outside")
"""The metrics of an area's run, defined once: :meth:`Result.metrics` and every row of
:func:`lfc.simulate_many` (the compiled loop's accumulators) have these keys."""
ALARM_COLUMNS = ("t", "u_ref", "u", "binding", "h_freq", "h_rocof", "margin_freq",
                 "margin_rocof", "infeasible", "outside", "invalid_input", "solver_error",
                 "reason")
#: an area's frames (a grid's: every area's, after an ``area`` column)
FRAMES = ("controls", "trips", "alarms", "line_trips")
LINE_TRIP_COLUMNS = ("line", "trip_t", "open_t")


@dataclass
class Result:
    """Outcome of one run, of an area or of a grid.

    Attributes
    ----------
    trace : DataFrame
        Every plant step.  An area's: ``t`` (s), ``pc_ref`` and ``pc`` (incoming
        and applied command, pu), the states ``dPg, dPm, dw, dw_meas`` (pu) and
        ``rocof_meas`` (pu/s), ``p_load`` (pu), ``wref`` (pu), ``scc_active``
        (bool) and the filter's barrier values ``h_freq`` (pu^2) and ``h_rocof``
        ((pu/s)^2) at the last control sample (NaN without a filter); in a grid
        also ``p_tie`` (export deviation, pu), ``p_net`` (the area's net
        disturbance, pu) and ``ace`` (pu).  A grid's: ``t`` and each area's columns
        with the suffix ``_{i}``.
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
        Line protection operations (the ANDES microgrid): ``line``, ``trip_t``
        (relay decision, s) and ``open_t`` (breaker open, s).
    grid : tuple of Result
        A grid's areas, each as the area would report it (its trace's ``p_load``
        is the area's own load; its alarms are its filter's); empty for an area.
        A grid's ``controls``, ``trips``, ``alarms`` and ``line_trips`` are every
        area's, after an ``area`` column (:meth:`of_grid`).
    """

    trace: pd.DataFrame
    controls: pd.DataFrame
    trips: pd.DataFrame
    alarms: pd.DataFrame
    settings: dict = field(default_factory=dict)
    line_trips: pd.DataFrame = field(
        default_factory=lambda: pd.DataFrame(columns=list(LINE_TRIP_COLUMNS)))
    grid: tuple[Result, ...] = ()

    @classmethod
    def of_grid(cls, areas: tuple[Result, ...], trace: pd.DataFrame,
                settings: dict) -> Result:
        """A grid's result: its areas' results, the grid's ``trace`` and ``settings``;
        its frames are the areas' (``FRAMES``), after an ``area`` column."""
        frames = {name: pd.concat([getattr(r, name).assign(area=a) for a, r in enumerate(areas)
                                   if len(getattr(r, name))] or
                                  [getattr(areas[0], name).assign(area=0)], ignore_index=True)
                  for name in FRAMES}
        frames = {name: f[["area", *(c for c in f.columns if c != "area")]]
                  for name, f in frames.items()}
        return cls(trace, frames["controls"], frames["trips"], frames["alarms"], settings,
                   frames["line_trips"], tuple(areas))

    @property
    def areas(self) -> tuple[Result, ...]:
        """Each area's result: ``(self,)`` for an area (a grid of one area)."""
        return self.grid or (self,)

    @property
    def n_areas(self) -> int:
        """The number of areas."""
        return len(self.areas)

    def metrics(self) -> dict:
        """An area's summary numbers (JSON-serializable), keys ``METRIC_KEYS``: the
        values of a :func:`lfc.simulate_many` row of the same scenario (where the row
        has NaN, no trip, this has None); a grid's: each area's, by area.

        ``tripped``, ``first_trip_relay``, ``first_trip_t`` (s): the first relay
        trip; ``max_abs_dw_meas`` (pu), ``max_abs_rocof_meas`` (pu/s) over the
        trace, ``final_abs_dw_meas`` (pu) at its end; ``scc_active_fraction``
        and ``max_abs_modification``, ``mean_abs_modification`` (pu,
        ``|pc - pc_ref|``) over the control samples (0 where ``pc_ref`` is
        non-finite or beyond ``MAX_ABS_INPUT``: invalid input, held); ``alarms`` (control
        samples that alarmed), ``outside`` (of them, flagged ``outside``).
        """
        if self.grid:
            return {i: r.metrics() for i, r in enumerate(self.grid)}
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

    def with_alarms(self, rows: dict[int, pd.DataFrame]) -> Result:
        """This result with ``rows[area]`` (``ALARM_COLUMNS``, in time order: e.g.
        :func:`lfc.sensors.alarm_rows`) added to each area's alarm log, those at or
        before its trace's end, in time order (the filter's first at a tie)."""
        if not rows:
            return self
        end = float(self.trace["t"].iat[-1]) + 1e-9
        areas = []
        for a, r in enumerate(self.areas):
            extra = rows.get(a)
            if extra is not None and len(extra := extra[extra.t <= end]):
                log = pd.concat([r.alarms, extra], ignore_index=True) if len(r.alarms) \
                    else extra.reset_index(drop=True)
                r = replace(r, alarms=log.sort_values("t", kind="stable")
                            .reset_index(drop=True))
            areas.append(r)
        return Result.of_grid(tuple(areas), self.trace, self.settings) if self.grid \
            else areas[0]

    def table(self) -> pd.DataFrame:
        """The metrics as :func:`lfc.simulate_many` rows (:func:`metrics_table`), one per
        area: ``area`` and ``METRIC_KEYS``."""
        return metrics_table([r.metrics() for r in self.areas])

    @property
    def tripped(self) -> bool:
        """Whether a relay tripped in any area."""
        return bool(len(self.trips))

    @property
    def first_trip(self) -> dict | None:
        """The first relay trip, ``{"relay": name, "t": s}`` (in a grid also
        ``"area"``: the first area's, at a tie), or None."""
        if not len(self.trips):
            return None
        row = self.trips.sort_values("t", kind="stable").iloc[0]
        first = {"relay": str(row["relay"]), "t": float(row["t"])}
        return {**first, "area": int(row["area"])} if self.grid else first

    @property
    def first_outside(self) -> dict | None:
        """The first control sample a filter flagged ``outside``, ``{"t": s}`` (in a
        grid also ``"area"``: the first area's, at a tie), or None."""
        flagged = self.alarms[self.alarms["outside"].astype(bool)]
        if not len(flagged):
            return None
        row = flagged.sort_values("t", kind="stable").iloc[0]
        return {"t": float(row["t"]), "area": int(row["area"])} if self.grid \
            else {"t": float(row["t"])}

    @property
    def warning_time(self) -> float | None:
        """The operator's warning: the first trip's time less the first ``outside``
        flag's (s; negative if the trip came first), or None if there was no trip or no
        flag."""
        trip, flag = self.first_trip, self.first_outside
        return None if trip is None or flag is None else trip["t"] - flag["t"]

    def load_alarms(self, threshold: float, window: float = 0.1) -> pd.DataFrame:
        """The control samples at which an area's load, as its controller side holds it,
        had moved by more than ``threshold`` (pu) within the last ``window`` (s): the
        alarm that the load, not a command, is moving.

        The load is the ``controls`` frame's ``p_load_hat``: with the exact state on a
        grid, or ``load_feedforward`` on one area, the load itself (then the alarm is
        exact: a move beyond ``threshold`` within ``window`` is flagged at the first
        sample that sees it); with ``estimator="kalman"``, its Kalman filter's estimate.
        That filter takes the applied command as a known input, so its estimate is the
        same function of the loads and the noise whatever the commands: a command attack
        alone never changes these alarms.  On one area with the exact state and no load
        given, ``p_load_hat`` is 0 and nothing is flagged.  ``window`` (s) should cover
        the estimate's lag (``docs/guarantees.md``: the threshold and window measured).

        Returns
        -------
        DataFrame
            ``t`` (s), ``p_load_hat`` (pu) and ``moved`` (pu: the largest
            ``|p_load_hat(t) - p_load_hat(s)|`` over ``t - window <= s < t``), one row per
            flagged sample; in a grid after an ``area`` column.

        Raises
        ------
        ValueError
            ``threshold`` not > 0 or ``window`` not > 0.
        """
        check_positive("threshold", threshold)
        check_positive("window", window)
        frames = []
        for a, r in enumerate(self.areas):
            t, p = r.controls["t"].to_numpy(), r.controls["p_load_hat"].to_numpy()
            moved = np.zeros_like(p)
            for lag in range(1, len(p)):
                if not t[lag] - t[0] <= window * (1 + 1e-9):
                    break
                moved[lag:] = np.maximum(moved[lag:], np.abs(p[lag:] - p[:-lag]))
            hit = moved > threshold
            frame = pd.DataFrame({"t": t[hit], "p_load_hat": p[hit], "moved": moved[hit]})
            frames.append(frame.assign(area=a)[["area", *frame.columns]] if self.grid
                          else frame)
        return pd.concat(frames, ignore_index=True) if self.grid else frames[0]

    def disturbance_step(self, area: int = 0) -> float:
        """The largest move of area ``area``'s net disturbance (``p_net``; an area's
        own run: its load ``p_load``) within one control period, from its value at the
        period's sample to any plant step up to the next sample (pu).  Assumption (c)
        of the certified filters' guarantee (:mod:`lfc.filters.certified`) held on
        this run where it is at most the filter's ``load_bound``."""
        area = check_index("area", area, self.n_areas)
        t = self.trace["t"].to_numpy()
        w = (self.trace[f"p_net_{area}"] if self.grid else self.trace["p_load"]).to_numpy()
        period = np.floor(t / self.settings["control_period"] + 1e-9).astype(int)
        first = np.searchsorted(period, period)          # each step's period's sample
        starts = np.unique(first)
        within = np.abs(w - w[first]).max()
        to_next = np.abs(np.diff(w[starts])).max() if len(starts) > 1 else 0.0
        return float(max(within, to_next))

    def save(self, directory: str | Path) -> Path:
        """Write ``trace.csv``, ``metrics.json`` and ``settings.json`` into
        ``directory`` (created), and an area's ``controls.csv``, ``trips.csv``,
        ``alarms.csv`` and ``line_trips.csv`` (a grid's areas: each area's files in
        ``area_{i}/``)."""
        out = check_folder("directory", directory)
        out.mkdir(parents=True, exist_ok=True)
        self.trace.to_csv(out / "trace.csv", index=False)
        (out / "metrics.json").write_text(json.dumps(self.metrics(), indent=2))
        (out / "settings.json").write_text(json.dumps(self.settings, indent=2, default=str))
        if self.grid:
            for i, r in enumerate(self.grid):
                r.save(out / f"area_{i}")
        else:
            for name in FRAMES:
                getattr(self, name).to_csv(out / f"{name}.csv", index=False)
        return out


def metrics_table(per_area: list[dict]) -> pd.DataFrame:
    """Each area's :meth:`Result.metrics` as rows: ``area`` then ``METRIC_KEYS``,
    as :func:`lfc.simulate_many` gives them (where no relay tripped,
    ``first_trip_relay`` None and ``first_trip_t`` NaN)."""
    table = pd.DataFrame([{"area": a, **m} for a, m in enumerate(per_area)],
                         columns=["area", *METRIC_KEYS])
    table["first_trip_t"] = table["first_trip_t"].astype(float)
    table["first_trip_relay"] = table["first_trip_relay"].astype(object).where(
        table["tripped"].astype(bool), None)
    return table


def area_result(trace: pd.DataFrame, tc: np.ndarray, ctrl: np.ndarray, trips: pd.DataFrame,
                scc: SafetyFilter | None, settings: dict,
                line_trips: pd.DataFrame | None = None) -> Result:
    """An area's :class:`Result` from a trace (``t``, states, ``p_load``), the control
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
    return Result(trace, controls, trips, alarms, settings,
                  line_trips if line_trips is not None else
                  pd.DataFrame(columns=list(LINE_TRIP_COLUMNS)))


def grid_result(params: MultiAreaParams, t: np.ndarray, states: np.ndarray,
                p_load: np.ndarray, p_tie: np.ndarray, trips: list[pd.DataFrame],
                tc: np.ndarray, ctrl: list[np.ndarray], filters: dict,
                settings: dict, p_net: np.ndarray | None = None) -> Result:
    """A grid's :class:`Result` from what a plant logged: times ``t`` (s),
    ``states`` (samples, areas, 5), each area's load and tie-line export
    (samples, areas; pu), its trips, the control samples ``tc`` and each area's
    generator-side rows ``ctrl`` (:func:`area_result`); ``p_net`` the
    net disturbance if metered (default load plus export)."""
    areas, columns = [], {"t": t}
    for a in range(params.n_areas):
        trace = pd.DataFrame({"t": t})
        for k, name in enumerate(STATES):
            trace[name] = states[:, a, k]
        trace["p_load"] = p_load[:, a]
        res = area_result(trace, tc, ctrl[a], trips[a], filters.get(a), {**settings, "area": a})
        areas.append(res)
        trace = res.trace
        trace["p_tie"] = p_tie[:, a]
        trace["p_net"] = trace["p_load"] + trace["p_tie"] if p_net is None else p_net[:, a]
        trace["ace"] = trace["p_tie"] + params.biases()[a] * trace["dw_meas"]
        columns.update({f"{c}_{a}": trace[c].to_numpy() for c in trace.columns if c != "t"})
    return Result.of_grid(tuple(areas), pd.DataFrame(columns), settings)
