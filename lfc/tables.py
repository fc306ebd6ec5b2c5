"""Many single-area scenarios at once: :func:`simulate_table`, which
:func:`lfc.simulate_many` runs for an ``LFCParams`` plant.

The engine of :func:`lfc.simulate` (:mod:`lfc.engine`) run over a table of
scenarios, one row each; the result is that table with the
:meth:`Result.metrics` fields added.  Each row may set its own plant, noise
(and so a Kalman estimate) and filter.  No trace is kept, so memory grows with
N, not with N × duration.

Large tables are split into chunks run by a ``concurrent.futures.Executor``
(default: a process pool with one worker per core; a Dask cluster's
``Client.get_executor()`` works the same).  With ``out`` every finished chunk
is written to its own CSV file at once, so an interrupted run loses at most the
chunks in flight and a rerun computes only the missing ones.  A chunk file is
named by a hash of its scenarios, the run's settings, the package version and
the core's source code (results of other code are never reused); it starts
with a line holding its row count and a SHA-256 of the rest, checked when it is
read (a damaged file is recomputed, with a :class:`ChunkWarning` naming it);
it is written under a unique temporary name and renamed into place, so
concurrent runs on one folder are safe.
"""

from __future__ import annotations

import difflib
import hashlib
import io
import math
import os
import warnings
from concurrent.futures import Executor, ProcessPoolExecutor
from dataclasses import fields, replace
from numbers import Integral, Real
from pathlib import Path

import numpy as np
import pandas as pd
from tqdm.auto import tqdm

from lfc._files import code_digest, write_atomic
from lfc._pool import completed
from lfc._validate import (ParameterTypeError, check_count, check_flag, check_folder,
                           is_finite, is_sequence)
from lfc.engine import METRICS
from lfc.estimation import STD
from lfc.filters import (CONFLICT_RULES, METHODS, OUTSIDE_RULES, PREDICTIONS, SafetyFilter,
                         options_of)
from lfc.filters.base import built_once
from lfc.filters.base import given as holds_value
from lfc.linear_area import check_timing, simulate_area
from lfc.model import LFCParams
from lfc.relays import RELAY_NAMES, RelaySettings, relays_or_default
from lfc.result import METRIC_KEYS
from lfc.run import Runner, only_for_metrics, register
from lfc.scenarios import Scenario, Scenarios
from lfc.sensor_attacks import Freeze, Replay, Scale
from lfc.signals import Chirp, Ramp, Samples, Signal, Sinusoid, Square, Step

WAVEFORMS = ("sinusoid", "square", "chirp", "step", "ramp", "samples", "scale", "freeze",
             "replay", "none")
READINGS_OF = ("scale", "freeze", "replay")    # what a sensor reports (lfc.sensor_attacks)
CHANNELS = ("pc", "wref", "load", "dw_meas", "rocof_meas")
REQUIRED = ("waveform", "channel", "amplitude", "freq_hz", "start", "alpha", "Ts")
READINGS = {"outside_rule": OUTSIDE_RULES, "conflict": CONFLICT_RULES,
            "prediction": PREDICTIONS}  # optional columns: the paper filter's readings
CHIRP_F0 = 0.1  # Hz, where every chirp starts
PLANT = ("M", "D", "tau_g", "tau_t", "droop")   # optional columns: the row's own plant
UNREAD_PARAMS = tuple(f.name for f in fields(LFCParams) if f.name not in PLANT)  # refused
NOISE = ("noise_w", "noise_rocof")             # optional: measurement noise std (pu, pu/s)
NOISE_FLAGS = ("declare_noise", "relay_noise")  # optional booleans that need noise
FLAGS = (*NOISE_FLAGS, "anti_windup")           # optional booleans
FILTER_COLUMNS = ("method", *dict.fromkeys(c for m in METHODS for c in options_of(m).COLUMNS))
# the columns that select a filter: each method's options declare theirs
INPUTS = tuple(dict.fromkeys((*REQUIRED, "stop", "values", "sample_period", *READINGS, *PLANT,
                              *NOISE, *FLAGS, "seed", *FILTER_COLUMNS)))
KNOWN = (*INPUTS, *METRIC_KEYS)      # any other column is a label, carried through
TYPO_CUTOFF = 0.85   # difflib ratio above which an unknown column is taken for a typo


def scenario_signal(row: pd.Series, duration: float) -> Signal | None:
    """The attack or load signal of one scenario row (None for ``"none"``).

    ``amplitude`` is in pu (pu/s for a ramp), ``freq_hz`` the frequency (the
    end frequency of a chirp, which starts at ``CHIRP_F0``), ``start`` and the
    optional ``stop`` in s (a chirp's default stop is ``duration``; a step with a
    stop is a pulse; a ramp holds its value after it).  A
    ``"samples"`` row (free-form attacks) carries a sequence ``values`` (pu),
    one every ``sample_period`` s from ``start``, interpolated linearly (so a
    sequence on the control grid is applied exactly as given).  On a sensor's
    channel, ``"scale"`` reports ``amplitude`` times the reading, ``"freeze"`` holds
    it, ``"replay"`` plays back the reports of ``amplitude`` s earlier
    (:mod:`lfc.sensor_attacks`).
    """
    w, a, f, start = row["waveform"], row["amplitude"], row["freq_hz"], row["start"]
    stop = row.get("stop", math.inf)
    stop = math.inf if stop is None or pd.isna(stop) else float(stop)
    if w == "sinusoid":
        return Sinusoid(a, f, start=start, stop=stop)
    if w == "square":
        return Square(a, f, start=start, stop=stop)
    if w == "chirp":          # one starting at or after the end never runs (simulate_table warns)
        return (Chirp(a, CHIRP_F0, f, start=start, stop=min(stop, duration))
                if start < duration else None)
    if w == "step":
        return Step(a, start=start, stop=stop)
    if w == "ramp":
        return Ramp(a, start=start, stop=stop)
    if w == "scale":
        return Scale(a, start=start, stop=stop)
    if w == "freeze":
        return Freeze(start=start, stop=stop)
    if w == "replay":
        return Replay(a, start=start, stop=stop)
    if w == "samples":  # free-form: one value per sample_period from start, held after
        values = np.asarray(row["values"], float)
        return Samples(start + row["sample_period"] * np.arange(len(values)), values)
    return None


