import math

import cvxpy as cp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from lfc.filters import CONFLICT_RULES, OUTSIDE_RULES, SafetyFilter
from lfc.filters.cvxpy_paper import PaperQP
from lfc.filters.paper import _priority, _relaxed, gamma
from lfc.model import LFCParams, discretize
from lfc.relays import RelaySettings

P = LFCParams()
EXACT = SafetyFilter(P)
PUSH = SafetyFilter(P, outside_rule="push", conflict="slack")
SCALE = np.array([0.5, 0.5, 0.04, 0.04, 0.08])  # typical magnitudes, includes outside states


def _random_cases(n, seed):
    rng = np.random.default_rng(seed)
    return (rng.normal(size=(n, 5)) * SCALE, rng.normal(scale=0.5, size=n),
            rng.normal(scale=0.05, size=n))


@pytest.mark.parametrize("limits", [(-math.inf, math.inf), (-0.5, 0.8)])
@pytest.mark.parametrize("outside_rule", OUTSIDE_RULES)
@pytest.mark.parametrize("conflict", CONFLICT_RULES)
def test_closed_form_equals_the_cvxpy_qp_written_from_the_definitions(limits, outside_rule,
                                                                       conflict):
    """The reference (lfc.filters.cvxpy_paper) builds h, dh/dx and the paper's
    dB/dt - alpha/B <= 0 itself, from scipy's expm; nothing is shared with the
    closed form but the model matrices."""
    kw = dict(u_min=limits[0], u_max=limits[1], outside_rule=outside_rule, conflict=conflict)
    exact = SafetyFilter(P, **kw)
    ref = PaperQP(P, RelaySettings(), alpha=exact.alpha, Ts=exact.Ts,
                  slack_weight=exact.slack_weight, **kw)
    x, u_ref, pl = _random_cases(400, seed=1)
    kinds = set()
    for i in range(len(u_ref)):
        ue, ie = exact.filter(x[i], u_ref[i], pl[i])
        uc = ref.solve(x[i], u_ref[i], pl[i])
        assert abs(ue - uc) <= 1e-6 * max(1.0, abs(ue)), (i, ue, uc, ie)
        kinds.add((ie.active, ie.infeasible, ie.outside))
    # the sample exercises every regime: inactive, active, outside, conflicting
    assert {(False, False, False), (True, False, False), (True, False, True),
            (True, True, True)} <= kinds


def test_solver_cvxpy_uses_the_reference_and_agrees_with_its_flags():
    ref = SafetyFilter(P, solver="cvxpy")
    x, u_ref, pl = _random_cases(200, seed=4)
    for i in range(len(u_ref)):
        ue, ie = EXACT.filter(x[i], u_ref[i], pl[i])
        uc, ic = ref.filter(x[i], u_ref[i], pl[i])
        assert not ic.solver_error and abs(ue - uc) <= 1e-6 * max(1.0, abs(ue))
        assert (ie.active, ie.infeasible, ie.outside) == (ic.active, ic.infeasible, ic.outside)


def test_cvxpy_problem_is_dpp_and_uses_clarabel():
    qp = SafetyFilter(P, solver="cvxpy").reference
    assert qp.hard.is_dpp() and qp.soft.is_dpp()
    assert all(a.is_dpp() and b.is_dpp() for a, b, _ in qp.lexi)
    qp.solve(np.array([0.0, 0.1, 0.01, 0.01, 0.03]), 0.6)
    assert qp.hard.solver_stats.solver_name == cp.CLARABEL


@pytest.mark.parametrize("kw", [{}, {"outside_rule": "push", "conflict": "slack"},
                                {"conflict": "rocof", "u_min": -0.5, "u_max": 0.8}])
def test_scalar_and_batch_agree(kw):
    filt = SafetyFilter(P, **kw)
    x, u_ref, pl = _random_cases(3000, seed=2)
    ub, flags = filt.filter_batch(x, u_ref, pl)
    for i in range(len(u_ref)):
        u, info = filt.filter(x[i], u_ref[i], pl[i])
        assert u == pytest.approx(ub[i], rel=1e-12, abs=1e-12)
        assert info.active == flags["active"][i] and info.outside == flags["outside"][i]
        assert info.infeasible == flags["infeasible"][i]
        assert info.h_freq == pytest.approx(flags["h"][i, 0], rel=1e-12, abs=1e-15)


def test_safe_reference_passes_unchanged():
    for u_ref in (-0.2, 0.0, 0.05, 0.2):
        u, info = EXACT.filter(np.zeros(5), u_ref)
        assert u == u_ref and not info.active and not info.alarm
        assert info.binding == () and info.reason == ""


