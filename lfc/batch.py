"""Many scenarios at once: :func:`simulate_batch`.

The linear plant, the local integral controller, the paper's SCC (exact
solver) and the relays of :func:`lfc.simulate`, advanced for N scenarios
together as arrays (the scenario axis is vectorized; time runs block by block,
one control period per block).  Scenarios come as a table, one row each; the
result is that table with the :meth:`SimResult.metrics` fields added.  No
trace is kept, so memory grows with N, not with N × duration.

Large tables are split into chunks run by a ``concurrent.futures.Executor``
(default: a process pool with one worker per core; a Dask cluster's
``Client.get_executor()`` works the same).  With ``out`` every finished chunk
is written to its own CSV file at once, so an interrupted run loses at most the
chunks in flight and a rerun computes only the missing ones.
"""

from __future__ import annotations

import hashlib
import math
import os
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np
import pandas as pd
from tqdm.auto import tqdm

from lfc.cbf import (CONFLICT_RULES, METHODS, OUTSIDE_RULES, PREDICTIONS, SafetyFilter,
                     alarm_mask)
from lfc.controller import sample_signal
from lfc.model import LFCParams, block_propagator, discretize
from lfc.relays import RELAY_NAMES, RelayBank, RelaySettings
from lfc.signals import Chirp, Ramp, Samples, Signal, Sinusoid, Square, Step
from lfc.simulate import check_timing

WAVEFORMS = ("sinusoid", "square", "chirp", "step", "ramp", "samples", "none")
CHANNELS = ("pc", "wref", "load")
REQUIRED = ("waveform", "channel", "amplitude", "freq_hz", "start", "alpha", "Ts")
READINGS = {"outside_rule": OUTSIDE_RULES, "conflict": CONFLICT_RULES,
            "prediction": PREDICTIONS}  # optional columns: the paper filter's readings
CHIRP_F0 = 0.1  # Hz, where every chirp starts
BATCH_METRICS = ("tripped", "first_trip_relay", "first_trip_t", "max_abs_dw_meas",
                 "max_abs_rocof_meas", "scc_active_fraction", "max_abs_modification",
                 "mean_abs_modification", "alarms")


def scenario_signal(row: pd.Series, duration: float) -> Signal | None:
    """The attack or load signal of one scenario row (None for ``"none"``).

    ``amplitude`` is in pu (pu/s for a ramp), ``freq_hz`` the frequency (the
    end frequency of a chirp, which starts at ``CHIRP_F0``), ``start`` and the
    optional ``stop`` in s (a chirp's default stop is ``duration``).  A
    ``"samples"`` row (free-form attacks) carries a sequence ``values`` (pu),
    one every ``sample_period`` s from ``start``, interpolated linearly (so a
    sequence on the control grid is applied exactly as given).
    """
    w, a, f, start = row["waveform"], row["amplitude"], row["freq_hz"], row["start"]
    stop = row.get("stop", math.inf)
    stop = math.inf if stop is None or pd.isna(stop) else float(stop)
    if w == "sinusoid":
        return Sinusoid(a, f, start=start, stop=stop)
    if w == "square":
        return Square(a, f, start=start, stop=stop)
    if w == "chirp":
        return Chirp(a, CHIRP_F0, f, start=start, stop=min(stop, duration))
    if w == "step":
        return Step(a, start=start)
    if w == "ramp":
        return Ramp(a, start=start, stop=stop)
    if w == "samples":  # free-form: one value per sample_period from start, held after
        values = np.asarray(row["values"], float)
        return Samples(start + row["sample_period"] * np.arange(len(values)), values)
    return None


