"""Survey (not a timing benchmark): the grid certificates beyond what the tests run.

Prints, from one run:

* the battery of ``tests/test_coupled.py`` (five attacks x every area x four
  instants x a ±0.05 pu load step, anti-windup, 20 s each) with the contract
  (``"contract"``) at every area of rings of 6 and 10 areas and a chain of 6
  (the three-area preset's areas in turn, T = 2 pu): runs, runs with a trip,
  runs with an ``outside`` flag;
* with ``--andes``: the red team's coordinated search (every family of
  ``MULTI_FAMILIES``, both areas at once) against the contract and the coupled
  certificate on Kundur's and the IEEE 39-bus system's areas as fitted to ANDES,
  and its winner replayed on ANDES with the same filters (anti-windup): the
  fitted model's worst severity, and on ANDES whether anything tripped, the
  ``outside`` samples per area and the peak |ROCOF| per area.

``docs/coupled-certificate.md`` quotes its numbers.

Run: python bench/survey_grid_certificates.py [--andes]
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

import lfc
from lfc.experiments.redteam import MULTI_FAMILIES, coordinated_attacks, coordinated_search

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_coupled import battery, ring  # noqa: E402  (the tests' battery, not a copy)


def grids() -> None:
    print("| grid | runs | with a trip | with an outside flag | time |")
    print("|---|---|---|---|---|")
    for name, grid in (("ring of 6", ring(6)), ("chain of 6", ring(6, chain=True)),
                       ("ring of 10", ring(10))):
        t0 = time.perf_counter()
        runs, tripped, outside = battery(grid, "contract", anti_windup=(True,))
        print(f"| {name} | {runs} | {tripped} | {outside} | {time.perf_counter() - t0:.0f} s |",
              flush=True)


def andes() -> None:
    from lfc.testbed import GridCase, grid_design
    from lfc.testbed.loop import TestbedError
    logging.getLogger("andes").setLevel(logging.ERROR)
    print("| case | filters | family | fitted: severity | ANDES: tripped | ANDES: outside "
          "samples | ANDES: peak abs ROCOF (pu/s) |")
    print("|---|---|---|---|---|---|---|")
    for case in (GridCase.kundur(), GridCase.ieee39()):
        fit = grid_design(case)
        for kind in ("contract", "coupled"):
            filters = {0: kind, 1: kind}
            for family in MULTI_FAMILIES:
                found = coordinated_search(fit, filters, family, duration=20.0, maxiter=2,
                                           popsize=4, jobs=1)
                try:
                    r = lfc.simulate(case, duration=20.0, filters=filters, anti_windup=True,
                                     attacks=coordinated_attacks(family, found["theta"], 2,
                                                                 20.0))
                except TestbedError as err:      # a finding, not a crash of the survey
                    print(f"| {case.name} | {kind} | {family} | {found['severity']:.3f} | "
                          f"ANDES diverged: {err} | | |", flush=True)
                    continue
                outside = [int(a.alarms.outside.sum()) for a in r.areas]
                peak = [round(a.metrics()["max_abs_rocof_meas"], 4) for a in r.areas]
                print(f"| {case.name} | {kind} | {family} | {found['severity']:.3f} | "
                      f"{r.tripped} | {outside} | {peak} |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--andes", action="store_true",
                        help="also the red team's winners replayed on ANDES (about 10 min)")
    args = parser.parse_args()
    grids()
    if args.andes:
        andes()


if __name__ == "__main__":
    main()