state = st.tuples(*(st.floats(-3 * s, 3 * s) for s in SCALE))


@given(state, st.floats(-2, 2), st.floats(-0.2, 0.2))
def test_constraints_met_when_feasible(x, u_ref, pl):
    u, info = EXACT.filter(np.array(x), u_ref, pl)
    assert math.isfinite(u)
    if not info.infeasible:   # margins in pu of command; NaN: the command has no influence
        for margin in (info.margin_freq, info.margin_rocof):
            assert math.isnan(margin) or margin >= -1e-9 * (1 + abs(u))
    if not info.active:
        assert u == u_ref


@given(state, st.floats(-5, 5), st.floats(-0.2, 0.2))
def test_actuator_limits_always_respected(x, u_ref, pl):
    f = SafetyFilter(P, u_min=-0.3, u_max=0.4)
    u, info = f.filter(np.array(x), u_ref, pl)
    assert -0.3 <= u <= 0.4
    assert info.active == (u != u_ref)


@given(state, st.floats(-2, 2))
def test_minimal_modification(x, u_ref):
    """The applied command is the admissible command closest to u_ref.

    The constraint rows depend on u_ref (the prediction holds it, E5), so the
    admissible set is checked on the rows of this call, on a grid of commands.
    """
    u, info = EXACT.filter(np.array(x), u_ref)
    if not info.active or info.infeasible:
        return
    assert info.binding, info
    _, flags = EXACT.filter_batch(np.array([x]), np.array([u_ref]))
    kind, bound = flags["kind"][0], flags["bound"][0]
    grid = u_ref + np.linspace(-1, 1, 2001) * 2 * abs(u - u_ref)
    ok = np.all(np.where(kind == 1, grid[:, None] >= bound,
                         np.where(kind == -1, grid[:, None] <= bound, True)), axis=1)
    assert ok.any()
    assert np.min(np.abs(grid[ok] - u_ref)) >= abs(u - u_ref) * (1 - 1e-9) - 1e-12


STEADY_DW = 0.05  # pu, a steady state beyond F
STEADY_X = np.array([P.D * STEADY_DW, P.D * STEADY_DW, STEADY_DW, STEADY_DW, 0.0])
STEADY_U = P.D * STEADY_DW + STEADY_DW / P.droop  # the command that holds it


def test_push_rule_pushes_a_steady_over_frequency_back():
    """E9, "push": from a steady state at dw = 0.05 pu (> F), the command lowers
    the frequency (dh/dt >= alpha |h|)."""
    u, info = PUSH.filter(STEADY_X, STEADY_U)
    assert info.outside and info.active and u < STEADY_U
    assert info.margin_freq >= -1e-12 and info.h_freq < 0
    Ad, Bd = discretize(P, 0.25)
    assert (Ad @ STEADY_X + Bd[:, 0] * u)[3] < STEADY_DW - 0.005


def test_hold_rule_lets_a_steady_over_frequency_stay_but_not_grow():
    """E9, "hold": dh/dt >= 0 -- a steady state outside is not pushed, a command
    that would raise the frequency further is cut back to dh/dt = 0."""
    u, info = EXACT.filter(STEADY_X, STEADY_U)
    # the steady command sits exactly on the bound dh/dt = 0, which the filter's data
    # (matrix exponentials, BLAS) put within round-off of it on either side (measured
    # 1 ulp below on an AMD EPYC): within BOUND_ULPS it satisfies the bound, on every
    # machine — not clipped, not flagged active
    assert info.outside and u == STEADY_U and not info.active
    u, info = EXACT.filter(STEADY_X, STEADY_U + 0.2)
    assert info.outside and info.active and u < STEADY_U + 0.2
    assert info.margin_freq == pytest.approx(0.0, abs=1e-12)
    assert "not letting it get worse" in info.reason


def test_push_back_uses_actuator_limit_when_it_cannot_do_enough():
    x = np.array([0.05, 0.05, STEADY_DW, STEADY_DW, 0.0])
    f = SafetyFilter(P, u_min=0.5, u_max=2.0, outside_rule="push", conflict="slack")
    u, info = f.filter(x, 1.05)
    assert u == 0.5 and info.infeasible and "u_min" in info.binding


