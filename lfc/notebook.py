"""Small helpers that keep the notebooks' code cells short: results I/O and claims."""

from __future__ import annotations

import json
from pathlib import Path

from lfc.simulate import SimResult

PLANTS = ("linear",)


def check_plant(plant: str) -> None:
    """Raise ``ValueError`` for a plant this package cannot run (yet)."""
    if plant not in PLANTS:
        raise ValueError(f"plant must be one of {PLANTS}, got {plant!r} "
                         "(the ANDES testbed is not available in this version)")


def write_metrics(results_dir: str | Path, runs: dict[str, SimResult],
                  parameters: dict) -> Path:
    """Write ``metrics.json``: each run name -> ``SimResult.metrics()`` plus ``parameters``."""
    out = Path(results_dir)
    out.mkdir(parents=True, exist_ok=True)
    data = {name: {**r.metrics(), "parameters": parameters} for name, r in runs.items()}
    path = out / "metrics.json"
    path.write_text(json.dumps(data, indent=2, sort_keys=False))
    return path


def record_claims(results_dir: str | Path, claims: dict[str, bool], check: bool) -> None:
    """Write ``claims.json`` and, if ``check``, fail loudly on any claim that does not hold."""
    out = Path(results_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "claims.json").write_text(json.dumps({k: bool(v) for k, v in claims.items()},
                                                indent=2))
    failed = [k for k, ok in claims.items() if not ok]
    if check and failed:
        raise AssertionError("claim(s) not reproduced: " + "; ".join(failed))
