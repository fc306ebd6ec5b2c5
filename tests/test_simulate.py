import json

import numpy as np
import pytest

from lfc import KalmanFilter, LFCParams, Samples, SafetyFilter, Sinusoid, Step, simulate
from lfc.result import ALARM_COLUMNS, METRIC_KEYS

P = LFCParams()


def test_equilibrium_stays_put():
    r = simulate(P, duration=2)
    assert (r.trace.drop(columns=["t", "h_freq", "h_rocof"]).to_numpy() == 0).all()
    assert r.trace[["h_freq", "h_rocof"]].isna().all().all()   # no filter, no barrier
    assert r.metrics() == {"tripped": False, "first_trip_relay": None, "first_trip_t": None,
                           "max_abs_dw_meas": 0.0, "max_abs_rocof_meas": 0.0,
                           "scc_active_fraction": 0.0, "max_abs_modification": 0.0,
                           "mean_abs_modification": 0.0, "alarms": 0,
                           "final_abs_dw_meas": 0.0, "outside": 0}


def test_trace_grid_and_command_hold():
    r = simulate(LFCParams(k_i=0.0), duration=1.0, pc_attack=Sinusoid(0.2, 1.0), dt=1e-3,
                 control_period=0.01)
    assert len(r.trace) == 1001 and r.trace.t.iloc[-1] == pytest.approx(1.0)
    assert len(r.controls) == 100
    pc = r.trace.pc.to_numpy()[:1000].reshape(100, 10)
    assert (pc == pc[:, :1]).all()                      # held over each control period
    np.testing.assert_allclose(pc[:, 0], Sinusoid(0.2, 1.0)(r.controls.t.to_numpy()))


def test_steady_state_of_load_step_matches_dc_gain():
    """Without integral action: dw = -dPL / (D + 1/R)."""
    r = simulate(LFCParams(k_i=0.0), duration=20, load=Step(0.1))
    assert r.trace.dw.iloc[-1] == pytest.approx(-0.1 / (P.D + 1 / P.droop), rel=1e-6)


def test_integral_action_restores_frequency():
    r = simulate(P, duration=60, load=Step(0.1, start=1))
    assert abs(r.trace.dw.iloc[-1]) < 2e-4
    assert r.controls.pc.iloc[-1] == pytest.approx(0.1, abs=5e-3)


def test_wref_attack_moves_frequency_reference():
    r = simulate(P, duration=80, wref_attack=Step(0.01))
    assert r.trace.dw.iloc[-1] == pytest.approx(0.01, abs=2e-4)


def test_stop_on_trip_truncates_at_trip():
    full = simulate(P, duration=5, pc_attack=Sinusoid(1.0, 1.0, start=1))
    stop = simulate(P, duration=5, pc_attack=Sinusoid(1.0, 1.0, start=1), stop_on_trip=True)
    t_trip = full.first_trip["t"]
    assert stop.first_trip == full.first_trip
    assert stop.trace.t.iloc[-1] == pytest.approx(t_trip)
    assert len(stop.trips) == 1 and len(full.trips) > 1
    np.testing.assert_array_equal(stop.trace.rocof_meas, full.trace.rocof_meas[:len(stop.trace)])


def test_continuity_records_every_trip():
    r = simulate(P, duration=6, pc_attack=Sinusoid(1.0, 1.0, start=1))
    assert (r.trips.relay == "ROCOF").sum() >= 8   # two per cycle, every cycle


def test_alarms_log_every_intervention():
    scc = SafetyFilter(P)
    r = simulate(P, duration=5, pc_attack=Sinusoid(0.5, 1.0, start=1), scc=scc)
    assert list(r.alarms.columns) == list(ALARM_COLUMNS)
    assert r.metrics()["alarms"] == len(r.alarms) >= r.controls.scc_active.sum() > 0
    active = r.controls[r.controls.scc_active]
    assert set(active.t) <= set(r.alarms.t)
    row = r.alarms.iloc[0]
    assert row.u != row.u_ref and row.t >= 1.0 and row.reason


def test_save_writes_everything(tmp_path):
    r = simulate(P, duration=2, pc_attack=Sinusoid(0.5, 1.0), scc=SafetyFilter(P))
    out = r.save(tmp_path / "run")
    metrics = json.loads((out / "metrics.json").read_text())
    assert tuple(metrics) == METRIC_KEYS and metrics == r.metrics()
    for name in ("trace", "controls", "trips", "alarms"):
        assert (out / f"{name}.csv").exists()
    assert json.loads((out / "settings.json").read_text())["params"]["M"] == 4.0


def test_noise_is_seeded():
    kw = dict(duration=2, pc_attack=Sinusoid(0.3, 1.0), scc=SafetyFilter(P),
              estimator="kalman", noise_std=(1e-4, 1e-3))
    a, b, c = simulate(P, seed=1, **kw), simulate(P, seed=1, **kw), simulate(P, seed=2, **kw)
    assert a.trace.equals(b.trace)
    assert not a.controls.dw_hat.equals(c.controls.dw_hat)


def test_samples_replay_equals_the_signal():
    t = np.arange(0, 3.001, 0.01)
    sig = Sinusoid(0.3, 1.0, start=0.5)
    a = simulate(P, duration=3, pc_attack=sig)
    b = simulate(P, duration=3, pc_attack=Samples(t, sig(t)))
    np.testing.assert_allclose(a.trace.dw, b.trace.dw, atol=1e-12)


def test_load_feedforward_reaches_the_scc():
    scc = SafetyFilter(P)
    r = simulate(P, duration=3, load=Step(0.1, start=1), scc=scc, load_feedforward=True)
    assert r.controls.p_load_hat.iloc[-1] == 0.1
    r = simulate(P, duration=3, load=Step(0.1, start=1), scc=scc)
    assert (r.controls.p_load_hat == 0).all()


@pytest.mark.parametrize("kwargs, name", [
    ({"duration": 0}, "duration"), ({"duration": -1}, "duration"),
    ({"duration": 1, "dt": 0}, "dt"), ({"duration": 1, "control_period": 0.0105}, "control_period"),
    ({"duration": 1, "control_period": 0.0005}, "control_period"),
    ({"duration": 1, "noise_std": (-1, 0)}, "noise_std"),
    ({"duration": 1, "noise_std": (0,)}, "noise_std"),
    ({"duration": 1, "estimator": "particle"}, "estimator"),
    ({"duration": 1, "estimator": KalmanFilter(P, 0.02)}, "period"),
    ({"duration": 1, "pc_attack": 0.3}, "pc_attack"),
    ({"duration": 1, "load": lambda t: np.nan * t}, "load"),
])
def test_bad_arguments(kwargs, name):
    with pytest.raises(ValueError, match=name):
        simulate(P, **kwargs)
