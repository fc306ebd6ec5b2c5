"""Benchmark: the compiled engine against the numpy engine it replaced, in one run.

Prints scenario-steps per second (1 ms plant steps x scenarios) for

* ``simulate_many`` with the paper's filter: 10,000 scenarios x 30 s on the
  default process pool (target >= 1e8/s: <= 3 s);
* ``simulate_many`` with the certified filter, 2,000 scenarios x 30 s (two
  chunks, one per core; target >= 2e7/s);
* ``simulate`` of one 60 s scenario with the paper's filter (target <= 0.2 s);
* the same batch on the numpy engine of commit ``REFERENCE`` (the last one before
  the compiled engine), checked out with ``git worktree`` and timed in a
  subprocess on ``REFERENCE_N`` scenarios: the ratio is what numba buys;

and an estimate of the machine's limit for this workload from the operations
per scenario-step (see ``limit``).

Run: python bench/bench_batch.py
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from lfc import LFCParams, SafetyFilter, Sinusoid, simulate, simulate_many

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = "a73c376"  # numpy engine (lfc/batch.py's _Batch), before lfc/engine.py
REFERENCE_N = 2000
DURATION, DT = 30.0, 1e-3
REFERENCE_RUN = """
import sys, time, numpy as np, pandas as pd, lfc
n = int(sys.argv[1])
rng = np.random.default_rng(0)
table = pd.DataFrame({"waveform": "sinusoid", "channel": "pc",
                      "amplitude": rng.uniform(0.05, 1.5, n), "freq_hz": rng.uniform(0.1, 2.0, n),
                      "start": 1.0, "alpha": rng.choice([3.0, 20.0], n), "Ts": 0.25})
run = lfc.simulate_batch  # the reference's name for simulate_many
run(lfc.LFCParams(), table.iloc[:10], duration=30.0, progress=False)
t0 = time.perf_counter()
run(lfc.LFCParams(), table, duration=30.0, progress=False)
print(time.perf_counter() - t0)
"""


def scenarios(n: int, method: str = "paper") -> pd.DataFrame:
    """Sinusoids on P_c over amplitude and frequency, SCC alpha 3 or 20 (seeded)."""
    rng = np.random.default_rng(0)
    return pd.DataFrame({"waveform": "sinusoid", "channel": "pc",
                         "amplitude": rng.uniform(0.05, 1.5, n),
                         "freq_hz": rng.uniform(0.1, 2.0, n), "start": 1.0,
                         "alpha": rng.choice([3.0, 20.0], n), "Ts": 0.25, "method": method})


def batch_rate(n: int, method: str, repeat: int) -> tuple[float, float]:
    """Median wall time (s) and scenario-steps/s of ``simulate_many`` on ``n`` rows."""
    table = scenarios(n, method)
    simulate_many(LFCParams(), table.iloc[:4], duration=DURATION, progress=False)  # compile
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        simulate_many(LFCParams(), table, duration=DURATION, progress=False)
        times.append(time.perf_counter() - t0)
    wall = statistics.median(times)
    return wall, n * DURATION / DT / wall


def simulate_60s(repeat: int) -> float:
    """Median wall time (s) of ``simulate`` over 60 s with the paper's filter."""
    p = LFCParams()
    times = []
    for _ in range(repeat + 1):
        t0 = time.perf_counter()
        simulate(p, duration=60.0, pc_attack=Sinusoid(0.5, 1.0, start=1.0),
                 scc=SafetyFilter(p, alpha=20.0))
        times.append(time.perf_counter() - t0)
    return statistics.median(times[1:])


def reference_rate() -> float | None:
    """Scenario-steps/s of the numpy engine at ``REFERENCE`` (None if git cannot check it out)."""
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "ref"
        add = subprocess.run(["git", "worktree", "add", "--detach", str(tree), REFERENCE],
                             cwd=ROOT, capture_output=True, text=True)
        if add.returncode:
            print(f"reference {REFERENCE} unavailable: {add.stderr.strip()}")
            return None
        try:
            out = subprocess.run([sys.executable, "-c", REFERENCE_RUN, str(REFERENCE_N)],
                                 cwd=tree, env={"PYTHONPATH": str(tree), "PATH": ""},
                                 capture_output=True, text=True)
            if out.returncode:
                print(f"reference {REFERENCE} failed: {out.stderr.strip().splitlines()[-1]}")
                return None
            return REFERENCE_N * DURATION / DT / float(out.stdout.split()[-1])
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT,
                           capture_output=True)


def limit(rate: float) -> None:
    """The machine's limit for this workload, and how far the engine is from it.

    One scenario-step is the 5-state plant update (5 x 6 multiply-adds), the
    three relay comparisons and two maxima; the paper's filter every 10 steps
    adds about 40 multiply-adds and a log per call.  Each step depends on the
    one before, so one scenario is latency-bound: 6 chained multiply-adds of
    4 cycles = 24 cycles per step.  Interleaving scenarios in SIMD lanes (8
    doubles per AVX-512 register, 2 FMA units) could reach ~35 / 16 = 2.2
    cycles per scenario-step.
    """
    ghz = _cpu_ghz()
    latency = 2 * ghz * 1e9 / 24      # 2 cores, 24 cycles per step
    throughput = 2 * ghz * 1e9 / 2.2
    print(f"machine: 2 cores at {ghz:.2f} GHz; latency-bound limit (one scenario per core) "
          f"{latency:.3g}/s, SIMD throughput limit {throughput:.3g}/s")
    print(f"engine: {rate:.3g}/s = {rate / latency:.2f} x the latency bound, "
          f"{throughput / rate:.0f} x below the SIMD throughput limit")


def _cpu_ghz() -> float:
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("cpu MHz"):
            return float(line.split(":")[1]) / 1000
    return 3.0


def main() -> None:
    wall, paper = batch_rate(10_000, "paper", repeat=3)
    cert_wall, cert = batch_rate(2000, "certified", repeat=3)
    sim = simulate_60s(repeat=5)
    ref = reference_rate()
    print(f"{'run':<52}{'wall (s)':>10}{'steps/s':>12}{'ratio':>10}")
    print(f"{'simulate_many, paper filter, 10,000 x 30 s':<52}{wall:>10.2f}{paper:>12.3g}"
          f"{'' if ref is None else f'{paper / ref:>10.1f}'}")
    print(f"{'simulate_many, certified filter, 2,000 x 30 s':<52}{cert_wall:>10.2f}{cert:>12.3g}")
    if ref is not None:
        print(f"{f'numpy engine at {REFERENCE}, paper filter, {REFERENCE_N:,} x 30 s':<52}"
              f"{REFERENCE_N * DURATION / DT / ref:>10.2f}{ref:>12.3g}{1.0:>10.1f}")
    print(f"{'simulate, 60 s, paper filter':<52}{sim:>10.3f}")
    print("targets: paper batch >= 1e8 steps/s (10,000 x 30 s <= 3 s); certified batch "
          ">= 2e7 steps/s; simulate 60 s <= 0.2 s")
    limit(paper)


if __name__ == "__main__":
    main()
