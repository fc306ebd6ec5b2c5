"""The robust certified filter (issue "Robust"): its guarantee between relay
samples, over a declared ±20 % parameter box, on Kalman estimates and with
noisy relays, and its cost on legitimate load steps.

What is proven is stated in ``lfc.filters.certified``; each test here measures
it on a named set of runs (batch where many are needed).  The "robust" filter
is ``SafetyFilter(params, relays, method="certified", uncertainty=0.2,
noise_std=NOISE)``; the plain certified filter declares neither.
"""

import functools
import itertools
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
import tiers
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

import lfc
from lfc.experiments.redteam import Defender, Search, family_search, piecewise_attack_table
from lfc.experiments.surface import attack_map, bias_map
from lfc.filters.box import BOX
from lfc.model import lfc_matrices, output_matrix

P, RELAYS = lfc.LFCParams(), lfc.RelaySettings()
NOISE = (1e-4, 1e-3)           # the default noise of notebooks 07 and 08 (pu, pu/s)
BOX_WIDTH = 0.2
ROBUST = {"method": "certified", "uncertainty": BOX_WIDTH, "declare_noise": True}


def map_attacks() -> pd.DataFrame:
    """The maps' attacks (notebook 06's default grid; periodic attacks on P_c, biases
    on ω_ref) up to 3 pu, plus seeded red-team-style piecewise attacks (±3 pu)."""
    grid = pd.concat([attack_map(["sinusoid", "square"], [0.1, 0.3, 0.6, 1.0, 2.0, 3.0],
                                 [0.1, 0.2, 0.3, 0.5, 1.0, 2.0], alphas=[1.0]),
                      bias_map([-0.1, -0.05, 0.03, 0.04, 0.06, 0.1], [1.0])],
                     ignore_index=True)
    return grid[grid.alpha.notna()]


def strong_attacks() -> pd.DataFrame:
    """The map attacks that stress the certified filter (severity >= 0.95 on the
    design model, measured here): per waveform and frequency the smallest and
    the largest such amplitude; plus four of the red team's piecewise attacks."""
    grid = map_attacks().assign(method="certified")
    res = lfc.simulate_many(P, grid, duration=20.0, progress=False)
    sev = np.maximum(res.max_abs_rocof_meas / RELAYS.rocof_limit, res.max_abs_dw_meas / RELAYS.F)
    strong = grid[(sev >= 0.95).to_numpy()].sort_values("amplitude")
    by = strong.groupby(["waveform", "freq_hz"], sort=False)
    picked = pd.concat([by.head(1), by.tail(1)]).drop_duplicates()
    red = piecewise_attack_table(n=4, amplitude=3.0, duration=20.0, seed=11).assign(alpha=1.0)
    return pd.concat([picked, red], ignore_index=True)


def corners() -> list[lfc.LFCParams]:
    return [replace(P, **{n: getattr(P, n) * f for n, f in zip(BOX, combo)})
            for combo in itertools.product((1 - BOX_WIDTH, 1 + BOX_WIDTH), repeat=len(BOX))]


def interior(n: int, seed: int = 5) -> list[lfc.LFCParams]:
    rng = np.random.default_rng(seed)
    return [replace(P, **{name: getattr(P, name) * rng.uniform(1 - BOX_WIDTH, 1 + BOX_WIDTH)
                          for name in BOX}) for _ in range(n)]


def on_plants(table: pd.DataFrame, plants: list[lfc.LFCParams]) -> pd.DataFrame:
    """``table`` once per plant (the row's own plant columns)."""
    return pd.concat([table.assign(**{n: getattr(p, n) for n in BOX}) for p in plants],
                     ignore_index=True)


@pytest.fixture(scope="module")
def attacks() -> pd.DataFrame:
    return strong_attacks()


def run_battery(key: str, table: pd.DataFrame, **options) -> pd.DataFrame:
    """``simulate_many`` of the battery ``table`` in this tier (``tests/tiers.py``): every
    row in the exhaustive tier, its most severe (and most flagged) recorded rows in the
    default tier; the metrics indexed as ``table``."""
    picked = tiers.Battery.of_table(key, table)
    rows = table.loc[picked.scenarios]
    res = lfc.simulate_many(P, rows, progress=False, **options)
    res.index = rows.index
    sev = np.maximum(res.max_abs_rocof_meas / RELAYS.rocof_limit, res.max_abs_dw_meas / RELAYS.F)
    picked.record(sev, res.outside)
    return res


