"""The islanded microgrid on ANDES: its data, its builder, the over-current
relay of its protected line, and the SCC in its loop (:func:`simulate_microgrid`).

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

**The over-current relay** on line B6–B5 (:class:`OvercurrentRelay`) reads the line
current (:func:`phase_a_current`).

**The SCC in the loop** (:func:`simulate_microgrid`). The microgrid is an
:class:`~lfc.testbed.loop.AndesPlant` (:class:`MicrogridPlant`) run by the one ANDES
adapter, :class:`lfc.testbed.loop.AndesLoop`. Its one area's state in the design model's
coordinates:

=============  ======================================================
``dPg``        governor valve ``TGOV1N.LAG_y`` minus its initial value
``dPm``        turbine output ``TGOV1N.pout`` minus its initial value
``dw``         rotor speed ``GENROU.omega − 1``
``dw_meas``    bus-B6 frequency ``BusFreq.f − 1`` (what relays and SCC read)
``rocof_meas`` bus-B6 ROCOF ``BusROCOF.Wf_y`` (pu/s)
=============  ======================================================

The returned command is written to ``TGOV1N.paux0`` (added after the droop
gain; on the 2.5 MVA base it is ΔP_c in machine pu) and held until the next
sample.  The frequency relays read the bus measurements, as a relay at the
generator terminals would, including their spikes at a fault; the
over-current relay of the protected line runs after every accepted step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

import lfc.testbed.stored_runs as stored_runs
from lfc._validate import check_multiple, check_nonnegative, check_positive, check_range
from lfc.engine import sample_signal
from lfc.estimation import KalmanFilter
from lfc.filters import SafetyFilter
from lfc.generator import GeneratorSide
from lfc.model import STATES, LFCParams
from lfc.relays import RelaySettings, relays_or_default
from lfc.result import Result, area_result
from lfc.signals import SignalLike
from lfc.testbed.loop import (AndesLoop, BreakerOpens, GeneratorSides, RecordedSides,
                              TestbedError)

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


IEC_SI_K, IEC_SI_A = 0.14, 0.02  # IEC 60255-151 standard inverse: t = TMS k / ((I/Is)^a - 1)


@dataclass(frozen=True)
class OvercurrentSettings:
    """IEC 60255-151 standard-inverse relay with an instantaneous element.

    Parameters
    ----------
    pickup : float
        Inverse-time pickup Is (pu of the 2.5 MVA / 27.6 kV current base,
        1 pu = 52.3 A). Default 0.5 pu (26 A), five times the feeder's load.
    tms : float
        Time multiplier setting. Default 0.05.
    instantaneous : float
        Instantaneous (definite-time) element pickup (pu). Default 2.5 pu
        (131 A), above any load or motor-start current of the feeder.
    instantaneous_delay : float
        Its operating time (s). Default 0.02 s (about one cycle).
    breaker_time : float
        Trip command to open contacts (s). Default 0.05 s (3 cycles).
    """

    pickup: float = 0.5
    tms: float = 0.05
    instantaneous: float = 2.5
    instantaneous_delay: float = 0.02
    breaker_time: float = 0.05

    def __post_init__(self) -> None:
        check_positive("pickup", self.pickup)
        check_positive("tms", self.tms)
        check_nonnegative("instantaneous_delay", self.instantaneous_delay)
        check_nonnegative("breaker_time", self.breaker_time)
        if not self.instantaneous > self.pickup:
            raise ValueError(f"instantaneous must be > pickup ({self.pickup}), "
                             f"got {self.instantaneous}")

    def operate_time(self, current: np.ndarray | float) -> np.ndarray:
        """Relay operating time (s) for a constant current (pu); inf below pickup."""
        i = np.asarray(current, float)
        ratio = np.maximum(i / self.pickup, 1.0)
        with np.errstate(divide="ignore"):
            t_inv = np.where(i > self.pickup, self.tms * IEC_SI_K / (ratio ** IEC_SI_A - 1),
                             np.inf)
        return np.where(i >= self.instantaneous, np.minimum(t_inv, self.instantaneous_delay),
                        t_inv)


class OvercurrentRelay:
    """Stateful relay fed one current sample per plant step.

    The inverse-time element integrates ``dt / operate_time(I)`` while I is
    above pickup and resets below it; the instantaneous element is a
    definite-time timer.  Either reaching its time issues the trip at ``trip_t``;
    the breaker opens ``breaker_time`` later (``open_t``).
    """

    def __init__(self, settings: OvercurrentSettings) -> None:
        self.settings = settings
        self.trip_t: float | None = None
        self._acc = 0.0
        self._inst_start: float | None = None
        self._t_prev: float | None = None

    @property
    def open_t(self) -> float | None:
        """When the breaker opens (s), None before a trip."""
        return None if self.trip_t is None else self.trip_t + self.settings.breaker_time

    def update(self, t: float, current: float) -> None:
        """Feed the current magnitude (pu) at time ``t`` (s)."""
        s = self.settings
        dt = 0.0 if self._t_prev is None else t - self._t_prev
        self._t_prev = t
        if self.trip_t is not None:
            return
        self._acc = self._acc + dt / float(s.operate_time(current)) if current > s.pickup else 0.0
        if current >= s.instantaneous:
            self._inst_start = t if self._inst_start is None else self._inst_start
        else:
            self._inst_start = None
        inst_due = self._inst_start is not None and t - self._inst_start >= s.instantaneous_delay
        if self._acc >= 1.0 or inst_due:
            self.trip_t = t


def phase_a_current(t: np.ndarray, phasor: np.ndarray, *, f_nominal: float, i_base: float,
                    fs: float = 3000.0) -> tuple[np.ndarray, np.ndarray]:
    """Instantaneous phase-A current reconstructed from its phasor.

    ``i_a(t) = √2 · i_base · |I(t)| · cos(2π f_nominal t + ∠I(t))``, with |I|
    and the unwrapped angle interpolated linearly onto a uniform grid.

    Parameters
    ----------
    t : ndarray
        Times of the phasor samples (s), increasing.
    phasor : ndarray of complex
        Line current phasor (pu, rms, on the synchronously rotating frame).
    f_nominal : float
        Hz.
    i_base : float
        A rms per pu.
    fs : float
        Sample rate of the waveform (Hz).

    Returns
    -------
    (t_fine, i_a) : seconds and amperes (instantaneous)
    """
    t = np.asarray(t, float)
    t_fine = np.arange(t[0], t[-1], 1.0 / fs)
    mag = np.interp(t_fine, t, np.abs(phasor))
    ang = np.interp(t_fine, t, np.unwrap(np.angle(phasor)))
    return t_fine, math.sqrt(2) * i_base * mag * np.cos(2 * np.pi * f_nominal * t_fine + ang)


TESTBED_COLUMNS = ("v_gen", "i_line_re", "i_line_im")


@dataclass(frozen=True)
class FaultSpec:
    """A bolted three-phase fault, cleared only by the over-current relay.

    Parameters
    ----------
    bus : int
        Faulted bus; must be beyond the protected line (default B5).
    t : float
        Inception (s).
    xf : float
        Fault reactance (pu, system base), in [1e-4, 1] (ANDES fails at
        inception for xf ≤ 1e-5).
    """

    bus: int = 5
    t: float = 1.0
    xf: float = 1e-3

    def __post_init__(self) -> None:
        check_nonnegative("t", self.t)
        if not 1e-4 <= self.xf <= 1.0:
            raise ValueError(f"xf must be in [1e-4, 1] pu, got {self.xf}")


def simulate_microgrid(params: LFCParams, *, duration: float,
                       pc_attack: SignalLike | None = None,
                       wref_attack: SignalLike | None = None, load: SignalLike | None = None,
                       fault: FaultSpec | None = None, scc: SafetyFilter | None = None,
                       relays: RelaySettings | None = None,
                       estimator: str | KalmanFilter | None = None,
                       noise_std: tuple[float, float] = (0.0, 0.0), seed: int = 0,
                       control_period: float = 0.01, step: float = 0.005,
                       stop_on_trip: bool = False, load_feedforward: bool = False,
                       anti_windup: bool = False, case: MicrogridCase | None = None,
                       overcurrent: OvercurrentSettings | None = None,
                       network=None) -> Result:
    """Simulate the closed loop on the ANDES microgrid; the same arguments and
    :class:`~lfc.Result` as :func:`lfc.simulate`, plus the ones below.

    Parameters
    ----------
    params : LFCParams
        The design model: the local controller's gain and the Kalman filter's
        model (the SCC carries its own; use :func:`lfc.testbed.design_model`).
    load : callable, optional
        Load change ΔP_L (pu at nominal voltage), added as a constant-impedance
        load at ``case.load_bus`` and updated every plant step.
    fault : FaultSpec, optional
        A three-phase fault, cleared by the over-current relay opening
        ``case.protected_line``.
    step : float
        ANDES time step (s); ``control_period`` must be a multiple of it.
    case : MicrogridCase
        Network data; default ``MicrogridCase()``.
    overcurrent : OvercurrentSettings
        Relay of the protected line; default ``OvercurrentSettings()``.
    network : lfc.wire.link.Link, optional
        The command channels arrive over a network (:func:`lfc.wire.run_wire`):
        no ``pc_attack`` or ``wref_attack`` (the man in the middle attacks), no
        ``fault`` (its breaker's replay would run the network twice).

    Returns
    -------
    Result
        ``trace`` has one row per accepted ANDES step, with the extra columns
        ``v_gen`` (B6 voltage, pu) and ``i_line_re``/``i_line_im`` (protected
        line's current phasor at B6, pu); ``line_trips`` holds the over-current
        trip.

    Raises
    ------
    ValueError
        Before anything runs, for a scenario the testbed cannot represent.
    TestbedError
        If ANDES does not converge (with the time and ANDES' reason).
    """
    case = case or MicrogridCase()
    if network is not None and fault is not None:
        raise ValueError("fault: not over a network (the breaker's opening is replayed in a "
                         "second pass, which would run the network twice)")
    n_ctrl = _check_scenario(case, duration, step, control_period, fault, load)
    relays = relays_or_default(relays)
    oc = overcurrent or OvercurrentSettings()
    tc = np.arange(n_ctrl) * control_period

    def side() -> GeneratorSide:
        return GeneratorSide(params, scc, estimator, noise_std, seed, tc, pc_attack,
                             wref_attack, load_feedforward, control_period,
                             anti_windup=anti_windup, network=network is not None)

    settings = {"plant": "testbed", "case": repr(case), "params": vars(params),
                "relays": vars(relays), "duration": duration, "step": step,
                "control_period": control_period, "seed": seed, "noise_std": list(noise_std),
                "scc": repr(scc), "estimator": repr(estimator), "pc_attack": repr(pc_attack),
                "wref_attack": repr(wref_attack), "load": repr(load), "fault": repr(fault),
                "overcurrent": repr(oc), "stop_on_trip": stop_on_trip,
                "load_feedforward": load_feedforward, "anti_windup": anti_windup}
    # the run is a function of these and of the commands its generator side returns
    # (lfc.testbed.stored_runs): read back where stored, else run on ANDES and stored
    call = {"params": params, "duration": duration, "pc_attack": pc_attack,
            "wref_attack": wref_attack, "load": load, "fault": fault, "relays": relays,
            "estimator": estimator, "noise_std": noise_std, "seed": seed,
            "control_period": control_period, "step": step, "stop_on_trip": stop_on_trip,
            "load_feedforward": load_feedforward, "anti_windup": anti_windup, "case": case,
            "overcurrent": oc, "network": network}
    share, key = stored_runs.scenario_keys(call, "microgrid")
    for stored in stored_runs.stored(key) if key is not None else ():
        gen = side()
        if isinstance(stored, MicrogridRun) and _replays(gen, stored, stop_on_trip):
            return _result(stored, gen, case, settings)
    run, gen = _run(case, fault, oc, load, side, relays, stop_on_trip, network, duration, step)
    if key is not None:
        stored_runs.store(key, run, run.commands.tobytes(), share,
                          {"case": "microgrid", "duration": duration}, "microgrid")
    return _result(run, gen, case, settings)


@dataclass
class MicrogridRun:
    """What a finished microgrid run leaves for a later call whose generator side
    returns the same commands (:mod:`lfc.testbed.stored_runs`)."""

    rows: np.ndarray            # (rows, 12): AndesLoop.rows (t, MEASURED, TESTBED_COLUMNS)
    trips: pd.DataFrame         # the frequency relays' trips (relay, t)
    read: np.ndarray            # (control samples run,): the row each sample read
    commands: np.ndarray        # (control samples run, 1), pu
    overcurrent: tuple          # the over-current relay's (trip_t, open_t), s (None: none)


def _run(case: MicrogridCase, fault: FaultSpec | None, oc: OvercurrentSettings, load,
         side, relays: RelaySettings, stop_on_trip: bool, network, duration: float,
         step: float, commands: np.ndarray | None = None
         ) -> tuple[MicrogridRun, GeneratorSide]:
    """Run on ANDES, with a fresh generator side from ``side()`` per pass: a fault takes
    two (:class:`MicrogridPlant`); ``commands`` (one per control sample), if given, are
    applied instead of what the generator side returns.  The run, and the generator
    side of its last pass."""
    def one(open_t: float | None) -> tuple[AndesLoop, MicrogridPlant]:
        plant = MicrogridPlant(case, fault, OvercurrentRelay(oc), open_t)
        loop = AndesLoop(plant, {} if load is None else {0: load}, [side()], relays,
                         stop_on_trip, network)
        if commands is not None:
            loop.sides = RecordedSides(commands)
        return loop, plant

    loop, plant = one(None)
    if loop.run(duration, step):  # second pass: the breaker opening as a scheduled ANDES event
        opened = plant.oc.open_t
        loop, plant = one(opened)
        loop.run(duration, step)
        if plant.oc.open_t is None or abs(plant.oc.open_t - opened) > 1e-9:
            raise TestbedError(f"the replay's over-current trip ({plant.oc.open_t}) differs "
                               f"from the first pass ({opened})")
    rows = np.array(loop.rows)
    t = rows[:, 0].round(9)        # ANDES accumulates its time in floating point
    run = MicrogridRun(rows, loop.trips(t)[0],
                       np.array([k for k, _ in loop.samples], dtype=np.int64),
                       np.array([u for _, u in loop.samples]).reshape(-1, 1),
                       (plant.oc.trip_t, plant.oc.open_t))
    return run, loop.gens[0]


def _replays(gen: GeneratorSide, run: MicrogridRun, stop_on_trip: bool) -> bool:
    """Whether ``gen`` returns ``run``'s commands, bit for bit, at every control sample
    it read (then ANDES would integrate ``run`` again)."""
    if len(run.read) != len(gen.tc) and not stop_on_trip:
        return False
    sides = GeneratorSides([gen])
    for j, (row, command) in enumerate(zip(run.read, run.commands)):
        command_now = sides.sample(j, run.rows[row, 1:9].reshape(1, 8))[0]
        if not stored_runs.same_float(command_now, command[0]):
            return False
    return True


def rerun(rec) -> MicrogridRun:
    """A recording's run (:class:`lfc.testbed.stored_runs.Recording`) computed again on
    ANDES, fed the commands it holds (no generator side computes them): what checks a
    recording (``tests/test_stored_runs.py``)."""
    import pickle
    call = pickle.loads(rec.call)                    # the committed call
    n_ctrl = int(np.ceil(call["duration"] / call["control_period"] - 1e-9))
    tc = np.arange(n_ctrl) * call["control_period"]

    def side() -> GeneratorSide:
        return GeneratorSide(call["params"], None, None, (0.0, 0.0), 0, tc, None, None, False,
                             call["control_period"])
    return _run(call["case"], call["fault"], call["overcurrent"], call["load"], side,
                call["relays"], call["stop_on_trip"], None, call["duration"], call["step"],
                rec.run.commands)[0]


def _result(run: MicrogridRun, gen: GeneratorSide, case: MicrogridCase,
            settings: dict) -> Result:
    cols = ("t", *STATES, "p_load", *TESTBED_COLUMNS)
    trace = pd.DataFrame(run.rows[:, [0, 1, 2, 3, 4, 5, 6, 9, 10, 11]], columns=list(cols))
    trace["t"] = trace["t"].round(9)  # ANDES accumulates its time in floating point
    t_end = float(trace["t"].iat[-1])
    trip_t, open_t = run.overcurrent
    line_trips = pd.DataFrame(
        [(case.protected_line, round(trip_t, 9), round(open_t, 9))]
        if trip_t is not None and trip_t <= t_end else [],
        columns=["line", "trip_t", "open_t"])
    return area_result(trace, gen.tc, gen.ctrl, run.trips, gen.scc, settings, line_trips)


def _check_scenario(case: MicrogridCase, duration: float, step: float, control_period: float,
                    fault: FaultSpec | None, load: SignalLike | None) -> int:
    check_positive("duration", duration)
    check_multiple("control_period", control_period, "step", step)
    if fault is not None:
        _check_fault(case, fault, duration)
    _check_load(case, load, duration, step)
    return int(np.ceil(duration / control_period - 1e-9))


def _check_fault(case: MicrogridCase, fault: FaultSpec, duration: float) -> None:
    check_bus("fault.bus", fault.bus, case)
    if fault.bus == case.generator_bus:
        raise ValueError(f"fault.bus must not be the generator bus B{case.generator_bus}: "
                         "no relay can isolate it and leave the island running")
    cleared_by = case.beyond(case.protected_line)
    if fault.bus not in cleared_by:
        raise ValueError(f"fault.bus must be beyond the protected line {case.protected_line} "
                         f"(buses {sorted(cleared_by)}), the only one with a relay; "
                         f"got B{fault.bus}")
    if not fault.t < duration:
        raise ValueError(f"fault.t must be in [0, duration={duration}), got {fault.t}")


def _check_load(case: MicrogridCase, load: SignalLike | None, duration: float,
                step: float) -> None:
    t = np.arange(0.0, duration + step, step)
    extra = sample_signal(load, t, "load")
    total = case.total_load + extra
    if total.max() > case.valve_max:
        raise ValueError(f"load takes the total load to {total.max():.3f} pu, more than the "
                         f"machine can carry (governor valve limit {case.valve_max} pu)")
    if total.min() < 0:
        raise ValueError(f"load takes the total load below zero ({total.min():.3f} pu)")


class MicrogridPlant:
    """The islanded microgrid as an :class:`~lfc.testbed.loop.AndesPlant`: one
    area, the load at ``case.load_bus``, a fault beyond the protected line
    cleared by its over-current relay.

    A run with a fault takes two passes.  The first runs the relay in the loop
    and stops when its breaker opens.  The second (``open_t`` given) schedules
    that opening as ANDES events (the line is toggled off and the isolated
    fault removed at ``open_t``), which ANDES handles exactly; switching a line
    inside the step callback instead failed to converge for faults with
    xf ≥ 0.1 pu.
    """

    n_areas = 1

    def __init__(self, case: MicrogridCase, fault: FaultSpec | None, oc: OvercurrentRelay,
                 open_t: float | None) -> None:
        self.case, self.fault, self.oc, self.open_t = case, fault, oc, open_t
        self.line_open = False
        self._extra = (math.nan, math.nan, math.nan)
        self._current = 0.0

    def build(self):
        fault = self.fault
        kw = {} if fault is None else dict(fault_bus=fault.bus, fault_xf=fault.xf,
                                           fault_t=fault.t, open_t=self.open_t)
        return build_system(self.case, **kw)

    def attach(self, ss) -> None:
        case = self.case
        gov, line = ss.TGOV1N, ss.Line
        self.ax = np.array([gov.LAG_y.a[0], ss.GENROU.omega.a[0]])
        self.ay = np.array([gov.pout.a[0], ss.BusFreq.f.a[0], ss.BusROCOF.Wf_y.a[0]])
        self.x0 = np.array([ss.dae.x[self.ax[0]], ss.dae.y[self.ay[0]]])
        if not (abs(ss.dae.x[self.ax[1]] - 1) < 1e-6 and abs(ss.dae.y[self.ay[1]] - 1) < 1e-6):
            raise TestbedError("the testbed did not initialize at 1.0 pu frequency")
        k = line.idx2uid(case.protected_line)
        _, a, b, _ = next(ln for ln in case.lines if ln[0] == case.protected_line)
        self.z_line = complex(line.r.v[k], line.x.v[k])
        self.y_shunt = complex(line.g.v[k] / 2 + line.g1.v[k], line.b.v[k] / 2 + line.b1.v[k])
        bus = ss.Bus
        self.bus_uid = (bus.idx2uid(a), bus.idx2uid(b))
        self.gen_uid = bus.idx2uid(case.generator_bus)
        self.v_addr, self.a_addr = bus.v.a, bus.a.a
        self.lstep = ss.PQ.idx2uid("LSTEP")
        self.lstep_v0 = float(bus.v.v[bus.idx2uid(case.load_bus)])

    def measure(self, ss, p_load: np.ndarray) -> np.ndarray:
        """The design-model state, the load, no tie-line, the load as the net
        disturbance; keeps the B6 voltage and the protected line's current."""
        x, y = ss.dae.x, ss.dae.y
        out = np.zeros((1, 8))
        out[0, :5] = (x[self.ax[0]] - self.x0[0], y[self.ay[0]] - self.x0[1],
                      x[self.ax[1]] - 1.0, y[self.ay[1]] - 1.0, y[self.ay[2]])
        out[0, 5] = out[0, 7] = p_load[0]
        v, a = y[self.v_addr], y[self.a_addr]
        if self.line_open:
            current = 0j
        else:
            v1, v2 = (v[u] * np.exp(1j * a[u]) for u in self.bus_uid)
            current = complex((v1 - v2) / self.z_line + v1 * self.y_shunt)
        self._current = abs(current)
        self._extra = (float(v[self.gen_uid]), current.real, current.imag)
        return out

    def extra(self) -> tuple[float, ...]:
        """``TESTBED_COLUMNS``: B6 voltage (pu) and the line current phasor (pu)."""
        return self._extra

    def protect(self, t: float) -> None:
        if self.line_open:
            return
        self.oc.update(t, self._current)
        if self.oc.open_t is None or t < self.oc.open_t - 1e-9:
            return
        if self.open_t is None:
            raise BreakerOpens
        self.line_open = True  # ANDES opened it at self.open_t

    def actuate(self, ss, area: int, u: float) -> None:
        ss.TGOV1N.paux0.v[:] = u

    def set_load(self, ss, p_load: np.ndarray) -> None:
        ss.PQ.Req.v[self.lstep] = p_load[0] / self.lstep_v0 ** 2