def check_scenarios(scenarios: pd.DataFrame) -> pd.DataFrame:
    """Raise ``ValueError`` naming the column and row of any invalid entry; return
    ``scenarios`` with its numeric columns as floats (:func:`_check_numbers`)."""
    if not isinstance(scenarios, pd.DataFrame):
        raise ParameterTypeError(f"scenarios must be a pandas DataFrame, got "
                                 f"{type(scenarios).__name__}")
    twice = scenarios.columns[scenarios.columns.duplicated()].unique().tolist()
    if twice:
        raise ValueError(f"scenarios has column(s) {twice} more than once; give each once")
    missing = [c for c in REQUIRED if c not in scenarios.columns]
    if missing:
        raise ValueError(f"scenarios is missing column(s) {missing}; required: {list(REQUIRED)}")
    for col in scenarios.columns:
        if col in UNREAD_PARAMS:
            raise ValueError(f"column {col!r} is an LFCParams field that a scenario table "
                             f"does not set per row (it reads {', '.join(PLANT)}); give it "
                             f"in params")
        close = ([] if col in KNOWN or not isinstance(col, str) else
                 [k for k in KNOWN if k.lower() == col.lower()]
                 or difflib.get_close_matches(col, KNOWN, n=1, cutoff=TYPO_CUTOFF))
        if close:
            raise ValueError(f"column {col!r} is not a scenario column; did you mean "
                             f"{close[0]!r}? (scenario columns: {', '.join(INPUTS)}; a column "
                             f"not close to one of them is carried through as a label)")
    scenarios = _check_numbers(scenarios)
    for col, allowed in (("waveform", WAVEFORMS), ("channel", CHANNELS)):
        bad = ~scenarios[col].isin(allowed)
        if bad.any():
            raise ValueError(f"column {col!r} must be one of {allowed}; row "
                             f"{scenarios.index[bad][0]!r} has {scenarios[col][bad].iloc[0]!r}")
    for col in ("amplitude", "freq_hz", "start", "Ts"):
        values = pd.to_numeric(scenarios[col], errors="coerce")
        scc = scenarios["alpha"].notna()
        bad = ~np.isfinite(values) if col != "Ts" else scc & ~(np.isfinite(values) & (values > 0))
        if col in ("freq_hz", "start"):
            bad |= values < 0
        if bad.any():
            raise ValueError(f"column {col!r} must be finite{' and > 0' if col == 'Ts' else ''}"
                             f"{' and >= 0' if col in ('freq_hz', 'start') else ''}; row "
                             f"{scenarios.index[bad][0]!r} has {scenarios[col][bad].iloc[0]!r}")
    bad = scenarios["waveform"].isin(READINGS_OF) & ~scenarios["channel"].isin(
        ["dw_meas", "rocof_meas"])
    bad |= (scenarios["waveform"] == "replay") & ~(
        (scenarios["amplitude"] > 0) & (scenarios["amplitude"] <= scenarios["start"]))
    if bad.any():
        row = scenarios.loc[scenarios.index[bad][0]]
        raise ValueError(f"a {row['waveform']!r} row reads a sensor (channel 'dw_meas' or "
                         f"'rocof_meas'); a 'replay' row's amplitude is its lag, in (0, "
                         f"start] s; row {scenarios.index[bad][0]!r} has channel "
                         f"{row['channel']!r}, amplitude {row['amplitude']!r}")
    if "stop" in scenarios.columns:
        stop = pd.to_numeric(scenarios["stop"], errors="coerce")
        start = pd.to_numeric(scenarios["start"], errors="coerce")
        given = scenarios["stop"].notna() & ~np.isposinf(stop)
        bad = given & ~(stop > start)
        if bad.any():
            raise ValueError(f"column 'stop' must be > start (or NaN: none); row "
                             f"{scenarios.index[bad][0]!r} has {scenarios['stop'][bad].iloc[0]!r}")
        bad = given & scenarios["waveform"].isin(["samples", "none"])
        if bad.any():
            raise ValueError(f"column 'stop' has no meaning for a "
                             f"{scenarios['waveform'][bad].iloc[0]!r} row (row "
                             f"{scenarios.index[bad][0]!r}): leave it NaN")
    for col in ("values", "sample_period"):
        if col not in scenarios.columns:
            continue
        bad = (scenarios["waveform"] != "samples") & scenarios[col].map(holds_value)
        if bad.any():
            raise ValueError(f"column {col!r} has no meaning for a "
                             f"{scenarios['waveform'][bad].iloc[0]!r} row (row "
                             f"{scenarios.index[bad][0]!r}; only 'samples' rows read it): "
                             f"leave it empty (None or NaN)")
    if (scenarios["waveform"] == "samples").any():
        rows = scenarios[scenarios["waveform"] == "samples"]
        missing = [c for c in ("values", "sample_period") if c not in scenarios.columns]
        if missing:
            raise ValueError(f"'samples' rows need the column(s) {missing}")
        bad = ~rows["values"].map(lambda v: is_sequence(v) and len(v) > 0 and np.asarray(
            v).dtype.kind in "iuf")
        if bad.any():
            raise ParameterTypeError(
                f"column 'values' must hold a non-empty sequence of numbers (pu) on "
                f"'samples' rows; row {rows.index[bad][0]!r} has {rows['values'][bad].iloc[0]!r:.60}"
                f" (a CSV holds text: build such rows in Python)")
        period = pd.to_numeric(rows["sample_period"], errors="coerce")
        bad = ~(np.isfinite(period) & (period > 0))
        if bad.any():
            raise ValueError(f"column 'sample_period' must be finite and > 0 on 'samples' "
                             f"rows; row {rows.index[bad][0]!r} has "
                             f"{rows['sample_period'][bad].iloc[0]!r}")
    for col, allowed in (("method", METHODS), *READINGS.items()):
        if col not in scenarios.columns:
            continue
        bad = ~scenarios[col].isin(allowed)
        if col in READINGS:                # NaN: the default reading
            bad &= scenarios[col].notna()
        if bad.any():
            raise ValueError(f"column {col!r} must be one of {allowed}; row "
                             f"{scenarios.index[bad][0]!r} has {scenarios[col][bad].iloc[0]!r}")
    for col, low, what in ([(c, 0.0, "> 0") for c in PLANT if c != "D"] + [("D", -1.0, ">= 0")]
                           + [(c, -1.0, ">= 0") for c in NOISE]):
        if col not in scenarios.columns:
            continue
        values = pd.to_numeric(scenarios[col], errors="coerce")
        bad = scenarios[col].notna() & ~(np.isfinite(values) & (values > low)
                                         & ((values >= 0) | (low == 0.0)))
        if bad.any():
            raise ValueError(f"column {col!r} must be finite and {what} (or NaN); row "
                             f"{scenarios.index[bad][0]!r} has {scenarios[col][bad].iloc[0]!r}")
    for col in NOISE:
        if col not in scenarios.columns:
            continue
        values = pd.to_numeric(scenarios[col], errors="coerce")
        bad = (values > 0) & ~((values >= STD[0]) & (values <= STD[1]))
        if bad.any():
            raise ValueError(f"column {col!r} must be 0 (no noise) or lie in [{STD[0]}, "
                             f"{STD[1]}]; row {scenarios.index[bad][0]!r} has "
                             f"{scenarios[col][bad].iloc[0]!r}")
    for col in ("uncertainty", "margin"):
        if col not in scenarios.columns:
            continue
        values = pd.to_numeric(scenarios[col], errors="coerce")
        bad = scenarios[col].notna() & ~((values >= 0) & (values < 1))
        if bad.any():
            raise ValueError(f"column {col!r} must be in [0, 1) or NaN; row "
                             f"{scenarios.index[bad][0]!r} has {scenarios[col][bad].iloc[0]!r}")
    if "trips_per_hour" in scenarios.columns:
        rate = pd.to_numeric(scenarios["trips_per_hour"], errors="coerce")
        declared = (scenarios["declare_noise"].astype(bool) if "declare_noise" in scenarios
                    else pd.Series(False, scenarios.index))
        bad = scenarios["trips_per_hour"].notna() & ~((rate > 0) & np.isfinite(rate) & declared)
        if bad.any():
            raise ValueError(f"column 'trips_per_hour' must be finite and > 0 (or NaN), on rows "
                             f"with declare_noise; row {scenarios.index[bad][0]!r} has "
                             f"{scenarios['trips_per_hour'][bad].iloc[0]!r}")
    noisy = np.zeros(len(scenarios), bool)
    for col in NOISE:
        if col in scenarios.columns:
            noisy |= pd.to_numeric(scenarios[col], errors="coerce").fillna(0).to_numpy() > 0
    for col in FLAGS:
        if col not in scenarios.columns:
            continue
        bad = ~scenarios[col].map(lambda v: isinstance(v, (bool, np.bool_)))
        if bad.any():
            value = scenarios[col][bad].iloc[0]
            raise ParameterTypeError(f"column {col!r} must be True or False; row "
                                     f"{scenarios.index[bad][0]!r} has {value!r} "
                                     f"({type(value).__name__})")
        if col in NOISE_FLAGS:
            bad = scenarios[col].astype(bool).to_numpy() & ~noisy
            if bad.any():
                raise ValueError(f"column {col!r} is True on row {scenarios.index[bad][0]!r}, "
                                 f"which has no measurement noise ({', '.join(NOISE)} all 0)")
        else:
            bad = scenarios[col].astype(bool).to_numpy() & scenarios["alpha"].isna().to_numpy()
            if bad.any():
                raise ValueError(f"column {col!r} is True on row {scenarios.index[bad][0]!r}, "
                                 f"which has no SCC (alpha NaN): there is nothing to wind up "
                                 f"behind")
    if "seed" in scenarios.columns:
        seeds = pd.to_numeric(scenarios["seed"], errors="coerce").astype(float)  # NA: NaN
        bad = ~(np.isfinite(seeds) & (seeds == np.round(seeds)) & (seeds >= 0))
        if bad.any():
            raise ValueError(f"column 'seed' must be integers >= 0; row "
                             f"{scenarios.index[bad][0]!r} has {scenarios['seed'][bad].iloc[0]!r}")
    alpha = pd.to_numeric(scenarios["alpha"], errors="coerce")
    bad = scenarios["alpha"].notna() & ~(alpha > 0)
    if bad.any():
        raise ValueError(f"column 'alpha' must be > 0 or NaN (no SCC); row "
                         f"{scenarios.index[bad][0]!r} has {scenarios['alpha'][bad].iloc[0]!r}")
    _check_unused(scenarios)
    return scenarios


