"""The two entry points: :func:`simulate` (one scenario, a trace) and
:func:`simulate_many` (a table of scenarios, one row of metrics each).

Both take the plant first, and the plant decides what a scenario is:

=========================  ==========================================  ===========================
plant                      ``simulate`` keywords, result               ``simulate_many`` scenarios
=========================  ==========================================  ===========================
``LFCParams``              ``pc_attack``, ``wref_attack``, ``load``,   a DataFrame, one row each
                           ``scc``, ... → ``SimResult``                (``lfc.batch``)
``MultiAreaParams``        ``attacks``, ``loads``, ``filters``, ...    a list of dicts of those
                           → ``MultiAreaResult``                       keywords
``MicrogridCase`` (ANDES)  as ``LFCParams``, plus ``design``, ``fault``  —
``GridCase`` (ANDES)       as ``MultiAreaParams``, plus ``design``     a list of dicts
``AndesPlant`` (yours)     as ``MultiAreaParams``, ``design`` needed   —
=========================  ==========================================  ===========================

On ANDES the filters and the AGC keep a linear design model, as in the paper:
``design`` (default: the model fitted to the case, cached on disk).
"""

from __future__ import annotations

import warnings

from lfc._validate import ParameterTypeError
from lfc.model import LFCParams
from lfc.multiarea import MultiAreaParams

__all__ = ["simulate", "simulate_many"]

PLANTS = ("an LFCParams, a MultiAreaParams, an lfc.testbed.MicrogridCase, an "
          "lfc.testbed.GridCase or an lfc.testbed.AndesPlant")
# the methods of lfc.testbed.loop.AndesPlant (a plant of your own on ANDES)
ANDES_PLANT = ("build", "attach", "measure", "extra", "protect", "actuate", "set_load")


def testbed_kind(plant) -> str | None:
    """``"microgrid"`` or ``"grid"`` for a testbed case, ``"andes"`` for an
    ANDES plant (:class:`lfc.testbed.loop.AndesPlant`), else None (ANDES is only
    imported when one is given)."""
    if all(callable(getattr(plant, m, None)) for m in ANDES_PLANT) \
            and hasattr(plant, "n_areas"):
        return "andes"
    module = type(plant).__module__
    if not module.startswith("lfc.testbed"):
        return None
    from lfc.testbed import GridCase, MicrogridCase
    if isinstance(plant, MicrogridCase):
        return "microgrid"
    if isinstance(plant, GridCase):
        return "grid"
    return None


def _bad_plant(plant) -> ParameterTypeError:
    return ParameterTypeError(f"plant must be {PLANTS}, got {type(plant).__name__}")


def simulate(plant, *, duration: float, design=None, **kwargs):
    """Simulate one scenario from equilibrium, with a trace.

    Parameters
    ----------
    plant : LFCParams, MultiAreaParams, MicrogridCase or GridCase
        The plant (module docstring).
    duration : float
        Simulated time (s), > 0.
    design : LFCParams or MultiAreaParams, optional
        ANDES cases only: the design model of the generator side (default the
        model fitted to the case).
    **kwargs
        The scenario: for an area, :func:`lfc.simulate.simulate_area`'s
        keywords; for a grid, :func:`lfc.simulate_multiarea.simulate_grid_linear`'s;
        on ANDES also :func:`lfc.testbed.plant.simulate_microgrid`'s (``fault``,
        ``overcurrent``, ``step``) or
        :func:`lfc.testbed.grid_plant.simulate_andes_grid`'s (``step``).

    Returns
    -------
    SimResult or MultiAreaResult
    """
    if design is not None and testbed_kind(plant) is None:
        raise ValueError("design is for ANDES cases only; a linear plant is its own design "
                         "model (give a filter built on another model to study mismatch)")
    if isinstance(plant, LFCParams):
        from lfc.simulate import simulate_area
        return simulate_area(plant, duration=duration, **kwargs)
    if isinstance(plant, MultiAreaParams):
        from lfc.simulate_multiarea import simulate_grid_linear
        return simulate_grid_linear(plant, duration=duration, **kwargs)
    kind = testbed_kind(plant)
    from lfc.engine import check_load_measured
    if kind == "microgrid":
        check_load_measured({None: kwargs.get("scc")}, kwargs.get("estimator"),
                            kwargs.get("load_feedforward", False))
    elif kind is not None:
        check_load_measured(kwargs.get("filters") or {}, kwargs.get("estimator"),
                            kwargs.get("feedforward", True))
    if kind == "microgrid":
        from lfc.testbed.fit import design_model
        from lfc.testbed.plant import simulate_microgrid
        return simulate_microgrid(design if design is not None else design_model(plant),
                                  duration=duration, case=plant, **kwargs)
    if kind == "grid":
        from lfc.testbed.grid_fit import grid_design
        from lfc.testbed.grid_plant import simulate_andes_grid
        return simulate_andes_grid(design if design is not None else grid_design(plant),
                                   duration=duration, case=plant, **kwargs)
    if kind == "andes":
        from lfc.testbed.grid_plant import simulate_andes_grid
        if design is None:
            raise ValueError("design is required for an AndesPlant of your own: a "
                             "MultiAreaParams of its n_areas areas")
        return simulate_andes_grid(design, duration=duration, plant=plant, **kwargs)
    raise _bad_plant(plant)


#: what :func:`simulate_many` returns: the metrics table, or one result per scenario
KEEP = ("metrics", "results")


