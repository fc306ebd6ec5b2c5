"""The coupled certificate on the grid Kalman estimate (``CoupledFilter(...,
noise_std=...)`` with ``estimator="kalman"``; ``docs/coupled-certificate.md``,
"With estimates").  The lemma the proof rests on — the estimate's error is a
noise part plus a part linear in the loads, and nothing else: no command and no
attack moves it — is checked against the engine to rounding; theorem A with
estimates is checked at its worst case (a step of exactly ``load_bound`` just
after a control sample); the battery is rerun on the estimate on the presets and
on Kundur and IEEE 39-bus as fitted to ANDES."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

import lfc
from lfc import MultiAreaParams
from lfc.filters.base import OUTSIDE
from lfc.filters.coupled import CoupledFilter, CoupledOptions
from lfc.filters.coupled_kernel import RHO_NEW
from lfc.filters.coupled_set import load_error_steps
from lfc.experiments.redteam import severity as sev
from lfc.linear_grid import simulate_grid_linear
from test_coupled import RELAYS, THREE, battery, ieee39, kundur
import tiers
from test_coupled_baseline import attacks, tally

NOISE = (1e-4, 1e-3)      # pu, pu/s: every area's dw_meas and rocof_meas
ESTIMATE = {"estimator": "kalman", "noise_std": NOISE}


def errors(result, area: int) -> dict[str, np.ndarray]:
    """True minus estimated ``dw_meas``, ``rocof_meas`` and load of ``area`` at
    every control sample (pu, pu/s, pu)."""
    res = result.areas[area]
    c = res.controls.set_index(np.round(res.controls.t, 6))
    tr = res.trace.set_index(np.round(res.trace.t, 6)).loc[c.index]
    return {"dw_meas": (tr.dw_meas - c.dw_hat).to_numpy(),
            "rocof_meas": (tr.rocof_meas - c.rocof_hat).to_numpy(),
            "p_load": (tr.p_load - c.p_load_hat).to_numpy()}


def test_the_error_is_the_lemmas_and_no_attack_moves_it():
    """The proof's lemma (``load_error_steps``), checked against the engine: on the
    two-area preset under a 1 pu sinusoid on area 0's command, without noise, the
    estimate's error is 0 (to rounding, 1e-15) until a 0.05 pu load step in area 1 at 2.003 s,
    then equals 0.05 times the lemma's response for that offset (0.3 of a period)
    and area, for 60 samples, to 1e-12.  With noise, the error of every area is the
    same under every attack of the battery (the tie-line flows are states of the
    estimator's model: the inter-area swing an attack drives is predicted, not a
    disturbance to it), and stays inside the ellipsoid the certificate covers
    (each coordinate within kappa standard deviations; 0.55 of it at most when
    measured)."""
    grid = MultiAreaParams.two_area()
    filt = CoupledFilter(grid, RELAYS, noise_std=NOISE)
    n_r = len(filt.cert.A)
    steps = load_error_steps(filt.kalman, filt.cert.A, filt.cert.Bl, 0.01)
    r = simulate_grid_linear(grid, loads={1: lfc.Step(0.05, start=2.003)},
                             filters={0: filt, 1: filt},
                             attacks={0: {"pc": lfc.Sinusoid(1.0, 0.5, start=1.0)}},
                             estimator="kalman", noise_std=(0.0, 0.0), duration=3.0)
    per_age = 11 * grid.n_areas                    # offsets x areas, per age
    for a in range(2):
        e = errors(r, a)
        assert np.max(np.abs(e["dw_meas"][:201])) < 1e-15
        assert np.max(np.abs(e["p_load"][:201])) < 1e-15
        for age in range(1, 61):
            row = steps.rows[(age - 1) * per_age + 3 * grid.n_areas + 1]
            k = 200 + age
            assert abs(e["dw_meas"][k] - 0.05 * row[5 * a + 3]) < 1e-12
            assert abs(e["rocof_meas"][k] - 0.05 * row[5 * a + 4]) < 1e-12
            assert abs(e["p_load"][k] - 0.05 * row[n_r + a]) < 1e-12
    cov = filt.kalman.posterior_covariance
    kappa = math.sqrt(chi2.ppf(CoupledOptions().confidence, len(cov)))
    sd = np.sqrt(np.diag(cov))
    first = None
    for attack in attacks(2).values():
        r = simulate_grid_linear(grid, attacks=attack, filters={0: filt, 1: filt}, seed=3,
                                 duration=10.0, anti_windup=True, **ESTIMATE)
        e = [errors(r, a) for a in range(2)]
        if first is None:
            first = e
        for a in range(2):
            for name, i in (("dw_meas", 5 * a + 3), ("rocof_meas", 5 * a + 4),
                            ("p_load", n_r + a)):
                np.testing.assert_allclose(e[a][name], first[a][name], rtol=0, atol=1e-12)
                assert np.max(np.abs(e[a][name])) < kappa * sd[i]


def test_a_step_of_exactly_load_bound_just_after_a_sample_trips_nothing():
    """Theorem A on the estimate, at its worst case: a load step of exactly
    ``load_bound`` (0.06 pu) landing 1 ms after a control sample (the estimator
    sees it only at the next one, then catches up over about a second), every
    0.5 s of the attacks, in every area, both signs, with measurement noise: no
    trip.  The battery's 0.05 pu steps: no trip, and the held re-check — not
    proven on an estimate, whose noise differs from one sample to the next — flags
    ``outside`` in at most a few runs (1 of 80 when measured)."""
    grid = MultiAreaParams.two_area()
    filt = CoupledFilter(grid, RELAYS, noise_std=NOISE)
    instants = tuple(np.round(np.arange(1.0, 6.0, 0.5) + 0.001, 6))
    runs, tripped, _ = battery(grid, "estimate:exact-step-bound", filt, instants=instants,
                               step=0.06, anti_windup=(True,), **ESTIMATE)
    assert runs == 200 and tripped == 0
    runs, tripped, outside = battery(grid, "estimate:two-area", filt, anti_windup=(True,),
                                     **ESTIMATE)
    assert runs == 80 and tripped == 0 and outside <= 4


@pytest.mark.parametrize("name", ["three-area", "kundur", "ieee39"])
def test_the_battery_on_the_estimate_trips_nothing(name):
    """The battery (five attacks x every area x four instants x ±0.05 pu) on the
    grid Kalman estimate with noise (1e-4 pu, 1e-3 pu/s): no trip (theorem A).
    Kundur (T = 98 pu) and IEEE 39-bus (T = 28 pu) as fitted to ANDES need a 12 s
    horizon (at 8 s their slowest mode, 0.116 1/s on Kundur, leaves too much of
    the estimate's error at the horizon: construction says so).  ``outside``
    flags, measured: three-area 0 of 120 runs, Kundur 5 of 80, IEEE 39-bus 0 of 80.
    The fitted models' filters here leave out their fits' mismatch
    (``mismatch_budget=False``: the battery runs on the model itself, which has none);
    with it, the default, the horizon is chosen (``"auto"``) and the filter builds."""
    grid = {"three-area": lambda: THREE, "kundur": kundur, "ieee39": ieee39}[name]()
    horizon = 8.0 if name == "three-area" else 12.0
    alone = {} if name == "three-area" else {"mismatch_budget": False}
    if horizon > 8.0:
        with pytest.raises(ValueError, match="raise horizon"):
            CoupledFilter(grid, RELAYS, noise_std=NOISE, **alone)
        assert CoupledFilter(grid, RELAYS, noise_std=NOISE).horizons
    filt = CoupledFilter(grid, RELAYS, noise_std=NOISE, horizon=horizon, **alone)
    runs, tripped, outside = battery(grid, f"estimate:{name}", filt, anti_windup=(True,),
                                     **ESTIMATE)
    assert runs == 40 * grid.n_areas and tripped == 0
    assert outside <= {"three-area": 0, "kundur": 10, "ieee39": 4}[name]
    if alone:      # the default filter, the fit's mismatch in its budget (horizon 8 s)
        default = CoupledFilter(grid, RELAYS, noise_std=NOISE)
        assert default.options.horizon == 8.0 and default.mismatch == grid.load_mismatch
        runs, tripped, outside = battery(grid, f"estimate:{name}:default", default,
                                         anti_windup=(True,), **ESTIMATE)
        assert runs == 40 * grid.n_areas and tripped == 0


def outside_runs(grid: MultiAreaParams, key: str, filt: CoupledFilter, loads: list
                 ) -> tuple[int, int, int]:
    """``(scenarios, runs with a trip, runs with an outside flag)`` of the battery's
    five attacks x ``loads`` (each a ``{area: signal}``) with ``filt`` at every area,
    on the estimate, with anti-windup (:func:`test_coupled_baseline.tally`)."""
    every = {a: filt for a in range(grid.n_areas)}
    cases = [(name, i) for name in attacks(grid.n_areas) for i in range(len(loads))]

    def make(name: str, i: int) -> dict:
        return {"attacks": attacks(grid.n_areas)[name], "loads": loads[i], "filters": every,
                "anti_windup": True, "seed": 0, **ESTIMATE}
    return tally(grid, f"estimate:{key}", cases, make,
                 lambda name, i: f"{name} | load path {i}: {loads[i]}")


@pytest.mark.long(35)
@pytest.mark.parametrize("name", ["two-area", "kundur"])
def test_the_widened_held_level_flags_nothing_within_the_bound_and_misses_what_lies_beyond(name):
    """Theorem C' (``held_level="widened"``) at its worst case: load paths of total
    variation exactly ``load_bound - recheck_bound`` = 0.05 pu — a step landing 1 ms
    after a control sample (the estimator sees it only at the next one), every 0.5 s
    of the five attacks, in every area, both signs — flag no ``outside`` and trip
    nothing, where the sharp level flags it with nothing wrong (the battery: 1 of 80
    runs on two areas, 5 of 80 on Kundur).  On two areas also pulses of ±0.025 pu
    lasting 0.05 and 0.3 s (the same total variation).  Beyond the tests, 0 / 0
    too: pulses of 0.01–1 s, ramps over 0.1 and 1 s, 0.025 pu steps in both areas
    0–1 s apart and ten more noise seeds (1,120 runs on each grid,
    ``python bench/survey_grid_certificates.py --held-levels``).  The price, a finding:
    beyond the bound the widened level is blind — on two areas the 0.1 pu steps of
    four runs trip ROCOF with no ``outside`` (the sharp level flags every run that
    trips; the commands are the same, only the flag differs), and on Kundur steps of
    0.06, 0.1 and 0.2 pu flag nothing (the sharp level: all 80 runs of each)."""
    grid = MultiAreaParams.two_area() if name == "two-area" else kundur()
    horizon = 8.0 if name == "two-area" else 12.0
    # on the model itself, which has no mismatch: Kundur's filter without its fit's
    widened = CoupledFilter(grid, RELAYS, noise_std=NOISE, horizon=horizon,
                            held_level="widened", mismatch_budget=False)
    instants = np.round(np.arange(1.0, 6.0, 0.5) + 0.001, 6)
    steps = [{a: lfc.Step(sign * 0.05, start=t)} for a in range(grid.n_areas)
             for t in instants for sign in (1, -1)]
    assert outside_runs(grid, f"widened-steps[{name}]", widened, steps) == (200, 0, 0)
    if name == "kundur":
        return
    pulses = [{a: lfc.Step(sign * 0.025, start=t, stop=t + width)} for a in range(2)
              for t in instants[::3] for sign in (1, -1) for width in (0.05, 0.3)]
    assert outside_runs(grid, "widened-pulses", widened, pulses) == (160, 0, 0)
    beyond = [{a: lfc.Step(sign * 0.1, start=t)} for a in range(2)
              for t in instants[::3] for sign in (1, -1)]
    sharp = CoupledFilter(grid, RELAYS, noise_std=NOISE)
    runs, tripped, outside = outside_runs(grid, "sharp-beyond", sharp, beyond)
    assert runs == 80 and 0 < tripped <= outside
    runs, tripped, outside = outside_runs(grid, "widened-beyond", widened, beyond)
    assert runs == 80 and tripped > 0 and outside == 0
    if tiers.exhaustive():
        assert tripped == 4


def widened() -> CoupledFilter:
    """The two-area preset's filter on the estimate at the widened held level (built
    once per process: :func:`lfc.filters.base.built_once`)."""
    return CoupledFilter(MultiAreaParams.two_area(), RELAYS, noise_std=NOISE,
                         held_level="widened")


def every_period(n_areas: int, seconds: float = 10.0, offset: float = 0.0015) -> list[dict]:
    """Load paths whose variation within every control period is exactly
    ``recheck_bound`` (0.01 pu), theorem B's assumption at its edge: a ramp of
    ±1 pu/s (0.01 pu per 10 ms period) for 1 s in one area or shared by all; a
    ±0.005 pu square wave at 50 Hz (a 0.01 pu swing every period); a random walk
    of ±0.01 pu every period (seeded).  The steps land ``offset`` s (default 1.5
    ms) after a control sample (the estimator sees them only at the next one)."""
    paths = []
    for sign in (1, -1):
        paths += [{a: lfc.Ramp(sign, start=1.0 + offset, stop=2.0 + offset)}
                  for a in range(n_areas)]
        paths.append({a: lfc.Ramp(sign / n_areas, start=1.0 + offset, stop=2.0 + offset)
                      for a in range(n_areas)})
    paths += [{a: lfc.Square(0.005, 50.0, start=1.0 + offset)} for a in range(n_areas)]
    for a in range(n_areas):
        at = np.arange(1.0, seconds, 0.01) + offset
        walk = np.cumsum(np.random.default_rng(a).choice([-0.01, 0.01], len(at)))
        paths.append({a: lfc.Samples(np.ravel(np.column_stack([at - 1e-6, at])),
                                     np.ravel(np.column_stack([np.r_[0.0, walk[:-1]], walk])))})
    return paths


def test_the_strict_held_level_takes_off_what_every_periods_loads_move_the_error():
    """Theorem B' (``held_level="strict"``), its lemma: if every control period's
    load variation is at most 1, the loads' part of the estimate's error moves a
    row by at most the sum over ages of the largest response of that age
    (:meth:`~lfc.filters.coupled_set.LoadErrors.total`: an enclosure, every instant of
    the period and every age included; the offsets' interpolation and the ages after
    the last add less than 0.1 % of it).  Checked against the engine without noise
    on two areas:
    under every path of :func:`every_period` the error of each area's frequency
    and ROCOF stays within 0.01 times it, and the ramps reach 0.90 of it (the
    bound is nearly tight).  The strict level is the sharp one less exactly that
    on the coming period's rows (the samples to the first at or after one control
    period, and the current outputs), the new level at most the strict held
    one there, every later row unchanged."""
    grid = MultiAreaParams.two_area()
    strict = CoupledFilter(grid, RELAYS, noise_std=NOISE, held_level="strict")
    sharp = CoupledFilter(grid, RELAYS, noise_std=NOISE)
    c = strict.cert
    steps = load_error_steps(strict.kalman, c.A, c.Bl, 0.01)
    w0 = np.hstack([c.C, np.zeros((4, 2))])
    bound = 0.01 * steps.total(w0)
    np.testing.assert_allclose(bound, [9.004e-5, 9.8375e-3] * 2, rtol=1e-4)
    ages = np.abs(w0 @ steps.rows.T).reshape(4, -1, steps.per_age).max(axis=2).sum(axis=1)
    assert np.all(bound - 0.01 * ages < 1e-3 * bound)   # the grid's values carry it
    reached = np.zeros(4)
    for loads in every_period(2):
        r = lfc.simulate(grid, duration=10.0, loads=loads, filters={0: strict, 1: strict},
                         estimator="kalman", noise_std=(0.0, 0.0))
        e = [errors(r, a) for a in range(2)]
        reached = np.maximum(reached, [np.max(np.abs(e[a][k])) / bound[2 * a + i]
                                       for a in range(2)
                                       for i, k in enumerate(("dw_meas", "rocof_meas"))])
    assert np.all(reached <= 1.0) and np.all(reached > 0.89)
    coming = np.searchsorted(c.times, 0.01) + 1
    new, held = (x.reshape(len(c.times), 4) for x in (c.rows[:, 0], c.rows[:, 1]))
    was_new, was_held = (x.reshape(len(c.times), 4) for x in (sharp.cert.rows[:, 0],
                                                              sharp.cert.rows[:, 1]))
    assert np.all(held[:coming] < was_held[:coming] - 1e-5)
    assert np.all(new[:coming] <= held[:coming]) and np.all(new <= was_new)
    np.testing.assert_array_equal(held[coming:], was_held[coming:])
    np.testing.assert_array_equal(new[coming:], was_new[coming:])
    assert "not yet seen a load change" in strict.reason(OUTSIDE)


@pytest.mark.long(25)
def test_at_the_strict_level_outside_comes_before_every_trip_at_the_sharp_one_not():
    """Theorem B' at its worst case: every control period's load variation exactly
    ``recheck_bound`` (:func:`every_period`) under each of the five attacks, with
    noise (seed 0), 10 s.  At the strict held level every run that trips flags
    ``outside`` first, on two and three areas, Kundur (``horizon=16``) and the
    IEEE 39-bus system (12) as fitted to ANDES, their fits' mismatch in the budget
    (220 runs, 82 trip; 88 without the mismatch: ramps of 1 pu/s
    and random walks go far beyond what the relays allow; the flag comes at least
    0.02 s before on two and three areas, 0.9 s on the fitted grids, when measured).  Finding, pinned — theorem B does not carry over to the estimate
    at the default sharp level: on two areas 17 of its 27 tripping runs trip before
    their first ``outside`` (the ramps: the estimator lags a load that moves every
    period, by up to 0.0099 pu/s of ROCOF, 20 % of the limit), on three areas 15
    of 35.  The price of the strict level, on the battery with anti-windup: 6 of
    80 two-area runs flag ``outside`` with nothing wrong (the sharp level 1)."""
    cases = (("two-area", MultiAreaParams.two_area(), 8.0), ("three-area", THREE, 8.0),
             ("kundur", kundur(), 16.0), ("ieee39", ieee39(), 12.0))
    expected = {"two-area": (50, 27, 0), "three-area": (70, 35, 0), "kundur": (50, 15, 0),
                "ieee39": (50, 5, 0)}
    for name, grid, horizon in cases:
        strict = CoupledFilter(grid, RELAYS, noise_std=NOISE, horizon=horizon,
                               held_level="strict")
        runs, trips, early = trips_before_outside(grid, f"strict[{name}]", strict)
        assert runs == expected[name][0] and trips > 0 and early == 0, name
        if tiers.exhaustive():
            assert (runs, trips, early) == expected[name], name
        if name in ("two-area", "three-area"):
            sharp = CoupledFilter(grid, RELAYS, noise_std=NOISE, horizon=horizon)
            early = trips_before_outside(grid, f"sharp[{name}]", sharp)[2]
            assert early > 0
            if tiers.exhaustive():
                assert early == {"two-area": 17, "three-area": 15}[name]
    two = MultiAreaParams.two_area()
    strict = CoupledFilter(two, RELAYS, noise_std=NOISE, held_level="strict")
    runs, tripped, outside = battery(two, "estimate:two-area-strict", strict,
                                     anti_windup=(True,), **ESTIMATE)
    assert runs == 80 and tripped == 0 and outside > 0
    if tiers.exhaustive():
        assert outside == 6


def trips_before_outside(grid: MultiAreaParams, key: str, filt: CoupledFilter,
                         seed: int = 0) -> tuple[int, int, int]:
    """``(scenarios, runs that trip, runs that trip before their first outside flag)``
    of the five attacks x :func:`every_period`'s paths with ``filt`` at every area (10
    s, noise ``seed``, anti-windup): a battery (``tests/tiers.py``) whose recorded
    cases are the most severe and those that trip before any flag."""
    paths = every_period(grid.n_areas)
    cases = [(name, i) for name in attacks(grid.n_areas) for i in range(len(paths))]
    picked = tiers.Battery(f"estimate:every-period:{key}", cases,
                           lambda case: f"{case[0]} | load path {case[1]}")
    severity, late = [], []
    trips = early = 0
    for name, i in picked.scenarios:
        r = lfc.simulate(grid, duration=10.0, attacks=attacks(grid.n_areas)[name],
                         loads=paths[i], seed=seed,
                         filters={a: filt for a in range(grid.n_areas)},
                         anti_windup=True, **ESTIMATE)
        severity.append(max(float(sev(m, RELAYS)) for m in r.metrics().values()))
        unflagged = False
        if r.tripped:
            trips += 1
            trip = min(a.metrics()["first_trip_t"] or np.inf for a in r.areas)
            flags = [a.alarms.query("outside").t for a in r.areas]
            unflagged = not min((f.min() for f in flags if len(f)), default=np.inf) < trip
            early += unflagged
        late.append(float(unflagged))
    picked.record(severity, late)
    return len(cases), trips, early


@settings(max_examples=tiers.examples(40))
@given(attack=st.sampled_from(sorted(attacks(2))), seed=st.integers(0, 2 ** 31 - 1),
       paths=st.lists(st.tuples(st.sampled_from(["none", "step", "pulse"]),
                                st.floats(1.0, 9.0), st.floats(0.005, 3.0),
                                st.floats(0.05, 1.0), st.sampled_from([1, -1])),
                      min_size=2, max_size=2))
def test_any_load_path_within_the_bound_flags_nothing_at_the_widened_level(attack, seed, paths):
    """Theorem C' as a property: on two areas, any of the battery's attacks, any
    noise seed, and in each area no load change, a step or a pulse (instant, width,
    sign and share drawn), scaled so that the total variation over both areas is
    exactly ``load_bound - recheck_bound`` = 0.05 pu: no ``outside`` at the widened
    held level, and no trip."""
    variation = sum(w * (2 if kind == "pulse" else 1) for kind, _, _, w, _ in paths
                    if kind != "none")
    assume(variation > 0)
    loads = {a: lfc.Step(sign * 0.05 * w / variation, start=start,
                         stop=start + width if kind == "pulse" else math.inf)
             for a, (kind, start, width, w, sign) in enumerate(paths) if kind != "none"}
    filt = widened()
    r = lfc.simulate(MultiAreaParams.two_area(), duration=15.0, seed=seed,
                     attacks=attacks(2)[attack], filters={0: filt, 1: filt},
                     loads=loads, anti_windup=True, **ESTIMATE)
    assert not r.tripped
    assert all(res.metrics()["outside"] == 0 for res in r.areas)


@pytest.mark.parametrize("family", ["sinusoid on P_c", "square on ω_ref", "bias on ACE",
                                    "ramp on ω_ref"])
def test_the_red_teams_coordinated_search_on_the_estimate_trips_nothing_and_flags_nothing(family):
    """The red team's coordinated search (both areas at once, maximizing the worst
    relay severity; ``tests/test_coupled.py`` runs it on the exact state) against
    the coupled filters on their grid Kalman estimate, with noise, at both held
    levels: its worst attack stays inside every relay (severity 0.29–0.66 when
    measured) and no filter flags ``outside`` at it."""
    from lfc.experiments.redteam import (MULTI_FAMILIES, coordinated_attacks,
                                         coordinated_search)
    grid = MultiAreaParams.two_area()
    for level in ("sharp", "widened"):
        filt = CoupledFilter(grid, RELAYS, noise_std=NOISE, held_level=level)
        found = tiers.searched(
            f"estimate:red-team[{family}-{level}]", lambda: coordinated_search(
                grid, {0: filt, 1: filt}, family, duration=20.0, maxiter=2, popsize=4,
                jobs=1, scenario={**ESTIMATE, "anti_windup": True}))
        assert not found["tripped"] and found["severity"] < 1.0 and found["outside"] == 0
        replayed = simulate_grid_linear(grid, duration=20.0, filters={0: filt, 1: filt},
                                        attacks=coordinated_attacks(family, found["theta"], 2,
                                                                    20.0),
                                        anti_windup=True, **ESTIMATE)
        worst = max(float(sev(m, RELAYS)) for m in replayed.metrics().values())
        assert worst == pytest.approx(found["severity"], rel=1e-6)
        assert sum(a.metrics()["outside"] for a in replayed.areas) == 0
    channel = MULTI_FAMILIES[family][0]           # fixed attacks only on other channels
    with pytest.raises(ValueError, match=f"must not be on '{channel}'"):
        coordinated_search(grid, {0: filt, 1: filt}, family,
                           scenario={"attacks": {1: {channel: lfc.Step(0.1)}}})


def test_it_refuses_what_its_error_bound_does_not_cover():
    """A filter built for the estimate needs ``estimator="kalman"`` and noise no
    larger than it was built for; one built for the exact state refuses an
    estimator; ``confidence`` or ``held_level`` without ``noise_std`` is an error;
    the string ``"coupled"`` with ``estimator="kalman"`` builds the estimating filter
    for the simulation's noise.  An ``outside`` flag's reason says what it may mean
    at the filter's held level."""
    grid = MultiAreaParams.two_area()
    filt = CoupledFilter(grid, RELAYS, noise_std=NOISE)
    both = {0: filt, 1: filt}
    with pytest.raises(ValueError, match="estimator='kalman'"):
        lfc.simulate(grid, duration=1.0, filters=both)
    with pytest.raises(ValueError, match="exceeds the noise"):
        lfc.simulate(grid, duration=1.0, filters=both, estimator="kalman",
                     noise_std=(2e-4, 1e-3))
    with pytest.raises(ValueError, match="confidence"):
        CoupledOptions(confidence=0.99)
    assert "not yet seen a load step" in filt.reason(OUTSIDE)       # what outside may mean
    assert "noise left its ellipsoid" in widened().reason(OUTSIDE)
    assert "not yet seen" not in CoupledFilter(grid, RELAYS).reason(OUTSIDE)
    with pytest.raises(ValueError, match="held_level='widened' has no effect"):
        CoupledOptions(held_level="widened")
    with pytest.raises(ValueError, match="held_level='strict' has no effect"):
        CoupledOptions(held_level="strict")
    with pytest.raises(ValueError, match="held_level must be one of"):
        CoupledOptions(noise_std=NOISE, held_level="wide")
    with pytest.raises(ValueError, match="noise_std"):
        CoupledOptions(noise_std=(-1.0, 1e-3))
    r = lfc.simulate(grid, duration=2.0, filters={0: "coupled", 1: "coupled"},
                     estimator="kalman", noise_std=NOISE,
                     attacks={0: {"pc": lfc.Sinusoid(1.0, 0.5, start=0.5)}})
    assert not r.tripped and r.areas[0].metrics()["alarms"] > 0
    assert "noise_std=(0.0001, 0.001)" in r.areas[0].settings["filters"][0]