# the metric columns' dtypes where not float, for an empty table (as a full one has them)
EMPTY_DTYPES = {"tripped": bool, "first_trip_relay": object, "alarms": "int64",
                "outside": "int64"}
# the value of a filter column that asks for nothing: its option's default (else False,
# e.g. declare_noise)
NEUTRAL = {f.name: f.default for m in reversed(METHODS) for f in fields(options_of(m))}
# numeric columns: the signal's, the plant's, the noise's and every filter option that is
# a number (its annotation names float)
NUMERIC = ("amplitude", "freq_hz", "start", "stop", "sample_period", *PLANT, *NOISE, "seed",
           *dict.fromkeys(f.name for m in METHODS for f in fields(options_of(m))
                          if f.name in options_of(m).COLUMNS and "float" in str(f.type)))


def _check_numbers(scenarios: pd.DataFrame) -> pd.DataFrame:
    """``scenarios`` with its numeric columns in the engine's types: a string or a
    bool there is refused (pandas would coerce "3" to 3 and True to 1: a typed table
    says what it means); a ``Fraction``, a numpy scalar or a categorical column of
    numbers becomes floats; an integer too large for a float is refused naming it."""
    converted = {}
    for col in NUMERIC:
        if col not in scenarios.columns or scenarios[col].dtype.kind in "iuf":
            continue
        values = scenarios[col].astype(object)
        bad = values.map(lambda v: isinstance(v, (str, bytes, bool, np.bool_)))
        if bad.any():
            value = values[bad].iloc[0]
            raise ParameterTypeError(f"column {col!r} must hold numbers (or NaN); row "
                                     f"{scenarios.index[bad][0]!r} has {value!r:.60} "
                                     f"({type(value).__name__})")
        too_large = values.map(lambda v: isinstance(v, Integral) and not is_finite(v))
        if too_large.any():
            raise ValueError(f"column {col!r} has an integer too large for a float on row "
                             f"{scenarios.index[too_large][0]!r}")
        if values.map(lambda v: v is None or isinstance(v, Real)).all():
            converted[col] = values.map(lambda v: np.nan if v is None else float(v)
                                        ).astype(float)
    return scenarios.assign(**converted) if converted else scenarios


