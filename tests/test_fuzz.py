"""A fuzz suite over the public entry points (issue "Hardened", item 5).

Each test takes a valid call and replaces one argument by a hostile value
(wrong types, NaN, ±inf, empty, huge, tiny).  The property: the call raises
``ValueError`` or ``TypeError`` naming the offending parameter, or it returns a
finite result on which the relays, the alarm log and the filter's flags agree —
and a filter claiming a guarantee never lets a relay trip without a flag.
Filters never raise: ``SafetyFilter.filter`` returns a finite command for any
input.  Derandomized (``tests/conftest.py``); ``HYPOTHESIS_PROFILE=explore``
draws new examples.
"""

from __future__ import annotations

import math
import warnings
from decimal import Decimal
from fractions import Fraction

import numpy as np
import pandas as pd
import pytest
import tiers
from hypothesis import given, settings
from hypothesis import strategies as st

import lfc
from lfc import LFCParams, MultiAreaParams, RelaySettings, SafetyFilter

P, RELAYS = LFCParams(), RelaySettings()
PAPER = SafetyFilter(P)
CERTIFIED = SafetyFilter(P, method="certified")

HOSTILE = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-10**12, 10**12),
    st.sampled_from([0, -1, 1e300, -1e300, 5e-324, np.nan, np.inf, -np.inf, True, False, None,
                     "", "1", "0.5", "no", b"1", [], [1.0], (1.0, 2.0, 3.0), {}, object(),
                     np.float32(0.5), np.int64(3), np.array([1.0, 2.0]), complex(1, 1)]),
)


def outcome(call, name: str):
    """``call()``'s result, or None if it raised ``ValueError``/``TypeError`` that
    names ``name``; any other exception, or an error naming something else,
    fails."""
    try:
        return call()
    except (ValueError, TypeError) as err:
        assert name in str(err), f"{name}: {type(err).__name__}: {err}"
        return None


def consistent(result) -> None:
    """A run's metrics are finite and agree with its trip list and alarm log; a
    certified filter never lets a relay trip without flagging."""
    m = result.metrics()
    for key in ("max_abs_dw_meas", "max_abs_rocof_meas", "scc_active_fraction",
                "max_abs_modification", "mean_abs_modification", "final_abs_dw_meas"):
        assert math.isfinite(m[key]) and m[key] >= 0, (key, m[key])
    assert m["tripped"] == (len(result.trips) > 0)
    assert m["alarms"] == len(result.alarms)
    assert m["outside"] == int(result.alarms.outside.sum())
    if m["tripped"]:
        assert m["first_trip_relay"] in ("OF2", "UF2", "ROCOF")
        assert m["first_trip_t"] == pytest.approx(result.trips.t.min())


# -- parameter classes -----------------------------------------------------------------------
@settings(max_examples=tiers.examples(80))
@given(name=st.sampled_from(list(LFCParams.__dataclass_fields__)), value=HOSTILE)
def test_fuzz_plant_parameters(name, value):
    params = outcome(lambda: LFCParams(**{name: value}), name)
    if params is not None:
        run = outcome(lambda: lfc.simulate(params, duration=0.5), name)
        if run is not None:
            consistent(run)


@settings(max_examples=tiers.examples(100))
@given(name=st.sampled_from(list(RelaySettings.__dataclass_fields__)), value=HOSTILE)
def test_fuzz_relay_settings(name, value):
    relays = outcome(lambda: RelaySettings(**{name: value}), name)
    if relays is not None:
        consistent(lfc.simulate(P, duration=0.5, relays=relays,
                                pc_attack=lfc.Step(0.5, start=0.1)))


@settings(max_examples=tiers.examples(60))
@given(name=st.sampled_from(["tie", "bias", "k_agc"]), value=HOSTILE)
def test_fuzz_grid_parameters(name, value):
    two = MultiAreaParams.two_area()
    outcome(lambda: MultiAreaParams(areas=two.areas, **{"tie": two.tie, name: value}), name)


