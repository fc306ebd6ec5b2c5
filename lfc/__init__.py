"""lfc-scc: a reproduction of the safety-critical controller for load-frequency control.

Mohamed, Kundur, Khalaf, "On the Use of Safety Critical Control for
Cyber-Physical Security in the Smart Grid".  Per-unit values are on the
generator's MVA base (``LFCParams.s_base_mva``); time in seconds.

The core (this namespace: model, relays, signals, filters, estimation, the
engine, ``simulate`` and ``simulate_many``) needs numpy, scipy,
python-control, numba and pandas.  ``lfc.experiments`` (the paper's scenarios,
maps, red team) builds on it, ``lfc.repro`` (notebooks, figures, command line)
on both; ``lfc.testbed`` (ANDES) and the cvxpy references are optional extras.
"""

__version__ = "0.3.0"   # also in pyproject.toml (tests/test_engine.py checks they match)

from lfc.estimation import KalmanFilter
from lfc.filters import FilterInfo, SafetyFilter
from lfc.model import LFCParams, discretize, lfc_matrices, lfc_model
from lfc.multiarea import MultiAreaParams, multiarea_matrices
from lfc.relays import RelayBank, RelaySettings
from lfc.signals import Chirp, Ramp, Samples, Sinusoid, Square, Step
from lfc.simulate import SimResult
from lfc.simulate_multiarea import MultiAreaResult
# last: importing the submodule lfc.simulate binds its name, which this rebinds to the function
from lfc.run import (simulate, simulate_batch, simulate_many, simulate_multiarea,  # noqa: I001
                     simulate_multiarea_batch)

__all__ = [
    "Chirp", "FilterInfo", "KalmanFilter", "LFCParams", "MultiAreaParams", "MultiAreaResult",
    "Ramp", "RelayBank", "RelaySettings", "SafetyFilter", "Samples", "SimResult", "Sinusoid",
    "Square", "Step", "discretize", "lfc_matrices", "lfc_model", "multiarea_matrices",
    "simulate", "simulate_many",
    # deprecated names of 0.3 (they call simulate and simulate_many), removed in 0.5
    "simulate_batch", "simulate_multiarea", "simulate_multiarea_batch",
]
