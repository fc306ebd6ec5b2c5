"""Benchmark: ``simulate_many`` on a Dask cluster against the process pool, in one run.

Runs ``N`` scenarios (default 10,000,000: 1 s each at 1 ms plant steps,
sinusoids on P_c, half of them with the paper's filter, alpha = 20) once on
the default process pool (one worker per core) and once on a Dask
``LocalCluster`` with 2 single-threaded workers (the same code path a remote
cluster takes: ``client.get_executor()``), checks that the two tables are
equal, and prints

* wall time and scenario-steps/s of each;
* the overhead per chunk of each executor, measured on 400 one-scenario chunks
  of 10 ms (wall time x workers / chunks, the simulation itself negligible);
* chunk-size guidance from those numbers (the overhead below 1 % of a chunk);
* what a 100-node cluster of such 2-core machines would reach, on paper: the
  measured rate per worker times 200 workers, capped by the scheduler's
  measured chunks per second times the chunk size.

Run: python bench/bench_dask.py [N]   (about 10 minutes on 2 cores for 1e7)
"""

from __future__ import annotations

import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pandas as pd
from distributed import Client, LocalCluster

from lfc import LFCParams, simulate_many

DURATION, DT, CHUNK = 1.0, 1e-3, 50_000
WORKERS = 2


def scenarios(n: int) -> pd.DataFrame:
    """Seeded sinusoids on P_c; every other row with the paper's filter (alpha 20)."""
    rng = np.random.default_rng(0)
    return pd.DataFrame({"waveform": "sinusoid", "channel": "pc",
                         "amplitude": rng.uniform(0.05, 1.5, n),
                         "freq_hz": rng.uniform(0.1, 2.0, n), "start": 0.1,
                         "alpha": np.where(np.arange(n) % 2 == 0, 20.0, np.nan), "Ts": 0.25})


def timed(table: pd.DataFrame, executor, chunk_size: int, duration: float
          ) -> tuple[float, pd.DataFrame]:
    t0 = time.perf_counter()
    out = simulate_many(LFCParams(), table, duration=duration, executor=executor,
                        chunk_size=chunk_size, progress=False)
    return time.perf_counter() - t0, out


def overhead(executor, workers: int) -> float:
    """Seconds of executor overhead per chunk (400 chunks of one 10 ms scenario)."""
    table = scenarios(400).assign(start=0.0)
    timed(table.iloc[:8], executor, 1, 0.01)                   # warm the workers
    wall, _ = timed(table, executor, 1, 0.01)
    return wall * workers / len(table)


def main() -> None:
    n = int(float(sys.argv[1])) if len(sys.argv) > 1 else 10_000_000
    table = scenarios(n)
    steps = n * DURATION / DT
    simulate_many(LFCParams(), table.iloc[:4], duration=DURATION, progress=False)  # compile
    with ProcessPoolExecutor(os.cpu_count()) as pool:
        pool_over = overhead(pool, os.cpu_count())
        pool_wall, pool_out = timed(table, pool, CHUNK, DURATION)
    with LocalCluster(n_workers=WORKERS, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        dask = client.get_executor()
        dask_over = overhead(dask, WORKERS)
        dask_wall, dask_out = timed(table, dask, CHUNK, DURATION)
    same = pool_out.equals(dask_out)
    print(f"{n:,} scenarios x {DURATION:g} s ({steps:.3g} scenario-steps), chunks of {CHUNK:,}")
    print(f"{'executor':<40}{'wall (s)':>10}{'steps/s':>12}{'overhead/chunk (ms)':>22}")
    print(f"{f'process pool, {os.cpu_count()} workers':<40}{pool_wall:>10.1f}"
          f"{steps / pool_wall:>12.3g}{1e3 * pool_over:>22.2f}")
    print(f"{f'Dask LocalCluster, {WORKERS} workers':<40}{dask_wall:>10.1f}"
          f"{steps / dask_wall:>12.3g}{1e3 * dask_over:>22.2f}")
    print(f"tables equal: {same}; trips {int(dask_out.tripped.sum()):,}")
    per_scenario = dask_wall * WORKERS / n                    # s of a worker per scenario
    smallest = int(np.ceil(100 * dask_over / per_scenario))
    print(f"chunk size: a scenario of {DURATION:g} s costs a worker {1e6 * per_scenario:.0f} us; "
          f"the overhead stays below 1 % from {smallest:,} scenarios per chunk "
          f"({smallest * DURATION:,.0f} scenario-seconds)")
    per_worker = steps / dask_wall / WORKERS
    cap = CHUNK / dask_over * DURATION / DT        # the scheduler's chunks/s x steps per chunk
    print(f"on paper, 100 such 2-core nodes (200 workers): {min(200 * per_worker, cap):.3g} "
          f"scenario-steps/s ({200 * per_worker:.3g} by the rate per worker, capped at "
          f"{cap:.3g} if the scheduler's overhead per chunk stays {1e3 * dask_over:.2f} ms)")
    if not same:
        raise SystemExit("the Dask table differs from the process pool's")


if __name__ == "__main__":
    main()
