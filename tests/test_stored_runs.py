"""Grid runs on ANDES kept on disk (lfc.testbed.stored_runs): read back, bit for
bit, by a later call whose generator sides return the same commands; run again
where they do not, where the file is damaged, or with the store off; keyed by
arguments whose code the key covers, the same in a fresh interpreter."""

import subprocess
import sys
import textwrap

import pandas as pd
import pytest

import lfc
from lfc.testbed import GridCase, case_design, grid_design
from lfc.testbed.loop import CLOCK_ENV
from lfc.testbed.stored_runs import SWITCH, scenario_keys

CASE = GridCase.kundur()


class MyStep(lfc.Step):
    """A signal class of the caller's own (its code is not in the key)."""


@pytest.fixture(scope="module")
def design():
    return grid_design(CASE)


def assert_same(mine, theirs) -> None:
    """Two grid results equal bit for bit: trace, each area's controls and alarms,
    settings."""
    pd.testing.assert_frame_equal(mine.trace, theirs.trace, check_exact=True)
    for a, b in zip(mine.areas, theirs.areas):
        pd.testing.assert_frame_equal(a.controls, b.controls, check_exact=True)
        pd.testing.assert_frame_equal(a.alarms, b.alarms, check_exact=True)
    assert mine.settings == theirs.settings


