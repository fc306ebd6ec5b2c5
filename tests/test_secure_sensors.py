"""A filter that survives lying sensors (issue "Sensors", item 3): three redundant
frequency and ROCOF sensors (``lfc.sensors``), at most one lying in any way, the
median fused channel by channel, the certified filter built for the median's error
(``sensor_bound``).  The proven statement (``lfc.sensors``'s docstring) at its worst
cases: the honest sensors' noise at the corners of its bound, constant or flipping every
sample, the liar on each sensor, lying far or staying just inside its noise bound, under
the strongest command attacks — no trip; the filter built without ``sensor_bound`` on the
same readings trips.  Beyond it (two sensors colluding) the measured exception is pinned."""

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
from lfc.sensors import Redundant, SensorArray, fuse

P, RELAYS = lfc.LFCParams(), lfc.RelaySettings()
WIDE = SensorArray(bound=(0.003, 0.02))     # pu, pu/s: coarse meters, where it shows
DURATION = 10.0
N = int(DURATION / 0.01)                    # control samples
TC = np.arange(N) * 0.01
ATTACKS = {"square 1 pu 0.3 Hz": lfc.Square(1.0, 0.3, start=1.0),
           "sinusoid 0.5 pu 1 Hz": lfc.Sinusoid(0.5, 1.0, start=1.0),
           "square 3 pu 0.5 Hz": lfc.Square(3.0, 0.5, start=1.0),
           "step 2 pu": lfc.Step(2.0, start=1.0)}


def honest(pattern: str, array: SensorArray = WIDE) -> dict:
    """The honest sensors' noise at the corners of its bound (``Redundant.noise``): all
    at +bound, all at -bound, or flipping sign every sample (-bound at the first)."""
    sign = {"high": np.ones(N), "low": -np.ones(N),
            "flipping": np.where(np.arange(N) % 2 == 0, -1.0, 1.0)}[pattern]
    return {k: {c: lfc.Samples(TC, sign * b) for c, b in zip(("dw_meas", "rocof_meas"),
                                                               array.bound)}
            for k in range(array.count)}


def sensed(array: SensorArray = WIDE, *, attacks: dict | None = None,
           honest: dict | None = None, duration: float = DURATION, **kwargs) -> lfc.Result:
    """``lfc.simulate`` of ``P`` whose AGC and filter read the median of ``array``'s
    sensors, the liars' ``attacks`` added to the ``honest`` noise."""
    return lfc.simulate(P, duration=duration, sensors=Redundant(array, attacks or {},
                                                                honest or {}), **kwargs)


def spoofed(result: lfc.Result) -> pd.DataFrame:
    """The alarm log's rows naming a lie."""
    return result.alarms[result.alarms.reason.astype(str).str.startswith("spoofed")]


def lies(sensor: int, kind: str, array: SensorArray = WIDE) -> dict:
    """A liar on ``sensor``: far (1 pu and -1 pu/s from 1 s), or just inside its noise
    bound (0.999 of it, opposite to the honest noise)."""
    if kind == "far":
        return {sensor: {"dw_meas": lfc.Step(1.0, start=1.0),
                         "rocof_meas": lfc.Step(-1.0, start=1.0)}}
    b = array.bound
    return {sensor: {"dw_meas": lfc.Step(-1.999 * b[0], start=1.0),
                     "rocof_meas": lfc.Step(-1.999 * b[1], start=1.0)}}


@settings(max_examples=tiers.examples(200), deadline=None)
@given(noise=st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6),
       liar=st.integers(0, 2), lie=st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3)))
def test_the_median_is_within_the_bound_and_names_only_the_liar(noise, liar, lie):
    """Any honest noise within the bound, any lie on any one sensor: the median is within
    the bound on both channels, no honest sensor is named, nothing is ``beyond``, and
    the liar is named exactly where it is farther than twice the bound from the median."""
    b = np.asarray(WIDE.bound)
    errors = np.asarray(noise).reshape(1, 3, 2) * b
    errors[0, liar] += lie
    fused = fuse(WIDE, np.zeros(1), errors)
    assert np.all(np.abs(fused.error) <= b * (1 + 1e-12))
    assert set(fused.spoofed.sensor) <= {liar} and fused.beyond.empty
    far = np.abs(errors[0, liar] - fused.error[0]) > 2 * b
    assert len(fused.spoofed) == far.sum()


