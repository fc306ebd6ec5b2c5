"""One compiled entry point for every filter method: :func:`decide` and :func:`decide_many`,
and :func:`decide_grid` for the methods that read the whole grid (:func:`grid_wide`).

The engine and :class:`lfc.SafetyFilter` both call these, so a filter runs the
same compiled code whether it is called once, on a batch of states or inside a
simulation; the engine imports no particular filter, only this module.

A method's code is given by :func:`assign` (``lfc.filters.register`` calls it), in the
order of registration; nothing writes a code by hand.  A compiled method's module
defines its decision: ``decide(fd, x, u_ref, p, mem)`` for one area or, for a class
with ``grid_wide = True``, ``decide_grid(fd, grid, estimate, first, u_ref, mem,
x_hat)`` (:func:`decide_grid`).  numba dispatches on codes it knows when it compiles,
so the dispatchers' bodies are written from the table of codes when numba types them
(:func:`_chain`), and the table is closed (:func:`close`) once ``lfc.filters`` has
registered its methods.  The compiled code is cached with the package's sources
(:mod:`lfc._jit`), which is why a compiled method must be a module of this package.
A filter that is not compiled (``jit = False``, ``solver="cvxpy"``) is registered
here with :func:`register_python` and called back through ``numba.objmode`` under the
code :data:`PYTHON`.
"""

from __future__ import annotations

import sys
import weakref

import numba as nb
import numpy as np
from numba.extending import overload

from lfc._jit import inline, jit

_PYTHON: weakref.WeakValueDictionary = weakref.WeakValueDictionary()  # id -> backend
#: by code: each method's compiled decision and whether it reads the whole grid
_KERNELS: list[tuple[object, bool]] = []
_open = [True]           # codes can be given (until close())


def register_python(backend) -> np.ndarray:
    """Register a backend that is not compiled; return the data its calls carry."""
    key = max(_PYTHON.keys(), default=0) + 1
    _PYTHON[key] = backend
    return np.array([float(key)])


def _call_python(key: float, x0: float, x1: float, x2: float, x3: float, x4: float,
                 u_ref: float, p: float, m0: float, m1: float) -> tuple:
    """The registered backend's ``decide_python`` on the state and memory given
    as numbers; returns its ten outputs and the memory after the call."""
    memory = np.array([m0, m1])
    out = _PYTHON[int(key)].decide_python(np.array([x0, x1, x2, x3, x4]), u_ref, p, memory)
    return (*out, memory[0], memory[1])


@nb.njit(cache=True)   # holds the GIL: it calls back into Python
def _decide_python(fd: np.ndarray, x: np.ndarray, u_ref: float, p: float,
                   mem: np.ndarray) -> tuple:
    # Numbers, not arrays, cross into object mode: handed ``x`` and ``mem``, the
    # block received a compiled caller's arrays of those names instead (the whole
    # batch of filter_batch, every area's memory in the engine).
    key, x0, x1, x2, x3, x4 = fd[0], x[0], x[1], x[2], x[3], x[4]
    m_in0, m_in1 = mem[0], mem[1]
    with nb.objmode(u="float64", flags="int64", h0="float64", h1="float64", g0="float64",
                    g1="float64", y0="float64", y1="float64", d0="float64", d1="float64",
                    m_out0="float64", m_out1="float64"):
        u, flags, h0, h1, g0, g1, y0, y1, d0, d1, m_out0, m_out1 = _call_python(
            key, x0, x1, x2, x3, x4, u_ref, p, m_in0, m_in1)
    mem[0], mem[1] = m_out0, m_out1
    return u, flags, h0, h1, g0, g1, y0, y1, d0, d1


def _add(kernel, grid: bool) -> int:
    if not _open[0]:
        raise RuntimeError("the compiled dispatchers' codes are given when lfc.filters is "
                           "imported: register a compiled method there (a method registered "
                           "later needs jit = False)")
    _KERNELS.append((kernel, grid))
    return len(_KERNELS) - 1


def close() -> None:
    """Close the table of codes (``lfc.filters`` calls it after registering its methods;
    the compiled dispatchers are written from it)."""
    _open[0] = False


#: the code of a filter that is not compiled (:func:`register_python`)
PYTHON = _add(_decide_python, False)


def assign(backend: type) -> int:
    """Give the compiled method ``backend`` (a class) its code, set as its ``method_id``
    and returned; its decision is its module's ``decide`` or, with ``grid_wide = True``,
    ``decide_grid`` (module docstring).

    Raises
    ------
    ValueError
        If the class is not of this package (its compiled dispatch could not be
        cached with it) or its module has no such decision.
    RuntimeError
        Once the table is closed (:func:`close`).
    """
    grid = bool(getattr(backend, "grid_wide", False))
    module, name = backend.__module__, "decide_grid" if grid else "decide"
    if module.split(".")[0] != "lfc":
        raise ValueError(f"a compiled method must be a module of lfc, got {backend.__name__} "
                         f"of {module}: give it jit = False and a decide_python")
    kernel = getattr(sys.modules.get(module), name, None)
    if not isinstance(kernel, nb.core.registry.CPUDispatcher):
        raise ValueError(f"{module} must define a numba-compiled {name} for "
                         f"{backend.__name__}")
    backend.method_id = _add(kernel, grid)
    return backend.method_id


def grid_wide_methods() -> tuple[int, ...]:
    """The codes of the methods whose decision reads the whole grid (the engine hands
    them every area's state, command and load: :func:`decide_grid`); the lanes, one
    area at a time, do not run them."""
    return tuple(code for code, (_, grid) in enumerate(_KERNELS) if grid)