@pytest.mark.long(13)
def test_a_stored_run_is_read_back_by_filters_that_return_its_commands_and_run_by_others(
        design, tmp_path, monkeypatch, capsys):
    """A 0.01 pu load step runs ANDES once: the same call again, and the same call
    with the certified or the coupled filters (silent on it), read the stored run
    back.  Under an
    ACE bias the certified filters act: that call runs, and its run is stored
    beside the unfiltered one, so both read back next time.  Every result read
    back equals the same call run with the store off, bit for bit; a table reads
    them back too, and its progress bar says so; a damaged
    file is run again, with a warning.  Runs counted by ANDES' clock file."""
    monkeypatch.setenv("LFC_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv(SWITCH, raising=False)
    clock = tmp_path / "clock"
    monkeypatch.setenv(CLOCK_ENV, str(clock))

    def run(**kwargs):
        return lfc.simulate(CASE, design=design, duration=2.0, anti_windup=True, **kwargs)

    def runs() -> int:
        return len(clock.read_text().split()) if clock.exists() else 0

    certified = {0: "certified", 1: "certified"}
    step = {"loads": {1: lfc.Step(-0.01, 0.5)}}
    bias = {"attacks": {a: {"ace": lfc.Step(-2.5, 0.5)} for a in range(2)}}
    coupled = {0: "coupled", 1: "coupled"}
    calls = [step, step, {**step, "filters": certified}, {**step, "filters": coupled}, bias,
             {**bias, "filters": certified}, bias, {**bias, "filters": certified}]
    stored = [run(**kwargs) for kwargs in calls]
    assert runs() == 3                              # the step once, the bias twice
    assert all(a.alarms.empty for r in stored[2:4] for a in r.areas)      # silent
    assert any(len(a.alarms) for a in stored[5].areas)                    # it acted
    files = sorted((tmp_path / "cache" / "andes-runs").rglob("*.json"))
    assert len(files) == 3 and len({f.name.split("-")[0] for f in files}) == 2

    lfc.simulate_many(CASE, calls[:4], design=design, duration=2.0, anti_windup=True,
                      jobs=1, progress=True)
    assert runs() == 3                              # a table reads them back too, and says so
    assert "ANDES ran 0, read back 4" in capsys.readouterr().err

    monkeypatch.setenv(SWITCH, "off")
    fresh = [run(**kwargs) for kwargs in calls[1:6]]
    assert runs() == 3 + 5
    for mine, theirs in zip(stored[1:6], fresh):
        assert_same(mine, theirs)

    monkeypatch.delenv(SWITCH)
    for f in files:
        f.write_text(f.read_text()[:-40] + "}")
    with pytest.warns(RuntimeWarning, match="damaged cache file"):
        again = run(**step)
    assert runs() == 3 + 5 + 1
    assert_same(again, stored[0])


def test_a_run_stopped_at_its_trip_is_read_back_up_to_the_trip(design, tmp_path, monkeypatch):
    """With ``stop_on_trip`` a run ends at its first trip (a 2 pu step on area 0's
    command trips it at 1.37 s): stored so, a second call reads it back, equal bit
    for bit to running it with the store off; filters that stop the trip run (their
    commands differ before it); the same attack without ``stop_on_trip`` is another
    key and runs to its end."""
    monkeypatch.setenv("LFC_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv(SWITCH, raising=False)
    clock = tmp_path / "clock"
    monkeypatch.setenv(CLOCK_ENV, str(clock))

    def run(**kwargs):
        return lfc.simulate(CASE, design=design, duration=3.0, anti_windup=True,
                            attacks={0: {"pc": lfc.Step(2.0, 0.5)}}, **kwargs)

    def runs() -> int:
        return len(clock.read_text().split()) if clock.exists() else 0

    first = run(stop_on_trip=True)
    assert first.tripped and float(first.trace.t.iat[-1]) < 2.0 and runs() == 1
    again = run(stop_on_trip=True)
    assert runs() == 1
    certified = run(stop_on_trip=True, filters={0: "certified", 1: "certified"})
    assert runs() == 2 and not certified.tripped
    whole = run()
    assert runs() == 3 and float(whole.trace.t.iat[-1]) == pytest.approx(3.0)
    monkeypatch.setenv(SWITCH, "off")
    assert_same(again, run(stop_on_trip=True))
    assert runs() == 4


def test_the_key_leaves_out_the_filters_and_is_the_same_in_a_fresh_interpreter():
    """A call's stored key is its arguments but ``filters`` (another filter: the
    same key), computed the same in a fresh Python; a signal whose code the key
    does not cover (a function or signal class of the caller's own) gives no
    stored key: such a call runs, and is not stored, though it may still share a
    run within one table where it pickles; a call over a network has neither."""
    source = textwrap.dedent("""
        import lfc
        from lfc.testbed import GridCase, case_design
        from lfc.testbed.stored_runs import scenario_keys
        CASE = GridCase.kundur()
        CALL = {"params": case_design(CASE), "duration": 2.0, "case": CASE,
                "loads": {1: lfc.Step(-0.01, 0.5)},
                "attacks": {0: {"pc": lfc.Sinusoid(0.3, 0.5, start=1.0)}},
                "relays": lfc.RelaySettings(), "seed": 3, "filters": None}
        """)
    here: dict = {}
    exec(source, here)
    call = here["CALL"]
    share, key = scenario_keys(call)
    assert len(key) == 64 and isinstance(share, bytes)
    assert scenario_keys({**call, "filters": {0: "certified"}}) == (share, key)
    assert scenario_keys({**call, "seed": 4})[1] != key
    fresh = subprocess.run([sys.executable, "-c", source + "print(scenario_keys(CALL)[1])"],
                           capture_output=True, text=True, check=True)
    assert fresh.stdout.strip() == key

    def own(t):
        return 0.0 * t

    assert scenario_keys({**call, "loads": {1: own}}) == (None, None)      # does not pickle
    assert scenario_keys({**call, "loads": {1: lambda t: 0.0 * t}}) == (None, None)
    mine = scenario_keys({**call, "loads": {1: MyStep(-0.01, 0.5)}})
    assert mine[0] is not None and mine[1] is None       # shares in a table, never stored
    assert scenario_keys({**call, "network": object()}) == (None, None)
    assert scenario_keys({**call, "params": case_design(CASE)})[1] == key


def test_the_switch_is_on_or_off_and_anything_else_is_refused(monkeypatch):
    """``LFC_ANDES_RUNS=off`` gives no stored key (every call runs; a table still
    shares); ``on`` or unset, a key; a typo is refused, naming the variable,
    rather than read as on."""
    call = {"params": case_design(CASE), "duration": 1.0}
    monkeypatch.setenv(SWITCH, "off")
    share, key = scenario_keys(call)
    assert share is not None and key is None
    monkeypatch.setenv(SWITCH, " ON ")
    assert scenario_keys(call)[1] is not None
    monkeypatch.setenv(SWITCH, "of")
    with pytest.raises(ValueError, match="LFC_ANDES_RUNS must be 'on' or 'off'.*'of'"):
        scenario_keys(call)


@pytest.mark.parametrize("kind", ["grid", "microgrid"])
def test_the_key_covers_the_plant_side_and_nothing_else(tmp_path, kind):
    """An edit of the code of any file, function or class of the plant side
    (``PLANT_CODE``) changes the key of every stored run of that kind of plant; an edit
    of a comment or a docstring there, or of a filter, the engine's loops, the rest of
    the plant's module or a notebook does not (the replay checks the generator side,
    command by command)."""
    import ast
    import shutil

    from lfc.testbed import stored_runs
    package = tmp_path / "lfc"
    shutil.copytree(stored_runs._PACKAGE, package,
                    ignore=shutil.ignore_patterns("__pycache__", "*.run"))

    def digest() -> str:
        return stored_runs.plant_digest(package, kind)

    before = digest()
    assert before == stored_runs.plant_digest(kind=kind)
    for name in stored_runs.PLANT_CODE[kind]:
        module, _, definition = name.partition(":")
        path = package / (module.split(".", 1)[1].replace(".", "/") + ".py"
                          if definition else module)
        text = path.read_text()
        path.write_text(text + "\n# a comment\n")
        assert digest() == before, name                           # not code
        if definition:                  # a statement added to the definition's body
            node = next(n for n in ast.parse(text).body if getattr(n, "name", "") == definition)
            lines = text.splitlines(keepends=True)
            indent = " " * (node.body[-1].col_offset)
            lines.insert(node.end_lineno, f"{indent}EDITED = 1\n")
            path.write_text("".join(lines))
        else:
            path.write_text(text + "\nEDITED = 1\n")
        assert digest() != before, name
        path.write_text(text)
    engine = package / "engine.py"
    text = engine.read_text()
    engine.write_text(text.replace('    """Evaluate an attack or load signal at times',
                                   '    """Evaluate an attack or a load signal at times'))
    assert digest() == before                                     # a docstring: not code
    engine.write_text(text + "\nEDITED = 1\n")                    # elsewhere in the engine
    for name in ("filters/certified.py", "filters/coupled.py", "linear_grid.py",
                 "testbed/grids.py", "testbed/microgrid.py"):    # (their other code)
        path = package / name
        path.write_text(path.read_text() + "\nEDITED = 1\n")
    assert digest() == before


def test_every_committed_recording_is_of_the_plant_side_as_it_is(tmp_path, monkeypatch):
    """The recordings (``lfc/testbed/recordings``) read back (their SHA-256), each of
    the plant side as it is now: an edit of the plant side makes them stale, and they
    are recorded again (docs/testbed.md).  A damaged one is refused, naming the file,
    and the run it stood for runs on ANDES instead."""
    import shutil
    import warnings

    from lfc.testbed import stored_runs
    paths = stored_runs.recordings()
    assert paths, "no committed recordings"
    stale = [p.name for p in paths if (rec := stored_runs.read_recording(p)).plant
             != stored_runs.plant_digest(kind=rec.kind)]
    assert not stale, (f"{len(stale)} recordings of an earlier plant side: record them again "
                       f"(docs/testbed.md, 'Recordings')")
    damaged = tmp_path / paths[0].name
    shutil.copy(paths[0], damaged)
    data = bytearray(damaged.read_bytes())
    data[-10] ^= 1
    damaged.write_bytes(bytes(data))
    with pytest.raises(ValueError, match=f"damaged recording {damaged}"):
        stored_runs.read_recording(damaged)
    key = paths[0].name.rsplit("-", 1)[0]
    monkeypatch.setenv("LFC_CACHE_DIR", str(tmp_path / "cache"))   # no machine store
    monkeypatch.delenv("LFC_ANDES_RECORDINGS")                       # the recordings read
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        stored_runs.RECORDINGS, kept = tmp_path, stored_runs.RECORDINGS
        try:
            assert list(stored_runs.stored(key)) == []
        finally:
            stored_runs.RECORDINGS = kept
    assert any("damaged recording" in str(w.message) for w in caught)


def checked_recordings() -> list:
    """The recordings the exhaustive tier runs again: every one of 20 s or less (the
    tests'), and of each case's longer ones (chapter 09's) the shortest."""
    from lfc.testbed import stored_runs
    headers = {p: stored_runs.recording_header(p) for p in stored_runs.recordings()}
    longer: dict = {}
    for p, h in sorted(headers.items(), key=lambda ph: (ph[1]["duration"], ph[0].name)):
        if h["duration"] > 20.0:
            longer.setdefault(h["case"], p)
    return [p for p, h in headers.items() if h["duration"] <= 20.0 or p in longer.values()]


@pytest.mark.exhaustive
@pytest.mark.parametrize("path", checked_recordings(), ids=lambda p: p.name[:12])
def test_andes_given_a_recordings_commands_computes_its_record(path):
    """ANDES, fed the commands a recording holds at its control samples (no generator
    side computes them), integrates the recorded run: every logged value within 1e-9
    (relative) on the machine that recorded it, ``CROSS_MACHINE``'s ANDES tolerance
    elsewhere (tests/regression_set.py)."""
    import numpy as np
    import regression_set as rs

    from lfc.testbed import grids, microgrid, stored_runs
    rec = stored_runs.read_recording(path)
    run = (grids if rec.kind == "grid" else microgrid).rerun(rec)
    rtol, atol = ((rs.ANDES_RTOL, rs.ATOL) if rec.machine == stored_runs.machine()
                  else rs.CROSS_MACHINE["andes"])
    assert np.array_equal(run.read, rec.run.read)
    if rec.kind == "grid":
        np.testing.assert_allclose(run.t, rec.run.t, rtol=0, atol=1e-9)
        np.testing.assert_allclose(run.per_area, rec.run.per_area, rtol=rtol, atol=atol)
        assert [t.to_dict() for t in run.trips] == [t.to_dict() for t in rec.run.trips]
    else:
        np.testing.assert_allclose(run.rows, rec.run.rows, rtol=rtol, atol=atol)
        assert run.trips.to_dict() == rec.run.trips.to_dict()
        assert run.overcurrent == pytest.approx(rec.run.overcurrent, abs=1e-9)


def test_a_microgrid_run_is_read_back_bit_for_bit_with_its_fault(tmp_path, monkeypatch):
    """The microgrid's runs are stored too (``kind="microgrid"``): a fault's two passes,
    an attack with the paper's SCC; each call again reads its run back, equal bit for
    bit to running it with the store off (trace, controls, alarms, the line's trip)."""
    from lfc.testbed import FaultSpec, MicrogridCase
    from lfc.testbed.fit import design_model
    monkeypatch.setenv("LFC_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv(SWITCH, raising=False)
    clock = tmp_path / "clock"
    monkeypatch.setenv(CLOCK_ENV, str(clock))
    params = design_model()
    scc = lfc.SafetyFilter(params, alpha=20.0)
    for kw in ({"pc_attack": lfc.Sinusoid(0.5, 1.0, start=1.0)}, {"fault": FaultSpec()}):
        run = dict(design=params, duration=2.0, scc=scc, **kw)
        lfc.simulate(MicrogridCase(), **run)
        n = len(clock.read_text().split())
        again = lfc.simulate(MicrogridCase(), **run)
        assert len(clock.read_text().split()) == n                   # read back
        monkeypatch.setenv(SWITCH, "off")
        fresh = lfc.simulate(MicrogridCase(), **run)
        monkeypatch.delenv(SWITCH)
        for frame in ("trace", "controls", "alarms", "trips", "line_trips"):
            pd.testing.assert_frame_equal(getattr(again, frame), getattr(fresh, frame),
                                          check_exact=True)
    assert len(fresh.line_trips) == 1


def test_the_key_follows_what_a_keyed_definition_names_in_its_module(tmp_path):
    """A keyed definition is hashed with every top-level definition of its module that it
    names, directly or through another (``stored_runs.source_digest``): an edit of the
    grid builder's helper ``_bus_kv`` (named by ``_build``, named by ``build_grid``)
    changes the grids' key; an edit of ``_result``, which builds a result from a run
    and which no keyed definition names, does not."""
    import ast
    import shutil

    from lfc.testbed import stored_runs
    package = tmp_path / "lfc"
    shutil.copytree(stored_runs._PACKAGE, package,
                    ignore=shutil.ignore_patterns("__pycache__", "*.run"))
    path = package / "testbed" / "grids.py"
    text = path.read_text()
    before = stored_runs.plant_digest(package, "grid")
    names = [n for n, _ in stored_runs._definitions(path, "build_grid")]
    assert {"_build", "_bus_kv", "GridCase"} <= set(names)

    def edited(definition: str) -> str:
        node = next(n for n in ast.parse(text).body if getattr(n, "name", "") == definition)
        lines = text.splitlines(keepends=True)
        lines.insert(node.end_lineno, f"{' ' * node.body[-1].col_offset}EDITED = 1\n")
        return "".join(lines)

    path.write_text(edited("_bus_kv"))
    assert stored_runs.plant_digest(package, "grid") != before
    path.write_text(edited("_result"))
    assert stored_runs.plant_digest(package, "grid") == before
    with pytest.raises(ValueError, match="defines no function, class or assignment"):
        stored_runs._definitions(path, "no_such_name")
