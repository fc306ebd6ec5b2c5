"""ANDES' time step: the chapters' scenarios on ANDES at 5 ms (the default) and 10 ms (the
control period), in one run: each chapter's claims, the peaks of every run, and ANDES' CPU.

The chapters' scenarios are built as ``tests/chapters.py`` builds them (each notebook's
defaults): chapters 02-05 on the microgrid, chapter 09 on Kundur's two areas and the IEEE
39-bus system.  Prints, per chapter and plant, whether every claim is the same at both
steps, the largest relative change of any run's peak frequency and ROCOF, and whether
chapter 09's attack table (the severities and trip counts it prints, to its stable digits:
``lfc._format``) is the same; then the CPU seconds ANDES took at each step.  The 5 ms runs
of every chapter replay the committed recordings (``lfc.testbed.stored_runs``: no ANDES
CPU to compare) unless ``--live`` (every run on ANDES: about 40 CPU-minutes); the 10 ms
runs run on ANDES.  A step at which ANDES does not converge is printed as such.

Run: python bench/andes_step.py [--microgrid] [--grids] [--live]   (both by default)
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import chapters  # noqa: E402

from lfc._format import number  # noqa: E402
from lfc.repro.runner import andes_seconds  # noqa: E402
from lfc.testbed.loop import CLOCK_ENV  # noqa: E402

STEPS = (0.005, 0.01)   # s
PEAKS = ("max_abs_dw_meas", "max_abs_rocof_meas")


def timed(run) -> tuple[object, float]:
    """``run()`` and the CPU seconds ANDES reported for it."""
    with tempfile.NamedTemporaryFile() as clock:
        os.environ[CLOCK_ENV] = clock.name
        try:
            out = run()
        finally:
            del os.environ[CLOCK_ENV]
        return out, andes_seconds(Path(clock.name))


def largest_change(a: dict, b: dict) -> float:
    """The largest relative change of a peak between two runs' metrics (by name)."""
    return max(abs(b[k][p] - a[k][p]) / abs(a[k][p]) for k in a for p in PEAKS if a[k][p])


def table(metrics: dict) -> list[str]:
    """Chapter 09's attack table as its stable digits: each attack, filter and area's
    severity, trip and outside count."""
    from lfc.relays import RelaySettings
    r = RelaySettings()
    rows = []
    for name, m in sorted(metrics.items()):
        if name.startswith(("load/", "model/")):
            continue
        sev = max(m["max_abs_dw_meas"] / r.F, m["max_abs_rocof_meas"] / r.rocof_limit)
        rows.append(f"{name} {number(sev)} {m['tripped']} {m['outside']}")
    return rows


def microgrid() -> None:
    for name in ("fig4", "fig5", "fig6", "fig7"):
        got = {}
        for step in STEPS:
            (claims, runs), seconds = timed(lambda: chapters.BUILDERS[name]("testbed", step=step))
            got[step] = claims, {k: r.metrics() for k, r in runs.items()}, seconds
        (c5, m5, s5), (c10, m10, s10) = got[STEPS[0]], got[STEPS[1]]
        print(f"{name} on the microgrid: claims {'the same' if c5 == c10 else 'DIFFER'}, "
              f"peaks move by up to {100 * largest_change(m5, m10):.2f} %; ANDES {s5:.1f} s "
              f"at 5 ms, {s10:.1f} s at 10 ms ({s5 / max(s10, 1e-9):.2f}x)", flush=True)


def grids() -> None:
    from lfc.testbed.loop import TestbedError
    for plant in ("testbed", "ieee39"):
        got = {}
        for step in STEPS:
            try:
                (claims, metrics), seconds = timed(lambda: chapters.multiarea(plant, step=step))
            except TestbedError as err:     # a step ANDES cannot take is a result too
                print(f"chapter 09 on {plant} at {1e3 * step:g} ms: {err}", flush=True)
                break
            got[step] = claims, metrics, seconds
        if len(got) < len(STEPS):
            continue
        (c5, m5, s5), (c10, m10, s10) = got[STEPS[0]], got[STEPS[1]]
        differ = [f"{a} -> {b}" for a, b in zip(table(m5), table(m10)) if a != b]
        print(f"chapter 09 on {plant}: claims {'the same' if c5 == c10 else 'DIFFER'}, "
              f"peaks move by up to {100 * largest_change(m5, m10):.2f} %, "
              f"{len(differ)} of {len(table(m5))} table rows differ; ANDES {s5:.1f} s at 5 ms, "
              f"{s10:.1f} s at 10 ms", flush=True)
        for row in differ:
            print(f"  {row}")


if __name__ == "__main__":
    which = set(sys.argv[1:]) - {"--live"} or {"--microgrid", "--grids"}
    if "--live" in sys.argv[1:]:
        os.environ["LFC_ANDES_RUNS"] = "off"     # no stored run, no recording: ANDES runs
    if "--microgrid" in which:
        microgrid()
    if "--grids" in which:
        grids()
