"""The batched simulator: equal to lfc.simulate, maps, resume, executors, bad input."""

import subprocess
import sys
import time
from concurrent.futures import Executor, Future

import numpy as np
import pandas as pd
import pytest
import tiers
from hypothesis import given, settings
from hypothesis import strategies as st

import lfc
from lfc import simulate_many
from lfc.tables import scenario_signal
from lfc.result import METRIC_KEYS
from same_metrics import same_metrics
from lfc.experiments.redteam import piecewise_attack_table

P = lfc.LFCParams()
CHANNEL_ARG = {"pc": "pc_attack", "wref": "wref_attack", "load": "load"}
SCALE = {"pc": 1.0, "wref": 0.08, "load": 0.25}  # amplitudes that trip some, not all


def random_scenarios(n: int, seed: int) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    channel = rng.choice(list(SCALE), n)
    waveform = rng.choice(["sinusoid", "square", "chirp", "step", "ramp", "none"], n)
    amplitude = rng.uniform(0.05, 1.0, n) * np.vectorize(SCALE.get)(channel)
    amplitude = np.where(waveform == "ramp", amplitude * 0.05, amplitude)
    return pd.DataFrame({"waveform": waveform, "channel": channel, "amplitude": amplitude,
                         "freq_hz": rng.uniform(0.1, 2.0, n), "start": rng.uniform(0, 2, n),
                         "alpha": rng.choice([np.nan, 3.0, 20.0], n),
                         "Ts": rng.choice([0.1, 0.25], n)})


def direct(row: pd.Series, duration: float) -> dict:
    """lfc.simulate on one scenario row."""
    sig = scenario_signal(row, duration)
    kw = {} if sig is None else {CHANNEL_ARG[row["channel"]]: sig}
    if np.isnan(row["alpha"]):
        scc = None
    elif row.get("method", "paper") == "certified":
        scc = lfc.SafetyFilter(P, method="certified")
    else:
        scc = lfc.SafetyFilter(P, alpha=row["alpha"], Ts=row["Ts"])
    return lfc.simulate(P, duration=duration, scc=scc, **kw).metrics()


def check_equal(scenarios: pd.DataFrame, res: pd.DataFrame, duration: float) -> None:
    """Every row of the batch result equals lfc.simulate on that row."""
    for i, row in scenarios.iterrows():
        assert same_metrics(direct(row, 8.0), res.loc[i]), i


def test_batch_equals_simulate_on_a_random_sample():
    scenarios = random_scenarios(60, seed=1)
    res = simulate_many(P, scenarios, duration=8.0, chunk_size=25, progress=False)
    assert list(res.columns) == list(scenarios.columns) + list(METRIC_KEYS)
    assert 5 <= res.tripped.sum() <= 55  # the sample exercises both outcomes
    check_equal(scenarios, res, 8.0)


def test_batch_equals_simulate_for_the_certified_filter_and_free_form_attacks():
    """The rows the certified filter's guarantee tests rely on: method="certified"
    and free-form "samples" attacks (with either filter)."""
    periodic = random_scenarios(20, seed=7)
    periodic = periodic[periodic.alpha.notna()].assign(method="certified")
    free = piecewise_attack_table(n=8, amplitude=2.0, duration=8.0, seed=3)
    scenarios = pd.concat([periodic, free, free.assign(method="certified")], ignore_index=True)
    res = simulate_many(P, scenarios, duration=8.0, chunk_size=13, progress=False)
    assert res[res.method == "paper"].tripped.any()
    assert (res[res.method == "certified"].alarms > 0).any()
    check_equal(scenarios, res, 8.0)


def test_small_map_matches_simulate_at_its_corners():
    amps, freqs = [0.1, 0.3, 0.6], [0.3, 1.0, 1.5]
    grid = pd.DataFrame([{"waveform": "sinusoid", "channel": "pc", "amplitude": a,
                          "freq_hz": f, "start": 1.0, "alpha": al, "Ts": 0.25}
                         for al in (np.nan, 20.0) for a in amps for f in freqs])
    res = simulate_many(P, grid, duration=10.0, progress=False)
    assert res.tripped.any() and not res.tripped.all()
    corners = res[res.amplitude.isin([amps[0], amps[-1]]) & res.freq_hz.isin([freqs[0],
                                                                                 freqs[-1]])]
    assert len(corners) == 8
    for _, row in corners.iterrows():
        m = direct(row, 10.0)
        assert m["tripped"] == row.tripped
        assert m["first_trip_relay"] == row.first_trip_relay


@settings(max_examples=tiers.examples(8), deadline=None)
@given(chunk=st.integers(1, 12), seed=st.integers(0, 2**16))
def test_chunking_and_row_order_do_not_change_results(chunk, seed):
    scenarios = random_scenarios(12, seed)
    whole = simulate_many(P, scenarios, duration=2.0, progress=False)
    shuffled = scenarios.sample(frac=1.0, random_state=seed % 1000)
    parts = simulate_many(P, shuffled, duration=2.0, chunk_size=chunk, progress=False)
    pd.testing.assert_frame_equal(parts.loc[whole.index], whole)


