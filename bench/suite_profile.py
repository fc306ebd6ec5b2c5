"""Where the test suite's time goes: a pytest plugin that records, for every test,
its wall time, the CPU seconds of its worker process (threads included) and of the
child processes it reaped (notebook kernels, process pools), and ANDES' own CPU
seconds in it (:func:`lfc.testbed.loop.record_andes_seconds`, a clock file per
worker, inherited by the test's kernels and pools).

Run from the repository's root, then summarize::

    PYTHONPATH=bench python -m pytest -p suite_profile
    python bench/suite_profile.py            # per file and the 25 most expensive tests

The records go to ``$LFC_SUITE_PROFILE`` (default ``build/suite-profile``), one
JSON line per test in ``tests-<worker>.jsonl``; a test whose wall time exceeds
its CPU time by much waited (on a lock another worker holds, for example).  A
test that points ``LFC_ANDES_CLOCK`` at a file of its own (to count its runs)
shows no ANDES seconds here: its runs report there.
"""

from __future__ import annotations

import json
import os
import resource
import sys
import time
from collections import defaultdict
from pathlib import Path

import pytest

from lfc.repro.runner import andes_seconds
from lfc.testbed.loop import CLOCK_ENV

OUT = Path(os.environ.get("LFC_SUITE_PROFILE", "build/suite-profile"))
WORKER = os.environ.get("PYTEST_XDIST_WORKER", "main")
CLOCK = OUT / f"clock-{WORKER}"


def pytest_configure(config) -> None:
    """Every ANDES run of this worker, its kernels and pools reports to its clock."""
    OUT.mkdir(parents=True, exist_ok=True)
    os.environ[CLOCK_ENV] = str(CLOCK.resolve())


def _cpu(who: int) -> float:
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    own, children = _cpu(resource.RUSAGE_SELF), _cpu(resource.RUSAGE_CHILDREN)
    start, andes = time.time(), andes_seconds(CLOCK)
    yield
    record = {"id": item.nodeid, "worker": WORKER, "start": start,
              "wall": time.time() - start, "cpu": _cpu(resource.RUSAGE_SELF) - own,
              "children": _cpu(resource.RUSAGE_CHILDREN) - children,
              "andes": andes_seconds(CLOCK) - andes}
    with open(OUT / f"tests-{WORKER}.jsonl", "a") as f:
        f.write(json.dumps(record) + "\n")


def summary(folder: Path = OUT, top: int = 25) -> str:
    """The records in ``folder`` per test file and the ``top`` most expensive tests."""
    records = [json.loads(line) for path in sorted(folder.glob("tests-*.jsonl"))
               for line in path.read_text().splitlines()]
    if not records:
        raise ValueError(f"no records in {folder}: run pytest with -p suite_profile first")
    cpu = lambda r: r["cpu"] + max(r["children"], 0.0)   # noqa: E731
    lines = [f"{len(records)} tests: wall {sum(r['wall'] for r in records):.0f} s, "
             f"CPU {sum(map(cpu, records)):.0f} s, ANDES {sum(r['andes'] for r in records):.0f} s",
             "", "| file | wall (s) | CPU (s) | ANDES (s) |", "|---|---:|---:|---:|"]
    files: dict[str, list[float]] = defaultdict(lambda: [0.0, 0.0, 0.0])
    for r in records:
        f = files[r["id"].split("::")[0]]
        f[0], f[1], f[2] = f[0] + r["wall"], f[1] + cpu(r), f[2] + r["andes"]
    for name, (wall, c, andes) in sorted(files.items(), key=lambda kv: -kv[1][1]):
        lines.append(f"| {name} | {wall:.0f} | {c:.0f} | {andes:.0f} |")
    lines += ["", "| test | wall (s) | CPU (s) | ANDES (s) | waited (s) |",
              "|---|---:|---:|---:|---:|"]
    for r in sorted(records, key=cpu, reverse=True)[:top]:
        lines.append(f"| {r['id']} | {r['wall']:.0f} | {cpu(r):.0f} | {r['andes']:.0f} | "
                     f"{max(r['wall'] - cpu(r), 0.0):.0f} |")
    return "\n".join(lines)


if __name__ == "__main__":
    print(summary(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT))
