"""The conformance suite every registered filter method passes (like
scikit-learn's ``check_estimator``): it runs on :func:`lfc.filters.available`,
so a method is tested the day it is registered.  Each check uses the method's
default options.

- its options are declared once, with unit, valid range and meaning, and the
  defaults are valid; an unknown option is refused naming the valid ones;
- its ``repr`` and ``options`` rebuild the same filter;
- any input (NaN, inf, huge, tiny) gives a finite command and flags that agree
  with the reason, the alarm and ``invalid_input``;
- one call = one row of a batch = one control sample of the compiled loop;
- the loop's alarm log and ``scc_active`` are exactly the calls that alarmed.

The grid-wide filters (the coupled certificate: ``GRID_KINDS``, every method the engine
dispatches with the whole grid) pass the same checks on a grid: their options rebuild
them, any input gives a finite command with consistent flags, and one call per area in
the engine's order replays the compiled loop.

and every linear plant :func:`lfc.simulate` and :func:`lfc.simulate_many`
take (an area, grids of two and three areas): a result's metrics are those of
its ``simulate_many`` row, and its trace keeps the barrier values.
"""

from __future__ import annotations

import math
from functools import partial

import numpy as np
import pandas as pd
import pytest
import tiers
from hypothesis import given, settings
from hypothesis import strategies as st
from same_metrics import same_metrics

import lfc
from lfc.filters import available, option_table, options_of
from lfc.filters.base import MAX_ABS_INPUT

PARAMS = lfc.LFCParams()
METHODS = available()
STATES = ["dPg", "dPm", "dw", "dw_meas", "rocof_meas"]
_BUILT: dict = {}


def build(method: str) -> lfc.SafetyFilter:
    """A fresh filter of ``method`` with its default options (the certified box
    takes seconds, so its data is built once and shared; memory is reset)."""
    if method not in _BUILT:
        _BUILT[method] = lfc.SafetyFilter(PARAMS, method=method)
    f = _BUILT[method]
    f.reset()
    return f


@pytest.mark.parametrize("method", METHODS)
def test_every_option_is_declared_with_unit_range_and_meaning(method):
    table = option_table(method)
    assert table, f"{method} declares no options"
    for row in table:
        assert {"name", "default", "unit", "valid", "doc"} <= set(row), row
        assert row["valid"] and row["doc"], row
    defaults = options_of(method)()          # the defaults pass validation
    assert defaults.as_dict() == {r["name"]: r["default"] for r in table}
    assert defaults.changed() == {}


@pytest.mark.parametrize("method", METHODS)
def test_an_unknown_option_or_method_is_refused_with_the_valid_ones(method):
    names = [r["name"] for r in option_table(method)]
    typo = names[0][:-1] + "x"
    with pytest.raises(ValueError, match=f"no option '{typo}'.*{names[-1]}"):
        lfc.SafetyFilter(PARAMS, method=method, **{typo: 1.0})
    with pytest.raises(ValueError, match=r"method must be one of \("):
        lfc.SafetyFilter(PARAMS, method=method + "_")


@pytest.mark.parametrize("method", METHODS)
def test_an_option_of_another_method_names_that_method(method):
    for other in METHODS:
        mine = {r["name"] for r in option_table(method)}
        theirs = [r["name"] for r in option_table(other) if r["name"] not in mine]
        if other != method and theirs:
            with pytest.raises(ValueError, match=f"option of method '{other}', not of"):
                lfc.SafetyFilter(PARAMS, method=method, **{theirs[0]: 1.0})


@pytest.mark.parametrize("method", METHODS)
def test_repr_and_options_rebuild_the_same_filter(method):
    f = build(method)
    again = lfc.SafetyFilter(PARAMS, method=method, **f.options.as_dict())
    np.testing.assert_array_equal(again.backend.data, f.backend.data)
    from_repr = eval(repr(f), {"SafetyFilter": partial(lfc.SafetyFilter, PARAMS),
                               "inf": math.inf})
    np.testing.assert_array_equal(from_repr.backend.data, f.backend.data)
    assert repr(from_repr) == repr(f) and from_repr.options == f.options


values = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                   st.sampled_from([0.0, 1e-300, -1e-300, MAX_ABS_INPUT, -MAX_ABS_INPUT,
                                    2 * MAX_ABS_INPUT, 1e308]))


