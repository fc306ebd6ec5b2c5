"""Restoration after an attack against the grid's own AGC (``lfc.experiments.restoration``):
its measurements at their corners and its refusals.  The rule on every grid and filter:
``tests/test_coupled.py::test_after_every_attack_agc_restores_frequency_and_schedules_at_its_own_pace``."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lfc
from lfc.experiments.restoration import (AGC_ALONE_START, RESTORATION_MARGIN, RESTORED_DW,
                                         Restoration, agc_alone, agc_residue, grid_battery,
                                         restoration, restored_after)

GRID = lfc.MultiAreaParams.two_area()


def test_restored_after_is_zero_at_rest_inf_when_not_back_and_reads_an_area_alone():
    rest = lfc.simulate(GRID, duration=5.0)
    assert restored_after(rest, 1.0) == 0.0
    cut = lfc.simulate(GRID, duration=5.0, loads={0: lfc.Step(0.1, start=1.0)})
    assert restored_after(cut, 1.0) == math.inf          # 4 s is not enough for AGC
    area = lfc.simulate(lfc.LFCParams(), duration=60.0, load=lfc.Step(0.1, start=1.0))
    assert "p_tie" not in area.trace and 0.0 < restored_after(area, 1.0) < 59.0


def test_restored_after_counts_from_the_last_sample_outside_either_tolerance():
    """At the tolerance's edge: the time is the last sample at or above it."""
    r = lfc.simulate(GRID, duration=60.0, loads={1: lfc.Step(-0.05, start=1.0)},
                     anti_windup=True)
    t = r.trace.t.to_numpy()
    dw = np.max([np.abs(a.trace.dw_meas) for a in r.areas], axis=0)
    tie = np.max([np.abs(a.trace.p_tie) for a in r.areas], axis=0)
    last = t[(dw >= RESTORED_DW) | (tie >= 5e-3)].max()
    assert restored_after(r, 1.0) == pytest.approx(last - 1.0, abs=1e-12)
    assert restored_after(r, last + 1.0) == 0.0
    looser = restored_after(r, 1.0, dw_tol=1e-3, tie_tol=1e-2)
    assert 0.0 < looser < restored_after(r, 1.0)


def test_the_residue_is_what_agc_still_has_to_move():
    """A step of 0.1 pu in area 0: at the step nothing has moved yet (residue -0.1 pu
    there), at the run's end AGC has taken it (residue 0)."""
    r = lfc.simulate(GRID, duration=120.0, loads={0: lfc.Step(0.1, start=1.0)},
                     anti_windup=True)
    np.testing.assert_allclose(agc_residue(r, 1.0005), [-0.1, 0.0], atol=1e-12)
    np.testing.assert_allclose(agc_residue(r, 120.0), [0.0, 0.0], atol=1e-4)


def test_agc_alone_restores_nothing_at_once_and_a_step_as_the_grid_does():
    assert agc_alone(GRID, [0.0, 0.0]) == 0.0
    step = lfc.simulate(GRID, duration=200.0, loads={0: lfc.Step(-0.1, start=AGC_ALONE_START)},
                        anti_windup=True)
    assert agc_alone(GRID, [0.1, 0.0]) == restored_after(step, AGC_ALONE_START)


@settings(max_examples=5, deadline=None)
@given(r0=st.floats(-0.3, 0.3), r1=st.floats(-0.3, 0.3))
def test_property_agc_alone_is_the_same_for_a_residue_and_its_opposite(r0, r1):
    """The grid is linear and the tolerances symmetric."""
    assert agc_alone(GRID, [r0, r1]) == agc_alone(GRID, [-r0, -r1])


def test_the_goal_is_agc_alone_plus_the_margin_and_met_at_its_edge():
    p = Restoration(restored=30.0, agc_alone=20.0, residue=(0.1, 0.0), margin=10.0)
    assert p.goal == 30.0 and p.at_agc_pace
    assert not Restoration(math.nextafter(30.0, 31.0), 20.0, (0.1, 0.0), 10.0).at_agc_pace
    assert not Restoration(math.inf, 20.0, (0.1, 0.0), 10.0).at_agc_pace
    assert RESTORATION_MARGIN == 10.0


def test_restoration_of_an_attack_that_ended():
    attack = grid_battery(2, stop=11.0)["bias on every ACE"]
    r = lfc.simulate(GRID, duration=81.0, attacks=attack, anti_windup=True,
                     filters={0: "contract", 1: "contract"})
    pace = restoration(GRID, r, 11.0)
    assert pace.residue == tuple(agc_residue(r, 11.0)) and min(pace.residue) > 0.1
    assert pace.restored == restored_after(r, 11.0) and pace.at_agc_pace
    assert restoration(GRID, r, 11.0, margin=0.0).goal == pace.agc_alone


def test_the_battery_holds_five_attacks_that_end_when_told():
    battery = grid_battery(3, start=2.0, stop=7.0)
    assert len(battery) == 5 and set(battery["bias on every ACE"]) == {0, 1, 2}
    for attack in battery.values():
        for channels in attack.values():
            for signal in channels.values():
                assert (signal.start, signal.stop) == (2.0, 7.0)


@pytest.mark.parametrize("call, message", [
    (lambda: agc_alone(GRID, [0.1]), "residue must hold one finite load"),
    (lambda: agc_alone(GRID, [0.1, math.nan]), "residue must hold one finite load"),
    (lambda: restored_after(lfc.simulate(GRID, duration=1.0), 0.0, dw_tol=0.0), "dw_tol"),
    (lambda: restored_after(lfc.simulate(GRID, duration=1.0), 0.0, tie_tol=-1.0), "tie_tol"),
    (lambda: agc_residue(lfc.simulate(GRID, duration=1.0), math.nan), "end"),
    (lambda: restoration(GRID, lfc.simulate(GRID, duration=1.0), 0.5, margin=-1.0), "margin"),
])
def test_bad_input_is_refused_naming_it(call, message):
    with pytest.raises(ValueError, match=message):
        call()