# -- filters ---------------------------------------------------------------------------------
PAPER_OPTIONS = ["alpha", "Ts", "solver", "u_min", "u_max", "slack_weight", "outside_rule",
                 "conflict", "prediction"]
CERTIFIED_OPTIONS = ["horizon", "load_bound", "load_kind", "margin", "noise_std", "confidence",
                     "trips_per_hour", "relay_rate", "u_min", "u_max", "control_period"]


@settings(max_examples=tiers.examples(80))
@given(name=st.sampled_from(PAPER_OPTIONS), value=HOSTILE)
def test_fuzz_paper_filter_options(name, value):
    filt = outcome(lambda: SafetyFilter(P, **{name: value}), name)
    if filt is not None:
        u, _ = filt.filter(np.zeros(5), 0.3)
        assert math.isfinite(u)


@settings(max_examples=tiers.examples(40))
@given(name=st.sampled_from(CERTIFIED_OPTIONS), value=HOSTILE)
def test_fuzz_certified_filter_options(name, value):
    filt = outcome(lambda: SafetyFilter(P, method="certified", **{name: value}), name)
    if filt is not None:
        u, _ = filt.filter(np.zeros(5), 0.3)
        assert math.isfinite(u)


STATE = st.one_of(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=5,
                           max_size=5).map(np.array),
                  st.lists(st.floats(-0.1, 0.1), min_size=5, max_size=5).map(np.array))


@settings(max_examples=tiers.examples(200))
@given(which=st.sampled_from(["paper", "certified"]), x=STATE,
       u_ref=st.floats(allow_nan=True, allow_infinity=True),
       p_load=st.floats(allow_nan=True, allow_infinity=True))
def test_fuzz_filters_never_raise_and_return_a_finite_command(which, x, u_ref, p_load):
    filt = PAPER if which == "paper" else CERTIFIED
    filt.reset()
    u, info = filt.filter(x, u_ref, p_load)
    assert math.isfinite(u) and isinstance(info.reason, str)
    if not (np.all(np.isfinite(x)) and math.isfinite(u_ref) and math.isfinite(p_load)):
        assert info.invalid_input and info.reason          # says why
    if u != u_ref:
        assert info.active and info.reason


# -- simulations -----------------------------------------------------------------------------
SIM_ARGS = ["duration", "dt", "control_period", "seed", "noise_std", "stop_on_trip",
            "relay_noise", "load_feedforward", "estimator", "pc_attack", "wref_attack", "load",
            "scc", "relays"]


@settings(max_examples=tiers.examples(150))
@given(name=st.sampled_from(SIM_ARGS), value=HOSTILE,
       scc=st.sampled_from([None, "paper", "certified"]))
def test_fuzz_simulate_arguments(name, value, scc):
    kwargs = {"duration": 1.0, "pc_attack": lfc.Sinusoid(1.5, 1.0, start=0.2),
              "scc": {None: None, "paper": PAPER, "certified": CERTIFIED}[scc], name: value}
    run = outcome(lambda: lfc.simulate(P, **kwargs), name)
    if run is not None:
        consistent(run)
        if scc == "certified" and run.metrics()["tripped"]:
            assert run.metrics()["alarms"] > 0


SIGNALS = {"Sinusoid": (lfc.Sinusoid, ["amplitude", "freq_hz", "start", "stop", "phase"],
                        dict(amplitude=0.5, freq_hz=1.0)),
           "Square": (lfc.Square, ["amplitude", "freq_hz", "start", "stop"],
                      dict(amplitude=0.5, freq_hz=1.0)),
           "Step": (lfc.Step, ["value", "start", "stop"], dict(value=0.1)),
           "Ramp": (lfc.Ramp, ["slope", "start", "stop"], dict(slope=0.01)),
           "Chirp": (lfc.Chirp, ["amplitude", "f0_hz", "f1_hz", "start", "stop"],
                     dict(amplitude=0.5, f0_hz=0.1, f1_hz=2.0))}