# -- between samples -------------------------------------------------------------------------
@pytest.mark.parametrize("dt", [2.5e-4, 5e-4, 1e-3, 2e-3])
def test_no_trip_at_any_plant_step(dt):
    """Every map attack and the red team's piecewise attacks, certified filter, at
    plant steps of 0.25–2 ms (the certificate holds in continuous time); the
    outputs stay within the limits at every step, not only at 1 ms."""
    table = pd.concat([map_attacks(), piecewise_attack_table(n=16, amplitude=3.0,
                                                             duration=20.0, seed=11)
                       .assign(alpha=1.0)], ignore_index=True).assign(method="certified")
    res = lfc.simulate_many(P, table, duration=20.0, dt=dt, progress=False)
    assert not res.tripped.any()
    assert res.max_abs_rocof_meas.max() <= RELAYS.rocof_limit
    assert res.max_abs_dw_meas.max() <= RELAYS.F


def test_the_issue_square_wave_at_half_a_millisecond():
    """The issue's example (1 pu, 0.3 Hz square on P_c tripped ROCOF at 6.46 s
    with dt = 0.5 ms): now the ROCOF peak is 99 % of the limit at any step."""
    filt = lfc.SafetyFilter(P, RELAYS, method="certified")
    for dt in (2.5e-4, 5e-4):
        r = lfc.simulate(P, duration=30.0, dt=dt, pc_attack=lfc.Square(1.0, 0.3, start=1.0),
                         scc=filt)
        assert not r.metrics()["tripped"]
        assert 0.98 * RELAYS.rocof_limit < r.metrics()["max_abs_rocof_meas"] < RELAYS.rocof_limit


# -- the parameter box -----------------------------------------------------------------------
@pytest.mark.long(46)
def test_robust_filter_never_trips_at_the_box_corners_or_inside(attacks):
    """The 32 corners of the ±20 % box (proven) and 8 random interior plants
    (measured), the strong attacks, plant step 0.5 ms."""
    table = on_plants(attacks.assign(method="certified", uncertainty=BOX_WIDTH),
                      corners() + interior(8))
    assert len(table) == 40 * len(attacks) >= 40 * 20
    res = run_battery("robust:box", table, duration=15.0, dt=5e-4, chunk_size=200)
    assert not res.tripped.any()


def test_without_the_box_the_certified_filter_trips_off_the_design_model(attacks):
    """The finding that motivated the box: the design-model certificate, on the
    low-inertia corners, trips under the same attacks."""
    low_inertia = [c for c in corners() if c.M < P.M][:4]
    res = lfc.simulate_many(P, on_plants(attacks.assign(method="certified"), low_inertia),
                             duration=20.0, progress=False)
    assert res.tripped.any()


def test_the_box_must_contain_the_design_model_and_be_a_box():
    with pytest.raises(ValueError, match="uncertainty"):
        lfc.SafetyFilter(P, RELAYS, method="certified", uncertainty=-0.1)
    cert = lfc.SafetyFilter(P, RELAYS, method="certified",
                            uncertainty={"M": (0.8, 1.0), "D": (1.0, 1.3)}).cert
    assert len(cert.plants) == 4 and cert.plants[0] == P
    assert {(p.M, p.D) for p in cert.plants} == {(4.0, 1.0), (3.2, 1.0), (4.0, 1.3), (3.2, 1.3)}


@functools.lru_cache(maxsize=None)
def free_response(corner: int, dt: float = 2.5e-4, seconds: float = 20.0) -> tuple:
    """``C e^{A k dt}`` for k = 0..seconds/dt (stacked, (K, 2, 5)) and ``A^-1 B``
    of a corner plant, by repeated multiplication with ``expm(A dt)``."""
    A, B = lfc_matrices(corners()[corner])
    step, C = expm(A * dt), output_matrix()
    out = np.empty((int(seconds / dt) + 1, 2, 5))
    out[0] = C
    for k in range(1, len(out)):
        out[k] = out[k - 1] @ step
    return out, np.linalg.solve(A, B)


