"""What every safety filter shares: the result of one call, the flag bits the
compiled filters return, and the backend interface.

A filter method is one module of :mod:`lfc.filters` with a :class:`Backend`
subclass and its :class:`Options` dataclass (each option declared once, with
its unit, default and valid range; validated when built), a flat ``data``
array that its compiled ``decide`` function reads, and ``memory`` per scenario
(e.g. the command it holds).  Every call goes through :func:`lfc.filters.dispatch.decide`
(one state) or :func:`~lfc.filters.dispatch.decide_many` (N states), the same
compiled code the engine runs; one state is a batch of one.
"""

from __future__ import annotations

import difflib
import functools
import math
import sys
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import MISSING, dataclass, field, fields
from typing import Any, ClassVar, NamedTuple, TypeVar, get_type_hints

import numpy as np

from lfc._files import cache_folder, content_key, kept
from lfc._jit import inline
from lfc._validate import (ParameterTypeError, check_number, conforms, engine_number,
                           kind)
from lfc.model import LFCParams
from lfc.relays import RelaySettings

# flag bits returned by every compiled decide()
ACTIVE, INFEASIBLE, OUTSIDE, INVALID, SOLVER_ERROR = 1, 2, 4, 8, 16
BIND_FREQ, BIND_ROCOF, BIND_UMIN, BIND_UMAX, BIND_CERT = 32, 64, 128, 256, 512
KIND_FREQ_LO, KIND_FREQ_HI, KIND_ROCOF_LO, KIND_ROCOF_HI = 1024, 2048, 4096, 8192
ALARM_BITS = ACTIVE | INFEASIBLE | OUTSIDE | INVALID | SOLVER_ERROR
ALARM_FLAGS = ("active", "infeasible", "outside", "invalid_input", "solver_error")
_FLAG_BITS = dict(zip(ALARM_FLAGS, (ACTIVE, INFEASIBLE, OUTSIDE, INVALID, SOLVER_ERROR)))
_BINDING = (("frequency", BIND_FREQ), ("rocof", BIND_ROCOF), ("certified", BIND_CERT),
            ("u_min", BIND_UMIN), ("u_max", BIND_UMAX))
MEMORY = 3  # floats of memory per scenario, for every method
CONSTRAINTS = ("frequency", "rocof")   # the barrier constraints, in the order of the outputs
MAX_ABS_INPUT = 1e6  # pu, pu/s: a state, command or load beyond is a corrupted message


@inline
def valid_input(x: np.ndarray, u_ref: float, p: float) -> bool:
    """Whether a filter can evaluate this call: every state, the command and the
    load finite and within ``MAX_ABS_INPUT`` (larger values would overflow the
    barrier and certificate arithmetic; no real measurement is near them)."""
    ok = abs(u_ref) <= MAX_ABS_INPUT and abs(p) <= MAX_ABS_INPUT   # False for NaN
    for v in x:
        ok = ok and abs(v) <= MAX_ABS_INPUT
    return ok


@inline
def hold_invalid(mem: np.ndarray, u_ref: float) -> tuple:
    """A filter's answer to a call it cannot evaluate (:func:`valid_input`): the
    last command ``mem[0]`` held, flagged ``INVALID`` (and ``ACTIVE`` if it differs
    from ``u_ref``), every value NaN — the ten outputs of every ``decide``."""
    nan = math.nan
    u = mem[0]
    return u, INVALID | (ACTIVE if u != u_ref else 0), nan, nan, nan, nan, nan, nan, nan, nan


@inline
def applied_flags(u: float, u_ref: float, certified: bool, u_min: float, u_max: float) -> int:
    """The flag bits of applying ``u`` for ``u_ref``: ``ACTIVE`` if they differ and,
    for a command clipped to a certified interval, ``BIND_CERT`` and the actuator
    limit it sits on (``BIND_UMIN``, ``BIND_UMAX``)."""
    flags = 0
    if u != u_ref:
        flags |= ACTIVE
        if certified:
            flags |= BIND_CERT
            for lim, bit in ((u_min, BIND_UMIN), (u_max, BIND_UMAX)):
                if math.isfinite(lim) and abs(u - lim) <= 1e-9 * (1 + abs(lim)):
                    flags |= bit
    return flags