def check_scenarios(scenarios: pd.DataFrame) -> None:
    """Raise ``ValueError`` naming the column and row of any invalid entry."""
    if not isinstance(scenarios, pd.DataFrame):
        raise ValueError(f"scenarios must be a pandas DataFrame, got {type(scenarios).__name__}")
    missing = [c for c in REQUIRED if c not in scenarios.columns]
    if missing:
        raise ValueError(f"scenarios is missing column(s) {missing}; required: {list(REQUIRED)}")
    for col, allowed in (("waveform", WAVEFORMS), ("channel", CHANNELS)):
        bad = ~scenarios[col].isin(allowed)
        if bad.any():
            raise ValueError(f"column {col!r} must be one of {allowed}; row "
                             f"{scenarios.index[bad][0]!r} has {scenarios[col][bad].iloc[0]!r}")
    for col in ("amplitude", "freq_hz", "start", "Ts"):
        values = pd.to_numeric(scenarios[col], errors="coerce")
        scc = scenarios["alpha"].notna()
        bad = ~np.isfinite(values) if col != "Ts" else scc & ~(values > 0)
        if col in ("freq_hz", "start"):
            bad |= values < 0
        if bad.any():
            raise ValueError(f"column {col!r} must be finite{' and > 0' if col == 'Ts' else ''}"
                             f"{' and >= 0' if col in ('freq_hz', 'start') else ''}; row "
                             f"{scenarios.index[bad][0]!r} has {scenarios[col][bad].iloc[0]!r}")
    for col, allowed in (("method", METHODS), *READINGS.items()):
        if col not in scenarios.columns:
            continue
        bad = ~scenarios[col].isin(allowed)
        if bad.any():
            raise ValueError(f"column {col!r} must be one of {allowed}; row "
                             f"{scenarios.index[bad][0]!r} has {scenarios[col][bad].iloc[0]!r}")
    alpha = pd.to_numeric(scenarios["alpha"], errors="coerce")
    bad = scenarios["alpha"].notna() & ~(alpha > 0)
    if bad.any():
        raise ValueError(f"column 'alpha' must be > 0 or NaN (no SCC); row "
                         f"{scenarios.index[bad][0]!r} has {scenarios['alpha'][bad].iloc[0]!r}")


def run_chunk(params: LFCParams, scenarios: pd.DataFrame, duration: float,
              relays: RelaySettings, dt: float, control_period: float) -> pd.DataFrame:
    """Simulate every row of ``scenarios`` (vectorized); return the metric columns
    ``BATCH_METRICS`` with the same index."""
    ratio = check_timing(duration, dt, control_period)
    return _Batch(params, scenarios, duration, relays, dt, ratio).run()