ROBUST_FILTER = lfc.SafetyFilter(P, RELAYS, method="certified", uncertainty=BOX_WIDTH)
STATE_SCALE = np.array([0.2, 0.2, 0.01, 0.01, 0.02])


@settings(max_examples=tiers.examples(40), deadline=None)
@given(z=st.lists(st.floats(-2, 2), min_size=5, max_size=5), u_ref=st.floats(-2, 2),
       corner=st.integers(0, 31), p_load=st.floats(-0.1, 0.1))
def test_a_certified_command_held_keeps_every_corner_inside_at_a_quarter_millisecond(
        z, u_ref, corner, p_load):
    """The box certificate's promise, checked independently: the command it
    certifies, held for 20 s on any corner plant with the load it was given,
    keeps both outputs inside the limits at every 0.25 ms."""
    x = np.array(z) * STATE_SCALE
    ROBUST_FILTER.reset()
    u, info = ROBUST_FILTER.filter(x, u_ref, p_load)
    lo, hi = info.details["interval"]
    if lo > hi:
        return                        # nothing certified from this state: the filter holds
    response, a_inv_b = free_response(corner)
    x_eq = -a_inv_b @ np.array([u, p_load])
    y = response @ (x - x_eq) + output_matrix() @ x_eq
    assert np.all(np.abs(y[:, 0]) <= RELAYS.F) and np.all(np.abs(y[:, 1]) <= RELAYS.rocof_limit)


# -- estimation error and noisy relays -------------------------------------------------------
@pytest.mark.long(37)
def test_robust_filter_on_kalman_estimates_over_many_seeds(attacks):
    """Default noise, 16 seeds per attack, on the design model and the corner
    with the least inertia and damping and the slowest governor."""
    table = attacks.assign(**ROBUST, noise_w=NOISE[0], noise_rocof=NOISE[1])
    table = pd.concat([table.assign(seed=s) for s in range(16)], ignore_index=True)
    weakest = replace(P, M=0.8 * P.M, D=0.8 * P.D, tau_g=1.2 * P.tau_g, tau_t=1.2 * P.tau_t,
                      droop=0.8 * P.droop)
    table = on_plants(table, [P, weakest])
    assert len(table) >= 2 * 16 * 20
    res = run_battery("robust:kalman-seeds", table, duration=10.0, chunk_size=200)
    assert not res.tripped.any()


@pytest.mark.long(38)
def test_robust_filter_on_kalman_estimates_at_all_32_corners(attacks):
    """The issue's "holds at all 32 corners with the Kalman estimate": every
    corner of the box, the strong attacks, one noise seed, 10 s.  No trip.  The
    finding beside it: the estimate's error bound is the design model's, so at
    the corners it is left, and the filter says so — some runs flag ``outside``
    (the guarantee ends there; what saves them is measured, not proven)."""
    table = on_plants(attacks.assign(**ROBUST, noise_w=NOISE[0], noise_rocof=NOISE[1],
                                     seed=0), corners())
    assert len(table) == 32 * len(attacks) >= 32 * 20
    res = run_battery("robust:kalman-corners", table, duration=10.0, chunk_size=200)
    assert not res.tripped.any()
    sev = np.maximum(res.max_abs_rocof_meas / RELAYS.rocof_limit,
                     res.max_abs_dw_meas / RELAYS.F)
    assert sev.max() < 1.0
    assert (res.outside > 0).any()


