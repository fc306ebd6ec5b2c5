"""E12 corrected: the no-SCC threshold on the measured ROCOF, and what a governor could do."""

import pytest

import lfc
from lfc.experiments.load_limits import governor_ride_through, no_scc_threshold

P, RELAYS = lfc.LFCParams(), lfc.RelaySettings()


def test_the_measured_rocof_lets_steps_above_m_times_the_limit_through():
    """The true ROCOF after a step is dPL / M; the relay reads it through a 50 ms lag,
    whose peak is about 0.9 dPL / M: steps up to 0.22284 pu do not trip without SCC."""
    threshold = no_scc_threshold(P, RELAYS)
    assert threshold == pytest.approx(0.22285, abs=1e-4)
    for step, trips in ((0.22284, False), (0.22285, True)):   # the README's numbers
        assert lfc.simulate(P, duration=5, load=lfc.Step(step, 1.0)).metrics()["tripped"] == trips
    assert threshold > P.M * RELAYS.rocof_limit
    for step, trips in ((threshold - 2e-4, False), (threshold, True)):
        r = lfc.simulate(P, duration=5, load=lfc.Step(step, 1.0))
        assert r.metrics()["tripped"] == trips
    peak = lfc.simulate(P, duration=5, load=lfc.Step(0.2, 1.0)).metrics()["max_abs_rocof_meas"]
    assert peak / (0.2 / P.M) == pytest.approx(0.9, abs=0.01)


@pytest.mark.parametrize("step, u_bound, rides", [(0.25, 1.0, True), (0.25, 3.0, True),
                                                   (0.3, 1.0, False), (0.3, 3.0, True)])
def test_a_governor_could_ride_through_steps_above_the_threshold(step, u_bound, rides):
    """A linear program over one command per 10 ms (reacting one period after the step):
    within +-3 pu a 0.3 pu step rides through, within +-1 pu a 0.25 pu step does.
    Replayed in lfc.simulate (no local integrator), the commands trip nothing."""
    best = governor_ride_through(P, RELAYS, step, u_bound=u_bound)
    assert best.rides_through == rides and abs(best.commands).max() <= u_bound + 1e-9
    assert best.commands[0] == 0.0  # the governor has not seen the step yet
    replay = lfc.simulate(lfc.LFCParams(k_i=0.0), duration=30, load=lfc.Step(step, 1.0),
                          pc_attack=lfc.Samples(best.t + 1.0, best.commands))
    assert replay.metrics()["tripped"] == (not rides)
    worst = max(replay.metrics()["max_abs_rocof_meas"] / RELAYS.rocof_limit,
                replay.metrics()["max_abs_dw_meas"] / RELAYS.F)
    assert worst == pytest.approx(best.severity, rel=1e-6)


def test_ride_through_rejects_bad_bounds():
    with pytest.raises(ValueError, match="u_bound"):
        governor_ride_through(P, RELAYS, 0.25, u_bound=0.0)