class _Batch:
    """N scenarios of :func:`run_chunk`, advanced one control period at a time."""

    def __init__(self, params: LFCParams, scenarios: pd.DataFrame, duration: float,
                 relays: RelaySettings, dt: float, ratio: int) -> None:
        self.params, self.index, self.ratio = params, scenarios.index, ratio
        self.n = n = len(scenarios)
        self.n_steps = int(round(duration / dt))
        self.n_ctrl = -(-self.n_steps // ratio)
        self.t = np.arange(self.n_steps + 1) * dt
        self.tc = np.arange(self.n_ctrl) * ratio * dt
        self.period = float(self.tc[1] - self.tc[0]) if self.n_ctrl > 1 else 0.0
        self.Phi, self.Gu, self.Gl = block_propagator(*discretize(params, dt), ratio)
        self._signals(scenarios, duration)
        self._filters(scenarios, relays)
        self.bank = RelayBank(relays, n)
        self.first_t = np.full(n, np.nan)
        self.first_relay = np.full(n, "", dtype=object)
        self.max_dw, self.max_rocof = np.zeros(n), np.zeros(n)
        self.active, self.alarms = np.zeros(n, int), np.zeros(n, int)
        self.max_mod, self.sum_mod = np.zeros(n), np.zeros(n)

    def _signals(self, scenarios: pd.DataFrame, duration: float) -> None:
        self.pc = np.zeros((self.n_ctrl, self.n))
        self.wref = np.zeros((self.n_ctrl, self.n))
        load_rows = np.flatnonzero(scenarios["channel"].to_numpy() == "load")
        self.load_rows, self.load = load_rows, np.zeros((self.n_steps + 1, len(load_rows)))
        col = {r: i for i, r in enumerate(load_rows)}
        for i, (_, row) in enumerate(scenarios.iterrows()):
            sig = scenario_signal(row, duration)
            if sig is None:
                continue
            if row["channel"] == "load":
                self.load[:, col[i]] = sample_signal(sig, self.t, "load")
            else:
                target = self.pc if row["channel"] == "pc" else self.wref
                target[:, i] = sample_signal(sig, self.tc, f"{row['channel']}_attack")

    def _filters(self, scenarios: pd.DataFrame, relays: RelaySettings) -> None:
        alpha = pd.to_numeric(scenarios["alpha"]).to_numpy(float)
        ts = pd.to_numeric(scenarios["Ts"]).to_numpy(float)
        method = scenarios.get("method", pd.Series("paper", index=scenarios.index)).to_numpy()
        readings = {c: scenarios[c].to_numpy() for c in READINGS if c in scenarios.columns}
        period = self.period if self.n_ctrl > 1 else self.ratio * float(self.t[1])
        self.groups = []
        keys = [(m, a, t, *(readings[c][i] for c in readings)) if m == "paper"
                else (m, 0.0, 0.0) for i, (m, a, t) in enumerate(zip(method, alpha, ts))]
        for key in sorted({k for k, a in zip(keys, alpha) if np.isfinite(a)}):
            rows = np.flatnonzero([k == key and np.isfinite(a) for k, a in zip(keys, alpha)])
            m, a, t = key[:3]
            filt = SafetyFilter(self.params, relays, alpha=a, Ts=t,
                                **dict(zip(readings, key[3:]))) if m == "paper" else \
                SafetyFilter(self.params, relays, method=m, period=period)
            self.groups.append((rows, filt))

    def run(self) -> pd.DataFrame:
        X = np.zeros((self.n, 5))
        pc_int = np.zeros(self.n)
        self._watch(0, X[None])
        for j in range(self.n_ctrl):
            k0 = j * self.ratio
            u_ref = pc_int + self.pc[j]
            u = self._filter(X, u_ref)
            pc_int = pc_int + self.params.k_i * self.period * (self.wref[j] - X[:, 3])
            X = self._advance(X, u, k0)
        return self._metrics()

    def _filter(self, X: np.ndarray, u_ref: np.ndarray) -> np.ndarray:
        u = u_ref.copy()
        for rows, filt in self.groups:
            u[rows], flags = filt.filter_batch(X[rows], u_ref[rows])
            self.active[rows] += flags["active"]
            self.alarms[rows] += alarm_mask(flags)
        mod = np.abs(u - u_ref)
        self.max_mod = np.maximum(self.max_mod, mod)
        self.sum_mod += mod
        return u

    def _advance(self, X: np.ndarray, u: np.ndarray, k0: int) -> np.ndarray:
        k1 = min(k0 + self.ratio, self.n_steps)
        m = k1 - k0
        pl = np.zeros((self.n, self.ratio))
        if len(self.load_rows):
            pl[self.load_rows, :m] = self.load[k0:k1].T
        block = X @ self.Phi.T + u[:, None] * self.Gu + pl @ self.Gl.T
        block = block.reshape(self.n, self.ratio, 5)[:, :m]  # (N, m, 5)
        self._watch(k0 + 1, block.transpose(1, 0, 2))
        return block[:, -1]

    def _watch(self, k: int, samples: np.ndarray) -> None:
        """Relays and maxima over plant samples ``k, k+1, ...`` (shape (T, N, 5))."""
        dw, rocof = samples[:, :, 3], samples[:, :, 4]
        self.max_dw = np.maximum(self.max_dw, np.abs(dw).max(axis=0))
        self.max_rocof = np.maximum(self.max_rocof, np.abs(rocof).max(axis=0))
        for relay, i, s in sorted(self.bank.update(self.t[k:k + len(samples)], dw, rocof),
                                  key=lambda f: (f[1], RELAY_NAMES.index(f[0]))):
            if np.isnan(self.first_t[s]):
                self.first_t[s], self.first_relay[s] = self.t[k + i], relay

    def _metrics(self) -> pd.DataFrame:
        n_ctrl = max(self.n_ctrl, 1)
        return pd.DataFrame({
            "tripped": ~np.isnan(self.first_t),
            "first_trip_relay": np.where(np.isnan(self.first_t), None, self.first_relay),
            "first_trip_t": self.first_t,
            "max_abs_dw_meas": self.max_dw, "max_abs_rocof_meas": self.max_rocof,
            "scc_active_fraction": self.active / n_ctrl,
            "max_abs_modification": self.max_mod,
            "mean_abs_modification": self.sum_mod / n_ctrl,
            "alarms": self.alarms}, index=self.index)


def simulate_batch(params: LFCParams, scenarios: pd.DataFrame, *, duration: float,
                   relays: RelaySettings | None = None, dt: float = 1e-3,
                   control_period: float = 0.01, executor: Executor | None = None,
                   chunk_size: int = 500, out: str | Path | None = None,
                   progress: bool = True) -> pd.DataFrame:
    """Simulate every scenario of a table; the same metrics as :func:`lfc.simulate`.

    Parameters
    ----------
    params : LFCParams
    scenarios : DataFrame
        One row per scenario with the columns ``REQUIRED``: ``waveform`` (one of
        ``WAVEFORMS``), ``channel`` (``"pc"`` command, ``"wref"`` frequency
        reference, ``"load"``), ``amplitude`` (pu; pu/s for a ramp), ``freq_hz``
        (Hz; a chirp's end frequency, from ``CHIRP_F0``), ``start`` (s),
        ``alpha`` (1/s; NaN runs without SCC) and ``Ts`` (s); optionally
        ``stop`` (s), ``values`` and ``sample_period`` (``"samples"`` rows)
        and ``method`` (``"paper"``, the default, or
        ``"certified"``; the certified filter ignores ``alpha`` and ``Ts`` but
        runs only where ``alpha`` is not NaN).  Other columns are carried through.
    duration, dt, control_period : float
        As in :func:`lfc.simulate` (s).
    relays : RelaySettings, optional
    executor : concurrent.futures.Executor, optional
        Runs the chunks; default a process pool with one worker per core
        (none for a single chunk).
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
        ``scenarios`` with the columns ``BATCH_METRICS`` added (the SCC
        metrics are 0 without SCC; ``first_trip_relay`` None and
        ``first_trip_t`` NaN without a trip).
    """
    check_scenarios(scenarios)
    check_timing(duration, dt, control_period)
    if out is not None and (scenarios["waveform"] == "samples").any():
        raise ValueError("out (chunk files) cannot hold 'samples' rows; run them without out")
    if not (isinstance(chunk_size, int) and chunk_size >= 1):
        raise ValueError(f"chunk_size must be an integer >= 1, got {chunk_size!r}")
    relays = relays or RelaySettings()
    args = (params, duration, relays, dt, control_period)
    chunks = [scenarios.iloc[i:i + chunk_size] for i in range(0, len(scenarios), chunk_size)]
    folder = Path(out) if out is not None else None
    if folder is not None:
        folder.mkdir(parents=True, exist_ok=True)
    results, todo = {}, []
    for i, chunk in enumerate(chunks):
        path = None if folder is None else folder / f"chunk_{i:05d}_{_digest(chunk, args)}.csv"
        if path is not None and path.exists():
            results[i] = pd.read_csv(path, index_col=0).set_axis(chunk.index)
        else:
            todo.append((i, chunk, path))
    with tqdm(total=len(scenarios), initial=sum(map(len, results.values())), unit="scenario",
              desc="simulate_batch", disable=not progress) as bar:
        for i, metrics in _execute(todo, args, executor):
            results[i] = metrics
            bar.update(len(metrics))
    if not chunks:
        return scenarios.assign(**{c: pd.Series(dtype=float) for c in BATCH_METRICS})
    metrics = pd.concat([results[i] for i in range(len(chunks))])
    metrics["first_trip_relay"] = metrics["first_trip_relay"].astype(object).where(
        metrics["tripped"].astype(bool), None)
    return pd.concat([scenarios, metrics.astype({"tripped": bool, "alarms": int})], axis=1)


def _execute(todo: list, args: tuple, executor: Executor | None):
    """Yield (chunk number, metrics) as chunks finish, writing each to its file."""
    def finish(i: int, metrics: pd.DataFrame, path: Path | None) -> tuple[int, pd.DataFrame]:
        if path is not None:
            tmp = path.with_suffix(".tmp")
            metrics.to_csv(tmp)
            tmp.replace(path)
        return i, metrics

    params, duration, relays, dt, cp = args
    if executor is None and len(todo) <= 1:
        for i, chunk, path in todo:
            yield finish(i, run_chunk(params, chunk, duration, relays, dt, cp), path)
        return
    pool = executor or ProcessPoolExecutor(max_workers=os.cpu_count() or 1)
    try:
        futures = {pool.submit(run_chunk, params, chunk, duration, relays, dt, cp): (i, path)
                   for i, chunk, path in todo}
        for fut in as_completed(futures):
            i, path = futures[fut]
            yield finish(i, fut.result(), path)
    finally:
        if executor is None:
            pool.shutdown(cancel_futures=True)


def _digest(chunk: pd.DataFrame, args: tuple) -> str:
    """Short hash of a chunk's scenarios and the run's settings (stale files never match)."""
    text = chunk.to_csv() + repr(args)
    return hashlib.sha256(text.encode()).hexdigest()[:12]
