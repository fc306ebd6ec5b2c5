"""What every protocol shares: the event loop the servers run on, the man in the
middle — a TCP relay that cuts the byte stream into the protocol's frames and lets a
policy rewrite the commands and reports it finds in them — and the network's delay,
jitter and loss it can add (:class:`Impairment`).

A protocol module (:mod:`lfc.wire.modbus`, :mod:`lfc.wire.dnp3`) provides a
``Codec`` with one signature:

* ``cut(buffer) -> list[bytes]``: whole frames off the front of a bytearray;
* ``command(frame) -> (values, seq) or None``: the command a frame carries;
* ``with_command(frame, values, seq) -> bytes``: the frame carrying another one;
* ``ack(frame, session) -> bytes``: the outstation's answer to a command, as the
  relay forges it when it drops the frame, made to match the session so far;
* ``upstream(frame, session) -> bytes``: a frame from the outstation as the centre
  then gets it (the session: a dict per connection the codec keeps what it needs in,
  e.g. DNP3's internal indications and transport sequence);
* ``downstream(frame, session) -> bytes or None``: a frame from the centre that is not a
  command as the outstation then gets it, or None to answer it (``ack``) instead — a
  DNP3 OPERATE made to match what the relay made of its SELECT, the period's command
  as forwarded (None: dropped), which the relay keeps in ``session["command"]``;
* ``report(frame) -> dict or None`` and ``with_report(frame, report) -> bytes``:
  the same for the report going back.

Every frame on both legs is logged with its wall-clock time, for the capture
(:mod:`lfc.wire.capture`).
"""

from __future__ import annotations

import asyncio
import random
import socket
import struct
import threading
import time
from dataclasses import dataclass
from contextlib import nullcontext
from typing import Callable

from lfc._validate import check_number, check_range, check_seed
from lfc.wire.network import LOOPBACK


#: what ``on_command`` returns to have the relay reset the connection (:class:`Relay`)
RESET = "reset"


class EventLoop:
    """An asyncio event loop in a daemon thread, for the servers of one run."""

    def __init__(self) -> None:
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True,
                                       name="lfc-wire")
        self.thread.start()

    def run(self, coro, timeout: float = 30.0):
        """Run ``coro`` on the loop and wait for its result."""
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    def close(self) -> None:
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5.0)


@dataclass(frozen=True)
class Impairment:
    """The wide-area network between the control centre and the substation, made in
    the relay as ``tc netem`` makes it in a kernel (this one has no ``sch_netem``):
    every frame the relay sends on, either way, leaves ``delay`` s after it arrived,
    plus a uniform draw in [-``jitter``, ``jitter``] s; with probability ``loss`` it
    is lost once, and TCP sends it again after its retransmission timeout ``rto`` s
    (Linux's least, 0.2 s).  TCP delivers in order, so a late frame holds back the
    ones behind it.  Draws are seeded (``seed``, the area, the direction).

    Parameters
    ----------
    delay, jitter : float
        s, ``0 <= jitter <= delay <= 10``.
    loss : float
        In [0, 1).
    rto : float
        s, in (0, 10].
    seed : int
    """

    delay: float = 0.0
    jitter: float = 0.0
    loss: float = 0.0
    rto: float = 0.2
    seed: int = 0

    def __post_init__(self) -> None:
        check_range("delay", self.delay, 0.0, 10.0, closed=True)
        check_range("jitter", self.jitter, 0.0, self.delay, closed=True)   # at most delay
        for name in ("loss", "rto"):
            check_number(name, getattr(self, name))
        if not 0.0 <= self.loss < 1.0:
            raise ValueError(f"loss must lie in [0, 1), got {self.loss!r}")
        if not 0.0 < self.rto <= 10.0:
            raise ValueError(f"rto must lie in (0, 10] s, got {self.rto!r}")
        check_seed("seed", self.seed)

    def __bool__(self) -> bool:
        return bool(self.delay or self.loss)


class _Impaired:
    """A writer behind an :class:`Impairment`: frames queued with their release time,
    written by a task of their own when it comes (``relay._note``d then)."""

    def __init__(self, writer, relay: Relay, leg: str, rng: random.Random) -> None:
        self.writer, self.relay, self.leg, self.rng = writer, relay, leg, rng
        self.queue: asyncio.Queue = asyncio.Queue()
        self.last = 0.0
        self.task = asyncio.create_task(self._pump())

    def put(self, frame: bytes) -> None:
        imp, now = self.relay.impairment, asyncio.get_running_loop().time()
        wait = imp.delay + (self.rng.uniform(-imp.jitter, imp.jitter) if imp.jitter else 0.0)
        if imp.loss and self.rng.random() < imp.loss:
            wait += imp.rto
        self.last = max(now + wait, self.last)
        self.queue.put_nowait((self.last, frame))

    async def _pump(self) -> None:
        loop = asyncio.get_running_loop()
        while (item := await self.queue.get()) is not None:
            release, frame = item
            await asyncio.sleep(max(0.0, release - loop.time()))
            self.relay._note(self.leg, frame)
            self.writer.write(frame)
            await self.writer.drain()

    async def close(self) -> None:
        """Send what is queued, then stop."""
        self.queue.put_nowait(None)
        await asyncio.gather(self.task, return_exceptions=True)


