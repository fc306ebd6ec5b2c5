"""One run over the wire, in lockstep: control centre, man in the middle and
generator exchanging Modbus/TCP or DNP3 frames on loopback or a network of
namespaces (:mod:`lfc.wire.network`), one command per control period.

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
  engine's generator side (:class:`lfc.generator.GeneratorSide`, ``network=True``:
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

import threading
import time
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from lfc._validate import check_flag, check_seed
from lfc.engine import check_area_keys
from lfc.filters import SafetyFilter
from lfc.filters.coupled import CoupledFilter
from lfc.generator import GeneratorSide
from lfc.linear_area import check_timing
from lfc.linear_grid import area_filter
from lfc.lockstep import LinearGrid
from lfc.model import LFCParams
from lfc.multiarea import MultiAreaParams, as_grid
from lfc.relays import relays_or_default
from lfc.result import Result
from lfc.run import runner_of
from lfc.scenarios import Scenario
from lfc.sensors import with_sensors
from lfc.wire.attacks import WireAttack
from lfc.wire.link import Link
from lfc.wire.network import NETWORKS
from lfc.wire.relay import Impairment

PROTOCOLS = ("modbus", "dnp3")
AGC = ("generator", "centre")
MODES = ("lockstep", "realtime")


def transport(protocol: str):
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
    sim : Result
        The generator side(s) as :func:`lfc.simulate` reports them (trace,
        controls, trips, the filter's alarms).
    exchanges : DataFrame
        One row per control period and area: ``t`` (s), ``area``, ``sent`` (the
        command the centre wrote, pu), ``received`` (what the generator got, pu),
        ``applied`` (pu), ``link`` (1: no command arrived, the last one was held),
        ``write_ms`` and ``read_ms`` (round trips through the relay, wall clock; NaN
        where the centre, in real time, woke up after the period's tick and skipped
        it), ``late_ms`` (real time: how late the generator's tick woke up).
    alarm_log : DataFrame
        The operator's view, one row per period and area whose report carries an
        alarm: ``t``, ``area``, ``sent`` (the command field ``pc`` it wrote),
        ``reported_received`` (that field as the generator reports it arrived),
        ``reported_applied``, ``binding`` (the filter's binding constraints),
        ``link``.
    frames : list of (float, str, bytes, int)
        Every frame on both legs of every area's relay: wall-clock time (s), leg
        (:attr:`lfc.wire.relay.Relay.log`), bytes, area.
    rejected : DataFrame
        Every command an outstation refused: ``time`` (wall clock, s, as ``frames``),
        ``area``, ``what`` (the write or the point operated) and ``reason`` (a partial
        or misplaced write, a value out of range or not finite, a point out of order).
    reconnects : DataFrame
        Every time the control centre lost its connection and made a new one: ``t``
        (the period's time, s), ``area``, ``seq`` (the period) and ``reason`` (what
        failed); the period's command is lost (the generator holds it and flags the
        link), the report is read on the new connection.
    settings : dict
    """

    sim: Result
    exchanges: pd.DataFrame
    alarm_log: pd.DataFrame
    frames: list
    rejected: pd.DataFrame
    reconnects: pd.DataFrame
    settings: dict

    @property
    def tripped(self) -> bool:
        return self.sim.tripped

    def forensics(self, area: int = 0) -> dict:
        """The operator's estimate of the attack on ``area`` from the alarm log
        (:func:`lfc.wire.forensics.estimate_attack`)."""
        from lfc.wire.forensics import estimate_attack
        return estimate_attack(self.alarm_log[self.alarm_log.area == area],
                               self.exchanges[self.exchanges.area == area].sent.to_numpy(),
                               self.settings["control_period"])

    def table(self) -> pd.DataFrame:
        """The outcome in one row: trips, alarms, largest |Δω| and ROCOF (over the
        areas), the exchanges' median and 99th-percentile round trips and the
        generator's 99th-percentile lateness (ms, real time)."""
        ex = self.exchanges
        areas, trips = self.sim.areas, self.sim.trips.sort_values("t")
        return pd.DataFrame([{
            "protocol": self.settings["protocol"], "agc": self.settings["agc"],
            "attack": self.settings["attack_name"],
            "filter": self.settings["filter"], "tripped": self.tripped,
            "first_trip": "" if trips.empty else
            f"{trips.relay.iat[0]} at {trips.t.iat[0]:.2f} s",
            "alarms": len(self.alarm_log), "link_lost": int(ex.link.sum()),
            "max |dw| (pu)": max(float(a.trace.dw_meas.abs().max()) for a in areas),
            "max |rocof| (pu/s)": max(float(a.trace.rocof_meas.abs().max()) for a in areas),
            "write median (ms)": float(ex.write_ms.median()),
            "read median (ms)": float(ex.read_ms.median()),
            "write p99 (ms)": float(ex.write_ms.quantile(0.99)),
            "late p99 (ms)": float(ex.late_ms.quantile(0.99))}])