@pytest.mark.andes_recorded
@pytest.mark.long(80)
def test_on_andes_the_coupled_filters_run_on_their_estimate():
    """Measured on ANDES, not proven (the certificate and its error bound are the
    fitted model's): the coupled filters on their grid Kalman estimate, fed each
    area's metered ``dw_meas`` and ``rocof_meas`` with noise (1e-4 pu, 1e-3 pu/s)
    and metered tie-line export, at both held levels, each as built by default —
    the fit's mismatch as load in the budget (Kundur 0.043 pu, IEEE 39-bus 0.27
    pu), the horizon chosen: 8 s on both — and without it (``mismatch_budget=False``;
    ``horizon=16`` on Kundur, where 12 s holds legitimate AGC:
    :func:`test_finding_on_kundur_a_12_s_horizon_holds_agc_after_a_legitimate_step`,
    12 on IEEE 39-bus).  Nothing trips in any run.

    * Kundur, a -2.5 pu bias on both areas' ACE and a -0.05 pu load step in
      area 1 at 3.37 s: the estimate follows ANDES' frequency meters within 6e-4
      pu.  With the mismatch, no ``outside``; without, ``outside`` only at the two
      samples after the step at the sharp level (none at the widened level) —
      ANDES' ROCOF meter jumps at a load step (0.011 pu/s in area 1, with the bus
      angle), which the fitted model cannot produce, so for a moment the estimate
      is off by about 0.009 pu/s.
    * IEEE 39-bus under chapter 09's coordinated sinusoid (0.6 pu, 0.5 Hz on both
      commands) and the same step: with the mismatch, no ``outside``; without,
      hundreds of samples (about 820 per area at the sharp level, 121 at the
      widened), as the exact-state filters without it (267) — the fitted model's
      mismatch (``tests/test_coupled.py``).
    * What the mismatch costs on the model: a legitimate 0.05 pu step holds no
      area's AGC (``held_after_step`` 0 s) on either grid, with it or without.
    """
    from lfc.testbed import GridCase
    step = {1: lfc.Step(-0.05, start=3.37)}
    expected = {("kundur", True): {"sharp": [0, 0], "widened": [0, 0]},
                ("kundur", False): {"sharp": [2, 2], "widened": [0, 0]},
                ("ieee39", True): {"sharp": [0, 0], "widened": [0, 0]}}
    for name, case, attack in (
            ("kundur", GridCase.kundur(), {a: {"ace": lfc.Step(-2.5, start=1.0)} for a in range(2)}),
            ("ieee39", GridCase.ieee39(), {a: {"pc": lfc.Sinusoid(0.6, 0.5, start=1.0)}
                                           for a in range(2)})):
        grid = {"kundur": kundur, "ieee39": ieee39}[name]()
        for budget in (True, False):
            options = {} if budget else {
                "mismatch_budget": False, "horizon": 16.0 if name == "kundur" else 12.0}
            outside = {}
            for level in ("sharp", "widened"):
                filt = CoupledFilter(grid, RELAYS, noise_std=NOISE, held_level=level, **options)
                assert filt.held_after_step() == 0.0
                if budget:
                    assert filt.mismatch == grid.load_mismatch and filt.options.horizon == 8.0
                r = lfc.simulate(case, duration=20.0, anti_windup=True,
                                 filters={0: filt, 1: filt}, attacks=attack, loads=step,
                                 **ESTIMATE)
                assert not r.tripped, (name, budget, level)
                assert all(a.metrics()["alarms"] > 1000 for a in r.areas)
                flagged = [a.alarms.t[a.alarms.outside.astype(bool)].to_numpy()
                           for a in r.areas]
                outside[level] = [len(f) for f in flagged]
                if name == "kundur":
                    assert all(np.all((f > 3.37) & (f < 3.40)) for f in flagged), flagged
                    for a in range(2):
                        assert np.max(np.abs(errors(r, a)["dw_meas"])) < 6e-4
            if (name, budget) in expected:
                assert outside == expected[name, budget], (name, budget)
            else:
                assert all(n > 500 for n in outside["sharp"]), outside
                assert all(50 < n < 200 for n in outside["widened"]), outside


