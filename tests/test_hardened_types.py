"""Type coercions that silently changed a run (issue "Hardened"): a string where a
bool or a number belongs is a TypeError naming the parameter."""

from __future__ import annotations

import numpy as np
import pandas as pd
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


# -- the second hostile review's coercions and crashes, each now a clear error --

P = LFCParams()


def _fam(**kw):
    from lfc.experiments import redteam
    args = dict(maxiter=1, popsize=2, duration=2.0)
    args.update(kw)
    family = args.pop("family", "sinusoid on P_c")
    return redteam.family_search(P, redteam.Defender("d"), family, **args)


def _row(**kw):
    import pandas as pd
    row = dict(waveform="sinusoid", channel="pc", amplitude=0.5, freq_hz=1.0, start=0.5,
               alpha=20.0, Ts=0.25)
    return pd.DataFrame([{**row, **kw}])


REFUSED = [  # (call, exception, words of the message)
    (lambda: lfc.Step(1.0, stop=True), TypeError, "stop must be a number, got True"),
    (lambda: lfc.Samples(["0", "1"], [1, 2]), TypeError, "t must hold real numbers"),
    (lambda: lfc.Samples([0, 1], [True, False]), TypeError, "values must hold real numbers"),
    (lambda: lfc.Samples([[0, 1], [2, 3]], [1, 2, 3, 4]), ValueError, "t must be 1-dim"),
    (lambda: lfc.SafetyFilter(P).filter([0.0] * 5, "0.5"), TypeError, "u_ref must be a number"),
    (lambda: lfc.SafetyFilter(P).filter([0.0] * 5, True), TypeError, "u_ref must be a number"),
    (lambda: lfc.SafetyFilter(P).filter([0.0] * 5, 1 + 0j), TypeError, "u_ref must be a number"),
    (lambda: lfc.SafetyFilter(P).filter([0.0] * 5, 0.1, "0"), TypeError, "p_load must be"),
    (lambda: lfc.SafetyFilter(P).filter([[0.0]] * 5, 0.1), ValueError, "x must have 5 entries"),
    (lambda: lfc.SafetyFilter(P).filter(["0"] * 5, 0.1), TypeError, "x must hold real numbers"),
    (lambda: lfc.SafetyFilter(P).filter_batch([[0.0] * 5] * 2, ["1", "2"]), TypeError,
     "u_ref must hold real numbers"),
    (lambda: lfc.SafetyFilter(P).filter_batch([[0.0] * 5] * 2, [[0.0], [0.0]]), ValueError,
     r"u_ref must have shape \(N,\)"),
    (lambda: lfc.SafetyFilter(P).filter_batch([[False] * 5] * 2, [0.0, 0.0]), TypeError,
     "x must hold real numbers"),
    (lambda: lfc.SafetyFilter(None), TypeError, "params must be an LFCParams"),
    (lambda: lfc.SafetyFilter(P, relays="x"), TypeError, "relays must be a RelaySettings"),
    (lambda: lfc.SafetyFilter(P, method=["paper"]), ValueError, "method must be one of"),
    (lambda: lfc.SafetyFilter(P, method="certified", uncertainty={"M": ("0.8", "1.2")}),
     ValueError, r"uncertainty\['M'\] must be factors"),
    (lambda: lfc.SafetyFilter(P, method="certified", uncertainty={"M": (0.8, 1.2), 3: (1, 1)}),
     ValueError, "unknown parameter.*3"),
    (lambda: lfc.KalmanFilter(P, estimate_load="False"), TypeError, "estimate_load must be"),
    (lambda: lfc.KalmanFilter(P, meas_std=(1e300, 1e300)), ValueError, r"meas_std\[0\] must lie"),
    (lambda: lfc.KalmanFilter(P, process_std=1e300), ValueError, "process_std must lie in"),
    (lambda: lfc.KalmanFilter(P, period=1e-300), ValueError, "period must lie in"),
    (lambda: lfc.simulate_many(P, _row(), duration=1.0, progress="no"), TypeError,
     "progress must be True or False"),
    (lambda: lfc.simulate_many(P, _row(noise_w=1e-4, relay_noise=1.0), duration=1.0),
     TypeError, "column 'relay_noise' must be True or False"),
    (lambda: lfc.simulate_many(P, _row(), duration=1.0, out=""), ValueError, "out must be a "
     "folder"),
    (lambda: MultiAreaParams((P, P), tie=((0, 1, 2.0),), bias={1.0, 2.0}), TypeError,
     "bias must be a sequence"),
    (lambda: _fam(maxiter=0), ValueError, "maxiter must be an integer >= 1"),
    (lambda: _fam(popsize=-1), ValueError, "popsize must be an integer >= 1"),
    (lambda: _fam(duration=0.5), ValueError, "duration must be > ATTACK_START"),
    (lambda: _fam(family="sinus"), ValueError, "family must be one of"),
]