class FilterInfo(NamedTuple):
    """What a safety filter did at one call.

    Attributes
    ----------
    u_ref, u : float
        Incoming and applied governor command (pu).
    active : bool
        The command was changed (the filter intervened; an alarm).
    infeasible : bool
        The constraints could not all be met; ``u`` is the method's compromise.
    outside : bool
        The filter could not act inside its guarantee: the paper's prediction is
        already outside the safe set (``h <= 0``, E9); the certified filter found
        no certified command and holds the last one.
    invalid_input : bool
        ``x``, ``u_ref`` or ``p_load`` was not finite; no constraint was evaluated.
    solver_error : bool
        A reference (cvxpy) solve failed; the exact solution was used.
    h_freq, h_rocof : float
        ``F^2 - y_freq^2`` (pu^2) and ``limit^2 - y_rocof^2`` ((pu/s)^2): how far
        inside its relay setting each output the filter checks is.
    margin_freq, margin_rocof : float
        Distance (pu of command) from the applied command to the nearest bound
        that keeps that relay safe (>= 0: met; NaN: the command has no influence
        or nothing was evaluated).
    y_freq, y_rocof : float
        The outputs the filter checks: the paper's prediction at ``t + Ts``; the
        certified filter's current measurement (pu, pu/s).
    binding : tuple of str
        Bounds the applied command sits on: ``"frequency"``, ``"rocof"``,
        ``"certified"``, ``"u_min"``, ``"u_max"`` (empty when not active).
    reason : str
        Human-readable explanation ("" when nothing happened).
    details : dict
        Method-specific values (the paper's constraint bounds, the certified
        interval; see the method's module).
    """

    u_ref: float
    u: float
    active: bool
    infeasible: bool
    outside: bool
    invalid_input: bool
    solver_error: bool
    h_freq: float
    h_rocof: float
    margin_freq: float
    margin_rocof: float
    y_freq: float
    y_rocof: float
    binding: tuple
    reason: str
    details: dict

    @property
    def alarm(self) -> bool:
        """True when the operator should be told (anything but a pass-through)."""
        return self.active or self.infeasible or self.outside or self.invalid_input \
            or self.solver_error


def flag(flags: np.ndarray | int, name: str) -> np.ndarray | bool:
    """The alarm flag ``name`` (one of ``ALARM_FLAGS``) of flag bits."""
    return (np.asarray(flags) & _FLAG_BITS[name]) != 0


def binding_names(flags: int) -> tuple[str, ...]:
    """The bounds named by the binding bits of ``flags``."""
    return tuple(name for name, bit in _BINDING if flags & bit)


def option(default: Any, unit: str, valid: str, doc: str) -> Any:
    """A field of an :class:`Options` dataclass: its default, unit (``""`` when
    dimensionless), valid range in words and meaning (shown by
    :func:`lfc.filters.option_table` and in every error about it)."""
    return field(default=default, metadata={"unit": unit, "valid": valid, "doc": doc})


@functools.cache
def _names(cls: type) -> frozenset[str]:
    """The field names of the dataclass ``cls`` (read once per class)."""
    return frozenset(f.name for f in fields(cls))


