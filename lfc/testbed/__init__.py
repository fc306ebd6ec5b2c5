"""The high-fidelity plants, simulated by ANDES: the paper's islanded microgrid and
two interconnected grids (Kundur's two-area system, the IEEE 39-bus system).

The SCC keeps its linear design model (as in the paper); only the plant
changes.  :func:`simulate_testbed` takes the same arguments as
:func:`lfc.simulate` (plus a fault) and returns the same
:class:`~lfc.simulate.SimResult`; :func:`simulate_grid` takes those of
:func:`lfc.simulate` (a grid) (plus the grid, a :class:`GridCase`) and returns
its :class:`~lfc.MultiAreaResult`.
"""

from lfc.testbed.andes_setup import prepare_andes
from lfc.testbed.case import MicrogridCase, build_system
from lfc.testbed.grid import GridCase, build_grid, case_design
from lfc.testbed.grid_fit import GridFit, grid_design, grid_fit_report
from lfc.testbed.grid_plant import simulate_grid, simulate_grid_batch
from lfc.testbed.plant import FaultSpec, TestbedError, simulate_testbed
from lfc.testbed.protection import OvercurrentRelay, OvercurrentSettings, phase_a_current

__all__ = ["FaultSpec", "GridCase", "GridFit", "MicrogridCase", "OvercurrentRelay",
           "OvercurrentSettings", "TestbedError", "build_grid", "build_system", "case_design",
           "grid_design", "grid_fit_report", "phase_a_current", "prepare_andes",
           "simulate_grid", "simulate_grid_batch", "simulate_testbed"]