@pytest.mark.exhaustive
def test_finding_on_kundur_a_12_s_horizon_holds_agc_after_a_legitimate_step():
    """Finding, pinned (measured): the cost of the estimate behind a stiff tie.
    Kundur as fitted to ANDES (T = 98 pu), the coupled filters on the estimate at
    ``horizon=12`` (the shortest that builds), a legitimate -0.05 pu load step in
    either area and no attack, anti-windup on: AGC does not restore frequency and
    schedules within 90 s (without filters 20.3 s after a step in area 0, 18.5 s in
    area 1; the exact-state filters 24.9 and 23.4 s).  Why: the estimate's error
    at the horizon takes almost all of the terminal ellipsoid, leaving new vectors
    a radius of 0.0011 (the exact state's at 12 s: 0.037), so a new command is
    certified only once a step's response has decayed to a few percent (the
    slowest mode, 0.116 1/s: about 30 s), and each move starts it again; the held
    vector's check still passes, so nothing is flagged and AGC waits.
    :meth:`CoupledFilter.held_after_step` says so before any run: the held
    command is not certifiable as new until 27.9 s after such a step (0 at 16 s;
    6.4 s for the exact state's filter at 8 s).  At
    ``horizon=16`` (radius 0.021) it restores in 20.3 and 18.5 s, exactly as
    without filters.  The IEEE 39-bus system's filters at 12 s (radius 0.024)
    restore as without filters (16.8 and 19.3 s).  The fitted model here leaves its
    fit's mismatch out (``load_mismatch=0``): the finding is the estimate's cost; with
    it, the default, 12 s does not build and ``"auto"`` takes 8 s, which holds
    nothing (:func:`test_the_battery_on_the_estimate_trips_nothing`)."""
    from lfc.experiments.restoration import restored_after
    grid = dataclasses.replace(kundur(), load_mismatch=0.0)   # the estimate's cost alone
    radius = {h: CoupledFilter(grid, RELAYS, noise_std=NOISE, horizon=h).data[RHO_NEW]
              for h in (12.0, 16.0)}
    assert radius[12.0] < 0.0012 < 0.02 < radius[16.0]
    held = {h: CoupledFilter(grid, RELAYS, noise_std=NOISE, horizon=h).held_after_step()
            for h in (12.0, 16.0)}
    assert held == {12.0: pytest.approx(27.88, abs=0.01), 16.0: 0.0}
    assert CoupledFilter(grid, RELAYS).held_after_step() == pytest.approx(6.44, abs=0.01)
    with pytest.raises(ValueError, match="size must lie in"):
        CoupledFilter(grid, RELAYS).held_after_step(0.07)
    for area, alone in ((0, 20.3), (1, 18.5)):
        step = {area: lfc.Step(-0.05, start=1.001)}
        r = simulate_grid_linear(grid, duration=91.0, loads=step, anti_windup=True)
        assert restored_after(r, 1.0) == pytest.approx(alone, abs=0.1)
        for h, restored in ((12.0, math.inf), (16.0, alone)):
            filt = CoupledFilter(grid, RELAYS, noise_std=NOISE, horizon=h)
            r = simulate_grid_linear(grid, duration=91.0, loads=step, anti_windup=True,
                                     filters={0: filt, 1: filt}, **ESTIMATE)
            assert not r.tripped
            assert restored_after(r, 1.0) == pytest.approx(restored, abs=0.1), (area, h)
            assert not any(a.alarms.outside.any() for a in r.areas)


