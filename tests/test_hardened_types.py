"""Type coercions that silently changed a run (issue "Hardened"): a string where a
bool or a number belongs is a TypeError naming the parameter."""

from __future__ import annotations

import pytest

import lfc
from lfc import LFCParams, MultiAreaParams
from lfc.repro.notebook import check_parameters

TWO = MultiAreaParams.two_area()


@pytest.mark.parametrize("plant", [LFCParams(), TWO], ids=["area", "grid"])
@pytest.mark.parametrize("name, value", [("stop_on_trip", "no"), ("stop_on_trip", 1),
                                         ("relay_noise", "yes")])
def test_a_flag_must_be_a_bool(plant, name, value):
    with pytest.raises(TypeError, match=f"{name} must be True or False, got {value!r}"):
        lfc.simulate(plant, duration=0.1, noise_std=(1e-4, 1e-3), **{name: value})


def test_load_feedforward_must_be_a_bool():
    with pytest.raises(TypeError, match="load_feedforward must be True or False"):
        lfc.simulate(LFCParams(), duration=0.1, load_feedforward="False")


def test_numpy_bools_are_bools():
    import numpy as np
    res = lfc.simulate(LFCParams(), duration=0.1, stop_on_trip=np.bool_(True))
    assert res.settings["stop_on_trip"]


def test_a_bias_given_as_a_string_is_refused_not_split_into_digits():
    with pytest.raises(TypeError, match="bias must be a sequence of 2 numbers"):
        MultiAreaParams(areas=TWO.areas, tie=TWO.tie, bias="12")
    with pytest.raises(TypeError, match=r"bias\[0\] must be a number, got 'a'"):
        MultiAreaParams(areas=TWO.areas, tie=TWO.tie, bias=("a", 2))


def _namespace(defaults: str, injected: str, **values) -> dict:
    return {"In": ["", defaults, "# Parameters\n" + injected], **values}


def test_papermills_raw_false_string_is_refused_for_a_bool_parameter():
    """``papermill -r check_claims False`` injects the string "False" (truthy)."""
    ns = _namespace("check_claims = True\nduration = 10.0\n", "check_claims = \"False\"\n",
                    check_claims="False", duration=10.0)
    with pytest.raises(TypeError, match="'check_claims' must be True or False"):
        check_parameters(ns)


@pytest.mark.parametrize("injected, value, ok", [
    ("duration = \"3\"\n", "3", False), ("duration = 3\n", 3, True),
    ("duration = True\n", True, False), ("duration = 3.5\n", 3.5, True)])
def test_a_number_parameter_takes_numbers_only(injected, value, ok):
    ns = _namespace("duration = 10.0\n", injected, duration=value)
    if ok:
        check_parameters(ns)
    else:
        with pytest.raises(TypeError, match="'duration' must be a finite number"):
            check_parameters(ns)


def test_a_parameter_whose_default_is_none_takes_anything():
    check_parameters(_namespace("alpha = None\n", "alpha = 3.0\n", alpha=3.0))


@pytest.mark.parametrize("tie, message", [
    (((0.7, 1, 1.0),), r"tie\[0\]'s i must be an integer index in \[0, 1\], got 0.7"),
    (((0, True, 1.0),), r"tie\[0\]'s j must be an integer index"),
    (((0, 1, "1.0"),), r"tie\[0\]'s T_ij must be a number, got '1.0'"),
])
def test_a_tie_line_index_or_coefficient_of_another_type_is_refused(tie, message):
    """An area index 0.7 was area 0; a coefficient "1.0" was 1.0."""
    with pytest.raises(TypeError, match=message):
        MultiAreaParams(areas=TWO.areas, tie=tie)


@pytest.mark.parametrize("key", [0.7, "0", True])
def test_an_area_key_must_be_an_integer(key):
    with pytest.raises(TypeError, match=r"a key of attacks \(an area\) must be an integer"):
        lfc.simulate(TWO, duration=0.1, attacks={key: {"pc": lfc.Step(0.1)}})


def test_a_wrong_type_is_a_type_error_that_value_error_handlers_still_catch():
    from lfc._validate import ParameterTypeError
    with pytest.raises(ParameterTypeError, match="alpha must be a number, got '20'"):
        lfc.SafetyFilter(LFCParams(), alpha="20")
    assert issubclass(ParameterTypeError, TypeError) and issubclass(ParameterTypeError,
                                                                    ValueError)


def test_a_run_that_becomes_non_finite_is_refused_not_reported_as_quiet():
    """Found by the second hostile review: Samples times 1e-320 apart interpolate
    to inf * 0 = NaN; the run went all-NaN and reported no trip, max |Δω| 0."""
    attack = lfc.Samples([0.0, 1e-320], [0.0, 1.0])
    for plant, kw in ((LFCParams(), {"pc_attack": attack}),
                      (TWO, {"attacks": {0: {"pc": attack}}})):
        with pytest.raises(ValueError, match="became non-finite.*pc_attack"):
            lfc.simulate(plant, duration=1.0, **kw)


def test_a_nan_command_is_held_and_flagged_by_the_filter():
    """Sinusoid(1, 1e308) is NaN where evaluated: with a filter, every sample is
    flagged invalid_input and the command held (the result was an IndexError)."""
    run = lfc.simulate(LFCParams(), duration=1.0, pc_attack=lfc.Sinusoid(1.0, 1e308),
                       scc=lfc.SafetyFilter(LFCParams()))
    assert run.alarms.invalid_input.all() and len(run.alarms) == 100
    assert not run.metrics()["tripped"]


def test_largest_load_bound_refuses_a_tolerance_it_cannot_reach():
    """tol=1e-300 looped for ever (the bisection stuck one ulp above tol)."""
    from lfc.filters.certified import largest_load_bound
    with pytest.raises(ValueError, match=r"tol must lie in \[1e-09, 1.0\]"):
        largest_load_bound(LFCParams(), lfc.RelaySettings(), tol=1e-300)


def test_bound_price_refuses_options_that_fix_the_bound_it_varies():
    from lfc.experiments.load_during_attack import bound_price
    with pytest.raises(ValueError, match="options must not set \\['load_bound'\\]"):
        bound_price(LFCParams(), (0.0,), (), options={"load_bound": 0.05})
