"""The certified filter: its guarantee on the design model, its cvxpy reference,
its assumptions' edges, and bad input."""

import ast
import math

import numpy as np
import pandas as pd
import papermill
import pytest
import tiers
from hypothesis import example, given, settings
from hypothesis import strategies as st

import lfc
from lfc.experiments.redteam import piecewise_attack_table
from lfc.experiments.surface import attack_map, bias_map
from lfc.filters.certified import CertifiedSet
from lfc.filters.cvxpy_certified import cvxpy_certified
from lfc.model import block_propagator, discretize
from lfc.repro import runner

P, RELAYS = lfc.LFCParams(), lfc.RelaySettings()
CERT = lfc.SafetyFilter(P, RELAYS, method="certified")
STATE_SCALE = np.array([0.2, 0.2, 0.01, 0.01, 0.02])


AD, BD = discretize(P, 1e-3)
AD100 = np.linalg.matrix_power(AD, 100)


def held_outputs(x: np.ndarray, u: float, seconds: float = 30.0) -> np.ndarray:
    """Measured outputs at every 1 ms sample when ``u`` is held from state ``x``:
    blocks of 100 samples, each from its block's start state."""
    Phi, Gu, _ = block_propagator(AD, BD, 100)
    out = []
    for _ in range(int(seconds / 0.1)):
        block = (Phi @ x + Gu * u).reshape(100, 5)
        out.append(block[:, 3:5])
        x = block[-1]
    return np.vstack(out)


@settings(max_examples=tiers.examples(60), deadline=None)
@given(z=st.lists(st.floats(-3, 3), min_size=5, max_size=5), u_ref=st.floats(-2, 2))
@example(z=[0.0, 0.0, 0.0, 0.0, 2.484375], u_ref=0.0)   # hold: found by CI
def test_a_certified_command_held_forever_keeps_the_relays_quiet(z, u_ref):
    x = np.array(z) * STATE_SCALE
    CERT.reset()                    # each example starts with 0 as the last certified command
    u, info = CERT.filter(x, u_ref)
    if info.outside:
        return  # nothing certified from this state: covered by the next test
    y = held_outputs(x, u)
    assert np.all(np.abs(y[:, 0]) <= RELAYS.F) and np.all(np.abs(y[:, 1]) <= RELAYS.rocof_limit)
    lo, hi = info.details["interval"]
    if lo > hi:             # no new command certified: the last one (0) passed its own check
        assert u == 0.0 and info.active == (u_ref != 0.0)
        return
    assert u == min(max(u_ref, lo), hi)
    assert min(info.margin_freq, info.margin_rocof) >= -1e-12   # u inside each relay's interval


def test_from_equilibrium_every_run_keeps_a_certificate():
    r = lfc.simulate(P, duration=20.0, pc_attack=lfc.Square(2.0, 0.3, start=1.0), scc=CERT)
    assert not r.metrics()["tripped"] and not r.alarms.outside.any()


@pytest.mark.parametrize("options, n", [({}, 25), ({"uncertainty": {"M": (0.8, 1.2)}}, 8)])
def test_exact_answer_equals_the_cvxpy_formulation(options, n):
    """The compiled interval against the definition in cvxpy, on the design model
    and on a box (its corners' constraints all at once), with a load."""
    filt = lfc.SafetyFilter(P, RELAYS, method="certified", u_min=-1.0, u_max=1.5, **options)
    cert = filt.cert
    rng = np.random.default_rng(7)
    states = rng.normal(size=(n, 5)) * STATE_SCALE
    refs = rng.normal(scale=0.8, size=n)
    loads = rng.uniform(-0.1, 0.1, size=n)
    n_certified = 0
    for x, u_ref, p in zip(states, refs, loads):
        filt.reset()
        lo, hi = filt.filter(x, u_ref, p_load=p)[1].details["interval"]
        reference = cvxpy_certified(cert, x, u_ref, p)
        if lo > hi:
            assert reference is None
            continue
        n_certified += 1
        assert min(max(u_ref, lo), hi) == pytest.approx(reference, abs=1e-7)
    assert n_certified >= 0.6 * n


def test_scalar_and_batch_agree():
    rng = np.random.default_rng(3)
    states, refs = rng.normal(size=(200, 5)) * STATE_SCALE, rng.normal(size=200)
    batch = lfc.SafetyFilter(P, RELAYS, method="certified")
    u_b, flags = batch.filter_batch(states, refs)
    scalar = lfc.SafetyFilter(P, RELAYS, method="certified")
    for i in range(200):
        scalar.reset()
        u, info = scalar.filter(states[i], refs[i])
        assert u == pytest.approx(u_b[i], abs=1e-12)
        assert info.outside == flags["outside"][i] and info.active == flags["active"][i]


