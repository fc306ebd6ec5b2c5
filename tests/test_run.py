"""The two entry points: simulate and simulate_many take any plant, each kind of plant
bringing its runner; the names of 0.3 are gone."""

import ast
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import lfc

P, TWO = lfc.LFCParams(), lfc.MultiAreaParams.two_area()
ATTACK = lfc.Sinusoid(0.5, 1.0, start=1.0)


def test_simulate_dispatches_on_the_plant():
    area = lfc.simulate(P, duration=2.0, pc_attack=ATTACK)
    grid = lfc.simulate(TWO, duration=2.0, attacks={0: {"pc": ATTACK}})
    assert type(area) is lfc.Result and type(grid) is lfc.Result
    one = lfc.simulate(lfc.MultiAreaParams(areas=(P,)), duration=2.0,
                       attacks={0: {"pc": ATTACK}}, feedforward=False)
    pd.testing.assert_frame_equal(one.areas[0].trace[area.trace.columns], area.trace)


def test_simulate_many_dispatches_on_the_plant():
    table = pd.DataFrame({"waveform": ["sinusoid"], "channel": ["pc"], "amplitude": [0.5],
                          "freq_hz": [1.0], "start": [1.0], "alpha": [np.nan], "Ts": [0.25]})
    rows = lfc.simulate_many(P, table, duration=2.0, progress=False)
    grid = lfc.simulate_many(TWO, [{"attacks": {0: {"pc": ATTACK}}}], duration=2.0)
    assert list(grid.area) == [0, 1] and len(rows) == 1
    assert rows.max_abs_rocof_meas[0] == lfc.simulate(P, duration=2.0, pc_attack=ATTACK)\
        .metrics()["max_abs_rocof_meas"]


def _same(table: pd.DataFrame, results: list, areas: bool) -> None:
    """``results``' metrics are ``table``'s rows, value for value (a grid's mean
    modification to 1e-12: the table sums it in the kernel, a result from its trace)."""
    rows = table.to_dict("records")
    mine = [{"scenario": i, "area": a, **m} for i, r in enumerate(results)
            for a, m in r.metrics().items()] if areas else [r.metrics() for r in results]
    assert len(rows) == len(mine)
    for row, m in zip(rows, mine):
        for key, value in m.items():
            if isinstance(value, float) and not pd.isna(value):
                assert row[key] == pytest.approx(value, rel=1e-12, abs=1e-15), key
            else:
                assert row[key] == value or (pd.isna(row[key]) and pd.isna(value)), key


def test_simulate_many_keeps_the_metrics_table_or_the_results_for_every_plant():
    """Issue "One": one return for every plant — the metrics table by default, one
    result per scenario with ``keep="results"``, whose ``metrics()`` are the table's
    rows (a single area's table with noise and a certified filter; a grid's scenarios
    with keywords they share)."""
    table = pd.DataFrame({"waveform": ["sinusoid", "step", "sinusoid"],
                          "channel": ["pc", "load", "pc"], "amplitude": [0.1, 0.05, 2.0],
                          "freq_hz": [1.0, 0.0, 1.0], "start": 0.5,
                          "alpha": [np.nan, 20.0, np.nan], "Ts": 0.25,
                          "method": ["paper", "certified", "paper"],
                          "noise_w": [0.0, 1e-4, 0.0], "noise_rocof": [0.0, 1e-3, 0.0],
                          "seed": [0, 3, 0]})
    metrics = lfc.simulate_many(P, table, duration=3.0, progress=False)
    results = lfc.simulate_many(P, table, duration=3.0, progress=False, keep="results")
    assert all(isinstance(r, lfc.Result) for r in results) and results[2].metrics()["tripped"]
    _same(metrics, results, areas=False)
    scenarios = [{}, {"filters": {0: "certified", 1: "certified"}}]
    shared = {"attacks": {0: {"pc": lfc.Sinusoid(1.0, 0.5, start=1.0)}}, "anti_windup": True}
    grid = lfc.simulate_many(TWO, scenarios, duration=5.0, **shared)
    runs = lfc.simulate_many(TWO, scenarios, duration=5.0, keep="results", **shared)
    assert list(grid.columns[:2]) == ["scenario", "area"] and len(grid) == 4
    _same(grid, runs, areas=True)
    one = lfc.simulate(TWO, duration=5.0, **shared)
    assert runs[0].metrics() == one.metrics()
    with pytest.raises(ValueError, match="keep must be one of"):
        lfc.simulate_many(TWO, scenarios, duration=5.0, keep="traces")
    with pytest.raises(ValueError, match="chunk_size is for keep='metrics'"):
        lfc.simulate_many(P, table, duration=3.0, keep="results", chunk_size=2)


