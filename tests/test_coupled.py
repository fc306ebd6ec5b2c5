"""The coupled certificate (``lfc.filters.coupled``): every area's filter knows the
grid's state and decides in a fixed order.  Its guarantees (module docstring) are
checked here at their worst cases — a load step of exactly the bound landing 1 ms
after a control sample, during every attack of the battery, in every area — and
the battery of ``tests/test_coupled_baseline.py`` (where the per-area filters
trip 23 of 160 runs) is rerun with it."""

from __future__ import annotations

import dataclasses
import functools
import math

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lfc
from lfc import MultiAreaParams
from lfc.filters.base import INVALID, OUTSIDE
from lfc.filters.coupled import CoupledFilter, CoupledOptions
from lfc.filters.coupled_kernel import row_intervals
from lfc.multiarea import reduced_model
from lfc.experiments.restoration import agc_residue, grid_battery, restored_after, restoration
from lfc.linear_grid import simulate_grid_linear
import tiers
from test_coupled_baseline import STEP, step_battery

RELAYS = lfc.RelaySettings()
THREE = MultiAreaParams.three_area()
LIGHT = lfc.LFCParams(M=3.0, tau_g=0.2, droop=0.04, s_base_mva=1000.0)   # damping ratio 0.03


def ring(n: int, chain: bool = False) -> MultiAreaParams:
    """``n`` areas (the three-area preset's, in turn) in a ring, or a chain."""
    areas = tuple(THREE.areas[i % 3] for i in range(n))
    return MultiAreaParams(areas=areas, tie=tuple((i, (i + 1) % n, 2.0)
                                                  for i in range(n - 1 if chain else n)))


def kundur() -> MultiAreaParams:
    from lfc.testbed import GridCase, grid_design
    return grid_design(GridCase.kundur())


def ieee39() -> MultiAreaParams:
    from lfc.testbed import GridCase, grid_design
    return grid_design(GridCase.ieee39())


def battery(grid: MultiAreaParams, key: str, filt, **options) -> tuple[int, int, int]:
    """``(scenarios, runs with a trip, runs with an outside flag)``: every attack of the
    battery x every area x ``instants`` x ``signs`` of a ``step`` pu load step
    (:func:`test_coupled_baseline.step_battery`), ``filt`` at every area; the default
    tier runs the battery's recorded worst cases (``tests/tiers.py``)."""
    return step_battery(grid, f"coupled:{key}", filt, **options)


@pytest.mark.parametrize("kind", ["coupled", "contract"])
@pytest.mark.parametrize("name", ["two-area", "three-area", "kundur", "ieee39"])
def test_the_battery_trips_nothing_and_never_leaves_the_certificate(name, kind):
    """Five attacks x every area x four instants x a ±0.05 pu load step x
    anti-windup off and on (on only beyond two areas, for time), 20 s each: no trip
    and no ``outside`` flag, on the
    presets and on Kundur's two areas (T = 98 pu) and the IEEE 39-bus system's
    two areas (T = 28 pu) as fitted to ANDES, with the coupled certificate or the
    contract (``tests/test_contract.py``) at every area; on Kundur the
    per-area filters flag ``outside`` in 117 of 160 runs.  A single 0.05 pu step is
    within what the coupled held level absorbs (``load_bound - recheck_bound``) and
    within the contract's ``load_bound``, so this is the proven statement, checked."""
    grid = {"two-area": MultiAreaParams.two_area, "three-area": lambda: THREE,
            "kundur": kundur, "ieee39": ieee39}[name]()
    aw = (False, True) if name == "two-area" else (True,)
    runs, tripped, outside = battery(grid, f"battery[{name}-{kind}]", kind, anti_windup=aw)
    assert runs == 40 * len(aw) * grid.n_areas
    assert (tripped, outside) == (0, 0)


def test_rings_build_and_ride_a_step_during_every_attack():
    """Rings, whose circulating line flow is a zero eigenvalue of the line-flow
    model: the certificate's reduced model (the reachable flows) has ``6 n - 1``
    states and is Hurwitz (4 to 10 areas); on the ring of 4 the filter builds at its
    defaults and a -0.05 pu step at 3.37 s in every area during every attack trips
    nothing and flags no ``outside``.  (Rings of 6 and 10 build too:
    ``bench/bench_coupled.py``, about 10 and 60 s each.)"""
    for n in (4, 6, 10):
        A = reduced_model(ring(n))[0]
        assert len(A) == 5 * n + n - 1 and np.max(np.linalg.eigvals(A).real) < 0
    runs, tripped, outside = battery(ring(4), "ring-4", "coupled", instants=(3.37,), signs=(-1,),
                                     anti_windup=(True,))
    assert runs == 20 and (tripped, outside) == (0, 0)


@pytest.mark.long(14)
def test_a_chain_builds_at_the_defaults_with_the_shaped_terminal_set():
    """On a chain of 4 areas (the three-area preset's, in turn) the Lyapunov
    terminal set leaves no room at the defaults (a 0.05 pu step still moves the
    state at the horizon too far in its norm: the finding of the last version,
    pinned); the shaped one builds, and a -0.05 pu step at 3.37 s in every area
    during every attack trips nothing and flags no ``outside`` (theorem C)."""
    chain = ring(4, chain=True)
    with pytest.raises(ValueError, match="lower load_bound - recheck_bound"):
        CoupledFilter(chain, RELAYS, terminal="lyapunov")
    filt = CoupledFilter(chain, RELAYS)
    assert filt.cert.terminal == "sdp"
    runs, tripped, outside = battery(chain, "chain-4", filt, instants=(3.37,), signs=(-1,),
                                     anti_windup=(True,))
    assert runs == 20 and (tripped, outside) == (0, 0)