class Relay:
    """The man in the middle, between the control centre and the outstation.

    Parameters
    ----------
    upstream : int
        The outstation's port (on ``upstream_host``).
    codec : object
        The protocol's frame codec (module docstring).
    on_command : callable
        ``(values, seq) -> (values, seq), None or RESET``: a command as forwarded
        (None: drop the frame and answer it; ``RESET``: drop it and reset the
        connection, both legs, with a TCP RST).
    on_report : callable
        ``report -> report``: a report (dict of its fields) as returned.
    host, upstream_host : str
        The address the relay listens on, and the outstation's (default: 127.0.0.1
        both).
    upstream_from : str, optional
        The address the relay connects to the outstation from (default: ``host``).
    impairment : Impairment, optional
        The network's delay, jitter and loss on what the relay sends on.
    area : int
        The area whose link this is (the impairment's draws).
    inside : callable, optional
        ``() -> context manager``: the block in which the relay opens its connection
        to the outstation (its namespace: :meth:`lfc.wire.network.Namespaces.inside`);
        default: where it runs.

    Attributes
    ----------
    log : list of (float, str, bytes)
        Every frame: wall-clock time (s, ``time.perf_counter``), leg
        (``"centre>relay"``, ``"relay>centre"``, ``"relay>generator"``,
        ``"generator>relay"``) and the frame's bytes.
    """

    def __init__(self, upstream: int, codec, on_command: Callable,
                 on_report: Callable, host: str = LOOPBACK.centre,
                 upstream_host: str = LOOPBACK.centre, upstream_from: str | None = None,
                 impairment: Impairment | None = None, area: int = 0,
                 inside: Callable = nullcontext) -> None:
        self.upstream, self.codec = upstream, codec
        self.host, self.upstream_host = host, upstream_host
        self.upstream_from, self.inside = upstream_from or host, inside
        self.impairment, self.area = impairment or None, area
        self.on_command, self.on_report = on_command, on_report
        self.log: list[tuple[float, str, bytes]] = []
        self.server, self.tasks = None, set()

    async def start(self) -> int:
        """Listen on ``host`` (a port the kernel chooses); return the port."""
        self.server = await asyncio.start_server(self._serve, self.host, 0)
        return self.server.sockets[0].getsockname()[1]

    async def stop(self) -> None:
        if self.tasks:       # the centre has closed: each connection winds down
            await asyncio.wait(self.tasks, timeout=2.0)
        if self.server is not None:
            self.server.close()
            await self.server.wait_closed()

    def _note(self, leg: str, frame: bytes) -> None:
        self.log.append((time.perf_counter(), leg, frame))

    async def _serve(self, c_reader, c_writer) -> None:
        self.tasks.add(asyncio.current_task())
        with self.inside():      # the socket is its creator's namespace's
            sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setblocking(False)
        sock.bind((self.upstream_from, 0))
        await asyncio.get_running_loop().sock_connect(sock, (self.upstream_host, self.upstream))
        g_reader, g_writer = await asyncio.open_connection(sock=sock)
        session: dict = {}
        c_out, g_out = c_writer, g_writer
        if self.impairment:
            seed = self.impairment.seed
            c_out = _Impaired(c_writer, self, "relay>centre",
                              random.Random(f"{seed}:{self.area}:up"))
            g_out = _Impaired(g_writer, self, "relay>generator",
                              random.Random(f"{seed}:{self.area}:down"))
        try:
            await asyncio.gather(self._down(c_reader, c_out, g_out, session),
                                 self._up(g_reader, c_out, session))
        except (ConnectionError, asyncio.IncompleteReadError):
            pass
        finally:
            if self.impairment:
                await asyncio.gather(c_out.close(), g_out.close(), return_exceptions=True)
            for w in (c_writer, g_writer):
                w.close()

    async def _send(self, out, leg: str, frame: bytes) -> None:
        """Send ``frame`` on ``leg``: now, or through the impairment (noted as it leaves)."""
        if isinstance(out, _Impaired):
            out.put(frame)
            return
        self._note(leg, frame)
        out.write(frame)
        await out.drain()

    async def _down(self, c_reader, c_writer, g_writer, session: dict) -> None:
        """Centre to generator: commands (rewritten or dropped) and the rest."""
        buffer, codec = bytearray(), self.codec
        while data := await c_reader.read(65536):
            buffer.extend(data)
            for frame in codec.cut(buffer):
                self._note("centre>relay", frame)
                command = codec.command(frame)
                if command is not None:
                    forwarded = session["command"] = self.on_command(*command)
                    if forwarded is RESET:
                        _reset(c_writer, g_writer)
                        return
                    sent = None if forwarded is None else codec.with_command(frame, *forwarded)
                else:
                    sent = codec.downstream(frame, session)
                if sent is None:
                    await self._send(c_writer, "relay>centre", codec.ack(frame, session))
                    continue
                await self._send(g_writer, "relay>generator", sent)
        if isinstance(g_writer, _Impaired):    # the centre hung up: so does the relay,
            await g_writer.close()            # upstream, once what it holds has left
            g_writer = g_writer.writer
        g_writer.close()

    async def _up(self, g_reader, c_writer, session: dict) -> None:
        """Generator to centre: reports (rewritten) and the rest."""
        buffer, codec = bytearray(), self.codec
        while data := await g_reader.read(65536):
            buffer.extend(data)
            for frame in codec.cut(buffer):
                self._note("generator>relay", frame)
                frame = codec.upstream(frame, session)
                report = codec.report(frame)
                if report is not None:
                    frame = codec.with_report(frame, self.on_report(report))
                await self._send(c_writer, "relay>centre", frame)


def _reset(*writers) -> None:
    """Close each writer's connection with a TCP RST (``SO_LINGER`` 0), what is queued
    discarded (an :class:`_Impaired` writer's queue too)."""
    for w in writers:
        if isinstance(w, _Impaired):
            w.task.cancel()
            w = w.writer
        sock = w.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        w.transport.abort()
