"""Benchmark: the interconnected grids on ANDES, with AGC and filters in the loop.

Prints, from one run (median of ``REPEAT``), for Kundur's two-area system and the
IEEE 39-bus system (:class:`lfc.testbed.GridCase`), the wall time of a 20 s
scenario (a 0.1 pu load step in area 0 at 1 s; 5 ms ANDES step, 10 ms control
period):

* ANDES alone: the same system run by ANDES with no callback (the reference);
* the loop with every area's AGC and no filter (``lfc.simulate(case, ...)``);
* the loop with the certified filter at every area;

with the real-time factor of each (issue 15 asks >= 0.5x for the 39-bus system) and
the loop's cost relative to ANDES alone.  The fitted design models are computed (or
read from the cache) before timing.

Run: python bench/bench_grids.py
"""

from __future__ import annotations

import statistics
import time

import lfc
from lfc.testbed import GridCase, build_grid, grid_design, prepare_andes
from lfc.testbed.loop import init_tds

DURATION = 20.0  # s simulated
STEP = 0.005     # s, ANDES step
REPEAT = 3


def median_time(fn) -> float:
    times = []
    for _ in range(REPEAT):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def andes_alone(case: GridCase) -> float:
    """Median seconds of the bare ANDES integration (build excluded)."""
    times = []
    for _ in range(REPEAT):
        ss = build_grid(case)
        init_tds(ss, DURATION, STEP)
        t0 = time.perf_counter()
        ss.TDS.run(no_summary=True)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    prepare_andes()
    load = {0: lfc.Step(0.1, 1.0)}
    print(f"{DURATION:g} s load step, median of {REPEAT}")
    print(f"{'grid':<8}{'run':<30}{'wall (s)':>10}{'x real time':>13}{'vs ANDES':>10}")
    for case in (GridCase.kundur(), GridCase.ieee39()):
        params = grid_design(case)
        bare = andes_alone(case)
        loop = median_time(lambda: lfc.simulate(case, design=params, duration=DURATION,
                                                loads=load))
        cert = median_time(lambda: lfc.simulate(case, design=params, duration=DURATION,
                                                loads=load,
                                                filters={a: "certified"
                                                         for a in range(case.n_areas)}))
        for name, t in (("ANDES alone (reference)", bare), ("loop, AGC, no filter", loop),
                        ("loop, AGC, certified filters", cert)):
            print(f"{case.name:<8}{name:<30}{t:>10.2f}{DURATION / t:>13.2f}{t / bare:>10.2f}")


if __name__ == "__main__":
    main()