def test_conflicting_constraints_give_finite_relaxed_compromise():
    x, u_ref, pl = _random_cases(4000, seed=3)
    _, flags = PUSH.filter_batch(x, u_ref, pl)
    idx = np.flatnonzero(flags["infeasible"])
    assert len(idx) > 0
    for i in idx[:50]:
        u, info = PUSH.filter(x[i], u_ref[i], pl[i])
        assert math.isfinite(u) and info.infeasible and "relaxed" in info.reason
        lo = [b for k, b in zip(flags["kind"][i], flags["bound"][i]) if k == 1]
        hi = [b for k, b in zip(flags["kind"][i], flags["bound"][i]) if k == -1]
        if lo and hi:  # a true conflict: the compromise lies between the bounds
            assert min(hi) - 1e-9 <= u <= max(lo) + 1e-9


def test_relaxed_qp_splits_conflict_evenly():
    """Frequency needs u >= 0.3, ROCOF u <= 0.1: the slack compromise is halfway."""
    assert _relaxed(0.0, 1, 0.3, -1, 0.1, 1e4) == pytest.approx(0.2, abs=1e-4)


def test_priority_rules_meet_their_constraint():
    """Frequency needs u >= 0.3, ROCOF u <= 0.1: the first-named one is met exactly;
    beyond the actuator limits, as close to it as they allow."""
    assert _priority(0.0, 1, 0.3, -1, 0.1, -np.inf, np.inf) == 0.3     # frequency first
    assert _priority(0.0, -1, 0.1, 1, 0.3, -np.inf, np.inf) == 0.1     # ROCOF first
    assert _priority(0.0, 1, 0.3, -1, 0.1, -1.0, 0.2) == 0.2


def test_default_meets_the_frequency_constraint_where_the_two_conflict():
    x, u_ref, pl = _random_cases(4000, seed=3)
    _, flags = EXACT.filter_batch(x, u_ref, pl)
    conflicting = flags["infeasible"] & (flags["kind"] != 0).all(axis=1)
    assert conflicting.sum() > 20
    assert (flags["margin"][conflicting, 0] >= -1e-9).all()
    assert (flags["margin"][conflicting, 1] < 0).all()


@pytest.mark.parametrize("x, u_ref", [
    ([np.nan, 0, 0, 0, 0], 0.2),
    ([0, 0, np.inf, 0, 0], -0.1),
    ([0, 0, 0, 0, 0], np.nan),
    ([0, 0, 0, 0, 0], np.inf),
    ([1e200, 0, 0, 0, 0], 0.1),
    ([0, 0, 0, 0, 0], 1e160),
])
def test_invalid_input_holds_the_last_applied_command(x, u_ref):
    """A command that cannot be evaluated is never passed through: the last
    applied command is held (0 at first), flagged."""
    for solver in ("exact", "cvxpy"):
        filt = SafetyFilter(P, solver=solver)
        assert filt.filter(np.array(x, float), u_ref)[0] == 0.0
        u0, _ = filt.filter(np.zeros(5), 0.03)
        u, info = filt.filter(np.array(x, float), u_ref)
        assert u == u0 == pytest.approx(0.03, abs=1e-6) and info.invalid_input and info.alarm
        assert "invalid input" in info.reason


def test_non_finite_reference_clipped_to_actuator_limit():
    u, info = SafetyFilter(P, u_min=-1, u_max=0.05).filter(np.zeros(5), 0.1)
    assert u == 0.05 and info.active and info.binding == ("u_max",)
    u, info = SafetyFilter(P, u_min=0.2, u_max=1).filter(np.zeros(5), np.inf)
    assert u == 0.2 and info.invalid_input         # the held command, within the limits
    u, info = SafetyFilter(P).filter(np.zeros(5), 0.1, p_load=np.nan)
    assert u == 0.0 and info.invalid_input


def test_cvxpy_failure_falls_back_to_exact(monkeypatch):
    def boom(self, *args):
        raise cp.error.SolverError("simulated failure")
    monkeypatch.setattr(PaperQP, "solve", boom)
    x = np.array([0.0, 0.0, 0.02, 0.02, 0.04])
    u, info = SafetyFilter(P, solver="cvxpy").filter(x, 0.5)
    assert info.solver_error and "exact solution used" in info.reason
    assert u == EXACT.filter(x, 0.5)[0]


def test_gamma_push_is_extended_class_k_and_hold_stops_at_zero():
    h = np.linspace(-0.01, 0.01, 2001)
    push = np.array([gamma(v, 3.0, True) for v in h])
    assert np.all(np.diff(push) > 0) and gamma(0.0, 3.0, True) == 0.0
    hold = np.array([gamma(v, 3.0, False) for v in h])
    assert np.all(hold[h <= 0] == 0) and np.all(np.diff(hold[h > 0]) > 0)
    assert gamma(1e-12, 3.0, False) < 1e-12  # continuous at 0
    # paper's form: dB/dt <= alpha / B  <=>  dh/dt >= -alpha h (1+h) / B(h)
    hp = 0.002
    B = -math.log(hp / (1 + hp))
    assert gamma(hp, 3.0, False) == pytest.approx(3.0 * hp * (1 + hp) / B)