@pytest.mark.parametrize("method", METHODS)
@settings(max_examples=tiers.examples(150), deadline=None)
@given(x=st.lists(values, min_size=5, max_size=5), u_ref=values, p=values,
       calls=st.integers(1, 3))
def test_any_input_gives_a_finite_command_and_consistent_flags(method, x, u_ref, p, calls):
    f = build(method)
    for _ in range(calls):               # also after the memory took a value
        u, info = f.filter(np.array(x), u_ref, p)
        assert math.isfinite(u)
        invalid = not all(abs(v) <= MAX_ABS_INPUT for v in (*x, u_ref, p))
        assert info.invalid_input == invalid
        assert info.alarm == bool(info.reason)
        assert info.active == (u != u_ref)
        assert not info.binding or info.active


@pytest.mark.parametrize("method", METHODS)
def test_one_call_equals_one_row_of_a_batch(method):
    rng = np.random.default_rng(7)
    x = rng.normal(0, [0.02, 0.02, 0.01, 0.01, 0.05], size=(60, 5))
    x[::7] *= 3                           # some near and beyond the relay limits
    u_ref = rng.normal(0, 0.5, 60)
    p = rng.normal(0, 0.01, 60)
    u, flags = build(method).filter_batch(x, u_ref, p)
    for i in range(60):
        one, info = build(method).filter(x[i], u_ref[i], p[i])
        assert one == u[i]
        assert info.active == flags["active"][i] and info.outside == flags["outside"][i]
        np.testing.assert_array_equal([info.h_freq, info.h_rocof], flags["h"][i])


@pytest.mark.parametrize("method", METHODS)
def test_the_compiled_loop_applies_what_one_call_returns_and_logs_its_alarms(method):
    """Replay the loop's control samples (exact state, no noise) through one call
    each: the applied command is equal, bit for bit; the alarm log has exactly
    the calls that alarmed; ``scc_active`` is the calls that changed the command."""
    r = lfc.simulate(PARAMS, duration=4.0, pc_attack=lfc.Sinusoid(2.0, 0.5, start=0.5),
                     load=lfc.Step(0.05, start=2.0), scc=build(method))
    f, t = build(method), r.trace["t"].to_numpy()
    alarms, active = [], []
    for tc, pc_ref, pc in zip(r.controls["t"], r.controls["pc_ref"], r.controls["pc"]):
        x = r.trace.loc[np.searchsorted(t, tc - 1e-9), STATES].to_numpy(float)
        u, info = f.filter(x, pc_ref, 0.0)
        assert u == pc
        alarms.append(info.alarm)
        active.append(info.active)
    assert len(r.alarms) == sum(alarms) > 0
    np.testing.assert_array_equal(r.controls["scc_active"].to_numpy(), active)


# -- every plant the two entry points take: one result, metrics defined once ----------------
LINEAR_PLANTS = {"area": PARAMS, "two areas": lfc.MultiAreaParams.two_area(),
                 "three areas": lfc.MultiAreaParams.three_area()}


def test_an_area_result_has_the_metrics_of_its_simulate_many_row():
    attack = lfc.Sinusoid(2.0, 0.5, start=0.5)
    table = pd.DataFrame({"waveform": "sinusoid", "channel": "pc", "amplitude": 2.0,
                          "freq_hz": 0.5, "start": 0.5, "alpha": [np.nan, 3.0, 20.0],
                          "Ts": 0.25, "method": ["paper", "paper", "certified"]})
    rows = lfc.simulate_many(PARAMS, table, duration=6.0, progress=False)
    runs = [lfc.simulate(PARAMS, duration=6.0, pc_attack=attack, scc=scc) for scc in
            (None, lfc.SafetyFilter(PARAMS, alpha=3.0), build("certified"))]
    assert rows.tripped.any() and not rows.tripped.all()   # both kinds of row
    for r, (_, row) in zip(runs, rows.iterrows()):
        assert same_metrics(r.metrics(), row)