def _plain(value: object) -> object:
    """A numpy scalar as its Python value (for messages: ``7``, not ``np.int64(7)``)."""
    return value.item() if isinstance(value, np.generic) else value


def _check_unused(scenarios: pd.DataFrame) -> None:
    """A filter column set (not NaN, not its neutral value) on a row whose filter
    does not read it — a row without SCC, or of another method — is refused: it
    would be silently ignored."""
    has_scc = scenarios["alpha"].notna()
    method = (scenarios["method"] if "method" in scenarios.columns
              else pd.Series("paper", scenarios.index))
    for col in FILTER_COLUMNS:
        if col in ("method", "alpha", "Ts", *NOISE) or col not in scenarios.columns:
            continue
        users = [m for m in METHODS if col in options_of(m).COLUMNS]
        neutral = NEUTRAL.get(col, False)
        values = scenarios[col]
        set_ = values.notna() & (values != neutral if neutral is not None else True)
        bad = (set_ & ~(has_scc & method.isin(users))).to_numpy()
        if bad.any():
            at = int(np.flatnonzero(bad)[0])       # by position: row labels may repeat
            row = _plain(scenarios.index[at])
            whose = ("has no SCC (alpha NaN)" if not has_scc.iloc[at]
                     else f"is method {method.iloc[at]!r}")
            raise ValueError(f"column {col!r} is set ({_plain(values.iloc[at])!r}) on row "
                             f"{row!r}, which "
                             f"{whose}: only method(s) {users} read it; leave it NaN"
                             f"{'' if neutral is None else f' or {neutral!r}'} there")


def row_scenario(params: LFCParams, relays: RelaySettings, row: dict, duration: float,
                 control_period: float, built: dict) -> Scenario:
    """One checked table row as an :class:`lfc.Scenario` (its plant, filter,
    estimator, noise, seed, flags and signal); ``built`` holds the filters already
    built for these ``params`` and ``relays``."""
    signal = scenario_signal(row, duration)
    channel = row["channel"]
    noise = tuple(0.0 if pd.isna(v) else float(v)             # NaN: no noise, as checked
                  for v in (row.get(c, 0.0) for c in NOISE))
    return Scenario(plant=_plant(params, row),
                    filters={0: _filter(params, relays, row, control_period, built)},
                    estimator="kalman" if any(noise) else None, noise_std=noise,
                    seed=int(row.get("seed", 0)),
                    relay_noise=bool(row.get("relay_noise", False)),
                    anti_windup=bool(row.get("anti_windup", False)),
                    attacks={0: {channel: signal}} if channel != "load" else None,
                    loads={0: signal} if channel == "load" else None)


def run_chunk(params: LFCParams, scenarios: pd.DataFrame, duration: float,
              relays: RelaySettings, dt: float, control_period: float,
              lanes: bool = True) -> pd.DataFrame:
    """Simulate every row of ``scenarios`` with the engine (in SIMD lanes where
    it can, with ``lanes``); return the metric columns ``METRIC_KEYS`` with the
    same index."""
    check_timing(duration, dt, control_period)
    sc = Scenarios(params, duration=duration, dt=dt, control_period=control_period,
                   relays=relays)
    built: dict = {}     # this chunk's filters by their options (built_once keys by repr: slower)
    for row in scenarios.to_dict("records"):
        sc.add(row_scenario(params, relays, row, duration, control_period, built))
    run = sc.run(lanes=lanes)
    return metrics_frame(run.metrics[:, 0], sc.n_ctrl, scenarios.index)


def table_results(params: LFCParams, scenarios: pd.DataFrame, *, duration: float,
                  relays: RelaySettings | None = None, dt: float = 1e-3,
                  control_period: float = 0.01, progress: bool = True) -> list:
    """Every row of a scenario table run as :func:`lfc.simulate` runs it, with its
    trace: one :class:`~lfc.Result` per row, in the table's order,
    whose ``metrics()`` are the row :func:`simulate_table` gives (the same
    numbers).  ``simulate_many(params, table, keep="results")``."""
    scenarios = check_scenarios(scenarios)
    check_timing(duration, dt, control_period)
    check_flag("progress", progress)
    relays = relays_or_default(relays)
    scenarios = scenarios.drop(columns=[c for c in METRIC_KEYS if c in scenarios.columns])
    built: dict = {}
    out = []
    for row in tqdm(scenarios.to_dict("records"), desc="simulate_many", unit="scenario",
                    disable=not progress):
        s = row_scenario(params, relays, row, duration, control_period, built)
        out.append(simulate_area(s.plant, duration=duration, dt=dt,
                                 control_period=control_period, relays=relays,
                                 **s.keywords("area")))
    return out