@pytest.mark.parametrize("name", ["two-area", "kundur"])
def test_a_step_of_exactly_the_bound_just_after_a_control_sample(name):
    """The worst case of the proof: a load step landing 1 ms after a control
    sample (the filter sees it only at the next one), every 0.5 s (Kundur: 1 s) of the
    attacks,
    in every area, both signs.  Of exactly ``load_bound - recheck_bound`` (0.05 pu):
    no trip and no ``outside`` (what the held level absorbs).  Of exactly
    ``load_bound`` (0.06 pu): no trip (a vector certified anew covers a total
    variation of ``load_bound`` from its certification on, whatever its re-check
    says)."""
    grid = MultiAreaParams.two_area() if name == "two-area" else kundur()
    o = CoupledOptions()
    instants = tuple(np.round(np.arange(1.0, 6.0, 0.5 if name == "two-area" else 1.0)
                              + 0.001, 6))
    runs, tripped, outside = battery(grid, f"exact-step-{name}-held", "coupled",
                                     instants=instants, step=o.load_bound - o.recheck_bound,
                                     anti_windup=(True,))
    assert (tripped, outside) == (0, 0)
    runs, tripped, _ = battery(grid, f"exact-step-{name}-bound", "coupled", instants=instants,
                               step=o.load_bound, anti_windup=(True,))
    assert runs == 5 * grid.n_areas * len(instants) * 2 and tripped == 0


def ended(n: int, stop: float) -> dict:
    """The battery's five attacks on ``n`` areas, each ending at ``stop`` s."""
    return grid_battery(n, stop=stop)


#: the attacks after which a grid's filters leave it restored later than its own AGC's pace
#: (a finding: the coupled certificate leaves the lightly damped mode ringing)
LATE = {("light", "coupled"): {"sinusoid on area 0's P_c", "coordinated sinusoid",
                               "opposite sinusoids"}}


@pytest.mark.parametrize("kind", ["coupled", "contract"])
@pytest.mark.parametrize("name", ["two-area", "three-area", "kundur", "ieee39", "light"])
def test_after_every_attack_agc_restores_frequency_and_schedules_at_its_own_pace(name, kind):
    """With anti-windup, after each attack of the battery (10 s long, a -0.05 pu step
    in area 1 during it; every attack on the two-area preset, on two lightly damped
    areas and on Kundur's and the IEEE 39-bus system's areas as fitted to ANDES, the
    ACE bias on the three-area one), with the coupled certificate or the contract at
    every area: nothing tripped, no filter flagged ``outside``, the filters fell silent
    within 5 s of the attack's end (2.7 s at most when measured), and every area's
    frequency and tie-line export were back at schedule (|dw_meas| < 5e-4 pu,
    |export| < 5e-3 pu) within the time the grid's own AGC, alone, takes to restore a
    legitimate step of the load the attack left in its integrators, plus 10 s
    (``lfc.experiments.restoration``; measured at most 5.3 s beyond AGC alone's time
    on these grids, up to 73.6 s for AGC alone after the square on two lightly damped
    areas).  Pinned exception (``LATE``): on two lightly damped areas the coupled
    certificate after the three sinusoids is back 11.8-14.9 s beyond AGC alone's time
    (restored 41-52 s after the attack's end): it let the grid go to its relay limits
    and leaves the lightly damped mode ringing; the contracts are back at AGC's pace
    after all five."""
    grid = {"two-area": MultiAreaParams.two_area, "three-area": lambda: THREE,
            "kundur": kundur, "ieee39": ieee39,
            "light": lambda: MultiAreaParams.two_area(LIGHT)}[name]()
    every = {a: kind for a in range(grid.n_areas)}
    attacks = ended(grid.n_areas, 11.0)
    late = set()
    for key in ["bias on every ACE"] if name == "three-area" else attacks:
        r = simulate_grid_linear(grid, duration=131.0 if name == "light" else 81.0,
                                 attacks=attacks[key], filters=every,
                                 loads={1: lfc.Step(-STEP, start=5.001)}, anti_windup=True)
        assert not r.tripped, key
        for a in range(grid.n_areas):
            alarms = r.areas[a].alarms
            assert not alarms.outside.any() and (alarms.empty or alarms.t.max() < 16.0), key
        pace = restoration(grid, r, 11.0)
        assert math.isfinite(pace.restored) and pace.agc_alone > 0.0, key
        if not pace.at_agc_pace:
            late.add(key)
    assert late == LATE.get((name, kind), set())


def test_where_it_cannot_be_built_it_says_why():
    """An unstable held grid (the default area behind a T = 98 pu tie: the
    inter-area mode grows at 0.07 1/s with every command held, so no hold is
    safe) and a lightly damped area (ratio 0.03), whose state at the horizon still
    carries a load step's response, so the held level cannot absorb one: a
    ``ValueError`` naming the reason and what to change."""
    with pytest.raises(ValueError, match="not asymptotically stable"):
        CoupledFilter(MultiAreaParams.two_area(T=98.0), RELAYS)
    light = MultiAreaParams(areas=THREE.areas[:2] + (LIGHT,), tie=THREE.tie)
    with pytest.raises(ValueError, match="lower load_bound - recheck_bound"):
        CoupledFilter(light, RELAYS, terminal="lyapunov")    # the shaped one builds
    # two areas behind T = 60 pu (stable when held, barely) asked to ride 0.08 pu of
    # load: neither terminal set fits, and the message does not send the user to the
    # one that was tried first (at the default 0.06 pu the shaped one builds, its
    # solver's Q moved inside its inequality: measured on an AMD EPYC, 2026-11-29)
    with pytest.raises(ValueError, match="and the Lyapunov ellipsoid, tried first, leaves no "
                                         "room .*lower load_bound or tightening"):
        CoupledFilter(MultiAreaParams.two_area(T=60.0), RELAYS, load_bound=0.08)
    with pytest.raises(ValueError, match="terminal must be one of"):
        CoupledFilter(THREE, RELAYS, terminal="box")
    with pytest.raises(ValueError, match="recheck_bound"):
        CoupledFilter(THREE, RELAYS, load_bound=0.01, recheck_bound=0.02)


