"""The regression set of the Grid rebuild: runs recorded with the code before it.

Every figure's scenarios on the linear model, the maps' corners, red-team
attacks, multi-area runs and testbed runs on ANDES, each reduced to named
arrays (metrics, traces at every 10th plant step, control samples, alarms,
trips).  ``tests/test_regression_set.py`` reruns them and compares with
``tests/data/grid_regression.npz``: 1e-12 relative on the linear model, 1e-9
on ANDES, on the machine that recorded it (:func:`machine`: the CPU numba compiles
for and the numeric libraries' versions).  On another machine numba's code
(fused multiply-adds) and the BLAS kernels round differently; there the
comparison is ``CROSS_MACHINE``'s, from the differences measured between two
machines (linear: at most 8e-9 relative where the value is not round-off; ANDES:
3.9e-5 relative, 2.6e-7 absolute, the tie-line flow of Kundur's case).

Record (only before a restructuring, with the code it protects)::

    python tests/regression_set.py            # writes tests/data/grid_regression.npz
    python tests/regression_set.py NAME ...   # adds or replaces those cases only

The scenarios call the public API.  Where the API is renamed, the calls here
are rewritten to the new names; the recorded values stay.
"""

from __future__ import annotations

import math
import re
import sys
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd

DATA = Path(__file__).parent / "data" / "grid_regression.npz"
ANDES_RTOL = 1e-9
LINEAR_RTOL = 1e-12
ATOL = 1e-15           # for values that are 0 in one run and round-off in the other
CROSS_MACHINE = {"linear": (1e-6, 1e-12), "andes": (1e-4, 1e-6)}   # (rtol, atol) elsewhere
MACHINE_KEY = "_machine"
# values the rebuild added (one metric set, the barrier values kept): new, so not recorded
ADDED = ("mean_abs_modification", "final_abs_dw_meas", "outside", "h_freq", "h_rocof")
TRACE_EVERY = 10       # keep every 10th plant step of a trace


def _frame(prefix: str, frame: pd.DataFrame, every: int = 1) -> dict[str, np.ndarray]:
    """A DataFrame's columns as arrays (every ``every``-th row and the last)."""
    rows = np.unique(np.r_[np.arange(0, len(frame), every), max(len(frame) - 1, 0)])
    rows = rows[rows < len(frame)]
    out = {}
    for col in frame.columns:
        values = frame[col].to_numpy()[rows]
        if values.dtype == object or values.dtype.kind in "USO":
            values = np.array([str(v) for v in values])
        elif values.dtype == bool:
            values = values.astype(float)
        out[f"{prefix}.{col}"] = np.asarray(values)
    out[f"{prefix}.rows"] = np.array([len(frame)], float)
    return out


def _sim(result) -> dict[str, np.ndarray]:
    """A :class:`lfc.Result` as arrays."""
    out = {}
    out.update(_frame("trace", result.trace, TRACE_EVERY))
    out.update(_frame("controls", result.controls))
    out.update(_frame("alarms", result.alarms.drop(columns=["reason"])))
    out.update(_frame("trips", result.trips))
    metrics = result.metrics()
    relay, t = metrics.pop("first_trip_relay"), metrics.pop("first_trip_t")
    out["metrics.first_trip_t"] = np.array([math.nan if t is None else t])
    out["metrics.first_trip_relay"] = np.array(["" if relay is None else relay])
    for key, value in metrics.items():
        out[f"metrics.{key}"] = np.array([float(value)])
    return out


def _multi(result) -> dict[str, np.ndarray]:
    """A :class:`lfc.Result` as arrays."""
    out = _frame("trace", result.trace, TRACE_EVERY)
    for a, area in enumerate(result.areas):
        out.update({f"area{a}.{k}": v for k, v in _sim(area).items()
                    if not k.startswith("trace.")})
    return out


def _table(frame: pd.DataFrame) -> dict[str, np.ndarray]:
    return _frame("table", frame.reset_index(drop=True))


