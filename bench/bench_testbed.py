"""Benchmark: the ANDES testbed, with and without the SCC in the loop.

Prints, from one run (median of ``REPEAT``), the wall time of a 20 s Fig. 4
scenario (0.5 pu, 1 Hz attack on P_c; 5 ms ANDES step, 10 ms control period):

* ANDES alone: the same system run by ANDES with no callback (the reference);
* the testbed loop without SCC (callback, logging, relays, local controller);
* the testbed loop with the SCC (alpha = 20, exact solver);

with the real-time factor of each and the SCC's overhead relative to the
ANDES run.  System build and power flow are timed separately (once per run).

Run: python bench/bench_testbed.py
"""

from __future__ import annotations

import statistics
import time

from lfc import SafetyFilter, Sinusoid, simulate
from lfc.testbed import MicrogridCase, build_system, prepare_andes

DURATION = 20.0  # s simulated
REPEAT = 3


def median_time(fn) -> float:
    times = []
    for _ in range(REPEAT):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def andes_alone(case: MicrogridCase) -> float:
    """Median seconds of the bare ANDES integration (build excluded)."""
    times = []
    for _ in range(REPEAT):
        ss = build_system(case)
        cfg = ss.TDS.config
        cfg.tf, cfg.tstep, cfg.no_tqdm, cfg.criteria = DURATION, 0.005, 1, 0
        cfg.linesearch, cfg.save_every = 0, 0
        ss.TDS.init()
        t0 = time.perf_counter()
        ss.TDS.run(no_summary=True)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    prepare_andes()
    case = MicrogridCase()
    params = case.design_params()
    attack = Sinusoid(0.5, 1.0, start=1.0)
    build = median_time(lambda: build_system(case))
    bare = andes_alone(case)
    loop = median_time(lambda: simulate(case, design=params, duration=DURATION,
                                        pc_attack=attack))
    scc = median_time(lambda: simulate(case, design=params, duration=DURATION, pc_attack=attack,
                                       scc=SafetyFilter(params, alpha=20.0)))
    print(f"20 s scenario, median of {REPEAT} (build + power flow: {build:.2f} s each)")
    print(f"{'run':<34}{'wall (s)':>10}{'x real time':>13}")
    for name, t in (("ANDES alone (reference)", bare), ("testbed loop, no SCC", loop),
                    ("testbed loop, SCC alpha=20", scc)):
        print(f"{name:<34}{t:>10.2f}{DURATION / t:>13.1f}")
    print(f"SCC overhead: {(scc - loop):.2f} s = {100 * (scc - loop) / bare:.1f} % of the "
          f"ANDES run (target <= 25 %); whole loop vs ANDES alone: {scc / bare:.2f}x")


if __name__ == "__main__":
    main()
