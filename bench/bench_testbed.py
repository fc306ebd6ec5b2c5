"""Benchmark: the ANDES testbeds, with and without the filters in the loop.

Prints, from one run (median of ``REPEAT``), the wall time of 20 s scenarios
(5 ms ANDES step, 10 ms control period), each against ANDES alone (the same
system, undisturbed, run by ANDES with no callback, built and initialized outside
the timing), and for each loop the share ANDES itself took (its CPU seconds as
the loop records them, :data:`lfc.testbed.loop.CLOCK_ENV`: building, initializing
and integrating the case) and the rest of the wall time (the loop's own: meters,
relays, AGC, filters, logging, the result; the difference of a wall time and a
CPU time, so only to about 0.1 s).  A disturbed system costs ANDES more Newton
iterations per step than an undisturbed one, so "vs alone" overstates the loop's
cost; the last column measures it.

* ``microgrid``: the paper's Fig. 4 scenario (a 0.5 pu, 1 Hz attack on P_c) on
  the microgrid, the loop without SCC (callback, logging, relays, local
  controller) and with the SCC (alpha = 20, exact solver), and the SCC's
  overhead relative to the ANDES run (target <= 25 %);
* ``grids``: a 0.1 pu load step in area 0 at 1 s on Kundur's two-area system
  and the IEEE 39-bus system (:class:`lfc.testbed.GridCase`), the loop with every
  area's AGC and no filter, and with the certified filter at every area (the
  fitted design models computed, or read from the cache, before timing);

with the real-time factor of each and the loop's cost relative to ANDES alone;

* ``shared``: chapter 09's load step (0.1 pu in area 0 at 1 s, 20 s here) with its
  four defences (no filter, the paper's SCC at alpha = 3 and 20, the certified
  filters) on both grids, as one ``lfc.simulate_many`` table in one process
  (scenarios whose filters never act share one ANDES run) against one
  ``lfc.simulate`` per scenario: wall time, ANDES' CPU seconds, the ANDES runs
  each made, and the ratio;
* ``stored``: the same table read back from the runs stored on disk by an
  earlier call (:mod:`lfc.testbed.stored_runs`, in a temporary cache folder)
  against running it: wall time, ANDES' CPU seconds, the ANDES runs, the ratio.

Every part but ``stored`` runs with the store off (``LFC_ANDES_RUNS=off``): a
repeated call would read its run back.

Run: python bench/bench_testbed.py [microgrid | grids | shared | stored]   (all by default)
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import lfc
from lfc.testbed import (GridCase, MicrogridCase, build_grid, build_system, grid_design,
                         prepare_andes)
from lfc.testbed.loop import CLOCK_ENV, init_tds
from lfc.testbed.stored_runs import SWITCH

DURATION = 20.0  # s simulated
STEP = 0.005     # s, ANDES step
REPEAT = 3


def median_time(fn) -> float:
    """Median wall time (s) of ``REPEAT`` calls of ``fn``."""
    times = []
    for _ in range(REPEAT):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def loop_time(fn) -> tuple[float, float]:
    """Median wall time (s) of ``REPEAT`` calls of ``fn`` (an ANDES loop) and the
    median of ANDES' own CPU seconds in each call."""
    wall, andes, _ = loop_runs(fn)
    return wall, andes


def loop_runs(fn) -> tuple[float, float, int]:
    """:func:`loop_time`, and the ANDES runs of the last call."""
    walls, andes, runs = [], [], 0
    with tempfile.TemporaryDirectory() as folder:
        clock = Path(folder) / "andes_seconds.txt"
        os.environ[CLOCK_ENV] = str(clock)
        try:
            for _ in range(REPEAT):
                clock.write_text("")
                t0 = time.perf_counter()
                fn()
                walls.append(time.perf_counter() - t0)
                seconds = clock.read_text().split()
                andes.append(sum(map(float, seconds)))
                runs = len(seconds)
        finally:
            del os.environ[CLOCK_ENV]
    return statistics.median(walls), statistics.median(andes), runs


def print_rows(label: str, bare: float, loops: dict[str, tuple[float, float]]) -> None:
    """One row for ANDES alone and one per loop: wall time, real-time factor, the
    ratio to ANDES alone, ANDES' own CPU seconds and the rest of the wall time (s)."""
    print(f"{label:<8}{'ANDES alone, undisturbed':<34}{bare:>9.2f}{DURATION / bare:>10.2f}"
          f"{1.0:>10.2f}")
    for name, (wall, andes) in loops.items():
        print(f"{label:<8}{name:<34}{wall:>9.2f}{DURATION / wall:>10.2f}{wall / bare:>10.2f}"
              f"{andes:>10.2f}{wall - andes:>10.2f}")


HEADER = (f"{'':<8}{'run':<34}{'wall (s)':>9}{'x real':>10}{'vs alone':>10}"
          f"{'ANDES (s)':>10}{'rest (s)':>10}")