# -- the scenarios ---------------------------------------------------------------------
def linear_cases() -> dict[str, Callable[[], dict]]:
    import lfc
    from lfc import LFCParams, RelaySettings, SafetyFilter, Samples, Sinusoid, Square, Step
    from lfc.experiments.scenarios import (ATTACK_START, FIG4_AMPLITUDE, FIG4_FREQ, FIG4_WEAK,
                                           FIG5_BIAS, FIG6_LOAD)
    p, relays = LFCParams(), RelaySettings()
    fig4 = Sinusoid(FIG4_AMPLITUDE, FIG4_FREQ, start=ATTACK_START)
    fig5 = Step(FIG5_BIAS, start=ATTACK_START)
    fig6 = Step(FIG6_LOAD, start=ATTACK_START)

    def paper(alpha: float, **kw) -> SafetyFilter:
        return SafetyFilter(p, relays, alpha=alpha, **kw)

    def run(**kw) -> dict:
        return _sim(lfc.simulate(p, **kw))

    cases = {
        "fig4_none": lambda: run(duration=10.0, pc_attack=fig4),
        "fig4_a3": lambda: run(duration=10.0, pc_attack=fig4, scc=paper(3.0)),
        "fig4_a20": lambda: run(duration=10.0, pc_attack=fig4, scc=paper(20.0)),
        "fig4_weak": lambda: run(duration=10.0, scc=paper(20.0),
                                 pc_attack=Sinusoid(FIG4_WEAK, FIG4_FREQ, start=ATTACK_START)),
        "fig4_stop": lambda: run(duration=10.0, pc_attack=fig4, stop_on_trip=True),
        "fig5_none": lambda: run(duration=30.0, wref_attack=fig5),
        "fig5_a20": lambda: run(duration=30.0, wref_attack=fig5, scc=paper(20.0)),
        "fig6_none": lambda: run(duration=30.0, load=fig6),
        "fig6_a20": lambda: run(duration=30.0, load=fig6, scc=paper(20.0)),
        "kalman": lambda: run(duration=10.0, pc_attack=fig4, scc=paper(20.0),
                              estimator="kalman", noise_std=(1e-4, 1e-3), seed=3),
        "relay_noise": lambda: run(duration=10.0, pc_attack=fig4, scc=paper(3.0),
                                   estimator="kalman", noise_std=(2e-4, 2e-3), seed=5,
                                   relay_noise=True),
        "readings_push_slack_applied": lambda: run(
            duration=10.0, pc_attack=Square(0.6, 0.5, start=ATTACK_START),
            scc=paper(3.0, outside_rule="push", conflict="slack", prediction="applied")),
        "certified_fig4": lambda: run(duration=10.0, pc_attack=Sinusoid(1.5, 1.0, start=1.0),
                                      scc=SafetyFilter(p, relays, method="certified")),
        "certified_load_ff": lambda: run(
            duration=10.0, load=Step(0.015, start=1.0), load_feedforward=True,
            pc_attack=Step(-1.0, start=3.0),
            scc=SafetyFilter(p, relays, method="certified", load_bound=0.02)),
        "robust_weak_plant": lambda: _sim(lfc.simulate(
            LFCParams(M=3.2, D=0.8), duration=8.0, pc_attack=Sinusoid(1.2, 0.8, start=1.0),
            estimator="kalman", noise_std=(1e-4, 1e-3), seed=1,
            scc=SafetyFilter(p, relays, method="certified", uncertainty=0.2,
                             noise_std=(1e-4, 1e-3)))),
        "other_plant_paper": lambda: _sim(lfc.simulate(
            LFCParams(M=3.0, tau_t=0.4), duration=10.0, pc_attack=fig4, scc=paper(20.0))),
        "samples_callable": lambda: run(
            duration=6.0, scc=paper(20.0),
            pc_attack=Samples(1.0 + 0.05 * np.arange(60), np.sin(np.arange(60)) * 0.8),
            load=lambda t: 0.03 * np.sin(2 * np.pi * 0.3 * np.asarray(t))),
        "chirp_ramp": lambda: run(duration=8.0, pc_attack=lfc.Chirp(0.4, 0.1, 3.0, start=1.0),
                                  load=lfc.Ramp(0.02, start=2.0, stop=4.0), scc=paper(3.0)),
        "slow_control": lambda: run(duration=8.0, pc_attack=fig4, scc=paper(20.0, Ts=0.25),
                                    dt=2e-3, control_period=0.05),
    }
    return cases