@pytest.mark.parametrize("plant", ["kundur", None, 3.0])
def test_an_unknown_plant_is_a_clear_error(plant):
    with pytest.raises(ValueError, match="plant must be an LFCParams, a MultiAreaParams, an "
                                         "lfc.testbed.MicrogridCase, an lfc.testbed.GridCase "
                                         "or an lfc.testbed.AndesPlant, got"):
        lfc.simulate(plant, duration=1.0)
    with pytest.raises(ValueError, match="plant must be"):
        lfc.simulate_many(plant, [], duration=1.0)


def test_design_is_for_andes_cases_only():
    with pytest.raises(ValueError, match="design is for ANDES cases only"):
        lfc.simulate(P, duration=1.0, design=P)


@pytest.mark.parametrize("old", ["simulate_batch", "simulate_multiarea",
                                 "simulate_multiarea_batch"])
def test_the_names_of_0_3_are_gone(old):
    """Removed in 0.4 (CHANGELOG.md names what replaces each); ``lfc.linear_grid``
    is the module once imported, not a function."""
    assert old not in lfc.__all__ and not callable(getattr(lfc, old, None))
    assert old in (Path(lfc.__file__).parents[1] / "CHANGELOG.md").read_text()


def test_simulate_runs_the_andes_cases_with_their_fitted_design_models():
    pytest.importorskip("andes")
    from lfc.testbed import GridCase, MicrogridCase, grid_design
    from lfc.testbed.fit import design_model
    micro = lfc.simulate(MicrogridCase(), duration=0.5, pc_attack=ATTACK)
    again = lfc.simulate(MicrogridCase(), design=design_model(), duration=0.5, pc_attack=ATTACK)
    pd.testing.assert_frame_equal(micro.trace, again.trace)
    case = GridCase.kundur()
    grid = lfc.simulate(case, duration=0.3, attacks={0: {"pc": ATTACK}})
    again = lfc.simulate(case, design=grid_design(case), duration=0.3,
                         attacks={0: {"pc": ATTACK}})
    pd.testing.assert_frame_equal(grid.trace, again.trace)
    many = lfc.simulate_many(case, [{"attacks": {0: {"pc": ATTACK}}}], duration=0.3, jobs=1,
                             progress=False, keep="results")
    pd.testing.assert_frame_equal(grid.trace, many[0].trace)
    with pytest.raises(ValueError, match="does not run the ANDES microgrid"):
        lfc.simulate_many(MicrogridCase(), [], duration=1.0)


