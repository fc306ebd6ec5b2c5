"""Safety filters: the paper's SCC, the certified filter and the contract, behind one
interface.

``SafetyFilter(params, relays, method=..., **options)`` builds the method
registered under that name (:func:`available`; each method is one module here:
a :class:`~lfc.filters.base.Backend` and its options dataclass, whose fields
carry unit, default and valid range, :func:`option_table`) and calls it through
the compiled dispatcher, one state at a time (:meth:`SafetyFilter.filter`) or
many (:meth:`SafetyFilter.filter_batch`).  A filter never raises for numeric
trouble and always returns a finite command; ``FilterInfo`` says what it did.

Adding a method: write its module (options, backend, a compiled ``decide`` or
a Python ``decide_python`` with ``jit = False``), then :func:`register` it here;
registering gives a compiled one its code in the compiled dispatcher
(:func:`lfc.filters.dispatch.assign`), in the order of the calls below; this file is
therefore part of the compiled code's cache stamp (:mod:`lfc._jit`).
``tests/test_conformance.py`` checks every registered method.

A grid-wide filter (the coupled certificate, :mod:`lfc.filters.coupled`) is not a
method of :class:`SafetyFilter`: it reads the whole grid's state, not one area's, and
is shared by the areas (``filters={i: "coupled"}`` in :func:`lfc.simulate`).  Its
class is built as ``cls(grid, relays, control_period=..., noise_std=...)``, its module
defines its compiled ``decide_grid``, and :func:`register_grid` registers it.
"""

from __future__ import annotations

import math
from dataclasses import fields

import numpy as np

from lfc._validate import (ParameterTypeError, as_float, check_array, check_number,
                           check_positive)
from lfc.filters.base import (ALARM_BITS, ALARM_FLAGS, MEMORY, Backend, FilterInfo, Options,
                              binding_names, built_once, flag)
from lfc.filters.certified import CertifiedFilter, CertifiedOptions
from lfc.filters.contract import ContractFilter, ContractOptions
from lfc.filters.coupled import CoupledFilter
from lfc.filters.dispatch import PYTHON, assign, close, decide, decide_many, register_python
from lfc.filters.paper import (CONFLICT_RULES, DEFAULT_READING, OUTSIDE_RULES, PREDICTIONS,
                               PaperFilter, PaperOptions)
from lfc.model import STATES, LFCParams
from lfc.multiarea import MultiAreaParams
from lfc.relays import RelaySettings, relays_or_default

__all__ = ["ALARM_BITS", "ALARM_FLAGS", "CONFLICT_RULES", "DEFAULT_READING", "METHODS",
           "OUTSIDE_RULES", "PREDICTIONS", "CertifiedOptions", "ContractOptions", "FilterInfo",
           "PaperOptions", "SafetyFilter", "alarm_mask", "available", "binding_names", "build",
           "option_table", "options_of", "register", "register_grid"]

REGISTRY: dict[str, type[Backend]] = {}
#: the grid-wide filters, by name (:func:`register_grid`)
GRID_REGISTRY: dict[str, type] = {}


def register(backend: type[Backend]) -> type[Backend]:
    """Make ``backend`` a method of :class:`SafetyFilter`, under ``backend.name``."""
    if not (isinstance(backend, type) and issubclass(backend, Backend)):
        raise ParameterTypeError(f"backend must be a Backend subclass, got {backend!r:.80}")
    if not backend.name or backend.name in REGISTRY:
        raise ValueError(f"a filter method needs a new name, got {backend.name!r}")
    if not (isinstance(backend.Options, type) and issubclass(backend.Options, Options)):
        raise ValueError(f"{backend.__name__}.Options must be an Options dataclass")
    if backend.jit:
        assign(backend)
    REGISTRY[backend.name] = backend
    return backend


def register_grid(cls: type) -> type:
    """Make ``cls`` (a compiled filter of the whole grid, ``grid_wide = True``; module
    docstring) buildable by its ``name`` in :func:`build` and give it its code."""
    if not (isinstance(cls, type) and getattr(cls, "grid_wide", False)):
        raise ParameterTypeError(f"cls must be a class with grid_wide = True, got {cls!r:.80}")
    if not getattr(cls, "name", "") or cls.name in REGISTRY or cls.name in GRID_REGISTRY:
        raise ValueError(f"a grid-wide filter needs a new name, got {getattr(cls, 'name', '')!r}")
    assign(cls)
    GRID_REGISTRY[cls.name] = cls
    return cls


