"""Attacks on what a sensor reports that depend on what it reads (issue "Sensors", item 1):
scale, freeze and replay (``lfc.sensor_attacks``), wherever the generator side reads the
sensor — one area, a table in lanes or one at a time, a grid's coupled filter, a row of a
scenario table, the wire.  What each does to the filters is measured and pinned."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lfc
import tiers
from lfc.filters import build
from lfc.linear_grid import area_filter
from lfc.multiarea import MultiAreaParams
from lfc.sensor_attacks import Freeze, Replay, Scale
from lfc.tables import scenario_row, table_scenarios
from lfc.wire.attacks import WireAttack

P, RELAYS = lfc.LFCParams(), lfc.RelaySettings()
LOAD = lfc.Step(0.05, start=0.5)          # pu: something for the sensors to read
KW = dict(duration=6.0, load=LOAD)


def reports(result: lfc.Result) -> pd.Series:
    """What the filter read of the frequency at every control sample (pu; exact state)."""
    return result.controls.set_index("t").dw_hat


@settings(max_examples=tiers.examples(10), deadline=None)
@given(start=st.floats(0.0, 5.0), channel=st.sampled_from(["dw_meas", "rocof_meas"]))
def test_a_scale_of_one_changes_nothing_bit_for_bit(start, channel):
    plain = lfc.simulate(P, **KW)
    scaled = lfc.simulate(P, **KW, **{f"{channel}_attack": Scale(1.0, start=start)})
    pd.testing.assert_frame_equal(plain.trace, scaled.trace, check_exact=True)
    pd.testing.assert_frame_equal(plain.controls, scaled.controls, check_exact=True)


def test_a_scale_reports_factor_times_the_reading_in_its_window_only():
    plain = reports(lfc.simulate(P, **KW))
    seen = reports(lfc.simulate(P, **KW, dw_meas_attack=Scale(-2.0, start=2.0, stop=3.0)))
    inside = (seen.index >= 2.0 - 1e-9) & (seen.index < 3.0 - 1e-9)
    before = seen.index < 2.0 - 1e-9
    np.testing.assert_array_equal(seen[before], plain[before])
    # inside, the report is -2 times what the sensor reads of the (changed) state
    assert np.all(np.sign(seen[inside]) == -np.sign(plain[inside]))


def test_a_freeze_holds_the_last_report_and_lets_go_at_its_stop():
    plain = reports(lfc.simulate(P, **KW))
    seen = reports(lfc.simulate(P, **KW, dw_meas_attack=Freeze(start=2.0, stop=4.0)))
    held = seen.loc[2.0 - 1e-9:4.0 - 1e-6]
    assert len(held) == 200 and (held == seen.loc[1.99 - 1e-9:1.99 + 1e-9].iloc[0]).all()
    assert seen.iloc[-1] != held.iloc[0]           # it reads the plant again after
    np.testing.assert_array_equal(seen.loc[:1.99 + 1e-9], plain.loc[:1.99 + 1e-9])


def test_a_replay_plays_the_recording_back_in_a_loop():
    seen = reports(lfc.simulate(P, **KW, dw_meas_attack=Replay(0.5, start=2.0)))
    recorded = seen.loc[1.5 - 1e-9:2.0 - 1e-6].to_numpy()
    assert len(recorded) == 50 and np.ptp(recorded) > 0
    for k in range(1, 7):       # each half second from 2 s plays it again
        t0 = 1.5 + 0.5 * k
        np.testing.assert_array_equal(seen.loc[t0 - 1e-9:t0 + 0.5 - 1e-6].to_numpy(), recorded)


def test_the_agc_and_the_kalman_filter_read_the_report_too():
    noisy = dict(KW, noise_std=(1e-4, 1e-3), estimator="kalman", seed=1)
    base = lfc.simulate(P, **noisy).controls.set_index("t")
    frozen = lfc.simulate(P, **noisy, dw_meas_attack=Freeze(start=1.0)).controls.set_index("t")
    # the AGC integrates a frozen frequency error: its command ramps at a constant rate
    ramp = np.diff(frozen.pc_ref.loc[1.0 + 1e-9:].to_numpy())
    np.testing.assert_allclose(ramp, ramp[0], rtol=1e-9)
    assert np.ptp(np.diff(base.pc_ref.loc[1.0 + 1e-9:].to_numpy())) > 1e-3 * abs(ramp[0])
    # the Kalman filter, fed the frozen reading, loses the frequency the plant has
    assert np.abs(frozen.dw_hat - base.dw_hat).loc[3.0:].min() > 1e-4


def test_in_lanes_and_one_at_a_time_the_same_bit_for_bit():
    rows = [dict(waveform=w, channel=c, amplitude=a, freq_hz=0.0, start=s, alpha=al, Ts=0.01)
            for w, a in (("scale", -1.0), ("scale", 2.5), ("freeze", 0.0), ("replay", 0.3))
            for c in ("dw_meas", "rocof_meas") for s in (0.6, 1.0) for al in (math.nan, 5.0)]
    table = pd.DataFrame(rows * 2)
    table["noise_w"] = np.repeat([0.0, 2e-4], len(rows))
    table["noise_rocof"] = np.repeat([0.0, 1e-3], len(rows))
    kw = dict(duration=4.0, progress=False, executor=None, chunk_size=len(table) + 1)
    lanes = lfc.simulate_many(P, table, lanes=True, **kw)
    scalar = lfc.simulate_many(P, table, lanes=False, **kw)
    pd.testing.assert_frame_equal(lanes, scalar, check_exact=True)
    assert lanes["max_abs_dw_meas"].nunique() > 8      # they are not all one run


def test_a_table_row_holds_each_and_reads_it_back():
    for attack in (Scale(0.5, start=1.0, stop=3.0), Freeze(start=2.0), Replay(0.4, start=1.0)):
        scenario = lfc.Scenario(attacks={0: {"rocof_meas": attack}})
        row = scenario_row(scenario, P)
        back = table_scenarios(pd.DataFrame([{**row, "alpha": math.nan, "Ts": 0.01}]), P,
                               duration=4.0)[0]
        assert back.keywords("area")["rocof_meas_attack"] == attack


def test_a_grid_coupled_filter_estimates_from_the_report():
    grid = MultiAreaParams.two_area()
    coupled = build("coupled", grid, relays=RELAYS, noise_std=(1e-4, 1e-3))
    kw = dict(duration=5.0, loads={0: lfc.Step(0.05, start=0.5)},
              filters={0: coupled, 1: coupled}, noise_std=(1e-4, 1e-3), seed=2,
              estimator="kalman")
    base = lfc.simulate(grid, **kw)
    same = lfc.simulate(grid, **kw, attacks={1: {"dw_meas": Scale(1.0, start=1.0)}})
    frozen = lfc.simulate(grid, **kw, attacks={1: {"dw_meas": Freeze(start=1.0)}})
    pd.testing.assert_frame_equal(base.table(), same.table(), check_exact=True)
    assert not base.table().equals(frozen.table())


@pytest.mark.parametrize("make, message", [
    (lambda: Scale(math.nan), "factor"),
    (lambda: Scale(1.0, start=-1.0), "start"),
    (lambda: Freeze(start=2.0, stop=1.0), "stop"),
    (lambda: Replay(0.0, start=1.0), "lag"),
    (lambda: Replay(2.0, start=1.0), "lag"),
    (lambda: lfc.simulate(P, duration=1.0, pc_attack=Scale(2.0)), "pc_attack"),
    (lambda: lfc.simulate(P, duration=1.0, load=Freeze()), "load"),
])
def test_bad_input_is_refused_by_name(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_a_transform_is_not_a_function_of_time():
    with pytest.raises(TypeError, match="not a function of time"):
        Freeze(start=1.0)(2.0)


def test_a_table_row_puts_them_on_a_sensor_only():
    row = dict(waveform="freeze", channel="pc", amplitude=0.0, freq_hz=0.0, start=1.0,
               alpha=math.nan, Ts=0.01)
    with pytest.raises(ValueError, match="reads a sensor"):
        lfc.simulate_many(P, pd.DataFrame([row]), duration=2.0, progress=False)
    with pytest.raises(ValueError, match="lag"):
        lfc.simulate_many(P, pd.DataFrame([dict(row, channel="dw_meas", waveform="replay",
                                                amplitude=3.0)]), duration=2.0, progress=False)


def test_on_the_wire_a_report_is_frozen_delayed_or_replayed():
    period = 0.1
    attack = WireAttack([{"op": "freeze", "field": "dw_meas", "start": 0.5, "stop": 1.0},
                         {"op": "delay", "field": "rocof_meas", "periods": 2},
                         {"op": "replay", "field": "u", "record": 0.1, "start": 0.6}])
    told = [attack.report(j, j * period, period,
                          {"dw_meas": float(j), "rocof_meas": 10.0 * j, "pc_received": 0.0,
                           "u_ref": 0.0, "u": 100.0 * j}) for j in range(12)]
    assert [r["dw_meas"] for r in told] == [0, 1, 2, 3, 4, 4, 4, 4, 4, 4, 10, 11]
    assert [r["rocof_meas"] for r in told] == [0, 0, 0, 10, 20, 30, 40, 50, 60, 70, 80, 90]
    assert [r["u"] for r in told][6:] == [100, 200, 300, 400, 500, 600]


# -- what they do to the filters, measured -------------------------------------------------
#: the command attacks of tests/test_secure_sensors.py (pu on P_c, from 1 s)
ATTACKS = {"sinusoid 0.5 pu 1 Hz": lfc.Sinusoid(0.5, 1.0, start=1.0),
           "square 1 pu 0.3 Hz": lfc.Square(1.0, 0.3, start=1.0),
           "square 3 pu 0.5 Hz": lfc.Square(3.0, 0.5, start=1.0),
           "step 2 pu": lfc.Step(2.0, start=1.0)}
#: the sensor blinded from 0.9 s, just before the attack
BLINDING = {"frozen": Freeze(start=0.9), "scaled by 0": Scale(0.0, start=0.9),
            "replaying 0.5 s": Replay(0.5, start=0.9), "scaled by -1": Scale(-1.0, start=0.9)}


def outcomes(kind: str) -> dict:
    """(attack, blinding, sensor) -> (first relay to trip or "-", outside flagged)."""
    scc = build(kind, P, relays=RELAYS)
    out = {}
    for (a, attack), (b, blind), sensor in itertools.product(
            ATTACKS.items(), BLINDING.items(), ("dw_meas", "rocof_meas")):
        m = lfc.simulate(P, duration=8.0, pc_attack=attack, scc=scc,
                         load_feedforward=kind == "certified",
                         **{f"{sensor}_attack": blind}).metrics()
        out[a, b, sensor] = (m["first_trip_relay"] if m["tripped"] else "-", m["outside"] > 0)
    return out


def test_the_certified_filter_blinded_on_rocof_passes_the_square_attacks():
    """Finding: the certified filter trusts what its ROCOF sensor reports.  Blinded
    from 0.9 s (frozen, scaled to 0, replaying a quiet recording), it passes the
    square attacks, which trip ROCOF, without flagging ``outside`` (what it reads is
    inside the safe set); a sign-flipped ROCOF trips too, flagged.  Blinding the
    frequency sensor alone, and the other two attacks, trip nothing; unblinded, none
    of the four attacks trips.
    The defence is redundancy (``lfc.sensors``: a blinded sensor of three is a
    liar like any other, and the median covers any lie)."""
    got = outcomes("certified")
    scc = build("certified", P, relays=RELAYS)
    for attack in ATTACKS.values():
        assert not lfc.simulate(P, duration=8.0, pc_attack=attack, scc=scc,
                                load_feedforward=True).metrics()["tripped"]
    for (a, b, sensor), (trip, outside) in got.items():
        tripping = sensor == "rocof_meas" and a.startswith("square")
        assert trip == ("ROCOF" if tripping else "-"), (a, b, sensor)
        if tripping:
            assert outside == (b == "scaled by -1"), (a, b, sensor)


def test_the_papers_scc_blinded_on_either_sensor_trips_nothing_here():
    """Measured: the paper's SCC (its default reading) trips under none of the 32
    blinded runs, flagging ``outside`` in every one (as it does unblinded under these
    attacks)."""
    got = outcomes("paper")
    assert len(got) == 32
    assert all(trip == "-" and outside for trip, outside in got.values())


def test_the_redundant_sensors_take_their_lies_as_waveforms():
    from lfc.sensors import Redundant, SensorArray
    with pytest.raises(ValueError, match=r"lies\[1\]\['dw_meas'\].*waveform of time"):
        Redundant(SensorArray(bound=(1e-3, 1e-2)), {1: {"dw_meas": Freeze(start=0.5)}})


def test_a_generator_side_takes_attacks_on_its_sensors_only():
    from lfc.generator import GeneratorSide
    tc = np.arange(100) * 0.01
    with pytest.raises(ValueError, match="sensor_attacks"):
        GeneratorSide(P, None, None, (0.0, 0.0), 0, tc, None, None, False, 0.01,
                      sensor_attacks={"pc": lfc.Step(1.0)})
    side = GeneratorSide(P, None, None, (0.0, 0.0), 0, tc, None, None, False, 0.01,
                         sensor_attacks={"rocof_meas": Scale(-1.0, start=0.5)})
    assert side.reports(10, np.array([1e-3, 2e-3])) == (1e-3, 2e-3)
    assert side.reports(60, np.array([1e-3, 2e-3])) == (1e-3, -2e-3)


def test_the_red_team_against_a_blinded_defender_finds_a_trip_nobody_flags():
    """The coordinated red team (``coordinated_search``) with area 0's ROCOF sensor
    frozen from 0.9 s (``scenario={"attacks": ...}``): against the certified filter of
    each area of the two-area preset a square attack on the commands trips, and no
    filter ever flags ``outside``; the same search unblinded finds no trip."""
    from lfc.experiments.redteam import coordinated_search
    grid, filters = MultiAreaParams.two_area(), {0: "certified", 1: "certified"}
    kw = dict(maxiter=3, popsize=4, duration=10.0)
    honest = coordinated_search(grid, filters, "square on P_c", **kw)
    blind = coordinated_search(grid, filters, "square on P_c", **kw,
                               scenario={"attacks": {0: {"rocof_meas": Freeze(start=0.9)}}})
    assert not honest["tripped"] and honest["severity"] < 1.0
    assert blind["tripped"] and blind["severity"] > 1.0 and blind["outside"] == 0
    with pytest.raises(ValueError, match="must not be on 'pc'"):
        coordinated_search(grid, filters, "square on P_c", **kw,
                           scenario={"attacks": {1: {"pc": lfc.Step(1.0)}}})


# -- the red team's sensor families on grids ------------------------------------------------
ESTIMATE = {"estimator": "kalman", "noise_std": (1e-4, 1e-3)}
#: (filter kind, on the estimate) -> the families whose winner trips, measured
SENSOR_TRIPS = {("none", False): {"bias on dw_meas"},
                ("certified", False): set(),
                ("certified", True): {"sinusoid on dw_meas"},
                ("coupled", True): {"sinusoid on dw_meas"}}


@pytest.mark.parametrize("grid", ["two_area", pytest.param("three_area",
                                                           marks=pytest.mark.exhaustive)])
@pytest.mark.parametrize("setting", list(SENSOR_TRIPS), ids=lambda s: f"{s[0]}-{s[1]}")
def test_finding_on_grids_the_sensor_families_against_each_filter(grid, setting):
    """The coordinated red team over the sensor families (a bias or a sinusoid on the
    frequency reading, a bias on ROCOF's; every area at once), 3 generations × 4, 20 s.
    Measured: without a filter a bias on the frequency reading trips (the AGC moves the
    frequency by it); the certified filters on the exact state trip nowhere (they read a
    state outside their safe set and hold); on the Kalman estimate a sinusoidal lie trips
    through the certified and the coupled filters — flagged ``outside`` first, 0.9 to 1.9 s
    before the trip."""
    from lfc.experiments.redteam import coordinated_scenario, coordinated_search
    params = getattr(MultiAreaParams, grid)()
    kind, estimated = setting
    filters = {} if kind == "none" else {a: kind for a in range(params.n_areas)}
    scenario = ESTIMATE if estimated else None
    for family in ("bias on dw_meas", "sinusoid on dw_meas", "bias on rocof_meas"):
        found = coordinated_search(params, filters, family, maxiter=3, popsize=4,
                                   duration=20.0, scenario=scenario)
        assert found["tripped"] == (family in SENSOR_TRIPS[setting]), family
        if found["tripped"] and filters:
            run = lfc.simulate(params, duration=20.0, filters=filters, **(scenario or {}),
                               **coordinated_scenario(family, found["theta"],
                                                      params.n_areas, 20.0))
            assert run.warning_time > 0.5, family


# -- the red team over the lies that read the sensor ------------------------------------------
#: pu, s: the operator's load alarm that sees a load estimate drift (Result.load_alarms)
STUCK_ALARM = (0.3, 10.0)
READING_FAMILIES = [f"{kind} on {channel}" for kind in ("scale", "freeze", "replay")
                    for channel in ("dw_meas", "rocof_meas")]


def test_finding_the_single_area_red_team_over_the_readings_under_an_honest_load_step():
    """``family_search`` over the lies that read the sensor (a gain in [−1, 3], a stuck
    meter for 0.1–30 s, a replay of 0.01–1 s earlier), every run with an honest 0.2 pu load
    step at 2 s (``scenario``: at equilibrium a reading of 0 stays 0 whatever it is
    scaled, frozen or replayed by), 3 generations × 4, 20 s.  Measured: nothing trips
    within 20 s; a negative gain on the frequency reading turns the AGC's integral
    feedback positive, and without a filter and through the paper's SCC the frequency
    has passed F (severity above 1.5) and keeps growing; the certified filter keeps
    every run below F."""
    from lfc.experiments.redteam import SENSOR_FAMILIES, Defender, family_search
    assert set(READING_FAMILIES) <= set(SENSOR_FAMILIES)
    load = {"load": lfc.Step(0.2, start=2.0)}
    for defender in (Defender("none", method="none"), Defender("paper α=20"),
                     Defender("certified", method="certified")):
        for family in READING_FAMILIES:
            found = family_search(P, defender, family, duration=20.0, maxiter=3, popsize=4,
                                  scenario=load)
            assert not found["tripped"], (defender.name, family)
            if defender.method == "certified":
                assert found["severity"] < 1.0, family
            elif family == "scale on dw_meas":
                assert found["severity"] > 1.5 and found["theta"][0] < 0, defender.name


def test_finding_a_blinded_rocof_meter_lets_the_single_area_red_team_trip_the_certified_filter():
    """The single-area red team (square and sinusoid on P_c, 3 generations × 4, 20 s)
    against the certified filter: unblinded it finds no trip; with the ROCOF meter
    frozen, scaled by 0 or replaying 0.5 s earlier from 0.9 s, it finds attacks that trip
    ROCOF with no ``outside`` flag; with the frequency meter frozen instead, none.  The
    paper's SCC (α = 20) trips under the same search blinded or not, flagged.  A found
    attack replays with ``replay`` and the same ``scenario``."""
    from lfc.experiments.redteam import Defender, family_search, replay, severity
    certified, paper = Defender("certified", method="certified"), Defender("paper α=20")
    kw = dict(duration=20.0, maxiter=3, popsize=4)
    blinded = [{"rocof_meas_attack": lie} for lie in (Freeze(start=0.9), Scale(0.0, start=0.9),
                                                      Replay(0.5, start=0.9))]
    for family in ("square on P_c", "sinusoid on P_c"):
        honest = family_search(P, certified, family, **kw)
        assert not honest["tripped"] and honest["severity"] < 1.0, family
        for scenario in blinded:
            found = family_search(P, certified, family, **kw, scenario=scenario)
            assert found["tripped"] and found["first_trip"] == "ROCOF", (family, scenario)
            assert found["outside"] == 0, (family, scenario)
        frozen_w = family_search(P, certified, family, **kw,
                                 scenario={"dw_meas_attack": Freeze(start=0.9)})
        assert not frozen_w["tripped"], family
        for scenario in (None, blinded[0]):
            found = family_search(P, paper, family, **kw, scenario=scenario)
            assert found["tripped"] and found["outside"] > 0, (family, scenario)
    again = lfc.simulate(P, duration=20.0, scc=lfc.SafetyFilter(P, RELAYS, method="certified"),
                         **blinded[0], **replay(found := family_search(
                             P, certified, "square on P_c", **kw, scenario=blinded[0]), 20.0))
    assert severity(again.metrics(), RELAYS) == pytest.approx(found["severity"], rel=1e-9)


def test_a_search_fixes_only_the_channels_its_family_leaves_alone():
    from lfc.experiments.redteam import Defender, family_search
    kw = dict(duration=5.0, maxiter=1, popsize=1)
    with pytest.raises(ValueError, match="'pc_attack'"):
        family_search(P, Defender("x"), "square on P_c", **kw,
                      scenario={"pc_attack": lfc.Step(1.0)})
    with pytest.raises(ValueError, match="scc"):
        family_search(P, Defender("x"), "square on P_c", **kw, scenario={"scc": None})
    with pytest.raises(TypeError, match="scenario"):
        family_search(P, Defender("x"), "square on P_c", **kw, scenario=[1])


def test_finding_a_stuck_frequency_meter_and_an_honest_load_step_trip_through_the_coupled_filter():
    """Two-area preset on the grid Kalman estimate (the chapters' noise), area 0's
    frequency meter frozen (or scaled by 0) from 1 s and an honest load step in area 0 at
    2 s, 40 s.  Without a filter and through the certified filters nothing trips (the
    frequency stays within 0.009 pu).  Through the coupled filters, for steps of ±0.05 pu
    (within their ``load_bound``, 0.06 pu) and ±0.1 pu, area 0 trips (UF2 for a load rise,
    OF2 for a drop) within 12–28 s, and no filter ever flags ``outside``: the grid estimate
    explains the honest ROCOF and the frozen frequency with a load that drifts past 4
    times the true step, and the certificate steers the commands by it while the
    estimated frequency stays near 0.  Steps of ±0.03 pu trip nothing and the estimate
    does not drift (nor at 0.04 pu over 120 s, measured).  Outside the certificate's
    statement (its estimate's error is the noise's and the loads', never a lie's: module
    docstring of :mod:`lfc.filters.coupled`), and a case where the filter makes the lie
    worse.  The operator's load alarm at 0.3 pu within 10 s (``Result.load_alarms``) comes
    1.5 s or more before every trip and never without the lie.  The red team over the
    readings (a 0.1 pu step in every run) finds it too: a gain near 0 on area 0's
    frequency reading trips with no ``outside``.  On the three-area preset the same stuck
    meter and load step trip nothing (measured)."""
    from lfc.experiments.redteam import coordinated_search
    grid, coupled = MultiAreaParams.two_area(), {0: "coupled", 1: "coupled"}
    assert area_filter(grid, 0, "coupled", RELAYS, 0.01).options.load_bound == 0.06
    for load in (0.05, -0.05, 0.1, -0.1, 0.03, -0.03):
        honest = lfc.simulate(grid, filters=coupled, duration=40.0,
                              loads={0: lfc.Step(load, start=2.0)}, **ESTIMATE)
        assert not honest.tripped and honest.load_alarms(*STUCK_ALARM).empty, load
        for lie in (Freeze(start=1.0), Scale(0.0, start=1.0)):
            scenario = dict(duration=40.0, loads={0: lfc.Step(load, start=2.0)},
                            attacks={0: {"dw_meas": lie}}, **ESTIMATE)
            for kind in ("none", "certified"):
                filters = {} if kind == "none" else {0: kind, 1: kind}
                m = lfc.simulate(grid, filters=filters, **scenario).table()
                assert not m.tripped.any() and m.max_abs_dw_meas.max() < 0.009, (kind, load)
            r = lfc.simulate(grid, filters=coupled, **scenario)
            if abs(load) < 0.05:
                assert not r.tripped and r.areas[0].controls.p_load_hat.abs().max() < 0.05
                continue
            m = r.table()
            assert m.tripped.tolist() == [True, False] and m.outside.sum() == 0, (load, lie)
            assert r.first_trip["relay"] == ("UF2" if load > 0 else "OF2")
            assert 12.0 < r.first_trip["t"] < 28.0
            assert r.load_alarms(*STUCK_ALARM).t.iloc[0] < r.first_trip["t"] - 1.5
            c = r.areas[0].controls
            before = c[c.t < r.first_trip["t"]]
            assert before.p_load_hat.abs().max() > 4 * abs(load)
            assert before.dw_hat.abs().max() < 1e-3
    three = MultiAreaParams.three_area()        # measured: there the same runs trip nothing
    r = lfc.simulate(three, filters={a: "coupled" for a in range(3)}, duration=30.0,
                     loads={0: lfc.Step(0.1, start=2.0)},
                     attacks={0: {"dw_meas": Freeze(start=1.0)}}, **ESTIMATE)
    assert not r.tripped and r.first_outside is None
    found = coordinated_search(grid, coupled, "scale on dw_meas",
                               maxiter=3, popsize=4, duration=20.0,
                               scenario={"loads": {0: lfc.Step(0.1, start=2.0)}, **ESTIMATE})
    assert found["tripped"] and found["outside"] == 0 and abs(found["theta"][0]) < 0.2


#: (fitted grid, filter kind, on the estimate) -> the sensor families whose winner trips
FIT_SENSOR_TRIPS = {(grid, *setting): ({"bias on dw_meas"} if setting[0] == "none" else set())
                    for grid in ("kundur", "ieee39") for setting in SENSOR_TRIPS}


@pytest.mark.parametrize("grid", ["kundur", pytest.param("ieee39", marks=pytest.mark.exhaustive)])
def test_finding_on_the_fitted_grids_the_sensor_families_against_each_filter(grid):
    """The same red team on the design models fitted to Kundur's and the IEEE 39-bus
    system (linear, as the filters see them; ``lfc.testbed.fit.grid_design``), 3
    generations × 4, 20 s.  Measured: without a filter a bias on the frequency reading
    trips, as on the presets; every filter, on the exact state and on the estimate, trips
    under none of the three families (on the presets a sinusoidal lie trips through the
    filters on the estimate).  The stuck meter and honest load step that trip through
    the coupled filters on the two-area preset trip nothing here (either area, ±0.05 and
    0.1 pu)."""
    from lfc.experiments.redteam import coordinated_search
    from test_coupled import ieee39, kundur
    params = {"kundur": kundur, "ieee39": ieee39}[grid]()
    for kind, estimated in SENSOR_TRIPS:
        filters = {} if kind == "none" else {a: kind for a in range(params.n_areas)}
        for family in ("bias on dw_meas", "sinusoid on dw_meas", "bias on rocof_meas"):
            found = coordinated_search(params, filters, family, maxiter=3, popsize=4,
                                       duration=20.0, scenario=ESTIMATE if estimated else None)
            assert found["tripped"] == (family in FIT_SENSOR_TRIPS[grid, kind, estimated]), \
                (kind, estimated, family)
    coupled = {a: "coupled" for a in range(params.n_areas)}
    for area, load in itertools.product(range(params.n_areas), (0.05, -0.05, 0.1)):
        r = lfc.simulate(params, filters=coupled, duration=40.0, **ESTIMATE,
                         loads={area: lfc.Step(load, start=2.0)},
                         attacks={area: {"dw_meas": Freeze(start=1.0)}})
        assert not r.tripped, (area, load)