@pytest.mark.long(15)
def test_an_auto_horizon_is_the_shortest_that_builds_and_keeps_agc_waiting_at_most_1_s(
        monkeypatch):
    """``horizon="auto"``, the finding above turned into a choice: on Kundur as
    fitted to ANDES on the estimate, 8 s does not build (the estimate's error
    takes the terminal set), 12 s holds a legitimate step 27.9 s, 16 s none, so it
    takes 16 s and is the ``horizon=16`` filter; the two-area preset keeps 8 s
    (it holds 0.22 s, within ``AUTO_HELD_MAX``).  At the bound's corners on two
    areas: a bound of exactly 0.22 s keeps 8 s, the next float below takes 12 s;
    with no horizon within the bound it keeps the one that holds least, the
    shortest of those that hold nothing (12 s of 12, 16, 20).  An invalid other option is named
    before anything is built, a horizon string other than "auto" is refused, and
    a grid where no horizon builds says why at each."""
    from lfc.filters.coupled import AUTO_HELD_MAX, AUTO_HORIZONS
    alone = {"mismatch_budget": False}     # the fit's mismatch aside (test_mismatch.py)
    auto = CoupledFilter(kundur(), RELAYS, noise_std=NOISE, horizon="auto", **alone)
    assert auto.options.horizon == 16.0 and list(auto.horizons) == [8.0, 12.0, 16.0]
    assert "raise horizon" in auto.horizons[8.0]
    assert auto.horizons[12.0] == pytest.approx(27.88, abs=0.01) and auto.horizons[16.0] == 0.0
    fixed = CoupledFilter(kundur(), RELAYS, noise_std=NOISE, horizon=16.0, **alone)
    assert np.array_equal(auto.data, fixed.data) and fixed.horizons == {}
    two = CoupledFilter(MultiAreaParams.two_area(), RELAYS, horizon="auto")
    assert two.options.horizon == 8.0 and two.horizons == {8.0: pytest.approx(0.22, abs=0.01)}
    assert 0.22 < AUTO_HELD_MAX
    import lfc.filters.coupled as coupled
    held = two.horizons[8.0]
    for bound, tried in ((held, [8.0]), (np.nextafter(held, 0.0), [8.0, 12.0])):
        monkeypatch.setattr(coupled, "AUTO_HELD_MAX", bound)
        f = CoupledFilter(MultiAreaParams.two_area(), RELAYS, horizon="auto")
        assert list(f.horizons) == tried and f.options.horizon == tried[-1]
    monkeypatch.setattr(coupled, "AUTO_HELD_MAX", -1.0)      # none within: the least held
    least = CoupledFilter(MultiAreaParams.two_area(), RELAYS, horizon="auto")
    assert list(least.horizons) == list(AUTO_HORIZONS) and least.options.horizon == 12.0
    assert least.horizons[12.0] == least.horizons[16.0] == least.horizons[20.0] == 0.0
    monkeypatch.undo()
    with pytest.raises(ValueError, match="tightening"):
        CoupledFilter(MultiAreaParams.two_area(), RELAYS, horizon="auto", tightening=0.5)
    with pytest.raises(TypeError, match="horizon must be a number of seconds in .* or 'auto'"):
        CoupledFilter(MultiAreaParams.two_area(), RELAYS, horizon="longest")
    with pytest.raises(ValueError, match="builds at none of 8 s .*; 12 s .*; 16 s .*; 20 s .*"
                                         "lower load_bound"):
        CoupledFilter(MultiAreaParams.two_area(), RELAYS, horizon="auto", load_bound=0.5)


