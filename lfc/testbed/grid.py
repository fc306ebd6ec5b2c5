"""Interconnected grids on ANDES: the case description, its builder and the
design model its data imply.

Two cases that ANDES ships are described (:meth:`GridCase.kundur`,
:meth:`GridCase.ieee39`); any case whose machines are ``GENROU`` with
``TGOV1`` or ``TGOV1N`` governors can be described the same way.

**Kundur's two-area system** (Kundur 1994, Example 12.6; Klein, Rogers and
Kundur 1991), ``kundur/kundur_full.xlsx``: four 900 MVA round-rotor machines
(H = 6.5 s in area 1, 6.175 s in area 2) with TGOV1 governors (5 % droop,
T1 = 0.49 s, turbine lead-lag T2 = 2.1 s over T3 = 7 s) and EXDC2 exciters,
two machines per area, 1159 MW of load in area 1 and 1575 MW in area 2, and
three 230 kV tie-lines from bus 7 to bus 8 carrying about 400 MW from area 1
to area 2.  ANDES numbers its buses 1-10 and names them as Kundur's figure
does::

    G1 (1) -- 5 (101) -- 6 (102) -- 7 (3) ===== 8 (13) -- 9 (112) -- 10 (111) -- G4 (4)
                          |                                  |
                        G2 (2)                             G3 (3)

**The IEEE 39-bus system** (New England; Athay, Podmore and Virmani 1979),
``ieee39/ieee39_full.xlsx``: ten GENROU machines with TGOV1N governors
(5 % droop, T1 = 0.05 s, turbine lead-lag T2 = 1 s over T3 = 2.1 s), IEEEX1
exciters and IEEEST stabilizers.  The case defines **two areas** (ANDES'
``Area`` 1 "WEST", 2 "EAST"), not three: machines 1, 2, 3, 8 and 10 (10, at
bus 39, is the equivalent of the external New York system: 1199 MVA, H = 50
s) against 4, 5, 6, 7 and 9, joined by five lines (4-14, 13-14, 16-17, 26-28,
26-29).  This package keeps the case's two areas (the issue asked for three;
the case has two).

What :func:`build_grid` changes in a case, and why:

* the case's own disturbances (``Toggle`` events: Kundur's line trip at 2 s;
  the 39-bus case's, already off) are switched off; scenarios bring their own;
* one ``BusFreq`` and one ``BusROCOF`` per area at its ``meter_buses`` bus:
  the frequency and ROCOF the area's relays, filter and AGC read (lags as in
  the microgrid, :class:`MicrogridCase`);
* one zero ``PQ`` load per area at its ``load_buses`` bus that carries
  load-step scenarios.

The AGC is not in the cases: each area's AGC is the engine's generator side
(:class:`lfc.engine.GeneratorSide`), whose command goes through the area's
filter and is shared by the area's governors in proportion to their ratings
(:mod:`lfc.testbed.grid_plant`).

Per unit.  ANDES keeps the cases' 100 MVA system base (their powers are
stored on it).  Everything this package reads or writes is in pu on the
**area base** ``area_mva``, one for every area (so that tie-line
coefficients are symmetric): 1800 MVA for Kundur (each area's two
machines), 5000 MVA for the 39-bus system (its areas' machines are rated
4889 and 6050 MVA); :attr:`GridCase.scale` converts.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lfc._validate import check_positive
from lfc.model import LFCParams
from lfc.multiarea import MultiAreaParams

GOVERNORS = ("TGOV1", "TGOV1N")


@dataclass(frozen=True)
class GridCase:
    """An interconnected grid as the testbed runs it (pu on ``area_mva``, s);
    the defaults are Kundur's two-area system (:meth:`kundur`).

    Parameters
    ----------
    name : str
        Short name, used in file names (``kundur_fit.md``).
    case_file : str
        The ANDES case (``andes.get_case`` path).
    area_mva : float
        Per-unit base of every area's model (MVA).
    system_mva : float
        The case's system base (MVA): ANDES stores its powers on it.
    f_nominal : float
        Nominal frequency (Hz).
    generators : tuple of tuple
        ANDES ``GENROU`` idx of each area's machines (area 0 first).
    governor : str
        The machines' governor model, ``"TGOV1"`` (the command enters before
        the droop gain) or ``"TGOV1N"`` (after it).
    meter_buses : tuple of int
        The bus whose frequency and ROCOF each area reads.
    load_buses : tuple of int
        Where ``loads[i]`` adds its constant-impedance load.
    tie_lines : tuple of str
        The lines between the areas (their power at each area's end is the
        area's tie-line export).
    tau_w, tau_washout, tau_rocof : float
        ``BusFreq`` lag and washout, ``BusROCOF`` lag (s).
    """

    name: str = "kundur"
    case_file: str = "kundur/kundur_full.xlsx"
    area_mva: float = 1800.0
    system_mva: float = 100.0
    f_nominal: float = 60.0
    generators: tuple[tuple[int | str, ...], ...] = ((1, 2), (3, 4))
    governor: str = "TGOV1"
    meter_buses: tuple[int, ...] = (6, 9)
    load_buses: tuple[int, ...] = (7, 8)
    tie_lines: tuple[str, ...] = ("Line_4", "Line_5", "Line_6")
    tau_w: float = 0.02
    tau_washout: float = 0.02
    tau_rocof: float = 0.05

    def __post_init__(self) -> None:
        for name in ("area_mva", "system_mva", "f_nominal", "tau_w", "tau_washout",
                     "tau_rocof"):
            check_positive(name, getattr(self, name))
        n = len(self.generators)
        if n < 2 or len(self.meter_buses) != n or len(self.load_buses) != n:
            raise ValueError("generators, meter_buses and load_buses must name the same "
                             f"number (>= 2) of areas, got {len(self.generators)}, "
                             f"{len(self.meter_buses)}, {len(self.load_buses)}")
        if not all(self.generators):
            raise ValueError(f"generators must name at least one machine per area, got "
                             f"{self.generators!r}")
        seen: dict = {}
        for a, machines in enumerate(self.generators):
            for m in machines:
                if m in seen:
                    raise ValueError(f"generators names machine {m!r} in area {seen[m]} and "
                                     f"area {a}: each machine belongs to one area")
                seen[m] = a
        if self.governor not in GOVERNORS:
            raise ValueError(f"governor must be one of {GOVERNORS}, got {self.governor!r}")
        if not self.tie_lines:
            raise ValueError("tie_lines must name at least one line")

    @classmethod
    def kundur(cls) -> GridCase:
        """Kundur's two-area system (module docstring): meters at buses 6 and 9,
        between each area's machines and the tie; load steps at the tie's ends,
        buses 7 and 8."""
        return cls()

    @classmethod
    def ieee39(cls) -> GridCase:
        """The IEEE 39-bus system in the case's two areas (module docstring):
        area 0 is the case's WEST (machines 1, 2, 3, 8 and the external
        system's 10; M 28.9 s on 5000 MVA), area 1 its EAST (machines 4, 5, 6,
        7, 9; M 7.4 s), the lighter one.  Meters at bus 2 (west, between
        machine 1 and the external system's bus 39) and bus 19 (east, between
        machines 4 and 5 and the tie's bus 16); load steps at buses 4 and 16,
        the ends of tie-lines 4-14 and 16-17."""
        return cls(name="ieee39", case_file="ieee39/ieee39_full.xlsx", area_mva=5000.0,
                   generators=(("GENROU_1", "GENROU_2", "GENROU_3", "GENROU_8", "GENROU_10"),
                               ("GENROU_4", "GENROU_5", "GENROU_6", "GENROU_7", "GENROU_9")),
                   governor="TGOV1N", meter_buses=(2, 19), load_buses=(4, 16),
                   tie_lines=("Line_8", "Line_18", "Line_21", "Line_32", "Line_33"))

    @property
    def n_areas(self) -> int:
        return len(self.generators)

    @property
    def scale(self) -> float:
        """System-base pu per area-base pu (18 for 1800 over 100 MVA)."""
        return self.area_mva / self.system_mva


def case_design(case: GridCase) -> MultiAreaParams:
    """The linear model the case's data imply (the fit's start), on the area
    base: each area's inertia the sum of its machines', its droop their
    parallel droops, its governor lag and turbine lag the governors' mean
    ``T1`` and ``T3``, a small load damping (the loads are constant
    impedance), the meters' lags, and a unit tie-line coefficient (the fit
    finds it).

    Raises
    ------
    ValueError
        As :func:`build_grid`.
    """
    ss = build_grid(case)
    gen, gov = ss.GENROU, getattr(ss, case.governor)
    areas = []
    for machines in case.generators:
        g = [gen.idx2uid(m) for m in machines]
        v = [list(gov.syn.v).index(m) for m in machines]
        areas.append(LFCParams(M=float(gen.M.v[g].sum()) / case.scale,
                               D=0.5, droop=case.scale / float((1 / gov.R.v[v]).sum()),
                               tau_g=float(np.mean(gov.T1.v[v])),
                               tau_t=float(np.mean(gov.T3.v[v])), tau_w=case.tau_w,
                               tau_rocof=case.tau_rocof, k_i=2.0, f_nominal=case.f_nominal,
                               s_base_mva=case.area_mva))
    return MultiAreaParams(areas=tuple(areas), tie=((0, 1, 1.0),))


def build_grid(case: GridCase):
    """Load, modify (module docstring), set up and solve the power flow.

    Returns
    -------
    andes.System
        With ``BusFreq`` ``F{i}``, ``BusROCOF`` ``R{i}`` and zero ``PQ``
        ``LS{i}`` for each area ``i``.

    Raises
    ------
    ValueError
        If a bus, machine, governor or line of ``case`` is not in the ANDES
        case, or a machine has no governor of the case's model.
    RuntimeError
        If the power flow does not converge.
    """
    from lfc.testbed.andes_setup import prepare_andes, quiet_load

    prepare_andes()
    with quiet_load(Path(case.case_file).stem, "loading"):
        return _build(case)


def _build(case: GridCase):
    """:func:`build_grid`'s work, its ANDES warnings collected."""
    import andes

    ss = andes.load(andes.get_case(case.case_file), setup=False, no_output=True,
                    default_config=True)
    buses = set(ss.Bus.idx.v)
    for name, group in (("meter_buses", case.meter_buses), ("load_buses", case.load_buses)):
        for bus in group:
            if bus not in buses:
                raise ValueError(f"{name} names bus {bus!r}, not in {case.case_file} "
                                 f"(buses {sorted(buses)})")
    for i, (meter, load) in enumerate(zip(case.meter_buses, case.load_buses)):
        ss.add("BusFreq", dict(idx=f"F{i}", bus=meter, Tf=case.tau_w, Tw=case.tau_washout,
                               fn=case.f_nominal))
        ss.add("BusROCOF", dict(idx=f"R{i}", bus=meter, Tf=case.tau_w, Tw=case.tau_washout,
                                Tr=case.tau_rocof, fn=case.f_nominal))
        ss.add("PQ", dict(idx=f"LS{i}", bus=load, Vn=float(_bus_kv(ss, load)), p0=0.0, q0=0.0))
    ss.setup()
    machines = set(ss.GENROU.idx.v)
    governed = set(getattr(ss, case.governor).syn.v)
    for gens in case.generators:
        for g in gens:
            if g not in machines:
                raise ValueError(f"generators names machine {g!r}, not in {case.case_file} "
                                 f"(GENROU {sorted(machines, key=str)})")
            if g not in governed:
                raise ValueError(f"generators names machine {g!r}, which has no "
                                 f"{case.governor} governor in {case.case_file} (governor)")
    lines = set(ss.Line.idx.v)
    for name in case.tie_lines:
        if name not in lines:
            raise ValueError(f"tie_lines names {name!r}, not a line of {case.case_file}")
    if ss.Toggle.n:                     # the case's own events: off, and never due
        ss.Toggle.u.v[:] = 0.0          # (ANDES steps onto every event time)
        ss.Toggle.t.v[:] = 1e9
    ss.PFlow.run()
    if not ss.PFlow.converged:
        raise RuntimeError(f"ANDES power flow of {case.case_file} did not converge")
    return ss


def _bus_kv(ss, bus: int) -> float:
    """Nominal voltage (kV) of ``bus`` in a system not yet set up."""
    return float(ss.Bus.Vn.v[list(ss.Bus.idx.v).index(bus)])
