"""The two-area Kundur system on ANDES: the case, the fitted design model, the
command's path to the governors, the tie-line meter, and bad scenarios.  What
the filters do on it is checked by notebook 09's claims on the testbed
(tests/test_notebooks.py)."""

import dataclasses
import json

import numpy as np
import pytest

import lfc
from lfc.multiarea import MultiAreaParams
from lfc.testbed import (KundurCase, build_kundur, kundur_fit_report, simulate_kundur,
                         simulate_kundur_batch)
from lfc.testbed import fit as fitting
from lfc.testbed import kundur_fit

CASE = KundurCase()


@pytest.fixture(scope="module")
def fit():
    return kundur_fit_report(CASE)


def test_the_fit_finds_the_case_inertia_and_reports_its_errors(fit):
    """Each area's fitted inertia is its machines' (13 and 12.35 s on 1800 MVA)
    within 10 %; the measurement lags stay the meters' settings; the fitted
    model is closer to ANDES than the case data's, and its frequency error is
    at most 15 % of the response's peak (measured: 10 % and 4 %; the case's
    turbine lead-lag is what is left)."""
    for report, m_case in zip(fit.areas, (13.0, 12.35)):
        assert report.params.M == pytest.approx(m_case, rel=0.10)
        assert (report.params.tau_w, report.params.tau_rocof) == (CASE.tau_w, CASE.tau_rocof)
        assert report.params.tau_g >= kundur_fit.LOWER["tau_g"] - 1e-12
        for out in ("dw", "dw_meas", "rocof_meas"):
            assert report.error[out] < min(0.15, report.initial_error[out]), out
    assert 50 < fit.T < 200 and fit.tie_error < 0.3
    assert fit.params.tie == ((0, 1, fit.T),)
    assert "Tie-line" in fit.table() and "| M (s) |" in fit.table()


def test_the_fit_cache_round_trips_exactly(fit, tmp_path, monkeypatch):
    monkeypatch.setenv("LFC_CACHE_DIR", str(tmp_path))
    path = fitting._cache_path(CASE, "kundur-fit")
    assert path.parent == tmp_path
    fitting._write_report(path, fit, kundur_fit._encode)
    assert fitting._read_report(path, kundur_fit._decode) == fit
    stored = json.loads(path.read_text())
    stored["payload"] = stored["payload"].replace('"T": ', '"T": 1')    # a changed value
    path.write_text(json.dumps(stored))
    with pytest.warns(RuntimeWarning, match="damaged cache file"):
        assert fitting._read_report(path, kundur_fit._decode) is None


def test_the_area_command_reaches_its_governors_on_the_area_base(fit):
    """Without AGC, a 0.02 pu command step in area 0 moves area 0's turbines
    0.02 pu more than area 1's in steady state (equal droops, one frequency):
    the command is written as ``R u scale / n`` to each governor."""
    params = dataclasses.replace(fit.params, k_agc=(0.0, 0.0))
    r = simulate_kundur(params, duration=40.0, attacks={0: {"pc": lfc.Step(0.02, 1.0)}},
                        case=CASE)
    end = r.trace.iloc[-1]
    assert end["pc_0"] == 0.02 and end["pc_1"] == 0.0
    assert end["dPm_0"] - end["dPm_1"] == pytest.approx(0.02, abs=5e-4)
    assert end["p_tie_0"] > 0.005                    # area 0 exports part of its extra power
    # what one end exports the other imports, but for the lines' losses (4 % measured)
    assert abs(end["p_tie_0"] + end["p_tie_1"]) < 0.05 * end["p_tie_0"]
    assert not r.tripped


def test_batch_equals_one_by_one(fit):
    scenarios = [{"attacks": {1: {"ace": lfc.Step(-0.5, 0.5)}}},
                 {"filters": {0: "certified"}, "loads": {0: lfc.Step(0.05, 0.5)}}]
    batch = simulate_kundur_batch(fit.params, scenarios, duration=2.0, jobs=2, progress=False)
    for s, r in zip(scenarios, batch):
        one = simulate_kundur(fit.params, duration=2.0, **s)
        assert np.array_equal(one.trace.to_numpy(), r.trace.to_numpy())


@pytest.mark.parametrize("kwargs, message", [
    ({"params": MultiAreaParams.three_area()}, "params must be a MultiAreaParams of 2 areas"),
    ({"attacks": {2: {"pc": lfc.Step(1.0)}}}, "attacks has key 2"),
    ({"attacks": {0: {"load": lfc.Step(1.0)}}}, "attacks\\[0\\] must be a dict with keys"),
    ({"control_period": 0.0125}, "control_period"),
    ({"duration": -1.0}, "duration"),
])
def test_bad_scenarios_are_refused_before_anything_runs(fit, kwargs, message):
    kwargs = {"params": fit.params, "duration": 1.0, **kwargs}
    with pytest.raises(ValueError, match=message):
        simulate_kundur(kwargs.pop("params"), **kwargs)


@pytest.mark.parametrize("change, message", [
    ({"meter_buses": (6, 99)}, "meter_buses names bus 99"),
    ({"generators": ((1, 2), (3, 9))}, "generators names machine 9"),
    ({"tie_lines": ("Line_99",)}, "tie_lines names 'Line_99'"),
])
def test_a_case_that_names_what_the_grid_lacks_is_refused(change, message):
    with pytest.raises(ValueError, match=message):
        build_kundur(dataclasses.replace(CASE, **change))


def test_case_values_are_checked():
    with pytest.raises(ValueError, match="area_mva"):
        KundurCase(area_mva=0.0)
    with pytest.raises(ValueError, match="same number"):
        KundurCase(meter_buses=(6,))


def test_stop_on_trip_ends_at_the_first_trip_of_the_full_run(fit):
    attacks = {a: {"ace": lfc.Step(-2.5, 1.0)} for a in range(2)}
    full = simulate_kundur(fit.params, duration=30.0, attacks=attacks)
    first = min(float(r.trips.t.min()) for r in full.areas if len(r.trips))
    stopped = simulate_kundur(fit.params, duration=30.0, attacks=attacks, stop_on_trip=True)
    assert stopped.tripped and float(stopped.trace.t.iat[-1]) == pytest.approx(first)
    for a, r in enumerate(stopped.areas):
        expected = full.areas[a].trips[full.areas[a].trips.t <= first + 1e-9]
        assert r.trips.to_dict("list") == expected.reset_index(drop=True).to_dict("list")
