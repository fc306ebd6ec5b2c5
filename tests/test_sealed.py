"""Every stored result is read back only for the request it answers (issue
"Sealed", item 1): batch chunks, stored values (built certificates, fits, ANDES
runs: :func:`lfc._files.read_stored`) and sweep runs, each swapped, copied from
another request, truncated, emptied or nested too deep, is recomputed with a
warning naming the file, never read back as a result."""

from __future__ import annotations

import hashlib
import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import lfc
import probe
from lfc import tables
from lfc._files import kept, read_stored, write_stored
from lfc.tables import ChunkWarning
from lfc.repro import runner

P = lfc.LFCParams()


def _table() -> pd.DataFrame:
    """Two rows: 0.1 pu (no trip) and 2.0 pu (trips ROCOF) sinusoids on P_c."""
    return pd.DataFrame({"waveform": "sinusoid", "channel": "pc", "amplitude": [0.1, 2.0],
                         "freq_hz": 1.0, "start": 0.1, "alpha": np.nan, "Ts": 0.25})


def _chunks(folder: Path) -> list[Path]:
    return sorted(folder.glob("chunk_*.csv"))


def test_swapped_batch_chunks_are_recomputed_not_read_for_each_others_rows(tmp_path):
    """The issue's case: two rows in chunks of one, the two files swapped — the
    0.1 pu row was reported tripped and the 2.0 pu row not.  Now each file is
    sealed with its chunk's key and rows: both are recomputed, with a warning."""
    first = lfc.simulate_many(P, _table(), duration=1.0, chunk_size=1, out=tmp_path)
    assert list(first.tripped) == [False, True]
    a, b = _chunks(tmp_path)
    text_a, text_b = a.read_text(), b.read_text()
    a.write_text(text_b)
    b.write_text(text_a)
    with pytest.warns(ChunkWarning, match="written for another request"):
        again = lfc.simulate_many(P, _table(), duration=1.0, chunk_size=1, out=tmp_path)
    pd.testing.assert_frame_equal(again, first)


def test_a_chunk_of_another_runs_settings_is_recomputed(tmp_path):
    """A chunk of a ``duration=0.3`` run copied over the same chunk of a
    ``duration=1.0`` run (the 2.0 pu row read ``tripped=False``): recomputed."""
    short, long_ = tmp_path / "short", tmp_path / "long"
    lfc.simulate_many(P, _table(), duration=0.3, chunk_size=1, out=short)
    first = lfc.simulate_many(P, _table(), duration=1.0, chunk_size=1, out=long_)
    shutil.copyfile(_chunks(short)[1], _chunks(long_)[1])
    with pytest.warns(ChunkWarning, match="written for another request"):
        again = lfc.simulate_many(P, _table(), duration=1.0, chunk_size=1, out=long_)
    assert bool(again.tripped.iloc[1])
    pd.testing.assert_frame_equal(again, first)


