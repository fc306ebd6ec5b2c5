"""The two entry points: simulate and simulate_many take any plant, and the names of
0.3 are deprecated aliases that call them."""

import numpy as np
import pandas as pd
import pytest

import lfc

P, TWO = lfc.LFCParams(), lfc.MultiAreaParams.two_area()
ATTACK = lfc.Sinusoid(0.5, 1.0, start=1.0)


def test_simulate_dispatches_on_the_plant():
    area = lfc.simulate(P, duration=2.0, pc_attack=ATTACK)
    grid = lfc.simulate(TWO, duration=2.0, attacks={0: {"pc": ATTACK}})
    assert isinstance(area, lfc.SimResult) and isinstance(grid, lfc.MultiAreaResult)
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
    assert all(isinstance(r, lfc.SimResult) for r in results) and results[2].metrics()["tripped"]
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


@pytest.mark.parametrize("old, args, new", [
    ("simulate_multiarea", (TWO,), lambda: lfc.simulate(TWO, duration=1.0)),
    ("simulate_multiarea_batch", (TWO, [{}]), lambda: lfc.simulate_many(TWO, [{}],
                                                                         duration=1.0)),
])
def test_old_names_warn_and_call_the_new_ones(old, args, new):
    with pytest.warns(DeprecationWarning, match=f"lfc.{old} is deprecated"):
        got = getattr(lfc, old)(*args, duration=1.0)
    want = new()
    if isinstance(want, pd.DataFrame):
        pd.testing.assert_frame_equal(got, want)
    else:
        pd.testing.assert_frame_equal(got.trace, want.trace)


def test_simulate_batch_warns_and_calls_simulate_many():
    table = pd.DataFrame({"waveform": ["step"], "channel": ["load"], "amplitude": [0.1],
                          "freq_hz": [0.0], "start": [0.5], "alpha": [20.0], "Ts": [0.25]})
    with pytest.warns(DeprecationWarning, match="lfc.simulate_batch is deprecated"):
        got = lfc.simulate_batch(P, table, duration=1.0, progress=False)
    pd.testing.assert_frame_equal(got, lfc.simulate_many(P, table, duration=1.0,
                                                         progress=False))


def test_old_grid_names_still_refuse_a_single_area():
    with pytest.warns(DeprecationWarning), \
            pytest.raises(ValueError, match="params must be a MultiAreaParams"):
        lfc.simulate_multiarea(P, duration=1.0)


def test_simulate_runs_the_andes_cases_with_their_fitted_design_models():
    pytest.importorskip("andes")
    from lfc.testbed import (GridCase, MicrogridCase, grid_design, simulate_grid,
                             simulate_grid_batch, simulate_testbed)
    from lfc.testbed.fit import design_model
    micro = lfc.simulate(MicrogridCase(), duration=0.5, pc_attack=ATTACK)
    with pytest.warns(DeprecationWarning, match="simulate_testbed is deprecated"):
        old = simulate_testbed(design_model(), duration=0.5, pc_attack=ATTACK)
    pd.testing.assert_frame_equal(micro.trace, old.trace)
    case = GridCase.kundur()
    grid = lfc.simulate(case, duration=0.3, attacks={0: {"pc": ATTACK}})
    with pytest.warns(DeprecationWarning, match="simulate_grid is deprecated"):
        old = simulate_grid(grid_design(case), case=case, duration=0.3,
                            attacks={0: {"pc": ATTACK}})
    pd.testing.assert_frame_equal(grid.trace, old.trace)
    with pytest.warns(DeprecationWarning, match="simulate_grid_batch is deprecated"):
        old = simulate_grid_batch(grid_design(case), [{"attacks": {0: {"pc": ATTACK}}}],
                                  duration=0.3, jobs=1, progress=False)
    pd.testing.assert_frame_equal(grid.trace, old[0].trace)
    with pytest.raises(ValueError, match="does not run the ANDES microgrid"):
        lfc.simulate_many(MicrogridCase(), [], duration=1.0)


def test_the_plant_check_names_every_method_of_an_andes_plant():
    """lfc.run recognizes an AndesPlant by its methods without importing the
    testbed: its list is the protocol's."""
    pytest.importorskip("andes")
    from lfc.run import ANDES_PLANT
    from lfc.testbed.loop import AndesPlant
    methods = {n for n, v in vars(AndesPlant).items() if callable(v) and not n.startswith("_")}
    assert set(ANDES_PLANT) == methods