@pytest.mark.exhaustive
def test_a_run_level_confidence_of_099_over_a_minute_costs_agc_little():
    """The probabilistic guarantees hold per certification at ``confidence``
    (0.9999): over a run of N control samples the union bound gives 1 - N 1e-4,
    0.8 over the batteries' 20 s at 10 ms.  Built for 0.99 over a minute (6,000
    samples: ``confidence_for_run(0.99, 6000)`` = 1 - 1.7e-6), the filters build
    and a legitimate step holds AGC a little longer: two areas 6.24 -> 7.46 s,
    Kundur at ``horizon=16`` 0 -> 0.02 s (without its fit's mismatch; with it, at
    16 s, 3.2 -> 4.9 s, where its default horizon, 8 s, holds nothing)."""
    from lfc.estimation import confidence_for_run, run_confidence
    assert run_confidence(0.9999, 2000) == pytest.approx(0.8)
    run = confidence_for_run(0.99, 6000)
    held = {}
    for name, grid, extra in (("two", MultiAreaParams.two_area(), {}),
                              ("kundur", kundur(),
                               {"horizon": 16.0, "mismatch_budget": False})):
        held[name] = [CoupledFilter(grid, RELAYS, noise_std=NOISE, confidence=c,
                                    **extra).held_after_step() for c in (0.9999, run)]
    assert held["two"] == [pytest.approx(6.24, abs=0.01), pytest.approx(7.46, abs=0.01)]
    assert held["kundur"] == [0.0, pytest.approx(0.02, abs=0.01)]
