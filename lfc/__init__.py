"""lfc-scc: a reproduction of the safety-critical controller for load-frequency control.

Mohamed, Kundur, Khalaf, "On the Use of Safety Critical Control for
Cyber-Physical Security in the Smart Grid".  Per-unit values are on the
generator's MVA base (``LFCParams.s_base_mva``); time in seconds.

The core (this namespace: model, relays, signals, filters, estimation, the
engine, ``simulate`` and ``simulate_many``) needs numpy, scipy,
python-control, numba and pandas.  ``lfc.experiments`` (the paper's scenarios,
maps, red team) builds on it, ``lfc.repro`` (notebooks, figures, command line)
on both; ``lfc.testbed`` (ANDES) and the cvxpy references are optional extras.

Each name of this namespace is imported when it is first used (``import lfc``
imports nothing else: the command line and a notebook's first cell start at once).
"""

from __future__ import annotations

import importlib

__version__ = "0.3.0"   # also in pyproject.toml (tests/test_engine.py checks they match)

#: name -> the module that defines it
_WHERE = {
    "KalmanFilter": "lfc.estimation",
    "FilterInfo": "lfc.filters", "SafetyFilter": "lfc.filters",
    "LFCParams": "lfc.model", "discretize": "lfc.model", "lfc_matrices": "lfc.model",
    "lfc_model": "lfc.model",
    "MultiAreaParams": "lfc.multiarea", "multiarea_matrices": "lfc.multiarea",
    "RelayBank": "lfc.relays", "RelaySettings": "lfc.relays",
    "Chirp": "lfc.signals", "Ramp": "lfc.signals", "Samples": "lfc.signals",
    "Sinusoid": "lfc.signals", "Square": "lfc.signals", "Step": "lfc.signals",
    "Scenario": "lfc.scenarios", "FollowingLoad": "lfc.load_attacks",
    "Result": "lfc.result",
    "simulate": "lfc.run", "simulate_many": "lfc.run", "design_of": "lfc.run",
}

__all__ = sorted(_WHERE)


def __getattr__(name: str):
    """The namespace's names, each imported from its module when first used."""
    where = _WHERE.get(name)
    if where is None:
        raise AttributeError(f"module 'lfc' has no attribute {name!r}")
    value = getattr(importlib.import_module(where), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))
