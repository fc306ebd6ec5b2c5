"""Small helpers that keep the notebooks' code cells short: results I/O and claims."""

from __future__ import annotations

import json
from pathlib import Path

from lfc.model import LFCParams
from lfc.relays import RelaySettings
from lfc.scenarios import PLANTS, check_plant, design_params
from lfc.simulate import SimResult

__all__ = ["PLANTS", "PLANT_LABELS", "check_plant", "figure_name", "record_claims", "setup",
           "update_markdown_section", "write_metrics"]
PLANT_LABELS = {"linear": "linear model", "testbed": "ANDES testbed"}


def setup(plant: str, supported: tuple[str, ...] = PLANTS) -> tuple[LFCParams, RelaySettings]:
    """The design model of ``plant`` and the paper's relay settings.

    Raises ``ValueError`` if the notebook does not run on ``plant`` (``supported``).
    """
    check_plant(plant)
    if plant not in supported:
        raise ValueError(f"plant must be one of {supported} for this notebook, got {plant!r}")
    return design_params(plant), RelaySettings()


def figure_name(base: str, plant: str) -> str:
    """File name of a figure: ``base`` on the linear plant, ``base_testbed`` on the testbed."""
    check_plant(plant)
    return base if plant == "linear" else f"{base}_{plant}"


def write_metrics(results_dir: str | Path, runs: dict[str, SimResult],
                  parameters: dict, extra: dict[str, dict] | None = None) -> Path:
    """Write ``metrics.json``: each run name -> ``SimResult.metrics()`` plus
    ``parameters`` and that run's ``extra`` entries (e.g. ``oc_trip_t``)."""
    out = Path(results_dir)
    out.mkdir(parents=True, exist_ok=True)
    extra = extra or {}
    data = {name: {**r.metrics(), **extra.get(name, {}), "parameters": parameters}
            for name, r in runs.items()}
    path = out / "metrics.json"
    path.write_text(json.dumps(data, indent=2, sort_keys=False))
    return path


# (plant, claim) -> why the paper's claim does not hold there; shown by ``python -m lfc
# reproduce`` as a documented deviation and explained in the README ("Testbed results").
DEVIATIONS = {
    ("testbed", "with SCC no relay trips"):
        "the SCC drives the frequency to the edge of its model's safe set; the fitted model "
        "under-predicts the testbed's frequency by about 1 %, so OF2 trips (max 1.0304 pu)",
    ("testbed", "with SCC frequency stays below OF2"):
        "as above: the testbed settles 0.0004 pu above OF2 for longer than 160 ms",
}


def record_claims(results_dir: str | Path, claims: dict[str, bool], check: bool,
                  plant: str = "linear") -> None:
    """Write ``claims.json`` (claim -> holds) and ``deviations.json`` (failed
    claims documented in ``DEVIATIONS``: claim -> why).

    With ``check``, raise ``AssertionError`` on a failed claim that is not a
    documented deviation, and on a documented deviation that now holds (so the
    README is updated).
    """
    out = Path(results_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "claims.json").write_text(json.dumps({k: bool(v) for k, v in claims.items()},
                                                indent=2))
    known = {c: why for (p, c), why in DEVIATIONS.items() if p == plant and c in claims}
    deviations = {c: why for c, why in known.items() if not claims[c]}
    (out / "deviations.json").write_text(json.dumps(deviations, indent=2))
    failed = [k for k, ok in claims.items() if not ok and k not in known]
    stale = [k for k in known if claims[k]]
    if check and (failed or stale):
        raise AssertionError("claim(s) not reproduced: " + "; ".join(failed) if failed else
                             "documented deviation(s) no longer observed, update DEVIATIONS "
                             "and the README: " + "; ".join(stale))


def update_markdown_section(path: str | Path, name: str, text: str) -> None:
    """Replace what lies between ``<!-- name:start -->`` and ``<!-- name:end -->``
    in the markdown file ``path`` with ``text`` (how notebooks regenerate the
    README's tables).  Raises ``ValueError`` if the markers are missing."""
    path = Path(path)
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    doc = path.read_text()
    if start not in doc or end not in doc:
        raise ValueError(f"{path} has no {start} ... {end} section")
    head, rest = doc.split(start, 1)
    path.write_text(f"{head}{start}\n{text.strip()}\n{end}{rest.split(end, 1)[1]}")
