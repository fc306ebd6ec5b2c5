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
