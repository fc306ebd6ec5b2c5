"""The two-area Kundur system on ANDES: data, builder and the design model's start.

ANDES ships Kundur's two-area system (Kundur 1994, Example 12.6; Klein, Rogers
and Kundur 1991) as ``kundur/kundur_full.xlsx``: four 900 MVA round-rotor
machines (GENROU, H = 6.5 s in area 1, 6.175 s in area 2) with TGOV1 governors
(5 % droop, T1 = 0.49 s, turbine lead-lag T2 = 2.1 s over T3 = 7 s) and EXDC2
exciters, two machines per area, 1159 MW of load in area 1 and 1575 MW in area
2, and three 230 kV tie-lines from bus 7 to bus 8 carrying about 400 MW from
area 1 to area 2.  ANDES numbers its buses 1-10 and names them as Kundur's
figure does::

    G1 (1) -- 5 (101) -- 6 (102) -- 7 (3) ===== 8 (13) -- 9 (112) -- 10 (111) -- G4 (4)
                          |                                  |
                        G2 (2)                             G3 (3)

What :class:`KundurCase` changes, and why:

* the case's own disturbance (a Toggle that opens a 8-9 line at 2 s) is
  switched off; scenarios bring their own;
* one ``BusFreq`` and one ``BusROCOF`` per area, at its 230 kV bus between the
  machines and the tie (buses 6 and 9): the frequency and ROCOF the area's
  relays, filter and AGC read (lags as in the microgrid, :class:`MicrogridCase`);
* one zero ``PQ`` load per area at the tie-line's end (buses 7 and 8) that
  carries load-step scenarios.

The AGC is not in the case: each area's AGC is the engine's generator side
(:class:`lfc.engine.GeneratorSide`), whose command goes through the area's
filter and is shared equally by the area's two governors.

Per unit.  ANDES keeps the case's 100 MVA system base (the case's powers are
stored on it).  Everything this package reads or writes is in pu on the
**area's base**, ``area_mva`` = 1800 MVA (its two machines' rating), so one
pu of command is 1800 MW; :meth:`KundurCase.scale` converts.
"""

from __future__ import annotations

from dataclasses import dataclass

from lfc._validate import check_positive
from lfc.model import LFCParams
from lfc.multiarea import MultiAreaParams


@dataclass(frozen=True)
class KundurCase:
    """The two-area Kundur system as the testbed runs it (pu on ``area_mva``, s).

    Parameters
    ----------
    case_file : str
        The ANDES case (``andes.get_case`` path).
    area_mva : float
        Per-unit base of each area's model (MVA): its two 900 MVA machines.
    generators : tuple of tuple of int
        ANDES ``GENROU`` idx of each area's machines (area 0 is ANDES' area 1).
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

    case_file: str = "kundur/kundur_full.xlsx"
    area_mva: float = 1800.0
    system_mva: float = 100.0
    f_nominal: float = 60.0
    generators: tuple[tuple[int, ...], ...] = ((1, 2), (3, 4))
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
        if not self.tie_lines:
            raise ValueError("tie_lines must name at least one line")

    @property
    def n_areas(self) -> int:
        return len(self.generators)

    @property
    def scale(self) -> float:
        """System-base pu per area-base pu (18 for 1800 over 100 MVA)."""
        return self.area_mva / self.system_mva

    def design_params(self, **overrides: float) -> MultiAreaParams:
        """The linear two-area model the case's data imply (the fit's start):
        each area's inertia the sum of its machines', its droop and governor
        lag the TGOV1 data, the turbine lag T3, a small load damping (the loads
        are constant impedance), and a tie-line coefficient from the case's
        power flow; ``overrides`` replace per-area fields."""
        m = 2 * (2 * 6.5 * 900) / self.area_mva       # two machines of H 6.5 s, 900 MVA
        areas = tuple(LFCParams(M=mi, D=0.5, droop=0.05, tau_g=0.49, tau_t=7.0,
                                tau_w=self.tau_w, tau_rocof=self.tau_rocof, k_i=2.0,
                                f_nominal=self.f_nominal, s_base_mva=self.area_mva,
                                **overrides)
                      for mi in (m, m * 6.175 / 6.5))
        return MultiAreaParams(areas=areas, tie=((0, 1, 1.0),))


def build_kundur(case: KundurCase):
    """Load, modify (module docstring), set up and solve the power flow.

    Returns
    -------
    andes.System
        With ``BusFreq`` ``F{i}``, ``BusROCOF`` ``R{i}`` and zero ``PQ``
        ``LS{i}`` for each area ``i``.

    Raises
    ------
    ValueError
        If a bus, machine or line of ``case`` is not in the ANDES case, or a
        tie-line does not join two areas.
    RuntimeError
        If the power flow does not converge.
    """
    import andes

    from lfc.testbed.andes_setup import prepare_andes

    prepare_andes()
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
    for gens in case.generators:
        for g in gens:
            if g not in machines:
                raise ValueError(f"generators names machine {g!r}, not in {case.case_file} "
                                 f"(GENROU {sorted(machines)})")
    lines = set(ss.Line.idx.v)
    for name in case.tie_lines:
        if name not in lines:
            raise ValueError(f"tie_lines names {name!r}, not a line of {case.case_file}")
    if ss.Toggle.n:                     # the case's own line trip at 2 s: off, and
        ss.Toggle.u.v[:] = 0.0          # never due (ANDES steps onto every event time)
        ss.Toggle.t.v[:] = 1e9
    ss.PFlow.run()
    if not ss.PFlow.converged:
        raise RuntimeError(f"ANDES power flow of {case.case_file} did not converge")
    return ss


def _bus_kv(ss, bus: int) -> float:
    """Nominal voltage (kV) of ``bus`` in a system not yet set up."""
    return float(ss.Bus.Vn.v[list(ss.Bus.idx.v).index(bus)])