def test_behind_soft_and_stiff_ties_the_defaults_build_and_ride_the_battery():
    """Found by chapter 10's scaling figure, fixed: on two areas behind T = 1 pu
    and T = 50 pu ties the Lyapunov terminal set leaves no room and the shaped
    one's semidefinite program returned an inaccurate ``Q`` (smallest eigenvalue
    about 1e-9) whose inverse was not invariant in floating point, so the
    defaults did not build.  With ``Q``'s smallest eigenvalue floored
    (``Q_FLOORS``, the first floor that gives an invariant ellipsoid: 1e-6 and
    1e-5 on Intel; on an AMD EPYC none does at T = 50 pu, and the solver's ``Q``
    moved inside its inequality does: the next test) both build (``shaped_terminal`` checks the invariance) and ride the battery at one
    instant (anti-windup): 0 trips, 0 ``outside`` (the full battery, 80 runs
    each, 0 / 0: ``python bench/survey_grid_certificates.py --chains``).  The
    contract builds there too."""
    from lfc.filters.contract import contract_design
    for T in (1.0, 50.0):
        grid = MultiAreaParams.two_area(T=T)
        assert CoupledFilter(grid, RELAYS).cert.terminal == "sdp"   # invariant: checked there
        runs, tripped, outside = battery(grid, f"two-area-T{T:g}", "coupled", instants=(3.37,),
                                         anti_windup=(True,))
        assert runs == 20 and (tripped, outside) == (0, 0), T
        assert contract_design(grid, RELAYS).half_width.min() > 0.1


def test_an_ellipsoid_the_solver_left_just_outside_invariance_is_moved_inside():
    """Found on an AMD EPYC (2026-11-29): behind T = 50 pu the solver's ``Q`` met
    ``A Q + Q A' <= 0`` only to its tolerance (about 5e-7 too high) at every floor,
    where Intel's BLAS kernels gave one that passed, so the defaults did not build
    there.  ``made_invariant`` moves such a ``Q`` inside: given one whose
    inequality is off by 1e-6 (a Lyapunov solution pushed out along its top
    eigenvector), the result makes ``A Q + Q A'`` negative definite and keeps
    every output's reach within its room."""
    from lfc.filters.coupled_set import made_invariant, output_rows
    from scipy.linalg import solve_continuous_lyapunov
    A, _, _, _ = reduced_model(MultiAreaParams.two_area(T=50.0))
    n = len(A)
    C = output_rows(2, n)
    Q = solve_continuous_lyapunov(A, -np.eye(n))            # A Q + Q A' = -I
    v = np.eye(n)[0]
    # A bad + bad A' = -I + (1 + 1e-6) v v': its largest eigenvalue is 1e-6
    bad = Q + solve_continuous_lyapunov(A, (1.0 + 1e-6) * np.outer(v, v))
    assert np.max(np.linalg.eigvalsh(A @ bad + bad @ A.T)) == pytest.approx(1e-6, rel=1e-3)
    room = 1.01 * np.sqrt(np.einsum("ij,jk,ik->i", C, bad, C))
    good = made_invariant(A, C, bad, room)
    assert np.max(np.linalg.eigvalsh(A @ good + good @ A.T)) < 0
    assert np.all(np.einsum("ij,jk,ik->i", C, good, C) <= room ** 2 * (1 + 1e-12))
    assert np.min(np.linalg.eigvalsh(good)) > 0


def test_the_shaped_terminal_set_builds_where_the_lyapunov_one_leaves_no_room():
    """The Lyapunov ellipsoid overstates what a held load step leaves at the
    horizon 37-67 times on a lightly damped area and on chains (``kappa sigma``
    per pu of load, against the relay limit); the ellipsoid shaped by the
    semidefinite program brings that to 0.5-3, and the defaults build there
    (``terminal="auto"``), keeping the Lyapunov one where it has room.  The shaped
    one is invariant (``A'P + PA`` negative definite) and keeps every output
    within its room."""
    from lfc.filters.coupled_set import output_rows, shaped_terminal
    light = MultiAreaParams(areas=THREE.areas[:2] + (LIGHT,), tie=THREE.tie)
    assert CoupledFilter(light, RELAYS).cert.terminal == "sdp"
    assert CoupledFilter(THREE, RELAYS).cert.terminal == "lyapunov"
    A, _, Bl, _ = reduced_model(light)
    C = output_rows(3, len(A))
    room = np.tile([RELAYS.F, RELAYS.rocof_limit], 3)
    loads = -np.linalg.solve(A, Bl)
    P = shaped_terminal(A, C, loads, room)
    assert np.max(np.linalg.eigvalsh(A.T @ P + P @ A)) < 0
    reach = np.sqrt(np.einsum("ij,jk,ik->i", C, np.linalg.inv(P), C))
    assert np.all(reach <= room * (1 + 1e-6))


@pytest.mark.long(47)
@pytest.mark.parametrize("kind", ["coupled", "contract"])
def test_a_lightly_damped_area_rides_the_battery_inside_its_certificate(kind):
    """The lightly damped grid at the defaults (for the coupled certificate, with
    the shaped terminal set): the battery's five attacks x every area x four
    instants x a ±0.05 pu step (anti-windup on): no trip and no ``outside`` — the
    proven statements (C) and (D); with the coupled certificate
    ``load_bound = recheck_bound`` used to leave most runs flagged."""
    grid = MultiAreaParams(areas=THREE.areas[:2] + (LIGHT,), tie=THREE.tie)
    runs, tripped, outside = battery(grid, f"light-{kind}", kind, anti_windup=(True,))
    assert runs == 120 and (tripped, outside) == (0, 0)


def residue_in(r, areas, end: float) -> float:
    """The most load left in the AGC integrators of ``areas`` at ``end`` s (pu)."""
    return float(np.abs(agc_residue(r, end)[list(areas)]).max())