register(PaperFilter)
register(CertifiedFilter)
register(ContractFilter)
register_grid(CoupledFilter)
close()   # the compiled dispatchers' codes are given: a method registered later is Python
METHODS = tuple(REGISTRY)   # the methods of this release (available() includes later ones)


def available() -> tuple[str, ...]:
    """The names of the registered filter methods."""
    return tuple(REGISTRY)


def _backend(method: str) -> type[Backend]:
    if not isinstance(method, str) or method not in REGISTRY:
        error = ValueError if isinstance(method, str) else ParameterTypeError
        raise error(f"method must be one of {available()}, got {method!r:.80}")
    return REGISTRY[method]


def build(kind: str, plant: LFCParams | MultiAreaParams, area: int = 0,
          relays: RelaySettings | None = None, *, control_period: float = 0.01,
          noise_std: tuple[float, float] | None = None):
    """The filter named ``kind`` for area ``area`` of ``plant``: the one way to build
    a filter by name.

    A registered method (:func:`available`) is a :class:`SafetyFilter` on the
    area's model with the options its backend takes in a grid
    (``Backend.grid_options``: the certified filter's tie-line ``load_bound`` and
    the grid's command range, the contract filter's share of the grid's contract;
    the defaults on a single area) and ``control_period`` where the method has
    one; a grid-wide kind (:data:`GRID_REGISTRY`: ``"coupled"``, the grid's coupled
    certificate :class:`lfc.filters.coupled.CoupledFilter`) is its class with its
    defaults, the same object for every area, which must all have it
    (``noise_std``: the noise of its grid Kalman estimate), built once per grid,
    relays, period and noise.

    Raises
    ------
    ValueError
        An unknown kind (naming the valid ones), or a filter its defaults cannot
        build on this area (naming them and why).
    """
    relays = relays_or_default(relays)
    grid = plant if isinstance(plant, MultiAreaParams) else None
    if grid is None and not isinstance(plant, LFCParams):
        raise ParameterTypeError(f"plant must be an LFCParams or a MultiAreaParams, got "
                                 f"{type(plant).__name__}")
    if isinstance(kind, str) and kind in GRID_REGISTRY:
        if grid is None:
            raise ValueError(f"{kind!r} is a grid's certificate: give a MultiAreaParams")
        return _grid_wide(GRID_REGISTRY[kind], grid, relays, control_period, noise_std, area)
    if not isinstance(kind, str) or kind not in REGISTRY:
        error = ValueError if isinstance(kind, str) else ParameterTypeError
        raise error(f"filters[{area}] must be one of {(*available(), *GRID_REGISTRY)}, a "
                    f"SafetyFilter or None, got {kind!r:.80}")
    backend = REGISTRY[kind]
    options = {**backend.Options.for_period(control_period),
               **(backend.grid_options(grid, area, relays, control_period) if grid else {})}
    try:
        return SafetyFilter(grid.areas[area] if grid else plant, relays, method=kind,
                            **options)
    except ValueError as err:
        given = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v!r}"
                          for k, v in options.items())
        raise ValueError(f"filters[{area}]={kind!r} cannot be built from its grid defaults "
                         f"{given} ({err}); lower control_period, or build a SafetyFilter "
                         f"yourself") from err


def _grid_wide(cls: type, grid: MultiAreaParams, relays: RelaySettings,
               control_period: float, noise_std: tuple[float, float] | None, area: int):
    noise = None if noise_std is None else tuple(noise_std)
    try:
        return built_once(lambda: cls(grid, relays, control_period=control_period,
                                      noise_std=noise),
                          f"{cls.name}_filter", grid, relays, control_period, noise)
    except ValueError as err:
        raise ValueError(f"filters[{area}]={cls.name!r} (the default options) cannot be "
                         f"built: {err}; build a {cls.__name__} with other options and give "
                         f"it to every area (with horizon='auto' its horizon also follows a "
                         f"legitimate load step: held_after_step)") from err


