"""Restoration after an attack, measured against the grid's own AGC.

After an attack ends, AGC has to unwind what the attack left in its integrators
(at the control centre: the generator-side filters never see it) and bring every
area's frequency and tie-line export back to schedule.  How long that takes is a
property of the grid's AGC, not of the filters: on two lightly damped areas no AGC
gain restores a legitimate 0.1 pu step within 40 s.  So the goal after an attack is
relative (:func:`restoration`):

* the **load left in the integrators** at the attack's end, per area:
  ``pc_ref - p_load`` (pu; with AGC at rest each area's command equals its own load);
* **AGC alone**: the seconds the same grid, no attack and no filter, anti-windup on,
  takes to restore a legitimate step of that load in every area at once
  (:func:`agc_alone`);
* the run is **restored at AGC's pace** when it is back at schedule within AGC alone's
  time plus ``margin`` (``RESTORATION_MARGIN``, 10 s: room for what is not in the
  integrators at the attack's end, the frequency and tie-line deviations and the
  governors' states).

"Back at schedule" (:func:`restored_after`): every area's measured frequency
deviation below ``RESTORED_DW`` and its tie-line export below ``RESTORED_TIE`` from
then to the run's end.  The grids' attacks are :func:`grid_battery`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lfc._validate import check_finite, check_nonnegative, check_positive
from lfc.multiarea import MultiAreaParams
from lfc.relays import RelaySettings
from lfc.result import Result
from lfc.run import simulate
from lfc.signals import Sinusoid, Square, Step

RESTORED_DW = 5e-4      # pu: |Δω_meas| below this in every area (0.03 Hz at 60 Hz)
RESTORED_TIE = 5e-3     # pu: |tie-line export| below this in every area
RESTORATION_MARGIN = 10.0   # s: added to AGC alone's time (module docstring)
AGC_ALONE_START = 1.0   # s: when AGC alone's legitimate steps land


def grid_battery(n_areas: int, *, start: float = 1.0, stop: float = math.inf) -> dict:
    """The grids' attack battery on ``n_areas`` areas, each on ``[start, stop)`` s:
    name -> the ``attacks`` keyword of :func:`lfc.simulate` for a grid.

    A 1 pu 0.5 Hz sinusoid on area 0's command; a 0.5 pu 0.3 Hz square on area 0's
    frequency reference; a -2.5 pu bias on every area's ACE; the sinusoid on every
    area's command, in phase and in opposite phases."""
    every = range(n_areas)
    return {
        "sinusoid on area 0's P_c": {0: {"pc": Sinusoid(1.0, 0.5, start=start, stop=stop)}},
        "square on area 0's ω_ref": {0: {"wref": Square(0.5, 0.3, start=start, stop=stop)}},
        "bias on every ACE": {a: {"ace": Step(-2.5, start=start, stop=stop)} for a in every},
        "coordinated sinusoid": {a: {"pc": Sinusoid(1.0, 0.5, start=start, stop=stop)}
                                 for a in every},
        "opposite sinusoids": {a: {"pc": Sinusoid((-1.0) ** a, 0.5, start=start, stop=stop)}
                               for a in every}}


def restored_after(result: Result, end: float, *, dw_tol: float = RESTORED_DW,
                   tie_tol: float = RESTORED_TIE) -> float:
    """Seconds after ``end`` (s) from which every area of ``result`` stays at schedule
    to the run's end: ``|dw_meas| < dw_tol`` (pu) and ``|p_tie| < tie_tol`` (pu).
    0 if it already is at ``end``; ``inf`` if it is not at the run's last sample."""
    check_positive("dw_tol", dw_tol)
    check_positive("tie_tol", tie_tol)
    t = result.trace.t.to_numpy()
    bad = np.zeros(len(t), dtype=bool)
    for area in result.areas:            # an area alone has no tie-line
        bad |= area.trace.dw_meas.abs().to_numpy() >= dw_tol
        if "p_tie" in area.trace:
            bad |= area.trace.p_tie.abs().to_numpy() >= tie_tol
    if bad[-1]:
        return math.inf
    return max(float(t[bad].max()) - end, 0.0) if bad.any() else 0.0


def agc_residue(result: Result, end: float) -> np.ndarray:
    """The load left in each area's AGC integrator at ``end`` (s): the AGC's command
    minus the area's load there, ``pc_ref - p_load`` (pu), shape (n_areas,)."""
    check_finite("end", end)
    i = min(int(np.searchsorted(result.trace.t, end)), len(result.trace) - 1)
    return np.array([float(a.trace.pc_ref.iat[i] - a.trace.p_load.iat[i])
                     for a in result.areas])


def agc_alone(grid: MultiAreaParams, residue, *, relays: RelaySettings | None = None,
              control_period: float = 0.01, duration: float = 200.0) -> float:
    """Seconds the grid's AGC alone (no attack, no filter, anti-windup on) takes to
    restore (:func:`restored_after`) a legitimate load step of ``-residue[a]`` pu in
    every area ``a`` at once, landing at ``AGC_ALONE_START``; ``inf`` if not within
    ``duration`` s."""
    residue = np.asarray(residue, dtype=float)
    if residue.shape != (grid.n_areas,) or not np.isfinite(residue).all():
        raise ValueError(f"residue must hold one finite load (pu) per area "
                         f"({grid.n_areas}), got {residue!r}")
    check_positive("duration", duration)
    loads = {a: Step(-float(r), start=AGC_ALONE_START) for a, r in enumerate(residue) if r}
    r = simulate(grid, duration=duration, loads=loads, relays=relays,
                 control_period=control_period, anti_windup=True)
    return restored_after(r, AGC_ALONE_START)


@dataclass(frozen=True)
class Restoration:
    """How a run was restored after its attack, against the grid's own AGC.

    Attributes
    ----------
    restored : float
        Seconds after the attack's end until back at schedule (:func:`restored_after`).
    agc_alone : float
        Seconds AGC alone takes to restore a step of ``residue`` (:func:`agc_alone`).
    residue : tuple of float
        The load left in each area's AGC integrator at the attack's end (pu).
    margin : float
        Seconds allowed beyond ``agc_alone`` (s).
    """

    restored: float
    agc_alone: float
    residue: tuple[float, ...]
    margin: float

    @property
    def goal(self) -> float:
        """AGC alone's time plus the margin (s)."""
        return self.agc_alone + self.margin

    @property
    def at_agc_pace(self) -> bool:
        """Whether the run was back at schedule within :attr:`goal`."""
        return self.restored <= self.goal


def restoration(grid: MultiAreaParams, result: Result, end: float, *,
                margin: float = RESTORATION_MARGIN, relays: RelaySettings | None = None,
                control_period: float = 0.01) -> Restoration:
    """``result`` (a run of ``grid`` whose attack ended at ``end`` s) against the
    grid's own AGC (module docstring); ``relays`` and ``control_period`` (s) those
    of the run."""
    check_nonnegative("margin", margin)
    residue = agc_residue(result, end)
    return Restoration(restored_after(result, end),
                       agc_alone(grid, residue, relays=relays, control_period=control_period),
                       tuple(float(r) for r in residue), float(margin))
