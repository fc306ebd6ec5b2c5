"""A fitted model's mismatch with ANDES, as load (``lfc.testbed.fit.equivalent_load``),
and the grid-wide certificates that add it to their load budget by default
(``mismatch_budget``: the coupled certificate and the contracts)."""

from __future__ import annotations

import dataclasses
import math

import control as ct
import numpy as np
import pytest

import lfc
from lfc.filters.base import OUTSIDE
from lfc.filters.contract import ContractFilter, contract_design
from lfc.filters.coupled import CoupledFilter
from lfc.model import lfc_model
from lfc.multiarea import MultiAreaParams
from lfc.testbed import fit as fitting

RELAYS = lfc.RelaySettings()
TWO = MultiAreaParams.two_area()


def record(params: lfc.LFCParams, duration: float = 8.0, dt: float = 0.005) -> dict:
    """A 0.02 pu command step at 1 s and a -0.03 pu load step at 3 s on the linear
    model ``params``: its time, inputs and rotor speed."""
    t = np.arange(0.0, duration + dt / 2, dt)
    u, p = 0.02 * (t >= 1.0), -0.03 * (t >= 3.0)
    states = ct.forced_response(lfc_model(params), t, np.vstack([u, p])).states
    return {"t": t, "u": u, "p_load": p, "dw": states[2]}


