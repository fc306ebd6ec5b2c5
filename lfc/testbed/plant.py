"""The SCC in the loop of the ANDES microgrid: :func:`simulate_microgrid`.

The microgrid is an :class:`~lfc.testbed.loop.AndesPlant` (:class:`MicrogridPlant`)
run by the one ANDES adapter, :class:`lfc.testbed.loop.AndesLoop`.  Its one
area's state in the design model's coordinates:

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
from dataclasses import dataclass

import numpy as np
import pandas as pd

from lfc._validate import check_multiple, check_nonnegative, check_positive
from lfc.engine import GeneratorSide, sample_signal
from lfc.estimation import KalmanFilter
from lfc.filters import SafetyFilter
from lfc.model import STATES, LFCParams
from lfc.relays import RelaySettings, relays_or_default
from lfc.signals import SignalLike
from lfc.simulate import SimResult, result
from lfc.testbed.case import MicrogridCase, build_system, check_bus
from lfc.testbed.loop import AndesLoop, BreakerOpens, TestbedError
import lfc.testbed.stored_runs as stored_runs
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
                       network=None) -> SimResult:
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
    network : lfc.wire.link.Link, optional
        The command channels arrive over a network (:func:`lfc.wire.run_wire`):
        no ``pc_attack`` or ``wref_attack`` (the man in the middle attacks), no
        ``fault`` (its breaker's replay would run the network twice).

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
            from lfc.testbed.grid_plant import _Recorded
            loop.sides = _Recorded(commands)
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
    from lfc.testbed.grid_plant import _same_float
    from lfc.testbed.loop import GeneratorSides
    if len(run.read) != len(gen.tc) and not stop_on_trip:
        return False
    sides = GeneratorSides([gen])
    for j, (row, command) in enumerate(zip(run.read, run.commands)):
        if not _same_float(sides.sample(j, run.rows[row, 1:9].reshape(1, 8))[0], command[0]):
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
            settings: dict) -> SimResult:
    cols = ("t", *STATES, "p_load", *TESTBED_COLUMNS)
    trace = pd.DataFrame(run.rows[:, [0, 1, 2, 3, 4, 5, 6, 9, 10, 11]], columns=list(cols))
    trace["t"] = trace["t"].round(9)  # ANDES accumulates its time in floating point
    t_end = float(trace["t"].iat[-1])
    trip_t, open_t = run.overcurrent
    line_trips = pd.DataFrame(
        [(case.protected_line, round(trip_t, 9), round(open_t, 9))]
        if trip_t is not None and trip_t <= t_end else [],
        columns=["line", "trip_t", "open_t"])
    return result(trace, gen.tc, gen.ctrl, run.trips, gen.scc, settings, line_trips)


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