def batch_cases() -> dict[str, Callable[[], dict]]:
    from lfc import LFCParams, simulate_many
    from lfc.experiments.redteam import piecewise_attack_table
    from lfc.experiments.surface import READINGS, attack_map, bias_map
    p = LFCParams()

    def corners() -> pd.DataFrame:
        attacks = attack_map(["sinusoid", "square"], [0.2, 3.0], [0.1, 5.0], [3.0, 20.0])
        biases = bias_map([-0.1, 0.1], [3.0, 20.0])
        return pd.concat([attacks, biases], ignore_index=True)

    def readings() -> pd.DataFrame:
        base = attack_map(["square"], [0.6], [0.5], [3.0]).iloc[[-1]]
        return pd.concat([base.assign(**r) for r in READINGS], ignore_index=True)

    def certified() -> pd.DataFrame:
        base = attack_map(["sinusoid"], [1.5], [1.0], [3.0])
        rows = [base.assign(method="certified"),
                base.assign(method="certified", uncertainty=0.2, M=3.2, D=0.8),
                base.assign(method="certified", noise_w=1e-4, noise_rocof=1e-3, seed=2,
                            declare_noise=True, trips_per_hour=1.0),
                base.assign(method="paper", noise_w=2e-4, noise_rocof=2e-3, seed=4,
                            relay_noise=True),
                base.assign(M=3.0, tau_t=0.4)]
        table = pd.concat(rows, ignore_index=True)
        return table.fillna({"method": "paper", "declare_noise": False, "relay_noise": False,
                             "noise_w": 0.0, "noise_rocof": 0.0, "seed": 0})

    def run(table: pd.DataFrame) -> dict:
        # The record's table set filter columns on rows without SCC too, which the
        # batch ignored then and refuses now: they are sent as NaN, and the inputs
        # are recorded as they were (the metrics must not change).
        sent, off = table.copy(), table.alpha.isna()
        for col, neutral in (("uncertainty", np.nan), ("trips_per_hour", np.nan),
                             ("declare_noise", False)):
            if col in sent:
                sent.loc[off, col] = neutral
        out = simulate_many(p, sent, duration=10.0, progress=False)
        out[table.columns] = table
        keep = [c for c in out.columns if c not in ("values",)]
        return _table(out[keep])

    return {
        "batch_map_corners": lambda: run(corners()),
        "batch_readings": lambda: run(readings()),
        "batch_certified": lambda: run(certified()),
        "batch_redteam_piecewise": lambda: run(
            piecewise_attack_table(n=6, amplitude=2.0, duration=10.0, seed=7)),
    }


def multiarea_cases() -> dict[str, Callable[[], dict]]:
    import lfc
    from lfc import MultiAreaParams, RelaySettings, SafetyFilter, Sinusoid, Step
    two, three = MultiAreaParams.two_area(), MultiAreaParams.three_area()

    def run(params, **kw) -> dict:
        return _multi(lfc.simulate(params, **kw))

    attack = {0: {"pc": Sinusoid(1.0, 0.5, start=1.0)}}
    return {
        "multi_load_agc": lambda: run(two, duration=20.0, loads={0: Step(0.1, start=1.0)}),
        "multi_paper": lambda: run(two, duration=10.0, attacks=attack,
                                   filters={0: "paper", 1: "paper"}),
        "multi_paper_a3": lambda: run(two, duration=10.0, attacks=attack, filters={
            a: SafetyFilter(two.areas[a], RelaySettings(), alpha=3.0) for a in (0, 1)}),
        "multi_certified": lambda: run(two, duration=10.0, attacks=attack,
                                       filters={0: "certified", 1: "certified"}),
        "multi_ace": lambda: run(two, duration=10.0, attacks={0: {"ace": Step(-2.5, start=1.0)}},
                                 filters={0: "certified", 1: "certified"}),
        "multi_three_coordinated": lambda: run(
            three, duration=10.0, filters={a: "certified" for a in range(3)},
            attacks={a: {"pc": Sinusoid(1.0, 0.5, start=1.0)} for a in range(3)}),
        "multi_kalman": lambda: run(two, duration=8.0, attacks=attack, estimator="kalman",
                                    noise_std=(1e-4, 1e-3), seed=2,
                                    filters={0: "paper", 1: "certified"}),
        "multi_stop": lambda: run(two, duration=10.0, attacks=attack, stop_on_trip=True),
        "multi_wref_noff": lambda: run(two, duration=10.0, feedforward=False,
                                       attacks={1: {"wref": Step(0.04, start=1.0)}},
                                       filters={1: "paper"}),
        "multi_batch": lambda: _table(lfc.simulate_many(two, [
            {"attacks": attack, "filters": {0: "paper", 1: "paper"}},
            {"attacks": attack, "filters": {0: "certified", 1: "certified"}},
            {"loads": {1: Step(0.1, start=1.0)}},
            {"attacks": {0: {"ace": Step(-2.5, start=1.0)}}, "estimator": "kalman",
             "noise_std": (1e-4, 1e-3), "seed": 1, "filters": {0: "certified"}}],
            duration=10.0, jobs=2)),
    }


