"""The paper's figure scenarios: documented defaults, the plants, and their simulators.

The notebooks build each scenario on the page from these constants (their
parameter defaults equal them: ``tests/test_notebooks.py`` checks it); the
tests use the same constants.

The paper gives no attack amplitudes, start times or durations.  The defaults
below are chosen on the default ``LFCParams`` so that each figure's situation
is clear, not marginal (reproduction notes section 4):

* Fig. 4: a 1 Hz sinusoid on dPc (the paper's "≈1 Hz" oscillation).  The
  ROCOF relay first trips at ~0.26 pu; 0.5 pu (about twice that) peaks at
  ~0.096 pu/s (1.9x the setting).  Panel (d) uses 0.1 pu (peak ~0.019 pu/s).
* Fig. 5: a +0.04 pu bias on the frequency reference dw_ref: the local
  integrator drives dw toward 0.04 pu > F = 0.03 pu (OF2 at ~15 s).
* Fig. 6: a 0.1 pu load step, half the E12 limit ``M * rocof_limit`` = 0.2 pu.
Attacks and disturbances start at 1 s so each plot shows the steady state first.

Every scenario runs on either plant (``plant="linear"``: :func:`lfc.simulate`;
``plant="testbed"``: the ANDES microgrid, ``lfc.simulate(MicrogridCase(), design=...)``)
with the same defaults.  On the testbed the design model is the one fitted to
it (:func:`lfc.testbed.fit.design_model`).
"""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:
    from lfc.model import LFCParams
    from lfc.multiarea import MultiAreaParams
    from lfc.relays import RelaySettings
    from lfc.result import Result
    from lfc.testbed import GridCase

PLANTS = ("linear", "testbed")   # single-area chapters: the linear model, the ANDES microgrid
# Notebook 09 runs on all three: the linear model; on ANDES "testbed" is Kundur's two-area
# system and "ieee39" the IEEE 39-bus system (lfc.testbed.GridCase.kundur / .ieee39).
ALL_PLANTS = ("linear", "testbed", "ieee39")
GRIDS = ("two_area", "three_area")   # notebook 09's linear presets (MultiAreaParams)

ATTACK_START = 1.0      # s
FIG4_AMPLITUDE = 0.5    # pu, trips ROCOF without SCC
FIG4_WEAK = 0.1         # pu, neither trips nor activates the SCC (alpha = 20)
FIG4_FREQ = 1.0         # Hz
FIG4_DURATION = 10.0    # s
FIG5_BIAS = 0.04        # pu on dw_ref
FIG5_DURATION = 30.0    # s
FIG6_LOAD = 0.1         # pu load step
FIG6_DURATION = 30.0    # s
FIG7_DURATION = 5.0     # s, fault at ATTACK_START, testbed only
# Notebook 09's sinusoid on the AGC command (pu of the area's base): 1 pu trips the linear
# two-area preset (1000 MVA areas, M = 4 s); Kundur's areas on ANDES (1800 MVA, M = 13 s)
# stay inside every relay setting at 1 pu (peak severity 0.54) and trip at 3 pu.  On the
# IEEE 39-bus system (5000 MVA base) the single attack is on its lighter east area (area 1):
# at 0.5 Hz it stays inside every setting at 0.5 pu (severity 0.75), trips ROCOF at 0.6 pu,
# and at 0.7 pu ANDES stops converging at 9.5 s; on the west area, with the external
# system's inertia, 3 pu stays inside (severity 0.36); chapter 09's tables print them.
MULTIAREA_AMPLITUDE = {"linear": 1.0, "testbed": 3.0, "ieee39": 0.6}
MULTIAREA_ATTACKED = {"linear": 0, "testbed": 0, "ieee39": 1}   # area of the single attack


def check_plant(plant: str, plants: tuple[str, ...] = PLANTS) -> None:
    """Raise ``ValueError`` unless ``plant`` is one of ``plants``."""
    if plant not in plants:
        raise ValueError(f"plant must be one of {plants}, got {plant!r}")


def simulator(plant: str) -> Callable[..., Result]:
    """The simulation function of ``plant``, called ``(params, **keywords)``:
    :func:`lfc.simulate` of ``params``, or of the ANDES microgrid with the
    design model ``params``."""
    from lfc.run import simulate
    check_plant(plant)
    if plant == "linear":
        return simulate
    from lfc.testbed import MicrogridCase
    return partial(_on_microgrid, MicrogridCase())


def _on_microgrid(case, params: LFCParams, **kwargs) -> Result:
    """:func:`lfc.simulate` of the microgrid with the design model ``params``."""
    from lfc.run import simulate
    return simulate(case, design=params, **kwargs)


def design_params(plant: str) -> LFCParams:
    """Default design model: ``LFCParams()``, or the one fitted to the testbed."""
    from lfc.model import LFCParams
    check_plant(plant)
    if plant == "linear":
        return LFCParams()
    from lfc.testbed.fit import design_model
    return design_model()


def multiarea_plant(plant: str, grid: str = "two_area") -> MultiAreaParams | GridCase:
    """Notebook 09's plant: the linear preset ``grid`` (``"two_area"`` or
    ``"three_area"``, a :class:`~lfc.multiarea.MultiAreaParams` constructor), or on
    ANDES Kundur's two-area system (``"testbed"``) or the IEEE 39-bus system
    (``"ieee39"``), where ``grid`` is not used.

    Raises ``ValueError`` naming the plant or the grid if either is unknown."""
    from lfc.multiarea import MultiAreaParams
    check_plant(plant, ALL_PLANTS)
    if plant == "linear":
        if grid not in GRIDS:
            raise ValueError(f"grid must be one of {GRIDS}, got {grid!r:.40}")
        return getattr(MultiAreaParams, grid)()
    from lfc.testbed import GridCase
    return GridCase.kundur() if plant == "testbed" else GridCase.ieee39()


def rocof_limit_load_step(params: LFCParams, relays: RelaySettings) -> float:
    """Largest load step (pu) whose *true* initial ROCOF ``dPL / M`` stays within
    the relay setting (E12).

    The relay reads the measured ROCOF, lagged: without SCC steps up to about
    10 % larger do not trip, and a governor can ride through larger ones still
    (:mod:`lfc.experiments.load_limits` computes both).
    """
    return params.M * relays.rocof_limit