def andes_alone(build) -> float:
    """Median seconds of the bare ANDES integration of ``build()``'s system
    (build and initialization excluded)."""
    times = []
    for _ in range(REPEAT):
        ss = build()
        init_tds(ss, DURATION, STEP)
        t0 = time.perf_counter()
        ss.TDS.run(no_summary=True)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def microgrid() -> None:
    case = MicrogridCase()
    params = case.design_params()
    attack = lfc.Sinusoid(0.5, 1.0, start=1.0)
    build = median_time(lambda: build_system(case))
    bare = andes_alone(lambda: build_system(case))
    loops = {
        "testbed loop, no SCC": loop_time(lambda: lfc.simulate(
            case, design=params, duration=DURATION, pc_attack=attack)),
        "testbed loop, SCC alpha=20": loop_time(lambda: lfc.simulate(
            case, design=params, duration=DURATION, pc_attack=attack,
            scc=lfc.SafetyFilter(params, alpha=20.0)))}
    print(f"microgrid: {DURATION:g} s Fig. 4 scenario, median of {REPEAT} "
          f"(build + power flow: {build:.2f} s each)")
    print(HEADER)
    print_rows("micro", bare, loops)
    (loop, _), (scc, _) = loops.values()
    print(f"SCC overhead: {(scc - loop):.2f} s = {100 * (scc - loop) / bare:.1f} % of the "
          f"ANDES run (target <= 25 %)")


def grids() -> None:
    load = {0: lfc.Step(0.1, 1.0)}
    print(f"grids: {DURATION:g} s load step, median of {REPEAT}")
    print(HEADER)
    for case in (GridCase.kundur(), GridCase.ieee39()):
        params = grid_design(case)
        bare = andes_alone(lambda: build_grid(case))
        certified = {a: "certified" for a in range(case.n_areas)}
        print_rows(case.name, bare, {
            "loop, AGC, no filter": loop_time(lambda: lfc.simulate(
                case, design=params, duration=DURATION, loads=load)),
            "loop, AGC, certified filters": loop_time(lambda: lfc.simulate(
                case, design=params, duration=DURATION, loads=load, filters=certified))})


def chapter09_table(case: GridCase):
    """Chapter 09's load step (0.1 pu in area 0 at 1 s) with its four defences as
    the keyword arguments of one ``lfc.simulate`` each (``defences``) and the
    ones they share (``common``)."""
    relays = lfc.RelaySettings()
    params = grid_design(case)
    defences = [{}, *({a: lfc.SafetyFilter(area, relays, alpha=alpha)
                       for a, area in enumerate(params.areas)} for alpha in (3.0, 20.0)),
                {a: "certified" for a in range(case.n_areas)}]
    common = {"design": params, "duration": DURATION, "loads": {0: lfc.Step(0.1, 1.0)},
              "relays": relays}
    return defences, common


RUNS_HEADER = f"{'':<8}{'run':<34}{'wall (s)':>9}{'ANDES (s)':>10}{'runs':>6}{'ratio':>8}"


def shared() -> None:
    print(f"shared: chapter 09's load step, {DURATION:g} s, four defences, one process, "
          f"median of {REPEAT}")
    print(RUNS_HEADER)
    for case in (GridCase.kundur(), GridCase.ieee39()):
        defences, common = chapter09_table(case)
        one = loop_runs(lambda: [lfc.simulate(case, filters=f, **common) for f in defences])
        table = loop_runs(lambda: lfc.simulate_many(case, [{"filters": f} for f in defences],
                                                    jobs=1, progress=False, **common))
        for name, (wall, andes, runs) in (("one simulate per scenario", one),
                                          ("one simulate_many table", table)):
            print(f"{case.name:<8}{name:<34}{wall:>9.2f}{andes:>10.2f}{runs:>6}"
                  f"{one[0] / wall:>8.2f}")


def stored() -> None:
    print(f"stored: chapter 09's load step, {DURATION:g} s, four defences, one table in one "
          f"process, run against read back from the stored runs, median of {REPEAT}")
    print(RUNS_HEADER)
    for case in (GridCase.kundur(), GridCase.ieee39()):
        defences, common = chapter09_table(case)       # the fit read before the folder moves

        def table():
            return lfc.simulate_many(case, [{"filters": f} for f in defences], jobs=1,
                                     progress=False, **common)
        ran = loop_runs(table)                         # the store off (main)
        with tempfile.TemporaryDirectory() as folder:
            os.environ["LFC_CACHE_DIR"], os.environ[SWITCH] = folder, "on"
            try:
                table()                                # stores its runs
                back = loop_runs(table)
            finally:
                del os.environ["LFC_CACHE_DIR"]
                os.environ[SWITCH] = "off"
        for name, (wall, andes, runs) in (("ANDES runs (store off)", ran),
                                          ("read back from the store", back)):
            print(f"{case.name:<8}{name:<34}{wall:>9.2f}{andes:>10.2f}{runs:>6}"
                  f"{ran[0] / wall:>8.2f}")


def main() -> None:
    parts = {"microgrid": microgrid, "grids": grids, "shared": shared, "stored": stored}
    chosen = sys.argv[1:] or list(parts)
    unknown = [p for p in chosen if p not in parts]
    if unknown:
        raise SystemExit(f"unknown part(s) {unknown}; choose among {list(parts)}")
    os.environ[SWITCH] = "off"      # every ANDES loop runs (stored() turns it on itself)
    prepare_andes()
    for name in chosen:
        parts[name]()


if __name__ == "__main__":
    main()