class InlineExecutor(Executor):
    """Runs each task at submission and records how many it ran."""

    def __init__(self):
        self.ran = 0

    def submit(self, fn, *args, **kwargs):
        fut = Future()
        fut.set_result(fn(*args, **kwargs))
        self.ran += 1
        return fut


KILLED_RUN = """
import sys, time, pandas as pd, lfc
from concurrent.futures import ThreadPoolExecutor

def slowly(*args):   # a chunk takes milliseconds: give the test time to kill the run
    time.sleep(0.5)
    return lfc.tables.run_chunk(*args)

class Slow(ThreadPoolExecutor):
    def submit(self, fn, *args):
        return super().submit(slowly, *args)

lfc.simulate_many(lfc.LFCParams(), pd.read_csv(sys.argv[2], index_col=0), duration=20.0,
                   chunk_size=5, out=sys.argv[1], executor=Slow(1), progress=False)
"""


def test_killed_run_resumes_without_recomputing_chunks(tmp_path):
    out, table = tmp_path / "chunks", tmp_path / "scenarios.csv"
    scenarios = random_scenarios(40, 3)
    scenarios.to_csv(table)
    scenarios = pd.read_csv(table, index_col=0)
    proc = subprocess.Popen([sys.executable, "-c", KILLED_RUN, str(out), str(table)])
    try:
        deadline = time.time() + 120
        while not list(out.glob("chunk_*.csv")) and time.time() < deadline:
            assert proc.poll() is None, "the run ended before it could be killed"
            time.sleep(0.05)
    finally:
        proc.kill()
        proc.wait()
    done = {p.name: p.stat().st_mtime_ns for p in out.glob("chunk_*.csv")}
    assert 1 <= len(done) < 8
    inline = InlineExecutor()
    resumed = simulate_many(P, scenarios, duration=20.0, chunk_size=5, out=out,
                             executor=inline, progress=False)
    assert inline.ran == 8 - len(done)
    for name, mtime in done.items():
        assert (out / name).stat().st_mtime_ns == mtime
    assert len(list(out.glob("chunk_*.csv"))) == 8 and not list(out.glob("*.tmp"))
    fresh = simulate_many(P, scenarios, duration=20.0, chunk_size=5, progress=False)
    pd.testing.assert_frame_equal(resumed, fresh)


def test_changed_settings_do_not_reuse_old_chunks(tmp_path):
    scenarios = random_scenarios(6, 4)
    simulate_many(P, scenarios, duration=2.0, chunk_size=3, out=tmp_path, progress=False)
    inline = InlineExecutor()
    simulate_many(P, scenarios, duration=3.0, chunk_size=3, out=tmp_path, executor=inline,
                   progress=False)
    assert inline.ran == 2


@pytest.mark.exhaustive
def test_dask_local_cluster_gives_the_same_table_as_the_process_pool():
    distributed = pytest.importorskip("distributed")
    scenarios = random_scenarios(16, 5)
    pool = simulate_many(P, scenarios, duration=3.0, chunk_size=4, progress=False)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        dask = simulate_many(P, scenarios, duration=3.0, chunk_size=4,
                              executor=client.get_executor(), progress=False)
    pd.testing.assert_frame_equal(dask, pool)


@pytest.mark.parametrize("change, message", [
    (lambda d: d.drop(columns="Ts"), "missing column"),
    (lambda d: d.assign(waveform="triangle"), "column 'waveform' must be one of"),
    (lambda d: d.assign(channel="ace"), "column 'channel' must be one of"),
    (lambda d: d.assign(alpha=-1.0), "column 'alpha' must be > 0 or NaN"),
    (lambda d: d.assign(amplitude=np.inf), "column 'amplitude' must be finite"),
    (lambda d: d.assign(start=-1.0), "column 'start' must be finite and >= 0"),
    (lambda d: d.assign(Ts=0.0), "column 'Ts' must be finite and > 0"),
])
def test_bad_scenarios_name_the_column(change, message):
    with pytest.raises(ValueError, match=message):
        simulate_many(P, change(random_scenarios(3, 0)), duration=1.0, progress=False)


def test_bad_settings_raise():
    with pytest.raises(ValueError, match="chunk_size"):
        simulate_many(P, random_scenarios(3, 0), duration=1.0, chunk_size=0)
    with pytest.raises(ValueError, match="control_period"):
        simulate_many(P, random_scenarios(3, 0), duration=1.0, control_period=0.0015)


# -- a row is the simulate call that matches it ----------------------------------------------
_FILTERS: dict = {}


def _matching_filter(spec: tuple, noise: tuple[float, float]):
    """The filter a row of ``spec`` selects, built independently of the batch."""
    from lfc.estimation import measurement_std
    kind, value = spec
    key = (spec, noise if kind == "declared" else None)
    if key not in _FILTERS:
        if kind == "paper":
            alpha, reading = value
            _FILTERS[key] = lfc.SafetyFilter(P, alpha=alpha, Ts=0.25, outside_rule=reading)
        elif kind == "certified":
            _FILTERS[key] = lfc.SafetyFilter(P, method="certified", uncertainty=value)
        else:
            _FILTERS[key] = lfc.SafetyFilter(P, method="certified",
                                             noise_std=measurement_std(noise))
    return _FILTERS[key]


