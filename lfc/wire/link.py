"""The network of one run: for every area an outstation, a man in the middle and
the control centre's connection, over one protocol, and what the centre does
with them each control period.

A plant drives it (:func:`lfc.wire.run.run_wire` for the linear model,
:class:`lfc.testbed.AndesLoop` for ANDES): at every control sample it calls
:meth:`Link.send` (the centre writes each area's command through its relay),
:meth:`Link.deliver` (each generator side receives what arrived), steps the
generator sides, :meth:`Link.publish` (each outstation's report) and
:meth:`Link.read` (the centre polls the reports, runs its AGC where it has one,
and logs the alarms).
"""

from __future__ import annotations

import math
import time

import numpy as np
import pandas as pd

from lfc.engine import CTRL_COLUMNS, agc_step
from lfc.filters.base import ACTIVE, ALARM_BITS, binding_names
from lfc.wire.network import NETWORKS, Loopback, Namespaces
from lfc.wire.relay import RESET, Impairment

U_COL, FLAG_COL = CTRL_COLUMNS.index("u_ref"), CTRL_COLUMNS.index("flags")


def _now() -> float:
    return time.perf_counter()


class Link:
    """The network between a control centre and ``n_areas`` generator sides.

    Parameters
    ----------
    n_areas : int
    transport : module
        The protocol's module (:mod:`lfc.wire.modbus`, :mod:`lfc.wire.dnp3`).
    policies : list of WireAttack
        The man in the middle's policy on each area's link.
    times : ndarray
        Each control sample's time as the engine computes it (s).
    period : float
        The control period (s).
    agc_gain : float or None
        The control centre's AGC gain times the period (``agc="centre"``, one
        area), or None: the integrators run at the generators.
    anti_windup : bool
        The centre's AGC does not integrate while the filter holds against it.
    impairment : Impairment, optional
        The network's delay, jitter and loss (:class:`lfc.wire.relay.Impairment`).
    select_before_operate : bool
        DNP3: the centre selects, then operates; the outstations take nothing else.
    network : str
        Where the parties sit (:mod:`lfc.wire.network`): ``"loopback"`` (default) or
        ``"namespaces"``; ``network`` holds it, entered by whoever opens the link
        before :meth:`open` and left after :meth:`close`.
    """

    def __init__(self, n_areas: int, transport, policies: list, times: np.ndarray,
                 period: float, agc_gain: float | None = None,
                 anti_windup: bool = False, impairment: Impairment | None = None,
                 select_before_operate: bool = False, network: str = "loopback") -> None:
        if network not in NETWORKS:
            raise ValueError(f"network must be one of {NETWORKS}, got {network!r}")
        self.network = Loopback() if network == "loopback" else Namespaces(n_areas)
        self.n_areas, self.transport, self.policies = n_areas, transport, policies
        self.device = {"select_before_operate": True} if select_before_operate else {}
        self.times, self.period = times, period
        self.agc_gain, self.anti_windup = agc_gain, anti_windup
        self.impairment = impairment
        self.g = np.zeros(1)        # the centre's AGC integrator (pu)
        self.clocks = [-1] * n_areas
        self.last = [{"pc": 0.0, "wref": 0.0, "ace": 0.0} for _ in range(n_areas)]
        self.side: dict = {}
        self.centre_rows: dict = {}
        self.log: list = []
        self.loop = self.stations = self.relays = self.centres = None
        self.ports: list[tuple[int, int]] = []

    def _hooks(self, a: int):
        def on_command(values, seq):
            self.clocks[a] += 1
            j = self.clocks[a]
            out = self.policies[a].command(j, self.times[min(j, len(self.times) - 1)],
                                           self.period, values)
            return out if out is None or out is RESET else (out, seq)

        def on_report(report):
            j = max(self.clocks[a], 0)   # before the first command (DNP3's startup poll): 0
            return {**report, **self.policies[a].report(j, self.times[min(j, len(self.times) - 1)],
                                                        self.period, report)}
        return on_command, on_report

    def open(self) -> None:
        """Start every outstation, relay and connection (each party at its own address
        of ``network``'s plan, :mod:`lfc.wire.network`; kernel-chosen ports, kept in
        ``ports`` as ``(relay's, outstation's)`` per area)."""
        tr, net, plan = self.transport, self.network, self.network.plan
        self.loop = tr.EventLoop()
        self.stations, self.relays, self.centres = [], [], []
        for a in range(self.n_areas):
            station = tr.Outstation(**self.device)
            with net.inside("generators", self.loop):
                port = self.loop.run(station.start(plan.generator(a)))
            relay = tr.Relay(port, tr.Codec, *self._hooks(a), host=plan.relay(a),
                             upstream_host=plan.generator(a),
                             upstream_from=plan.relay_upstream(a),
                             impairment=self.impairment, area=a,
                             inside=lambda: net.inside("substation"))
            self.stations.append(station)
            self.relays.append(relay)
            with net.inside("substation", self.loop):
                self.ports.append((self.loop.run(relay.start()), port))
            with net.inside("centre", self.loop):
                self.centres.append(tr.Centre(self.ports[-1][0], self.loop,
                                              host=plan.relay(a), **self.device,
                                              inside=lambda: net.inside("centre", self.loop)))

    def close(self) -> None:
        """Hang up, stop the relays and outstations, stop the event loop."""
        if self.loop is None:
            return
        try:
            for centre in self.centres:
                centre.close()
            for relay, station in zip(self.relays, self.stations):
                self.loop.run(relay.stop())
                self.loop.run(station.stop())
        finally:
            self.loop.close()

    def send(self, j: int) -> None:
        """The centre writes period ``j``'s command to every area."""
        for a, centre in enumerate(self.centres):
            sent = self.g[0] if self.agc_gain is not None else 0.0
            t0 = _now()
            centre.send({"pc": sent, "wref": 0.0, "ace": 0.0}, j)
            self.centre_rows[j, a] = [sent, 1e3 * (_now() - t0), math.nan]

    def skip(self, j: int) -> None:
        """The centre, late for period ``j``'s tick, neither sends nor reads for it
        (real time): its row has no round trips."""
        for a in range(len(self.centres)):
            sent = self.g[0] if self.agc_gain is not None else 0.0
            self.centre_rows[j, a] = [sent, math.nan, math.nan]

    def deliver(self, j: int, gens: list) -> list[int]:
        """Each generator side receives what arrived for period ``j`` (the last
        command again if none did); returns each area's link flag (1: none)."""
        links = []
        for a, gen in enumerate(gens):
            got = self.stations[a].take()
            link = 1
            if got is not None and got[1] == j % 65536:
                self.last[a], link = got[0], 0
            last = self.last[a]
            gen.receive(j, last["pc"], last["wref"], last["ace"])
            links.append(link)
        return links

    def publish(self, j: int, a: int, gen, x: np.ndarray, link: int, trips: int,
                lateness: float = 0.0) -> None:
        """Area ``a``'s report of period ``j``: the measurement the generator side
        made at the sample (state ``x`` there, design-model coordinates, plus its
        noise), what it received and applied, its flags, the relays ``trips``
        (bits) and the link flag; ``lateness`` (s) how late its tick woke up."""
        u = float(gen.ctrl[j, CTRL_COLUMNS.index("u")])
        self.stations[a].publish({
            "seq": j % 65536, "dw_meas": x[3] + gen.noise[j, 0],
            "rocof_meas": x[4] + gen.noise[j, 1], "pc_received": self.last[a]["pc"],
            "u_ref": float(gen.ctrl[j, U_COL]), "u": u, "flags": int(gen.ctrl[j, FLAG_COL]),
            "trips": int(trips), "link": link})
        self.side[j, a] = (self.last[a]["pc"], u, link, 1e3 * lateness)

    def read(self, j: int) -> None:
        """The centre polls every report of period ``j``, integrates (its AGC, if
        it has one) and logs the alarms."""
        for a, centre in enumerate(self.centres):
            t0 = _now()
            rep = centre.poll()
            self.centre_rows[j, a][2] = 1e3 * (_now() - t0)
            if self.agc_gain is not None:
                agc_step(self.g, self.agc_gain, 0.0, rep["dw_meas"], 0.0, 0.0,
                         self.anti_windup, rep["u_ref"], rep["u"])
            if rep["flags"] & ALARM_BITS or rep["link"]:
                self.log.append((self.times[j], a, self.centre_rows[j, a][0],
                                 rep["pc_received"], rep["u"],
                                 ";".join(binding_names(rep["flags"]))
                                 if rep["flags"] & ACTIVE else "", rep["link"]))

    def outcome(self, n_ctrl: int) -> tuple[pd.DataFrame, pd.DataFrame, list, pd.DataFrame,
                                            pd.DataFrame]:
        """``(exchanges, alarm_log, frames, rejected, reconnects)`` of
        :class:`lfc.wire.run.WireResult`."""
        rows = [(self.times[j], a, self.centre_rows[j, a][0], *self.side[j, a][:3],
                 self.centre_rows[j, a][1], self.centre_rows[j, a][2], self.side[j, a][3])
                for j in range(n_ctrl) for a in range(self.n_areas)
                if (j, a) in self.side and (j, a) in self.centre_rows]
        exchanges = pd.DataFrame(rows, columns=["t", "area", "sent", "received", "applied",
                                                "link", "write_ms", "read_ms", "late_ms"])
        alarm_log = pd.DataFrame(self.log, columns=["t", "area", "sent", "reported_received",
                                                    "reported_applied", "binding", "link"])
        frames = sorted((f + (a,) for a, relay in enumerate(self.relays or [])
                         for f in relay.log), key=lambda f: f[0])
        rejected = pd.DataFrame(sorted((t, a, what, why) for a, station
                                       in enumerate(self.stations or [])
                                       for t, what, why in station.rejected),
                                columns=["time", "area", "what", "reason"])
        reconnects = pd.DataFrame(sorted((self.times[min(seq, len(self.times) - 1)], a, seq,
                                          why) for a, centre in enumerate(self.centres or [])
                                         for seq, why in centre.reconnects),
                                  columns=["t", "area", "seq", "reason"])
        return exchanges, alarm_log, frames, rejected, reconnects
