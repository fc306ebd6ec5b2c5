"""One run over the wire, in lockstep: control centre, man in the middle and
generator exchanging Modbus/TCP or DNP3 frames on loopback, one command per
control period.

Who does what (the paper, section II: the control centre sets the frequency
reference and runs the AGC; the signals travel over an insecure network; the
filter sits at the generator):

* the **control centre** writes the command every period, reads the report
  back and keeps the operator's alarm log.  Where the integrator runs is a
  choice the paper leaves open, and both readings are here: ``agc="generator"``
  (the paper's eq. 2, a *local* controller ``dPc' = k (dw_ref - dw_meas)`` at
  the generator; the centre sends the reference ``wref`` and a command
  supplement ``pc``, both 0) and ``agc="centre"`` (the centre's AGC integrates
  the frequency the generator reports, with the engine's own
  :func:`lfc.engine.agc_step`, and sends its output as ``pc``);
* the **man in the middle** (:class:`lfc.wire.relay.Relay`) forwards every
  frame and applies the attack (:class:`lfc.wire.attacks.WireAttack`);
* the **generator** receives the command, runs its safety filter in the
  engine's generator side (:class:`lfc.engine.GeneratorSide`, ``network=True``:
  the same compiled code as :func:`lfc.simulate`), holds the command on the
  plant for one control period, watches its relays and publishes its report.

*Lockstep*: the plant advances one control period per exchanged command, so a
run over the wire reproduces :func:`lfc.simulate` of the same attack: the
command channel's sum, the reference's difference, the integrator's update and
the plant's step are the same operations (``tests/test_wire.py`` checks 1e-9
pu).  A reference attack is, with ``agc="generator"``, an attack on the
``wref`` field; with ``agc="centre"``, where no reference is sent, the opposite
attack on the frequency the centre is told (:func:`lfc.wire.attacks.from_simulate`).
The measured time of every exchange (write and read, round trip through the
relay) is in the result.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

import numpy as np
import pandas as pd

from lfc.engine import CTRL_COLUMNS, GeneratorSide, agc_step, sample_signal
from lfc.filters.base import ACTIVE, ALARM_BITS, binding_names
from lfc.model import STATES, LFCParams
from lfc.multiarea import as_grid, discretize_grid
from lfc.relays import RELAY_NAMES, relay_sample, relays_or_default
from lfc.simulate import SimResult, check_timing, result
from lfc.filters import SafetyFilter
from lfc.wire.attacks import WireAttack
PROTOCOLS = ("modbus", "dnp3")
AGC = ("generator", "centre")
MODES = ("lockstep", "realtime")


def _transport(protocol: str):
    """The module of ``protocol``: each has ``Outstation``, ``Codec`` and ``Centre``
    with one interface (:mod:`lfc.wire.modbus`), and the shared ``EventLoop`` and
    ``Relay`` (:mod:`lfc.wire.relay`)."""
    if protocol == "modbus":
        from lfc.wire import modbus
        return modbus
    from lfc.wire import dnp3
    return dnp3


@dataclass
class WireResult:
    """Outcome of a run over the wire.

    Attributes
    ----------
    sim : SimResult
        The generator's side as :func:`lfc.simulate` reports it (trace, controls,
        trips, the filter's alarms).
    exchanges : DataFrame
        One row per control period: ``t`` (s), ``sent`` (the command the centre
        wrote, pu), ``received`` (what the generator got, pu), ``applied`` (pu),
        ``link`` (1: no command arrived, the last one was held),
        ``write_ms`` and ``read_ms`` (round trips through the relay, wall clock),
        ``late_ms`` (real time: how late the generator's tick woke up).
    alarm_log : DataFrame
        The operator's view, one row per period whose report carries an alarm:
        ``t``, ``sent`` (the command field ``pc`` it wrote), ``reported_received``
        (that field as the generator reports it arrived), ``reported_applied``,
        ``binding`` (the filter's binding constraints), ``link``.
    frames : list of (float, str, bytes)
        Every Modbus/TCP frame on both legs (:attr:`lfc.wire.modbus.Relay.log`).
    settings : dict
    """

    sim: SimResult
    exchanges: pd.DataFrame
    alarm_log: pd.DataFrame
    frames: list
    settings: dict

    @property
    def tripped(self) -> bool:
        return not self.sim.trips.empty

    def forensics(self) -> dict:
        """The operator's estimate of the attack from the alarm log
        (:func:`lfc.wire.forensics.estimate_attack`)."""
        from lfc.wire.forensics import estimate_attack
        return estimate_attack(self.alarm_log, self.exchanges.sent.to_numpy(),
                               self.settings["control_period"])

    def table(self) -> pd.DataFrame:
        """The outcome in one row: trips, alarms, largest |Δω| and ROCOF, the
        exchanges' median and 99th-percentile round trips and the generator's
        99th-percentile lateness (ms, real time)."""
        tr, ex = self.sim.trace, self.exchanges
        return pd.DataFrame([{
            "protocol": self.settings["protocol"], "agc": self.settings["agc"],
            "attack": self.settings["attack_name"],
            "filter": self.settings["filter"], "tripped": self.tripped,
            "first_trip": ("" if self.sim.trips.empty else
                           f"{self.sim.trips.relay.iat[0]} at {self.sim.trips.t.iat[0]:.2f} s"),
            "alarms": len(self.alarm_log), "link_lost": int(ex.link.sum()),
            "max |dw| (pu)": float(tr.dw_meas.abs().max()),
            "max |rocof| (pu/s)": float(tr.rocof_meas.abs().max()),
            "write median (ms)": float(ex.write_ms.median()),
            "read median (ms)": float(ex.read_ms.median()),
            "write p99 (ms)": float(ex.write_ms.quantile(0.99)),
            "late p99 (ms)": float(ex.late_ms.quantile(0.99))}])


def run_wire(params: LFCParams, *, duration: float, attack: list | str = "none",
             scc: SafetyFilter | None = None, protocol: str = "modbus", load=None,
             noise_std: tuple[float, float] = (0.0, 0.0), seed: int = 0, dt: float = 0.001,
             control_period: float = 0.01, relays=None, anti_windup: bool = False,
             agc: str = "generator", mode: str = "lockstep") -> WireResult:
    """Run one area over the wire in lockstep (module docstring).

    Parameters
    ----------
    params : LFCParams
        The area (plant and design model).
    duration : float
        Simulated time (s).
    attack : list of dict or str
        The man in the middle's operations, or a name of
        :data:`lfc.wire.attacks.ATTACKS` (``"fig4"``, ``"fig5"``, ...).
    scc : SafetyFilter or None
        The generator's filter.
    protocol : str
        ``"modbus"`` (Modbus/TCP) or ``"dnp3"``.
    load, noise_std, seed, dt, control_period, relays, anti_windup
        As in :func:`lfc.simulate` (``anti_windup``: the integrator, wherever it
        runs, does not integrate while the generator's filter holds against it).
    agc : str
        Where the integrator runs: ``"generator"`` (default, the paper's local
        controller) or ``"centre"`` (module docstring).
    mode : str
        ``"lockstep"`` (default: the plant advances one control period per
        exchanged command) or ``"realtime"`` (the plant at the wall clock: the
        generator ticks every control period whatever has arrived, the centre
        reads and writes half a period before; a run takes ``duration`` s).

    Returns
    -------
    WireResult
    """
    if not isinstance(params, LFCParams):
        raise ValueError(f"params must be an LFCParams (one area), got {type(params).__name__}")
    if protocol not in PROTOCOLS:
        raise ValueError(f"protocol must be one of {PROTOCOLS}, got {protocol!r}")
    ratio = check_timing(duration, dt, control_period)
    relays = relays_or_default(relays)
    name = attack if isinstance(attack, str) else "custom"
    policy = WireAttack(attack)
    if agc not in AGC:
        raise ValueError(f"agc must be one of {AGC}, got {agc!r}")
    if agc == "centre" and any(op.get("field") == "wref" for op in policy.ops):
        raise ValueError("attack: with agc='centre' no reference is sent (the centre's AGC "
                         "integrates the frequency it is told): attack dw_meas instead "
                         "(lfc.wire.attacks.from_simulate(..., agc='centre'))")
    local = agc == "generator"
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    n_steps = int(round(duration / dt))
    n_ctrl = -(-n_steps // ratio)
    period = ratio * dt
    t = np.arange(n_steps + 1) * dt
    tc = np.arange(n_ctrl) * period
    gen = GeneratorSide(params, scc, None, noise_std, seed, tc, None, None, False, period,
                        k_agc=None if local else (0.0, 0.0), network=True,
                        anti_windup=anti_windup and local)
    A, Bu, Bl = discretize_grid(as_grid(params), dt)
    p = sample_signal(load, t, "load")
    limits, delays = relays.arrays()
    start, due = np.full(3, np.nan), np.zeros(3)
    relay_sample(0.0, 0.0, 0.0, limits, delays, start, due)

    transport = _transport(protocol)
    loop = transport.EventLoop()
    outstation = transport.Outstation()
    clock = {"j": -1}

    def on_command(values, seq):
        clock["j"] += 1
        j = clock["j"]
        out = policy.command(j, (j * ratio) * dt, period, values)
        return None if out is None else (out, seq)

    def on_report(report):
        j = clock["j"]
        return {**report, **policy.report(j, (j * ratio) * dt, period, report)}

    state = {"x": np.zeros(5), "last": {"pc": 0.0, "wref": 0.0, "ace": 0.0}}
    xs = np.zeros((n_steps + 1, 5))
    trips = np.zeros(n_steps + 1, np.int64)
    g = np.zeros(1)          # the control centre's AGC integrator (pu; agc="centre")
    side, centre_rows, log = {}, {}, []
    u_col, flag_col = CTRL_COLUMNS.index("u_ref"), CTRL_COLUMNS.index("flags")

    def generate(j: int, lateness: float) -> None:
        """The generator at control sample j: take the command, filter, hold it on
        the plant for one period, watch the relays, publish the report."""
        x, k0 = state["x"], j * ratio
        got = outstation.take()
        link = 1
        if got is not None and got[1] == j % 65536:
            state["last"], link = got[0], 0
        last = state["last"]
        gen.receive(j, last["pc"], last["wref"], last["ace"])
        y0, y1 = x[3] + gen.noise[j, 0], x[4] + gen.noise[j, 1]
        u = gen.step(j, x, float(p[k0]))
        flags, u_ref = int(gen.ctrl[j, flag_col]), float(gen.ctrl[j, u_col])
        bits = 0
        for k in range(k0, min(k0 + ratio, n_steps)):
            x = A @ x + Bu[:, 0] * u + Bl[:, 0] * p[k]
            xs[k + 1] = x
            trips[k + 1] = relay_sample((k + 1) * dt, x[3], x[4], limits, delays, start, due)
            bits |= int(trips[k + 1])
        state["x"] = x
        outstation.publish({"seq": j % 65536, "dw_meas": y0, "rocof_meas": y1,
                            "pc_received": last["pc"], "u_ref": u_ref, "u": u, "flags": flags,
                            "trips": bits, "link": link})
        side[j] = (last["pc"], u, link, 1e3 * lateness)

    def send(j: int) -> None:
        t0 = _now()
        centre.send({"pc": g[0], "wref": 0.0, "ace": 0.0}, j)
        centre_rows[j] = [g[0], 1e3 * (_now() - t0), math.nan]

    def read(j: int) -> None:
        t0 = _now()
        rep = centre.poll()
        centre_rows[j][2] = 1e3 * (_now() - t0)
        if not local:
            agc_step(g, params.k_i * period, 0.0, rep["dw_meas"], 0.0, 0.0, anti_windup,
                     rep["u_ref"], rep["u"])
        if rep["flags"] & ALARM_BITS or rep["link"]:
            log.append((tc[j], centre_rows[j][0], rep["pc_received"], rep["u"],
                        ";".join(binding_names(rep["flags"])) if rep["flags"] & ACTIVE else "",
                        rep["link"]))

    try:
        port = loop.run(outstation.start())
        relay = transport.Relay(port, transport.Codec, on_command, on_report)
        centre = transport.Centre(loop.run(relay.start()), loop)
        if mode == "lockstep":
            for j in range(n_ctrl):
                send(j)
                generate(j, 0.0)
                read(j)
        else:
            _realtime(n_ctrl, period, send, generate, read)
        centre.close()
        loop.run(relay.stop())
        loop.run(outstation.stop())
    finally:
        loop.close()
    rows = [(tc[j], centre_rows[j][0], *side[j][:3], centre_rows[j][1], centre_rows[j][2],
             side[j][3]) for j in range(n_ctrl)]
    trace = pd.DataFrame({"t": t})
    for i, state in enumerate(STATES):
        trace[state] = xs[:, i]
    trace["p_load"] = p
    trip_rows = pd.DataFrame([(RELAY_NAMES[r], float(t[k])) for k in np.flatnonzero(trips)
                              for r in range(3) if trips[k] >> r & 1], columns=["relay", "t"])
    settings = {"params": vars(params), "relays": vars(relays), "duration": duration, "dt": dt,
                "control_period": control_period, "seed": seed, "noise_std": list(noise_std),
                "scc": repr(scc), "protocol": protocol, "attack": repr(policy.spec),
                "attack_name": name, "filter": "none" if scc is None else scc.method,
                "load": repr(load), "anti_windup": anti_windup, "agc": agc, "mode": mode}
    sim = result(trace, tc, gen.ctrl, trip_rows, scc, settings)
    exchanges = pd.DataFrame(rows, columns=["t", "sent", "received", "applied", "link",
                                            "write_ms", "read_ms", "late_ms"])
    alarm_log = pd.DataFrame(log, columns=["t", "sent", "reported_received",
                                           "reported_applied", "binding", "link"])
    return WireResult(sim, exchanges, alarm_log, relay.log, settings)


def _now() -> float:
    return time.perf_counter()


def _realtime(n_ctrl: int, period: float, send, generate, read) -> None:
    """The two sides on the wall clock: the generator (a thread) at ``t0 + j
    period``, the control centre half a period before, reading the last report
    and then sending the next command; a side that wakes up late does its work
    late (the lateness is recorded), a command that has not arrived is not
    waited for (the generator holds)."""
    t0 = _now() + 0.05
    failed: list[BaseException] = []

    def generator() -> None:
        try:
            for j in range(n_ctrl):
                _sleep_until(t0 + j * period)
                generate(j, _now() - (t0 + j * period))
        except BaseException as err:          # reported in the caller's thread
            failed.append(err)

    thread = threading.Thread(target=generator, name="lfc-wire-generator")
    thread.start()
    for j in range(n_ctrl):
        _sleep_until(t0 + (j - 0.5) * period)
        if j > 0:
            read(j - 1)
        send(j)
    thread.join()
    if failed:
        raise failed[0]
    read(n_ctrl - 1)


def _sleep_until(when: float) -> None:
    delay = when - _now()
    if delay > 0:
        time.sleep(delay)