@pytest.mark.exhaustive
def test_finding_on_two_lightly_damped_areas_agc_restores_in_up_to_a_minute():
    """Finding, pinned (measured): on two lightly damped areas (ratio 0.03), after
    each attack of the battery (10 s long, a -0.05 pu step in area 1 during it,
    anti-windup on), the filters fall silent within 1.5 s of the attack's end and
    nothing trips, but AGC takes longer than a fixed 40 s goal to bring frequency
    and schedules back from where the attack left the grid: with the contracts
    25-43 s (42.6 s after the ACE bias when measured), with the coupled
    certificate 41-59 s (all five attacks beyond 40 s).  The same step
    without an attack is restored in 29 s with or without the contracts (they
    never act on it).  Hence the goal measured against the grid's own AGC
    (``lfc.experiments.restoration``, checked on every grid by
    ``test_after_every_attack_agc_restores_frequency_and_schedules_at_its_own_pace``).

    Why (measured here): a fixed 40 s is beyond this grid's AGC itself, which
    restores a legitimate 0.1 pu step, no attack, no filter, in 42.7 s (0.05 pu
    in 32 s); and what an attack leaves behind is larger.  The attacks on AGC's
    own inputs (the square on ω_ref, the ACE bias) leave 0.29-0.50 pu in its
    integrators at the control centre (the filters never see them: the commands
    they produce after the attack are legitimate AGC), to be unwound at AGC's
    pace; under the sinusoids the coupled certificate, which lets the grid go to
    its relay limits, leaves the lightly damped mode ringing (|Δω| 0.004-0.007 pu
    at the attack's end, 8-14 times the restoration tolerance)."""
    grid = MultiAreaParams.two_area(LIGHT)
    attacks = ended(2, 11.0)
    late, residue = {}, {}
    for kind in ("contract", "coupled"):
        every = {a: kind for a in range(2)}
        times = []
        for key, attack in attacks.items():
            r = simulate_grid_linear(grid, duration=131.0, attacks=attack, filters=every,
                                     loads={1: lfc.Step(-STEP, start=5.001)}, anti_windup=True)
            assert not r.tripped, (kind, key)
            for res in r.areas:
                assert not res.alarms.outside.any() and (res.alarms.empty
                                                         or res.alarms.t.max() < 12.5), key
            times.append(restored_after(r, 11.0))
            residue[kind, key] = residue_in(r, range(2), 11.0)   # the attack's end
        late[kind] = sum(t > 40.0 for t in times)
        assert 20.0 < min(times) and max(times) < {"contract": 45.0, "coupled": 65.0}[kind], kind
    assert late == {"contract": 1, "coupled": 5}
    on_inputs = ("square on area 0's ω_ref", "bias on every ACE")
    assert min(residue["coupled", k] for k in on_inputs) > 0.25
    assert residue["contract", "bias on every ACE"] > 0.25
    step = {1: lfc.Step(-STEP, start=1.0)}
    alone = simulate_grid_linear(grid, duration=60.0, loads=step, anti_windup=True,
                                 filters={0: "contract", 1: "contract"})
    assert all(res.alarms.empty for res in alone.areas)
    assert 25.0 < restored_after(alone, 1.0) < 35.0
    agc = simulate_grid_linear(grid, duration=100.0, loads={1: lfc.Step(0.1, start=1.0)},
                               anti_windup=True)
    assert not agc.tripped and 40.0 < restored_after(agc, 1.0) < 45.0


#: AGC integral gains (1/s) tried on two lightly damped areas: around the default
#: ``k_i / B`` (the second), from half of it to four times it
LIGHT_AGC_GAINS = (0.05, float(MultiAreaParams.two_area(LIGHT).agc_gains()[1][0]), 0.1, 0.15,
                   0.2, 0.3)


def agc_alone_on_light(k_agc: float, step: float) -> tuple[float, bool]:
    """Two lightly damped areas, AGC gain ``k_agc`` (1/s), no attack, no filter,
    anti-windup: seconds until a ``-step`` pu step in area 1 at 1 s is restored
    (``restored_after``; 120 if not within the 121 s run), and whether it tripped."""
    grid = dataclasses.replace(MultiAreaParams.two_area(LIGHT), k_agc=(k_agc, k_agc))
    r = simulate_grid_linear(grid, duration=121.0, loads={1: lfc.Step(-step, start=1.0)},
                             anti_windup=True)
    return restored_after(r, 1.0), r.tripped


def test_finding_on_two_lightly_damped_areas_no_agc_gain_restores_a_tenth_pu_step_in_40_s():
    """Finding, pinned (measured): why the 40 s restoration goal is beyond the
    lightly damped grid's AGC, not only beyond its filters.  With no attack and no
    filter, a -0.1 pu step in area 1 is restored (``restored_after``) in no less
    than 42 s at any AGC integral gain ``k_agc`` tried, from half the default
    (``k_i / B`` = 0.077 1/s) to four times it: the default is the fastest; a faster
    integrator rings with the lightly damped mode (not restored within 120 s at
    0.2 1/s), and 0.3 1/s trips.  ``python bench/survey_grid_certificates.py
    --restoration`` prints the table."""
    default = LIGHT_AGC_GAINS[1]
    restored, tripped = {}, {}
    for k in LIGHT_AGC_GAINS:
        restored[k], tripped[k] = agc_alone_on_light(k, 0.1)
    assert min(restored.values()) == restored[default]
    assert 42.0 < restored[default] < 43.5
    assert restored[0.2] >= 119.0 and not tripped[0.2]
    assert tripped[0.3] and not any(tripped[k] for k in (0.05, default, 0.1, 0.15))


