"""Redundant sensors as a scenario's field (issue "Sensors", items 1 and 3): the
sensors of :class:`lfc.sensors.Redundant` run wherever a scenario runs — ``simulate``,
``simulate_many`` (in SIMD lanes or one at a time), a grid, the Kalman estimate, the red
team (a fixed liar, or the liar's lie searched) and the wire — and the alarm log names
each reading found a lie.  The proven statement itself is tested at its worst cases in
``tests/test_secure_sensors.py``; here: that every path runs the same scenario, and the
secure filter on a grid against the red team."""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd
import pytest

import lfc
from lfc.experiments.redteam import SPOOF_FAMILIES, coordinated_search
from lfc.sensors import Redundant, SensorArray

P, RELAYS = lfc.LFCParams(), lfc.RelaySettings()
WIDE = SensorArray(bound=(0.003, 0.02))     # pu, pu/s: coarse meters, where it shows
GRID = lfc.MultiAreaParams.two_area()
SQUARE = lfc.Square(1.0, 0.3, start=1.0)    # pu, Hz: the command attack of every area


def far(sensor: int) -> dict:
    """A liar on ``sensor``: 1 pu on the frequency, -1 pu/s on ROCOF, from 1 s."""
    return {sensor: {"dw_meas": lfc.Step(1.0, start=1.0),
                     "rocof_meas": lfc.Step(-1.0, start=1.0)}}


def certified(params: lfc.LFCParams, secure: bool) -> lfc.SafetyFilter:
    """The certified filter, built for the median's error (``secure``) or not."""
    return lfc.SafetyFilter(params, RELAYS, method="certified",
                            sensor_bound=WIDE.bound if secure else None)


def named(result: lfc.Result) -> pd.Series:
    """The reasons of the alarm log's rows naming a lie or a sample beyond the statement."""
    reason = result.alarms.reason.astype(str)
    return reason[reason.str.startswith(("spoofed", "beyond"))]


def test_simulate_many_in_lanes_or_not_gives_simulates_metrics():
    """Twelve scenarios (a liar on each sensor, lying far or not at all, with the secure
    filter, the naive one or none, each its own seed): ``simulate_many``'s rows equal
    ``simulate``'s metrics — the ``alarms`` count holds the named lies — in SIMD lanes
    and one at a time alike, bit for bit."""
    rows = [lfc.Scenario.for_area(sensors=Redundant(WIDE, far(k % 3) if k % 4 else {}),
                                  scc=[None, certified(P, True), certified(P, False)][k % 3],
                                  pc_attack=lfc.Step(2.0, start=1.0), seed=k)
            for k in range(12)]
    lanes = lfc.simulate_many(P, rows, duration=3.0)
    alone = lfc.simulate_many(P, rows, duration=3.0, lanes=False)
    pd.testing.assert_frame_equal(lanes, alone, check_exact=True)
    results = lfc.simulate_many(P, rows, duration=3.0, keep="results")
    one = pd.concat([r.table() for r in results], ignore_index=True)
    cols = [c for c in one.columns if c != "mean_abs_modification"]
    pd.testing.assert_frame_equal(lanes[cols], one[cols], check_dtype=False)
    np.testing.assert_allclose(lanes.mean_abs_modification, one.mean_abs_modification,
                               rtol=1e-12)
    counts = [len(named(r)) for r in results]
    assert all(c == 2 * 200 for c, k in zip(counts, range(12)) if k % 4)
    assert all(c == 0 for c, k in zip(counts, range(12)) if not k % 4)


