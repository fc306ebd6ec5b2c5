"""The SCC in the loop of the ANDES microgrid: :func:`simulate_testbed`.

ANDES integrates the network (implicit trapezoidal, fixed ``step`` except
around events).  Before every step it calls back into :class:`_Testbed`,
which logs the last accepted state, runs the over-current relay, and, when a
control sample is due, hands the generator-side loop
(:class:`lfc.engine.GeneratorSide`: noise, Kalman filter, local integral
controller, attacks, filter — the engine's own compiled code) the state in the
design model's coordinates:

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
generator terminals would, including their spikes at a fault.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from lfc._validate import check_multiple, check_nonnegative, check_positive
from lfc.engine import GeneratorSide, sample_signal
from lfc.estimation import KalmanFilter
from lfc.filters import SafetyFilter
from lfc.model import STATES, LFCParams
from lfc.relays import RelayBank, RelaySettings
from lfc.signals import SignalLike
from lfc.simulate import SimResult, result
from lfc.testbed.case import MicrogridCase, build_system, check_bus
from lfc.testbed.protection import OvercurrentRelay, OvercurrentSettings

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


class TestbedError(RuntimeError):
    """ANDES failed during a run (the message says when and why)."""

    __test__ = False  # not a pytest test class


def simulate_testbed(params: LFCParams, *, duration: float,
                     pc_attack: SignalLike | None = None,
                     wref_attack: SignalLike | None = None, load: SignalLike | None = None,
                     fault: FaultSpec | None = None, scc: SafetyFilter | None = None,
                     relays: RelaySettings | None = None,
                     estimator: str | KalmanFilter | None = None,
                     noise_std: tuple[float, float] = (0.0, 0.0), seed: int = 0,
                     control_period: float = 0.01, step: float = 0.005,
                     stop_on_trip: bool = False, load_feedforward: bool = False,
                     case: MicrogridCase | None = None,
                     overcurrent: OvercurrentSettings | None = None) -> SimResult:
    """Simulate the closed loop on the ANDES microgrid; the same arguments and
    :class:`~lfc.simulate.SimResult` as :func:`lfc.simulate`, plus the ones below.

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

    Returns
    -------
    SimResult
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
    n_ctrl = _check_scenario(case, duration, step, control_period, fault, load)
    relays = relays if relays is not None else RelaySettings()
    oc = overcurrent or OvercurrentSettings()
    tc = np.arange(n_ctrl) * control_period

    def testbed(open_t: float | None) -> _Testbed:
        gen = GeneratorSide(params, scc, estimator, noise_std, seed, tc, pc_attack,
                            wref_attack, load_feedforward, control_period)
        return _Testbed(case, fault, load, gen, OvercurrentRelay(oc),
                        RelayBank(relays) if stop_on_trip else None, open_t)

    bed = testbed(None)
    opened = bed.run(duration, step)
    if opened is not None:  # second pass: the breaker opening as a scheduled ANDES event
        bed = testbed(opened)
        bed.run(duration, step)
        if bed.oc.open_t is None or abs(bed.oc.open_t - opened) > 1e-9:
            raise TestbedError(f"the replay's over-current trip ({bed.oc.open_t}) differs "
                               f"from the first pass ({opened})")
    settings = {"plant": "testbed", "case": repr(case), "params": vars(params),
                "relays": vars(relays), "duration": duration, "step": step,
                "control_period": control_period, "seed": seed, "noise_std": list(noise_std),
                "scc": repr(scc), "estimator": repr(estimator), "pc_attack": repr(pc_attack),
                "wref_attack": repr(wref_attack), "load": repr(load), "fault": repr(fault),
                "overcurrent": repr(oc), "stop_on_trip": stop_on_trip,
                "load_feedforward": load_feedforward}
    return bed.result(relays, settings)


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


def init_tds(ss, duration: float, step: float) -> None:
    """Configure ANDES' time-domain run of ``ss`` (to ``duration`` at ``step``,
    s; quiet, no line search, no stored history: the callback logs) and
    initialize it."""
    cfg = ss.TDS.config
    cfg.tf, cfg.tstep, cfg.no_tqdm, cfg.criteria = duration, step, 1, 0
    cfg.linesearch, cfg.save_every = 0, 0
    ss.TDS.init()


def run_tds(ss, duration: float, callback) -> float:
    """Run the initialized ``ss`` with ``callback(t, system)`` before every step
    attempt; return the end time (s), or raise :class:`TestbedError` with ANDES'
    reason if it stopped before ``duration``."""
    ss.TDS.callpert = callback
    ss.TDS.run(no_summary=True)
    t_end = float(ss.dae.t)
    if ss.TDS.busted or t_end < duration - 1e-9:
        raise TestbedError(f"ANDES did not converge at t = {t_end:.4f} s: "
                           f"{ss.TDS.err_msg or 'the run ended early'}")
    return t_end


class _Stop(Exception):
    """Raised inside the ANDES callback to end a run early."""


class _BreakerOpens(_Stop):
    """Raised in a first pass when the over-current relay's breaker opens."""