@pytest.mark.exhaustive
def test_finding_on_a_chain_of_four_a_square_on_wref_leaves_agc_a_minute_of_unwinding():
    """Finding, pinned (measured): on a chain of four areas (the three-area
    preset's, T = 2 pu) the battery's other four attacks are restored within 29 s
    of their end with the contracts and 35 s with the coupled certificate (when
    measured; a ring of four: all five within 34 s), but after the square on
    area 0's ω_ref (10 s long, a -0.05 pu step in area 1 during
    it, anti-windup on) the coupled certificate's run is back at schedule only
    50-65 s after the attack's end (59.7 s when measured), the contracts' in
    35-45 s (40.6 s); nothing trips, no ``outside``.  Why: the attack on AGC's own
    frequency reference leaves 0.29 pu in area 0's integrator at the control
    centre when it ends (the contracts, whose box is ±0.085 pu, let 0.09 pu
    through), which AGC unwinds at its pace: it restores a legitimate 0.1 pu
    step, no attack, no filter, in 35 s on this grid.  The same finding as on
    two lightly damped areas: what an attack on AGC's inputs leaves is beyond
    what a generator-side filter sees; both runs are back within the time AGC
    alone takes to restore a step of what the attack left in its integrators
    (63.3 s and 41.7 s when measured) plus 10 s (``lfc.experiments.restoration``)."""
    chain = ring(4, chain=True)
    attack = ended(4, 11.0)["square on area 0's ω_ref"]
    late, residue = {}, {}
    for kind in ("coupled", "contract"):
        r = simulate_grid_linear(chain, duration=81.0, attacks=attack,
                                 filters={a: kind for a in range(4)},
                                 loads={1: lfc.Step(-STEP, start=5.001)}, anti_windup=True)
        assert not r.tripped and not any(res.alarms.outside.any() for res in r.areas)
        late[kind] = restored_after(r, 11.0)
        residue[kind] = residue_in(r, [0], 11.0)
        assert restoration(chain, r, 11.0).at_agc_pace, kind
    assert 50.0 < late["coupled"] < 65.0 and 35.0 < late["contract"] < 45.0
    assert residue["coupled"] > 0.25 and 0.05 < residue["contract"] < 0.1
    agc = simulate_grid_linear(chain, duration=80.0, loads={1: lfc.Step(-0.1, start=1.0)},
                               anti_windup=True)
    assert not agc.tripped and 30.0 < restored_after(agc, 1.0) < 40.0


def test_finding_a_lightly_damped_area_flags_outside_but_trips_nothing():
    """Finding, pinned: with ``load_bound = recheck_bound`` = 0.05 pu (nothing for
    the held level to absorb) the filter builds on the lightly damped grid; over
    the battery nothing trips — proven: each applied vector was certified anew and
    a single 0.05 pu step is within ``load_bound`` from then on — but most runs
    flag ``outside`` after the step (185 of 240 over the whole battery when measured;
    here the negative steps with anti-windup): the held vector's
    re-check, made for the load now, cannot vouch for it."""
    grid = MultiAreaParams(areas=THREE.areas[:2] + (LIGHT,), tie=THREE.tie)
    filt = CoupledFilter(grid, RELAYS, load_bound=0.05, recheck_bound=0.05)
    runs, tripped, outside = battery(grid, "light-no-room", filt, signs=(-1,),
                                     anti_windup=(True,))
    assert runs == 60 and tripped == 0 and outside > 0
    if tiers.exhaustive():
        assert 30 <= outside <= 60


def test_the_filters_share_one_certificate_and_refuse_what_breaks_it():
    """Every area must have the same coupled filter; no estimator (exact state),
    or its own grid Kalman filter if built with ``noise_std``; the simulation's
    period; a generator side driven by another plant (ANDES) must be given the
    grid, and on the estimate the estimator's arrays."""
    grid = MultiAreaParams.two_area()
    filt = CoupledFilter(grid, RELAYS)
    with pytest.raises(ValueError, match="same CoupledFilter at every area"):
        lfc.simulate(grid, duration=1.0, filters={0: filt})
    with pytest.raises(ValueError, match="same CoupledFilter at every area"):
        lfc.simulate(grid, duration=1.0, filters={0: filt, 1: "certified"})
    with pytest.raises(ValueError, match="exact state"):
        lfc.simulate(grid, duration=1.0, filters={0: filt, 1: filt}, estimator="kalman",
                     noise_std=(1e-4, 1e-3))
    with pytest.raises(ValueError, match="control_period"):
        lfc.simulate(grid, duration=1.0, filters={0: filt, 1: filt}, control_period=0.02)
    with pytest.raises(ValueError, match="built for"):
        lfc.simulate(THREE, duration=1.0, filters={a: filt for a in range(3)})
    from lfc.generator import GeneratorSide, GridReading
    with pytest.raises(ValueError, match="exact state"):
        GeneratorSide(grid.areas[0], filt, "kalman", (1e-4, 1e-3), 0, np.arange(3) * 0.01,
                      None, None, False, 0.01)
    side = GeneratorSide(grid.areas[0], filt, None, (0.0, 0.0), 0, np.arange(3) * 0.01, None,
                         None, False, 0.01)
    with pytest.raises(ValueError, match="needs grid"):
        side.step(0, np.zeros(5), 0.0)
    estimating = CoupledFilter(grid, RELAYS, noise_std=(1e-4, 1e-3))
    with pytest.raises(ValueError, match="give estimator='kalman'"):
        GeneratorSide(grid.areas[0], estimating, None, (1e-4, 1e-3), 0, np.arange(3) * 0.01,
                      None, None, False, 0.01)
    side = GeneratorSide(grid.areas[0], estimating, "kalman", (1e-4, 1e-3), 0,
                         np.arange(3) * 0.01, None, None, False, 0.01)
    with pytest.raises(ValueError, match="on its estimate also"):   # the estimator's arrays
        side.step(0, np.zeros(5), 0.0, 0.0, GridReading(0, np.zeros(grid.n_states),
                                                        np.zeros(2), np.zeros(2)))


def test_the_tightest_case_a_search_found_reaches_the_certificates_ceiling_and_holds():
    """Theorem A attacked where it is weakest (2026-11-27: differential evolution
    and hand batteries, about 25,000 runs on two- and three-area grids, Kundur,
    chains, corners of the relays and control periods, load paths of total
    variation exactly ``load_bound``): no trip, no ``outside`` below the bound.
    The closest, pinned here: two lightly damped areas, a 5 pu 0.3 Hz square on
    area 0's reference, a step of exactly ``load_bound`` (0.06 pu) when area 0's
    vector was certified, relays that trip at any instant beyond a limit (no
    delay), a 0.25 ms plant step.  Area 0's frequency peaks at 0.992 of its
    limit: the held vector's own prediction sits on its tightest row (slack 0)
    and the step adds its full load gain, so what is left is the allowance
    between samples.  The certificate is tight there,
    and holds; without the step the peak is 0.79."""
    grid = MultiAreaParams.two_area(LIGHT)
    relays = dataclasses.replace(RELAYS, of2_delay=0.0, uf2_delay=0.0)
    run = dict(duration=7.0, dt=2.5e-4, relays=relays, anti_windup=True,
               filters={0: "coupled", 1: "coupled"},
               attacks={0: {"wref": lfc.Square(5.0, 0.3, start=1.0)}})
    for start in (3.8815, 3.8865, 3.8915):
        r = simulate_grid_linear(grid, loads={0: lfc.Step(0.06, start=start)}, **run)
        m = r.metrics()
        assert not r.tripped and m[0]["outside"] == m[1]["outside"] == 0
        assert 0.99 < m[0]["max_abs_dw_meas"] / relays.F < 1.0
    alone = simulate_grid_linear(grid, **run).metrics()[0]["max_abs_dw_meas"] / relays.F
    assert 0.75 < alone < 0.85


