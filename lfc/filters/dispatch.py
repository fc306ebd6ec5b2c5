"""One compiled entry point for every filter method: :func:`decide` and :func:`decide_many`,
and :func:`decide_grid` for the methods that read the whole grid (``GRID_WIDE``).

The engine and :class:`lfc.SafetyFilter` both call these, so a filter runs the
same compiled code whether it is called once, on a batch of states or inside a
simulation; the engine imports no particular filter, only this module.
A method is a code (``lfc.filters.base.METHOD_IDS``); a filter that is not
compiled (``solver="cvxpy"``) is registered here and called back through
``numba.objmode``.
"""

from __future__ import annotations

import weakref

import numba as nb
import numpy as np

from lfc._jit import inline, jit
from lfc.filters.base import METHOD_IDS
from lfc.filters.certified import CertifiedFilter
from lfc.filters.certified import decide as decide_certified
from lfc.filters.contract import ContractFilter
from lfc.filters.contract import decide as decide_contract
from lfc.filters.coupled import CoupledFilter
from lfc.filters.coupled_kernel import N_R as N_R_COUPLED
from lfc.filters.coupled_kernel import decide as decide_coupled
from lfc.filters.coupled_kernel import grid_estimate, rows_scratch
from lfc.filters.paper import PaperFilter
from lfc.filters.paper import decide as decide_paper
from lfc.multiarea import N_AREA_STATES

PAPER, CERTIFIED, CONTRACT, PYTHON = (PaperFilter.method_id, CertifiedFilter.method_id,
                                     ContractFilter.method_id, METHOD_IDS["python"])
_PYTHON: weakref.WeakValueDictionary = weakref.WeakValueDictionary()  # id -> backend


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
    if method == PAPER:
        return decide_paper(fd, x, u_ref, p, mem)
    if method == CERTIFIED:
        return decide_certified(fd, x, u_ref, p, mem)
    if method == CONTRACT:
        return decide_contract(fd, x, u_ref, p, mem)
    return _decide_python(fd, x, u_ref, p, mem)


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


#: the methods whose decision reads the whole grid (the engine hands them every area's
#: state, command and load: :func:`decide_grid`); the lanes, one area at a time, do not
#: run them
COUPLED = CoupledFilter.method_id
GRID_WIDE = (COUPLED,)


@inline
def grid_wide(method: int) -> bool:
    """Whether ``method`` is one of ``GRID_WIDE`` (:func:`decide_grid` runs it)."""
    return method == COUPLED


@inline
def decide_grid(method: int, fd: np.ndarray, grid: tuple, estimate: tuple, first: bool,
                u_ref: float, mem: np.ndarray, x_hat: np.ndarray) -> tuple:
    """One call of the grid-wide filter ``method`` (``GRID_WIDE``: the coupled
    certificate, :mod:`lfc.filters.coupled`) with data ``fd`` at one area of the grid
    ``grid`` (:class:`lfc.engine.GridView`) and incoming command ``u_ref`` (pu); ``mem``
    is the area's memory.  On the filter's grid Kalman estimate (``estimate``'s index
    >= 0, its matrices :class:`lfc.engine.Estimate`'s) area 0's call steps the estimator
    (predicting from the last sample unless ``first``) and every area reads it; the
    state the filter sees is written to ``x_hat`` (5,).  Returns :func:`decide`'s ten
    values and the load the filter assumed for this area (pu)."""
    area, grid_x, grid_u, grid_p, ym, xe, ks, sums = grid
    est, ka, kb, kc, kg, _ = estimate
    if est >= 0:       # the grid's Kalman filter (state ks, area 0's), stepped by area 0
        if area == 0:
            grid_p = grid_estimate(fd, ka, kb, kc, kg, ks, ym[:kc.shape[0]],
                                   ym[kc.shape[0]:], grid_u, not first, xe)
        else:
            grid_p = ks[1, int(fd[N_R_COUPLED]):int(fd[N_R_COUPLED]) + len(grid_u)]
        grid_x = xe
        for r in range(5):
            x_hat[r] = xe[N_AREA_STATES * area + r]
    u, flags, h0, h1, m0, m1, q0, q1, d0, d1 = decide_coupled(fd, grid_x, grid_u, grid_p,
                                                              area, u_ref, mem, sums)
    return u, flags, h0, h1, m0, m1, q0, q1, d0, d1, grid_p[area]


def scratch_size(filt) -> int:
    """The scratch entries ``filt``'s compiled decision needs inside a simulation
    (:class:`lfc.engine.Work`'s ``sums``): 0 but for a grid-wide method."""
    return rows_scratch(filt.data) if filt.method_id in GRID_WIDE else 0