@pytest.mark.parametrize("plant", ["two areas", "three areas"])
def test_a_grid_result_has_the_metrics_of_its_simulate_many_rows(plant):
    params = LINEAR_PLANTS[plant]
    scenarios = [{"attacks": {0: {"pc": lfc.Sinusoid(2.0, 0.5, start=0.5)}}},
                 {"attacks": {0: {"pc": lfc.Sinusoid(2.0, 0.5, start=0.5)}},
                  "loads": {1: lfc.Step(0.05, start=2.0)},
                  "filters": {0: "certified", 1: "paper"}}]
    rows = lfc.simulate_many(params, scenarios, duration=6.0)
    for k, s in enumerate(scenarios):
        r = lfc.simulate(params, duration=6.0, **s)
        for a, m in r.metrics().items():
            row = rows[(rows.scenario == k) & (rows.area == a)].iloc[0]
            assert same_metrics(m, row), (k, a)
    assert rows.tripped.any() and not rows.tripped.all()


@pytest.mark.parametrize("plant", sorted(LINEAR_PLANTS))
def test_the_trace_keeps_the_barrier_values_each_control_sample_saw(plant):
    params = LINEAR_PLANTS[plant]
    if isinstance(params, lfc.LFCParams):
        areas = [lfc.simulate(params, duration=2.0, scc=build("paper"),
                              pc_attack=lfc.Sinusoid(2.0, 0.5))]
    else:
        areas = lfc.simulate(params, duration=2.0, filters={0: "paper"},
                             attacks={0: {"pc": lfc.Sinusoid(2.0, 0.5)}}).areas
    r = areas[0]
    assert {"h_freq", "h_rocof"} <= set(r.trace) and {"h_freq", "h_rocof"} <= set(r.controls)
    assert np.isfinite(r.controls[["h_freq", "h_rocof"]].to_numpy()).all()
    at = r.trace.set_index("t").loc[r.controls["t"], ["h_freq", "h_rocof"]].to_numpy()
    np.testing.assert_array_equal(at, r.controls[["h_freq", "h_rocof"]].to_numpy())
    alarmed = r.alarms.set_index("t")[["h_freq", "h_rocof"]]
    np.testing.assert_array_equal(
        r.controls.set_index("t").loc[alarmed.index, ["h_freq", "h_rocof"]], alarmed)


def test_a_filter_called_back_from_compiled_code_runs_in_a_batch():
    """The cvxpy reference of the paper's SCC (a Python filter): a batch equals its
    rows one by one.  Before the fix in ``dispatch.decide_many`` numba's inlining
    handed the callback the whole batch and the batch failed to compile."""
    pytest.importorskip("cvxpy")
    f = lfc.SafetyFilter(PARAMS, solver="cvxpy")
    x = np.random.default_rng(0).normal(0, 0.01, size=(4, 5))
    u, _ = f.filter_batch(x, np.ones(4))
    one = []
    for row in x:
        f.reset()
        one.append(f.filter(row, 1.0)[0])
    np.testing.assert_allclose(u, one, rtol=0, atol=1e-9)


@pytest.mark.parametrize("reading", [{}, {"prediction": "applied"}])
def test_the_cvxpy_reference_in_the_compiled_loop_applies_the_closed_forms_commands(reading):
    """A Python filter inside the compiled loop, in an area and in a grid: the
    cvxpy reference QP applies the closed form's commands (to the solver's
    tolerance).  Before the fixes the callback was handed every area's memory
    (it failed to compile), and the reference predicted with the command the
    closed form had just written over the one applied last (0.84 pu off)."""
    pytest.importorskip("cvxpy")
    attack = lfc.Sinusoid(2.0, 0.5)
    runs = [lfc.simulate(PARAMS, duration=2.0, pc_attack=attack,
                         scc=lfc.SafetyFilter(PARAMS, alpha=3.0, solver=s, **reading))
            for s in ("exact", "cvxpy")]
    assert runs[0].metrics()["alarms"] > 100
    np.testing.assert_allclose(runs[1].controls["pc"], runs[0].controls["pc"], atol=1e-6)
    grid = lfc.MultiAreaParams.two_area()
    attacks = {0: {"pc": attack}, 1: {"pc": lfc.Sinusoid(1.0, 0.3)}}
    runs = [lfc.simulate(grid, duration=2.0, attacks=attacks, filters={
        a: lfc.SafetyFilter(area, alpha=3.0, solver=s, **reading)
        for a, area in enumerate(grid.areas)}) for s in ("exact", "cvxpy")]
    for a in range(2):
        np.testing.assert_allclose(runs[1].areas[a].controls["pc"],
                                   runs[0].areas[a].controls["pc"], atol=1e-6)


