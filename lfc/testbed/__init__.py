"""The high-fidelity plant: an islanded microgrid simulated by ANDES.

The SCC keeps its linear design model (as in the paper); only the plant
changes.  :func:`simulate_testbed` takes the same arguments as
:func:`lfc.simulate` (plus a fault) and returns the same
:class:`~lfc.simulate.SimResult`.
"""

from lfc.testbed.andes_setup import prepare_andes
from lfc.testbed.case import MicrogridCase, build_system
from lfc.testbed.plant import FaultSpec, TestbedError, simulate_testbed
from lfc.testbed.protection import OvercurrentRelay, OvercurrentSettings, phase_a_current

__all__ = ["FaultSpec", "MicrogridCase", "OvercurrentRelay", "OvercurrentSettings",
           "TestbedError", "build_system", "phase_a_current", "prepare_andes",
           "simulate_testbed"]