def options_of(method: str) -> type[Options]:
    """The options dataclass of ``method``."""
    return _backend(method).Options


def option_table(method: str) -> list[dict]:
    """Each option of ``method``: ``name``, ``default``, ``unit``, ``valid``
    (range), ``doc``; in declaration order."""
    return [{"name": f.name, "default": f.default, **f.metadata}
            for f in fields(options_of(method))]


def alarm_mask(flags: dict[str, np.ndarray]) -> np.ndarray:
    """:attr:`FilterInfo.alarm` for the flags of :meth:`SafetyFilter.filter_batch`."""
    present = [np.asarray(flags[f], bool) for f in ALARM_FLAGS if f in flags]
    if not present:
        raise ValueError(f"flags must hold at least one of {ALARM_FLAGS} (the flags of "
                         f"filter_batch), got keys {sorted(map(str, flags))}")
    return np.logical_or.reduce(present)


class SafetyFilter:
    """A safety filter at the generator: minimally modify the governor command so
    that the frequency and ROCOF relays stay safe.

    Parameters
    ----------
    params : LFCParams
        Design model.
    relays : RelaySettings, optional
        Relay settings defining the safe set (default IEEE 1547 Cat. III).
    method : str
        One of :func:`available`: ``"paper"`` (default), the paper's CBF-QP
        (options :class:`PaperOptions`: ``alpha``, ``Ts``, ``solver``,
        ``u_min``, ``u_max``, ``slack_weight``, ``outside_rule``,
        ``conflict``, ``prediction``); ``"certified"``, the filter with a
        guarantee (options :class:`CertifiedOptions`: ``horizon``,
        ``load_bound``, ``load_kind``, ``margin``, ``uncertainty``, ``noise_std``,
        ``confidence``, ``trips_per_hour``, ``relay_rate``, ``tightening``,
        ``u_min``, ``u_max``, ``control_period``); ``"contract"``, the command kept in
        a box that certifies a grid by contract (options :class:`ContractOptions`:
        ``half_width``, ``rate``, ``load_bound``, ``margin``, ``control_period``;
        :mod:`lfc.filters.contract`).
        :func:`option_table` lists units, defaults and ranges.
    **options
        The method's options.

    Raises
    ------
    ValueError
        For an unknown method, an option the method does not take, or an
        invalid option value (the message names it).
    """

    def __init__(self, params: LFCParams, relays: RelaySettings | None = None, *,
                 method: str = "paper", **options) -> None:
        if not isinstance(params, LFCParams):
            raise ParameterTypeError(f"params must be an LFCParams (the design model), got "
                                     f"{params!r:.80} ({type(params).__name__})")
        backend = _backend(method)
        for name in options:
            owners = [m for m in available() if m != method and name in
                      {f.name for f in fields(options_of(m))}]
            if owners and name not in {f.name for f in fields(backend.Options)}:
                raise ValueError(f"{name!r} is an option of method {owners[0]!r}, not of "
                                 f"{method!r} (give method={owners[0]!r}; {method!r} takes "
                                 f"{', '.join(f.name for f in fields(backend.Options))})")
        self.params = params
        self.relays = relays_or_default(relays)
        self.backend = backend(params, self.relays, backend.Options.build(method, options))
        self.method = method
        if self.backend.jit:
            self.method_id, self.data = self.backend.method_id, self.backend.data
        else:   # called back from compiled code
            self.method_id, self.data = PYTHON, register_python(self.backend)
        self.reset()

    @property
    def options(self) -> Options:
        """The method's options (``SafetyFilter(params, relays, method=...,
        **options.as_dict())`` rebuilds this filter)."""
        return self.backend.options

    def check_period(self, control_period: float) -> None:
        """Raise ``ValueError`` if this filter was built for calls at another period
        than ``control_period`` (s): its option ``control_period``, where it has one
        (the certified filter's estimation bound depends on it)."""
        check_positive("control_period", control_period)
        own = getattr(self.options, "control_period", None)
        if own is not None and not math.isclose(own, control_period, rel_tol=1e-9):
            raise ValueError(f"the filter was built for control_period={own} s but the "
                             f"simulation calls it every {control_period} s; build it with "
                             f"control_period={control_period}")

    def __getattr__(self, name: str):
        """The backend's options (``alpha``, ``Ts``, ``cert``, ...) read through."""
        if name == "backend":
            raise AttributeError(name)
        return getattr(self.backend, name)

    def __repr__(self) -> str:
        return self.backend.describe()

    def reset(self) -> None:
        """Forget the memory of earlier calls (held or last applied command)."""
        self._memory = np.zeros(MEMORY)
        self._batch_memory = np.zeros((0, MEMORY))

    def filter(self, x: np.ndarray, u_ref: float, p_load: float = 0.0
               ) -> tuple[float, FilterInfo]:
        """Filter one governor command.

        Parameters
        ----------
        x : array_like, shape (5,)
            State ``[dPg, dPm, dw, dw_meas, rocof_meas]`` (pu, pu/s): true or estimated.
        u_ref : float
            Incoming governor command dPc (pu).
        p_load : float
            Load change the filter assumes (pu); 0 when unmeasured (E7).

        Returns
        -------
        u : float
            Command to apply (pu), always finite.
        info : FilterInfo
            What the filter did and why.

        Raises
        ------
        ValueError
            If ``x`` does not have shape (5,) (a programming error, not numeric trouble).
        TypeError
            If ``x``, ``u_ref`` or ``p_load`` is not made of real numbers (a string,
            a bool, a complex number).
        """
        x = check_array("x", x)
        if x.shape != (5,):
            raise ValueError(f"x must have 5 entries {STATES}, got shape {x.shape}")
        check_number("u_ref", u_ref)
        check_number("p_load", p_load)
        u_ref = as_float(u_ref)
        out = decide(self.method_id, self.data, x, u_ref, as_float(p_load), self._memory)
        return out[0], self.backend.info(u_ref, out)

    def filter_batch(self, x: np.ndarray, u_ref: np.ndarray, p_load: np.ndarray | None = None
                     ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Filter N commands at once (each row has its own memory, kept between
        calls while N stays the same).

        Parameters
        ----------
        x : ndarray, shape (N, 5)
            States (pu, pu/s).
        u_ref : ndarray, shape (N,)
            Incoming commands (pu).
        p_load : ndarray, shape (N,), optional
            Load change the filter assumes (pu); default 0 (unmeasured, E7).

        Returns
        -------
        u : ndarray, shape (N,)
            Applied commands (pu), always finite.
        flags : dict of ndarray
            ``active``, ``infeasible``, ``outside``, ``invalid_input``,
            ``solver_error`` (N,), ``h``, ``margin``, ``y`` (N, 2) as in
            :class:`FilterInfo`, and the method's ``details`` (N, 2 each).

        Raises
        ------
        ValueError
            If ``x`` is not (N, 5), ``u_ref`` or ``p_load`` not (N,) or their
            lengths differ (a programming error, not numeric trouble).
        TypeError
            If an array does not hold real numbers.
        """
        x = check_array("x", x)
        if x.shape == (5,):
            x = x[None]
        x = np.ascontiguousarray(check_array("x", x, shape=(None, 5)))
        u_ref = check_array("u_ref", u_ref, shape=(None,))
        p = np.zeros(len(u_ref)) if p_load is None else check_array("p_load", p_load,
                                                                     shape=(None,))
        if not len(x) == len(u_ref) == len(p):
            raise ValueError(f"x, u_ref and p_load must have the same length N, got "
                             f"{len(x)}, {len(u_ref)} and {len(p)}")
        if len(self._batch_memory) != len(u_ref):
            self._batch_memory = np.zeros((len(u_ref), MEMORY))
        bits, values = np.zeros(len(u_ref), np.int64), np.zeros((len(u_ref), 8))
        u = decide_many(self.method_id, self.data, x, u_ref, p, self._batch_memory, bits, values)
        out = {name: flag(bits, name) for name in ALARM_FLAGS}
        out.update(h=values[:, 0:2], margin=values[:, 2:4], y=values[:, 4:6], bits=bits)
        d = self.backend.details(values[:, 6], values[:, 7], bits)
        out.update({k: np.column_stack(v) for k, v in d.items()})
        return u, out

