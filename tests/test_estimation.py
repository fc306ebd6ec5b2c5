import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lfc import KalmanFilter, LFCParams, Sinusoid, Step, simulate

P = LFCParams()


def test_estimates_track_true_measurements_under_noise():
    r = simulate(P, duration=10, pc_attack=Sinusoid(0.2, 1.0, start=1), load=Step(0.05, start=4),
                 estimator="kalman", noise_std=(1e-4, 1e-3), seed=3)
    truth = r.trace.set_index("t").loc[r.controls.t]
    err_w = np.abs(r.controls.dw_hat.to_numpy() - truth.dw_meas.to_numpy())
    err_v = np.abs(r.controls.rocof_hat.to_numpy() - truth.rocof_meas.to_numpy())
    assert np.sqrt(np.mean(err_w**2)) < 1e-4      # below the 1e-4 pu sensor noise
    assert np.sqrt(np.mean(err_v**2)) < 1e-3      # below the 1e-3 pu/s sensor noise


def test_load_state_converges_to_the_step():
    r = simulate(P, duration=6, load=Step(0.1, start=1), estimator="kalman",
                 noise_std=(1e-4, 1e-3))
    late = r.controls[r.controls.t > 3].p_load_hat
    assert late.mean() == pytest.approx(0.1, abs=0.01)


def test_without_load_state():
    kf = KalmanFilter(P, 0.01, estimate_load=False)
    assert kf.n == 5
    r = simulate(P, duration=2, load=Step(0.05, start=1), estimator=kf)
    assert (r.controls.p_load_hat == 0).all()


def test_converged_gain_is_stable():
    kf = KalmanFilter(P)
    closed = (np.eye(kf.n) - kf.gain @ kf.C) @ kf.A
    assert np.max(np.abs(np.linalg.eigvals(closed))) < 1


@pytest.mark.parametrize("kwargs, name", [
    ({"period": 0}, "period"), ({"meas_std": (0, 1e-3)}, r"meas_std\[0\]"),
    ({"meas_std": (1e-4,)}, "meas_std"), ({"process_std": -1}, "process_std"),
    ({"load_std": -1}, "load_std")])
def test_bad_parameters(kwargs, name):
    with pytest.raises(ValueError, match=name):
        KalmanFilter(P, **kwargs)


@settings(max_examples=200, deadline=None)
@given(st.floats(1e-6, 1 - 1e-9), st.integers(1, 10**7))
def test_a_runs_confidence_is_the_union_bound_and_its_inverse_never_falls_short(run, n):
    """``run_confidence`` is ``1 - n (1 - confidence)`` (at least 0);
    ``confidence_for_run`` its inverse, rounded so the run's figure is never below
    what was asked."""
    from lfc.estimation import confidence_for_run, run_confidence
    c = confidence_for_run(run, n)
    assert run <= run_confidence(c, n) <= run + 1e-6
    assert run_confidence(0.9999, 2000) == pytest.approx(0.8)
    assert run_confidence(0.9999, 20_000) == 0.0


def test_a_runs_confidence_refuses_what_is_not_a_probability():
    from lfc.estimation import confidence_for_run, run_confidence
    for bad in (0.0, 1.0, -0.1, float("nan")):
        with pytest.raises(ValueError, match="confidence must lie in"):
            run_confidence(bad, 10)
        with pytest.raises(ValueError, match="run must lie in"):
            confidence_for_run(bad, 10)
    with pytest.raises(ValueError, match="certifications"):
        run_confidence(0.5, 0)