def test_on_a_grid_the_secure_filters_trip_nothing_and_the_log_names_the_liar_by_area():
    """Two areas, each under a 1 pu square command attack, area 1's sensor 2 lying (a
    0.5 pu bias on the frequency, a 1 pu/s square on ROCOF): the certified filters
    built for the median's error trip nothing; built without it, area 1's ROCOF relay
    trips (measured: at 3.145 s).  The log names sensor 2 in area 1 only, on both
    channels, at every sample from 1 s."""
    lie = {2: {"dw_meas": lfc.Step(0.5, start=1.0), "rocof_meas": lfc.Square(1.0, 1.0,
                                                                              start=1.0)}}
    kw = dict(duration=10.0, sensors={1: Redundant(WIDE, lie)},
              attacks={a: {"pc": SQUARE} for a in range(2)})
    secure = lfc.simulate(GRID, filters={a: certified(GRID.areas[a], True) for a in range(2)},
                          **kw)
    naive = lfc.simulate(GRID, filters={a: certified(GRID.areas[a], False) for a in range(2)},
                         **kw)
    assert not secure.tripped
    assert naive.first_trip == {"relay": "ROCOF", "t": pytest.approx(3.145), "area": 1}
    log = secure.alarms.assign(reason=secure.alarms.reason.astype(str))
    lies = log[log.reason.str.startswith("spoofed")]
    assert set(lies.area) == {1} and len(lies) == 2 * 900
    assert set(lies.reason) == {"spoofed: sensor 2 (dw_meas)", "spoofed: sensor 2 (rocof_meas)"}
    assert len(named(secure.areas[0])) == 0


ATTACKS = {"square 1 pu 0.3 Hz": SQUARE, "sinusoid 0.5 pu 1 Hz": lfc.Sinusoid(0.5, 1.0, start=1.0),
           "square 3 pu 0.5 Hz": lfc.Square(3.0, 0.5, start=1.0),
           "step 2 pu": lfc.Step(2.0, start=1.0)}
N = 1000                                     # control samples of a 10 s run


def corner(pattern: str) -> dict:
    """Every honest sensor's noise at a corner of its bound: +bound, -bound, or flipping
    sign every sample."""
    sign = {"high": np.ones(N), "low": -np.ones(N),
            "flipping": np.where(np.arange(N) % 2 == 0, -1.0, 1.0)}[pattern]
    tc = np.arange(N) * 0.01
    return {k: {c: lfc.Samples(tc, sign * b) for c, b in zip(("dw_meas", "rocof_meas"),
                                                              WIDE.bound)}
            for k in range(WIDE.count)}


@pytest.mark.parametrize("grid", [GRID, pytest.param(lfc.MultiAreaParams.three_area(),
                                                     marks=pytest.mark.exhaustive)],
                         ids=["two_area", "three_area"])
def test_on_grids_the_secure_filters_trip_nothing_at_the_worst_cases(grid):
    """The statement in each area of a grid at its worst cases: every command attack of
    ``tests/test_secure_sensors.py`` in every area at once, a liar far off on each sensor
    of each area in turn, the honest noise at its corners in every area (72 runs on two
    areas, 108 on three): no trip through the certified filters built for the median's
    error — and they are not idle: ``outside`` at about a third of the samples, the
    frequency up to 0.017 pu (measured); through the same filters built without it,
    two runs in three trip (measured: 48 of 72, 72 of 108)."""
    n = grid.n_areas
    cases = list(itertools.product(ATTACKS, range(n), range(3), ("high", "low", "flipping")))
    trips = {}
    for secure in (True, False):
        filters = {a: certified(grid.areas[a], secure) for a in range(n)}
        rows = [{"sensors": {a: Redundant(WIDE, far(sensor) if a == liar else {},
                                          corner(pattern)) for a in range(n)},
                 "attacks": {a: {"pc": ATTACKS[attack]} for a in range(n)},
                 "filters": filters}
                for attack, liar, sensor, pattern in cases]
        table = lfc.simulate_many(grid, rows, duration=10.0)
        trips[secure] = table.groupby("scenario").tripped.any()
        if secure:
            assert 0.2 < table.outside.sum() / (len(table) * N) < 0.5
            assert table.max_abs_dw_meas.max() > 0.01
    assert not trips[True].any(), [cases[i] for i in np.flatnonzero(trips[True])]
    assert trips[False].sum() == 2 * len(cases) // 3


