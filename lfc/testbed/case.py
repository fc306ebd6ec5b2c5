"""The islanded microgrid on ANDES: data and the builder.

The paper's test system (a 27.6 kV rural distribution feeder in Ontario with a
2.5 MVA synchronous generator SG at bus B6) is not public.  :class:`MicrogridCase`
holds plausible data for it, each value's source next to it; the README's
testbed table is this docstring's table.  Every per-unit value is on the
generator's 2.5 MVA base (the ANDES system base is set to it, so ANDES' system
per unit and the linear model's per unit are the same thing).

Topology (the utility tie at B1 is open, so the island is B1..B6)::

    B1 -- B2 -- B3 -- B4 -- B6 (SG) -- B5
    |<------- feeder 1 ------->|      |<- feeder 2 (line L65, over-current relay)

A fault at B5 is cleared by opening L65; feeder 1 keeps running on SG.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from lfc._validate import check_positive, check_range
from lfc.model import LFCParams

LineData = tuple[str, int, int, float]  # name, from bus, to bus, length (km)
LoadData = tuple[int, float, float]  # bus, P (pu), Q (pu)


@dataclass(frozen=True)
class MicrogridCase:
    """Data of the ANDES microgrid (pu on ``s_base_mva``, seconds, kV, km).

    ===================  =========================  ==========================================
    group                value                      source / reason
    ===================  =========================  ==========================================
    base                 2.5 MVA, 27.6 kV, 60 Hz    paper (SG rating; Ontario MV distribution)
    SG (GENROU)          M = 2H = 4 s, D = 1        design model of notes §4
                         xd 1.8, xq 1.7, xd' 0.3,   typical round-rotor data, Kundur (1994)
                         xq' 0.55, xd''=xq'' 0.25,  Table 4.2; ra, xl typical for a
                         xl 0.15, ra 0.003,         2.5 MVA unit
                         T'd0 4 s, T'q0 0.6 s,
                         T''d0 0.03 s, T''q0 0.05 s
    governor (TGOV1N)    R 0.05, T1 = τ_G 0.1 s,    notes §4 (T2 = 0 so the lead-lag is the
                         T2 0, T3 = τ_T 0.3 s,      turbine lag τ_T); valve 0..1.1 pu
                         VMAX 1.1, VMIN 0
    exciter (SEXS)       K 40, TA/TB 0.5, TB 1 s,   a fast static exciter; tuned here so the
                         TE 0.05 s, E 0..5 pu       B6 voltage recovers in ≈ 1 s after a fault
    measurements         BusFreq Tf 0.02 s,         τ_ω of notes §4; ANDES default washout
                         Tw 0.02 s; BusROCOF        shortened; Tr = τ_ν of notes §4
                         Tr 0.05 s
    lines                r 0.19, x 0.38 Ω/km,       336 kcmil ACSR overhead line on a 27.6 kV
                         b 3 µS/km                  pole-top (Kersting, Distribution System
                                                    Modeling, ch. 4, typical)
    loads                2.0 MW, pf 0.95 in total   80 % of rating; constant impedance in
                         (0.8 pu), five buses       the dynamics (ANDES' PQ default)
    ===================  =========================  ==========================================

    Parameters
    ----------
    lines : tuple of (name, from_bus, to_bus, length_km)
    loads : tuple of (bus, p_pu, q_pu)
    protected_line : str
        The line with the over-current relay and breaker (B6–B5).
    load_bus : int
        Where load-step scenarios add their load.
    """

    kv: float = 27.6
    s_base_mva: float = 2.5
    f_nominal: float = 60.0
    M: float = 4.0
    D: float = 1.0
    ra: float = 0.003
    xl: float = 0.15
    xd: float = 1.8
    xq: float = 1.7
    xd1: float = 0.3
    xq1: float = 0.55
    xd2: float = 0.25
    Td10: float = 4.0
    Tq10: float = 0.6
    Td20: float = 0.03
    Tq20: float = 0.05
    droop: float = 0.05
    tau_g: float = 0.1
    tau_t: float = 0.3
    valve_max: float = 1.1
    avr_k: float = 40.0
    avr_tatb: float = 0.5
    avr_tb: float = 1.0
    avr_te: float = 0.05
    tau_w: float = 0.02
    tau_washout: float = 0.02
    tau_rocof: float = 0.05
    r_ohm_km: float = 0.19
    x_ohm_km: float = 0.38
    b_us_km: float = 3.0
    lines: tuple[LineData, ...] = (("L65", 6, 5, 4.0), ("L64", 6, 4, 3.0),
                                   ("L43", 4, 3, 5.0), ("L32", 3, 2, 4.0),
                                   ("L21", 2, 1, 3.0))
    loads: tuple[LoadData, ...] = ((5, 0.10, 0.033), (4, 0.25, 0.082), (3, 0.20, 0.066),
                                   (2, 0.15, 0.049), (1, 0.10, 0.033))
    protected_line: str = "L65"
    load_bus: int = 3
    generator_bus: int = field(default=6, init=False)

    def __post_init__(self) -> None:
        for name in ("kv", "s_base_mva", "f_nominal", "M", "droop", "tau_g", "tau_t",
                     "valve_max", "avr_k", "avr_tb", "avr_te", "tau_w", "tau_washout",
                     "tau_rocof", "xd", "xq", "xd1", "xq1", "xd2", "Td10", "Tq10", "Td20",
                     "Tq20", "x_ohm_km"):
            check_positive(name, getattr(self, name))
        check_range("D", self.D, 0.0, 100.0)
        if self.protected_line not in {ln[0] for ln in self.lines}:
            raise ValueError(f"protected_line must name one of the lines "
                             f"{[ln[0] for ln in self.lines]}, got {self.protected_line!r}")
        check_bus("load_bus", self.load_bus, self)

    @property
    def buses(self) -> list[int]:
        """Bus numbers (1..6)."""
        return sorted({b for ln in self.lines for b in ln[1:3]})

    @property
    def z_base_ohm(self) -> float:
        """Impedance base (Ω) on ``kv`` and ``s_base_mva``."""
        return self.kv ** 2 / self.s_base_mva

    @property
    def i_base_amp(self) -> float:
        """Current base (A rms) on ``kv`` and ``s_base_mva``."""
        return self.s_base_mva * 1e3 / (3 ** 0.5 * self.kv)

    @property
    def total_load(self) -> float:
        """Total initial active load (pu)."""
        return sum(p for _, p, _ in self.loads)

    def line_pu(self, length_km: float) -> tuple[float, float, float]:
        """Series r, x and total shunt b (pu) of a line of ``length_km``."""
        zb = self.z_base_ohm
        return (self.r_ohm_km * length_km / zb, self.x_ohm_km * length_km / zb,
                self.b_us_km * 1e-6 * length_km * zb)

    def beyond(self, line: str) -> set[int]:
        """Buses that the opening of ``line`` disconnects from the generator."""
        edges = [(a, b) for name, a, b, _ in self.lines if name != line]
        reached, frontier = {self.generator_bus}, [self.generator_bus]
        while frontier:
            bus = frontier.pop()
            for a, b in edges:
                for u, v in ((a, b), (b, a)):
                    if u == bus and v not in reached:
                        reached.add(v)
                        frontier.append(v)
        return set(self.buses) - reached

    def design_params(self, **overrides: float) -> LFCParams:
        """The linear design model that this case's data imply (before any fit)."""
        values = dict(tau_g=self.tau_g, tau_t=self.tau_t, M=self.M, D=self.D,
                      droop=self.droop, tau_w=self.tau_w, tau_rocof=self.tau_rocof,
                      f_nominal=self.f_nominal, s_base_mva=self.s_base_mva)
        values.update(overrides)
        return LFCParams(**values)


def check_bus(name: str, bus: int, case: MicrogridCase) -> None:
    """Raise ``ValueError`` unless ``bus`` is one of the case's buses."""
    if bus not in case.buses:
        raise ValueError(f"{name} must be one of the buses {case.buses}, got {bus!r}")


def build_system(case: MicrogridCase, *, fault_bus: int | None = None,
                 fault_xf: float = 1e-3, fault_t: float = 1e6, open_t: float | None = None):
    """Build, set up and solve the power flow of the ANDES system.

    Parameters
    ----------
    case : MicrogridCase
    fault_bus : int, optional
        Adds a three-phase ``Fault`` device at this bus.
    fault_xf : float
        Fault reactance (pu on the system base); ANDES fails at inception for
        xf ≤ 1e-5.
    fault_t : float
        Fault inception (s).
    open_t : float, optional
        When the protected line's breaker opens (s): the line is toggled off and
        the fault, isolated by it, is removed from the equations at that time.

    Returns
    -------
    andes.System
        Power flow solved; an extra zero load ``"LSTEP"`` at ``case.load_bus``
        carries load-step scenarios.

    Raises
    ------
    RuntimeError
        If the power flow does not converge.
    """
    import andes

    from lfc.testbed.andes_setup import prepare_andes

    prepare_andes()
    ss = andes.System(default_config=True, no_output=True, config={"mva": case.s_base_mva})
    for bus in case.buses:
        ss.add("Bus", dict(idx=bus, name=f"B{bus}", Vn=case.kv))
    for name, a, b, km in case.lines:
        r, x, bsh = case.line_pu(km)
        ss.add("Line", dict(idx=name, bus1=a, bus2=b, Sn=case.s_base_mva, Vn1=case.kv,
                            Vn2=case.kv, r=r, x=x, b=bsh))
    for bus, p, q in case.loads:
        ss.add("PQ", dict(idx=f"PQ{bus}", bus=bus, Vn=case.kv, p0=p, q0=q))
    ss.add("PQ", dict(idx="LSTEP", bus=case.load_bus, Vn=case.kv, p0=0.0, q0=0.0))
    _add_generator(ss, case)
    if fault_bus is not None:
        tc = open_t if open_t is not None else 2e6
        ss.add("Fault", dict(idx="F", bus=fault_bus, tf=fault_t, tc=tc, xf=fault_xf))
    if open_t is not None:
        ss.add("Toggle", dict(idx="BREAKER", model="Line", dev=case.protected_line, t=open_t))
    ss.setup()
    ss.PFlow.run()
    if not ss.PFlow.converged:
        raise RuntimeError("ANDES power flow of the microgrid did not converge")
    return ss


def _add_generator(ss, case: MicrogridCase) -> None:
    g = case.generator_bus
    ss.add("Slack", dict(idx="G", bus=g, Sn=case.s_base_mva, Vn=case.kv, v0=1.0,
                         p0=case.total_load))
    ss.add("GENROU", dict(idx="SG", bus=g, gen="G", Sn=case.s_base_mva, Vn=case.kv,
                          fn=case.f_nominal, M=case.M, D=case.D, ra=case.ra, xl=case.xl,
                          xd=case.xd, xq=case.xq, xd1=case.xd1, xq1=case.xq1, xd2=case.xd2,
                          xq2=case.xd2, Td10=case.Td10, Tq10=case.Tq10, Td20=case.Td20,
                          Tq20=case.Tq20))
    ss.add("TGOV1N", dict(idx="GOV", syn="SG", R=case.droop, T1=case.tau_g, T2=0.0,
                          T3=case.tau_t, VMAX=case.valve_max, VMIN=0.0, Dt=0.0))
    ss.add("SEXS", dict(idx="AVR", syn="SG", K=case.avr_k, TATB=case.avr_tatb,
                        TB=case.avr_tb, TE=case.avr_te, EMIN=0.0, EMAX=5.0))
    ss.add("BusFreq", dict(idx="BF", bus=g, Tf=case.tau_w, Tw=case.tau_washout,
                           fn=case.f_nominal))
    ss.add("BusROCOF", dict(idx="BR", bus=g, Tf=case.tau_w, Tw=case.tau_washout,
                            Tr=case.tau_rocof, fn=case.f_nominal))