def test_smaller_alpha_is_stricter():
    x = np.array([0.0, 0.1, 0.01, 0.01, 0.03])
    u3, _ = SafetyFilter(P, alpha=3).filter(x, 0.6)
    u20, _ = SafetyFilter(P, alpha=20).filter(x, 0.6)
    assert u3 <= u20 < 0.6


@pytest.mark.parametrize("kwargs, name", [
    ({"alpha": 0}, "alpha"), ({"alpha": -3}, "alpha"), ({"Ts": 0}, "Ts"),
    ({"Ts": float("nan")}, "Ts"), ({"solver": "osqp"}, "solver"),
    ({"u_min": 1, "u_max": 1}, "u_min"), ({"u_min": float("nan")}, "u_min"),
    ({"slack_weight": 0}, "slack_weight"), ({"outside_rule": "ignore"}, "outside_rule"),
    ({"conflict": "first"}, "conflict"), ({"prediction": "zero"}, "prediction")])
def test_bad_parameters(kwargs, name):
    with pytest.raises(ValueError, match=name):
        SafetyFilter(P, **kwargs)


def test_bad_state_shape():
    with pytest.raises(ValueError, match="5 entries"):
        EXACT.filter(np.zeros(4), 0.0)


def test_safe_set_comes_from_relay_settings():
    f = SafetyFilter(P, RelaySettings(of2=1.02, uf2=0.95, rocof_limit=0.03))
    np.testing.assert_allclose(f.limits, [0.02, 0.03])


@pytest.mark.parametrize("ulps", [-8, -1, 0, 1, 4, 8, 9, 12])
def test_a_command_within_a_few_ulps_of_its_bound_is_not_clipped(ulps):
    """The decision at a bound does not flip on the last bits of the bound: a
    command within ``BOUND_ULPS`` (8) ulp beyond the bound computed for it is kept
    and not flagged, one further is clipped to that bound; 64 ulp beyond is clipped.

    The bound moves with the command (the incoming reading predicts with it): 0 or
    1 ulp here, differently under two OpenBLAS kernels, so a command 8 ulp beyond
    another command's bound was kept under the default kernel and clipped under
    ``OPENBLAS_CORETYPE=Sandybridge`` (9 ulp beyond its own).  So each call is
    judged against its own bound, and up to 4 ulp beyond the first is always kept."""
    from lfc.filters.paper import BOUND_ULPS, EPS
    u_big, info = EXACT.filter(STEADY_X, STEADY_U + 0.2)
    bound = info.details["bound"][0]
    assert info.active and u_big == bound
    u_ref = bound + ulps * np.spacing(bound)
    u, info = EXACT.filter(STEADY_X, u_ref)
    own = info.details["bound"][0]
    assert abs(own - bound) <= 2 * np.spacing(bound)
    within = u_ref <= own or abs(u_ref - own) <= BOUND_ULPS * EPS * abs(own)
    assert within or ulps > 4
    assert within == (ulps <= 4) or 4 < ulps < 12
    if within:
        assert u == u_ref and not info.active
    else:
        assert info.active and u == own
    u, info = EXACT.filter(STEADY_X, bound + 64 * np.spacing(bound))
    assert info.active and u == info.details["bound"][0]


@given(flags=st.integers(0, 2 ** 15 - 1))
def test_what_info_reads_from_the_flags_is_each_filters_own(flags):
    """``FilterInfo``'s booleans, binding bounds and reason depend on the flag bits
    and the filter's frozen options only, and are worked out once per flag value
    and filter: a filter that pushes back and one that holds word an ``outside``
    differently, whichever was asked first, and every answer equals the one
    computed afresh (the same for the batch's kinds)."""
    from lfc.filters import base
    from lfc.filters.paper import _kinds
    push, hold = (SafetyFilter(P, outside_rule=rule).backend for rule in ("push", "hold"))
    out = (0.1, flags, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.5, -0.5)
    for backend in (hold, push, hold):
        info = backend.info(0.2, out)
        assert info.reason == (backend.reason(flags) if flags & base.ALARM_BITS else "")
        assert info.binding == (base.binding_names(flags) if flags & base.ACTIVE else ())
        assert (info.active, info.outside) == (bool(flags & base.ACTIVE),
                                               bool(flags & base.OUTSIDE))
        assert info.details["kind"] == _kinds(flags)
    if flags & base.OUTSIDE:
        assert push.info(0.2, out).reason != hold.info(0.2, out).reason
