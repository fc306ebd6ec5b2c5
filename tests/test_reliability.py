"""Nothing silently wrong (issue "Reliability"): damaged and stale chunk files,
concurrent runs on one folder, pulses in scenario tables, what the core refuses,
filters on absurd input, and the command line's errors — each case of the issue
a test, plus property-based tests of the scenario table, the chunk files and the
command line."""

import math
import os
import threading
import warnings

import numpy as np
import pandas as pd
import pytest
import tiers
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import lfc
from lfc import tables
from lfc import simulate_many
from lfc.tables import ChunkWarning
from lfc.repro.cli import main

P = lfc.LFCParams()
ROW = {"waveform": "sinusoid", "channel": "pc", "amplitude": 0.5, "freq_hz": 1.0,
       "start": 1.0, "alpha": 20.0, "Ts": 0.25}


def table(n: int = 4) -> pd.DataFrame:
    return pd.DataFrame([{**ROW, "amplitude": 0.1 + 0.2 * i} for i in range(n)])


# -- scenario tables ---------------------------------------------------------------------
def test_a_step_with_a_stop_is_a_pulse():
    """A 0.5 s, +0.04 pu pulse on ω_ref: no OF2 trip (it was reported as one at
    15 s when the stop was ignored), exactly as ``simulate`` with a pulse."""
    row = {**ROW, "waveform": "step", "channel": "wref", "amplitude": 0.04, "alpha": np.nan,
           "stop": 1.5}
    res = simulate_many(P, pd.DataFrame([row]), duration=20.0, progress=False)
    pulse = lfc.simulate(P, duration=20.0, wref_attack=lfc.Step(0.04, 1.0, stop=1.5)).metrics()
    assert not res.tripped[0] and not pulse["tripped"]
    assert res.max_abs_dw_meas[0] == pulse["max_abs_dw_meas"]
    held = simulate_many(P, pd.DataFrame([{**row, "stop": np.nan}]), duration=20.0,
                          progress=False)
    assert held.first_trip_relay[0] == "OF2"


def test_a_load_pulse_ends():
    r = lfc.simulate(P, duration=10.0, load=lfc.Step(0.1, 1.0, stop=2.0))
    assert abs(r.trace.p_load.iloc[-1]) == 0.0 and r.trace.p_load.max() == 0.1


@pytest.mark.parametrize("change, message", [
    ({"stop": 0.5}, "'stop' must be > start"),
    ({"waveform": "none", "stop": 3.0}, "'stop' has no meaning"),
    ({"uncertainty": 1.5, "method": "certified"}, "'uncertainty' must be in"),
    ({"margin": -0.1, "method": "certified"}, "'margin' must be in"),
    ({"relay_noise": True}, "'relay_noise' is True on row"),
    ({"relay_noise": "yes"}, "'relay_noise' must be True or False"),
    ({"trips_per_hour": 1.0}, "'trips_per_hour' must be finite and > 0"),
])
def test_bad_robust_and_pulse_columns_name_the_column(change, message):
    with pytest.raises(ValueError, match=message):
        simulate_many(P, pd.DataFrame([{**ROW, **change}]), duration=1.0, progress=False)


# -- chunk files ---------------------------------------------------------------------------
def chunk_files(folder) -> list:
    return sorted(folder.glob("chunk_*.csv"))


