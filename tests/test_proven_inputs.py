"""Inputs that used to loosen a certified limit silently (issue "Proven", items 4-5):
each is now refused with a ValueError naming the parameter and its valid range."""

from __future__ import annotations

import math

import numpy as np
import pytest

import lfc
from lfc import LFCParams, SafetyFilter, Sinusoid
from lfc.estimation import KalmanFilter

P = LFCParams()


@pytest.mark.parametrize("noise_std, match", [
    ((-1e-4, 1e-3), r"noise_std\[0\] must be a finite number > 0"),
    ((math.nan, 1e-3), r"noise_std\[0\] must be a finite number > 0"),
    ((1e-4, 0.0), r"noise_std\[1\] must be a finite number > 0"),
    ((1e-4, 1e-3, 1e-3), "noise_std must be None or a pair"),
    (1e-4, "noise_std must be None or a pair"),
])
def test_noise_std_that_would_loosen_the_bound_is_refused(noise_std, match):
    with pytest.raises(ValueError, match=match):
        SafetyFilter(P, method="certified", noise_std=noise_std)


def test_trips_per_hour_at_one_per_relay_sample_is_refused():
    """At ``relay_rate * 3600`` per hour the union bound's quantile is 0 and above it
    negative: the limits would widen.  The range is (0, 3600 relay_rate)."""
    with pytest.raises(ValueError, match=r"trips_per_hour must lie in \(0.0, 3600000.0\)"):
        SafetyFilter(P, method="certified", noise_std=(1e-4, 1e-3), trips_per_hour=3.6e6)
    with pytest.raises(ValueError, match="trips_per_hour"):
        SafetyFilter(P, method="certified", noise_std=(1e-4, 1e-3), relay_rate=10.0,
                     trips_per_hour=1e5)
    ok = SafetyFilter(P, method="certified", noise_std=(1e-4, 1e-3), trips_per_hour=1.0)
    assert ok.options.trips_per_hour == 1.0


@pytest.mark.parametrize("limits", [{"u_min": 0.1}, {"u_max": -0.1}])
def test_actuator_limits_must_contain_the_equilibrium_command(limits):
    """The filter starts by holding 0: with 0 outside [u_min, u_max] it would start
    outside its own limits."""
    with pytest.raises(ValueError, match="u_min <= 0 <= u_max"):
        SafetyFilter(P, method="certified", **limits)


def test_a_box_with_an_unstable_corner_is_refused():
    """±60 % of the default plant reaches unstable corners (light M, slow turbine):
    accepted before, it then flagged ``outside`` at every call."""
    with pytest.raises(ValueError, match="uncertainty: the plant .* is unstable"):
        SafetyFilter(P, method="certified", uncertainty=0.6)


def test_extreme_parameters_give_a_value_error_not_a_solver_runtime_error():
    with pytest.raises(ValueError):
        SafetyFilter(LFCParams(M=1e-9), method="certified")


@pytest.mark.parametrize("period", [0.02, 0.05])
def test_the_covariance_uses_the_filters_control_period(period):
    """The estimation bound is the Kalman filter's at the period the filter is
    called (it was the 10 ms one whatever the period: 26-29 % too small at 50 ms)."""
    f = SafetyFilter(P, method="certified", noise_std=(1e-4, 1e-3), control_period=period)
    kf = KalmanFilter(P, period, meas_std=(1e-4, 1e-3))
    from lfc.filters.certified import _estimate_covariance
    assert np.array_equal(_estimate_covariance(P, (1e-4, 1e-3), period),
                          kf.posterior_covariance)
    f10 = SafetyFilter(P, method="certified", noise_std=(1e-4, 1e-3))
    # a longer period: a larger error, so tighter limits (a smaller certified interval)
    x = np.array([0.0, 0.0, 0.0, 0.0, 0.0])
    lo, hi = f.filter(x, 10.0)[1].details["interval"]
    lo10, hi10 = f10.filter(x, 10.0)[1].details["interval"]
    assert hi < hi10 and lo > lo10


def test_a_simulation_refuses_a_filter_built_for_another_control_period():
    f = SafetyFilter(P, method="certified")          # control_period 0.01 s
    with pytest.raises(ValueError, match=r"built for control_period=0.01 s .* every 0.05 s"):
        lfc.simulate(P, duration=1.0, dt=1e-3, control_period=0.05, scc=f,
                     pc_attack=Sinusoid(0.5, 1.0))
    f50 = SafetyFilter(P, method="certified", control_period=0.05)
    res = lfc.simulate(P, duration=1.0, dt=1e-3, control_period=0.05, scc=f50,
                       pc_attack=Sinusoid(0.5, 1.0))
    assert not res.metrics()["tripped"]


def test_a_batch_builds_its_certified_filters_for_its_control_period():
    import pandas as pd
    rows = pd.DataFrame({"waveform": "sinusoid", "channel": "pc", "amplitude": [0.8],
                         "freq_hz": [1.0], "start": 1.0, "alpha": 3.0, "Ts": 0.25,
                         "method": "certified", "noise_w": 1e-4, "noise_rocof": 1e-3,
                         "declare_noise": True})
    out = lfc.simulate_many(P, rows, duration=3.0, control_period=0.05, dt=1e-3,
                            progress=False)
    assert not bool(out["tripped"].iloc[0])


@pytest.mark.parametrize("x, u, p, match", [
    (np.zeros((3, 5)), np.zeros(2), None, "same length"),
    (np.zeros((3, 5)), np.zeros(3), np.zeros(4), "same length"),
    (np.zeros(10), np.zeros(2), None, r"shape \(N, 5\)"),
    (np.zeros((2, 4)), np.zeros(2), None, r"shape \(N, 5\)"),
])
def test_filter_batch_checks_its_array_lengths(x, u, p, match):
    for method in ("paper", "certified"):
        with pytest.raises(ValueError, match=match):
            SafetyFilter(P, method=method).filter_batch(x, u, p)


def test_filter_batch_takes_one_state_as_a_batch_of_one():
    u, _ = SafetyFilter(P).filter_batch(np.zeros(5), [0.5])
    assert u.shape == (1,)
