"""Argument checks shared by the parameter classes (clear messages naming the
parameter and its valid range).

A number is a real (Python or numpy) that is not a bool: ``True`` is not a time
constant.  A value of the wrong type (a string where a number belongs) raises
:class:`ParameterTypeError`, never coerced; a number out of range ``ValueError``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from numbers import Integral, Real
from types import UnionType
from typing import Any, Union, get_args, get_origin, get_type_hints

import numpy as np


class ParameterTypeError(TypeError, ValueError):
    """A parameter of the wrong type.  A ``TypeError``, and a ``ValueError`` too,
    so that code catching bad input as ``ValueError`` still catches it."""


def _is_number(value: object) -> bool:
    if type(value) is float or type(value) is int:   # the common case, without the ABC check
        return True
    return isinstance(value, Real) and not isinstance(value, bool)


def _is_integer(value: object) -> bool:
    if type(value) is int:                           # the common case, without the ABC check
        return True
    return isinstance(value, Integral) and not isinstance(value, bool)


def is_finite(value: float) -> bool:
    """``math.isfinite``, false for an integer too large for a float (10**400)."""
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def as_float(value: float) -> float:
    """A checked number as a float: an integer too large for one becomes an
    infinity of its sign (which a filter then refuses as non-finite input)."""
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def engine_number(name: str, value: Any, hint: Any) -> Any:
    """``value`` (which conforms to ``hint``) in the engine's types: a number where
    the hint says ``float`` (a ``Fraction``, a numpy scalar, an integer) as a
    Python float, in a tuple of floats likewise; anything else as it is.  An
    integer too large for a float is refused naming ``name`` (``ValueError``):
    nothing accepted fails later inside numba, scipy or numpy."""
    floats = _float_hint(hint)
    if floats and _is_number(value):
        return _float(name, value)
    if floats is None and isinstance(value, tuple):
        return tuple(_float(f"{name}[{i}]", v) if _is_number(v) else v
                     for i, v in enumerate(value))
    return value


def in_engine_types(params: Any) -> Any:
    """A frozen dataclass of parameters (``RelaySettings``, ``LFCParams``) with every
    field annotated ``float`` in the engine's types (:func:`engine_number`): the
    same object when they already are, else a copy (built, so validated, again).
    Where a dataclass enters a run, so that a ``Fraction`` or a numpy scalar its
    checks accept never reaches numba as a Python object."""
    hints = _hints(type(params))
    changes = {}
    for f in dataclasses.fields(params):
        value = getattr(params, f.name)
        if type(value) is not float and f.name in hints:
            converted = engine_number(f.name, value, hints[f.name])
            if converted is not value:
                changes[f.name] = converted
    return dataclasses.replace(params, **changes) if changes else params


@functools.lru_cache(maxsize=None)
def _hints(cls: type) -> dict:
    return get_type_hints(cls)


def _float_hint(hint: Any) -> bool | None:
    """True if ``hint`` admits a float (``float``, ``float | None``); None for a
    tuple of floats; False otherwise."""
    if hint is float:
        return True
    args = get_args(hint)
    if get_origin(hint) is tuple:
        return None if args and all(a is float or a is Ellipsis for a in args) else False
    if get_origin(hint) in (Union, UnionType):
        if float in args:
            return True
        return None if any(get_origin(a) is tuple and _float_hint(a) is None
                           for a in args) else False
    return False


def _float(name: str, value: Any) -> float:
    try:
        return float(value)
    except OverflowError:
        raise ValueError(f"{name} = {value!r:.40} is too large for a float") from None


def is_sequence(value: object) -> bool:
    """Whether ``value`` is an ordered sequence of values: a list, a tuple or a 1-D
    array (not a string, a set or a dict, whose order or meaning differs)."""
    return isinstance(value, (list, tuple)) or (isinstance(value, np.ndarray)
                                                and value.ndim == 1)


def check_number(name: str, value: object) -> None:
    """Raise :class:`ParameterTypeError` unless ``value`` is a number."""
    if not _is_number(value):
        raise ParameterTypeError(f"{name} must be a number, got {value!r} "
                                 f"({type(value).__name__})")


def check_positive(name: str, value: float) -> None:
    """Raise unless ``value`` is a finite number > 0."""
    check_number(name, value)
    if not (is_finite(value) and value > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")


def check_nonnegative(name: str, value: float) -> None:
    """Raise unless ``value`` is a finite number >= 0."""
    check_number(name, value)
    if not (is_finite(value) and value >= 0):
        raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")


def check_finite(name: str, value: float) -> None:
    """Raise unless ``value`` is a finite number."""
    check_number(name, value)
    if not is_finite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")


def check_index(name: str, value: object, n: int) -> int:
    """Raise unless ``value`` is an integer (not a bool, not 0.7) in ``[0, n)``;
    return it as an int."""
    if not _is_integer(value):
        raise ParameterTypeError(f"{name} must be an integer index in [0, {n - 1}], got "
                                 f"{value!r} ({type(value).__name__})")
    if not 0 <= value < n:
        raise ValueError(f"{name} must be an integer index in [0, {n - 1}], got {value!r}")
    return int(value)


def check_range(name: str, value: float, low: float, high: float, *,
                closed: bool = False) -> None:
    """Raise unless ``value`` is a number with ``low < value < high`` (``closed``:
    ``low <= value <= high``)."""
    check_number(name, value)
    inside = low <= value <= high if closed else low < value < high
    if not inside:
        interval = f"[{low}, {high}]" if closed else f"({low}, {high})"
        raise ValueError(f"{name} must lie in {interval}, got {value!r}")


def check_flag(name: str, value: object) -> bool:
    """Raise ``TypeError`` unless ``value`` is a bool (Python's or numpy's): a string
    such as ``"no"`` or ``"False"`` is truthy and would silently mean yes."""
    if not isinstance(value, (bool, np.bool_)):
        raise ParameterTypeError(f"{name} must be True or False, got {value!r} "
                        f"({type(value).__name__})")
    return bool(value)


def check_multiple(name: str, value: float, of_name: str, of: float) -> int:
    """Raise ``ValueError`` unless ``value`` is a positive integer multiple of
    ``of`` (both > 0); return the integer ratio."""
    check_positive(name, value)
    check_positive(of_name, of)
    ratio = as_float(value) / as_float(of)      # a float32 or a Fraction: in doubles
    if abs(ratio - round(ratio)) > 1e-9 * ratio or round(ratio) < 1:
        raise ValueError(f"{name} must be a positive integer multiple of {of_name} ({of}), "
                         f"got {value}")
    return int(round(ratio))


def check_pair(name: str, value: object, *, positive: bool = False) -> tuple[float, float]:
    """``value`` as two floats; raise unless it is a sequence of two finite
    numbers >= 0 (> 0 with ``positive``), naming ``name[i]``."""
    if not is_sequence(value) or len(value) != 2:
        raise ParameterTypeError(f"{name} must be a pair of numbers, got {value!r}")
    check = check_positive if positive else check_nonnegative
    for i, v in enumerate(value):
        check(f"{name}[{i}]", v)
    return float(value[0]), float(value[1])


SEED_LIMIT = 2 ** 32   # the relays' noise generator (numba's legacy seed) keeps 32 bits


def check_integer(name: str, value: object, low: int = 0, high: int | None = None,
                  high_text: str | None = None) -> int:
    """Raise unless ``value`` is an integer (not a bool, not 2.0) with ``low <= value``
    (and ``value < high``; ``high_text`` writes ``high`` in the message); return it."""
    if _is_integer(value) and low <= value and (high is None or value < high):
        return int(value)                       # the common case: no message to build
    want = (f"an integer >= {low}" if high is None else
            f"an integer in [{low}, {high_text or high})")
    if not _is_integer(value):
        raise ParameterTypeError(f"{name} must be {want}, got {value!r} "
                                 f"({type(value).__name__})")
    raise ValueError(f"{name} must be {want}, got {value!r}")


def check_seed(name: str, value: object) -> int:
    """Raise unless ``value`` is an integer in ``[0, 2**32)`` (a random seed: the
    relays' noise generator keeps 32 bits, so two larger seeds could give the
    same noise); return it."""
    return check_integer(name, value, 0, SEED_LIMIT, "2**32")


def check_array(name: str, value: object, *, ndim: int | None = None,
                shape: tuple[int | None, ...] | None = None):
    """``value`` as a float ndarray; raise :class:`ParameterTypeError` unless it
    holds real numbers (not strings, bools, complex or objects), and
    ``ValueError`` unless it has ``ndim`` dimensions or ``shape`` (``None``: any
    length on that axis).  Values are not checked: NaN and inf pass."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "iuf":
        raise ParameterTypeError(f"{name} must hold real numbers, got {value!r:.80} "
                                 f"(dtype {arr.dtype})")
    if shape is not None and (arr.ndim != len(shape) or any(
            s is not None and s != n for s, n in zip(shape, arr.shape))):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + \
            ("," if len(shape) == 1 else "") + ")"
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name} must be {ndim}-dimensional, got shape {arr.shape}")
    return arr.astype(float)