@pytest.mark.parametrize("damage", ["emptied", "truncated", "header only"])
def test_an_emptied_or_truncated_chunk_is_recomputed(tmp_path, damage):
    first = lfc.simulate_many(P, _table(), duration=1.0, chunk_size=1, out=tmp_path)
    path = _chunks(tmp_path)[1]
    text = path.read_text()
    path.write_text({"emptied": "", "truncated": text[:len(text) // 2],
                     "header only": text.partition("\n")[0] + "\n"}[damage])
    with pytest.warns(ChunkWarning, match=path.name):
        again = lfc.simulate_many(P, _table(), duration=1.0, chunk_size=1, out=tmp_path)
    pd.testing.assert_frame_equal(again, first)


def test_a_chunk_stored_for_other_row_labels_is_not_read_for_these(tmp_path):
    metrics = lfc.simulate_many(P, _table(), duration=0.5)[list(lfc.tables.METRIC_KEYS)]
    path = tmp_path / "chunk.csv"
    tables._write_chunk(path, metrics)
    assert tables._read_chunk(path, metrics.index) is not None
    with pytest.warns(ChunkWarning, match="stored for other rows"):
        assert tables._read_chunk(path, pd.Index([5, 6])) is None


@pytest.mark.parametrize("damage", ["swapped", "copied", "truncated", "emptied", "deep",
                                    "not an object"])
def test_a_stored_value_is_read_back_only_under_the_name_it_was_written_for(tmp_path, damage):
    """:func:`lfc._files.read_stored`, which built certificates, fits and ANDES runs
    share: each file is sealed with the name it was written under (a key of its
    request), so one swapped with or copied from another name is not read back;
    a truncated, emptied or 200,000-deep file neither (a warning, then None), and
    nothing raises."""
    one, two = tmp_path / "key-one.json", tmp_path / "key-two.json"
    write_stored(one, {"margin": 0.0}, dict)
    write_stored(two, {"margin": 0.3}, dict)
    assert read_stored(one, dict) == {"margin": 0.0}
    if damage == "swapped":
        a, b = one.read_text(), two.read_text()
        one.write_text(b)
        two.write_text(a)
    elif damage == "copied":
        shutil.copyfile(two, one)
    elif damage == "truncated":
        one.write_text(one.read_text()[:-20])
    elif damage == "emptied":
        one.write_text("")
    elif damage == "deep":
        one.write_text("[" * 200_000 + "]" * 200_000)
    else:
        one.write_text(json.dumps([1, 2]))
    with pytest.warns(RuntimeWarning, match="key-one.json"):
        assert read_stored(one, dict) is None


def test_a_file_of_another_versions_layout_is_stale_computed_again_without_a_warning(
        tmp_path):
    """A cache that outlives an upgrade (CI keeps ``~/.cache``) holds files of the
    layout before the seals: stale, not damaged — they are computed again, and no
    notebook shows a warning for them."""
    path = tmp_path / "key.json"
    payload = json.dumps({"margin": 0.3})                   # the unsealed layout
    path.write_text(json.dumps({"payload": payload,
                                "sha256": hashlib.sha256(payload.encode()).hexdigest()}))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert read_stored(path, dict) is None
    write_stored(path, {"margin": 0.3}, dict)
    assert read_stored(path, dict) == {"margin": 0.3}


def test_swapped_built_certificates_are_built_again_not_used_for_each_other(tmp_path,
                                                                             monkeypatch):
    """The issue's case: two coupled certificates (``margin=0.0`` and ``0.3``) stored
    in one cache, their files swapped: a new process asking for ``margin=0.3`` used
    the untightened one.  Through :func:`lfc._files.kept` (what ``built_once``'s
    store calls), the swapped files are built again, each for its own request."""
    from lfc.filters.coupled import CoupledFilter
    grid = lfc.MultiAreaParams.two_area()
    made = {m: CoupledFilter(grid, lfc.RelaySettings(), margin=m) for m in (0.0, 0.3)}
    paths = {m: tmp_path / f"built-{m}.json" for m in made}
    for m, path in paths.items():
        kept(path, lambda m=m: made[m], 0.0, 1e9)
    a, b = paths[0.0].read_text(), paths[0.3].read_text()
    paths[0.0].write_text(b)
    paths[0.3].write_text(a)
    with pytest.warns(RuntimeWarning, match="written for another request"):
        read = kept(paths[0.3], lambda: made[0.3], 0.0, 1e9)
    assert read is made[0.3]                          # built again, not the other's
    np.testing.assert_array_equal(kept(paths[0.3], lambda: None, 0.0, 1e9).data,
                                  made[0.3].data)     # and stored for its own request


@pytest.mark.long(30)
def test_a_sweeps_metrics_swapped_or_emptied_are_run_again(tmp_path):
    """The issue's case: a sweep's two ``metrics.json`` swapped gave each point the
    other's peaks (exit 0); one replaced by ``{}`` dropped its rows.  ``done.json``
    seals each run's metrics by their SHA-256: both are run again, with a warning,
    and the table is the clean run's."""
    out = tmp_path / "sweep"
    grid = {"alpha": [3.0, 20.0], "duration": [2.0]}
    table = runner.sweep(probe.NOTEBOOK, grid, out)
    a, b = (out / runner.run_id({"alpha": v, "duration": 2.0}) / "metrics.json"
            for v in (3.0, 20.0))
    text_a, text_b = a.read_text(), b.read_text()
    a.write_text(text_b)
    b.write_text(text_a)
    with pytest.warns(UserWarning, match="metrics.json is not the one this run wrote"):
        pd.testing.assert_frame_equal(runner.sweep(probe.NOTEBOOK, grid, out), table)
    a.write_text("{}")
    with pytest.warns(UserWarning, match="stale or damaged"):
        pd.testing.assert_frame_equal(runner.sweep(probe.NOTEBOOK, grid, out), table)


@pytest.mark.long(30)
def test_a_sweep_folder_belongs_to_one_notebook_and_adds_points(tmp_path):
    """A second sweep of the same notebook into the folder adds its points (the
    table holds both, the first not run again); another notebook's sweep into it
    is refused, naming both; an empty ``out`` is refused."""
    out = tmp_path / "sweep"
    runner.sweep(probe.NOTEBOOK, {"alpha": [3.0], "duration": [2.0]}, out)
    done = next(out.glob("*/done.json")).stat().st_mtime_ns
    both = runner.sweep(probe.NOTEBOOK, {"alpha": [20.0], "duration": [2.0]}, out)
    assert sorted(set(both.alpha)) == [3.0, 20.0]
    assert len(pd.read_csv(out / "sweep.csv")) == len(both) == 4
    assert min(p.stat().st_mtime_ns for p in out.glob("*/done.json")) == done
    other = tmp_path / "other.ipynb"
    shutil.copyfile(probe.NOTEBOOK, other)
    with pytest.raises(ValueError, match="holds a sweep of probe.ipynb, not of other.ipynb"):
        runner.sweep(other, {"alpha": [3.0], "duration": [2.0]}, out)
    with pytest.raises(ValueError, match="out must name a folder"):
        runner.sweep(probe.NOTEBOOK, {"alpha": [3.0]}, "")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert runner.sweep(probe.NOTEBOOK, {"alpha": [3.0], "duration": [2.0]}, out).equals(
            both)


# -- one numeric gate (item 2): what the validators accept, the engine runs -----------------

def test_fraction_and_numpy_options_become_floats_before_the_engine_sees_them():
    """A ``Fraction`` ``confidence`` or ``control_period`` and a ``float32`` noise level
    are floats from the filter's construction on (a Fraction used to fail inside
    numba after minutes of compiling), and the filter equals the one built from
    floats."""
    from fractions import Fraction
    f = lfc.SafetyFilter(P, method="certified", noise_std=(Fraction(1, 10_000), np.float32(1e-3)),
                         confidence=Fraction(9999, 10_000), control_period=Fraction(1, 100))
    o = f.options
    assert type(o.confidence) is float and type(o.control_period) is float
    assert all(type(v) is float for v in o.noise_std)
    g = lfc.SafetyFilter(P, method="certified", noise_std=(1e-4, float(np.float32(1e-3))),
                         confidence=0.9999, control_period=0.01)
    np.testing.assert_array_equal(f.data, g.data)


def test_a_float32_duration_is_a_multiple_of_dt_and_a_huge_integer_is_refused_naming_it():
    """``duration=np.float32(0.5)`` was called "not a multiple of dt" (float32
    arithmetic); an integer too large for a float ended in ``OverflowError``."""
    assert not lfc.simulate(P, duration=np.float32(0.5)).metrics()["tripped"]
    with pytest.raises(ValueError, match="confidence = 1000.* is too large for a float"):
        lfc.SafetyFilter(P, method="certified", confidence=10 ** 400)


@pytest.mark.parametrize("kwargs, error, message", [
    ({"duration": float("inf")}, ValueError, "duration must be finite"),
    ({"control_period": 0}, ValueError, "control_period must be a finite number > 0"),
    ({"control_period": -0.01}, ValueError, "control_period must be a finite number > 0"),
    ({"control_period": "x"}, TypeError, "control_period must be a number"),
    ({"duration": 1e9}, ValueError, "more than a table holds"),
])
def test_a_piecewise_attack_table_refuses_what_it_cannot_build(kwargs, error, message):
    """These ended in ``OverflowError``, ``ZeroDivisionError``, negative dimensions, a
    bare ``TypeError`` and a 745 GiB ``MemoryError``; each is refused, named, before
    any allocation."""
    from lfc.experiments.redteam import piecewise_attack_table
    with pytest.raises(error, match=message):
        piecewise_attack_table(**{"n": 2, "amplitude": 1.0, "seed": 0, "duration": 5.0,
                                  **kwargs})


def test_a_contract_without_relays_and_a_sweep_plot_without_a_name_are_refused(tmp_path):
    """``contract_design(grid, None)`` ended in ``AttributeError``; ``plot-sweep --out
    ''`` wrote ``./.png``; a table without ``panel`` ended in ``KeyError``."""
    from lfc.repro.cli import main
    from lfc.filters.contract import contract_design
    with pytest.raises(TypeError, match="relays must be a RelaySettings, got None"):
        contract_design(lfc.MultiAreaParams.two_area(), None)
    table = tmp_path / "sweep.csv"
    pd.DataFrame({"alpha": [1.0, 2.0], "max_abs_rocof_meas": [0.1, 0.2]}).to_csv(table)
    assert main(["plot-sweep", str(table), "-x", "alpha", "-y", "max_abs_rocof_meas"]) == 2
    table.write_text(pd.DataFrame({"alpha": [1.0], "max_abs_rocof_meas": [0.1],
                                   "panel": ["a"]}).to_csv(index=False))
    assert main(["plot-sweep", str(table), "-x", "alpha", "-y", "max_abs_rocof_meas",
                 "--out", ""]) == 2
    assert not list(tmp_path.glob(".png")) and not Path(".png").exists()


def test_a_nan_noise_column_means_no_noise_as_the_column_check_says():
    """``noise_w`` NaN passed the column check ("or NaN") and was then refused
    naming ``noise_std[0]``; it now means no noise on that row, as documented."""
    table = _table().assign(noise_w=[np.nan, 1e-4], noise_rocof=[np.nan, 1e-3])
    out = lfc.simulate_many(P, table, duration=0.5, progress=False)
    clean = lfc.simulate_many(P, _table().iloc[:1], duration=0.5, progress=False)
    assert out.iloc[0]["max_abs_rocof_meas"] == clean.iloc[0]["max_abs_rocof_meas"]


def test_a_400_digit_integer_in_a_sweep_is_refused_naming_the_parameter():
    """It ended in ``OverflowError`` inside the validation."""
    with pytest.raises(ValueError, match="parameter 'alpha' has an integer of about 400 digits"):
        runner.validate_parameters(probe.NOTEBOOK, {"alpha": [10 ** 400]})


def test_a_signal_subclass_without_the_engines_hooks_is_named_or_sampled():
    """A ``Signal`` subclass without ``spec()`` ended in a bare
    ``NotImplementedError``: one that is a callable of time is sampled like any
    callable; one that is not is refused naming the channel."""
    class Bare(lfc.signals.Signal):
        pass

    class Ramp(lfc.signals.Signal):
        def __call__(self, t):
            return 0.1 * np.asarray(t)

    with pytest.raises(TypeError, match="pc_attack: Bare is a Signal without a spec"):
        lfc.simulate(P, duration=0.5, pc_attack=Bare())
    sampled = lfc.simulate(P, duration=0.5, pc_attack=Ramp()).metrics()
    assert sampled == lfc.simulate(P, duration=0.5, pc_attack=lambda t: 0.1 * np.asarray(t)
                                   ).metrics()


@pytest.mark.parametrize("plant", ["single", "grid"])
def test_a_fraction_relay_setting_runs_as_its_float(plant):
    """A ``Fraction`` relay setting compiled for minutes, then failed with a numba
    ``TypingError``: relays enter every run (and every filter) as floats, and the
    run equals the one with the float settings."""
    from fractions import Fraction
    exact = lfc.RelaySettings(rocof_limit=Fraction(1, 20), of2=Fraction(103, 100))
    floats = lfc.RelaySettings(rocof_limit=0.05, of2=1.03)
    params = P if plant == "single" else lfc.MultiAreaParams.two_area()
    attack = lfc.Sinusoid(2.0, 1.0, start=0.1)
    if plant == "single":
        runs = [lfc.simulate(P, duration=1.0, relays=r, pc_attack=attack,
                             scc=lfc.SafetyFilter(P, r, method="certified"))
                for r in (exact, floats)]
        assert runs[0].settings["relays"] == runs[1].settings["relays"]
    else:
        runs = [lfc.simulate(params, duration=1.0, relays=r, attacks={0: {"pc": attack}})
                for r in (exact, floats)]
    assert runs[0].metrics() == runs[1].metrics()
    assert all(type(v) is float for v in lfc.SafetyFilter(P, exact).relays.__dict__.values())


def test_a_scenario_table_of_fractions_or_categories_runs_as_floats_and_repeated_labels_are_named():
    """A column of ``Fraction``s was refused as "not finite", a categorical one went
    through pandas, an integer too large for a float ended in ``OverflowError``, and a
    filter option on a filterless row of a table with repeated row labels ended in
    pandas' "truth value of a Series is ambiguous"."""
    from fractions import Fraction
    plain = lfc.simulate_many(P, _table(), duration=1.0, progress=False)
    exotic = _table().assign(amplitude=pd.Series([Fraction(1, 10), Fraction(2)], dtype=object),
                             waveform=pd.Categorical(["sinusoid", "sinusoid"]),
                             freq_hz=pd.Categorical([1.0, 1.0]))
    again = lfc.simulate_many(P, exotic, duration=1.0, progress=False)
    assert list(again.tripped) == list(plain.tripped) == [False, True]
    np.testing.assert_array_equal(again.max_abs_rocof_meas, plain.max_abs_rocof_meas)
    with pytest.raises(ValueError, match="column 'amplitude' has an integer too large for a "
                                         "float on row 1"):
        lfc.simulate_many(P, _table().assign(amplitude=pd.Series([0.1, 10 ** 400],
                                                                 dtype=object)),
                          duration=1.0, progress=False)
    twice = _table().assign(method="certified", uncertainty=[0.1, np.nan]).set_axis([7, 7])
    with pytest.raises(ValueError, match="column 'uncertainty' is set .* on row 7, which has "
                                         "no SCC"):
        lfc.simulate_many(P, twice, duration=1.0, progress=False)


def test_a_400_digit_integer_as_a_papermill_parameter_or_a_wire_stop_is_named():
    """Both ended in ``OverflowError``: a notebook's injected parameter is checked
    against its default's kind (a float default: a finite number; an integer one:
    below 2**63), and a wire attack's ``stop`` of 10**400 is "never"."""
    from lfc.repro.notebook import check_type
    from lfc.wire.attacks import WireAttack
    with pytest.raises(TypeError, match="parameter 'duration' must be a finite number"):
        check_type("duration", 10 ** 400, 10.0)
    with pytest.raises(ValueError, match=r"parameter 'seed' = 1000.* is too large"):
        check_type("seed", 10 ** 400, 0)
    attack = WireAttack([{"op": "drop", "start": 1.0, "stop": 10 ** 400}])
    assert attack.command(0, 2.0, 0.01, {"pc": 0.1}) is None        # dropped: never stops
    with pytest.raises(ValueError, match=r"attack\[0\]: need 0 <= start < stop"):
        WireAttack([{"op": "drop", "start": 10 ** 400}])


def test_a_damaged_numba_cache_file_is_compiled_again_with_a_warning(tmp_path, monkeypatch):
    """A cache file cut short raised ``UnpicklingError`` on every later call of the
    function: the package's own files are now a miss (numba compiles and rewrites
    them), with a warning naming the file; other packages' files are numba's."""
    from numba.core import caching

    from lfc import _numba_cache
    _numba_cache.install()
    monkeypatch.setattr(_numba_cache, "_PACKAGE", tmp_path)
    cache = caching.IndexDataCacheFile(str(tmp_path), "engine._run-1.py311", b"stamp")
    cache.save("key", {"code": 1})
    assert cache.load("key") == {"code": 1}
    data = next(tmp_path.glob("*.nbc"))
    data.write_bytes(data.read_bytes()[:5])
    with pytest.warns(RuntimeWarning, match="damaged numba cache file of engine._run-1"):
        assert cache.load("key") is None
    cache.save("key", {"code": 2})                                  # rewritten
    assert cache.load("key") == {"code": 2}
    index = next(tmp_path.glob("*.nbi"))
    index.write_bytes(index.read_bytes()[:-3])
    with pytest.warns(RuntimeWarning, match="damaged numba cache file"):
        assert cache.load("key") is None
    monkeypatch.setattr(_numba_cache, "_PACKAGE", tmp_path / "elsewhere")
    with pytest.raises(Exception):
        cache.load("key")


def test_a_numba_cache_file_naming_a_class_since_renamed_is_stale_not_damaged(tmp_path,
                                                                              monkeypatch):
    """numba's index pickles the compiled types, the kernel's named tuples among them:
    after a class of the package is renamed, the old file cannot be read.  That is a
    stale file (compiled again, silently), not a damaged one."""
    import warnings

    from numba.core import caching

    from lfc import _numba_cache, engine
    _numba_cache.install()
    monkeypatch.setattr(_numba_cache, "_PACKAGE", tmp_path)
    cache = caching.IndexDataCacheFile(str(tmp_path), "engine.run_kernel-1.py311", b"stamp")
    cache.save("key", {"types": engine.Timing(1, 1, 1e-3, False)})
    monkeypatch.delattr(engine, "Timing")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert cache.load("key") is None


def test_the_longest_run_is_scaled_by_the_grids_size_and_checked_before_allocating():
    """A six-area chain at the single area's longest run ended in ``MemoryError``:
    the limit is on the trace's values, with the estimate in the message."""
    from lfc.linear_area import MAX_STEPS, check_timing
    check_timing(MAX_STEPS * 1e-3, 1e-3, 0.01)                      # one area: as before
    with pytest.raises(ValueError, match=r"\(6 area\(s\), 35 states\) would take about "
                                         r"[0-9.]+ GB; lower duration \(at most 1[0-9.]+ s"):
        check_timing(MAX_STEPS * 1e-3, 1e-3, 0.01, 6, 35)
    with pytest.raises(ValueError, match=r"3 area\(s\), 18 states"):
        lfc.simulate(lfc.MultiAreaParams.three_area(), duration=MAX_STEPS * 1e-3)


@pytest.mark.parametrize("call, message", [
    (lambda: lfc.simulate("x", duration=1.0), "plant must be"),
    (lambda: lfc.simulate(P, duration=1.0, estimator=3), "estimator must be None"),
    (lambda: lfc.SafetyFilter(P, method=3), "method must be one of"),
    (lambda: lfc.simulate_many(P, "x", duration=1.0), "scenarios must be a pandas DataFrame"),
    (lambda: lfc.simulate_many(lfc.MultiAreaParams.two_area(), "x", duration=1.0),
     "scenarios must be a non-empty list of dicts"),
    (lambda: lfc.simulate_many(lfc.MultiAreaParams.two_area(), [1], duration=1.0),
     r"scenarios\[0\] must be a dict"),
    (lambda: lfc.simulate(lfc.MultiAreaParams.two_area(), duration=1.0, attacks={0: 3}),
     r"attacks\[0\] must be a dict"),
])
def test_a_wrong_type_is_a_type_error_as_documented(call, message):
    """These raised a plain ``ValueError`` where the docs promise ``TypeError`` for a
    wrong type (``ParameterTypeError`` is both, so ``except ValueError`` still catches
    it); a right type with a wrong value stays a ``ValueError``."""
    with pytest.raises(TypeError, match=message):
        call()
    with pytest.raises(ValueError, match="method must be one of") as err:
        lfc.SafetyFilter(P, method="nope")
    assert not isinstance(err.value, TypeError)