def run_wire(params: LFCParams | MultiAreaParams, *, duration: float,
             attack: list | str | dict = "none", scc=None, protocol: str = "modbus",
             load=None, noise_std: tuple[float, float] = (0.0, 0.0), seed: int = 0,
             dt: float = 0.001, control_period: float = 0.01, relays=None,
             anti_windup: bool = False, agc: str = "generator", mode: str = "lockstep",
             feedforward: bool | None = None, capture: str | Path | None = None,
             impairment: Impairment | None = None,
             select_before_operate: bool = False, network: str = "loopback",
             sensors=None, following_load=None) -> WireResult:
    """Run one area, or every area of a grid, over the wire (module docstring).

    Parameters
    ----------
    params : LFCParams or MultiAreaParams
        The area, or the grid (plant and design model): one outstation, relay and
        control-centre connection per area.
    duration : float
        Simulated time (s).
    attack : list of dict, str or dict
        The man in the middle's operations, or a name of
        :data:`lfc.wire.attacks.ATTACKS` (``"fig4"``, ``"fig5"``, ...); for a grid
        ``{area: operations}`` (a list or a name alone attacks area 0).
    scc : SafetyFilter, None or dict
        The generator's filter; for a grid ``{area: "paper" | "certified" |
        filter}`` (:func:`lfc.linear_grid.area_filter`; the coupled
        certificate reads the whole grid and does not travel over one area's link).
    protocol : str
        ``"modbus"`` (Modbus/TCP) or ``"dnp3"``.
    load, noise_std, seed, dt, control_period, relays, anti_windup
        As in :func:`lfc.simulate` (``load``: ``{area: signal}`` for a grid;
        ``anti_windup``: the integrator, wherever it runs, does not integrate
        while the generator's filter holds against it).
    agc : str
        Where the integrator runs: ``"generator"`` (default, the paper's local
        controller; a grid's area AGC, on its metered tie-line export) or
        ``"centre"`` (one area only; module docstring).
    mode : str
        ``"lockstep"`` (default: the plant advances one control period per
        exchanged command) or ``"realtime"`` (the plant at the wall clock: the
        generator ticks every control period whatever has arrived, the centre
        reads and writes half a period before; a run takes ``duration`` s).
    feedforward : bool, optional
        Give each filter its area's true net disturbance (load plus tie-line
        export), as :func:`lfc.simulate` does by default for a grid (True) and not
        for one area (False): the default follows it.
    capture : str or Path, optional
        Write the run's traffic as the network carried it to this pcap
        (:class:`lfc.wire.sniff.Capture`: root or ``CAP_NET_RAW``, else a
        ``PermissionError``); the ports it needs to be decoded are in
        ``settings["ports"]``.
    impairment : Impairment, optional
        The network's delay, jitter and loss between the centre and the substation,
        made in the relay (:class:`lfc.wire.relay.Impairment`).  In lockstep it
        slows the run and changes nothing else; in real time a command that arrives
        after its tick is not waited for.
    select_before_operate : bool
        DNP3 only: every command is a SELECT and then an OPERATE of the same values,
        and the outstations refuse a DIRECT_OPERATE (:class:`lfc.wire.dnp3.Outstation`);
        the man in the middle rewrites (or drops and answers) both alike.
    network : str
        Where the parties sit (:mod:`lfc.wire.network`): ``"loopback"`` (default:
        each at its own address of this machine's loopback) or ``"namespaces"`` (the
        centre, the substation's relays and the generators in network namespaces of
        their own joined by veth links, made for the run and removed after it: root,
        else a ``PermissionError`` naming ``"loopback"``).
    sensors : Redundant or dict, optional
        Linear plants only: the generator's redundant frequency and ROCOF sensors,
        some of which may lie (:class:`lfc.sensors.Redundant`; for a grid ``{area:
        Redundant}``), as in :func:`lfc.simulate`: the generator side reads their
        median; ``sim``'s alarm log names each reading found a lie (the reports carry
        the filter's flags).  Not with ``noise_std``.
    following_load : FollowingLoad or dict, optional
        Linear plants only: a botnet's load that follows the area's frequency meter
        (:class:`lfc.load_attacks.FollowingLoad`; for a grid ``{area:
        FollowingLoad}``), added to ``load``, as :func:`lfc.simulate`'s
        ``following_load`` (``following_loads`` of a grid).

    Returns
    -------
    WireResult
    """
    try:
        kind = runner_of(params).name
    except ValueError:
        kind = None
    if kind not in ("area", "grid", "microgrid", "grid case"):
        raise ValueError(f"params must be an LFCParams (one area), a MultiAreaParams, a "
                         f"MicrogridCase or a GridCase, got {type(params).__name__}")
    testbed = {"microgrid": "microgrid", "grid case": "grid"}.get(kind)
    if protocol not in PROTOCOLS:
        raise ValueError(f"protocol must be one of {PROTOCOLS}, got {protocol!r}")
    if agc not in AGC:
        raise ValueError(f"agc must be one of {AGC}, got {agc!r}")
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if network not in NETWORKS:
        raise ValueError(f"network must be one of {NETWORKS}, got {network!r}")
    if capture is not None and not isinstance(capture, str | Path):
        raise ValueError(f"capture must be a path (str or Path) or None, got {capture!r}")
    if impairment is not None and not isinstance(impairment, Impairment):
        raise ValueError(f"impairment must be an lfc.wire.relay.Impairment or None, got "
                         f"{impairment!r}")
    check_seed("seed", seed)
    check_flag("select_before_operate", select_before_operate)
    if select_before_operate and protocol != "dnp3":
        raise ValueError(f"select_before_operate is DNP3's (SELECT, then OPERATE); "
                         f"protocol {protocol!r} has no such function: use protocol='dnp3'")
    if testbed is not None:
        for name, given in (("sensors", sensors), ("following_load", following_load)):
            if given is not None:
                raise ValueError(f"{name}: runs over the wire on the linear plants "
                                 f"(lfc.simulate takes it on an ANDES GridCase)")
        return _on_andes(params, testbed, duration=duration, attack=attack, scc=scc,
                         protocol=protocol, load=load, noise_std=noise_std, seed=seed,
                         control_period=control_period, relays=relays,
                         anti_windup=anti_windup, agc=agc, mode=mode, capture=capture,
                         impairment=impairment, select_before_operate=select_before_operate,
                         network=network)
    single = isinstance(params, LFCParams)
    grid = as_grid(params)
    n_a = grid.n_areas
    if not single and agc == "centre":
        raise ValueError("agc='centre' is for one area: a grid's AGC integrates its area's "
                         "tie-line export, metered at the generator side (agc='generator')")
    ratio = check_timing(duration, dt, control_period, n_a, grid.n_states)
    relays = relays_or_default(relays)
    period = ratio * dt
    attacks = attack if isinstance(attack, dict) else {0: attack}
    check_area_keys(attacks, n_a, "attack")
    policies = [WireAttack(attacks.get(a, [])) for a in range(n_a)]
    local = agc == "generator"
    if not local and any(op.get("field") == "wref" for op in policies[0].ops):
        raise ValueError("attack: with agc='centre' no reference is sent (the centre's AGC "
                         "integrates the frequency it is told): attack dw_meas instead "
                         "(lfc.wire.attacks.from_simulate(..., agc='centre'))")
    if single:
        filters = {0: scc}
        if scc is not None and not isinstance(scc, SafetyFilter):
            raise ValueError(f"scc must be a SafetyFilter or None, got {scc!r}")
        loads = {0: load}
    else:
        filters = {a: area_filter(grid, a, f, relays, period)
                   for a, f in check_area_keys(scc, n_a, "scc").items()}
        if any(isinstance(f, CoupledFilter) for f in filters.values()):
            raise ValueError("scc: the coupled certificate reads the whole grid's state, not "
                             "what one area's link carries; give per-area filters")
        loads = check_area_keys(load, n_a, "load")
    n_steps = int(round(duration / dt))
    n_ctrl = -(-n_steps // ratio)
    tc = np.arange(n_ctrl) * period
    checked = Scenario(sensors={0: sensors} if single else sensors, noise_std=noise_std,
                       seed=seed, following_loads={0: following_load} if single
                       else following_load)          # the threats beyond the command
    check_area_keys(checked.sensors, n_a, "sensors")
    check_area_keys(checked.following_loads, n_a, "following_load")
    told, logs = with_sensors(checked.sensors, {}, tc, seed)
    k_freq, k_tie = grid.agc_gains()
    feedforward = (not single) if feedforward is None else feedforward
    gens = [GeneratorSide(grid.areas[a], filters.get(a), None, noise_std,
                          seed if a == 0 else (seed, a), tc, None, None,
                          feedforward and filters.get(a) is not None, period,
                          k_agc=(k_freq[a], k_tie[a]) if local else (0.0, 0.0), network=True,
                          anti_windup=anti_windup and local, sensor_attacks=told.get(a))
            for a in range(n_a)]
    plant = LinearGrid(grid, loads, n_steps, ratio, dt, relays, checked.following_loads)

    link = Link(n_a, transport(protocol), policies, np.arange(n_ctrl) * ratio * dt, period,
                None if local else k_freq[0] * period, anti_windup, impairment,
                select_before_operate, network)

    def generate(j: int, lateness: float) -> None:
        """Every generator at control sample j: take the command, filter, then the
        grid holds every command for one period; relays watched, reports published."""
        seen = plant.measured(j)
        links = link.deliver(j, gens)
        u = np.array([gen.step(j, seen[a, :5], seen[a, 7], seen[a, 6])
                      for a, gen in enumerate(gens)])
        bits = plant.advance(j, u)
        for a, gen in enumerate(gens):   # what each measured at the sample
            link.publish(j, a, gen, seen[a, :5], links[a], bits[a], lateness)

    with _captured(link, capture):
        if mode == "lockstep":
            for j in range(n_ctrl):
                link.send(j)
                generate(j, 0.0)
                link.read(j)
        else:
            _realtime(n_ctrl, period, link.send, generate, link.read, link.skip)
    if not np.isfinite(plant.xs).all():
        raise ValueError("the plant became non-finite: an attack (a bias or a factor so large "
                         "that the plant overflows) or a load signal gives a non-finite value, "
                         "and no filter stood in the way; lfc.simulate refuses the same run")
    settings = {"params": repr(params), "relays": vars(relays), "duration": duration,
                "dt": dt, "control_period": control_period, "seed": seed,
                "noise_std": list(noise_std), "protocol": protocol,
                "attack": repr([pol.spec for pol in policies]),
                "attack_name": attack if isinstance(attack, str) else "custom",
                "filter": ",".join("none" if filters.get(a) is None else
                                   getattr(filters[a], "method", "?") for a in range(n_a)),
                "scc": repr(filters), "load": repr(loads), "anti_windup": anti_windup,
                "agc": agc, "mode": mode, "feedforward": feedforward,
                "capture": None if capture is None else str(capture), "ports": link.ports,
                "impairment": repr(impairment),
                "select_before_operate": select_before_operate, "network": network,
                **({"sensors": repr(sensors)} if sensors else {}),
                **({"following_load": repr(following_load)} if following_load else {})}
    sim = plant.result(single, tc, [gen.ctrl for gen in gens], filters,
                       settings).with_alarms(logs)
    return WireResult(sim, *link.outcome(n_ctrl), settings)


def _on_andes(case, kind: str, *, duration: float, attack, scc, protocol: str, load,
              noise_std, seed: int, control_period: float, relays, anti_windup: bool,
              agc: str, mode: str, capture, impairment,
              select_before_operate: bool, network: str) -> WireResult:
    """:func:`run_wire` on an ANDES case: the microgrid (one area) or a grid (one
    link per area), in lockstep, the integrator at the generators; the
    generator sides and their attacks are :func:`lfc.simulate`'s on the case."""
    if mode != "lockstep":
        raise ValueError("mode: ANDES runs in lockstep only (it keeps its own time, not the "
                         "wall clock's)")
    if agc != "generator":
        raise ValueError("agc: on ANDES the integrators run at the generators "
                         "(agc='generator')")
    from lfc.testbed.fit import design_model
    from lfc.testbed.fit import grid_design
    from lfc.testbed.grids import simulate_andes_grid
    from lfc.testbed.microgrid import simulate_microgrid
    n_a = 1 if kind == "microgrid" else case.n_areas
    attacks = attack if isinstance(attack, dict) else {0: attack}
    check_area_keys(attacks, n_a, "attack")
    policies = [WireAttack(attacks.get(a, [])) for a in range(n_a)]
    n_ctrl = int(np.ceil(duration / control_period - 1e-9))
    link = Link(n_a, transport(protocol), policies, np.arange(n_ctrl) * control_period,
                control_period, impairment=impairment,
                select_before_operate=select_before_operate, network=network)
    common = dict(duration=duration, relays=relays, noise_std=noise_std, seed=seed,
                  control_period=control_period, anti_windup=anti_windup, case=case,
                  network=link)
    design = design_model(case) if kind == "microgrid" else grid_design(case)  # fitted first:
    with _captured(link, capture):     # opened after the fit: the server closes idle links
        if kind == "microgrid":
            sim = simulate_microgrid(design, scc=scc, load=load, **common)
        else:
            sim = simulate_andes_grid(design, filters=scc, loads=load, **common)
    settings = {"plant": repr(case), "duration": duration, "control_period": control_period,
                "seed": seed, "noise_std": list(noise_std), "protocol": protocol,
                "attack": repr([pol.spec for pol in policies]),
                "attack_name": attack if isinstance(attack, str) else "custom",
                "filter": repr(scc), "load": repr(load), "anti_windup": anti_windup,
                "agc": agc, "mode": mode,
                "capture": None if capture is None else str(capture), "ports": link.ports,
                "impairment": repr(impairment),
                "select_before_operate": select_before_operate, "network": network}
    return WireResult(sim, *link.outcome(n_ctrl), settings)


@contextmanager
def _captured(link: Link, capture: str | Path | None):
    """``link`` opened on its network for the block and closed after it, its traffic
    captured into ``capture`` (a pcap) if given: the capture stops after the link has
    closed (its FINs in it), then is written, and the network is removed last,
    whatever the block raised."""
    with ExitStack() as stack:          # exits in reverse: close, stop, write, network
        stack.enter_context(link.network)
        if capture is not None:
            from lfc.wire.sniff import Capture
            sniffer = Capture(link.network)
            stack.callback(lambda: sniffer.write(capture, {p for pair in link.ports
                                                          for p in pair}))
            stack.enter_context(sniffer)
        stack.callback(link.close)
        link.open()
        yield


def _now() -> float:
    return time.perf_counter()


def _realtime(n_ctrl: int, period: float, send, generate, read, skip) -> None:
    """The two sides on the wall clock: the generator (a thread) at ``t0 + j
    period``, the control centre half a period before, reading the last report
    and then sending the next command; a side that wakes up late does its work
    late (the lateness is recorded), a command that has not arrived is not
    waited for (the generator holds).  A centre that wakes up after the tick its
    command was for skips that period (``skip(j)``: neither read nor sent) and
    catches up with the clock, rather than sending every later command late too."""
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
        if _now() > t0 + j * period:          # too late for tick j: catch up
            skip(j)
            continue
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
