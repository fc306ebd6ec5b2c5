"""The threats beyond the command channel on ANDES (issue "Sensors", items 1 and 5): a load
that follows the frequency (``following_loads``) and attacks on what the sensors report,
on the Kundur grid; the eigenvalue prediction of the destabilizing gain, made on the
fitted design model, against the ANDES runs."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import lfc
from lfc.load_attacks import FollowingLoad, closed_loop, critical_gain
from lfc.sensor_attacks import Freeze, Scale

pytestmark = pytest.mark.andes_recorded

testbed = pytest.importorskip("lfc.testbed")
CASE = testbed.GridCase.kundur()
KICK = 0.01                # pu: a load step at 1 s, to start the loop moving
PERIOD = 1.6               # s: the window a peak is taken in (the mode's period, 1.6 s)


@pytest.fixture(scope="module")
def design():
    from lfc.testbed.fit import grid_design
    return grid_design(CASE)


def growth(trace: pd.DataFrame, start: float = 4.0, window: float = PERIOD) -> float:
    """The growth rate (1/s) of the frequency meter's swing from ``start`` (s): the
    slope of the log of its peak in each ``window`` (s)."""
    t, y = trace.t.to_numpy(), trace.dw_meas.abs().to_numpy()
    edges = np.arange(start, t[-1] - window, window)
    peaks = [(t[m][np.argmax(y[m])], y[m].max())
             for m in ((t >= a) & (t < a + window) for a in edges)]
    times, values = np.array(peaks).T
    return float(np.polyfit(times, np.log(values), 1)[0])


def laa_run(design, area: int, factor: float, case=CASE, window: float = PERIOD
            ) -> tuple[float, float]:
    """(eigenvalue's growth rate, ANDES' growth rate) (1/s) of a following load of
    ``factor`` times the design model's critical gain in ``area`` of ``case``, 30 s."""
    gain = factor * critical_gain(design, area)
    predicted = float(np.linalg.eigvals(closed_loop(design, {area: gain})).real.max())
    r = lfc.simulate(case, duration=30.0, loads={area: lfc.Step(KICK, start=1.0)},
                     following_loads={area: FollowingLoad(gain, limit=0.5, start=1.0)})
    return predicted, growth(r.areas[area].trace, window=window)


@pytest.mark.long(60)
def test_finding_on_kundur_the_fitted_models_destabilizing_gain_is_conservative(design):
    """Finding, measured on ANDES (growth rate of the 0.62 Hz mode from 4 s to 30 s):
    at the gain the fitted design model's eigenvalues call critical — and at twice it —
    the ANDES run decays in both areas; area 0's grows at 2.5 times it, area 1's still
    decays there.  The fitted model under-damps the mode (at the critical gain ANDES
    decays at 0.12 and 0.16 1/s), so its prediction errs on the safe side: a gain it
    calls safe is safe on ANDES.  The eigenvalues' growth rate rises with the gain as
    ANDES' does in area 0 (within 10 % between 1 and 2.5 times); in area 1 ANDES' rises
    about 30 % slower."""
    rates = {(a, f): laa_run(design, a, f) for a in (0, 1) for f in (1.0, 2.0, 2.5)}
    for a in (0, 1):
        assert rates[a, 1.0][0] == pytest.approx(0.0, abs=1e-6)     # the prediction: critical
        assert rates[a, 1.0][1] < -0.1 and rates[a, 2.0][1] < 0.0   # ANDES: decays
        assert rates[a, 2.5][0] > 0.15                              # predicted: grows fast
    assert rates[0, 2.5][1] > 0.02 and rates[1, 2.5][1] < 0.0
    slope = [(rates[a, 2.5][1] - rates[a, 1.0][1]) / (rates[a, 2.5][0] - rates[a, 1.0][0])
             for a in (0, 1)]
    assert slope[0] == pytest.approx(1.0, rel=0.1)
    assert 0.6 < slope[1] < 0.8


