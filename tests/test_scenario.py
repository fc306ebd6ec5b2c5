"""Issue "One": one ``Scenario`` for every plant — checked once when made, run by
``lfc.simulate(plant, scenario)`` and ``lfc.simulate_many(plant, [scenario, ...])`` on
an area, a grid and ANDES, read from a scenario table and written back to one
(``lfc.tables.table_scenarios``, ``scenario_row``)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
import tiers
from hypothesis import given, settings
from hypothesis import strategies as st
from same_metrics import same_metrics
from test_lanes import mixed

import lfc
from lfc.tables import scenario_row, table_scenarios
from lfc.scenarios import Scenario
from lfc.result import METRIC_KEYS

P, TWO = lfc.LFCParams(), lfc.MultiAreaParams.two_area()
ATTACK = lfc.Sinusoid(1.0, 0.5, start=0.5)


@pytest.mark.parametrize("fields, error, match", [
    ({"attacks": {0: 3}}, TypeError, r"attacks\[0\] must be a dict with keys among"),
    ({"attacks": {0: {"pz": ATTACK}}}, ValueError, r"attacks\[0\] must be a dict"),
    ({"attacks": {-1: {}}}, ValueError, "a key of attacks must be an area index"),
    ({"loads": {True: ATTACK}}, ValueError, "a key of loads must be an area index"),
    ({"loads": [ATTACK]}, TypeError, r"loads must be a dict \{area: ...\}"),
    ({"noise_std": (-1.0, 0.0)}, ValueError, "noise_std"),
    ({"seed": -1}, ValueError, "seed"),
    ({"feedforward": "yes"}, TypeError, "feedforward"),
    ({"relay_noise": True}, ValueError, "relay_noise=True needs noise_std > 0"),
    ({"plant": "kundur"}, TypeError, "plant must be an LFCParams, a MultiAreaParams or None"),
])
def test_a_scenario_is_checked_once_when_made_naming_the_field(fields, error, match):
    with pytest.raises(error, match=match):
        Scenario(**fields)


def test_an_area_is_area_0_and_its_keywords_come_back():
    scc = lfc.SafetyFilter(P, alpha=3.0)
    s = Scenario.for_area(pc_attack=ATTACK, load=lfc.Step(0.05, start=1.0), scc=scc,
                          seed=4, anti_windup=True)
    assert s.attacks == {0: {"pc": ATTACK}} and s.filters == {0: scc}
    kw = s.keywords("area")
    assert (kw["pc_attack"], kw["wref_attack"], kw["scc"], kw["seed"]) == (ATTACK, None, scc, 4)
    assert Scenario.for_area(**kw) == s
    assert "feedforward" not in Scenario().keywords("grid")      # the plant's default
    for bad, match in (({"attacks": {1: {"pc": ATTACK}}}, "a single area is area 0"),
                       ({"attacks": {0: {"ace": ATTACK}}}, "has no tie-line"),
                       ({"filters": {0: "certified"}}, "takes a built filter")):
        with pytest.raises(ValueError, match=match):
            Scenario(**bad).keywords("area")
    with pytest.raises(ValueError, match="form must be"):
        s.keywords("areas")


@pytest.mark.parametrize("plant, scenario", [
    (P, Scenario.for_area(pc_attack=ATTACK, scc=lfc.SafetyFilter(P, method="certified"),
                          noise_std=(1e-4, 1e-3), estimator="kalman", seed=2)),
    (TWO, Scenario(attacks={0: {"pc": ATTACK}, 1: {"ace": lfc.Step(0.2, start=1.0)}},
                   loads={1: lfc.Step(0.05, start=2.0)}, filters={0: "certified", 1: "paper"},
                   anti_windup=True)),
    (TWO, Scenario(attacks={0: {"pc": ATTACK}}, filters={0: "coupled", 1: "coupled"})),
])
def test_simulate_runs_a_scenario_as_its_keywords(plant, scenario):
    """One scenario as an object or as keywords: the same run; its result's metrics
    table (``table()``: ``area`` and the metrics, an area's as a grid's) is its
    ``simulate_many`` rows."""
    form = "area" if isinstance(plant, lfc.LFCParams) else "grid"
    one = lfc.simulate(plant, scenario, duration=4.0)
    pd.testing.assert_frame_equal(one.trace, lfc.simulate(plant, duration=4.0,
                                                          **scenario.keywords(form)).trace)
    rows = lfc.simulate_many(plant, [scenario, Scenario()], duration=4.0)
    assert list(rows.columns[:2]) == ["scenario", "area"]
    for a, area in enumerate(one.areas):              # an area is a grid of one area
        assert same_metrics(area.metrics(), rows[(rows.scenario == 0) & (rows.area == a)]
                            .iloc[0]), a
    mine = rows[rows.scenario == 0].drop(columns="scenario").reset_index(drop=True)
    pd.testing.assert_frame_equal(one.table(), mine, check_dtype=False, rtol=1e-12)
    assert not rows[rows.scenario == 1].tripped.any()
    with pytest.raises(ValueError, match="as a Scenario or as keywords, not both"):
        lfc.simulate(plant, scenario, duration=1.0, seed=3)


def test_a_scenario_with_its_own_plant_runs_in_simulate_many_of_an_area_only():
    heavy = Scenario.for_area(pc_attack=ATTACK)
    light = Scenario(attacks=heavy.attacks, plant=lfc.LFCParams(M=0.8 * P.M))
    rows = lfc.simulate_many(P, [heavy, light], duration=3.0)
    assert rows.max_abs_rocof_meas[1] > rows.max_abs_rocof_meas[0]     # less inertia
    with pytest.raises(ValueError, match="simulate runs the plant it is given"):
        lfc.simulate(P, light, duration=1.0)
    with pytest.raises(ValueError, match=r"scenarios\[1\].plant"):
        lfc.simulate_many(P, [heavy, light], duration=1.0, keep="results")
    with pytest.raises(ValueError, match=r"scenarios\[0\].plant: a grid's scenarios"):
        lfc.simulate_many(TWO, [Scenario(plant=TWO)], duration=1.0)
    with pytest.raises(TypeError, match=r"scenarios\[1\] is a dict"):
        lfc.simulate_many(P, [heavy, {}], duration=1.0)


def test_a_scenario_list_keeps_its_results_as_simulate_gives_them():
    scenarios = [Scenario.for_area(pc_attack=ATTACK), Scenario.for_area(
        load=lfc.Step(0.1, start=1.0), scc=lfc.SafetyFilter(P, alpha=3.0))]
    results = lfc.simulate_many(P, scenarios, duration=3.0, keep="results")
    for r, s in zip(results, scenarios):
        assert r.metrics() == lfc.simulate(P, s, duration=3.0).metrics()


@settings(max_examples=tiers.examples(8), deadline=None)
@given(seed=st.integers(0, 10_000))
def test_a_table_read_as_scenarios_and_written_back_runs_the_same(seed):
    """``table_scenarios`` then ``scenario_row``: the same table, row for row (every kind
    of row: waveforms on every channel, the filters and their readings, other plants,
    noise with its Kalman estimate, relay noise, anti-windup); its scenarios as a list
    give the table's metrics."""
    table = mixed(24, seed)
    scenarios = table_scenarios(table, P, duration=4.0)
    again = pd.DataFrame([scenario_row(s, P) for s in scenarios])
    twice = pd.DataFrame([scenario_row(s, P) for s in table_scenarios(again, P, duration=4.0)])
    pd.testing.assert_frame_equal(twice, again)
    want = lfc.simulate_many(P, table, duration=4.0, progress=False)
    back = lfc.simulate_many(P, again, duration=4.0, progress=False)
    listed = lfc.simulate_many(P, scenarios, duration=4.0)
    keys = list(METRIC_KEYS)
    for got in (back[keys], listed[keys].set_index(want.index)):
        pd.testing.assert_frame_equal(got, want[keys], check_dtype=False, rtol=1e-12)


