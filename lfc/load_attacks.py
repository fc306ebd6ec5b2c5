"""Dynamic load-altering attacks: a botnet's load that follows the frequency it measures.

A botnet of high-wattage devices in an area (Amini, Pasqualetti and Mohsenian-Rad,
IEEE Trans. Smart Grid 2018; Lakshminarayana et al., IEEE Trans. Smart Grid 2021)
switches its load with the frequency its devices measure: ``p(t) = -gain *
dw_meas(t)`` (pu on the area's base), clipped to ``±limit``, from ``start`` to
``stop``.  A positive gain sheds load as the frequency rises and adds it as the
frequency falls: the opposite of the load's own damping, so a large enough gain
destabilizes the area however well its commands are protected — a generator-side
filter cannot stop it; it can only know.  A static load-altering attack (steps,
ramps, chirps on a share of the load) is an ordinary load signal (``loads=``).

:class:`FollowingLoad` is the attack, given to :func:`lfc.simulate` as
``following_load=`` (an area) or ``following_loads={area: ...}`` (a grid) of a
linear plant; the devices read the area's frequency meter (``dw_meas``, the state
the generator's meter holds, lag ``tau_w``), the load is held over each plant step
from the meter's value at its start.  :func:`critical_gain` is the smallest gain at
which the closed loop of the continuous-time design model (:func:`closed_loop`:
every area, its tie-lines' reachable flows, its AGC integrator on its measured
frequency and export, or its command held) has an eigenvalue with a non-negative
real part.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lfc._validate import check_index, check_number, check_range
from lfc.multiarea import reduced_model
from lfc.model import STATES, LFCParams
from lfc.multiarea import N_AREA_STATES, MultiAreaParams, as_grid

#: the state of an area the devices read (the frequency meter)
DW_MEAS = STATES.index("dw_meas")
#: the largest gain :func:`critical_gain` searches (pu load per pu frequency)
LARGEST_GAIN = 1e4


@dataclass(frozen=True)
class FollowingLoad:
    """A load that follows the area's measured frequency (module docstring).

    Parameters
    ----------
    gain : float
        ``K`` in ``p = -K dw_meas`` (pu load per pu frequency), finite; positive
        opposes the load's damping (the attack), negative adds to it.
    limit : float
        The most load the botnet switches, either way (pu), > 0; default ∞.
    start, stop : float
        When it acts (s): from ``start`` (>= 0, default 0) until ``stop`` (> ``start``,
        default ∞).

    Raises
    ------
    ValueError
        Naming the parameter, for a value out of its range.
    """

    gain: float
    limit: float = math.inf
    start: float = 0.0
    stop: float = math.inf

    def __post_init__(self) -> None:
        check_number("gain", self.gain)
        if not math.isfinite(self.gain):
            raise ValueError(f"gain must be a finite number (pu/pu), got {self.gain!r}")
        check_number("limit", self.limit)
        if not self.limit > 0:
            raise ValueError(f"limit must be > 0 pu (math.inf: none), got {self.limit!r}")
        check_range("start", self.start, 0.0, math.inf, closed=True)
        check_number("stop", self.stop)
        if not self.stop > self.start:
            raise ValueError(f"stop must be > start={self.start!r} s, got {self.stop!r}")
        for name in ("gain", "limit", "start", "stop"):
            object.__setattr__(self, name, float(getattr(self, name)))

    def row(self) -> tuple[float, float, float, float]:
        """``(gain, limit, start, stop)``, as the engine reads it (``Rows.following``)."""
        return self.gain, self.limit, self.start, self.stop

    def load(self, t: np.ndarray, dw_meas: np.ndarray) -> np.ndarray:
        """The attack's load (pu) at times ``t`` (s) for the meter's readings
        ``dw_meas`` (pu) there: what the engine applies over the plant step from
        each ``t``."""
        t, dw_meas = np.asarray(t, float), np.asarray(dw_meas, float)
        p = np.clip(-self.gain * dw_meas, -self.limit, self.limit)
        return np.where((self.start <= t) & (t < self.stop), p, 0.0)


#: ``Rows.following`` of an area without the attack
NO_FOLLOWING = (0.0, math.inf, 0.0, 0.0)


def closed_loop(params: LFCParams | MultiAreaParams, gains: dict[int, float], *,
                agc: bool = True) -> np.ndarray:
    """The continuous-time closed loop of the design model ``params`` with a
    following load of gain ``gains[a]`` in each area ``a`` (no limit) — its ``A``.

    The states are the grid's on its tie-line flows' reachable subspace
    (:func:`lfc.multiarea.reduced_model`: every area's five, then the
    flows that can move; a ring's circulating flow, a zero eigenvalue nothing
    drives, left out) and, with ``agc``, every area's AGC integrator
    ``d dPc_a/dt = -k_freq_a dw_meas_a - k_tie_a dP_tie,a``
    (:meth:`MultiAreaParams.agc_gains`; one area: its local integral controller);
    without, every command is held (a filter that holds, or AGC off).
    """
    grid = as_grid(params)
    n_a, m = grid.n_areas, N_AREA_STATES
    A, Bu, Bl, R = reduced_model(grid)
    for a, gain in gains.items():
        a = check_index("area", a, n_a)
        check_number(f"gains[{a}]", gain)
        A[:, m * a + DW_MEAS] -= gain * Bl[:, a]             # p_a = -gain dw_meas_a
    if not agc:
        return A
    k_freq, k_tie = grid.agc_gains()
    exports = grid.incidence() @ R[m * n_a:, m * n_a:].T   # each area's export, of phi
    n = len(A)
    closed = np.zeros((n + n_a, n + n_a))
    closed[:n, :n], closed[:n, n:] = A, Bu
    for a in range(n_a):
        closed[n + a, m * a + DW_MEAS] = -k_freq[a]
        closed[n + a, m * n_a:n] = -k_tie[a] * exports[a]
    return closed


def growth_rate(params: LFCParams | MultiAreaParams, gains: dict[int, float], *,
                agc: bool = True) -> float:
    """The largest real part of :func:`closed_loop`'s eigenvalues (1/s): < 0 stable."""
    return float(np.max(np.linalg.eigvals(closed_loop(params, gains, agc=agc)).real))


def critical_gain(params: LFCParams | MultiAreaParams, area: int = 0, *, agc: bool = True,
                  tol: float = 1e-9) -> float:
    """The smallest gain ``K`` > 0 of a following load in ``area`` alone at which
    :func:`closed_loop` is not asymptotically stable (an eigenvalue's real part
    >= 0), to ``tol`` relative; ``math.inf`` if none up to ``LARGEST_GAIN``.  The
    gains are scanned geometrically (64 per decade) from 1e-3 pu/pu, then the first
    crossing is bisected.

    Raises
    ------
    ValueError
        If the loop is not stable without the attack (``K = 0``), or ``area`` is not
        one of the grid's.
    """
    check_index("area", area, as_grid(params).n_areas)
    if growth_rate(params, {area: 0.0}, agc=agc) >= 0.0:
        raise ValueError("the closed loop is not stable without the attack (gain 0): no "
                         "smallest destabilizing gain")
    scan = np.geomspace(1e-3, LARGEST_GAIN, 64 * 7 + 1)
    stable = 0.0
    for gain in scan:
        if growth_rate(params, {area: gain}, agc=agc) >= 0.0:
            low, high = stable, float(gain)
            while high - low > tol * high:
                mid = 0.5 * (low + high)
                low, high = (low, mid) if growth_rate(params, {area: mid}, agc=agc) >= 0.0 \
                    else (mid, high)
            return high
        stable = float(gain)
    return math.inf