def metrics_frame(metrics: np.ndarray, n_ctrl: int, index) -> pd.DataFrame:
    """The engine's ``metrics`` (N, len(METRICS)) as the columns ``METRIC_KEYS``
    (``n_ctrl`` control periods per scenario, ``index`` the rows' labels)."""
    m = dict(zip(METRICS, np.asarray(metrics).T))
    tripped = ~np.isnan(m["first_trip_t"])
    relay = np.array(RELAY_NAMES, dtype=object)[np.maximum(m["first_trip_relay"], 0)
                                                 .astype(int)]
    n_ctrl = max(n_ctrl, 1)
    # object, None where no trip (pandas would infer a string column with NaN there)
    first = pd.Series(np.where(tripped, relay, None), index=index, dtype=object)
    return pd.DataFrame({
        "tripped": tripped, "first_trip_relay": first,
        "first_trip_t": m["first_trip_t"], "max_abs_dw_meas": m["max_abs_dw_meas"],
        "max_abs_rocof_meas": m["max_abs_rocof_meas"],
        "scc_active_fraction": m["active"] / n_ctrl,
        "max_abs_modification": m["max_abs_modification"],
        "mean_abs_modification": m["sum_abs_modification"] / n_ctrl,
        "alarms": m["alarms"].astype(int), "final_abs_dw_meas": m["final_abs_dw_meas"],
        "outside": m["outside"].astype(int)}, columns=list(METRIC_KEYS), index=index)


def _plant(params: LFCParams, row: dict) -> LFCParams:
    """The row's plant: ``params`` with any of the ``PLANT`` columns the row sets."""
    own = {c: float(row[c]) for c in PLANT if c in row and pd.notna(row[c])}
    return replace(params, **own) if own else params


def _filter(params: LFCParams, relays: RelaySettings, row: dict, control_period: float,
            built: dict) -> SafetyFilter | None:
    """The row's filter (None without SCC): one object per distinct setting and
    process (:func:`~lfc.filters.base.built_once`), kept for later chunks
    (:func:`_execute` builds them before the workers fork, so they inherit them);
    ``built`` holds those of one chunk (same ``params`` and ``relays``) by their options."""
    if pd.isna(row["alpha"]):
        return None
    method = row.get("method", "paper")
    Options = options_of(method)
    options = {**Options.from_columns(row), **Options.for_period(control_period)}
    key = (method, tuple(sorted(options.items())))
    if key not in built:
        built[key] = built_once(lambda: SafetyFilter(params, relays, method=method, **options),
                                "SafetyFilter", params, relays, *key)
    return built[key]


def simulate_table(params: LFCParams, scenarios: pd.DataFrame, *, duration: float,
                   relays: RelaySettings | None = None, dt: float = 1e-3,
                   control_period: float = 0.01, executor: Executor | None = None,
                   chunk_size: int = 1000, out: str | Path | None = None,
                   progress: bool = True, lanes: bool = True) -> pd.DataFrame:
    """Simulate every scenario of a table; the same metrics as :func:`lfc.simulate`.

    Parameters
    ----------
    params : LFCParams
    scenarios : DataFrame
        One row per scenario with the columns ``REQUIRED``: ``waveform`` (one of
        ``WAVEFORMS``), ``channel`` (``"pc"`` command, ``"wref"`` frequency
        reference, ``"load"``, or what the sensors read: ``"dw_meas"``,
        ``"rocof_meas"``), ``amplitude`` (pu; pu/s for a ramp; the factor of a
        ``"scale"``, the lag in s of a ``"replay"``), ``freq_hz``
        (Hz; a chirp's end frequency, from ``CHIRP_F0``), ``start`` (s),
        ``alpha`` (1/s; NaN runs without SCC) and ``Ts`` (s); optionally
        ``stop`` (s), ``values`` and ``sample_period`` (``"samples"`` rows),
        ``method`` (``"paper"``, the default, or ``"certified"``; the certified
        filter ignores ``alpha`` and ``Ts`` but runs only where ``alpha`` is not
        NaN), the paper filter's readings ``outside_rule``, ``conflict``,
        ``prediction`` (NaN: the default reading), the row's own plant ``M``,
        ``D``, ``tau_g``, ``tau_t``, ``droop`` (the filter keeps the design
        model ``params``), measurement noise ``noise_w`` (pu), ``noise_rocof``
        (pu/s) with its ``seed`` (noise > 0: the generator side uses a Kalman
        estimate built, like the filter, on the design model ``params``, not on
        the row's plant), and the certified filter's
        ``uncertainty`` (its plant box, NaN or 0: the design model only),
        ``margin`` (NaN: 0) and
        ``declare_noise`` (True: it covers the row's noise, ``noise_std``) with
        its ``trips_per_hour`` (NaN: none), and
        ``relay_noise`` (True: the relays read through the row's noise too, as
        ``simulate(relay_noise=True)``) and ``anti_windup`` (as in
        :func:`lfc.simulate`; rows with SCC).  A row equals, bitwise,
        ``lfc.simulate(row_plant, scc=SafetyFilter(params, ...),
        estimator=KalmanFilter(params, control_period, meas_std=...),
        noise_std=..., seed=...)`` with the same attack (``tests/test_batch.py``).
        A filter column set on a row whose filter does not read it (a row
        without SCC, or of another method) is refused, and so is a column
        whose name is close to a scenario column's (a typo); other columns
        are carried through as labels.
    duration, dt, control_period : float
        As in :func:`lfc.simulate` (s).
    relays : RelaySettings, optional
    executor : concurrent.futures.Executor, optional
        Runs the chunks; default a process pool with one worker per core
        (none for a single chunk).
    lanes : bool
        Run the rows that allow it in SIMD lanes (:meth:`lfc.scenarios.Scenarios.run`;
        the same numbers bit for bit); False runs every row one at a time, the
        reference the benchmark compares against.
    chunk_size : int
        Scenarios per chunk (vectorized together).
    out : path, optional
        Folder for one CSV per finished chunk; chunks already there (same
        scenarios and settings) are read instead of recomputed.
    progress : bool
        Show a tqdm bar in scenarios per second.

    Returns
    -------
    DataFrame
        ``scenarios`` with the columns ``METRIC_KEYS`` added (a table that
        already has them, a result fed back, gets them recomputed; the SCC
        metrics are 0 without SCC; ``first_trip_relay`` None and
        ``first_trip_t`` NaN without a trip).
    """
    scenarios = check_scenarios(scenarios)
    check_timing(duration, dt, control_period)
    if executor is not None and not isinstance(executor, Executor):
        raise ParameterTypeError(f"executor must be a concurrent.futures.Executor or None, "
                                 f"got {executor!r:.80}")
    scenarios = scenarios.drop(columns=[c for c in METRIC_KEYS if c in scenarios.columns])
    if out is not None and (scenarios["waveform"] == "samples").any():
        raise ValueError("out (chunk files) cannot hold 'samples' rows; run them without out")
    check_count("chunk_size", chunk_size)
    check_flag("progress", progress)
    lanes = check_flag("lanes", lanes)
    late = (scenarios["waveform"] != "none") & (pd.to_numeric(scenarios["start"]) >= duration)
    if late.any():
        warnings.warn(f"{int(late.sum())} row(s) start their signal at or after the run's end "
                      f"(duration {duration} s) and run without it: row "
                      f"{scenarios.index[late][0]!r}, column 'start' = "
                      f"{float(scenarios['start'][late].iloc[0])} s", RuntimeWarning,
                      stacklevel=3)
    if out is not None:
        check_folder("out", out)
    relays = relays_or_default(relays)
    args = (params, duration, relays, dt, control_period, lanes)
    chunks = [scenarios.iloc[i:i + chunk_size] for i in range(0, len(scenarios), chunk_size)]
    folder = Path(out) if out is not None else None
    if folder is not None:
        folder.mkdir(parents=True, exist_ok=True)
    results, todo = {}, []
    for i, chunk in enumerate(chunks):
        path = None if folder is None else folder / f"chunk_{i:05d}_{_digest(chunk, args)}.csv"
        stored = (_read_chunk(path, chunk.index) if path is not None and path.exists()
                  else None)
        if stored is not None:
            results[i] = stored.set_axis(chunk.index)
        else:
            todo.append((i, chunk, path))
    with tqdm(total=len(scenarios), initial=sum(map(len, results.values())), unit="scenario",
              desc="simulate_many", disable=not progress) as bar:
        for i, metrics in _execute(todo, args, executor):
            results[i] = metrics
            bar.update(len(metrics))
    if not chunks:
        return scenarios.assign(**{c: pd.Series(dtype=EMPTY_DTYPES.get(c, float))
                                   for c in METRIC_KEYS})
    metrics = pd.concat([results[i] for i in range(len(chunks))])
    metrics["first_trip_relay"] = metrics["first_trip_relay"].astype(object).where(
        metrics["tripped"].astype(bool), None)
    return pd.concat([scenarios, metrics.astype({"tripped": bool, "alarms": int})], axis=1)