def test_a_call_never_raises_and_says_why():
    """Called directly: at equilibrium a command inside the interval passes; a huge
    one is clipped (active, certified); a corrupted state holds the last command
    and flags ``invalid_input``; every command returned is finite."""
    grid = MultiAreaParams.two_area()
    filt = CoupledFilter(grid, RELAYS)
    x, u, p, mem = np.zeros(grid.n_states), np.zeros(2), np.zeros(2), np.zeros(2)
    v, flags, why = filt.filter(x, u, p, 0, 1e-4, mem)
    assert v == 1e-4 and flags == 0 and why == ""
    v, flags, why = filt.filter(x, u, p, 1, 50.0, mem.copy())
    assert 0 < v < 1.0 and flags & 1 and "clipped" in why
    bad = x.copy()
    bad[3] = np.nan
    v, flags, why = filt.filter(bad, u, p, 0, 0.3, mem)
    assert v == 1e-4 and flags & INVALID and not flags & OUTSIDE and "invalid" in why
    with pytest.raises(ValueError, match="area must be"):
        filt.filter(x, u, p, 2, 0.0, mem)
    with pytest.raises(ValueError, match="recheck_bound"):
        CoupledOptions(load_bound=0.0)


def intervals_row_by_row(rows: np.ndarray, n_s: int, x: np.ndarray, u: np.ndarray,
                         p: np.ndarray, k: int) -> tuple:
    """``lfc.filters.coupled_kernel.row_intervals`` written out in Python, one
    row of ``rows`` (bound new, bound held, the state's, the commands' and the
    loads' gains) after another: the specification the compiled pass must equal."""
    n_a, inf = len(u), math.inf
    lo_f, hi_f, lo_r, hi_r, lo_h, hi_h = -inf, inf, -inf, inf, -inf, inf
    for r, row in enumerate(rows.tolist()):
        s = 0.0
        for c in range(n_s):
            s += row[2 + c] * float(x[c])
        for j in range(n_a):
            s += row[2 + n_s + j] * float(u[j]) + row[2 + n_s + n_a + j] * float(p[j])
        h = row[2 + n_s + k]
        s -= h * float(u[k])
        bn, bh = row[0], row[1]
        if h != 0.0:
            a1, a2, c1, c2 = (-bn - s) / h, (bn - s) / h, (-bh - s) / h, (bh - s) / h
            lo_n, hi_n, lo_hh, hi_hh = min(a1, a2), max(a1, a2), min(c1, c2), max(c1, c2)
        else:
            lo_n, hi_n = (-inf, inf) if abs(s) <= bn else (inf, -inf)
            lo_hh, hi_hh = (-inf, inf) if abs(s) <= bh else (inf, -inf)
        if r % 2 == 0:
            lo_f, hi_f = max(lo_f, lo_n), min(hi_f, hi_n)
        else:
            lo_r, hi_r = max(lo_r, lo_n), min(hi_r, hi_n)
        lo_h, hi_h = max(lo_h, lo_hh), min(hi_h, hi_hh)
    return lo_f, hi_f, lo_r, hi_r, lo_h, hi_h


@functools.lru_cache(maxsize=None)
def certificate(name: str) -> tuple:
    """``(grid, its coupled certificate at the defaults)`` for a preset's name."""
    grid = {"two-area": MultiAreaParams.two_area, "three-area": lambda: THREE}[name]()
    return grid, CoupledFilter(grid, RELAYS).cert


@numba.njit
def _columns(fd, x, u, p, k, sums):
    return row_intervals(fd, x, u, p, k, sums)


@settings(max_examples=tiers.examples(25), deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), scale=st.floats(-6.0, 0.5), grid=st.sampled_from(
    ["two-area", "three-area"]))
def test_summing_the_rows_column_by_column_equals_row_by_row_bit_for_bit(seed, scale, grid):
    """The filter sums all its rows at once, one column after another (SIMD lanes);
    its six intervals equal, bit for bit, those of one row after another (states
    from 1e-6 to 3 pu, commands to about 1 pu, loads to 0.15 pu, every area)."""
    params, cert = certificate(grid)
    rng = np.random.default_rng(seed)
    x = rng.normal(size=params.n_states) * 10.0 ** scale
    u, p = rng.normal(size=params.n_areas) * 0.3, rng.normal(size=params.n_areas) * 0.05
    sums = np.full(cert.n_rows, np.nan)           # scratch: whatever it held is overwritten
    for k in range(params.n_areas):
        got = np.array(_columns(cert.data, x, u, p, k, sums))
        want = np.array(intervals_row_by_row(cert.rows, params.n_states, x, u, p, k))
        assert got.tobytes() == want.tobytes(), (k, got, want)


@pytest.mark.parametrize("kind", ["coupled", "contract"])
@pytest.mark.parametrize("family", ["sinusoid on P_c", "square on ω_ref", "bias on ACE",
                                    "ramp on ω_ref"])