def is_grid_wide(filt) -> bool:
    """Whether the filter ``filt`` (anything with a ``method_id``) reads the whole grid."""
    return getattr(filt, "method_id", None) in grid_wide_methods()


def _by_method(method, fd, x, u_ref, p, mem):
    """Stub that numba replaces with the table's dispatch (:func:`_chain`)."""
    raise NotImplementedError("compiled code only")


def _grid_by_method(method, fd, grid, estimate, first, u_ref, mem, x_hat):
    """Stub that numba replaces with the table's dispatch (:func:`_chain`)."""
    raise NotImplementedError("compiled code only")


def _is_grid_wide(method):
    """Stub that numba replaces with the table's test (:func:`_is_grid_wide_impl`)."""
    raise NotImplementedError("compiled code only")


def _chain(name: str, grid: bool, args: str):
    """A Python function ``impl(method, <args>)`` returning the decision of method
    ``method`` of the kind ``grid``: an ``if`` per code, the last code of the kind
    (for one area: :data:`PYTHON`, every other code) unconditional; written from the
    table of codes."""
    if _open[0]:
        raise RuntimeError(f"{name} compiled before lfc.filters registered its methods")
    codes = [code for code, (_, is_grid) in enumerate(_KERNELS) if is_grid == grid]
    if not codes:
        raise TypeError(f"{name}: no {'grid-wide ' if grid else ''}method is registered")
    last = PYTHON if not grid else codes[-1]
    namespace = {f"k{code}": _KERNELS[code][0] for code in codes}
    lines = [f"def impl(method, {args}):"]
    lines += [f"    if method == {code}:\n        return k{code}({args})"
              for code in codes if code != last]
    lines.append(f"    return k{last}({args})")
    exec("\n".join(lines), namespace)   # the table's own functions, nothing else
    return namespace["impl"]


@overload(_by_method, inline="always")
def _by_method_impl(method, fd, x, u_ref, p, mem):
    return _chain("decide", False, "fd, x, u_ref, p, mem")


@overload(_grid_by_method, inline="always")
def _grid_by_method_impl(method, fd, grid, estimate, first, u_ref, mem, x_hat):
    return _chain("decide_grid", True, "fd, grid, estimate, first, u_ref, mem, x_hat")


@overload(_is_grid_wide, inline="always")
def _is_grid_wide_impl(method):
    if _open[0]:
        raise RuntimeError("grid_wide compiled before lfc.filters registered its methods")
    codes = grid_wide_methods()
    namespace = {}
    exec("def impl(method):\n    return " + (" or ".join(f"method == {c}" for c in codes)
                                              or "False"), namespace)
    return namespace["impl"]


@jit
def decide(method: int, fd: np.ndarray, x: np.ndarray, u_ref: float, p: float,
           mem: np.ndarray) -> tuple:
    """One call of filter ``method`` with data ``fd`` at state ``x`` (5,), incoming
    command ``u_ref`` and assumed load ``p`` (pu); ``mem`` is the scenario's
    memory.  Returns ``(u, flags, h_freq, h_rocof, margin_freq, margin_rocof,
    y_freq, y_rocof, detail0, detail1)``.

    Compiled as a function of its own, not inlined: the engine's two loops call
    it once per control period, and link its machine code instead of compiling
    every filter into each of them (``lfc._jit``)."""
    return _by_method(method, fd, x, u_ref, p, mem)


@jit
def decide_many(method: int, fd: np.ndarray, x: np.ndarray, u_ref: np.ndarray, p: np.ndarray,
                mem: np.ndarray, flags: np.ndarray, values: np.ndarray) -> np.ndarray:
    """:func:`decide` for N states ``x`` (N, 5), commands and loads (N,) and
    memories (N, MEMORY); writes ``flags`` (N,) and ``values`` (N, 8: h, margin,
    y, details as pairs) and returns the commands (N,)."""
    n = x.shape[0]
    u = np.empty(n)
    for i in range(n):
        out = decide(method, fd, x[i], u_ref[i], p[i], mem[i])
        u[i], flags[i] = out[0], out[1]
        values[i, 0], values[i, 1], values[i, 2], values[i, 3] = out[2], out[3], out[4], out[5]
        values[i, 4], values[i, 5], values[i, 6], values[i, 7] = out[6], out[7], out[8], out[9]
    return u


@inline
def grid_wide(method: int) -> bool:
    """Whether ``method`` reads the whole grid (:func:`grid_wide_methods`)."""
    return _is_grid_wide(method)


@inline
def decide_grid(method: int, fd: np.ndarray, grid: tuple, estimate: tuple, first: bool,
                u_ref: float, mem: np.ndarray, x_hat: np.ndarray) -> tuple:
    """One call of the grid-wide filter ``method`` (:func:`grid_wide`) with data ``fd``
    at one area of the grid ``grid`` (:class:`lfc.engine.GridView`) and incoming command
    ``u_ref`` (pu); ``mem`` is the area's memory, ``estimate`` the grid's Kalman filter
    (:class:`lfc.engine.Estimate`; its index >= 0: on the estimate, which the method
    steps, predicting from the last sample unless ``first``).  The state the filter
    sees is written to ``x_hat`` (5,).  Returns :func:`decide`'s ten values and the
    load the filter assumed for this area (pu)."""
    return _grid_by_method(method, fd, grid, estimate, first, u_ref, mem, x_hat)


def scratch_size(filt) -> int:
    """The scratch entries ``filt``'s compiled decision needs inside a simulation
    (:class:`lfc.engine.Work`'s ``sums``): its ``scratch_size()`` for a grid-wide
    method, else 0."""
    return filt.scratch_size() if is_grid_wide(filt) else 0