def test_the_run_reads_the_median_exactly_and_names_the_liar_every_sample():
    """What the filter reads is the meters' state plus the median's error (to 1e-15), and
    a liar far off is named at every sample from its start on both channels."""
    red = Redundant(WIDE, lies(1, "far"), honest("flipping"))
    run = lfc.simulate(P, duration=DURATION, sensors=red, pc_attack=ATTACKS["step 2 pu"])
    c, trace = run.controls, run.trace.set_index("t")
    read = c.dw_hat.to_numpy() - trace.loc[c.t, "dw_meas"].to_numpy()
    np.testing.assert_allclose(read, red.fused(TC, 0).error[:, 0], rtol=0, atol=1e-15)
    named = spoofed(run)
    assert set(named.reason) == {"spoofed: sensor 1 (dw_meas)", "spoofed: sensor 1 (rocof_meas)"}
    assert len(named) == 2 * (N - 100) and named.t.min() == pytest.approx(1.0)


@pytest.mark.parametrize("attack", list(ATTACKS))
def test_the_secure_filter_trips_nothing_at_the_worst_cases(attack):
    """Proven (``lfc.sensors``), tested at its worst cases: for every liar position (each
    sensor), far off or just inside its noise bound, the honest noise at its corners
    (+bound, -bound, flipping every sample), the certified filter with
    ``sensor_bound=bound`` never trips; the same filter without it, on the same
    readings, trips on the far liars with the honest noise at +bound (finding: it trusts
    the median as the truth)."""
    secure = lfc.SafetyFilter(P, RELAYS, method="certified", sensor_bound=WIDE.bound)
    naive = lfc.SafetyFilter(P, RELAYS, method="certified")
    trips = []
    for sensor, kind, pattern in itertools.product(range(3), ("far", "inside"),
                                                   ("high", "low", "flipping")):
        run = dict(attacks=lies(sensor, kind), honest=honest(pattern),
                   pc_attack=ATTACKS[attack])
        r = sensed(scc=secure, **run)
        assert not r.tripped, (attack, sensor, kind, pattern, r.first_trip)
        if kind == "far" and pattern == "high":
            trips.append(sensed(scc=naive, **run).tripped)
    assert any(trips) == (attack != "step 2 pu"), (attack, trips)


def test_finding_two_colluding_sensors_beat_the_median():
    """Beyond the statement (two of three lie, ``tolerate=1``), measured: two sensors
    agreeing on a lie of 0.05 pu on the frequency out-vote the honest one, which is
    named ``spoofed`` in their place and nothing is ``beyond``; the filter reads the lie,
    as with one lying sensor (``tests/test_sensors.py``): nothing certified, ``outside``
    at every sample from the lie on, the AGC frozen, no trip.  Two liars that disagree
    (+0.05, -0.05) leave no two readings within twice the bound: ``beyond`` at every
    sample."""
    secure = lfc.SafetyFilter(P, RELAYS, method="certified", sensor_bound=WIDE.bound)
    lie = {s: {"dw_meas": lfc.Step(0.05, start=1.0)} for s in (0, 1)}
    run = sensed(scc=secure, attacks=lie, honest=honest("flipping"))
    assert set(spoofed(run).reason.str[:17]) == {"spoofed: sensor 2"}
    assert not run.alarms.reason.astype(str).str.startswith("beyond").any()
    m = run.metrics()
    assert not m["tripped"] and m["outside"] == N - 100       # every sample from 1 s
    assert m["max_abs_dw_meas"] < 1e-5       # the AGC moved only on the noise before it
    split = {0: {"dw_meas": lfc.Step(0.05, start=1.0)},
             1: {"dw_meas": lfc.Step(-0.05, start=1.0)}}
    beyond = sensed(scc=secure, attacks=split, honest=honest("flipping")).alarms
    beyond = beyond[beyond.reason.astype(str).str.startswith("beyond")]
    assert len(beyond) == N - 100
    assert set(beyond.reason) == {"beyond: more than tolerate lie (dw_meas)"}