def test_the_red_teams_coordinated_search_trips_nothing(family, kind):
    """The red team's coordinated search (differential evolution over the family's
    parameters in both areas at once, maximizing the worst relay severity) against
    the coupled filters or the contracts of the two-area preset: its worst attack
    stays inside every relay (severity < 1), where it drives the paper's SCC past
    them (``tests/test_multiarea.py``)."""
    from lfc.experiments.redteam import coordinated_attacks, coordinated_search, severity
    grid = MultiAreaParams.two_area()
    every = {0: kind, 1: kind}
    found = tiers.searched(f"coupled:red-team[{family}-{kind}]", lambda: coordinated_search(
        grid, every, family, duration=20.0, maxiter=2, popsize=4, jobs=1))
    assert not found["tripped"] and found["severity"] < 1.0
    replayed = simulate_grid_linear(grid, duration=20.0, filters=every, attacks=(
        coordinated_attacks(family, found["theta"], 2, 20.0)))
    worst = max(float(severity(m, RELAYS)) for m in replayed.metrics().values())
    assert worst == pytest.approx(found["severity"], rel=1e-6) and not replayed.tripped


def test_finding_a_step_four_times_the_bound_during_an_attack_trips_after_outside():
    """Finding, pinned (attacking the guarantee where it ends): opposite 1 pu,
    0.5 Hz sinusoids on both areas' commands and a -0.2 pu load step in area 0
    (total variation 0.2 pu, beyond ``load_bound`` = 0.06 pu and the 0.01 pu per
    period): ROCOF trips, after the filters flagged ``outside`` (the step alone,
    without attack or filter, does not trip: its ROCOF peaks at 0.045 pu/s).
    Steps of 0.1 and 0.15 pu, also beyond the proof, trip nothing (measured)."""
    grid = MultiAreaParams.two_area()
    every = {0: "coupled", 1: "coupled"}
    attack = {a: {"pc": lfc.Sinusoid((-1.0) ** a, 0.5, start=1.0)} for a in range(2)}

    def run(step):
        return lfc.simulate(grid, duration=30.0, attacks=attack, filters=every,
                            loads={0: lfc.Step(step, start=3.001)}, anti_windup=True)

    r = run(-0.2)
    assert r.tripped
    first_trip = min(a.metrics()["first_trip_t"] or np.inf for a in r.areas)
    first_outside = min(a.alarms.query("outside").t.min() for a in r.areas)
    assert 3.0 < first_outside < first_trip
    assert not lfc.simulate(grid, duration=30.0, loads={0: lfc.Step(-0.2, start=3.001)}).tripped
    for step in (-0.1, -0.15):
        assert not run(step).tripped


def test_the_commands_stay_within_the_design_models_command_range():
    """A design model that holds only within ``±command_range`` (one fitted to
    ANDES, :func:`lfc.testbed.fit.validated_range`) gives its coupled filters
    that range as ``u_min``/``u_max``: under a 1 pu sinusoid on area 0's command
    every applied command stays within it and nothing trips; an explicit
    ``u_min``/``u_max`` overrides it, and a model without a range has none."""
    grid = dataclasses.replace(MultiAreaParams.two_area(), command_range=0.05)
    f = CoupledFilter(grid, RELAYS)
    assert (f.options.u_min, f.options.u_max) == (-0.05, 0.05)
    assert CoupledFilter(grid, RELAYS, u_min=-1.0, u_max=1.0).options.u_max == 1.0
    assert CoupledFilter(MultiAreaParams.two_area(), RELAYS).options.u_max == np.inf
    r = lfc.simulate(grid, duration=10.0, filters={0: "coupled", 1: "coupled"},
                     attacks={0: {"pc": lfc.Sinusoid(1.0, 0.5, start=1.0)}})
    assert not r.tripped
    assert max(float(a.controls.pc.abs().max()) for a in r.areas) == pytest.approx(0.05)


@pytest.mark.andes_recorded
def test_on_andes_kundur_the_coupled_filters_never_leave_their_certificate():
    """Kundur's two-area system on ANDES (measured, not proven: the certificate is
    built on the fitted model), a -2.5 pu bias on both areas' ACE and a -0.05 pu
    load step in area 1 at 3.37 s: with the coupled filters (the grid's state
    from each area's metered states and tie-line export) nothing trips and no
    filter flags ``outside``; the per-area certified filters also trip nothing but
    leave their certificate (hundreds of ``outside`` samples)."""
    from lfc.testbed import GridCase
    case = GridCase.kundur()
    run = dict(duration=20.0, attacks={a: {"ace": lfc.Step(-2.5, start=1.0)} for a in range(2)},
               loads={1: lfc.Step(-STEP, start=3.37)}, anti_windup=True)
    coupled = lfc.simulate(case, filters={0: "coupled", 1: "coupled"}, **run)
    assert not coupled.tripped
    assert [int(a.alarms.outside.sum()) for a in coupled.areas] == [0, 0]
    assert all(a.metrics()["alarms"] > 0 for a in coupled.areas)
    per_area = lfc.simulate(case, filters={0: "certified", 1: "certified"}, **run)
    assert not per_area.tripped
    assert sum(int(a.alarms.outside.sum()) for a in per_area.areas) > 100


@pytest.mark.andes_recorded
def test_finding_on_andes_ieee39_without_the_fits_mismatch_the_filters_leave_their_certificate():
    """Finding, pinned (measured, the fit's mismatch): the IEEE 39-bus system's two
    areas on ANDES under chapter 09's coordinated attack (a 0.6 pu, 0.5 Hz
    sinusoid on both areas' commands) and a -0.05 pu load step in area 1: the
    coupled filters built on the fitted model without its mismatch
    (``mismatch_budget=False``: the load budget 0.06 pu, the 0.05 pu step its
    whole; commands within its ±0.2 pu range) trip nothing but flag ``outside`` at
    hundreds of samples (267 and 265 when measured) — ANDES' trajectory leaves
    what the fitted model certified.  With the mismatch, the default, they flag
    nothing (the next test)."""
    from lfc.testbed import GridCase, grid_design
    case = GridCase.ieee39()
    alone = CoupledFilter(grid_design(case), RELAYS, mismatch_budget=False)
    assert alone.mismatch == 0.0 and alone.options.horizon == 8.0
    r = lfc.simulate(case, duration=20.0, anti_windup=True,
                     attacks={a: {"pc": lfc.Sinusoid(0.6, 0.5, start=1.0)} for a in range(2)},
                     loads={1: lfc.Step(-STEP, start=3.37)}, filters={0: alone, 1: alone})
    assert not r.tripped
    assert all(int(a.alarms.outside.sum()) > 100 for a in r.areas)


