"""Benchmark: the SCC's exact solution against the cvxpy/Clarabel reference.

Prints, from one run: median time per ``filter`` call for each solver and
their ratio, and the wall time of a 60 s scenario (SCC at a 10 ms control
period, 1 ms plant step) for each solver.

Run: python bench/bench_filter.py
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from lfc import LFCParams, SafetyFilter, Sinusoid, simulate


def per_call(filt: SafetyFilter, states: np.ndarray, refs: np.ndarray, repeat: int) -> float:
    """Median seconds per filter call over ``repeat`` passes of the state set."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for x, u in zip(states, refs):
            filt.filter(x, u)
        times.append((time.perf_counter() - t0) / len(refs))
    return statistics.median(times)


def scenario(solver: str, repeat: int) -> float:
    """Median wall time (s) of a 60 s Fig. 4-style scenario with the SCC on."""
    p = LFCParams()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        simulate(p, duration=60.0, pc_attack=Sinusoid(0.5, 1.0, start=1.0),
                 scc=SafetyFilter(p, solver=solver))
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    p = LFCParams()
    rng = np.random.default_rng(0)
    states = rng.normal(size=(500, 5)) * [0.5, 0.5, 0.02, 0.02, 0.04]
    refs = rng.normal(scale=0.3, size=500)
    exact = per_call(SafetyFilter(p), states, refs, repeat=21)
    ref = per_call(SafetyFilter(p, solver="cvxpy"), states[:100], refs[:100], repeat=5)
    print(f"{'measure':<40}{'exact':>12}{'cvxpy':>12}{'ratio':>10}")
    print(f"{'median per filter call (us)':<40}{exact * 1e6:>12.1f}{ref * 1e6:>12.1f}"
          f"{ref / exact:>10.0f}")
    s_exact, s_ref = scenario("exact", repeat=5), scenario("cvxpy", repeat=1)
    print(f"{'60 s scenario, SCC every 10 ms (s)':<40}{s_exact:>12.2f}{s_ref:>12.2f}"
          f"{s_ref / s_exact:>10.0f}")
    print("targets: exact <= 5 us per call; 60 s scenario with exact <= 0.2 s")


if __name__ == "__main__":
    main()