@pytest.mark.long(60)
def test_finding_on_ieee39_the_fitted_models_destabilizing_gain_is_conservative():
    """Finding, measured on ANDES (the peak of each 5 s from 4 s to 30 s): on the IEEE
    39-bus grid the ANDES run decays at the fitted model's critical gain and at twice
    it, in both areas, where the model predicts growth at twice it (area 0 by a real
    eigenvalue, 0.75 1/s; area 1 by its 2.1 rad/s mode, 0.15 1/s): conservative, as on
    Kundur.  Area 0's grows at 2.5 times it; area 1's still decays there."""
    from lfc.testbed.fit import grid_design
    case = testbed.GridCase.ieee39()
    model = grid_design(case)
    rates = {(a, f): laa_run(model, a, f, case, window=5.0)
             for a in (0, 1) for f in (1.0, 2.0, 2.5)}
    for a in (0, 1):
        assert rates[a, 1.0][0] == pytest.approx(0.0, abs=1e-6) and rates[a, 2.0][0] > 0.1
        assert rates[a, 1.0][1] < 0.0 and rates[a, 2.0][1] < 0.0
    assert rates[0, 2.5][1] > 0.1 and rates[1, 2.5][1] < 0.0     # area 0 grows at 2.5 times


def test_on_andes_a_sensor_attack_reaches_what_reads_the_sensor():
    """A reading transform on ANDES (``lfc.sensor_attacks``): a scale of 1 changes
    nothing, bit for bit; a frozen frequency sensor holds what the generator side
    reads from its start; the relays read ANDES and see the frequency move."""
    kw = dict(duration=6.0, loads={0: lfc.Step(0.05, start=1.0)})
    base = lfc.simulate(CASE, **kw)
    same = lfc.simulate(CASE, **kw, attacks={0: {"dw_meas": Scale(1.0, start=2.0)}})
    frozen = lfc.simulate(CASE, **kw, attacks={0: {"dw_meas": Freeze(start=2.0)}})
    pd.testing.assert_frame_equal(base.table(), same.table(), check_exact=True)
    seen = frozen.areas[0].controls.set_index("t").dw_hat
    held = seen.loc[2.0 - 1e-9:]
    assert (held == seen.loc[1.99 - 1e-9:1.99 + 1e-9].iloc[0]).all()
    assert frozen.areas[0].trace.dw_meas.iloc[-1] != base.areas[0].trace.dw_meas.iloc[-1]


def test_on_andes_the_coupled_filters_estimate_reads_the_report():
    """The coupled filter's grid Kalman estimate reads each area's sensors as they
    report (``GeneratorSide.reports``): a frozen sensor changes its estimate."""
    noise = (1e-4, 1e-3)
    kw = dict(duration=4.0, loads={0: lfc.Step(0.02, start=1.0)},
              filters={0: "coupled", 1: "coupled"}, estimator="kalman", noise_std=noise)
    base = lfc.simulate(CASE, **kw)
    same = lfc.simulate(CASE, **kw, attacks={1: {"rocof_meas": Scale(1.0, start=1.5)}})
    frozen = lfc.simulate(CASE, **kw, attacks={1: {"rocof_meas": Freeze(start=1.5)}})
    pd.testing.assert_frame_equal(base.table(), same.table(), check_exact=True)
    hat = [r.areas[0].controls.set_index("t").dw_hat.loc[2.0:] for r in (base, frozen)]
    assert not np.allclose(hat[0], hat[1])


def test_on_andes_simulate_many_runs_both_threats_as_simulate_does():
    """A following load and a frozen sensor as :class:`lfc.Scenario` rows of
    ``simulate_many`` on a grid case: the metrics of ``simulate`` of each."""
    rows = [lfc.Scenario(loads={0: lfc.Step(KICK, start=1.0)},
                         following_loads={0: FollowingLoad(10.0, limit=0.5, start=1.0)}),
            lfc.Scenario(loads={0: lfc.Step(KICK, start=1.0)},
                         attacks={0: {"dw_meas": Freeze(start=2.0)}})]
    many = lfc.simulate_many(CASE, rows, duration=5.0)
    for i, row in enumerate(rows):
        one = lfc.simulate(CASE, duration=5.0, **row.keywords("grid")).table()
        got = many[many.scenario == i].drop(columns="scenario").reset_index(drop=True)
        pd.testing.assert_frame_equal(got[one.columns], one, check_exact=True, check_dtype=False)