@pytest.mark.parametrize("call, error, words", REFUSED, ids=[w for *_, w in REFUSED])
def test_the_second_reviews_inputs_are_refused_naming_the_parameter(call, error, words):
    with pytest.raises(error, match=words):
        call()


def test_red_team_arguments_are_checked():
    from lfc.experiments import redteam
    with pytest.raises(ValueError, match="method must be one of"):
        redteam.Defender("x", method="nope")
    with pytest.raises(TypeError, match="n_seeds must be an integer"):
        redteam.Search(n_seeds="2")
    for found, words in (({}, "a dict with 'search'"),
                         ({"search": "sinusoid on P_c", "theta": (1.0,)},
                          r"found\['theta'\] must have shape \(2,\)"),
                         ({"search": "free-form on P_c"}, "a dict with 'values'")):
        with pytest.raises(ValueError, match=words):
            redteam.replay(found, 10.0)
    # a row of a table of results replays (notebook 08 passes one)
    import pandas as pd
    row = pd.DataFrame([{"search": "sinusoid on P_c", "theta": (0.5, 1.0)}]).iloc[0]
    assert redteam.replay(row, 10.0)["pc_attack"] == lfc.Sinusoid(0.5, 1.0, start=1.0)


def test_load_battery_arguments_are_checked():
    from lfc.experiments import load_during_attack as lda
    with pytest.raises(ValueError, match=r"instants must be times \(s\) in \[0, duration"):
        lda.battery(P, None, (0.1,), instants=[20.0], duration=2.0)
    with pytest.raises(TypeError, match="steps must be a non-empty sequence"):
        lda.battery(P, None, 0.1, instants=[1.5], duration=2.0)
    with pytest.raises(TypeError, match="bounds must be a non-empty sequence"):
        lda.bound_price(P, 0.1, (0.1,))


def test_samples_compare_by_their_values():
    """Every Samples compared equal (its fields were excluded from ==)."""
    a = lfc.Samples([0.0, 1.0], [1.0, 2.0])
    assert a == lfc.Samples([0.0, 1.0], [1.0, 2.0]) and hash(a) == hash(lfc.Samples([0, 1], [1, 2]))
    assert a != lfc.Samples([0.0, 1.0], [3.0, 4.0])


def test_a_step_stop_of_a_numpy_integer_is_a_number():
    assert lfc.Step(1.0, start=1.0, stop=np.int64(5))(4.0) == 1.0


def test_a_kalman_filter_exists_at_every_corner_or_says_why():
    """Every corner of the valid ranges (noise std 1e-9 and 100, period 1e-5 and
    1 s, load_std 0 and 100 with estimate_load, and without it) gives a finite gain
    or a ValueError that names the noise models: never a solver's exception."""
    import itertools

    from lfc.estimation import LOAD_STD, PERIOD, STD
    solved = 0
    for m0, m1, q, (ls, est), per in itertools.product(
            STD, STD, STD, ((0.0, True), (STD[1], True), (LOAD_STD, False)), PERIOD):
        try:
            k = lfc.KalmanFilter(P, meas_std=(m0, m1), process_std=q, load_std=ls,
                                 period=per, estimate_load=est)
        except ValueError as e:
            assert "no steady-state Kalman gain" in str(e) or "not observable" in str(e)
        else:
            assert np.isfinite(k.gain).all()
            solved += 1
    assert solved > 0


def test_noise_beyond_the_kalman_filters_range_is_refused_naming_the_noise():
    """noise_w=101 reached the Kalman filter and was refused as meas_std[0]: the
    user never wrote meas_std (found by the fuzz suite)."""
    with pytest.raises(ValueError, match=r"noise_std\[0\] must be 0 \(no noise\) or lie in"):
        lfc.simulate(P, duration=1.0, noise_std=(101.0, 0.0))
    with pytest.raises(ValueError, match="column 'noise_w' must be 0"):
        lfc.simulate_many(P, _row(noise_w=1e-12), duration=1.0)
    with pytest.raises(ValueError, match=r"noise_std\[1\] must be 0"):
        lfc.SafetyFilter(P, method="certified", noise_std=(1e-4, 1e3))


