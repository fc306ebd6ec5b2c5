"""The high-fidelity plants, simulated by ANDES: the paper's islanded microgrid and
two interconnected grids (Kundur's two-area system, the IEEE 39-bus system).

The SCC keeps its linear design model (as in the paper); only the plant
changes.  A case is a plant of :func:`lfc.simulate` and :func:`lfc.simulate_many`:
``lfc.simulate(MicrogridCase(), ...)`` takes the keywords of an area (plus a
fault) and returns a :class:`~lfc.Result`;
``lfc.simulate(GridCase.kundur(), ...)`` those of a grid, returning a
:class:`~lfc.Result`.  ``design=`` is the generator sides' model
(default: the one fitted to the case).  Each case is an
:class:`~lfc.testbed.loop.AndesPlant` run by the one ANDES adapter,
:class:`~lfc.testbed.loop.AndesLoop`; :mod:`lfc.testbed.runners` tells :func:`lfc.simulate`
how to run each.
"""

from lfc.testbed.andes_setup import prepare_andes
from lfc.testbed.fit import GridFit, grid_design, grid_fit_report
from lfc.testbed.grids import GridCase, build_grid, case_design
from lfc.testbed.loop import AndesLoop, AndesPlant, TestbedError
from lfc.testbed.microgrid import (FaultSpec, MicrogridCase, OvercurrentRelay,
                                   OvercurrentSettings, build_system, phase_a_current)
from lfc.testbed.runners import ANDES_PLANT, is_andes_plant   # registers the runners (lfc.run)

__all__ = ["AndesLoop", "AndesPlant", "FaultSpec", "GridCase", "GridFit", "MicrogridCase",
           "OvercurrentRelay", "OvercurrentSettings", "TestbedError", "build_grid",
           "build_system", "case_design", "grid_design", "grid_fit_report", "phase_a_current",
           "prepare_andes", "ANDES_PLANT", "is_andes_plant"]
