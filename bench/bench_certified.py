"""Benchmark: per-call latency of the certified filter against the paper's filter.

Prints, from one run: the offline set-computation time (building the certified
set: horizon rows, terminal ellipsoid, load ℓ1 norms), and the median time per
``filter`` call of the certified filter and of the paper's exact filter on
states of an attacked run, with their ratio.

Run: python bench/bench_certified.py
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from lfc import LFCParams, SafetyFilter, Square, simulate

REPEAT = 5


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


def main() -> None:
    p = LFCParams()
    builds = []
    for _ in range(REPEAT):
        t0 = time.perf_counter()
        certified = SafetyFilter(p, method="certified")
        builds.append(time.perf_counter() - t0)
    run = simulate(p, duration=20.0, pc_attack=Square(1.0, 0.3, start=1.0), scc=certified)
    states = run.trace[["dPg", "dPm", "dw", "dw_meas", "rocof_meas"]].to_numpy()[::10]
    refs = np.interp(np.arange(len(states)) * 0.01, run.controls.t, run.controls.pc_ref)
    t_cert = per_call(certified, states, refs)
    t_paper = per_call(SafetyFilter(p, alpha=20.0), states, refs)
    rows = certified.cert.n_rows
    print(f"offline set computation (median of {REPEAT}): "
          f"{1e3 * statistics.median(builds):.0f} ms ({rows} horizon rows)")
    print(f"{'filter':<28}{'median per call (us)':>22}")
    print(f"{'certified':<28}{1e6 * t_cert:>22.1f}")
    print(f"{'paper (exact), alpha=20':<28}{1e6 * t_paper:>22.1f}")
    print(f"certified / paper: {t_cert / t_paper:.1f}x  (targets: paper <= 5 us, "
          "certified <= 20 us)")


if __name__ == "__main__":
    main()