@pytest.mark.andes_recorded
def test_on_andes_ieee39_the_fits_mismatch_as_load_budget_leaves_no_outside():
    """Measured (not proven: ANDES is not the fitted model, and its mismatch is
    measured on the fit's records) — the default coupled filter of the IEEE 39-bus
    fit adds the fit's mismatch as load (``load_mismatch``, 0.27 pu: the swing of the
    load that makes the model reproduce ANDES' rotor speeds, summed over the areas,
    at the largest rung of the command range) to its 0.06 pu ``load_bound``, and
    chooses its horizon with it (``"auto"``: the shortest that builds and holds a
    legitimate 0.05 pu step at most 1 s; 8 s).  The same run as the finding above
    flags no ``outside`` and trips nothing, and the price on the model is nil here:
    a legitimate 0.05 pu step holds no area's AGC (``held_after_step`` 0 s)."""
    from lfc.testbed import GridCase, grid_design
    case = GridCase.ieee39()
    design = grid_design(case)
    filt = CoupledFilter(design, RELAYS)
    assert filt.mismatch == design.load_mismatch == pytest.approx(0.27, abs=0.005)
    assert filt.options.horizon == 8.0 and filt.horizons
    assert filt.held_after_step() == 0.0
    r = lfc.simulate(case, duration=20.0, anti_windup=True,
                     attacks={a: {"pc": lfc.Sinusoid(0.6, 0.5, start=1.0)} for a in range(2)},
                     loads={1: lfc.Step(-STEP, start=3.37)}, filters={0: filt, 1: filt})
    assert not r.tripped
    assert [int(a.alarms.outside.sum()) for a in r.areas] == [0, 0]


@pytest.mark.andes_recorded
# Not marked long (it takes about 190 s of CPU): started first, it waited 159 s, idle,
# for the IEEE 39-bus fit the chapter 09 test computes on the other worker (measured
# with a per-test CPU record of the suite); in file order the fit is done by then.
def test_on_andes_ieee39_the_red_teams_winner_leaves_the_certificate_only_beyond_the_range():
    """Measured on ANDES (the coupled certificate is the fitted model's, not
    ANDES'): the red team's coordinated search (a square wave on both areas'
    commands) against the coupled filters of the IEEE 39-bus system's areas as
    fitted to ANDES.

    * As built by default — every command within the fitted model's range
      (±0.2 pu, 1 GW: ``lfc.testbed.fit.validated_range``) and the fit's mismatch
      within it (0.27 pu) added to the load budget: its winner trips neither the
      fitted model (severity 0.43) nor ANDES, and no filter flags ``outside``
      there (18 samples per area without the mismatch, when measured).
    * Finding, pinned — why the range: without it and without the mismatch
      (``u_min``/``u_max`` = ∓∞, ``mismatch_budget=False``) the winner trips
      nothing on the fitted model (severity 0.38); on ANDES the filters hold
      commands up to 0.57 pu (2.8 GW), far beyond where the linear tie describes
      ANDES', and flag ``outside`` at 311 samples per area — the fitted model's
      certificate no longer covers ANDES, and the filters say so.  It does not trip
      there (severity 0.35); before the enclosures of the Rigor issue, whose gains
      are about 1 % smaller, the same attack tripped ROCOF after the flags.
    * Finding, pinned — why the mismatch needs the range: with the mismatch budget
      and no range, the winner of a search against those filters (severity 0.48
      on the model) drives the commands to 0.88 pu on ANDES and trips ROCOF at
      5.8 s *without any flag* (measured): the budget was measured within the range,
      and is blind beyond it.  So the filter refuses that combination.
    * The per-area certified filters, kept within the same range
      (``linear_grid.area_filter``), trip nothing on the unbounded winner; without
      the range they trip on it; nor do the contracts (boxes of ±0.095 pu with the
      mismatch)."""
    from lfc.experiments.redteam import coordinated_attacks, coordinated_search
    from lfc.testbed import GridCase, grid_design
    case = GridCase.ieee39()
    design = grid_design(case)
    assert design.command_range == 0.2
    with pytest.raises(ValueError, match="command_range"):
        CoupledFilter(design, RELAYS, u_min=-np.inf, u_max=np.inf)
    unbounded = CoupledFilter(design, RELAYS, u_min=-np.inf, u_max=np.inf,
                              mismatch_budget=False)
    for filters, ranged in (({0: "coupled", 1: "coupled"}, True),
                            ({0: unbounded, 1: unbounded}, False)):
        found = tiers.searched(
            f"coupled:ieee39-red-team[{'ranged' if ranged else 'unbounded'}]",
            lambda: coordinated_search(design, filters, "square on P_c", duration=20.0,
                                       maxiter=2, popsize=4, jobs=1))
        assert not found["tripped"]
        replay = coordinated_attacks("square on P_c", found["theta"], 2, 20.0)
        r = lfc.simulate(case, duration=20.0, filters=filters, anti_windup=True,
                         attacks=replay, stop_on_trip=True)   # the verdict is in at a trip
        assert not r.tripped
        held = max(float(a.controls.pc.abs().max()) for a in r.areas)
        flags = [int(a.metrics()["outside"]) for a in r.areas]
        if ranged:
            assert held <= 0.2 and flags == [0, 0]
        else:                      # far beyond the range, and the filters say so
            assert held > 0.5 and min(flags) > 300
    unranged = dataclasses.replace(design, command_range=np.inf)
    for grid, kind, trips in ((design, "certified", False), (design, "contract", False),
                              (unranged, "certified", True)):
        other = lfc.simulate(case, design=grid, duration=20.0, filters={0: kind, 1: kind},
                             anti_windup=True, attacks=replay, stop_on_trip=True)
        assert other.tripped == trips, (kind, grid.command_range)
