"""The probe chapter: ``tests/data/probe.ipynb``, a parameters cell and one code cell
(two 2 s runs of the linear model, a figure, metrics and a claim), for the tests of
the runner, ``sweep``, the caches and Ctrl-C — what a chapter's machinery does,
without executing a chapter (the chapters' claims are checked through the API, and
each chapter is executed by ``reproduce`` and by the exhaustive tier).

Run as a script, it is ``python -m lfc`` with the probe among the chapters (for the
tests that interrupt a real process)::

    python tests/probe.py reproduce --only probe ...
"""

from __future__ import annotations

import runpy
import sys
from pathlib import Path

NOTEBOOK = Path(__file__).resolve().parent / "data" / "probe.ipynb"
NAME = "probe"


def register(patch) -> None:
    """Make the probe a chapter of the manifest, the runner and the book;
    ``patch(module, name, value)`` sets an attribute (``monkeypatch.setattr``, or
    ``setattr`` in a process of its own)."""
    from lfc.repro import book, manifest, runner
    probe = manifest.Chapter(NAME, str(NOTEBOOK), "A probe of the chapters' machinery",
                             ("linear",), ("probe",), {"duration": 2.0})
    chapters = (*manifest.CHAPTERS, probe)
    for module in (manifest, runner, book):
        patch(module, "CHAPTERS", chapters)
    patch(runner, "FIGURES", {**runner.FIGURES, NAME: str(NOTEBOOK)})
    patch(runner, "FIGURE_PLANTS", {**runner.FIGURE_PLANTS, NAME: ("linear",)})


if __name__ == "__main__":
    register(setattr)
    sys.argv[0] = "lfc"
    runpy.run_module("lfc", run_name="__main__", alter_sys=True)
