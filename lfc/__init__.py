"""lfc-scc: a reproduction of the safety-critical controller for load-frequency control.

Mohamed, Kundur, Khalaf, "On the Use of Safety Critical Control for
Cyber-Physical Security in the Smart Grid".  Per-unit values are on the
generator's MVA base (``LFCParams.s_base_mva``); time in seconds.
"""

from lfc.batch import simulate_batch
from lfc.cbf import FilterInfo, SafetyFilter
from lfc.estimation import KalmanFilter
from lfc.model import LFCParams, discretize, lfc_matrices, lfc_model
from lfc.relays import RelayBank, RelaySettings
from lfc.signals import Chirp, Ramp, Samples, Sinusoid, Square, Step
from lfc.simulate import SimResult, simulate

__all__ = [
    "Chirp", "FilterInfo", "KalmanFilter", "LFCParams", "Ramp", "RelayBank", "RelaySettings",
    "SafetyFilter", "Samples", "SimResult", "Sinusoid", "Square", "Step", "discretize",
    "lfc_matrices", "lfc_model", "simulate", "simulate_batch",
]
