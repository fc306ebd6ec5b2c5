"""Benchmark: the engine in SIMD lanes, one scenario at a time, and the numpy engine, in one run.

Prints scenario-steps per second (1 ms plant steps x scenarios, 10 plant steps
per control period) of ``simulate_many`` on the default process pool (2 cores
here), each workload with ``lanes=True`` (16 scenarios advanced together in
SIMD registers, :func:`lfc.lanes.run_lanes`) and ``lanes=False`` (one at a
time, :func:`lfc.engine.run_kernel`, the reference; the metrics are the same bit for
bit, ``tests/test_lanes.py``):

* no filter, 10,000 scenarios x 30 s (the plant, the relays and the AGC);
* the paper's filter, 10,000 x 30 s (goal >= 4e8/s: < 0.8 s);
* the certified filter, 2,000 x 30 s (goal >= 1.5e8/s);

then ``simulate`` of one 60 s scenario with the paper's filter, the same batch on
the numpy engine of commit ``REFERENCE`` (checked out with ``git worktree``,
timed in a subprocess on ``REFERENCE_N`` scenarios), the machine's measured
multiply-add throughput and the fraction of it each run reaches (``limit``).

With ``--fill``, instead: how full a block must be for lanes to pay (one core,
960 scenarios of 8 s, k scenarios per plant, k = 1 ... 16; a block pays for all
its lanes): lanes (every block, ``LANE_MIN_FILL`` 1) against one at a time, the
best of two, per filter: the measurement behind ``lfc.lanes.LANE_MIN_FILL``.

Run: python bench/bench_batch.py [--fill]
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba as nb
import numpy as np
import pandas as pd

from lfc import LFCParams, SafetyFilter, Sinusoid, simulate, simulate_many

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = "a73c376"  # numpy engine (lfc/tables.py's _Batch), before lfc/engine.py
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
    """Sinusoids on P_c over amplitude and frequency, SCC alpha 3 or 20 (seeded);
    ``method`` "none" runs without a filter."""
    rng = np.random.default_rng(0)
    table = pd.DataFrame({"waveform": "sinusoid", "channel": "pc",
                          "amplitude": rng.uniform(0.05, 1.5, n),
                          "freq_hz": rng.uniform(0.1, 2.0, n), "start": 1.0,
                          "alpha": rng.choice([3.0, 20.0], n), "Ts": 0.25,
                          "method": "paper" if method == "none" else method})
    if method == "none":
        table["alpha"] = np.nan
    return table


def batch_rate(n: int, method: str, repeat: int, lanes: bool) -> tuple[float, float]:
    """Median wall time (s) and scenario-steps/s of ``simulate_many`` on ``n`` rows."""
    table = scenarios(n, method)
    simulate_many(LFCParams(), table.iloc[:4], duration=DURATION, progress=False,
                  lanes=lanes)  # compile
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        simulate_many(LFCParams(), table, duration=DURATION, progress=False, lanes=lanes)
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


@nb.njit(cache=False)
def _multiply_adds(x: np.ndarray, a: float, b: float, n: int) -> None:
    """``n`` rounds of ``x = a x + b`` on 64 independent doubles: a multiply and an
    add each, as the engine computes them (no fused multiply-add), in SIMD lanes."""
    for _ in range(n):
        for lane in range(64):
            x[lane] = a * x[lane] + b


def madd_rate() -> float:
    """Measured multiply-adds per second on one core (median of 5)."""
    x, n = np.ones(64), 2_000_000
    _multiply_adds(x, 0.5, 0.25, 10)
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        _multiply_adds(x, 0.5, 0.25, n)
        times.append(time.perf_counter() - t0)
    return 64 * n / statistics.median(times)


def limit(rates: dict[str, float]) -> None:
    """The machine's limit for this workload, and the fraction of it each run reaches.

    One scenario-step of the plant is 35 multiplies and 30 adds (5 states x 5
    state terms, the held command's and the load's; ``_lane_steps``): at the
    measured multiply-add rate R per core the plant alone can reach
    ``2 R / 35`` scenario-steps/s on 2 cores.  The relays, the generator side
    every 10 steps and the filters come on top of it.
    """
    r = madd_rate()
    ceiling = 2 * r / 35
    print(f"machine: {r:.3g} multiply-adds/s per core measured (64 independent lanes, "
          f"{_cpu_ghz():.2f} GHz); the plant's 35 per scenario-step bound 2 cores at "
          f"{ceiling:.3g} scenario-steps/s")
    for name, rate in rates.items():
        print(f"  {name:<44}{rate:>10.3g}/s = {rate / ceiling:5.1%} of that bound")


def _cpu_ghz() -> float:
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("cpu MHz"):
            return float(line.split(":")[1]) / 1000
    return 3.0


def fill() -> None:
    """Lanes against one at a time (one core) as the scenarios per plant grow."""
    from lfc import scenarios as scenario_tables
    from lfc.tables import run_chunk
    from lfc.relays import RelaySettings
    n, rng = 960, np.random.default_rng(0)
    print(f"{'filter':<12}{'per plant':>10}{'one (s)':>9}{'lanes (s)':>10}{'one/lanes':>10}")
    for method in ("none", "paper", "certified"):
        for k in (1, 2, 4, 6, 8, 12, 16):
            table = scenarios(n, method).assign(M=np.repeat(rng.uniform(3.2, 4.8, n // k), k))
            best = {}
            for lanes in (False, True) * 2:
                scenario_tables.LANE_MIN_FILL = 1
                run_chunk(LFCParams(), table.iloc[:4], 8.0, RelaySettings(), DT, 0.01, lanes)
                t0 = time.perf_counter()
                run_chunk(LFCParams(), table, 8.0, RelaySettings(), DT, 0.01, lanes)
                best[lanes] = min(best.get(lanes, np.inf), time.perf_counter() - t0)
            print(f"{method:<12}{k:>10}{best[False]:>9.3f}{best[True]:>10.3f}"
                  f"{best[False] / best[True]:>10.2f}", flush=True)


def main() -> None:
    if "--fill" in sys.argv[1:]:
        fill()
        return
    runs = {}
    print(f"{'run':<62}{'wall (s)':>10}{'steps/s':>12}{'lanes/one':>10}")
    for method, n, goal in (("none", 10_000, None), ("paper", 10_000, 4e8),
                            ("certified", 2000, 1.5e8)):
        one_wall, one = batch_rate(n, method, 3, lanes=False)
        wall, rate = batch_rate(n, method, 3, lanes=True)
        label = f"{method} filter, {n:,} x 30 s" if method != "none" else \
            f"no filter, {n:,} x 30 s"
        print(f"{'simulate_many, ' + label + ', one at a time':<62}{one_wall:>10.2f}"
              f"{one:>12.3g}{1.0:>10.2f}")
        print(f"{'simulate_many, ' + label + ', lanes':<62}{wall:>10.2f}{rate:>12.3g}"
              f"{rate / one:>10.2f}" + ("" if goal is None else f"   goal >= {goal:.2g}: "
                                        f"{'met' if rate >= goal else 'NOT met'}"))
        runs[f"{method}, lanes"] = rate
        runs[f"{method}, one at a time"] = one
    ref = reference_rate()
    if ref is not None:
        print(f"{f'numpy engine at {REFERENCE}, paper filter, {REFERENCE_N:,} x 30 s':<62}"
              f"{REFERENCE_N * DURATION / DT / ref:>10.2f}{ref:>12.3g}"
              f"   lanes / numpy = {runs['paper, lanes'] / ref:.1f}")
    sim = simulate_60s(repeat=5)
    print(f"{'simulate, 60 s, paper filter':<62}{sim:>10.3f}")
    limit(runs)


if __name__ == "__main__":
    main()