@settings(max_examples=tiers.examples(150))
@given(kind=st.sampled_from(list(SIGNALS)), data=st.data(), value=HOSTILE)
def test_fuzz_signals(kind, data, value):
    cls, names, valid = SIGNALS[kind]
    name = data.draw(st.sampled_from(names))
    sig = outcome(lambda: cls(**{**valid, name: value}), name)
    if sig is not None:
        run = outcome(lambda: lfc.simulate(P, duration=1.0, pc_attack=sig, scc=CERTIFIED), name)
        if run is not None:
            consistent(run)


COLUMNS = ["waveform", "channel", "amplitude", "freq_hz", "start", "alpha", "Ts", "stop",
           "method", "outside_rule", "M", "droop", "noise_w", "noise_rocof", "seed",
           "uncertainty", "margin", "declare_noise", "relay_noise", "trips_per_hour"]


@settings(max_examples=tiers.examples(80))
@given(name=st.sampled_from(COLUMNS), value=HOSTILE)
def test_fuzz_scenario_table_columns(name, value):
    table = pd.DataFrame({"waveform": ["sinusoid", "square"], "channel": "pc",
                          "amplitude": 1.0, "freq_hz": 0.5, "start": 0.2, "alpha": 20.0,
                          "Ts": 0.25, "method": ["paper", "certified"]})
    try:
        table[name] = [value, value]
    except (ValueError, TypeError):
        return                                   # pandas itself refuses the value
    res = outcome(lambda: lfc.simulate_many(P, table, duration=1.0, progress=False), name)
    if res is not None:
        assert np.isfinite(res.max_abs_dw_meas).all() and np.isfinite(res.max_abs_rocof_meas).all()
        assert (res.tripped == res.first_trip_t.notna()).all()


# -- exotic numbers (issue "Sealed"): what the validators accept, the engine runs ------------
EXOTIC = st.sampled_from([Fraction(1, 20), Fraction(103, 100), Fraction(16, 100), 10**400,
                          -10**400, 2**63, np.float32(0.05), np.float16(0.5), np.int8(1),
                          np.uint64(3), Decimal("0.05")])


@settings(max_examples=tiers.examples(40))
@given(name=st.sampled_from(list(RelaySettings.__dataclass_fields__)), value=EXOTIC)
def test_fuzz_relay_settings_of_exotic_numbers_run_or_are_refused_naming_them(name, value):
    """A ``Fraction``, a numpy scalar or an integer that the relay checks accept
    reaches numba as a float (a Fraction once failed after minutes of compiling
    with a ``TypingError``); one they refuse is named."""
    relays = outcome(lambda: RelaySettings(**{name: value}), name)
    if relays is not None:
        consistent(lfc.simulate(P, duration=0.5, relays=relays, scc=SafetyFilter(P, relays),
                                pc_attack=lfc.Step(0.5, start=0.1)))


@settings(max_examples=tiers.examples(40))
@given(method=st.sampled_from(["paper", "certified"]), data=st.data(), value=EXOTIC)
def test_fuzz_filter_options_of_exotic_numbers_run_or_are_refused_naming_them(method, data,
                                                                              value):
    names = PAPER_OPTIONS if method == "paper" else CERTIFIED_OPTIONS
    name = data.draw(st.sampled_from([n for n in names if n not in
                                      ("solver", "outside_rule", "conflict", "prediction",
                                       "load_kind", "noise_std")]))
    scc = outcome(lambda: SafetyFilter(P, method=method, **{name: value}), name)
    if scc is not None:
        period = scc.options.control_period if method == "certified" else 0.01
        run = outcome(lambda: lfc.simulate(P, duration=0.5, scc=scc, control_period=period,
                                           pc_attack=lfc.Step(0.5, start=0.1)), name)
        if run is not None:
            consistent(run)