def _execute(todo: list, args: tuple, executor: Executor | None):
    """Yield (chunk number, metrics) as chunks finish, writing each to its file."""
    def finish(i: int, metrics: pd.DataFrame, path: Path | None) -> tuple[int, pd.DataFrame]:
        if path is not None:
            _write_chunk(path, metrics)
        return i, metrics

    params, duration, relays, dt, cp, lanes = args
    if executor is None and len(todo) <= 1:
        for i, chunk, path in todo:
            yield finish(i, run_chunk(params, chunk, duration, relays, dt, cp, lanes), path)
        return
    if executor is None:   # compiled code and filters once, before the workers fork
        run_chunk(params, todo[0][1].iloc[:1], duration, relays, dt, cp, lanes)
        for _, chunk, _ in todo:
            for row in chunk.drop_duplicates(
                    subset=[c for c in FILTER_COLUMNS if c in chunk]).to_dict("records"):
                _filter(params, relays, row, cp, {})
    pool = executor or ProcessPoolExecutor(max_workers=os.cpu_count() or 1)
    wait, futures = True, {}
    try:
        futures = {pool.submit(run_chunk, params, chunk, duration, relays, dt, cp, lanes):
                   (i, path) for i, chunk, path in todo}
        for fut in completed(futures):
            i, path = futures[fut]
            yield finish(i, fut.result(), path)
    except KeyboardInterrupt:          # stop the workers now, not after their chunks
        if executor is None:
            for proc in list((getattr(pool, "_processes", None) or {}).values()):
                proc.terminate()
            wait = False
        else:
            for fut in futures:
                fut.cancel()
        raise
    finally:
        if executor is None:
            pool.shutdown(wait=wait, cancel_futures=True)


class ChunkWarning(UserWarning):
    """A chunk file of ``simulate_many(out=...)`` was damaged and is recomputed."""


CHUNK_MAGIC = "# lfc-chunk"


def _write_chunk(path: Path, metrics: pd.DataFrame) -> None:
    """Write ``metrics`` with its row count, its seal (``path``'s name, a key of the
    chunk's scenarios, the run's settings and the code: :func:`_digest`) and a
    checksum of both, atomically (a unique temporary file renamed into place)."""
    body = metrics.to_csv()
    sealed = f"key={path.name} rows={len(metrics)}"
    header = (f"{CHUNK_MAGIC} {sealed} "
              f"sha256={hashlib.sha256((sealed + body).encode()).hexdigest()}\n")
    write_atomic(path, header + body)


def _read_chunk(path: Path, index: pd.Index) -> pd.DataFrame | None:
    """The metrics stored in ``path`` for the scenarios of ``index``, or None — with
    a :class:`ChunkWarning` naming the file — if it is unreadable, damaged, sealed
    for another request (copied or swapped from another chunk's or run's name) or
    not of these rows."""
    rows = len(index)
    def damaged(why: str) -> None:
        warnings.warn(f"chunk file {path} is damaged ({why}); recomputing it", ChunkWarning,
                      stacklevel=4)

    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        return damaged(f"unreadable: {err}")
    header, _, body = text.partition("\n")
    head = dict(f.split("=", 1) for f in header.removeprefix(CHUNK_MAGIC).split() if "=" in f)
    if not header.startswith(CHUNK_MAGIC) or set(head) != {"key", "rows", "sha256"}:
        return damaged("no lfc-chunk header")
    sealed = f"key={head['key']} rows={head['rows']}"
    if hashlib.sha256((sealed + body).encode()).hexdigest() != head["sha256"]:
        return damaged("checksum mismatch: cut short or changed")
    if head["key"] != path.name:
        return damaged(f"written for another request ({head['key']})")
    if head["rows"] != str(rows):
        return damaged(f"{head['rows']} rows stored, {rows} expected")
    metrics = pd.read_csv(io.StringIO(body), index_col=0)
    if len(metrics) != rows or list(metrics.columns) != list(METRIC_KEYS):
        return damaged("unexpected rows or columns")
    if list(metrics.index.astype(str)) != list(index.astype(str)):
        return damaged("stored for other rows")
    insane = _insane(metrics)
    return damaged(insane) if insane else metrics


