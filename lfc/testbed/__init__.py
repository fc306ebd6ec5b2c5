"""The high-fidelity plants, simulated by ANDES: the paper's islanded microgrid and
two interconnected grids (Kundur's two-area system, the IEEE 39-bus system).

The SCC keeps its linear design model (as in the paper); only the plant
changes.  A case is a plant of :func:`lfc.simulate` and :func:`lfc.simulate_many`:
``lfc.simulate(MicrogridCase(), ...)`` takes the keywords of an area (plus a
fault) and returns a :class:`~lfc.simulate.SimResult`;
``lfc.simulate(GridCase.kundur(), ...)`` those of a grid, returning a
:class:`~lfc.MultiAreaResult`.  ``design=`` is the generator sides' model
(default: the one fitted to the case).  Each case is an
:class:`~lfc.testbed.loop.AndesPlant` run by the one ANDES adapter,
:class:`~lfc.testbed.loop.AndesLoop`.  ``simulate_testbed``, ``simulate_grid``
and ``simulate_grid_batch`` are deprecated names of 0.3 for those calls.
"""

from lfc.testbed.andes_setup import prepare_andes
from lfc.testbed.case import MicrogridCase, build_system
from lfc.testbed.deprecated import simulate_grid, simulate_grid_batch, simulate_testbed
from lfc.testbed.grid import GridCase, build_grid, case_design
from lfc.testbed.grid_fit import GridFit, grid_design, grid_fit_report
from lfc.testbed.loop import AndesLoop, AndesPlant, TestbedError
from lfc.testbed.plant import FaultSpec
from lfc.testbed.protection import OvercurrentRelay, OvercurrentSettings, phase_a_current

__all__ = ["AndesLoop", "AndesPlant", "FaultSpec", "GridCase", "GridFit", "MicrogridCase",
           "OvercurrentRelay", "OvercurrentSettings", "TestbedError", "build_grid",
           "build_system", "case_design", "grid_design", "grid_fit_report", "phase_a_current",
           "prepare_andes",
           # deprecated names of 0.3 (they run what lfc.simulate and simulate_many run)
           "simulate_grid", "simulate_grid_batch", "simulate_testbed"]
