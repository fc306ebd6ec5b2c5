"""What every protocol shares: the event loop the servers run on, and the man in
the middle — a TCP relay that cuts the byte stream into the protocol's frames
and lets a policy rewrite the commands and reports it finds in them.

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
* ``report(frame) -> dict or None`` and ``with_report(frame, report) -> bytes``:
  the same for the report going back.

Every frame on both legs is logged with its wall-clock time, for the capture
(:mod:`lfc.wire.capture`).
"""

from __future__ import annotations

import asyncio
import threading
import time
from typing import Callable


#: where each party listens or connects from on loopback (all of 127.0.0.0/8 is this
#: machine's): the control centre, then each area's relay and generator, so that a
#: capture of the loopback interface tells the parties and areas apart by address
CENTRE = "127.0.0.1"


def relay_address(area: int) -> str:
    """The address area ``area``'s relay listens on and connects upstream from."""
    return f"127.0.1.{area + 1}"


def generator_address(area: int) -> str:
    """The address area ``area``'s outstation listens on."""
    return f"127.0.2.{area + 1}"


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


class Relay:
    """The man in the middle, between the control centre and the outstation.

    Parameters
    ----------
    upstream : int
        The outstation's port on 127.0.0.1.
    codec : object
        The protocol's frame codec (module docstring).
    on_command : callable
        ``(values, seq) -> (values, seq) or None``: a command as forwarded
        (None: drop the frame and answer it).
    on_report : callable
        ``report -> report``: a report (dict of its fields) as returned.
    host, upstream_host : str
        The address the relay listens on and connects upstream from, and the
        outstation's (default: 127.0.0.1 both).

    Attributes
    ----------
    log : list of (float, str, bytes)
        Every frame: wall-clock time (s, ``time.perf_counter``), leg
        (``"centre>relay"``, ``"relay>centre"``, ``"relay>generator"``,
        ``"generator>relay"``) and the frame's bytes.
    """

    def __init__(self, upstream: int, codec, on_command: Callable,
                 on_report: Callable, host: str = CENTRE, upstream_host: str = CENTRE) -> None:
        self.upstream, self.codec = upstream, codec
        self.host, self.upstream_host = host, upstream_host
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
        g_reader, g_writer = await asyncio.open_connection(self.upstream_host, self.upstream,
                                                           local_addr=(self.host, 0))
        session: dict = {}
        try:
            await asyncio.gather(self._down(c_reader, c_writer, g_writer, session),
                                 self._up(g_reader, c_writer, session))
        except (ConnectionError, asyncio.IncompleteReadError):
            pass
        finally:
            for w in (c_writer, g_writer):
                w.close()

    async def _down(self, c_reader, c_writer, g_writer, session: dict) -> None:
        """Centre to generator: commands (rewritten or dropped) and the rest."""
        buffer, codec = bytearray(), self.codec
        while data := await c_reader.read(65536):
            buffer.extend(data)
            for frame in codec.cut(buffer):
                self._note("centre>relay", frame)
                command = codec.command(frame)
                if command is not None:
                    forwarded = self.on_command(*command)
                    if forwarded is None:
                        ack = codec.ack(frame, session)
                        self._note("relay>centre", ack)
                        c_writer.write(ack)
                        await c_writer.drain()
                        continue
                    frame = codec.with_command(frame, *forwarded)
                self._note("relay>generator", frame)
                g_writer.write(frame)
                await g_writer.drain()
        g_writer.close()          # the centre hung up: so does the relay, upstream

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
                self._note("relay>centre", frame)
                c_writer.write(frame)
                await c_writer.drain()