def _insane(metrics: pd.DataFrame) -> str | None:
    """Why stored metrics cannot be a run's (None if they can): peaks and
    fractions finite and >= 0, counts integers >= 0, a trip time and relay
    exactly on the rows that tripped."""
    tripped = metrics["tripped"]
    if not tripped.isin([True, False]).all():
        return "'tripped' is not True or False"
    tripped = tripped.astype(bool)
    for col in ("max_abs_dw_meas", "max_abs_rocof_meas", "scc_active_fraction",
                "max_abs_modification", "mean_abs_modification", "final_abs_dw_meas",
                "alarms", "outside"):
        values = pd.to_numeric(metrics[col], errors="coerce")
        if not (np.isfinite(values) & (values >= 0)).all():
            return f"{col!r} is not finite and >= 0"
        if col in ("alarms", "outside") and not (values == np.round(values)).all():
            return f"{col!r} is not a count"
    if (metrics["scc_active_fraction"] > 1).any():
        return "'scc_active_fraction' > 1"
    t = pd.to_numeric(metrics["first_trip_t"], errors="coerce")
    if not ((tripped & (t >= 0)) | (~tripped & t.isna())).all():
        return "'first_trip_t' is not a time >= 0 exactly where 'tripped'"
    relay = metrics["first_trip_relay"]
    if not ((tripped & relay.isin(RELAY_NAMES)) | (~tripped & relay.isna())).all():
        return "'first_trip_relay' is not a relay exactly where 'tripped'"
    return None


def _digest(chunk: pd.DataFrame, args: tuple) -> str:
    """Short hash of a chunk's scenarios, the run's settings and the code (stale
    files never match)."""
    text = chunk.to_csv() + repr(args) + code_digest()
    return hashlib.sha256(text.encode()).hexdigest()[:12]

# -- the table's rows as lfc.Scenario, and back ----------------------------------------------
#: the waveform a table row names, by signal class (:func:`scenario_signal`'s inverse)
SIGNAL_WAVEFORMS = {Sinusoid: "sinusoid", Square: "square", Chirp: "chirp", Step: "step",
                    Ramp: "ramp", Samples: "samples", Scale: "scale", Freeze: "freeze",
                    Replay: "replay"}


def table_scenarios(table: pd.DataFrame, params: LFCParams, *, duration: float,
                    relays: RelaySettings | None = None,
                    control_period: float = 0.01) -> list[Scenario]:
    """Each row of a scenario table (:func:`simulate_table`'s columns, checked as it
    checks them) as an :class:`lfc.Scenario` of the area ``params``, its filter built
    on ``params`` with ``relays`` (default IEEE 1547 Cat. III) for ``control_period``
    (s); ``duration`` (s) ends a chirp."""
    relays = relays_or_default(relays)
    built: dict = {}
    return [row_scenario(params, relays, row, duration, control_period, built)
            for row in check_scenarios(table).to_dict("records")]


def scenario_row(scenario: Scenario, params: LFCParams) -> dict:
    """``scenario`` as one row of a scenario table for the area ``params``
    (:func:`table_scenarios` reads it back to the same scenario): one signal of a
    ``SIGNAL_WAVEFORMS`` class on ``pc``, ``wref``, the load or a sensor, or none; a filter built
    on ``params`` or none; the Kalman estimate exactly where there is noise; the
    plant's ``M``, ``D``, ... where it is not ``params``.  ``ValueError`` naming what
    a table cannot hold."""
    kw = scenario.keywords("area")
    given = [(c, s) for c, s in (("pc", kw["pc_attack"]), ("wref", kw["wref_attack"]),
                                 ("load", kw["load"]),
                                 ("dw_meas", kw.get("dw_meas_attack")),
                                 ("rocof_meas", kw.get("rocof_meas_attack")))
             if s is not None]
    if len(given) > 1:
        raise ValueError(f"a table row holds one signal, got {[c for c, _ in given]}")
    channel, signal = given[0] if given else ("pc", None)
    row = {"channel": channel, **_waveform(signal)}
    noisy = any(s > 0 for s in scenario.noise_std)
    row.update(noise_w=scenario.noise_std[0], noise_rocof=scenario.noise_std[1],
               seed=scenario.seed, relay_noise=scenario.relay_noise,
               anti_windup=scenario.anti_windup)
    row.update(_filter_columns(kw["scc"], params, row))
    row.setdefault("declare_noise", False)        # a table's flags are in every row
    if (scenario.estimator is not None) != noisy or (noisy and scenario.estimator != "kalman"):
        raise ValueError("a table row's estimator is the Kalman filter exactly where "
                         "there is noise")
    if kw["load_feedforward"]:
        raise ValueError("a table row has no load feed-forward")
    if "following_load" in kw:
        raise ValueError("a table row has no following load (lfc.load_attacks.FollowingLoad): "
                         "give it to lfc.simulate or a grid's simulate_many")
    if "sensors" in kw:
        raise ValueError("a table row has no redundant sensors (lfc.sensors.Redundant): give "
                         "them to lfc.simulate or simulate_many of a list of Scenario")
    plant = scenario.plant
    if plant is not None and plant != params:
        if not isinstance(plant, LFCParams) or any(
                getattr(plant, f) != getattr(params, f) for f in UNREAD_PARAMS):
            raise ValueError(f"a table row's plant differs from params only in {PLANT}")
        row.update({f: getattr(plant, f) for f in PLANT})
    return row