def test_what_a_table_cannot_hold_is_refused_naming_it():
    cases = [
        (Scenario.for_area(pc_attack=ATTACK, load=ATTACK), "holds one signal"),
        (Scenario.for_area(pc_attack=lfc.Sinusoid(1.0, 0.5, phase=1.0)), "has no phase"),
        (Scenario.for_area(pc_attack=lfc.Chirp(1.0, 0.5, 2.0)), "chirp starts at"),
        (Scenario.for_area(scc=lfc.SafetyFilter(lfc.LFCParams(M=3.0))), "built on the table"),
        (Scenario.for_area(scc=lfc.SafetyFilter(P, method="certified", load_bound=0.02)),
         r"cannot hold the filter's option\(s\) \['load_bound'\]"),
        (Scenario.for_area(noise_std=(1e-4, 1e-3)), "exactly where there is noise"),
        (Scenario.for_area(scc=lfc.SafetyFilter(P), load_feedforward=True), "feed-forward"),
    ]
    for scenario, match in cases:
        with pytest.raises(ValueError, match=match):
            scenario_row(scenario, P)
    row = scenario_row(Scenario(), P)
    assert row["waveform"] == "none" and math.isnan(row["alpha"])


def test_the_andes_cases_run_a_scenario():
    pytest.importorskip("andes")
    from lfc.testbed import GridCase, MicrogridCase
    micro = lfc.simulate(MicrogridCase(), Scenario.for_area(pc_attack=ATTACK), duration=0.5)
    pd.testing.assert_frame_equal(
        micro.trace, lfc.simulate(MicrogridCase(), duration=0.5, pc_attack=ATTACK).trace)
    case, grid = GridCase.kundur(), Scenario(attacks={0: {"pc": ATTACK}})
    rows = lfc.simulate_many(case, [grid], duration=0.3, jobs=1, progress=False)
    one = lfc.simulate(case, grid, duration=0.3)
    assert np.allclose(rows.max_abs_rocof_meas, [m["max_abs_rocof_meas"]
                                                 for m in one.metrics().values()])
