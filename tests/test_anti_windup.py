"""Anti-windup (issue "Coupled", item 2): while a filter holds, the integrator
behind it must not wind up, so that frequency and tie-line schedule recover once
the attack ends.  Without it (the default, the paper's loop) the integrator runs
off behind a held command: pinned here as a finding."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import lfc
from lfc import LFCParams, MultiAreaParams
from lfc.linear_grid import simulate_grid_linear

TWO = MultiAreaParams.two_area()
PULSE = lfc.Step(3.0, start=1.0, stop=11.0)    # pu on area 0's ACE, 10 s


def _ace_pulse(anti_windup: bool):
    return simulate_grid_linear(TWO, duration=51.0, attacks={0: {"ace": PULSE}},
                                filters={0: "certified", 1: "certified"},
                                anti_windup=anti_windup)


def _at(trace, column, t):
    return float(trace[column][trace.t >= t].iloc[0])


def test_finding_without_anti_windup_the_agc_winds_up_behind_the_held_command():
    r = _ace_pulse(False)
    tr = r.trace
    assert tr.pc_ref_0.abs().max() > 2.4 and tr.pc_0.abs().max() < 0.65
    assert abs(_at(tr, "dw_meas_0", 31.0)) > 0.01            # 20 s after the pulse
    assert abs(_at(tr, "p_tie_0", 51.0)) > 0.2               # schedule still off at 40 s


def test_with_anti_windup_the_agc_stays_with_the_applied_command_and_recovers():
    r = _ace_pulse(True)
    tr = r.trace
    assert tr.pc_ref_0.abs().max() <= tr.pc_0.abs().max() + 0.01
    for a in (0, 1):
        assert abs(_at(tr, f"dw_meas_{a}", 31.0)) < 0.004
        assert abs(_at(tr, f"p_tie_{a}", 51.0)) < 0.012
        m = r.metrics()[a]
        assert not m["tripped"] and m["outside"] == 0


@pytest.mark.parametrize("scc", [None, "certified"])
def test_anti_windup_changes_nothing_while_the_filter_does_not_act(scc):
    """Without a filter, or with one that never alters the command, the runs are
    bitwise equal."""
    P = LFCParams()
    filt = None if scc is None else lfc.SafetyFilter(P, method=scc)
    run = dict(duration=8.0, load=lfc.Step(0.01, start=1.0), scc=filt)
    a, b = lfc.simulate(P, **run), lfc.simulate(P, **run, anti_windup=True)
    assert a.metrics()["alarms"] == 0
    pd.testing.assert_frame_equal(a.trace, b.trace, check_exact=True)


def test_single_area_local_integrator_does_not_wind_up_behind_a_held_bias():
    """A 10 s bias on ω_ref the certified filter holds off: the local integrator
    follows the applied command instead of running off."""
    P = LFCParams()
    run = dict(duration=40.0, wref_attack=lfc.Step(0.04, start=1.0, stop=11.0),
               scc=lfc.SafetyFilter(P, method="certified"))
    plain, held = lfc.simulate(P, **run), lfc.simulate(P, **run, anti_windup=True)
    gap = lambda r: float((r.controls.pc_ref - r.controls.pc).abs().max())  # noqa: E731
    assert gap(plain) > 10 * gap(held)
    for r in (plain, held):
        assert not r.metrics()["tripped"]
    assert abs(held.trace.dw_meas.iloc[-1]) <= abs(plain.trace.dw_meas.iloc[-1])


def test_anti_windup_must_be_a_bool():
    with pytest.raises(TypeError, match="anti_windup must be True or False"):
        lfc.simulate(LFCParams(), duration=0.1, anti_windup="yes")


@pytest.mark.andes_recorded
def test_anti_windup_on_the_andes_testbed():
    """The ANDES loop runs the engine's generator side: the same option, the same
    effect (a 0.2 pu ω_ref bias the certified filter holds off, 4 s)."""
    from lfc.testbed import MicrogridCase
    from lfc.testbed.fit import design_model
    case = MicrogridCase()
    design = design_model(case)
    run = dict(design=design, duration=6.0, wref_attack=lfc.Step(0.2, start=0.5, stop=4.5),
               scc=lfc.SafetyFilter(design, method="certified"))
    plain = lfc.simulate(case, **run)
    held = lfc.simulate(case, **run, anti_windup=True)
    gap = lambda r: float((r.controls.pc_ref - r.controls.pc).abs().max())  # noqa: E731
    assert held.settings["anti_windup"] and gap(plain) > 5 * gap(held)
    assert not held.metrics()["tripped"]


def test_a_scenario_table_row_with_anti_windup_equals_simulate():
    P = LFCParams()
    row = dict(waveform="step", channel="wref", amplitude=0.04, freq_hz=0.0, start=1.0,
               stop=11.0, alpha=20.0, Ts=0.25, method="certified")
    table = pd.DataFrame([row, {**row, "anti_windup": True}])
    table["anti_windup"] = table["anti_windup"].fillna(False).astype(bool)
    got = lfc.simulate_many(P, table, duration=20.0, progress=False)
    run = dict(duration=20.0, wref_attack=lfc.Step(0.04, start=1.0, stop=11.0),
               scc=lfc.SafetyFilter(P, method="certified"))
    for k, aw in enumerate((False, True)):
        want = lfc.simulate(P, **run, anti_windup=aw).metrics()
        assert got.loc[k, "mean_abs_modification"] == pytest.approx(want["mean_abs_modification"],
                                                                    rel=1e-12)
        assert got.loc[k, "final_abs_dw_meas"] == want["final_abs_dw_meas"]
    assert got.loc[1, "max_abs_modification"] < got.loc[0, "max_abs_modification"]
    table.loc[0, ["alpha", "method"]] = [np.nan, "paper"]
    table.loc[0, "anti_windup"] = True
    with pytest.raises(ValueError, match="'anti_windup' is True on row 0, which has no SCC"):
        lfc.simulate_many(P, table, duration=20.0, progress=False)