def check_sizes(name: str, value: object, *, nonnegative: bool = False,
                empty: bool = False) -> tuple[float, ...]:
    """``value`` as a tuple of floats; raise unless it is a sequence of finite
    numbers (>= 0 with ``nonnegative``; non-empty unless ``empty``), e.g.
    ``(0.05, 0.1)`` and not ``0.1``."""
    if not is_sequence(value) or (len(value) == 0 and not empty):
        raise ParameterTypeError(f"{name} must be a {'' if empty else 'non-empty '}sequence "
                                 f"of numbers such as (0.05, 0.1), got {value!r}")
    check = check_nonnegative if nonnegative else check_finite
    for i, v in enumerate(value):
        check(f"{name}[{i}]", v)
    return tuple(float(v) for v in value)


def check_count(name: str, value: object) -> int:
    """Raise unless ``value`` is an integer >= 1 (not a bool, not 2.0); return it."""
    return check_integer(name, value, 1)


def conforms(value: Any, hint: Any) -> bool:
    """Whether ``value`` is of the annotated type ``hint`` (a number is a real
    that is not a bool, Python's or numpy's; a tuple any 1-D sequence of the
    right length; a union any of its members)."""
    origin, args = get_origin(hint), get_args(hint)
    if origin in (Union, UnionType):
        return any(conforms(value, a) for a in args)
    if hint is float:
        return isinstance(value, Real) and not isinstance(value, (bool, np.bool_))
    if hint is int:
        return isinstance(value, Integral) and not isinstance(value, (bool, np.bool_))
    if hint is bool:
        return isinstance(value, (bool, np.bool_))
    if hint is str:
        return isinstance(value, str)
    if hint is type(None):
        return value is None
    if origin is tuple:
        return (isinstance(value, (tuple, list, np.ndarray)) and np.ndim(value) == 1
                and len(value) == len(args) and all(conforms(v, a) for v, a in zip(value, args)))
    if hint is dict or origin is dict:
        return isinstance(value, dict)
    return isinstance(value, hint) if isinstance(hint, type) else True


def kind(hint: Any) -> str:
    """``hint`` in words, for an error message."""
    origin, args = get_origin(hint), get_args(hint)
    if origin in (Union, UnionType):
        return " or ".join(sorted((kind(a) for a in args), key=lambda k: k != "None"))
    if origin is tuple:
        return "a pair of numbers" if len(args) == 2 else f"a {len(args)}-tuple"
    return {float: "a number", int: "an integer", bool: "True or False", str: "a string",
            type(None): "None", dict: "a dict"}.get(hint, getattr(hint, "__name__", str(hint)))


def check_folder(name: str, value: object):
    """``value`` as a ``Path``; raise unless it is a non-empty path (a string or
    ``os.PathLike``): ``""`` would mean the current directory."""
    import os
    from pathlib import Path
    if not isinstance(value, (str, os.PathLike)):
        raise ParameterTypeError(f"{name} must be a folder path, got {value!r:.80} "
                                 f"({type(value).__name__})")
    if not str(value).strip():
        raise ValueError(f"{name} must be a folder path, not empty (that would be the "
                         f"current directory), got {value!r}")
    return Path(value)