@dataclass(frozen=True)
class Options:
    """A filter method's options: subclasses declare each one with :func:`option`
    and check them in ``__post_init__`` (a ``ValueError`` naming the option and
    its valid range).  ``COLUMNS`` names the scenario-table columns
    (:func:`lfc.simulate_many`) that :meth:`from_columns` reads."""

    COLUMNS: ClassVar[tuple[str, ...]] = ()

    @classmethod
    def build(cls, method: str, given: dict) -> "Options":
        """The options of ``method`` from keyword arguments; an unknown name is a
        ``ValueError`` listing the valid ones (with the closest match)."""
        names = [f.name for f in fields(cls)]
        unknown = [k for k in given if k not in names]
        if unknown:
            close = difflib.get_close_matches(unknown[0], names, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise ValueError(f"method {method!r} has no option {unknown[0]!r}{hint} "
                             f"(its options: {', '.join(names)})")
        return cls(**given)

    def __post_init__(self) -> None:
        """Every option of the type it is annotated with (a string where a number
        belongs is a :class:`~lfc._validate.ParameterTypeError`), however the
        options are built; subclasses check ranges after calling this."""
        hints = get_type_hints(type(self))
        for f in fields(self):
            value = getattr(self, f.name)
            if not conforms(value, hints[f.name]):
                raise ParameterTypeError(f"{f.name} must be {kind(hints[f.name])}, got "
                                         f"{value!r} ({type(value).__name__})")
            object.__setattr__(self, f.name, engine_number(f.name, value, hints[f.name]))

    @classmethod
    def from_columns(cls, row: dict) -> dict:  # pragma: no cover - abstract
        """Keyword arguments from one scenario-table row (its ``COLUMNS``)."""
        raise NotImplementedError

    def to_columns(self) -> dict:
        """The scenario-table columns :meth:`from_columns` reads back as these options
        (those of ``COLUMNS`` that are options; a row's noise columns are its
        scenario's)."""
        return {c: getattr(self, c) for c in self.COLUMNS if hasattr(self, c)}

    @classmethod
    def for_period(cls, control_period: float) -> dict:
        """``{"control_period": control_period}`` for a method whose options depend
        on the period of its calls (s), else ``{}``: what a simulation adds to the
        options of a filter it builds."""
        return {"control_period": control_period} if "control_period" in _names(cls) else {}

    def as_dict(self) -> dict:
        """Every option and its value (``SafetyFilter(..., **as_dict())`` rebuilds it)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def changed(self) -> dict:
        """The options that differ from their defaults."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if f.default is MISSING or getattr(self, f.name) != f.default}


class Layout:
    """The named fields of a packed float64 array, in order: a name alone is one
    number, ``(name, size)`` a block of ``size``; every offset is computed here,
    none written by hand.  A filter's compiled ``decide`` reads its data at the
    offsets of its module's layout (module constants: numba reads them as
    compile-time numbers); :meth:`unpack` names what an array holds.

    >>> Layout("alpha", ("P", 10), "u_max").offsets()
    (0, 1, 11)
    """

    def __init__(self, *fields: str | tuple[str, int]) -> None:
        self.fields = tuple((f, 1) if isinstance(f, str) else (str(f[0]), int(f[1]))
                            for f in fields)
        names = [name for name, _ in self.fields]
        if len(set(names)) != len(names) or any(size < 1 for _, size in self.fields):
            raise ValueError(f"a layout's fields need distinct names and sizes >= 1, got "
                             f"{self.fields}")
        starts = np.concatenate([[0], np.cumsum([size for _, size in self.fields])])
        self.start = dict(zip(names, (int(k) for k in starts[:-1])))
        self.size = int(starts[-1])

    def offsets(self) -> tuple[int, ...]:
        """Every field's first index, in order."""
        return tuple(self.start.values())

    def unpack(self, data: np.ndarray, at: int = 0) -> dict[str, float | np.ndarray]:
        """The fields of ``data[at:at + size]`` by name: a number, or an array for a
        block."""
        out: dict[str, float | np.ndarray] = {}
        for name, size in self.fields:
            k = at + self.start[name]
            out[name] = float(data[k]) if size == 1 else np.asarray(data[k:k + size])
        return out

    def __repr__(self) -> str:
        return "Layout(" + ", ".join(n if s == 1 else f"({n!r}, {s})"
                                     for n, s in self.fields) + ")"


class Backend:
    """A filter method: options, compiled data, memory, and how to explain a call.

    Subclasses set ``name`` and ``Options`` (their :class:`Options` dataclass),
    define their compiled ``decide(fd, x, u_ref, p, mem)`` in their module (its code,
    ``method_id``, is given when they are registered: :func:`lfc.filters.dispatch.assign`;
    a backend with ``jit = False`` is called back from compiled code instead and needs
    none), build ``data`` (float64, read by ``decide``) in ``__init__``, and implement
    :meth:`reason` and :meth:`details`.  The options read through as attributes
    (``backend.alpha``).
    """

    name: str = ""
    method_id: int = -1
    Options: type[Options] = Options
    jit: bool = True

    def __init__(self, params: LFCParams, relays: RelaySettings, options: Options) -> None:
        self.params, self.relays, self.options = params, relays, options
        self.data = np.zeros(1)
        self._flag_memo: dict[int, tuple] = {}     # _by_flags' answers, per flag value

    def __getattr__(self, name: str):
        if name == "options":
            raise AttributeError(name)
        try:
            return getattr(self.options, name)
        except AttributeError:
            raise AttributeError(f"{type(self).__name__!r} has no attribute {name!r}") from None

    @classmethod
    def grid_options(cls, grid: Any, area: int, relays: RelaySettings,
                     control_period: float) -> dict:
        """The options this method takes at area ``area`` of ``grid`` (a
        ``MultiAreaParams``) when a grid's filter is named by kind
        (:func:`lfc.filters.build`): none beyond its defaults unless the method
        says otherwise."""
        return {}

    def reason(self, flags: int) -> str:  # pragma: no cover - abstract
        raise NotImplementedError

    def details(self, d0: float, d1: float, flags: int) -> dict:  # pragma: no cover
        raise NotImplementedError

    def describe(self) -> str:
        """The constructor call that rebuilds this filter (for ``repr`` and logs):
        every option, defaults included."""
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options.as_dict().items())
        return f"SafetyFilter(method={self.name!r}, {opts})"

    def info(self, u_ref: float, out: tuple) -> FilterInfo:
        """A :class:`FilterInfo` from one compiled ``decide`` result."""
        u, flags, h0, h1, m0, m1, y0, y1, d0, d1 = out
        active, infeasible, outside, invalid, error, binding, reason = self._by_flags(flags)
        return FilterInfo(u_ref, u, active, infeasible, outside, invalid, error,
                          h0, h1, m0, m1, y0, y1, binding, reason,
                          self.details(d0, d1, flags))

    def _by_flags(self, flags: int) -> tuple:
        """What :meth:`info` reads from the flag bits alone (the booleans, the binding
        bounds and the reason), worked out once per value of ``flags`` (a handful
        occur; the options that word the reason are frozen)."""
        memo = self._flag_memo
        if flags not in memo:
            memo[flags] = (bool(flags & ACTIVE), bool(flags & INFEASIBLE),
                           bool(flags & OUTSIDE), bool(flags & INVALID),
                           bool(flags & SOLVER_ERROR),
                           binding_names(flags) if flags & ACTIVE else (),
                           self.reason(flags) if flags & ALARM_BITS else "")
        return memo[flags]