def test_the_kalman_estimate_reads_the_median():
    """With ``estimator="kalman"`` each area's Kalman filter reads its median: a liar
    far off changes nothing it sees (the median is within the honest noise, drawn the
    same), so the run equals the run with that sensor honest, but for the named lies."""
    kw = dict(duration=5.0, filters={a: "certified" for a in range(2)}, estimator="kalman",
              loads={0: lfc.Step(0.02, start=1.0)})
    honest = lfc.simulate(GRID, sensors={0: Redundant(WIDE)}, **kw)
    lying = lfc.simulate(GRID, sensors={0: Redundant(WIDE, far(0))}, **kw)
    same = honest.areas[0].trace.dw_meas
    assert not np.array_equal(lying.areas[0].trace.dw_meas, same)     # the median moved
    assert np.max(np.abs(lying.areas[0].trace.dw_meas - same)) < 1e-3
    assert len(named(lying)) == 2 * 400 and len(named(honest)) == 0


@pytest.mark.parametrize("family", list(SPOOF_FAMILIES))
def test_the_red_team_finds_no_lie_of_one_sensor_that_trips_the_secure_filters(family):
    """The red team searches the lie of sensor 0 in each area of the two-area preset
    (a bias or a sinusoid on a channel, every area at once) under the 1 pu square
    command attack in each: against the certified filters built for the median's error
    it finds no trip (the proof's statement: one liar of three, any lie); against the
    same filters built without it, a trip (measured: the honest noise alone is enough:
    they take the median for the truth)."""
    fixed = {"sensors": {a: Redundant(WIDE) for a in range(2)},
             "attacks": {a: {"pc": SQUARE} for a in range(2)}}
    found = {secure: coordinated_search(
        GRID, {a: certified(GRID.areas[a], secure) for a in range(2)}, family, duration=10.0,
        maxiter=3, popsize=4, scenario=fixed) for secure in (True, False)}
    assert not found[True]["tripped"] and found[True]["outside"] > 0
    assert found[False]["tripped"]


def test_a_spoofed_family_without_sensors_is_refused():
    with pytest.raises(ValueError, match="sensors"):
        coordinated_search(GRID, {}, next(iter(SPOOF_FAMILIES)), duration=2.0, maxiter=1,
                           popsize=1)


@pytest.mark.parametrize("protocol", ["modbus", "dnp3"])
def test_over_the_wire_the_sensors_run_as_simulate_runs_them(protocol):
    """Lockstep over the wire with redundant sensors at the generator (a liar far off,
    the secure filter, Fig. 4's attack injected in the frames): the trace equals
    ``lfc.simulate``'s to 1e-12 pu, the same alarm log, lies named."""
    from lfc.wire import run_wire
    from lfc.wire.attacks import from_simulate
    red = Redundant(WIDE, far(1))
    attack = lfc.Sinusoid(0.5, 1.0, start=1.0)
    wire = run_wire(P, duration=3.0, attack=from_simulate(pc_attack=attack),
                    scc=certified(P, True), sensors=red, protocol=protocol)
    sim = lfc.simulate(P, duration=3.0, pc_attack=attack, scc=certified(P, True), sensors=red)
    cols = ["dPg", "dPm", "dw", "dw_meas", "rocof_meas", "pc_ref", "pc"]
    diff = np.abs(wire.sim.trace[cols].to_numpy() - sim.trace[cols].to_numpy())
    assert diff.max() < 1e-12        # the lockstep plant rounds its own way (~1e-14)
    pd.testing.assert_frame_equal(wire.sim.alarms, sim.alarms, rtol=1e-9)
    assert len(named(wire.sim)) == 2 * 200


def test_what_cannot_hold_redundant_sensors_says_so():
    """A scenario table's row, the ANDES microgrid and the wire on ANDES refuse them by
    name; so does a grid's scenario naming an area the grid lacks."""
    row = lfc.Scenario.for_area(sensors=Redundant(WIDE))
    from lfc.tables import scenario_row
    with pytest.raises(ValueError, match="redundant sensors"):
        scenario_row(row, P)
    with pytest.raises(ValueError, match="sensors"):
        lfc.simulate(GRID, duration=1.0, sensors={2: Redundant(WIDE)})
    with pytest.raises(ValueError, match="sensors"):
        lfc.Scenario(sensors={0: WIDE})
    testbed = pytest.importorskip("lfc.testbed")
    with pytest.raises(ValueError, match="sensors"):
        lfc.simulate(testbed.MicrogridCase(), duration=1.0, sensors=Redundant(WIDE))
    from lfc.wire import run_wire
    with pytest.raises(ValueError, match="sensors"):
        run_wire(testbed.GridCase.kundur(), duration=1.0, sensors={0: Redundant(WIDE)})