FILTER_SPECS = [("none", None), ("paper", (3.0, "hold")), ("paper", (20.0, "push")),
                ("certified", 0.0), ("certified", 0.2), ("declared", None)]
ROW = st.fixed_dictionaries({
    "filter": st.sampled_from(FILTER_SPECS),
    "noisy": st.booleans(),
    "seed": st.integers(0, 3),
    "plant": st.one_of(st.none(), st.tuples(*[st.floats(0.8, 1.2)] * 5)),
    "attack": st.tuples(st.sampled_from(["pc", "wref"]), st.sampled_from(["sinusoid", "square"]),
                        st.floats(0.1, 1.0), st.floats(0.2, 1.5)),
})


def _row(r: dict) -> dict:
    channel, waveform, amp, freq = r["attack"]
    kind, value = r["filter"]
    noise = (1e-4, 1e-3) if r["noisy"] or kind == "declared" else (0.0, 0.0)
    row = {"waveform": waveform, "channel": channel,
           "amplitude": amp * (0.08 if channel == "wref" else 1.0), "freq_hz": freq,
           "start": 1.0, "alpha": np.nan, "Ts": 0.25, "method": "paper",
           "outside_rule": np.nan, "uncertainty": np.nan, "declare_noise": False,
           "noise_w": noise[0], "noise_rocof": noise[1], "seed": r["seed"]}
    if kind == "paper":
        row.update(alpha=value[0], outside_rule=value[1])
    elif kind in ("certified", "declared"):
        row.update(alpha=20.0, method="certified", uncertainty=value if kind == "certified"
                   else np.nan, declare_noise=kind == "declared")
    if r["plant"] is not None:
        row.update({n: getattr(P, n) * f for n, f in zip(("M", "D", "tau_g", "tau_t", "droop"),
                                                         r["plant"])})
    return row


@settings(max_examples=tiers.examples(8), deadline=None)
@given(st.lists(ROW, min_size=6, max_size=6))
def test_every_batch_row_is_the_matching_simulate_call(rows):
    """Issue "Hardened": a row equals ``simulate`` on the row's plant with the
    filter and the Kalman estimator built on the design model (what the docstring
    says), for every filter, estimator and row plant."""
    from dataclasses import replace

    from lfc.estimation import KalmanFilter, measurement_std
    table = pd.DataFrame([_row(r) for r in rows])
    res = simulate_many(P, table, duration=4.0, chunk_size=3, progress=False)
    for r, (i, row) in zip(rows, table.iterrows()):
        noise = (row.noise_w, row.noise_rocof)
        plant = P if r["plant"] is None else replace(
            P, **{n: row[n] for n in ("M", "D", "tau_g", "tau_t", "droop")})
        scc = None if r["filter"][0] == "none" else _matching_filter(r["filter"], noise)
        estimator = (KalmanFilter(P, 0.01, meas_std=measurement_std(noise))
                     if noise[0] > 0 else None)
        sig = scenario_signal(row, 4.0)
        m = lfc.simulate(plant, duration=4.0, scc=scc, estimator=estimator, noise_std=noise,
                         seed=int(row.seed), **{CHANNEL_ARG[row.channel]: sig}).metrics()
        assert same_metrics(m, res.loc[i]), (i, r)


@pytest.mark.parametrize("change, message", [
    (lambda d: d.assign(uncertainy=0.2), "did you mean 'uncertainty'"),
    (lambda d: d.assign(seeds=1), "did you mean 'seed'"),
    (lambda d: d.assign(alpha=20.0, uncertainty=0.2), "only method\\(s\\) \\['certified'\\]"),
    (lambda d: d.assign(alpha=np.nan, outside_rule="push"), "has no SCC"),
    (lambda d: d.assign(alpha=20.0, method="certified", conflict="slack"), "is method 'certified'"),
])
def test_a_column_that_would_be_ignored_is_refused(change, message):
    with pytest.raises(ValueError, match=message):
        simulate_many(P, change(random_scenarios(3, 0)), duration=1.0, progress=False)


def test_label_columns_neutral_values_and_nan_readings_pass():
    table = random_scenarios(4, 0).assign(alpha=[np.nan, 3.0, 20.0, 20.0], label="x",
                                          uncertainty=0.0,
                                          outside_rule=[np.nan, "push", np.nan, "hold"])
    res = simulate_many(P, table, duration=1.0, progress=False)
    assert list(res.label) == ["x"] * 4


@pytest.mark.parametrize("column, values", [("alpha", ["3", 20.0, 20.0]),
                                            ("amplitude", [True, 0.5, 0.5]),
                                            ("seed", [0, "1", 2])])
def test_a_string_or_bool_in_a_numeric_column_is_refused_not_coerced(column, values):
    """pandas would read "3" as 3 and True as 1; a typed table says what it means."""
    table = random_scenarios(3, 0).assign(**{column: values})
    with pytest.raises(TypeError, match=f"column '{column}' must hold numbers"):
        simulate_many(P, table, duration=1.0, progress=False)