def given(value: object) -> bool:
    """Whether a scenario-table cell holds a value (not None, not NaN)."""
    return value is not None and not (isinstance(value, float) and math.isnan(value))


def check_limits(u_min: float, u_max: float) -> None:
    """Raise ``ValueError`` unless ``u_min < u_max`` (actuator limits, pu)."""
    check_number("u_min", u_min)
    check_number("u_max", u_max)
    if not (u_min < u_max) or math.isnan(u_min) or math.isnan(u_max):
        raise ValueError(f"u_min must be < u_max, got u_min={u_min!r}, u_max={u_max!r}")


def check_choice(name: str, value: str, allowed: tuple[str, ...]) -> None:
    """Raise ``ValueError`` unless ``value`` is one of ``allowed``."""
    if not isinstance(value, str):
        raise ParameterTypeError(f"{name} must be one of {allowed}, got {value!r} "
                                 f"({type(value).__name__})")
    if value not in allowed:
        raise ValueError(f"{name} must be one of {allowed}, got {value!r}")


T = TypeVar("T")
_BUILT: OrderedDict[str, Any] = OrderedDict()     # built_once's, most recent last
BUILT_KEPT = 64
STORE_AFTER = 0.5   # s: with ``store``, a value that took this long to build is kept on disk
STORE_LIMIT = 512e6   # bytes: beyond, the least recently written stored values are removed


def built_once(make: Callable[[], T], *key: object, store: bool = False) -> T:
    """``make()``, built once per process for the same ``key`` and shared (the last
    ``BUILT_KEPT`` kept; the same object each time): a certificate's rows take
    seconds to build (a robust set, a coupled grid's), and notebooks and tests ask
    for the same one again.  The key is
    ``key``'s ``repr`` (every value exactly: a float's ``repr`` round-trips, an
    array's is printed whole with every digit), so pass every argument ``make``
    reads (a module constant changed at run time is not in it: build such a value
    directly, as ``tests/test_proven_recovery.py`` does); what ``make`` returns
    must never be changed after.

    With ``store``, a value that took at least ``STORE_AFTER`` seconds to build is
    also kept on disk (pickled, in ``$LFC_CACHE_DIR/built/``, under a key of
    ``key`` and of the code, the environment, the Python version and the BLAS
    kernel: :func:`lfc._files.content_key`; a damaged file is detected by its
    SHA-256 and built again; the folder is kept under ``STORE_LIMIT`` bytes), so
    that another process reads it instead of building it: a test worker, a
    notebook's kernel, a papermill sweep's next run.
    """
    text = repr(key)
    if "array(" in text:          # every element of an array, every digit
        with np.printoptions(threshold=sys.maxsize, floatmode="unique"):
            text = repr(key)
    if text in _BUILT:
        _BUILT.move_to_end(text)
        return _BUILT[text]
    made = _BUILT[text] = stored(make, text) if store else make()
    while len(_BUILT) > BUILT_KEPT:
        _BUILT.popitem(last=False)
    return made


def stored(make: Callable[[], T], text: str) -> T:
    """``make()`` read from the disk (:func:`built_once`'s ``store``), or built
    and written there if it took at least ``STORE_AFTER`` seconds."""
    return kept(cache_folder() / "built" / f"{content_key('built_once', text)}.json", make,
                STORE_AFTER, STORE_LIMIT)


def clear_built() -> None:
    """Forget everything :func:`built_once` keeps (a benchmark timing construction)."""
    _BUILT.clear()