def test_a_fit_cache_is_kept_per_blas_kernel(monkeypatch, tmp_path):
    """A fit computed under OPENBLAS_CORETYPE=Haswell was read by a run under the
    default kernel (one cache file), which then differed from the regression
    record by 1e-11: each kernel keeps its own file."""
    pytest.importorskip("andes")
    from lfc.testbed.microgrid import MicrogridCase
    from lfc.testbed.fit import _cache_path
    monkeypatch.setenv("LFC_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("OPENBLAS_CORETYPE", raising=False)
    default = _cache_path(MicrogridCase())
    monkeypatch.setenv("OPENBLAS_CORETYPE", "Haswell")
    assert _cache_path(MicrogridCase()) != default


# -- the third hostile review --

def test_relay_settings_have_ranges_the_filters_can_compute_with():
    """rocof_limit=1e155 made the paper filter divide by zero, 1e60 flagged every
    valid call invalid_input; 10 pu/s (600 Hz/s) is "ROCOF off"."""
    for kw, words in ((dict(rocof_limit=1e155), r"rocof_limit must lie in \(0.0, 10.0\]"),
                      (dict(rocof_limit=0.0), "rocof_limit must lie in"),
                      (dict(of2=1.0), r"of2 must lie in \(1.0, 2.0\]"),
                      (dict(of2_delay=1e5), r"of2_delay must lie in \[0.0, 10000.0\]")):
        with pytest.raises(ValueError, match=words):
            lfc.RelaySettings(**kw)
    off = lfc.RelaySettings(rocof_limit=10.0, of2=2.0)
    for method in ("paper", "certified"):
        u, info = lfc.SafetyFilter(P, off, method=method).filter(np.zeros(5), 0.5)
        assert u == 0.5 and not info.alarm


def test_relays_of_a_falsy_value_are_refused_not_defaulted():
    from lfc.experiments.load_during_attack import battery
    with pytest.raises(TypeError, match="relays must be a RelaySettings or None, got 0"):
        lfc.simulate_many(P, _row(), duration=1.0, relays=0)
    with pytest.raises(TypeError, match="relays must be a RelaySettings or None"):
        battery(P, None, (0.1,), relays=0)


def test_a_filter_keeping_other_relay_thresholds_than_the_simulation_is_refused():
    """A certified filter built for 0.05 pu/s in a run whose ROCOF relay is set at
    0.02 tripped with no flag at all: its guarantee is for another safe set."""
    for plant, kw in ((P, {"scc": lfc.SafetyFilter(P, method="certified")}),
                      (TWO, {"filters": {0: lfc.SafetyFilter(TWO.areas[0])}})):
        with pytest.raises(ValueError, match="a trip would go unflagged"):
            lfc.simulate(plant, duration=1.0, relays=lfc.RelaySettings(rocof_limit=0.02), **kw)
    slow = lfc.RelaySettings(of2_delay=0.5)       # other delays, same thresholds: fine
    lfc.simulate(P, duration=1.0, relays=slow, scc=lfc.SafetyFilter(P))


def test_red_team_searches_check_their_plant_filters_and_noise_before_searching():
    """scipy's vectorized search turned any error in the objective into "The
    map-like callable must be of the form f(func, iterable)"."""
    from lfc.experiments import redteam
    d = redteam.Defender("p")
    with pytest.raises(TypeError, match="params must be an LFCParams"):
        redteam.family_search(TWO, d, "sinusoid on P_c", duration=2.0, maxiter=1, popsize=2)
    with pytest.raises(ValueError, match=r"noise_std\[0\] must be 0"):
        redteam.Search(noise_std=(1e-12, 0.0))
    for params, filters, kw, error, words in (
            (P, {}, {}, TypeError, "params must be a MultiAreaParams"),
            (TWO, ["paper"], {}, ValueError, "filters must be a dict"),
            (TWO, {5: "paper"}, {}, ValueError, "a key of filters"),
            (TWO, {"0": "paper"}, {}, TypeError, "a key of filters"),
            (TWO, {}, {"jobs": 0}, ValueError, "jobs must be an integer >= 1")):
        with pytest.raises(error, match=words):
            redteam.coordinated_search(params, filters, "bias on ACE", duration=2.0,
                                       maxiter=1, popsize=2, **kw)


def test_a_freeform_attack_runs_at_its_own_period_and_within_the_run():
    """control_period was not passed to the runs (20 ms values interpolated at 10
    ms), and a 5 s attack in a 2 s run reported 500 values."""
    from lfc.experiments import redteam
    with pytest.raises(ValueError, match="attack_duration .* must end within the run"):
        redteam.freeform_search(P, redteam.Defender("p"), attack_duration=5.0, duration=2.0,
                                maxiter=1, popsize=2)
    found = redteam.freeform_search(P, redteam.Defender("p"), attack_duration=0.1,
                                    control_period=0.02, duration=2.0, maxiter=1, popsize=2)
    replayed = lfc.simulate(P, duration=2.0, control_period=0.02,
                            scc=lfc.SafetyFilter(P), **redteam.replay(found, 2.0))
    assert found["severity"] == pytest.approx(float(redteam.severity(replayed.metrics(),
                                                                     lfc.RelaySettings())))


def test_no_scc_threshold_refuses_what_it_cannot_compute():
    from lfc.experiments.load_limits import governor_ride_through, no_scc_threshold
    with pytest.raises(ValueError, match=r"tol must lie in \[1e-09, 1.0\]"):
        no_scc_threshold(P, lfc.RelaySettings(), tol=1e-300)        # looped for ever
    with pytest.raises(ValueError, match="duration must be > 1 s"):
        no_scc_threshold(P, lfc.RelaySettings(), duration=0.5)      # "0.4 pu trips"
    with pytest.raises(ValueError, match="horizon must be a positive integer multiple"):
        governor_ride_through(P, lfc.RelaySettings(), 0.1, u_bound=1.0, horizon=0.005)
    with pytest.raises(ValueError, match="delay_periods must be an integer >= 0"):
        governor_ride_through(P, lfc.RelaySettings(), 0.1, u_bound=1.0, delay_periods=-3)


def test_scenario_tables_refuse_what_they_would_silently_ignore():
    import pandas as pd
    for kw, error, words in (
            (dict(k_i=0.0), ValueError, "'k_i' is an LFCParams field"),
            (dict(tau_w=0.1), ValueError, "'tau_w' is an LFCParams field"),
            (dict(m=0.5), ValueError, "did you mean 'M'"),
            (dict(Stop=0.6), ValueError, "did you mean 'stop'"),
            (dict(Alpha=3.0), ValueError, "did you mean 'alpha'"),
            (dict(waveform="samples", values="[0.1, 0.2]", sample_period=0.01), TypeError,
             "column 'values' must hold a non-empty sequence of numbers"),
            (dict(waveform="samples", values=0.5, sample_period=0.01), TypeError,
             "column 'values' must hold")):
        with pytest.raises(error, match=words):
            lfc.simulate_many(P, _row(**kw), duration=1.0, progress=False)
    seeds = _row(noise_w=1e-4).loc[[0, 0]].reset_index(drop=True)
    seeds["seed"] = pd.array([pd.NA, 1], dtype="Int64")
    with pytest.raises(ValueError, match="column 'seed' must be integers >= 0"):
        lfc.simulate_many(P, seeds, duration=1.0, progress=False)
    with pytest.raises(TypeError, match="executor must be a concurrent.futures.Executor"):
        lfc.simulate_many(P, _row(), duration=1.0, executor="threads")
    with pytest.warns(RuntimeWarning, match="1 row.* start their signal at or after the run's"):
        lfc.simulate_many(P, _row(start=1.5), duration=1.0, progress=False)
    # D = 0 is a valid plant (LFCParams allows it), so is a row with D = 0
    assert len(lfc.simulate_many(P, _row(D=0.0), duration=1.0, progress=False)) == 1


def test_a_results_table_fed_back_gets_its_metrics_recomputed_not_duplicated():
    once = lfc.simulate_many(P, _row(), duration=1.0, progress=False)
    twice = lfc.simulate_many(P, once, duration=1.0, progress=False)
    assert list(twice.columns) == list(once.columns)
    assert twice.equals(once)


def test_more_of_the_third_reviews_inputs_are_refused():
    from fractions import Fraction

    from lfc.filters import CertifiedOptions
    run = lfc.simulate(TWO, duration=1.0)
    cases = [
        (lambda: MultiAreaParams((P, P), tie=((0, 1, 2.0),), bias=(1e-300, 21.0)), ValueError,
         r"bias must be 2 numbers in \[1e-09"),
        (lambda: MultiAreaParams((P, P), tie=((0, 1, 2.0),), k_agc=(1e300, 0.1)), ValueError,
         r"k_agc must be 2 numbers in \[0"),
        (lambda: lfc.simulate(TWO, duration=1.0, feedforward="yes"), TypeError,
         r"^feedforward must be True or False"),
        (lambda: run.disturbance_step(5), ValueError, r"area must be an integer index in \[0, 1\]"),
        (lambda: run.disturbance_step(1.0), TypeError, "area must be an integer index"),
        (lambda: lfc.lfc_matrices(P, printed_droop_sign="no"), TypeError,
         "printed_droop_sign must be True or False"),
        (lambda: lfc.KalmanFilter(P).correct([1.0]), ValueError, r"y must have shape \(2,\)"),
        (lambda: lfc.KalmanFilter(P).correct([1.0, 2.0, 3.0]), ValueError, "y must have shape"),
        (lambda: lfc.KalmanFilter(P).correct([np.nan, 0.0]), ValueError, "y must be finite"),
        (lambda: lfc.KalmanFilter(P).predict([1, 2]), TypeError, "u must be a number"),
        (lambda: lfc.simulate(P, duration=1.0, pc_attack=lambda t: t * 1j), TypeError,
         "pc_attack must return real numbers"),
        (lambda: lfc.simulate(P, duration=1.0, pc_attack=lambda t: t > 0), TypeError,
         "pc_attack must return real numbers"),
        (lambda: lfc.simulate(P, duration=1.0, pc_attack=lambda t: t[:3]), ValueError,
         "pc_attack must return one value per time"),
        (lambda: lfc.simulate(P, duration=1.0007), ValueError,
         "duration must be a positive integer multiple of dt"),
        (lambda: lfc.simulate(P, duration=1.0).save(""), ValueError, "directory must be a "
         "folder path, not empty"),
        (lambda: lfc.simulate(P, duration=1.0).save(None), TypeError, "directory must be a "
         "folder path"),
        (lambda: CertifiedOptions(margin="0.1"), TypeError, "margin must be a number"),
        (lambda: CertifiedOptions(uncertainty="x"), TypeError, "uncertainty must be a number "
         "or a dict"),
    ]
    for call, error, words in cases:
        with pytest.raises(error, match=words):
            call()
    assert np.isfinite(lfc.KalmanFilter(P, np.float32(0.01)).gain).all()
    assert isinstance(LFCParams(M=Fraction(4, 1)).M, float)
    u, _ = lfc.SafetyFilter(LFCParams(M=Fraction(4, 1)), method="certified").filter(
        np.zeros(5), 0.0)
    assert u == 0.0


def test_relay_bank_surface_builders_and_cost_check_their_inputs():
    from lfc.experiments import surface
    from lfc.experiments.assess import load_step_cost
    bank = lfc.RelayBank(lfc.RelaySettings())
    cases = [
        (lambda: lfc.RelayBank(lfc.RelaySettings(), n=-1), ValueError, "n must be an integer"),
        (lambda: lfc.RelayBank(lfc.RelaySettings(), n=True), TypeError, "n must be an integer"),
        (lambda: lfc.RelayBank(None), TypeError, "settings must be a RelaySettings"),
        (lambda: bank.update([0.0, 0.2, 0.1, 0.3], [0.0] * 4, [0.0] * 4), ValueError,
         "t must be increasing"),
        (lambda: bank.update([0.0, 0.1], [0.0] * 3, [0.0] * 2), ValueError,
         "dw_meas must have shape"),
        (lambda: surface.attack_map([], [0.5], [1.0], [3.0]), TypeError, "waveforms must be"),
        (lambda: surface.attack_map("sinusoid", [0.5], [1.0], [3.0]), TypeError,
         "waveforms must be a non-empty list"),
        (lambda: surface.attack_map(["sinusoid"], [], [1.0], [3.0]), TypeError,
         "amplitudes must be a non-empty sequence"),
        (lambda: surface.bias_map(0.1, [3.0]), TypeError, "biases must be"),
        (lambda: load_step_cost(P, {"none": lambda q: None}, [0.1], duration=0.5), ValueError,
         "duration must be > ATTACK_START"),
        (lambda: lfc.filters.alarm_mask({}), ValueError, "flags must hold at least one"),
    ]
    for call, error, words in cases:
        with pytest.raises(error, match=words):
            call()
    assert len(surface.attack_map(["sinusoid"], [0.5], [1.0], [])) == 1    # no SCC only


def test_an_empty_table_has_the_metric_dtypes_of_a_full_one():
    import pandas as pd
    empty = lfc.simulate_many(P, _row().iloc[:0], duration=1.0, progress=False)
    full = lfc.simulate_many(P, _row(), duration=1.0, progress=False)
    assert (empty.dtypes == full.dtypes).all()
    assert isinstance(empty, pd.DataFrame) and len(empty) == 0


def test_small_public_helpers_name_their_bad_argument():
    from lfc.experiments import redteam
    cases = [
        (lambda: lfc.discretize(None, 0.1), TypeError, "params must be an LFCParams"),
        (lambda: lfc.multiarea_matrices(P), TypeError, "params must be a MultiAreaParams"),
        (lambda: redteam.severity({"max_abs_rocof_meas": 0.1, "max_abs_dw_meas": 0.0}, 0),
         TypeError, "relays must be a RelaySettings"),
        (lambda: lfc.filters.register(object), TypeError, "backend must be a Backend"),
        (lambda: lfc.SafetyFilter(P).check_period("x"), TypeError, "control_period must be"),
        (lambda: redteam.piecewise_attack_table(n=1, amplitude=1.0, duration=0.5, seed=0),
         ValueError, "duration must be finite and > ATTACK_START"),
        (lambda: redteam.piecewise_attack_table(n=1, amplitude=1.0, duration=2.0, seed=-1),
         ValueError, "seed must be an integer in \\[0, 2\\*\\*32\\)"),
    ]
    for call, error, words in cases:
        with pytest.raises(error, match=words):
            call()


@pytest.mark.parametrize("build, match", [
    (lambda: lfc.SafetyFilter(LFCParams(), method="certified", confidence=0.99),
     "confidence=0.99 has no effect without noise_std"),
    (lambda: lfc.SafetyFilter(LFCParams(), method="certified", noise_std=(1e-4, 1e-3),
                              relay_rate=10.0), "relay_rate=10.0 has no effect without "
                                                "trips_per_hour"),
    (lambda: lfc.KalmanFilter(LFCParams(), estimate_load=False, load_std=0.1),
     "load_std=0.1 has no effect with estimate_load=False"),
    (lambda: lfc.simulate(LFCParams(), duration=0.1, load_feedforward=True),
     "load_feedforward=True .* needs scc and estimator=None"),
    (lambda: lfc.simulate(LFCParams(), duration=0.1, load_feedforward=True, estimator="kalman",
                          scc=lfc.SafetyFilter(LFCParams())), "needs scc and estimator=None"),
])
def test_an_option_that_would_have_no_effect_is_refused(build, match):
    """Third review: these were accepted and silently did nothing."""
    with pytest.raises(ValueError, match=match):
        build()


def test_red_team_settings_that_would_be_dropped_are_refused():
    from lfc.experiments.redteam import Defender, Search
    with pytest.raises(ValueError, match="method 'none' does not read alpha"):
        Defender("x", method="none", alpha=5.0)
    with pytest.raises(ValueError, match="method 'paper' does not read uncertainty, "
                                         "declare_noise"):
        Defender("x", uncertainty=0.2, declare_noise=True)
    with pytest.raises(ValueError, match="method 'certified' does not read Ts"):
        Defender("x", method="certified", Ts=0.5)
    with pytest.raises(ValueError, match="n_seeds=4 needs noise_std > 0"):
        Search(n_seeds=4)
    assert Defender("x", method="certified", uncertainty=0.2, declare_noise=True).columns()[
        "uncertainty"] == 0.2
    assert Search(noise_std=(1e-4, 1e-3), n_seeds=4).bounds() == [(0, 3)]


def test_samples_columns_on_other_rows_are_refused():
    rows = pd.DataFrame([dict(waveform="samples", channel="pc", amplitude=0.0, freq_hz=0.0,
                              start=1.0, alpha=np.nan, Ts=0.25, values=[0.1, 0.2],
                              sample_period=0.01),
                         dict(waveform="step", channel="pc", amplitude=0.1, freq_hz=0.0,
                              start=1.0, alpha=np.nan, Ts=0.25, values=None,
                              sample_period=np.nan)])
    assert len(lfc.simulate_many(LFCParams(), rows, duration=2.0, progress=False)) == 2
    for col, value in (("sample_period", 0.01), ("values", [0.3])):
        bad = rows.copy()
        bad[col] = bad[col].astype(object)
        bad.at[1, col] = value
        with pytest.raises(ValueError, match=f"column '{col}' has no meaning for a 'step' row"):
            lfc.simulate_many(LFCParams(), bad, duration=2.0, progress=False)


def test_the_sweep_helps_examples_parse_into_their_grids():
    """``python -m lfc sweep --help`` ends with two examples; each is a valid command
    (the notebook exists, its parameters are the notebook's)."""
    import json
    import re
    import shlex
    from pathlib import Path

    from lfc.repro import cli
    parser = cli._parser()
    sweep = parser._subparsers._group_actions[0].choices["sweep"]
    text = sweep.epilog.replace("\\\n", " ")
    examples = re.findall(r"python -m lfc (sweep .*)", text)
    grids = [{"alpha": [3, 20], "amplitude": [0.3, 0.5, 1.0]}, {"load_step": [0.05, 0.1, 0.2]}]
    assert len(examples) == 2
    root = Path(__file__).resolve().parents[1]
    for example, grid in zip(examples, grids):
        args = parser.parse_args(shlex.split(example))
        assert cli._grid(args.param) == grid
        nb = json.loads((root / args.notebook).read_text())
        source = "".join(next(c for c in nb["cells"] if "parameters" in c["metadata"].get(
            "tags", []))["source"])
        assert all(f"\n{name} = " in "\n" + source for name in grid)


def test_a_refused_filter_leaves_the_scenarios_as_they_were():
    """The relays and period of a filter are checked once, when a scenario first
    names it, and a scenario's areas are kept only once all of them pass: a
    refused scenario (its second area's filter keeps other relays, or its second
    area's attack is not a signal) adds no row, noise or samples, and the next
    one runs as if it had never been tried."""
    from lfc.scenarios import Scenarios
    other = lfc.SafetyFilter(TWO.areas[1], lfc.RelaySettings(rocof_limit=0.02))
    good = lfc.SafetyFilter(TWO.areas[0])
    sc = Scenarios(TWO, duration=1.0, dt=1e-3, control_period=0.01,
                   relays=lfc.RelaySettings())
    with pytest.raises(ValueError, match="the filter of area 1 .* a trip would go unflagged"):
        sc.add(filters={0: good, 1: other}, attacks={0: {"pc": lfc.Step(0.3, start=0.1)}})
    with pytest.raises(ValueError, match="pc_attack must be a callable"):   # area 1's signal
        sc.add(filters={0: good}, attacks={0: {"pc": lfc.Samples([0.1, 0.2], [0.3, 0.3])},
                                           1: {"pc": "0.3"}}, noise_std=(1e-4, 1e-3))
    assert sc._filters.items == [good] and sc._rows == [] and sc._sig == []
    assert sc._noise == [] and sc._st == [] and sc._n_samples == 0
    row = sc.add(filters={0: good}, attacks={0: {"pc": lfc.Step(0.3, start=0.1)}})
    alone = lfc.simulate(TWO, duration=1.0, filters={0: good},
                         attacks={0: {"pc": lfc.Step(0.3, start=0.1)}})
    run = sc.run()
    assert row == 0 and run.metrics.shape[0] == 1
    assert alone.metrics()[0]["alarms"] == run.metrics[0, 0, 5] == 7   # the filter acted


# -- a fuzz pass of 2026-11-27: each input below misbehaved (a silent wrong answer, a
# crash other than ValueError / TypeError, a filter raising or a damaged file read) --
def test_seeds_the_relay_noise_cannot_tell_apart_are_refused():
    """The relays' noise generator keeps 32 bits of the seed: seeds 5 and 5 + 2**32
    gave the same relay noise.  Every seed is now in [0, 2**32)."""
    run = dict(duration=0.2, noise_std=(1e-3, 0.04), relay_noise=True)
    lfc.simulate(LFCParams(), seed=2 ** 32 - 1, **run)
    for seed in (2 ** 32, 5 + 2 ** 32, -1):
        with pytest.raises(ValueError, match=r"seed must be an integer in \[0, 2\*\*32\)"):
            lfc.simulate(LFCParams(), seed=seed, **run)
    from lfc.wire import run_wire
    with pytest.raises(ValueError, match=r"seed must be an integer in \[0, 2\*\*32\)"):
        run_wire(LFCParams(), duration=0.1, seed=-1, noise_std=(1e-4, 1e-3))


def test_an_integer_too_large_for_a_float_is_refused_by_name_or_flagged():
    huge = 10 ** 400
    for make, name in ((lambda: LFCParams(D=huge), "D"), (lambda: lfc.Step(huge), "value"),
                       (lambda: lfc.simulate(LFCParams(), duration=huge), "duration")):
        with pytest.raises(ValueError, match=f"{name} must be a finite number"):
            make()
    u, info = lfc.SafetyFilter(LFCParams()).filter(np.zeros(5), huge)   # never raises
    assert u == 0.0 and info.invalid_input


def test_the_coupled_filter_checks_its_call_and_refuses_a_grid_without_ties():
    from lfc.filters.coupled import INVALID, CoupledFilter, CoupledOptions
    with pytest.raises(ValueError, match="needs a connected grid"):
        lfc.simulate(MultiAreaParams(TWO.areas), duration=0.2,
                     filters={0: "coupled", 1: "coupled"})
    cf = CoupledFilter(TWO, lfc.RelaySettings())
    x, two = np.zeros(TWO.n_states), np.zeros(2)
    with pytest.raises(TypeError, match=r"area must be an integer index in \[0, 1\], got True"):
        cf.filter(x, two, two, True, 0.1, np.zeros(2))
    with pytest.raises(TypeError, match="u_ref must be a number, got '0.5'"):
        cf.filter(x, two, two, 0, "0.5", np.zeros(2))
    with pytest.raises(TypeError, match="x must hold real numbers"):
        cf.filter(["0"] * TWO.n_states, two, two, 0, 0.1, np.zeros(2))
    for memory in (np.array([np.nan, 0.0]), np.zeros(0), np.zeros(2, int)):
        with pytest.raises(ValueError, match="memory must be a writable float64 array"):
            cf.filter(x, two, two, 0, 0.1, memory)      # it held a NaN command, or wrote past
    u, flags, reason = cf.filter(x, two, two, 0, 10 ** 400, np.zeros(2))
    assert u == 0.0 and flags & INVALID and reason.startswith("invalid input")
    with pytest.raises(TypeError, match="margin must be a number"):
        CoupledOptions(margin="0.1")


def test_a_command_the_filter_cannot_read_counts_no_modification():
    """A command of 1.7e308 (invalid input: held) gave a mean modification of inf
    and a maximum of 1.7e308; the row of simulate_many and simulate agree on 0."""
    P = LFCParams()
    for attack in (lfc.Step(1.7e308, start=0.5), lfc.Sinusoid(1.0, 1e308)):
        m = lfc.simulate(P, duration=1.0, pc_attack=attack, scc=lfc.SafetyFilter(P)).metrics()
        assert m["max_abs_modification"] == m["mean_abs_modification"] == 0.0
        assert m["alarms"] > 0
    row = pd.DataFrame([dict(waveform="step", channel="pc", amplitude=1.7e308, freq_hz=0.0,
                             start=0.5, alpha=20.0, Ts=0.25)])
    out = lfc.simulate_many(P, row, duration=1.0, progress=False).iloc[0]
    assert out.max_abs_modification == out.mean_abs_modification == 0.0


def test_scenario_tables_refuse_repeated_columns_and_strings_in_contract_columns():
    P = LFCParams()
    base = dict(waveform="sinusoid", channel="pc", amplitude=1.0, freq_hz=1.0, start=1.0,
                alpha=20.0, Ts=0.25)
    twice = pd.DataFrame([list(base.values()) + [2.0]], columns=[*base, "freq_hz"])
    with pytest.raises(ValueError, match=r"column\(s\) \['freq_hz'\] more than once"):
        lfc.simulate_many(P, twice, duration=0.1, progress=False)
    for name, value in (("half_width", "0.01"), ("rate", True)):
        row = pd.DataFrame([{**base, "method": "contract", name: value}])
        with pytest.raises(TypeError, match=f"column '{name}' must hold numbers"):
            lfc.simulate_many(P, row, duration=0.1, progress=False)


def test_a_grids_result_and_estimate_name_what_is_wrong():
    with pytest.raises(ValueError, match="directory must be a folder path, not empty"):
        lfc.simulate(TWO, duration=0.1).save("")
    with pytest.raises(TypeError, match="noise_std must be a pair of numbers"):
        lfc.simulate(TWO, duration=0.2, estimator="kalman", noise_std=1e-3)


def test_a_damaged_store_whose_payload_is_not_text_is_computed_again(tmp_path):
    import json

    from lfc._files import STORED_FORMAT, read_stored
    path = tmp_path / "stored.json"
    for payload in (1, None):
        path.write_text(json.dumps({"format": STORED_FORMAT, "payload": payload,
                                    "sha256": "x"}))
        with pytest.warns(RuntimeWarning, match="damaged cache file"):
            assert read_stored(path, lambda d: d) is None


def test_a_malformed_frame_is_not_a_command_and_never_stops_the_generator():
    """A write cut short, or of fewer registers, raised struct.error or IndexError,
    in the relay and in the generator's outstation (its loop would stop); now it is
    not a command (the generator side counts it as one that did not arrive)."""
    import struct

    from lfc.wire import modbus, registers
    good = struct.pack(">HHHBBHHB", 1, 0, 7 + 26, 1, 16, 0, 13, 26) + b"\x00" * 26
    assert modbus.Codec.command(good) == ({"pc": 0.0, "wref": 0.0, "ace": 0.0}, 0)
    short = struct.pack(">HHHBBHHB", 1, 0, 13, 1, 16, 0, 3, 6) + b"\x00" * 6
    report = struct.pack(">HHHBBB", 1, 0, 3 + 48, 1, 4, 48) + b"\x00" * 10
    assert modbus.Codec.command(good[:20]) is modbus.Codec.command(short) is None
    assert modbus.Codec.report(report) is None
    for regs in ([0] * 5, [70000] + [0] * 12, [-1] + [0] * 12):
        assert registers.read_command(regs) is None
    assert registers.read_report([0] * 5) is None
    station = modbus.Outstation()
    station.inbox = ([0, 0, 0, 0], 0.0)
    assert station.take() is None


@pytest.mark.parametrize("protocol", ["modbus", "dnp3"])
def test_the_wire_refuses_a_setpoint_that_would_overflow_the_plant(protocol):
    """A 1e308 pu bias injected in the frames once made the plant non-finite (the run
    then refused, as simulate does); the outstation now refuses the setpoint with its
    protocol's range error (issue "Field"): the generator holds its last command, the
    plant stays finite and the run lists every refusal."""
    from lfc.wire import run_wire
    bias = [{"op": "bias", "field": "pc", "value": 1e308}] * 2
    run = run_wire(LFCParams(), duration=0.2, attack=bias, protocol=protocol)
    assert np.isfinite(run.sim.trace[["dw", "rocof_meas"]].to_numpy()).all()
    assert len(run.rejected) == len(run.exchanges) == 20 and run.exchanges.link.all()
    assert run.rejected.reason.str.contains("not a finite value within").all()