def test_bad_sensor_models_are_refused_naming_what():
    for kwargs, name in (({"count": 2}, "count"), ({"tolerate": 0}, "tolerate"),
                         ({"bound": (0.0, 1e-3)}, "bound"), ({"bound": (1e-4,)}, "bound"),
                         ({"count": 4, "tolerate": 2}, "count")):
        with pytest.raises(ValueError, match=name):
            SensorArray(**{"bound": WIDE.bound, **kwargs})
    t = np.arange(3) * 0.01
    for attacks, what in (({3: {"dw_meas": lfc.Step(1.0)}}, "sensor"),
                          ({0: {"pc": lfc.Step(1.0)}}, "channel")):
        with pytest.raises(ValueError, match=what):
            WIDE.readings(t, attacks)
    with pytest.raises(ValueError, match="honest"):
        WIDE.readings(t, None, honest=np.full((3, 3, 2), 1.0))
    for red, what in ((lambda: Redundant(WIDE, {3: {"dw_meas": lfc.Step(1.0)}}), "sensor"),
                      (lambda: Redundant(WIDE, {0: {"pc": lfc.Step(1.0)}}), "lies\\[0\\]"),
                      (lambda: Redundant(WIDE, {}, {0: {"wref": lfc.Step(1.0)}}), "noise"),
                      (lambda: Redundant(WIDE, {0: {"dw_meas": 1.0}}), "signal"),
                      (lambda: Redundant(WIDE.bound), "array")):
        with pytest.raises((ValueError, TypeError), match=what):
            red()
    with pytest.raises(ValueError, match=r"noise\[1\]\['dw_meas'\]"):
        sensed(honest={1: {"dw_meas": lfc.Step(1.001 * WIDE.bound[0])}}, duration=1.0)
    with pytest.raises(ValueError, match=r"attacks\[0\].*sensors\[0\]"):
        sensed(dw_meas_attack=lfc.Step(0.1), duration=1.0)
    with pytest.raises(ValueError, match="noise_std"):
        sensed(noise_std=(1e-4, 1e-3), estimator="kalman", duration=1.0)
    with pytest.raises(ValueError, match="sensor_bound"):
        lfc.SafetyFilter(P, RELAYS, method="certified", sensor_bound=(1e-4, 1e-3),
                         noise_std=(1e-4, 1e-3))
    with pytest.raises(ValueError, match="sensor_bound"):
        lfc.SafetyFilter(P, RELAYS, method="certified", sensor_bound=(0.0, math.inf))


@pytest.mark.parametrize("array, load_bound", [(WIDE, 0.02),
                                               (SensorArray(bound=(1e-4, 1e-3)), 0.05)],
                         ids=["coarse", "fine"])
def test_the_secure_filter_trips_nothing_with_loads_within_its_bound(array, load_bound):
    """The statement with its load assumption at its edge: a step of exactly
    ``load_bound`` (either sign, 3 ms after a control sample or at 4.5 s) during every
    attack, the liar far off on each sensor, the honest noise at its corners: no trip
    (``outside`` is flagged — the re-check of the held command fails on the next
    sample's error — but the held command was certified for it).  The default tier runs
    the flipping noise and the first instant; the exhaustive tier all 144 per bound."""
    secure = lfc.SafetyFilter(P, RELAYS, method="certified", sensor_bound=array.bound,
                              load_bound=load_bound)
    patterns = ("high", "low", "flipping") if tiers.exhaustive() else ("flipping",)
    instants = (2.003, 4.5) if tiers.exhaustive() else (2.003,)
    for attack, sensor, pattern, start, sign in itertools.product(
            ATTACKS, range(3), patterns, instants, (1, -1)):
        r = sensed(array, scc=secure, attacks=lies(sensor, "far", array),
                   honest=honest(pattern, array), pc_attack=ATTACKS[attack],
                   load=lfc.Step(sign * load_bound, start=start))
        assert not r.tripped, (attack, sensor, pattern, start, sign, r.first_trip)


def test_the_alarm_log_names_the_spoofed_sensor_and_what_is_beyond():
    """The run's alarm log: the filter's rows (as without the sensors' rows) and a row
    per lie named, in time order, the filter's first at a tie; its ``alarms`` metric
    counts both; two disagreeing liars put ``beyond`` rows in it."""
    scc = lfc.SafetyFilter(P, RELAYS, method="certified", sensor_bound=WIDE.bound)
    red = Redundant(WIDE, lies(2, "far"), honest("high"))
    one = lfc.simulate(P, duration=3.0, scc=scc, sensors=red, pc_attack=ATTACKS["step 2 pu"])
    log, named = one.alarms, spoofed(one)
    fused = red.fused(TC[:300], 0)
    assert len(named) == len(fused.spoofed) > 0
    assert set(named.reason) == {"spoofed: sensor 2 (dw_meas)", "spoofed: sensor 2 (rocof_meas)"}
    assert log.t.is_monotonic_increasing and one.metrics()["alarms"] == len(log)
    told = red.attacks(fused)                  # the median's error as a plain sensor attack
    plain = lfc.simulate(P, duration=3.0, scc=scc, pc_attack=ATTACKS["step 2 pu"],
                         dw_meas_attack=told["dw_meas"], rocof_meas_attack=told["rocof_meas"])
    assert len(plain.alarms) > 0
    pd.testing.assert_frame_equal(log.drop(named.index).reset_index(drop=True), plain.alarms)
    at = log.reset_index(drop=True)
    first = at.groupby("t").head(1)
    assert not first.reason.astype(str).str.startswith("spoofed").any()   # filter's first
    two = sensed(scc=scc, duration=3.0, honest=honest("high"),
                 attacks={**lies(1, "far"), 2: {"dw_meas": lfc.Step(-1.0, start=1.0)}})
    assert two.alarms.reason.astype(str).str.startswith("beyond").any()
