"""The two entry points: :func:`simulate` (one scenario, a trace) and
:func:`simulate_many` (a table of scenarios, one row of metrics each).

Both take the plant first, and the plant decides what a scenario is:

=========================  ==========================================  ===========================
plant                      ``simulate`` keywords                       ``simulate_many`` scenarios
=========================  ==========================================  ===========================
``LFCParams``              ``pc_attack``, ``wref_attack``, ``load``,   a DataFrame, one row each
                           ``scc``, ...                                (``lfc.tables``)
``MultiAreaParams``        ``attacks``, ``loads``, ``filters``, ...    a list of dicts of those
                                                                       keywords
``MicrogridCase`` (ANDES)  as ``LFCParams``, plus ``design``, ``fault``  —
``GridCase`` (ANDES)       as ``MultiAreaParams``, plus ``design``     a list of dicts
``AndesPlant`` (yours)     as ``MultiAreaParams``, ``design`` needed   —
=========================  ==========================================  ===========================

Every plant's run returns one type, :class:`lfc.Result` (an area's result is its own
only area). On ANDES the filters and the AGC keep a linear design model, as in the paper:
``design`` (default: the model fitted to the case, cached on disk).

A plant brings its own way to run: a :class:`Runner` registered for its type
(:func:`register`) or for a protocol it follows (:func:`register_protocol`: an
``AndesPlant`` of your own is recognized by its methods).  The linear plants register
theirs in :mod:`lfc.tables` (an area) and :mod:`lfc.linear_grid`, the ANDES cases in
:mod:`lfc.testbed.runners`; :data:`PLUGINS` are imported the first time a plant
matches no runner, so this module names no plant type and imports no testbed.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from lfc._validate import ParameterTypeError

__all__ = ["design_of", "simulate", "simulate_many"]

#: the modules that register runners, imported when a plant matches no runner (a module
#: whose optional dependency is missing, the testbed without ANDES, is skipped)
PLUGINS = ("lfc.tables", "lfc.linear_grid", "lfc.testbed")
#: what :func:`simulate_many` returns: the metrics table, or one result per scenario
KEEP = ("metrics", "results")


@dataclass(frozen=True)
class Runner:
    """How one kind of plant runs.

    Parameters
    ----------
    form : {"area", "grid"}
        The form of its scenario keywords (:meth:`lfc.scenarios.Scenario.keywords`):
        an area's (``pc_attack``, ``scc``, ...) or a grid's (``attacks``,
        ``filters``, ...).
    name : str
        The kind of plant (``"area"``, ``"grid"``, ``"microgrid"``, ``"grid case"``,
        ``"andes plant"``): what :func:`runner_of` tells callers that treat kinds
        differently (:mod:`lfc.wire`).
    label : str
        The plant as an error message names it (``"an LFCParams"``).
    simulate : callable
        ``simulate(plant, *, duration, design, **scenario)``: one scenario's result.
    simulate_many : callable, optional
        ``simulate_many(plant, scenarios, *, duration, design, keep, **keywords)``;
        None if the plant runs one scenario per call (``many_refused`` says so).
    takes_design : bool
        Whether ``design=`` (the generator sides' model) means anything for it.
    design : callable, optional
        ``design(plant)``: the plant's default design model (:func:`design_of`); None for
        a linear plant, its own design model.
    many_refused : str
        The message of :func:`simulate_many` for a plant without one.
    """

    form: str
    name: str
    label: str
    simulate: Callable[..., Any]
    simulate_many: Callable[..., Any] | None = None
    takes_design: bool = False
    many_refused: str = ""
    design: Callable[[Any], Any] | None = None


_BY_TYPE: dict[type, Runner] = {}
_BY_PROTOCOL: list[tuple[Callable[[object], bool], Runner]] = []
_plugins_loaded = False


def register(plant_type: type, runner: Runner) -> None:
    """Run plants of ``plant_type`` (and its subclasses) with ``runner``."""
    if not isinstance(plant_type, type) or not isinstance(runner, Runner):
        raise ParameterTypeError(f"register takes a type and a Runner, got {plant_type!r}, "
                                 f"{runner!r:.60}")
    _BY_TYPE[plant_type] = runner


def register_protocol(matches: Callable[[object], bool], runner: Runner) -> None:
    """Run plants for which ``matches(plant)`` is true with ``runner`` (tried after the
    registered types, in the order registered)."""
    if not callable(matches) or not isinstance(runner, Runner):
        raise ParameterTypeError(f"register_protocol takes a callable and a Runner, got "
                                 f"{matches!r:.60}, {runner!r:.60}")
    _BY_PROTOCOL.append((matches, runner))


def _find(plant) -> Runner | None:
    for cls in type(plant).__mro__:
        if cls in _BY_TYPE:
            return _BY_TYPE[cls]
    return next((runner for matches, runner in _BY_PROTOCOL if matches(plant)), None)


def _load_plugins() -> None:
    global _plugins_loaded
    for module in PLUGINS:
        try:
            importlib.import_module(module)
        except ImportError:        # an optional extra that is not installed
            continue
    _plugins_loaded = True


def runner_of(plant) -> Runner:
    """The :class:`Runner` of ``plant``.

    Raises
    ------
    TypeError
        (:class:`~lfc._validate.ParameterTypeError`, also a ``ValueError``) naming the
        plants there are runners for, if ``plant`` is none of them.
    """
    runner = _find(plant)
    if runner is None and not _plugins_loaded:
        _load_plugins()
        runner = _find(plant)
    if runner is None:
        labels = [r.label for r in (*_BY_TYPE.values(), *(r for _, r in _BY_PROTOCOL))]
        names = ", ".join(labels[:-1]) + f" or {labels[-1]}" if len(labels) > 1 else labels[0]
        raise ParameterTypeError(f"plant must be {names}, got {type(plant).__name__}")
    return runner


def design_of(plant):
    """The linear model a plant's filters and AGC are designed on, by default.

    Parameters
    ----------
    plant : LFCParams, MultiAreaParams, MicrogridCase or GridCase
        The plant (module docstring).

    Returns
    -------
    LFCParams or MultiAreaParams
        A linear plant itself; an ANDES case's model fitted to it (what
        :func:`simulate` uses when ``design`` is not given).

    Raises
    ------
    ValueError
        For a plant with no default design model (an ``AndesPlant`` of your own), or
        no runner.
    """
    runner = runner_of(plant)
    return plant if runner.design is None else runner.design(plant)


def simulate(plant, scenario=None, *, duration: float, design=None, **kwargs):
    """Simulate one scenario from equilibrium, with a trace.

    Parameters
    ----------
    plant : LFCParams, MultiAreaParams, MicrogridCase, GridCase or an AndesPlant
        The plant (module docstring).
    scenario : lfc.scenarios.Scenario, optional
        The scenario as one object, in place of its keywords (any plant: an area
        is area 0).
    duration : float
        Simulated time (s), > 0.
    design : LFCParams or MultiAreaParams, optional
        ANDES cases only: the design model of the generator side (default the
        model fitted to the case; required for an ``AndesPlant`` of your own).
    **kwargs
        The scenario: for an area, :func:`lfc.linear_area.simulate_area`'s
        keywords; for a grid, :func:`lfc.linear_grid.simulate_grid_linear`'s;
        on ANDES also :func:`lfc.testbed.microgrid.simulate_microgrid`'s (``fault``,
        ``overcurrent``, ``step``) or
        :func:`lfc.testbed.grids.simulate_andes_grid`'s (``step``).

    Returns
    -------
    Result
    """
    runner = runner_of(plant)
    _check_design(runner, design)
    if scenario is not None:
        kwargs = _with_scenario(runner, scenario, kwargs)
    return runner.simulate(plant, duration=duration, design=design, **kwargs)


def simulate_many(plant, scenarios, *, duration: float, design=None, keep: str = "metrics",
                  **kwargs):
    """Simulate many scenarios: the metrics table for every plant, or one result
    (with its trace) per scenario.

    Parameters
    ----------
    plant : LFCParams, MultiAreaParams or GridCase
        The plant (module docstring).
    scenarios : DataFrame, list of Scenario or list of dict
        A list of :class:`lfc.scenarios.Scenario` for every plant; for an area also a
        table (:func:`lfc.tables.simulate_table`: one row per scenario), for a grid a
        list of dicts of :func:`simulate`'s keywords.
    duration : float
        Simulated time (s), > 0.
    design : MultiAreaParams, optional
        ``GridCase`` only (default the model fitted to the case).
    keep : {"metrics", "results"}
        ``"metrics"`` (default): the metrics table; ``"results"``: a list of one
        :class:`lfc.Result` per scenario, in their order, whose ``table()`` rows are
        the metrics table's.
    **kwargs
        For an area: ``relays``, ``dt``, ``control_period``, ``progress``, and with
        ``keep="metrics"`` ``executor``, ``chunk_size``, ``out``, ``lanes``; for a
        grid: ``relays``, ``dt``, ``control_period``, ``jobs`` and keywords every
        scenario shares (``loads=``, ``anti_windup=``, ...); for a ``GridCase``
        also ``progress``.

    Returns
    -------
    DataFrame or list
        An area's table: ``scenarios`` with the metric columns added; a list of
        scenarios, or a grid (linear or ANDES): one row per scenario and area
        (``scenario``, ``area`` and the metrics).  With ``keep="results"``, the
        results.
    """
    if keep not in KEEP:
        raise ValueError(f"keep must be one of {KEEP}, got {keep!r:.40}")
    runner = runner_of(plant)
    _check_design(runner, design)
    if runner.simulate_many is None:
        raise ValueError(runner.many_refused)
    return runner.simulate_many(plant, scenarios, duration=duration, design=design, keep=keep,
                                **kwargs)


def _with_scenario(runner: Runner, scenario, kwargs: dict) -> dict:
    """``kwargs`` with ``scenario``'s keywords in the runner's form."""
    from lfc.scenarios import AREA_KEYS, GRID_KEYS, Scenario
    if not isinstance(scenario, Scenario):
        raise ParameterTypeError(f"scenario must be an lfc.scenarios.Scenario, got "
                                 f"{type(scenario).__name__}")
    both = sorted(set(kwargs) & {*AREA_KEYS, *GRID_KEYS})
    if both:
        raise ValueError(f"give the scenario as a Scenario or as keywords, not both: {both}")
    if scenario.plant is not None:
        raise ValueError("scenario.plant: simulate runs the plant it is given (a scenario's "
                         "own plant is for simulate_many of a linear area)")
    return {**scenario.keywords(runner.form), **kwargs}


def _check_design(runner: Runner, design) -> None:
    if design is not None and not runner.takes_design:
        raise ValueError("design is for ANDES cases only; a linear plant is its own design "
                         "model (give a filter built on another model to study mismatch)")


def only_for_metrics(kwargs: dict, names: tuple[str, ...]) -> None:
    """``ValueError`` if ``kwargs`` holds one of ``names``, keywords of the metrics
    table only (``keep="results"`` runs each scenario with its trace)."""
    given = [n for n in names if n in kwargs]
    if given:
        raise ValueError(f"{given[0]} is for keep='metrics' (the metrics table, in chunks and "
                         f"processes); keep='results' runs each row with its trace")