def test_a_plant_brings_its_runner_and_an_andes_plant_is_known_by_its_methods():
    """Issue "One": lfc.run names no plant type — each kind registers its runner
    (the linear plants in their modules, the ANDES cases in lfc.testbed, loaded the
    first time a plant matches none); a plant of your own with every method of the
    AndesPlant protocol and ``n_areas`` runs as one, and lacking one method it is an
    unknown plant."""
    pytest.importorskip("andes")
    from lfc.run import Runner, register, runner_of
    from lfc.testbed import ANDES_PLANT, GridCase, MicrogridCase
    source = ast.parse(Path(lfc.run.__file__).read_text())
    named = {n.id for n in ast.walk(source) if isinstance(n, ast.Name)}
    imported = {n.module for n in ast.walk(source) if isinstance(n, ast.ImportFrom)}
    assert not named & {"LFCParams", "MultiAreaParams", "MicrogridCase", "GridCase"}
    assert not [m for m in imported if m.startswith(("lfc.testbed", "lfc.simulate", "lfc.tables"))]
    assert [runner_of(p).name for p in (P, TWO, MicrogridCase(), GridCase.kundur())] == \
        ["area", "grid", "microgrid", "grid case"]
    methods = {name: (lambda *args: None) for name in ANDES_PLANT}
    own = type("Own", (), {**methods, "n_areas": 2})()
    assert runner_of(own).name == "andes plant"
    for no_design in (lambda: lfc.simulate(own, duration=1.0), lambda: lfc.design_of(own)):
        with pytest.raises(ValueError, match="has no fitted design model: give"):
            no_design()
    lacking = type("Lacking", (), {**methods, "n_areas": 2, ANDES_PLANT[0]: None})()
    with pytest.raises(ValueError, match="plant must be"):
        runner_of(lacking)

    class Mine(lfc.LFCParams):
        pass
    assert runner_of(Mine()).name == "area"              # a subclass runs as its base
    # each plant's design model: a linear plant is its own, an ANDES case's is its fit
    from lfc.testbed.fit import design_model, grid_design
    assert lfc.design_of(P) is P and lfc.design_of(TWO) is TWO
    assert lfc.design_of(MicrogridCase()) == design_model(MicrogridCase())
    assert lfc.design_of(GridCase.kundur()) == grid_design(GridCase.kundur())
    with pytest.raises(TypeError, match="register takes a type and a Runner"):
        register(Mine(), Runner("area", "x", "an x", lfc.simulate))


def test_one_result_type_an_area_is_its_own_only_area_and_a_grid_holds_its_areas(tmp_path):
    """Issue "One": every plant's run returns :class:`lfc.Result`.  An area's result is
    its own only area; a grid's holds each area's, and its controls, trips, alarms and
    line trips are every area's after an ``area`` column, in area order; its first trip
    names its area; ``table()`` is one row per area on both; ``save`` writes an area's
    frames, a grid's per area."""
    attacks = {0: {"pc": lfc.Square(2.0, 0.5, start=0.5)}, 1: {"pc": ATTACK}}
    filters = {0: lfc.SafetyFilter(TWO.areas[0], alpha=20.0)}
    grid = lfc.simulate(TWO, duration=4.0, attacks=attacks, filters=filters)
    area = grid.areas[0]
    assert area.areas == (area,) and area.n_areas == 1 and grid.n_areas == 2
    assert area.grid == () and grid.grid == grid.areas
    for name in ("controls", "trips", "alarms", "line_trips"):
        frame = getattr(grid, name)
        assert list(frame.columns) == ["area", *getattr(area, name).columns], name
        parts = [getattr(r, name) for r in grid.areas]
        assert list(frame.area) == [a for a, p in enumerate(parts) for _ in range(len(p))]
        for a, part in enumerate(parts):
            got = frame[frame.area == a].drop(columns="area").reset_index(drop=True)
            pd.testing.assert_frame_equal(got, part.reset_index(drop=True), check_dtype=False)
    assert grid.tripped and len(grid.alarms) == len(area.alarms) > 0
    first = min((float(r.trips.t.min()), a) for a, r in enumerate(grid.areas) if r.tripped)
    assert (grid.first_trip["t"], grid.first_trip["area"]) == first
    assert set(grid.areas[first[1]].first_trip) == {"relay", "t"}
    pd.testing.assert_frame_equal(grid.table(), pd.concat(
        [r.table().assign(area=a) for a, r in enumerate(grid.areas)], ignore_index=True))
    assert grid.metrics() == {a: r.metrics() for a, r in enumerate(grid.areas)}
    grid.save(tmp_path / "grid")
    area.save(tmp_path / "area")
    assert {p.name for p in (tmp_path / "grid").iterdir()} == {
        "trace.csv", "metrics.json", "settings.json", "area_0", "area_1"}
    assert {p.name for p in (tmp_path / "area").iterdir()} == {
        "trace.csv", "metrics.json", "settings.json", "controls.csv", "trips.csv",
        "alarms.csv", "line_trips.csv"}
    assert grid.disturbance_step(1) > 0.0            # the tie-line flow moves p_net_1
    with pytest.raises(ValueError, match="area"):
        grid.disturbance_step(2)
    step = lfc.simulate(P, duration=2.0, load=lfc.Step(0.05, 0.505))
    assert step.disturbance_step() == pytest.approx(0.05)
