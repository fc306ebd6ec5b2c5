"""Benchmark: multi-area batches against one ``simulate`` call per scenario.

Prints, from one run on this machine: the median wall time of a batch of
two-area scenarios (30 s each, 1 ms plant step, a sinusoid or square on both
areas' commands, the paper's SCC or the certified filter at both areas) with
``simulate_many`` on 2 threads, its throughput in area-steps per
second (target >= 1e7 on 2 cores), and the ratio to the reference: the same
scenarios one by one with ``simulate`` (a trace each, and its filters
built per call, as a user's call does).

Run: python bench/bench_multiarea.py
"""

from __future__ import annotations

import statistics
import time

import numpy as np

import lfc

DURATION, N, REFERENCE_N, REPEAT = 30.0, 400, 40, 3


def scenarios(n: int) -> list[dict]:
    rng = np.random.default_rng(0)
    out = []
    for k in range(n):
        wave = lfc.Sinusoid if k % 2 else lfc.Square
        kind = "paper" if k % 4 < 2 else "certified"
        out.append({"attacks": {a: {"pc": wave(float(rng.uniform(-3, 3)),
                                               float(rng.uniform(0.05, 3)), start=1.0)}
                                for a in range(2)},
                    "filters": {0: kind, 1: kind}})
    return out


def main() -> None:
    grid = lfc.MultiAreaParams.two_area()
    batch, one = scenarios(N), scenarios(REFERENCE_N)
    lfc.simulate_many(grid, batch[:4], duration=1.0)          # compile, build filters
    times = []
    for _ in range(REPEAT):
        t0 = time.perf_counter()
        lfc.simulate_many(grid, batch, duration=DURATION, jobs=2)
        times.append(time.perf_counter() - t0)
    t_batch = statistics.median(times) / N
    ref = []
    for _ in range(REPEAT):
        t0 = time.perf_counter()
        for s in one:
            lfc.simulate(grid, duration=DURATION, **s)
        ref.append(time.perf_counter() - t0)
    t_ref = statistics.median(ref) / REFERENCE_N
    steps = 2 * DURATION / 1e-3
    print(f"two areas, {DURATION:g} s per scenario, 1 ms plant step, median of {REPEAT}")
    print(f"simulate_many ({N} scenarios, 2 threads): {1e3 * t_batch:.2f} ms per "
          f"scenario, {steps / t_batch:.3g} area-steps/s (target >= 1e7)")
    print(f"simulate one by one ({REFERENCE_N} scenarios, traced, filters built "
          f"per call): {1e3 * t_ref:.2f} ms per scenario")
    print(f"ratio: the batch is {t_ref / t_batch:.1f}x faster per scenario")


if __name__ == "__main__":
    main()
