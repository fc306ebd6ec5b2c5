"""Benchmark: the batched simulator against lfc.simulate (exact and cvxpy SCC).

Prints, from one run, scenario-steps per second (1 ms plant steps × scenarios)
for ``simulate`` with the cvxpy solver, ``simulate`` with the exact solver and
``simulate_batch``, the ratios between them, the wall time of the target sweep
(10,000 scenarios × 30 s, SCC on, default process pool) and the peak resident
memory of this process and of its largest worker.

Run: python bench/bench_batch.py [n_scenarios]
"""

from __future__ import annotations

import resource
import sys
import time

import numpy as np
import pandas as pd

from lfc import LFCParams, SafetyFilter, Sinusoid, simulate, simulate_batch

DURATION = 30.0  # s per scenario
DT = 1e-3        # plant step (s)


def scenarios(n: int) -> pd.DataFrame:
    """Sinusoids on P_c over amplitude and frequency, SCC alpha 3 or 20 (seeded)."""
    rng = np.random.default_rng(0)
    return pd.DataFrame({"waveform": "sinusoid", "channel": "pc",
                         "amplitude": rng.uniform(0.05, 1.5, n),
                         "freq_hz": rng.uniform(0.1, 2.0, n), "start": 1.0,
                         "alpha": rng.choice([3.0, 20.0], n), "Ts": 0.25})


def scalar_rate(solver: str, n: int, duration: float) -> float:
    """Scenario-steps per second of ``simulate`` over the first ``n`` scenarios."""
    p, table = LFCParams(), scenarios(n)
    t0 = time.perf_counter()
    for _, row in table.iterrows():
        simulate(p, duration=duration, pc_attack=Sinusoid(row.amplitude, row.freq_hz, 1.0),
                 scc=SafetyFilter(p, alpha=row.alpha, Ts=row.Ts, solver=solver))
    return n * duration / DT / (time.perf_counter() - t0)


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 10_000
    cvxpy = scalar_rate("cvxpy", 1, 5.0)
    exact = scalar_rate("exact", 4, DURATION)
    t0 = time.perf_counter()
    out = simulate_batch(LFCParams(), scenarios(n), duration=DURATION, progress=False)
    wall = time.perf_counter() - t0
    batch = n * DURATION / DT / wall
    rss_self = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    rss_child = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(f"{'method':<34}{'scenario-steps/s':>18}{'vs cvxpy':>10}{'vs exact':>10}")
    for name, rate in (("simulate, cvxpy SCC", cvxpy), ("simulate, exact SCC", exact),
                       ("simulate_batch (process pool)", batch)):
        print(f"{name:<34}{rate:>18.3g}{rate / cvxpy:>10.1f}{rate / exact:>10.1f}")
    print(f"{n} scenarios x {DURATION:g} s (SCC on): {wall:.1f} s wall (target <= 60 s); "
          f"{int(out.tripped.sum())} tripped")
    print(f"peak RSS: main process {rss_self:.0f} MB, largest worker {rss_child:.0f} MB "
          f"(target <= 2048 MB)")


if __name__ == "__main__":
    main()