@settings(max_examples=tiers.examples(40))
@given(name=st.sampled_from(["amplitude", "freq_hz", "start", "alpha", "Ts", "M", "droop",
                             "uncertainty", "margin"]), value=EXOTIC)
def test_fuzz_scenario_columns_of_exotic_numbers_run_or_are_refused_naming_them(name, value):
    """A column of ``Fraction``s or numpy scalars (object dtype) runs as floats; an
    integer too large for a float is refused naming the column."""
    table = pd.DataFrame({"waveform": ["sinusoid", "square"], "channel": "pc",
                          "amplitude": 0.5, "freq_hz": 0.5, "start": 0.2, "alpha": 20.0,
                          "Ts": 0.25, "method": ["paper", "certified"]})
    table[name] = pd.Series([value, value], dtype=object)
    res = outcome(lambda: lfc.simulate_many(P, table, duration=0.5, progress=False), name)
    if res is not None:
        assert np.isfinite(res.max_abs_rocof_meas).all()
        as_floats = table.assign(**{name: [float(value)] * 2})
        again = lfc.simulate_many(P, as_floats, duration=0.5, progress=False)
        pd.testing.assert_series_equal(res.max_abs_rocof_meas, again.max_abs_rocof_meas)


# -- stored-artifact tampering ---------------------------------------------------------------
@settings(max_examples=tiers.examples(60))
@given(kind=st.sampled_from(["truncate", "flip", "swap", "insert"]), at=st.floats(0, 1),
       byte=st.integers(0, 255))
def test_fuzz_a_tampered_stored_file_is_never_read_back_as_another_value(tmp_path_factory,
                                                                        kind, at, byte):
    """:func:`lfc._files.read_stored` returns the value written under that name or
    None (recomputed), whatever is done to the file: cut, a byte changed or
    inserted, or the file of another request copied over it."""
    from lfc._files import read_stored, write_stored
    folder = tmp_path_factory.mktemp("stored")
    one, two = folder / "key-one.json", folder / "key-two.json"
    write_stored(one, {"margin": 0.0, "rows": [1, 2, 3]}, dict)
    write_stored(two, {"margin": 0.3, "rows": [3, 2, 1]}, dict)
    data = bytearray(one.read_bytes())
    k = min(int(at * len(data)), len(data) - 1)
    if kind == "truncate":
        data = data[:k]
    elif kind == "flip":
        data[k] = byte
    elif kind == "insert":
        data[k:k] = bytes([byte])
    else:
        data = bytearray(two.read_bytes())
    one.write_bytes(bytes(data))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        value = read_stored(one, dict)
    assert value in (None, {"margin": 0.0, "rows": [1, 2, 3]})


# -- size limits -----------------------------------------------------------------------------
@settings(max_examples=tiers.examples(60))
@given(n_areas=st.integers(1, 12), duration=st.floats(1.0, 2e4), dt=st.sampled_from([1e-3, 1e-2]))
def test_fuzz_a_runs_size_is_checked_by_its_states_before_anything_is_allocated(n_areas,
                                                                                 duration, dt):
    """``check_timing`` scales the longest run by the grid's size: a run it accepts
    traces at most ``MAX_TRACE_VALUES`` values; one it refuses says how many GB."""
    from lfc.engine import N_CTRL
    from lfc.linear_area import MAX_TRACE_VALUES, check_timing
    n_states = 5 * n_areas + max(n_areas - 1, 0)
    duration = round(duration / dt) * dt
    try:
        check_timing(duration, dt, 10 * dt, n_areas, n_states)
    except ValueError as err:
        assert "GB" in str(err) or "multiple" in str(err), err
        return
    steps = duration / dt
    assert steps * (n_states + n_areas + n_areas * N_CTRL / 10) <= MAX_TRACE_VALUES * (1 + 1e-9)