def test_on_andes_redundant_sensors_run_as_their_median():
    """Redundant sensors on a grid case (``sensors={area: Redundant}``): the AGC of area
    0 reads the median of three sensors, one lying 0.5 pu off from 1 s; the run equals
    the one given the median's error as the area's sensor attack, bit for bit, and its
    log names the liar at every sample from 1 s; ``simulate_many`` of the scenario gives
    ``simulate``'s metrics."""
    from lfc.sensors import Redundant, SensorArray
    red = Redundant(SensorArray(bound=(1e-4, 1e-3)), {1: {"dw_meas": lfc.Step(0.5, start=1.0)}})
    kw = dict(duration=4.0, loads={0: lfc.Step(KICK, start=1.0)})
    sensed = lfc.simulate(CASE, sensors={0: red}, **kw)
    told = red.attacks(red.fused(np.arange(400) * 0.01, 0))
    plain = lfc.simulate(CASE, attacks={0: told}, **kw)
    pd.testing.assert_frame_equal(sensed.trace, plain.trace, check_exact=True)
    lies = sensed.alarms[sensed.alarms.reason.astype(str).str.startswith("spoofed")]
    assert set(lies.area) == {0} and len(lies) == 300 and lies.t.min() == pytest.approx(1.0)
    many = lfc.simulate_many(CASE, [lfc.Scenario(sensors={0: red}, **{"loads": kw["loads"]})],
                             duration=4.0)
    one = sensed.table()
    pd.testing.assert_frame_equal(many.drop(columns="scenario")[one.columns], one,
                                  check_exact=True, check_dtype=False)


#: the ANDES runs' smallest destabilizing gain, bracketed by a bisection on the growth rate
#: of the following load's area (4 halvings from the first factor that grows), as factors
#: of the fitted design model's critical gain: (grid, area) -> (decays at, grows at)
ANDES_CRITICAL = {("kundur", 0): (2.09375, 2.125), ("kundur", 1): (3.28125, 3.359375),
                  ("ieee39", 0): (2.125, 2.15625), ("ieee39", 1): (12.12890625, 12.392578125)}


@pytest.mark.long(120)
@pytest.mark.parametrize("grid", ["kundur", "ieee39"])
def test_finding_the_andes_critical_gain_is_2_to_12_times_the_fitted_models(grid):
    """Finding, measured on ANDES (growth rate of the area's frequency meter from 4 s to
    30 s, a following load of limit 0.5 pu after a 0.01 pu kick): the smallest gain at
    which ANDES grows, bracketed by a bisection to 1.5 %, is 2.09-2.13 times the fitted
    model's critical gain in Kundur's area 0 (14.3-14.5 pu/pu), 3.28-3.36 times in area 1
    (18.1-18.5), 2.13-2.16 times in IEEE 39's area 0 (61.5-62.4) and 12.1-12.4 times in
    its area 1 (50.5-51.6): the model's prediction errs on the safe side everywhere, by a
    factor of 2 to 12.  Each bracket is tested at both ends (decays, then grows)."""
    case = getattr(testbed.GridCase, grid)()
    from lfc.testbed.fit import grid_design
    model = grid_design(case)
    window = PERIOD if grid == "kundur" else 5.0
    for area in (0, 1):
        decays, grows = ANDES_CRITICAL[grid, area]
        low = laa_run(model, area, decays, case, window=window)[1]
        high = laa_run(model, area, grows, case, window=window)[1]
        assert low < 0.0 < high, (area, low, high)