# -- grid-wide filters (the coupled certificate): the same checks, on a grid ---------------
TWO, RELAYS = lfc.MultiAreaParams.two_area(), lfc.RelaySettings()
GRID_KINDS = tuple(lfc.filters.GRID_REGISTRY)   # built by name through lfc.filters.build


def grid_filter(kind: str):
    return lfc.filters.build(kind, TWO, 0, RELAYS)


def test_every_grid_wide_method_is_in_this_suite():
    """A method the engine dispatches with the whole grid
    (:func:`lfc.filters.dispatch.grid_wide_methods`) is one of ``GRID_KINDS``:
    registering one adds it here."""
    from lfc.filters.dispatch import grid_wide_methods
    assert {grid_filter(kind).method_id for kind in GRID_KINDS} == set(grid_wide_methods())


@pytest.mark.parametrize("kind", GRID_KINDS)
def test_a_grid_filters_options_rebuild_it_and_its_repr_names_them(kind):
    f = grid_filter(kind)
    again = type(f)(f.params, f.relays, **vars(f.options))
    np.testing.assert_array_equal(again.data, f.data)
    assert again.options == f.options
    for name, value in vars(f.options).items():
        assert f"{name}={value!r}" in repr(f), name


@pytest.mark.parametrize("kind", GRID_KINDS)
@settings(max_examples=tiers.examples(150), deadline=None)
@given(data=st.data(), area=st.integers(0, 1), calls=st.integers(1, 3))
def test_any_grid_input_gives_a_finite_command_and_consistent_flags(kind, data, area, calls):
    from lfc.filters.base import ACTIVE, ALARM_BITS, INVALID
    f = grid_filter(kind)
    n, n_s = TWO.n_areas, TWO.n_states
    x = np.array(data.draw(st.lists(values, min_size=n_s, max_size=n_s)))
    u = np.array(data.draw(st.lists(values, min_size=n, max_size=n)))
    p = np.array(data.draw(st.lists(values, min_size=n, max_size=n)))
    u_ref = data.draw(values)
    memory = np.zeros(2)
    for _ in range(calls):               # also after the memory took a value
        cmd, flags, reason = f.filter(x, u, p, area, u_ref, memory)
        assert math.isfinite(cmd) and np.isfinite(memory).all()
        invalid = not all(abs(v) <= MAX_ABS_INPUT for v in (*x, *u, *p, u_ref))
        assert bool(flags & INVALID) == invalid
        assert bool(flags & ALARM_BITS) == bool(reason)
        assert bool(flags & ACTIVE) == (cmd != u_ref)


@pytest.mark.parametrize("kind", GRID_KINDS)
def test_the_compiled_loop_applies_what_a_grid_filters_calls_return_and_logs_its_alarms(kind):
    """Replay a two-area run's control samples (exact state) through one call per area
    in the engine's order (area 0 first; each area sees the commands decided before it
    this period): the applied commands are equal, up to the round-off of the line flows
    recovered from the metered exports (:meth:`grid_state`; the engine holds the flows
    themselves), and each area's alarm log is exactly its calls that alarmed."""
    r = lfc.simulate(TWO, duration=4.0, attacks={0: {"pc": lfc.Sinusoid(2.0, 0.5, start=0.5)}},
                     loads={1: lfc.Step(0.05, start=2.0)}, filters={0: kind, 1: kind})
    f, t = grid_filter(kind), r.trace["t"].to_numpy()
    n = TWO.n_areas
    memory, u, alarms = [np.zeros(2) for _ in range(n)], np.zeros(n), [0] * n
    controls = [area.controls for area in r.areas]
    for j, tc in enumerate(controls[0]["t"]):
        row = r.trace.iloc[np.searchsorted(t, tc - 1e-9)]
        x = f.grid_state(np.array([[row[f"{s}_{a}"] for s in STATES] for a in range(n)]),
                         np.array([row[f"p_tie_{a}"] for a in range(n)]))
        p = np.array([row[f"p_load_{a}"] for a in range(n)])
        for a in range(n):
            cmd, _, reason = f.filter(x, u, p, a, controls[a]["pc_ref"].iloc[j], memory[a])
            assert cmd == pytest.approx(controls[a]["pc"].iloc[j], rel=0, abs=1e-12), (j, a)
            u[a] = cmd
            alarms[a] += bool(reason)
    assert [len(area.alarms) for area in r.areas] == alarms and sum(alarms) > 0