def simulate_many(plant, scenarios, *, duration: float, design=None, keep: str = "metrics",
                  **kwargs):
    """Simulate many scenarios: the metrics table for every plant, or one result
    (with its trace) per scenario.

    Parameters
    ----------
    plant : LFCParams, MultiAreaParams or GridCase
        The plant (module docstring).
    scenarios : DataFrame or list of dict
        For an area, a table (:func:`lfc.batch.simulate_table`: one row per
        scenario); for a grid, a list of dicts of :func:`simulate`'s keywords.
    duration : float
        Simulated time (s), > 0.
    design : MultiAreaParams, optional
        ``GridCase`` only (default the model fitted to the case).
    keep : {"metrics", "results"}
        ``"metrics"`` (default): the metrics table; ``"results"``: a list of one
        :class:`SimResult` or :class:`MultiAreaResult` per scenario, in their
        order, whose ``metrics()`` are the table's rows.
    **kwargs
        For an area: ``relays``, ``dt``, ``control_period``, ``progress``, and with
        ``keep="metrics"`` ``executor``, ``chunk_size``, ``out``, ``lanes``; for a
        grid: ``relays``, ``dt``, ``control_period``, ``jobs`` and keywords every
        scenario shares (``loads=``, ``anti_windup=``, ...); for a ``GridCase``
        also ``progress``.

    Returns
    -------
    DataFrame or list
        An area: ``scenarios`` with the metric columns added; a grid (linear or
        ANDES): one row per scenario and area (``scenario``, ``area`` and the
        metrics).  With ``keep="results"``, the results.
    """
    if keep not in KEEP:
        raise ValueError(f"keep must be one of {KEEP}, got {keep!r:.40}")
    if design is not None and testbed_kind(plant) is None:
        raise ValueError("design is for ANDES cases only")
    if isinstance(plant, LFCParams):
        from lfc.batch import simulate_table, table_results
        if keep == "metrics":
            return simulate_table(plant, scenarios, duration=duration, **kwargs)
        _only_for_metrics(kwargs, ("executor", "chunk_size", "out", "lanes"))
        return table_results(plant, scenarios, duration=duration, **kwargs)
    if isinstance(plant, MultiAreaParams):
        from lfc.simulate_multiarea import (SCENARIO_KEYS, check_grid_scenarios, grid_results,
                                            simulate_grid_table)
        shared = {k: kwargs.pop(k) for k in SCENARIO_KEYS if k in kwargs}
        if shared:                                   # keywords every scenario shares
            check_grid_scenarios(scenarios)
            scenarios = [{**shared, **s} for s in scenarios]
        run = simulate_grid_table if keep == "metrics" else grid_results
        return run(plant, scenarios, duration=duration, **kwargs)
    kind = testbed_kind(plant)
    if kind == "grid":
        from lfc.simulate_multiarea import results_table
        from lfc.testbed.grid_fit import grid_design
        from lfc.testbed.grid_plant import simulate_andes_grid_table
        results = simulate_andes_grid_table(design if design is not None else grid_design(plant),
                                            scenarios, duration=duration, case=plant, **kwargs)
        return results if keep == "results" else results_table(results)
    if kind == "microgrid":
        raise ValueError("simulate_many does not run the ANDES microgrid (one scenario per "
                         "call: simulate(MicrogridCase(), ...))")
    if kind == "andes":
        raise ValueError("simulate_many does not run an AndesPlant of your own (one scenario "
                         "per call: simulate(plant, design=..., ...))")
    raise _bad_plant(plant)


def _only_for_metrics(kwargs: dict, names: tuple[str, ...]) -> None:
    given = [n for n in names if n in kwargs]
    if given:
        raise ValueError(f"{given[0]} is for keep='metrics' (the metrics table, in chunks and "
                         f"processes); keep='results' runs each row with its trace")


# -- the names of release 0.3, for one release --------------------------------------------
def _deprecated(old: str, new: str) -> None:
    warnings.warn(f"lfc.{old} is deprecated and will be removed in 0.5; use lfc.{new} "
                  f"(the same keywords)", DeprecationWarning, stacklevel=3)
# (simulate_testbed, simulate_grid, simulate_grid_batch: lfc/testbed/deprecated.py)


def simulate_batch(params: LFCParams, scenarios, **kwargs):
    """Deprecated: :func:`simulate_many` of an ``LFCParams`` plant."""
    _deprecated("simulate_batch", "simulate_many")
    return simulate_many(params, scenarios, **kwargs)


def simulate_multiarea(params: MultiAreaParams, **kwargs):
    """Deprecated: :func:`simulate` of a ``MultiAreaParams`` plant."""
    _deprecated("simulate_multiarea", "simulate")
    if not isinstance(params, MultiAreaParams):
        raise ParameterTypeError(f"params must be a MultiAreaParams, got "
                                 f"{type(params).__name__}")
    return simulate(params, **kwargs)


def simulate_multiarea_batch(params: MultiAreaParams, scenarios, **kwargs):
    """Deprecated: :func:`simulate_many` of a ``MultiAreaParams`` plant."""
    _deprecated("simulate_multiarea_batch", "simulate_many")
    if not isinstance(params, MultiAreaParams):
        raise ParameterTypeError(f"params must be a MultiAreaParams, got "
                                 f"{type(params).__name__}")
    return simulate_many(params, scenarios, **kwargs)