@pytest.mark.parametrize("damage", ["truncate", "flip", "header", "empty", "binary"])
def test_a_damaged_chunk_is_recomputed_with_a_warning_naming_it(tmp_path, damage):
    first = simulate_many(P, table(), duration=5.0, chunk_size=2, out=tmp_path,
                           progress=False)
    path = chunk_files(tmp_path)[1]
    data = path.read_bytes()
    path.write_bytes({"truncate": data[:len(data) // 2 + 7],
                      "flip": data[:-40] + bytes([data[-40] ^ 0x04]) + data[-39:],
                      "header": data.split(b"\n", 1)[1],          # a file of the old format
                      "empty": b"",
                      "binary": b"\xff\xfe\x00garbage"}[damage])
    with pytest.warns(ChunkWarning, match=path.name):
        again = simulate_many(P, table(), duration=5.0, chunk_size=2, out=tmp_path,
                               progress=False)
    pd.testing.assert_frame_equal(again, first)
    with warnings.catch_warnings():
        warnings.simplefilter("error")                      # repaired: read silently now
        simulate_many(P, table(), duration=5.0, chunk_size=2, out=tmp_path, progress=False)


def test_chunks_of_other_code_are_not_reused(tmp_path, monkeypatch):
    simulate_many(P, table(), duration=5.0, chunk_size=2, out=tmp_path, progress=False)
    old = chunk_files(tmp_path)
    monkeypatch.setattr(tables, "code_digest", lambda: "another version of the engine")
    simulate_many(P, table(), duration=5.0, chunk_size=2, out=tmp_path, progress=False)
    assert len(chunk_files(tmp_path)) == 2 * len(old)       # computed again, under new names


def test_two_runs_on_one_folder_at_once(tmp_path):
    """Concurrent runs write the same chunks: unique temporary names, atomic
    renames; both finish with the same table and leave no temporary file."""
    results, errors = [], []

    def run():
        try:
            results.append(simulate_many(P, table(8), duration=5.0, chunk_size=1,
                                          out=tmp_path, progress=False))
        except Exception as err:  # noqa: BLE001 - the test reports any failure
            errors.append(err)

    threads = [threading.Thread(target=run) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    for r in results[1:]:
        pd.testing.assert_frame_equal(r, results[0])
    assert not list(tmp_path.glob("*.tmp")) and len(chunk_files(tmp_path)) == 8


SANE_METRICS = pd.DataFrame({
    "tripped": [False, True, False], "first_trip_relay": [None, "ROCOF", None],
    "first_trip_t": [np.nan, 2.5, np.nan], "max_abs_dw_meas": [0.01, 0.02, 0.0],
    "max_abs_rocof_meas": [0.03, 0.06, 0.0], "scc_active_fraction": [0.0, 0.25, 1.0],
    "max_abs_modification": [0.0, 0.5, 1.5], "mean_abs_modification": [0.0, 0.1, 0.7],
    "alarms": [0, 25, 100], "final_abs_dw_meas": [0.0, 0.01, 0.002], "outside": [0, 3, 0]})


@pytest.mark.parametrize("col, value, why", [
    ("max_abs_dw_meas", np.nan, "'max_abs_dw_meas' is not finite and >= 0"),
    ("max_abs_rocof_meas", -5.0, "'max_abs_rocof_meas' is not finite and >= 0"),
    ("alarms", 2.5, "'alarms' is not a count"),
    ("scc_active_fraction", 1.5, "'scc_active_fraction' > 1"),
    ("first_trip_t", 3.0, "'first_trip_t' is not a time >= 0 exactly where 'tripped'"),
    ("first_trip_relay", "OF3", "'first_trip_relay' is not a relay"),
])
def test_a_chunk_with_a_valid_checksum_but_impossible_metrics_is_recomputed(tmp_path, col,
                                                                          value, why):
    """Issue "Hardened": the checksum says the file is what was written, not that
    what was written is a run's metrics (NaN, -5, a fractional count, a trip time
    without a trip)."""
    metrics = SANE_METRICS.astype({"alarms": float}).copy()
    metrics.loc[0, col] = value
    path = tmp_path / "chunk.csv"
    tables._write_chunk(path, metrics)
    with pytest.warns(ChunkWarning, match=why):
        assert tables._read_chunk(path, SANE_METRICS.index) is None
    tables._write_chunk(path, SANE_METRICS)
    pd.testing.assert_frame_equal(tables._read_chunk(path, SANE_METRICS.index).reset_index(drop=True),
                                  SANE_METRICS, check_dtype=False)


@settings(max_examples=tiers.examples(60), deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                   HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_property_damaged_chunk_files_never_give_a_wrong_result(tmp_path_factory, data):
    """Random truncation and byte changes of a stored chunk: reading it gives the
    stored metrics exactly, or nothing (and a warning) — never other numbers."""
    folder = tmp_path_factory.mktemp("chunk")
    metrics = SANE_METRICS.copy()
    path = folder / "chunk.csv"
    tables._write_chunk(path, metrics)
    raw = bytearray(path.read_bytes())
    if data.draw(st.booleans(), "truncate"):
        raw = raw[:data.draw(st.integers(0, len(raw) - 1), "length")]
    for _ in range(data.draw(st.integers(0, 3), "flips")):
        if raw:
            i = data.draw(st.integers(0, len(raw) - 1), "at")
            raw[i] = data.draw(st.integers(0, 255).filter(lambda b, old=raw[i]: b != old), "byte")
    path.write_bytes(bytes(raw))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        read = tables._read_chunk(path, SANE_METRICS.index)
    if read is None:
        assert any(issubclass(w.category, ChunkWarning) and path.name in str(w.message)
                   for w in caught)
    else:
        pd.testing.assert_frame_equal(read.reset_index(drop=True), metrics,
                                      check_dtype=False)


# -- scenario tables, property ---------------------------------------------------------------
VALID_ROW = st.fixed_dictionaries({
    "waveform": st.sampled_from(["sinusoid", "square", "step", "ramp", "chirp", "none"]),
    "channel": st.sampled_from(["pc", "wref", "load"]),
    "amplitude": st.floats(-2, 2), "freq_hz": st.floats(0.05, 3), "start": st.floats(0, 1.5),
    "stop": st.one_of(st.just(math.nan), st.floats(1.6, 3)),
    "alpha": st.sampled_from([20.0, 3.0, math.nan]), "Ts": st.floats(0.05, 1),
    "method": st.sampled_from(["paper", "certified"])})
BAD = {"waveform": ["saw", 3], "channel": ["Pc", None], "amplitude": [math.nan, math.inf, "x"],
       "freq_hz": [-1.0, math.nan, "x"], "start": [-1.0, math.inf], "stop": [0.0, -1.0],
       "alpha": [-1.0, 0.0, "x"], "Ts": [0.0, math.inf, -1.0], "method": ["cbf", 1]}
corruption = st.one_of(st.none(), st.sampled_from([(c, v) for c, vs in BAD.items() for v in vs]))


@settings(max_examples=tiers.examples(60), deadline=None)
@given(rows=st.lists(VALID_ROW, min_size=1, max_size=3), bad=corruption,
       which=st.integers(0, 2))
def test_property_a_scenario_table_is_refused_or_simulated_correctly(rows, bad, which):
    """A table of valid rows, one entry possibly made invalid: a ValueError that
    names the column and the row, or (nothing invalid) every row equal to
    ``simulate`` of the same scenario."""
    scenarios = pd.DataFrame(rows)
    scenarios.loc[scenarios.waveform == "none", "stop"] = math.nan   # no stop without a wave
    if bad is not None:
        column, value = bad
        if column == "alpha" or scenarios.alpha.notna().any() or column != "Ts":
            row = which % len(scenarios)
            scenarios[column] = scenarios[column].astype(object)
            scenarios.loc[row, column] = value
            if column == "Ts":
                scenarios.loc[row, "alpha"] = 20.0      # Ts matters only with an SCC
            if column == "stop" and scenarios.loc[row, "waveform"] in ("none",):
                scenarios.loc[row, "waveform"] = "step"
            with pytest.raises(ValueError, match=f"column '{column}'.*row {row}"):
                simulate_many(P, scenarios, duration=2.0, progress=False)
            event("refused")
            return
    res = simulate_many(P, scenarios, duration=2.0, progress=False)
    event("simulated")
    for i, row in scenarios.iterrows():
        signal = tables.scenario_signal(row, 2.0)
        channel = {"pc": "pc_attack", "wref": "wref_attack", "load": "load"}[row.channel]
        scc = None if np.isnan(row.alpha) else (
            lfc.SafetyFilter(P, method="certified") if row.method == "certified"
            else lfc.SafetyFilter(P, alpha=row.alpha, Ts=row.Ts))
        m = lfc.simulate(P, duration=2.0, scc=scc, **({channel: signal} if signal else {}))
        assert m.metrics()["max_abs_rocof_meas"] == res.max_abs_rocof_meas[i]
        assert m.metrics()["tripped"] == res.tripped[i]


# -- the core refuses what it cannot simulate --------------------------------------------------
@pytest.mark.parametrize("call, message", [
    (lambda: lfc.simulate(lfc.LFCParams(droop=1e-20), duration=1.0), "droop must lie in"),
    (lambda: lfc.simulate(P, duration=1e-4), "duration must be at least one plant step"),
    (lambda: lfc.simulate(P, duration="10"), "duration must be a number, got"),
    (lambda: lfc.simulate(P, duration=True), "duration must be a number, got"),
    (lambda: lfc.LFCParams(M="4"), "M must be a number, got"),
    (lambda: lfc.LFCParams(M=True), "M must be a number, got"),
    (lambda: lfc.simulate(P, duration=1.0, dt=np.nan), "dt must be a finite number"),
    (lambda: lfc.Step(0.1, 2.0, stop=1.0), "stop must be > start"),
    (lambda: lfc.SafetyFilter(P, method="certified", horizon=60.0),
     r"horizon must lie in \[0.2, 20"),
    (lambda: lfc.simulate(P, duration=1.0, relay_noise=True), "relay_noise=True needs noise_std"),
])
def test_the_core_refuses_what_it_cannot_simulate(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_integer_and_numpy_numbers_are_numbers():
    r = lfc.simulate(lfc.LFCParams(M=np.float64(4.0), D=np.int64(1)), duration=np.int64(1))
    assert len(r.trace) == 1001


def test_a_long_certified_horizon_works():
    filt = lfc.SafetyFilter(P, method="certified", horizon=20.0)
    assert filt.filter(np.zeros(5), 0.1)[0] == 0.1


# -- filters on absurd input ----------------------------------------------------------------
FILTERS = {"paper": {"alpha": 20.0}, "certified": {"method": "certified"}}
absurd = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                   st.sampled_from([1e160, -1e160, 1e7, math.nan, math.inf]))


@pytest.mark.parametrize("name", list(FILTERS))
def test_a_huge_command_or_state_is_invalid_input_not_passed_through(name):
    filt = lfc.SafetyFilter(P, **FILTERS[name])
    u0, _ = filt.filter(np.zeros(5), 0.05)
    u, info = filt.filter(np.zeros(5), 1e160)
    assert info.invalid_input and u == u0 and "invalid input" in info.reason
    u, info = filt.filter(np.full(5, 1e200), 0.05)
    assert info.invalid_input and u == u0 and math.isfinite(u)


@pytest.mark.parametrize("name", list(FILTERS))
@settings(max_examples=tiers.examples(150), deadline=None)
@given(x=st.lists(absurd, min_size=5, max_size=5), u_ref=absurd, p=absurd)
def test_property_filters_never_raise_and_return_a_finite_command(name, x, u_ref, p):
    filt = FILTER_OBJECTS[name]
    u, info = filt.filter(np.array(x), u_ref, p)
    assert math.isfinite(u)
    expected_invalid = not all(abs(v) <= 1e6 for v in [*x, u_ref, p])
    assert info.invalid_input == expected_invalid
    if info.invalid_input:
        assert info.reason


FILTER_OBJECTS = {name: lfc.SafetyFilter(P, **kw) for name, kw in FILTERS.items()}


# -- the command line ----------------------------------------------------------------------
def one_line_error(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: ") and "Traceback" not in err, err
    return err


def scenario_csv(tmp_path) -> str:
    path = tmp_path / "s.csv"
    table(1).to_csv(path, index=False)
    return str(path)


def test_cli_out_path_is_a_file(tmp_path, capsys):
    (tmp_path / "out").write_text("not a folder")
    assert main(["batch", scenario_csv(tmp_path), "--duration", "1",
                 "--out", str(tmp_path / "out")]) == 2
    one_line_error(capsys)


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores file permissions")
def test_cli_read_only_out_folder(tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        assert main(["batch", scenario_csv(tmp_path), "--duration", "1",
                     "--out", str(ro / "x")]) == 2
        one_line_error(capsys)
    finally:
        ro.chmod(0o700)


def test_cli_folder_as_scenario_table(tmp_path, capsys):
    assert main(["batch", str(tmp_path), "--duration", "1", "--out", str(tmp_path / "o")]) == 2
    assert "not a file" in one_line_error(capsys)


def test_cli_unreachable_dask_scheduler(tmp_path, capsys):
    assert main(["batch", scenario_csv(tmp_path), "--duration", "1", "--out",
                 str(tmp_path / "o"), "--dask", "tcp://127.0.0.1:9"]) == 2
    assert "cannot reach the Dask scheduler" in one_line_error(capsys)


def test_cli_ctrl_c_is_one_line_and_resumable(tmp_path, capsys, monkeypatch):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr("lfc.run.simulate_many", interrupted)
    assert main(["batch", scenario_csv(tmp_path), "--duration", "1",
                 "--out", str(tmp_path / "o")]) == 130
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "rerun the same command to resume" in err


def test_cli_usage_error_is_one_line(capsys):
    assert main(["reproduce", "--jobs", "0"]) == 2
    one_line_error(capsys)
    assert main(["frobnicate"]) == 2
    one_line_error(capsys)


@settings(max_examples=tiers.examples(40), deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(args=st.lists(st.sampled_from(["--duration", "-1", "0", "nan", "1e-5", "0.5", "--out",
                                      "--chunk-size", "0", "2", "x", "--dask", "", "-p"]),
                     max_size=6))
def test_property_the_batch_command_exits_cleanly(tmp_path_factory, capsys, args):
    """Random arguments to ``python -m lfc batch``: exit 0, or 2 with one line."""
    folder = tmp_path_factory.mktemp("cli")
    argv = ["batch", scenario_csv(folder)] + [str(folder / a) if a == "x" else a for a in args]
    code = main(argv)
    err = capsys.readouterr().err
    assert code in (0, 2)
    if code == 2:
        assert err.count("\n") == 1 and err.startswith("error: "), err