class _Testbed:
    """One ANDES run with the generator-side loop in its per-step callback.

    A run with a fault takes two passes.  The first runs the relay in the loop
    and stops when its breaker opens (``run`` returns that time).  The second
    (``open_t`` given) schedules that opening as ANDES events (the line is
    toggled off and the isolated fault removed at ``open_t``), which ANDES
    handles exactly; switching a line inside the step callback instead failed
    to converge for faults with xf ≥ 0.1 pu.
    """

    def __init__(self, case: MicrogridCase, fault: FaultSpec | None, load: SignalLike | None,
                 gen: GeneratorSide, oc: OvercurrentRelay, bank: RelayBank | None,
                 open_t: float | None) -> None:
        self.case, self.fault, self.load, self.gen, self.oc = case, fault, load, gen, oc
        self.bank, self.open_t = bank, open_t
        kw = {} if fault is None else dict(fault_bus=fault.bus, fault_xf=fault.xf,
                                           fault_t=fault.t, open_t=open_t)
        self.ss = build_system(case, **kw)
        self.rows: list[tuple] = []
        self.trips: list[tuple[str, float]] = []
        self.next_j = 0
        self.line_open = False
        self._load_at = (math.nan, 0.0)  # (t, dP_L): the last load value evaluated

    def run(self, duration: float, step: float) -> float | None:
        """Integrate to ``duration``; return the breaker-open time if a first
        pass stopped there, else None."""
        init_tds(self.ss, duration, step)
        self._addresses()
        try:
            self._log(run_tds(self.ss, duration, self._callback))  # the final accepted state
        except _BreakerOpens:
            return self.oc.open_t
        except _Stop:
            pass
        return None

    def _addresses(self) -> None:
        ss, case = self.ss, self.case
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
        lstep = ss.PQ.idx2uid("LSTEP")
        self.lstep, self.lstep_v0 = lstep, float(bus.v.v[bus.idx2uid(case.load_bus)])

    def _state(self) -> tuple[np.ndarray, float, complex]:
        """Design-model state (pu), B6 voltage (pu) and line current (pu) now."""
        x, y = self.ss.dae.x, self.ss.dae.y
        state = np.array([x[self.ax[0]] - self.x0[0], y[self.ay[0]] - self.x0[1],
                          x[self.ax[1]] - 1.0, y[self.ay[1]] - 1.0, y[self.ay[2]]])
        v, a = y[self.v_addr], y[self.a_addr]
        if self.line_open:
            current = 0j
        else:
            v1, v2 = (v[u] * np.exp(1j * a[u]) for u in self.bus_uid)
            current = (v1 - v2) / self.z_line + v1 * self.y_shunt
        return state, float(v[self.gen_uid]), complex(current)

    def _p_load(self, t: float) -> float:
        """dP_L at ``t`` (pu); the callback asks for each step's end time, and the
        log for the same time one call later, so the last value is kept."""
        if self.load is None:
            return 0.0
        if t != self._load_at[0]:
            self._load_at = (t, float(sample_signal(self.load, np.array([t]), "load")[0]))
        return self._load_at[1]

    def _callback(self, t_attempt, system) -> None:
        ss = self.ss
        t_next = float(t_attempt)
        self._log(max(t_next - ss.TDS.h, 0.0))
        ss.PQ.Req.v[self.lstep] = self._p_load(t_next) / self.lstep_v0 ** 2

    def _log(self, t: float) -> None:
        """Record the accepted state at ``t`` (once), protect, and control if due."""
        if self.rows and t <= self.rows[-1][0] + 1e-9:
            return
        state, v_gen, current = self._state()
        p_load = self._p_load(t)
        self.rows.append((t, *state, p_load, v_gen, current.real, current.imag))
        self._protect(t, abs(current))
        self._check_relays(t, state)
        while self.next_j < len(self.gen.tc) and self.gen.tc[self.next_j] <= t + 1e-7:
            u = self.gen.step(self.next_j, state, p_load)
            self.ss.TGOV1N.paux0.v[:] = u
            self.next_j += 1

    def _protect(self, t: float, current: float) -> None:
        if self.line_open:
            return
        self.oc.update(t, current)
        if self.oc.open_t is None or t < self.oc.open_t - 1e-9:
            return
        if self.open_t is None:
            raise _BreakerOpens
        self.line_open = True  # ANDES opened it at self.open_t

    def _check_relays(self, t: float, state: np.ndarray) -> None:
        if self.bank is None:
            return
        found = self.bank.update(np.array([t]), state[3:4], state[4:5])
        if found:
            self.trips.extend((relay, round(t, 9)) for relay, _, _ in found)  # as the trace
            raise _Stop

    def result(self, relays: RelaySettings, settings: dict) -> SimResult:
        cols = ("t", *STATES, "p_load", *TESTBED_COLUMNS)
        trace = pd.DataFrame(self.rows, columns=list(cols))
        trace["t"] = trace["t"].round(9)  # ANDES accumulates its time in floating point
        if self.bank is None:
            found = RelayBank(relays).update(trace["t"].to_numpy(), trace["dw_meas"].to_numpy(),
                                             trace["rocof_meas"].to_numpy())
            self.trips = [(r, float(trace["t"].iat[k])) for r, k, _ in
                          sorted(found, key=lambda f: f[1])]
        t_end = float(trace["t"].iat[-1])
        trips = pd.DataFrame(self.trips, columns=["relay", "t"])
        line_trips = pd.DataFrame(
            [(self.case.protected_line, round(self.oc.trip_t, 9), round(self.oc.open_t, 9))]
            if self.oc.trip_t is not None and self.oc.trip_t <= t_end else [],
            columns=["line", "trip_t", "open_t"])
        return result(trace, self.gen.tc, self.gen.ctrl, trips, self.gen.scc, settings,
                      line_trips)