def surface_defaults() -> dict:
    """The default grid of notebooks/06_attack_surface.ipynb (its parameters cell)."""
    found = papermill.inspect_notebook(str(runner.NOTEBOOKS_DIR / runner.FIGURES["surface"]))
    return {k: ast.literal_eval(v["default"]) for k, v in found.items()}


def test_no_trip_over_the_whole_attack_surface_grid():
    """Every attack of the sweeps issue's maps (periodic attacks on P_c and biases on
    ω_ref, 30 s each, the notebook's defaults) plus amplitudes up to 3 pu."""
    d = surface_defaults()
    grid = pd.concat([attack_map(d["waveforms"], d["amplitudes"] + [2.0, 3.0], d["freqs"],
                                 alphas=[1.0]),
                      bias_map(d["biases"], [1.0])], ignore_index=True)
    grid = grid[grid.alpha.notna()].assign(method="certified")
    res = lfc.simulate_many(P, grid, duration=d["duration"], chunk_size=200, progress=False)
    assert len(res) == 2 * 16 * 11 + 15
    assert not res.tripped.any()
    assert res.max_abs_rocof_meas.max() <= RELAYS.rocof_limit
    assert res.max_abs_dw_meas.max() <= RELAYS.F


def test_no_trip_on_seeded_red_team_attacks():
    table = piecewise_attack_table(n=40, amplitude=3.0, duration=15.0, seed=11)
    paper = lfc.simulate_many(P, table, duration=15.0, progress=False)
    certified = lfc.simulate_many(P, table.assign(method="certified"), duration=15.0,
                                   progress=False)
    assert paper.tripped.any()            # the attacks are strong enough to matter
    assert not certified.tripped.any()


def test_a_load_step_beyond_the_assumption_is_flagged_not_silent():
    e12 = P.M * RELAYS.rocof_limit
    r = lfc.simulate(P, duration=5.0, load=lfc.Step(1.25 * e12, 1.0), scc=CERT)
    assert r.metrics()["tripped"]                # physics: E12
    assert r.alarms.outside.any()                # and the filter says it lost its guarantee
    assert "the load moved beyond load_bound" in r.alarms.reason[r.alarms.outside].iloc[0]


def test_load_bound_covers_load_steps_and_rejects_impossible_bounds():
    covered = lfc.SafetyFilter(P, RELAYS, method="certified", load_bound=0.05)
    r = lfc.simulate(P, duration=10.0, load=lfc.Step(0.05, 1.0),
                     pc_attack=lfc.Square(1.0, 0.3, start=1.0), scc=covered)
    assert not r.metrics()["tripped"]
    with pytest.raises(ValueError, match=r"load_bound=0.2 pu is too large.*must be < 0.05984"):
        CertifiedSet(P, RELAYS, load_bound=P.M * RELAYS.rocof_limit)
    # a bound that leaves the samples' limits but no terminal set names itself, not the
    # estimation error (there is none here)
    with pytest.raises(ValueError, match="no room for the terminal set: .*load .*lower load_bound"):
        CertifiedSet(P, RELAYS, load_bound=0.05935)


def test_invalid_input_holds_the_last_certified_command():
    filt = lfc.SafetyFilter(P, RELAYS, method="certified")
    u0, _ = filt.filter(np.zeros(5), 0.2)
    u, info = filt.filter(np.array([np.nan, 0, 0, 0, 0]), 0.9)
    assert info.invalid_input and u == u0 and math.isfinite(u)


@pytest.mark.parametrize("kwargs, message", [
    ({"method": "robust"}, "method must be one of"),
    ({"method": "certified", "solver": "cvxpy"}, "option of method 'paper', not of 'certified'"),
    ({"method": "certified", "margin": 1.0}, "margin must be in"),
    ({"method": "certified", "load_bound": -0.1}, "load_bound"),
    ({"method": "certified", "tightening": 0.5}, "tightening"),
    ({"method": "certified", "uncertainty": 1.0}, "uncertainty"),
    ({"method": "certified", "uncertainty": {"H": (0.9, 1.1)}}, "unknown parameter"),
    ({"method": "certified", "uncertainty": {"M": (1.1, 1.2)}}, "0 < low <= 1 <= high"),
    ({"method": "certified", "trips_per_hour": 1.0}, "needs noise_std"),
    ({"method": "certified", "horizon": 0.0}, "horizon"),
])
def test_bad_parameters(kwargs, message):
    with pytest.raises(ValueError, match=message):
        lfc.SafetyFilter(P, RELAYS, **kwargs)
