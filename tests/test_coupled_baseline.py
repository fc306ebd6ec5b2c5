"""Where the per-area certificate stands on a legitimate load step during an attack
(issue "Coupled", item 2: a 0.05 pu step in any area at any instant during an attack
must trip nothing).  Measured, not proven: the battery below is every attack of
``ATTACKS`` x every area x four instants x a ±0.05 pu step x anti-windup off and on,
20 s each.  Pinned so that the coupled certificates have a baseline to beat."""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np
import pandas as pd
import pytest
import tiers

import lfc
from lfc import MultiAreaParams
from lfc.filters.bounds import tie_step_bound
from lfc.experiments.restoration import grid_battery
from lfc.linear_grid import simulate_grid_linear, simulate_grid_table

RELAYS = lfc.RelaySettings()
INSTANTS = (2.0, 3.37, 5.0, 7.71)   # s, while the attacks run (they start at 1 s)
STEP = 0.05                          # pu, the legitimate load step


def attacks(n: int) -> dict:
    """The battery's attacks on a grid of ``n`` areas (name: ``attacks`` argument)."""
    return grid_battery(n)


def runs_of(grid: MultiAreaParams, scenarios: list[dict]) -> pd.DataFrame:
    """One row per scenario of ``scenarios`` (20 s each): ``tripped`` (any area),
    ``outside`` (samples flagged, every area) and ``severity`` (the largest peak of
    frequency or ROCOF over its relay setting, every area)."""
    table = simulate_grid_table(grid, scenarios, duration=20.0)
    table["severity"] = np.maximum(table.max_abs_dw_meas / RELAYS.F,
                                   table.max_abs_rocof_meas / RELAYS.rocof_limit)
    return table.groupby("scenario").agg(tripped=("tripped", "any"), outside=("outside", "sum"),
                                         severity=("severity", "max"))


def tally(grid: MultiAreaParams, key: str, cases: list, make: Callable[..., dict],
          label: Callable[..., str], k: int = 3) -> tuple[int, int, int]:
    """``(scenarios in the battery, runs with a trip, runs with an outside flag)``: the
    battery ``key`` of ``cases``, each run as the scenario ``make(*case)`` names
    ``label(*case)``, on this tier's runs (:class:`tiers.Battery`: all of them, or the
    ``k`` most severe and the ``k`` that flag the most)."""
    picked = tiers.Battery(key, cases, lambda case: label(*case), k)
    runs = runs_of(grid, [make(*case) for case in picked.scenarios])
    picked.record(runs.severity, runs.outside)
    return len(cases), int(runs.tripped.sum()), int((runs.outside > 0).sum())


def step_battery(grid: MultiAreaParams, key: str, filters, *, instants=INSTANTS,
                 signs=(1, -1), step: float = STEP, anti_windup=(False, True),
                 attack_set: dict | None = None, **extra) -> tuple[int, int, int]:
    """:func:`tally` of the battery: every attack of ``attack_set`` (default
    :func:`attacks`) x every area x ``instants`` x ``signs`` of a ``step`` pu load step
    x ``anti_windup``; ``filters`` at every area (a name, a filter, or a dict per
    area); ``extra``: more keys of every scenario (e.g. ``estimator``)."""
    every = filters if isinstance(filters, dict) else {a: filters for a in range(grid.n_areas)}
    cases = list(itertools.product((attack_set or attacks(grid.n_areas)).items(),
                                   range(grid.n_areas), instants, signs, anti_windup))

    def make(attack, area, t, sign, aw) -> dict:
        return {"attacks": attack[1], "loads": {area: lfc.Step(sign * step, start=t)},
                "filters": every, "anti_windup": aw, **extra}

    def label(attack, area, t, sign, aw) -> str:
        return (f"{attack[0]} | {sign * step:+g} pu in area {area} at {t:g} s"
                + (" | anti-windup" if aw else ""))
    return tally(grid, key, cases, make, label)


def battery(grid: MultiAreaParams, key: str, filters: dict) -> tuple[int, int, int]:
    """``(scenarios, runs with a trip, runs with an outside flag)`` over the battery."""
    return step_battery(grid, key, filters)


def steps_filters(grid: MultiAreaParams, bound: float, recheck: bool = False,
                  **options) -> dict:
    """Per-area certified filters with ``load_kind="steps"`` and ``load_bound=bound``;
    with ``recheck``, ``recheck_bound`` = the step plus the tie-line's move in one
    control period (:func:`tie_step_bound`), so a hold is proven period by period
    (``load_bound`` raised to it where it is larger: behind a T = 98 pu tie)."""
    def build(a: int, area: lfc.LFCParams) -> lfc.SafetyFilter:
        again = STEP + tie_step_bound(grid, a, RELAYS, 0.01) if recheck else 0.0
        return lfc.SafetyFilter(area, RELAYS, method="certified", load_kind="steps",
                                load_bound=max(bound, again), recheck_bound=again, **options)
    return {a: build(a, area) for a, area in enumerate(grid.areas)}