def testbed_cases() -> dict[str, Callable[[], dict]]:
    def microgrid() -> dict:
        from lfc import RelaySettings, SafetyFilter, Sinusoid, simulate
        from lfc.testbed import MicrogridCase
        from lfc.testbed.fit import design_model
        design = design_model()
        return _sim(simulate(MicrogridCase(), design=design, duration=3.0,
                             pc_attack=Sinusoid(0.5, 1.0, start=1.0),
                             scc=SafetyFilter(design, RelaySettings(), alpha=3.0)))

    def kundur() -> dict:
        from lfc import Sinusoid, simulate
        from lfc.testbed import GridCase, grid_design
        case = GridCase.kundur()
        return _multi(simulate(case, design=grid_design(case), duration=2.0,
                               attacks={0: {"pc": Sinusoid(3.0, 0.5, start=0.5)}},
                               filters={0: "paper", 1: "paper"}))

    def ieee39() -> dict:
        from lfc import Sinusoid, Step, simulate
        from lfc.testbed import GridCase, grid_design
        case = GridCase.ieee39()
        return _multi(simulate(case, design=grid_design(case), duration=2.0,
                               attacks={1: {"pc": Sinusoid(0.6, 0.5, start=0.5)}},
                               loads={0: Step(-0.05, start=1.0)},
                               filters={0: "certified", 1: "certified"}))

    return {"testbed_microgrid": microgrid, "testbed_kundur": kundur, "testbed_ieee39": ieee39}


def all_cases() -> dict[str, Callable[[], dict]]:
    return {**linear_cases(), **batch_cases(), **multiarea_cases(), **testbed_cases()}


def machine() -> str:
    """What decides the last bits of a run (:func:`lfc.testbed.stored_runs.machine`)."""
    from lfc.testbed.stored_runs import machine as this_machine
    return this_machine()


def recorded_machine(name: str | None = None) -> str:
    """:func:`machine` where the record (of case ``name``, if recorded later than the
    rest, with a machine of its own) was made."""
    with np.load(DATA, allow_pickle=False) as data:
        for key in (f"{MACHINE_KEY}/{name}", MACHINE_KEY):
            if key in data.files:
                return str(data[key])
    return "unknown"


def tolerances(name: str, same_machine: bool) -> tuple[float, float]:
    """``(rtol, atol)`` for case ``name``: exact up to round-off on the recording
    machine, ``CROSS_MACHINE`` elsewhere."""
    andes = name.startswith("testbed")
    if same_machine:
        return (ANDES_RTOL if andes else LINEAR_RTOL), ATOL
    return CROSS_MACHINE["andes" if andes else "linear"]


def compare(name: str, got: dict[str, np.ndarray], stored: dict[str, np.ndarray],
            same_machine: bool = True) -> list[str]:
    """Differences between a rerun and the record of case ``name`` (empty: equal)."""
    rtol, atol = tolerances(name, same_machine)
    problems = []
    new = {k for k in set(got) - set(stored)
           if re.sub(r"_\d+$", "", k.rsplit(".", 1)[-1]) not in ADDED}   # "h_freq_1": area 1
    if set(stored) - set(got) or new:
        problems.append(f"{name}: keys differ: missing {sorted(set(stored) - set(got))}, "
                        f"new {sorted(new)}")
    for key in sorted(set(got) & set(stored)):
        a, b = got[key], stored[key]
        if a.shape != b.shape:
            problems.append(f"{name}.{key}: shape {a.shape} != recorded {b.shape}")
        elif b.dtype.kind in "US":
            if not np.array_equal(a.astype(str), b):
                problems.append(f"{name}.{key}: {a[:5]} != recorded {b[:5]}")
        elif not np.allclose(a.astype(float), b, rtol=rtol, atol=atol, equal_nan=True):
            err = np.nanmax(np.abs(a.astype(float) - b))
            problems.append(f"{name}.{key}: max abs difference {err:.3g}")
    return problems


def load() -> dict[str, dict[str, np.ndarray]]:
    """The recorded set: ``{case: {key: array}}``."""
    with np.load(DATA, allow_pickle=False) as data:
        out: dict[str, dict[str, np.ndarray]] = {}
        for key in data.files:
            if key.startswith(MACHINE_KEY):
                continue
            case, _, rest = key.partition("/")
            out.setdefault(case, {})[rest] = data[key]
    return out


def record(names: list[str] | None = None) -> None:
    """Record every case (or, given ``names``, those cases, added to the record with
    this machine as theirs: ``recorded_machine(name)``)."""
    cases = all_cases()
    arrays = {}
    if names:
        with np.load(DATA, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files if k.partition("/")[0] not in names}
        arrays.update({f"{MACHINE_KEY}/{n}": np.array(machine()) for n in names})
    else:
        arrays[MACHINE_KEY] = np.array(machine())
    for name, make in cases.items():
        if names and name not in names:
            continue
        print(f"recording {name}", flush=True)
        arrays.update({f"{name}/{k}": v for k, v in make().items()})
    DATA.parent.mkdir(exist_ok=True)
    np.savez_compressed(DATA, **arrays)
    print(f"wrote {DATA} ({DATA.stat().st_size / 1e6:.1f} MB, {len(arrays)} arrays)")


if __name__ == "__main__":
    record(sys.argv[1:] or None)
