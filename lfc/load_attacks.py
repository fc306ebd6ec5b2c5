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
real part.  :func:`secure_load` is the least load to secure in each area so that a
botnet of the rest cannot destabilize it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scipy.optimize import linprog

from lfc._validate import check_count, check_index, check_number, check_positive, check_range
from lfc.model import STATES, LFCParams
from lfc.multiarea import N_AREA_STATES, MultiAreaParams, as_grid, reduced_model

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


@dataclass(frozen=True)
class SecuredLoad:
    """What :func:`secure_load` found.

    Attributes
    ----------
    secured : ndarray
        The load to secure in each area (pu).
    gains : ndarray
        The gain the botnet keeps in each area (pu/pu).
    growth : float
        The exact closed loop's largest real part at those gains (1/s).
    rounds : int
        The linear programs solved.
    converged : bool
        Whether the last two agreed and the exact loop meets the margin.
    first : ndarray
        The one-shot linear program's answer (linearized at the full attack, as in
        Lakshminarayana et al.), pu per area; ``first_growth`` its exact growth (1/s).
    first_growth : float
    """

    secured: np.ndarray
    gains: np.ndarray
    growth: float
    rounds: int
    converged: bool
    first: np.ndarray
    first_growth: float


def _sensitivities(params, gains: np.ndarray, agc: bool) -> tuple[np.ndarray, np.ndarray]:
    """The real parts of :func:`closed_loop`'s eigenvalues at ``gains`` and their
    first-order sensitivities to each area's gain, ``(n_modes,)`` and ``(n_modes,
    n_areas)`` (1/s, 1/s per pu/pu): ``w_i E_a v_i`` with ``v_i``, ``w_i`` the right
    and left eigenvectors (``W V = I``) and ``E_a`` the loop's change per unit gain."""
    n_a = len(gains)
    A = closed_loop(params, dict(enumerate(gains)), agc=agc)
    zero = closed_loop(params, {}, agc=agc)
    change = [closed_loop(params, {a: 1.0}, agc=agc) - zero for a in range(n_a)]
    lam, V = np.linalg.eig(A)
    W = np.linalg.inv(V)
    return lam.real, np.array([[(W[i] @ E @ V[:, i]).real for E in change]
                               for i in range(len(lam))])


def secure_load(params: LFCParams | MultiAreaParams, vulnerable, gain_per_pu: float, *,
                margin: float = 0.0, agc: bool = True, rounds: int = 50) -> SecuredLoad:
    """The least load to secure in each area so that a botnet of the rest of its
    vulnerable load cannot destabilize the design model's closed loop.

    A botnet that compromises ``vulnerable[a] - s_a`` pu of area ``a``'s load makes it
    follow the frequency with the gain ``K_a = gain_per_pu (vulnerable[a] - s_a)``
    (pu/pu: each pu of devices switched fully for a frequency deviation of
    ``1 / gain_per_pu`` pu).  The linear program over the eigenvalues' first-order
    sensitivities (Lakshminarayana et al., IEEE Trans. Smart Grid 2021):
    ``min sum s_a`` subject to ``Re l_i(K0) + sum_a dRe l_i/dK_a (K_a - K0_a) <= -margin``
    for every eigenvalue ``l_i`` of :func:`closed_loop` and ``0 <= s_a <=
    vulnerable[a]``, first linearized at the full attack (``K0``: nothing secured: the
    one-shot program, kept as ``first``), then again at each answer until two agree
    and the exact eigenvalues there meet the margin (a sequential linear program).  The
    stable set of the gains is not convex (docs/guarantees.md), so the answer is a local
    one, and the one-shot program's may be unstable: its exact growth is reported.

    Parameters
    ----------
    params : LFCParams or MultiAreaParams
        The design model.
    vulnerable : sequence of float
        The load the botnet can compromise in each area (pu), each >= 0.
    gain_per_pu : float
        The gain a pu of compromised load gives the botnet (pu/pu per pu), > 0.
    margin : float
        The decay rate the loop keeps (1/s), >= 0 and below its own without the attack.
    agc : bool
        The AGC on (default) or every command held (:func:`closed_loop`).
    rounds : int
        At most this many linear programs, >= 1.

    Raises
    ------
    ValueError
        Naming the parameter: out of its range, ``vulnerable`` not one value per area,
        or a loop not stable by ``margin`` without the attack.
    """
    n_a = as_grid(params).n_areas
    v = np.asarray(vulnerable, float)
    if v.shape != (n_a,) or not np.all(np.isfinite(v)) or np.any(v < 0):
        raise ValueError(f"vulnerable must be {n_a} finite loads >= 0 pu (one per area), got "
                         f"{vulnerable!r:.80}")
    check_positive("gain_per_pu", gain_per_pu)
    check_range("margin", margin, 0.0, math.inf, closed=True)
    check_count("rounds", rounds)
    if growth_rate(params, {}, agc=agc) > -margin:
        raise ValueError(f"margin={margin!r} 1/s: the closed loop does not decay that fast "
                         f"without the attack (its largest real part is "
                         f"{growth_rate(params, {}, agc=agc):.4g} 1/s)")

    def exact(s: np.ndarray) -> float:
        return growth_rate(params, dict(enumerate(gain_per_pu * (v - s))), agc=agc)

    s, first = np.zeros(n_a), None
    for done in range(1, rounds + 1):
        gains = gain_per_pu * (v - s)
        re, sens = _sensitivities(params, gains, agc)
        # re + sens (g (v - s') - gains) <= -margin, as A_ub s' <= b_ub
        lp = linprog(np.ones(n_a), A_ub=-gain_per_pu * sens,
                     b_ub=-margin - re - sens @ (gain_per_pu * v - gains),
                     bounds=list(zip(np.zeros(n_a), v)), method="highs")
        new = lp.x if lp.status == 0 else v.copy()        # infeasible: secure it all
        first = new.copy() if first is None else first
        settled = np.max(np.abs(new - s), initial=0.0) <= 1e-9
        s = new
        if settled and exact(s) <= -margin + 1e-9:
            break
    growth = exact(s)
    return SecuredLoad(s, gain_per_pu * (v - s), growth, done,
                       bool(settled and growth <= -margin + 1e-9), first, exact(first))