def test_finding_the_default_per_area_filter_trips_on_a_load_step_during_an_attack():
    """Its ``load_bound`` covers the tie-line's move in one control period (0.0012 pu
    on the two-area preset), not a load step: a -0.05 pu step in area 0 at 3.37 s
    during a 1 pu, 0.5 Hz sinusoid on its command trips ROCOF 25 ms later, after
    the filter flagged ``outside`` (the step broke its assumption).  Over the
    battery 23 of 160 runs trip."""
    grid = MultiAreaParams.two_area()
    run = simulate_grid_linear(grid, duration=20.0,
                               attacks={0: {"pc": lfc.Sinusoid(1.0, 0.5, start=1.0)}},
                               loads={0: lfc.Step(-STEP, start=3.37)},
                               filters={0: "certified", 1: "certified"})
    m = run.metrics()[0]
    assert m["first_trip_relay"] == "ROCOF" and m["first_trip_t"] == pytest.approx(3.395)
    first_outside = run.areas[0].alarms.query("outside").t.min()
    assert 3.37 <= first_outside < m["first_trip_t"]
    runs, tripped, outside = battery(grid, "baseline[two-area-default]",
                                     {0: "certified", 1: "certified"})
    assert runs == 160 and 0 < tripped <= outside
    if tiers.exhaustive():
        assert 15 <= tripped


@pytest.mark.parametrize("recheck", [False, True], ids=["certified-only", "recheck"])
@pytest.mark.parametrize("grid", [MultiAreaParams.two_area(), MultiAreaParams.three_area()],
                         ids=["two-area", "three-area"])
def test_per_area_filters_covering_steps_ride_every_step_of_the_battery(grid, recheck):
    """``load_kind="steps"``, ``load_bound=0.1`` pu at every area (room for the
    0.05 pu step and the tie-line's variation while a command is held): no trip and
    no ``outside`` flag on 160 (two-area) and 240 (three-area) runs.  With
    ``recheck_bound`` = 0.05 pu + one period's tie-line move, each hold is proven
    period by period and a 0.05 pu step is within the assumption: the no-trip
    result is then proven for these runs (no ``outside``), not only measured."""
    name = f"baseline[{grid.n_areas}-area-steps{'-recheck' if recheck else ''}]"
    runs, tripped, outside = battery(grid, name, steps_filters(grid, 0.1, recheck))
    assert runs == 80 * grid.n_areas
    assert (tripped, outside) == (0, 0)


def test_finding_behind_kundurs_stiff_tie_the_steps_filters_leave_their_certificate():
    """On Kundur's two-area system as fitted to ANDES (T = 98 pu) the same filters
    build and nothing trips, but runs flag ``outside`` (none without the load step):
    the step and the tie-line flow it sets swinging vary the net disturbance while a
    command is held.  Without ``recheck_bound``, 5 of 160 runs (their sampled total
    variation exceeds the bound: a breach; 117 before the held level absorbed the
    load's move within the bound); with it, 118 (the coming period is not re-proven)."""
    from lfc.testbed import GridCase, grid_design
    grid = grid_design(GridCase.kundur())
    for recheck, most in ((False, (1, 15)), (True, (100, 135))):
        name = f"baseline[kundur-steps{'-recheck' if recheck else ''}]"
        runs, tripped, outside = battery(grid, name, steps_filters(grid, 0.1, recheck))
        assert runs == 160 and tripped == 0 and outside > 0
        if tiers.exhaustive():
            assert most[0] <= outside <= most[1]


@pytest.mark.parametrize("recheck", [False, True], ids=["certified-only", "recheck"])
def test_the_steps_filters_on_the_findings_of_the_default_per_area_filter(recheck):
    """The scenarios where the default per-area filter flags ``outside``
    (``tests/test_multiarea.py``'s findings), with ``load_kind="steps",
    load_bound=0.1`` at every area instead: no ``outside`` on the three-area
    sinusoid, on Kundur's fitted model under the ACE attack, with each area's
    Kalman filter (noise declared), and behind a T = 98 pu tie for the default
    area (which the default cannot even build), and on the lightly damped area
    (which flagged it at about 70 samples before the held level absorbed the load's
    move within the bound).  Without
    ``recheck_bound`` the certificate covers the net disturbance's total variation
    since the *held command was certified*, which a tie-line flow accumulates while
    a command is held (measured, not proven); with it each hold is re-proven period
    by period (proven up to the first ``outside``), and the counts are the same."""
    from test_multiarea import KUNDUR_LIKE, NOISE, THREE, TWO

    def outside(grid, **run):
        r = lfc.simulate(grid, duration=run.pop("duration", 20.0),
                         filters=steps_filters(grid, 0.1, recheck, **run.pop("options", {})),
                         **run)
        assert not r.tripped
        return [int(a.alarms.outside.sum()) for a in r.areas]

    bias = lfc.Step(-2.5, start=1.0)
    assert outside(THREE, duration=15.0,
                   attacks={2: {"pc": lfc.Sinusoid(1.0, 0.5, start=1.0)}}) == [0, 0, 0]
    assert outside(KUNDUR_LIKE, duration=30.0,
                   attacks={a: {"ace": bias} for a in range(2)}) == [0, 0]
    assert outside(TWO, attacks={0: {"pc": lfc.Sinusoid(1.0, 0.5, start=1.0)}},
                   options={"noise_std": NOISE}, estimator="kalman", noise_std=NOISE) == [0, 0]
    assert outside(MultiAreaParams.two_area(T=98.0), attacks={0: {"ace": bias}}) == [0, 0]
    light = lfc.LFCParams(M=3.0, tau_g=0.2, droop=0.04, s_base_mva=1000.0)
    grid = MultiAreaParams(areas=THREE.areas[:2] + (light,), tie=THREE.tie)
    squares = {a: {"pc": lfc.Square(amp, freq, start=1.0)}
               for a, (amp, freq) in enumerate(((3.0, 0.05), (-3.0, 3.0), (3.0, 0.3)))}
    flagged = outside(grid, duration=15.0, attacks=squares)
    assert flagged == [0, 0, 0]