def test_off_the_box_every_trip_is_flagged_outside_first(attacks):
    """Attacking the guarantee where it is weakest: the robust filter (±20 % box,
    noise declared) on the low-inertia corners of a ±40 % box, Kalman estimate on
    the design model.  Off its assumptions it trips — but every trip comes after
    the filter flagged ``outside`` (measured here: no silent trip)."""
    from lfc.tables import scenario_signal
    from lfc.estimation import KalmanFilter
    wide = [replace(P, **{n: getattr(P, n) * f for n, f in zip(BOX, combo)})
            for combo in itertools.product((0.6, 1.4), repeat=len(BOX))]
    weak = [c for c in wide if c.M < P.M]
    table = on_plants(attacks.assign(**ROBUST, noise_w=NOISE[0], noise_rocof=NOISE[1],
                                     seed=0), weak)
    res = run_battery("robust:off-the-box", table, duration=10.0, chunk_size=200)
    trips = table.loc[res.index[res.tripped.to_numpy()]]
    assert len(trips) >= (10 if tiers.exhaustive() else 1)
    scc = lfc.SafetyFilter(P, method="certified", uncertainty=BOX_WIDTH, noise_std=NOISE)
    kalman = KalmanFilter(P, 0.01, meas_std=NOISE)     # what a batch row uses: the design
    for _, row in trips.iterrows():
        attack = {f"{row.channel}_attack": scenario_signal(row, 10.0)}
        run = lfc.simulate(replace(P, **{n: row[n] for n in BOX}), duration=10.0, scc=scc,
                           estimator=kalman, noise_std=NOISE, seed=0, **attack)
        flagged = run.alarms[run.alarms.outside].t
        assert run.metrics()["tripped"] and len(flagged)
        assert flagged.min() < run.metrics()["first_trip_t"]


def test_undeclared_noise_trips_the_certified_filter(attacks):
    """Without ``noise_std`` the certificate trusts the estimate: some seed trips."""
    table = attacks.assign(method="certified", noise_w=NOISE[0], noise_rocof=NOISE[1])
    table = pd.concat([table.assign(seed=s) for s in range(4)], ignore_index=True)
    assert run_battery("robust:undeclared-noise", table, duration=15.0).tripped.any()


def test_noisy_relays_trip_rate_within_the_claim(attacks):
    """Relays read through the noise at every 1 ms step.  With ``trips_per_hour=1``
    declared, one simulated hour against the strong attacks (0.5 s each after the
    attack starts, 15 s runs) gives no trip; without it the filter rides the
    limit and the noise trips the relays (the reason for the option)."""
    base = attacks.assign(method="certified", declare_noise=True, noise_w=NOISE[0],
                          noise_rocof=NOISE[1], relay_noise=True)
    n = int(np.ceil(3600 / 15.0 / len(base)))
    table = pd.concat([base.assign(seed=s) for s in range(n)], ignore_index=True)
    claimed = lfc.simulate_many(P, table.assign(trips_per_hour=1.0), duration=15.0,
                                 progress=False, chunk_size=500)
    assert len(claimed) * 15.0 >= 3600 and not claimed.tripped.any()
    unclaimed = lfc.simulate_many(P, table.iloc[:len(base) * 2], duration=15.0,
                                   progress=False)
    assert unclaimed.tripped.any()


# -- the red team searches the plant and the noise ---------------------------------------------
def test_red_team_over_box_and_noise_beats_certified_not_robust():
    search = Search(box=BOX_WIDTH, noise_std=NOISE, n_seeds=8)
    kw = dict(family="square on P_c", duration=10.0, maxiter=3, popsize=3, search=search)
    certified = family_search(P, Defender("certified", method="certified"), **kw)
    robust = family_search(P, Defender("robust", method="certified", uncertainty=BOX_WIDTH,
                                       declare_noise=True), **kw)
    assert certified["tripped"]
    assert not robust["tripped"] and robust["severity"] < 1.0


# -- the cost of safety ----------------------------------------------------------------------
@pytest.mark.parametrize("step", [0.05, 0.1, 0.15, 0.19, -0.19])
def test_legitimate_load_steps_pass_and_recover(step):
    """On the Kalman estimate (which estimates the load): no trip, and 40 s after
    the step the estimated frequency deviation is within 0.003 pu."""
    filt = lfc.SafetyFilter(P, RELAYS, method="certified", uncertainty=BOX_WIDTH,
                            noise_std=NOISE)
    r = lfc.simulate(P, duration=42.0, load=lfc.Step(step, 1.0), scc=filt, estimator="kalman",
                     noise_std=NOISE, seed=1)
    assert not r.metrics()["tripped"]
    c = r.controls
    assert abs(c.dw_hat[c.t >= 41.0].iloc[0]) < 0.003
    assert r.metrics()["alarms"] <= 20      # measured: 0, 0, 0, 8, 0 control periods