def test_the_single_area_red_team_takes_redundant_sensors_as_a_fixed_part():
    """``family_search(..., scenario={"sensors": Redundant(...)})``: every run of the
    search reads three coarse sensors, one lying; against the certified filter built
    without ``sensor_bound`` (a ``Defender`` has no such column) the search finds a
    trip, as on grids."""
    from lfc.experiments.redteam import Defender, family_search
    found = family_search(P, Defender("certified", method="certified"), "sinusoid on P_c",
                          maxiter=2, popsize=3,
                          scenario={"sensors": Redundant(WIDE, far(0))})
    assert found["tripped"] and found["outside"] > 0


def test_the_single_area_red_team_finds_no_trip_through_the_filter_built_for_the_median():
    """The single-area red team's every command family (``FAMILIES``, 3 generations × 4)
    while sensor 0 of three lies far off (1 pu, -1 pu/s from 1 s), coarse meters: against
    ``Defender(method="certified", sensor_bound=...)`` no family trips (the proof's
    statement); against the same filter without it, the sinusoid, square and chirp
    families on the command and the square on the reference trip (measured: 4 of 6)."""
    from lfc.experiments.redteam import FAMILIES, Defender, family_search
    fixed = {"sensors": Redundant(WIDE, far(0))}
    for name, bound in (("secure", WIDE.bound), ("naive", None)):
        defender = Defender(name, method="certified", sensor_bound=bound)
        tripped = [family_search(P, defender, family, maxiter=3, popsize=4,
                                 scenario=fixed)["tripped"] for family in FAMILIES]
        assert sum(tripped) == (0 if bound else 4), (name, tripped)


def test_a_table_row_holds_the_filter_built_for_the_median():
    """The certified filter's ``sensor_bound`` is a scenario table's ``sensor_bound_w``,
    ``sensor_bound_rocof`` columns: a row written from a scenario reads back to the same
    filter (its metrics equal), and a row with one of the two is refused naming it."""
    from lfc.tables import scenario_row
    secure = lfc.SafetyFilter(P, RELAYS, method="certified", sensor_bound=WIDE.bound)
    row = scenario_row(lfc.Scenario.for_area(scc=secure, pc_attack=SQUARE), P)
    assert (row["sensor_bound_w"], row["sensor_bound_rocof"]) == WIDE.bound
    table = pd.DataFrame([row])
    got = lfc.simulate_many(P, table, duration=3.0)
    one = lfc.simulate(P, duration=3.0, scc=secure, pc_attack=SQUARE).metrics()
    assert got.alarms.iat[0] == one["alarms"] and got.outside.iat[0] == one["outside"]
    with pytest.raises(ValueError, match="sensor_bound"):
        lfc.simulate_many(P, table.assign(sensor_bound_rocof=np.nan), duration=1.0)


def test_the_coupled_filters_read_the_median_through_their_grid_estimate_only():
    """The coupled certificate reads the sensors through its grid Kalman filter
    (``estimator="kalman"``): on meters as fine as the chapters' noise (1e-4 pu,
    1e-3 pu/s), every area's sensor 0 lying far off and a 1 pu square on every command,
    it trips nothing and flags nothing (measured, not proven: its statement is the
    Gaussian noise's).  On the exact grid state it reads the plant, not the sensors, so
    redundant sensors are refused there, as any attack on the sensors is."""
    fine = SensorArray(bound=(1e-4, 1e-3))
    kw = dict(duration=10.0, filters={0: "coupled", 1: "coupled"},
              sensors={a: Redundant(fine, far(0)) for a in range(2)},
              attacks={a: {"pc": SQUARE} for a in range(2)})
    r = lfc.simulate(GRID, estimator="kalman", **kw)
    assert not r.tripped and r.table().outside.sum() == 0
    assert len(named(r)) == 2 * 2 * 900
    with pytest.raises(ValueError, match="coupled filter"):
        lfc.simulate(GRID, **kw)