def windowed(signal: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``signal``'s mean over each ``MISMATCH_WINDOW`` ending at a sample (trapezoids)."""
    from scipy.integrate import cumulative_trapezoid
    n = int(round(fitting.MISMATCH_WINDOW / (t[1] - t[0])))
    total = cumulative_trapezoid(signal, t, initial=0.0)
    return (total[n:] - total[:-n]) / (t[n] - t[0])


def test_the_equivalent_load_of_a_models_own_record_is_zero():
    """The model given its own record needs no extra load: zero to the trapezoids'
    error, the load step included (read as a step, not as a spike)."""
    params = lfc.LFCParams()
    r = record(params)
    d = fitting.equivalent_load(params, r["t"], r["u"], r["p_load"], r["dw"])
    assert len(d) == len(r["t"]) - int(round(fitting.MISMATCH_WINDOW / 0.005))
    assert np.abs(d).max() < 1e-5          # measured 1.2e-6 pu, against steps of 0.02 and 0.03


@pytest.mark.parametrize("M, D", [(4.0, 1.0), (6.0, 1.0), (4.0, 1.5), (6.0, 0.5)])
def test_the_equivalent_load_of_another_inertia_and_damping_is_their_swing_terms(M, D):
    """Recorded on a plant with inertia ``M`` and damping ``D``, read by the default
    model (M = 4 s, D = 1): the load that explains the record is what the swing
    equation's terms differ by, ``(M - 4) dw' + (D - 1) dw``, averaged over the
    window — the identity and the corners of a range of both."""
    model = lfc.LFCParams()
    r = record(dataclasses.replace(model, M=M, D=D))
    d = fitting.equivalent_load(model, r["t"], r["u"], r["p_load"], r["dw"])
    n = len(r["t"]) - len(d)
    expected = (M - 4.0) * (r["dw"][n:] - r["dw"][:-n]) / (n * 0.005) \
        + (D - 1.0) * windowed(r["dw"], r["t"])
    np.testing.assert_allclose(d, expected, atol=1e-5)    # measured 1e-6 pu
    assert fitting.swing(d) == pytest.approx(fitting.swing(expected), abs=2e-5)


def test_a_run_whose_last_sample_is_off_the_grid_is_read_on_its_grid():
    """ANDES ends a run at its exact end, off the 5 ms grid: the signals are read on
    the uniform grid, the last sample dropped."""
    params = lfc.LFCParams()
    r = record(params)
    t = np.append(r["t"][:-1], r["t"][-2] + 0.00025)
    d = fitting.equivalent_load(params, t, r["u"], r["p_load"], r["dw"])
    full = fitting.equivalent_load(params, r["t"], r["u"], r["p_load"], r["dw"])
    np.testing.assert_array_equal(d, full[:-1])


def test_the_committed_fits_carry_their_mismatch_and_the_design_models_too():
    """Each committed fit's mismatch (computed on its records: ``python -m lfc fit``),
    and the grids' budget is the largest of the fitting runs and the ladder's rungs
    within the command range, each rung's larger than the smaller rung's (the mismatch
    grows with the command): Kundur 0.043 pu, the IEEE 39-bus system 0.27 pu; the
    design model carries it, the microgrid's mismatch is reported."""
    from lfc.testbed import GridCase, MicrogridCase, grid_design, grid_fit_report
    expected = {"kundur": 0.043, "ieee39": 0.27}
    for case in (GridCase.kundur(), GridCase.ieee39()):
        report = grid_fit_report(case)
        within = [m for step, _, _, _, m in report.validation if step <= report.command_range]
        assert report.load_mismatch == max(within + [report.load_mismatch])
        assert report.load_mismatch >= max(within)
        assert report.load_mismatch == pytest.approx(expected[case.name], abs=0.005)
        by_step = {step: m for step, _, _, _, m in report.validation}
        steps = sorted(by_step)
        assert all(by_step[a] < by_step[b] for a, b in zip(steps, steps[1:]))
        assert grid_design(case).load_mismatch == report.load_mismatch
        assert all(a.mismatch > 0 for a in report.areas)
        assert "mismatch as load" in report.table()
    assert 0 < fitting.fit_report(MicrogridCase()).mismatch < 0.1


@pytest.mark.parametrize("bad", [-0.01, math.nan, math.inf])
def test_a_mismatch_that_is_not_a_finite_load_is_refused(bad):
    with pytest.raises(ValueError, match="load_mismatch"):
        dataclasses.replace(TWO, load_mismatch=bad)


def test_the_coupled_certificate_adds_the_mismatch_to_its_load_bound():
    """A model carrying 0.02 pu of mismatch: its coupled certificate is the one of
    ``load_bound`` 0.08 pu (0.06 + 0.02) at the same horizon, its options keep the
    user's 0.06, its repr names both; ``mismatch_budget=False`` is the model's
    certificate without it; the horizon is chosen (``"auto"``) unless given."""
    fitted = dataclasses.replace(TWO, load_mismatch=0.02)
    f = CoupledFilter(fitted, RELAYS, horizon=8.0)
    wide = CoupledFilter(TWO, RELAYS, load_bound=0.08, horizon=8.0)
    np.testing.assert_array_equal(f.data, wide.data)
    assert f.options.load_bound == 0.06 and f.mismatch == 0.02
    assert "load budget 0.06 + fit mismatch 0.02 pu" in repr(f)
    assert "the fit's mismatch (0.02 pu as load)" in f.reason(OUTSIDE)
    assert "mismatch" not in CoupledFilter(TWO, RELAYS).reason(OUTSIDE)
    off = CoupledFilter(fitted, RELAYS, mismatch_budget=False)
    np.testing.assert_array_equal(off.data, CoupledFilter(TWO, RELAYS).data)
    assert off.mismatch == 0.0 and not off.horizons
    chosen = CoupledFilter(fitted, RELAYS)
    assert chosen.horizons and chosen.options.horizon in chosen.horizons
    assert not CoupledFilter(TWO, RELAYS).horizons      # a model that is its plant: 8 s
    # the legitimate step the horizon is chosen for is the user's, not the mismatch
    assert chosen.held_after_step() == chosen.held_after_step(0.05)
    with pytest.raises(TypeError, match="mismatch_budget"):
        CoupledFilter(fitted, RELAYS, mismatch_budget="no")


def test_the_contracts_add_the_mismatch_to_their_load_bound():
    """The contracts of a model carrying 0.02 pu of mismatch are those of
    ``load_bound`` 0.08 pu; ``mismatch_budget=False`` gives the model's own."""
    fitted = dataclasses.replace(TWO, load_mismatch=0.02)
    share = contract_design(fitted, RELAYS)
    np.testing.assert_array_equal(share.half_width,
                                  contract_design(TWO, RELAYS, load_bound=0.08).half_width)
    assert share.load_bound == pytest.approx(0.08)
    off = contract_design(fitted, RELAYS, mismatch_budget=False)
    np.testing.assert_array_equal(off.rate, contract_design(TWO, RELAYS).rate)
    assert ContractFilter.grid_options(fitted, 0, RELAYS, 0.01)["half_width"] == \
        pytest.approx(float(share.half_width[0]))
    with pytest.raises(TypeError, match="mismatch_budget"):
        contract_design(fitted, RELAYS, mismatch_budget=1)


@pytest.mark.parametrize("limits", [{"u_max": 0.2000001}, {"u_min": -0.25},
                                    {"u_min": -math.inf, "u_max": math.inf}])
def test_command_limits_beyond_the_range_the_mismatch_was_measured_in_are_refused(limits):
    """The mismatch is measured within the fitted model's command range: limits beyond
    it (the next float up, one side, both infinite) are refused while the budget is on,
    and allowed without it; limits at the range itself are the default."""
    fitted = dataclasses.replace(TWO, command_range=0.2, load_mismatch=0.02)
    with pytest.raises(ValueError, match=r"command_range .*mismatch_budget=False"):
        CoupledFilter(fitted, RELAYS, horizon=8.0, **limits)
    alone = CoupledFilter(fitted, RELAYS, horizon=8.0, mismatch_budget=False, **limits)
    assert alone.mismatch == 0
    at_range = CoupledFilter(fitted, RELAYS, horizon=8.0, u_min=-0.2, u_max=0.2)
    assert (at_range.options.u_min, at_range.options.u_max) == (-0.2, 0.2)


@pytest.mark.exhaustive
@pytest.mark.long(150)
def test_a_users_own_fitted_case_gets_its_mismatch_budget_the_same_way():
    """A case nobody committed (Kundur with a slower frequency meter, 30 ms): its fit
    (two ANDES experiments and the command-range ladder, run here) computes its
    mismatch as the committed fits do, its design model carries it and the coupled
    filter built on that model by name adds it to its budget."""
    from lfc.testbed import GridCase
    case = dataclasses.replace(GridCase.kundur(), tau_w=0.03)
    fit = fitting.fit_grid(case)
    within = [m for step, _, _, _, m in fit.validation if step <= fit.command_range]
    assert fit.load_mismatch >= max(within) > 0
    design = fit.params
    assert design.load_mismatch == fit.load_mismatch
    filt = lfc.filters.build("coupled", design, 0, RELAYS)
    assert filt.mismatch == fit.load_mismatch
