"""Benchmark: the certified filters' offline set computation and per-call latency,
against the paper's filter.

Prints, from one run: the median time to build each certified set (the design
model; the robust filter's ±20 % box, 33 plants; the box with the Kalman
estimate's error bound) with its size, and the median time per ``filter``
call of each on states of an attacked run, with the ratio to the paper's exact
filter.  Targets (issues "Engine" and "Robust"): certified <= 20 us per call;
robust <= 500 us per call (the control period is 10 ms) and <= 5 s offline.

Run: python bench/bench_certified.py
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time

import numpy as np

from lfc import LFCParams, RelaySettings, SafetyFilter, Square, simulate
from lfc.filters.base import clear_built

REPEAT = 5
NOISE = (1e-4, 1e-3)
FILTERS = {"certified": {},
           "robust, ±20 % box": {"uncertainty": 0.2},
           "robust, box + Kalman noise": {"uncertainty": 0.2, "noise_std": NOISE}}


def per_call(filt: SafetyFilter, states: np.ndarray, refs: np.ndarray) -> float:
    """Median seconds per call over ``REPEAT`` passes."""
    times = []
    for _ in range(REPEAT):
        filt.reset()
        t0 = time.perf_counter()
        for x, u in zip(states, refs):
            filt.filter(x, u)
        times.append((time.perf_counter() - t0) / len(refs))
    return statistics.median(times)


def build(options: dict, repeat: int) -> tuple[SafetyFilter, float]:
    """The filter and the median time to build it (s)."""
    times = []
    for _ in range(repeat):
        clear_built()               # time the construction, not the process's shared set
        t0 = time.perf_counter()
        filt = SafetyFilter(LFCParams(), RelaySettings(), method="certified", **options)
        times.append(time.perf_counter() - t0)
    return filt, statistics.median(times)


def main() -> None:
    os.environ["LFC_CACHE_DIR"] = tempfile.mkdtemp(prefix="lfc-bench-")   # nothing stored read
    p = LFCParams()
    SafetyFilter(p, method="certified", noise_std=NOISE)   # imports (python-control) once
    run = simulate(p, duration=20.0, pc_attack=Square(1.0, 0.3, start=1.0),
                   scc=SafetyFilter(p, method="certified"))
    states = run.trace[["dPg", "dPm", "dw", "dw_meas", "rocof_meas"]].to_numpy()[::10]
    refs = np.interp(np.arange(len(states)) * 0.01, run.controls.t, run.controls.pc_ref)
    t_paper = per_call(SafetyFilter(p, alpha=20.0), states, refs)
    print(f"{'filter':<30}{'build (s)':>10}{'plants':>8}{'samples':>9}{'per call (us)':>15}"
          f"{'/ paper':>9}")
    for name, options in FILTERS.items():
        filt, seconds = build(options, 1 if options else REPEAT)
        t = per_call(filt, states, refs)
        cert = filt.cert
        print(f"{name:<30}{seconds:>10.2f}{len(cert.plants):>8}{len(cert.times):>9}"
              f"{1e6 * t:>15.1f}{t / t_paper:>8.1f}x")
    print(f"{'paper (exact), alpha=20':<57}{1e6 * t_paper:>15.1f}")
    print("targets: paper <= 5 us, certified <= 20 us; robust <= 500 us per call and <= 5 s "
          "offline")


if __name__ == "__main__":
    main()