def _waveform(signal) -> dict:
    """A table row's signal columns for ``signal`` (None: ``"none"``)."""
    if signal is None:
        return {"waveform": "none", "amplitude": 0.0, "freq_hz": 0.0, "start": 0.0}
    kind = SIGNAL_WAVEFORMS.get(type(signal))
    if kind is None:
        raise ValueError(f"a table row's signal is one of {sorted(SIGNAL_WAVEFORMS.values())}, "
                         f"got "
                         f"{type(signal).__name__}")
    if kind == "samples":
        times, values = np.asarray(signal.t, float), np.asarray(signal.values, float)
        period = float(times[1] - times[0]) if len(times) > 1 else 1.0
        if not np.allclose(np.diff(times), period, rtol=0, atol=1e-12):
            raise ValueError("a table row's samples are uniform in time")
        return {"waveform": kind, "amplitude": 0.0, "freq_hz": 0.0,
                "start": float(times[0]), "values": values.tolist(), "sample_period": period}
    if kind == "chirp":
        if signal.f0_hz != CHIRP_F0:
            raise ValueError(f"a table row's chirp starts at {CHIRP_F0} Hz, got {signal.f0_hz}")
        return {"waveform": kind, "amplitude": signal.amplitude, "freq_hz": signal.f1_hz,
                "start": signal.start, "stop": signal.stop}
    if getattr(signal, "phase", 0.0) != 0.0:
        raise ValueError("a table row's sinusoid has no phase")
    amplitude = {"step": "value", "ramp": "slope", "scale": "factor", "replay": "lag"}.get(
        kind, "amplitude")
    return {"waveform": kind, "amplitude": getattr(signal, amplitude, 0.0),
            "freq_hz": getattr(signal, "freq_hz", 0.0), "start": signal.start,
            "stop": signal.stop}


def _filter_columns(scc, params: LFCParams, row: dict) -> dict:
    """A table row's filter columns for ``scc`` (None: ``alpha`` NaN), checked by
    reading them back as :func:`lfc.tables.simulate_table` does (``row`` holds the
    row's noise columns, which the certified filter's declared noise reads)."""
    if scc is None:
        return {"method": "paper", "alpha": math.nan, "Ts": math.nan}
    if not isinstance(scc, SafetyFilter) or scc.params != params:
        raise ValueError("a table row's filter is a SafetyFilter built on the table's model "
                         "(params)")
    options = scc.options.as_dict()
    columns = {"method": scc.method, "alpha": NEUTRAL["alpha"], "Ts": NEUTRAL["Ts"],
               **scc.options.to_columns()}
    Options = options_of(scc.method)
    read = {**Options.from_columns({**row, **columns}),
            **Options.for_period(options.get("control_period", 0.0))}
    lost = sorted({k for k, v in read.items() if k in options and v != options[k]}
                  | {k for k in scc.options.changed() if k not in read})
    if lost:
        raise ValueError(f"a table row cannot hold the filter's option(s) {lost}")
    return columns


# -- the area's runner (lfc.run): simulate and simulate_many of an LFCParams ---------------
def _simulate(plant: LFCParams, *, duration: float, design=None, **scenario):
    return simulate_area(plant, duration=duration, **scenario)


def _simulate_many(plant: LFCParams, scenarios: pd.DataFrame, *, duration: float,
                   design=None, keep: str = "metrics", **kwargs):
    if isinstance(scenarios, list):
        return scenario_list(plant, scenarios, duration=duration, keep=keep, **kwargs)
    if keep == "metrics":
        return simulate_table(plant, scenarios, duration=duration, **kwargs)
    only_for_metrics(kwargs, ("executor", "chunk_size", "out", "lanes"))
    return table_results(plant, scenarios, duration=duration, **kwargs)


def scenario_list(params: LFCParams, scenarios: list, *, duration: float,
                  relays: RelaySettings | None = None, dt: float = 1e-3,
                  control_period: float = 0.01, keep: str = "metrics", lanes: bool = True,
                  progress: bool = False) -> pd.DataFrame | list:
    """``simulate_many`` of the area ``params`` over a list of
    :class:`~lfc.scenarios.Scenario` (each may carry its own ``plant``: the filters
    and the local controller keep ``params``), in this process, in SIMD lanes where
    they allow it: one row per scenario (``scenario``, ``area`` 0 and the metrics, as
    a grid's), or with ``keep="results"`` one result each (a scenario with its own
    plant is refused there: :func:`lfc.simulate` runs the plant it is given)."""
    from lfc.scenarios import Scenario
    bad = next((i for i, s in enumerate(scenarios) if not isinstance(s, Scenario)), None)
    if bad is not None:
        raise ParameterTypeError(f"scenarios must be a DataFrame or a list of Scenario; "
                                 f"scenarios[{bad}] is a {type(scenarios[bad]).__name__}")
    check_timing(duration, dt, control_period)
    check_flag("progress", progress)
    relays = relays_or_default(relays)
    if keep == "results":
        own = next((i for i, s in enumerate(scenarios) if s.plant is not None), None)
        if own is not None:
            raise ValueError(f"scenarios[{own}].plant: keep='results' runs each scenario as "
                             f"lfc.simulate does, on the plant given")
        return [simulate_area(params, duration=duration, relays=relays, dt=dt,
                              control_period=control_period, **s.keywords("area"))
                for s in tqdm(scenarios, desc="simulate_many", unit="scenario",
                              disable=not progress)]
    sc = Scenarios(params, duration=duration, dt=dt, control_period=control_period,
                   relays=relays)
    for s in scenarios:
        sc.add(s)
    run = sc.run(lanes=check_flag("lanes", lanes))
    table = metrics_frame(run.metrics[:, 0], sc.n_ctrl, pd.RangeIndex(len(scenarios)))
    table.insert(0, "area", 0)
    table.insert(0, "scenario", np.arange(len(scenarios)))
    return table


register(LFCParams, Runner("area", "area", "an LFCParams", _simulate, _simulate_many))
