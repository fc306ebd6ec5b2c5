"""The ANDES plants' runners (:mod:`lfc.run`): what :func:`lfc.simulate` and
:func:`lfc.simulate_many` do with a :class:`~lfc.testbed.MicrogridCase`, a
:class:`~lfc.testbed.GridCase` and an :class:`~lfc.testbed.loop.AndesPlant` of your own.

The generator sides keep a linear design model: ``design`` (default: the model fitted
to the case, cached on disk; required for a plant of your own).  Importing
:mod:`lfc.testbed` registers them.
"""

from __future__ import annotations

import numpy as np

from lfc._validate import check_positive
from lfc.engine import SENSOR_CHANNELS, check_load_measured
from lfc.linear_grid import SCENARIO_KEYS, results_table
from lfc.run import Runner, register, register_protocol
from lfc.scenarios import Scenario, grid_scenarios
from lfc.sensors import with_sensors
from lfc.testbed.grids import GridCase
from lfc.testbed.loop import AndesPlant
from lfc.testbed.microgrid import MicrogridCase

#: the methods of an ANDES plant (:class:`~lfc.testbed.loop.AndesPlant`)
ANDES_PLANT = tuple(n for n, v in vars(AndesPlant).items()
                    if callable(v) and not n.startswith("_"))


def _microgrid_refuses(scenario: dict) -> None:
    """``ValueError`` for an attack on the microgrid's sensors or a load that follows
    the frequency: its runner (:func:`lfc.testbed.microgrid.simulate_microgrid`) takes
    neither yet (a grid case does)."""
    named = [f"{c}_attack" for c in SENSOR_CHANNELS if scenario.get(f"{c}_attack") is not None]
    if named:
        raise ValueError(f"{', '.join(named)}: attacks on the sensors run on the linear plants "
                         f"and the ANDES grid cases (GridCase), not on the microgrid yet")
    for name, what in (("following_load", "a load that follows the frequency "
                                          "(lfc.load_attacks)"),
                       ("sensors", "redundant sensors (lfc.sensors.Redundant)")):
        if scenario.get(name) is not None:
            raise ValueError(f"{name}: {what} run on the linear plants and the ANDES grid "
                             f"cases (GridCase), not on the microgrid yet")


def _lowered(scenario: dict, duration: float, period: float) -> tuple[dict, dict]:
    """An ANDES grid's ``scenario`` (:func:`~lfc.testbed.grids.simulate_andes_grid`'s
    keywords) with its redundant sensors (``sensors``) given as their fused error on the
    areas' sensor channels, at the generator sides' control samples of ``period`` s
    (:func:`lfc.sensors.with_sensors`), and their alarm rows by area."""
    if not scenario.get("sensors"):
        return {k: v for k, v in scenario.items() if k != "sensors"}, {}
    check_positive("duration", duration)
    check_positive("control_period", period)
    checked = Scenario(**{k: scenario[k] for k in ("sensors", "attacks", "noise_std", "seed")
                          if k in scenario})
    tc = np.arange(int(np.ceil(duration / period - 1e-9))) * period
    attacks, logs = with_sensors(checked.sensors, checked.attacks, tc, checked.seed)
    return {**{k: v for k, v in scenario.items() if k != "sensors"}, "attacks": attacks}, logs


def _fitted_model(case: MicrogridCase):
    from lfc.testbed.fit import design_model
    return design_model(case)


def _fitted_grid(case: GridCase):
    from lfc.testbed.fit import grid_design
    return grid_design(case)


def _no_design(plant):
    raise ValueError("an AndesPlant of your own has no fitted design model: give "
                     "simulate(plant, design=...) a MultiAreaParams of its n_areas areas")


def _microgrid(case: MicrogridCase, *, duration: float, design=None, **scenario):
    from lfc.testbed.microgrid import simulate_microgrid
    _microgrid_refuses(scenario)
    check_load_measured({None: scenario.get("scc")}, scenario.get("estimator"),
                        scenario.get("load_feedforward", False))
    return simulate_microgrid(design if design is not None else _fitted_model(case),
                              duration=duration, case=case, **scenario)


def _grid_case(case: GridCase, *, duration: float, design=None, **scenario):
    from lfc.testbed.grids import simulate_andes_grid
    check_load_measured(scenario.get("filters") or {}, scenario.get("estimator"),
                        scenario.get("feedforward", True))
    scenario, logs = _lowered(scenario, duration, scenario.get("control_period", 0.01))
    return simulate_andes_grid(design if design is not None else _fitted_grid(case),
                               duration=duration, case=case, **scenario).with_alarms(logs)


def _grid_case_many(case: GridCase, scenarios: list[dict], *, duration: float, design=None,
                    keep: str = "metrics", **kwargs):
    from lfc.testbed.grids import simulate_andes_grid_table
    shared = {k: kwargs.pop(k) for k in SCENARIO_KEYS if k in kwargs}   # every scenario's
    lowered = [_lowered({**shared, **s}, duration, kwargs.get("control_period", 0.01))
               for s in grid_scenarios(scenarios)]
    results = simulate_andes_grid_table(design if design is not None else _fitted_grid(case),
                                        [s for s, _ in lowered], duration=duration,
                                        case=case, **kwargs)
    results = [r.with_alarms(logs) for r, (_, logs) in zip(results, lowered)]
    return results if keep == "results" else results_table(results)


def _own_plant(plant, *, duration: float, design=None, **scenario):
    from lfc.testbed.grids import simulate_andes_grid
    if design is None:
        _no_design(plant)
    check_load_measured(scenario.get("filters") or {}, scenario.get("estimator"),
                        scenario.get("feedforward", True))
    scenario, logs = _lowered(scenario, duration, scenario.get("control_period", 0.01))
    return simulate_andes_grid(design, duration=duration, plant=plant,
                               **scenario).with_alarms(logs)


def is_andes_plant(plant) -> bool:
    """Whether ``plant`` follows the :class:`~lfc.testbed.loop.AndesPlant` protocol:
    every one of its methods, and ``n_areas``."""
    return all(callable(getattr(plant, m, None)) for m in ANDES_PLANT) \
        and hasattr(plant, "n_areas")


register(MicrogridCase, Runner(
    "area", "microgrid", "an lfc.testbed.MicrogridCase", _microgrid, takes_design=True,
    design=_fitted_model,
    many_refused="simulate_many does not run the ANDES microgrid (one scenario per call: "
                 "simulate(MicrogridCase(), ...))"))
register(GridCase, Runner("grid", "grid case", "an lfc.testbed.GridCase", _grid_case,
                          _grid_case_many, takes_design=True, design=_fitted_grid))
register_protocol(is_andes_plant, Runner(
    "grid", "andes plant", "an lfc.testbed.AndesPlant", _own_plant, takes_design=True,
    design=_no_design,
    many_refused="simulate_many does not run an AndesPlant of your own (one scenario per "
                 "call: simulate(plant, design=..., ...))"))
