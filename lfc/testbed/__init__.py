"""The high-fidelity plants, simulated by ANDES: the paper's islanded microgrid and
Kundur's two-area system.

The SCC keeps its linear design model (as in the paper); only the plant
changes.  :func:`simulate_testbed` takes the same arguments as
:func:`lfc.simulate` (plus a fault) and returns the same
:class:`~lfc.simulate.SimResult`; :func:`simulate_kundur` takes those of
:func:`lfc.simulate_multiarea` and returns its :class:`~lfc.MultiAreaResult`.
"""

from lfc.testbed.andes_setup import prepare_andes
from lfc.testbed.case import MicrogridCase, build_system
from lfc.testbed.kundur import KundurCase, build_kundur
from lfc.testbed.kundur_fit import KundurFit, kundur_design, kundur_fit_report
from lfc.testbed.kundur_plant import simulate_kundur, simulate_kundur_batch
from lfc.testbed.plant import FaultSpec, TestbedError, simulate_testbed
from lfc.testbed.protection import OvercurrentRelay, OvercurrentSettings, phase_a_current

__all__ = ["FaultSpec", "KundurCase", "KundurFit", "MicrogridCase", "OvercurrentRelay",
           "OvercurrentSettings", "TestbedError", "build_kundur", "build_system",
           "kundur_design", "kundur_fit_report", "phase_a_current", "prepare_andes",
           "simulate_kundur", "simulate_kundur_batch", "simulate_testbed"]
