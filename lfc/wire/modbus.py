"""Modbus/TCP on loopback: the generator outstation, the man in the middle and the
control centre's client (pymodbus 3.16), on real sockets (127.0.0.1, ports the
kernel chooses).

The outstation is a pymodbus server whose device calls back on every access:
a write of the command registers (function 16) lands in its inbox, a read of
the input registers (function 4) returns its latest report
(:mod:`lfc.wire.registers`).  The man in the middle is a TCP relay that cuts
the byte stream into Modbus/TCP frames (the MBAP header's length field), hands
every command write and every report read to a policy
(:class:`lfc.wire.attacks.WireAttack`) and forwards what it returns; a dropped
write is answered by the relay itself (a forged acknowledgement), so the
control centre sees nothing.  Every frame on both legs is logged with its
time for the capture (:mod:`lfc.wire.capture`).
"""

from __future__ import annotations

import asyncio
import struct
import threading
import time
from typing import Callable

from lfc.wire.registers import N_COMMAND, N_REPORT

WRITE, READ = 16, 4          # function codes: write multiple registers, read input registers


class EventLoop:
    """An asyncio event loop in a daemon thread, for the servers of one run."""

    def __init__(self) -> None:
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True,
                                       name="lfc-wire")
        self.thread.start()

    def run(self, coro, timeout: float = 10.0):
        """Run ``coro`` on the loop and wait for its result."""
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    def close(self) -> None:
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5.0)


class Outstation:
    """The generator's Modbus server: device 1, 13 holding and 20 input registers.

    ``inbox`` holds the last command's registers and the wall-clock time it
    arrived (``time.perf_counter``); :meth:`publish` sets the report the next
    read returns."""

    def __init__(self) -> None:
        self.inbox: tuple[list[int], float] | None = None
        self.report = [0] * N_REPORT
        self.lock = threading.Lock()
        self.server = None

    async def _action(self, function_code: int, start_address: int, address: int, count: int,
                      current_registers: list[int], set_values) -> None:
        if function_code == WRITE and set_values is not None:
            with self.lock:
                self.inbox = (list(set_values), time.perf_counter())
        elif function_code == READ:
            with self.lock:
                for i in range(count):
                    current_registers[address - start_address + i] = self.report[address + i]

    def publish(self, registers: list[int]) -> None:
        """The report the next read returns."""
        with self.lock:
            self.report = list(registers)

    def take(self) -> tuple[list[int], float] | None:
        """The command that arrived since the last call (None if none), emptied."""
        with self.lock:
            got, self.inbox = self.inbox, None
        return got

    async def start(self) -> int:
        """Listen on 127.0.0.1 (a port the kernel chooses); return the port."""
        from pymodbus.server import ModbusTcpServer
        from pymodbus.simulator import DataType, SimData, SimDevice

        def block(n):
            return [SimData(0, count=n, datatype=DataType.REGISTERS)]

        bits = [SimData(0, count=1, datatype=DataType.BITS)]
        device = SimDevice(id=1, simdata=(bits, bits, block(N_COMMAND), block(N_REPORT)),
                           action=self._action)
        self.server = ModbusTcpServer(device, address=("127.0.0.1", 0))
        await self.server.listen()
        return self.server.transport.sockets[0].getsockname()[1]

    async def stop(self) -> None:
        if self.server is not None:
            await self.server.shutdown()


def frames(buffer: bytearray) -> list[bytes]:
    """Cut whole Modbus/TCP frames (MBAP header: transaction, protocol, length,
    then unit and PDU) off the front of ``buffer``."""
    out = []
    while len(buffer) >= 7:
        length = struct.unpack(">H", buffer[4:6])[0]
        if len(buffer) < 6 + length:
            break
        out.append(bytes(buffer[:6 + length]))
        del buffer[:6 + length]
    return out


def write_values(frame: bytes) -> list[int] | None:
    """The registers a function-16 request at address 0 writes, else None."""
    if len(frame) < 13 or frame[7] != WRITE:
        return None
    address, count = struct.unpack(">HH", frame[8:12])
    return list(struct.unpack(f">{count}H", frame[13:13 + 2 * count])) if address == 0 else None


def with_write_values(frame: bytes, registers: list[int]) -> bytes:
    """``frame`` (a function-16 request) writing ``registers`` instead."""
    return frame[:13] + struct.pack(f">{len(registers)}H", *registers)


def write_ack(frame: bytes) -> bytes:
    """The server's answer to a function-16 request, as the relay forges it."""
    return frame[:4] + struct.pack(">H", 6) + frame[6:8] + frame[8:12]


def read_values(frame: bytes) -> list[int] | None:
    """The registers of a function-4 response, else None."""
    if len(frame) < 9 or frame[7] != READ:
        return None
    n = frame[8] // 2
    return list(struct.unpack(f">{n}H", frame[9:9 + 2 * n]))


def with_read_values(frame: bytes, registers: list[int]) -> bytes:
    return frame[:9] + struct.pack(f">{len(registers)}H", *registers)


class Relay:
    """The man in the middle: a TCP relay between the control centre and the
    outstation that parses Modbus/TCP frames.

    Parameters
    ----------
    upstream : int
        The outstation's port on 127.0.0.1.
    on_command : callable
        ``registers -> registers or None``: a command write's registers as
        forwarded (None: drop the frame and acknowledge it).
    on_report : callable
        ``registers -> registers``: a report read's registers as returned.

    Attributes
    ----------
    log : list of (float, str, bytes)
        Every frame: wall-clock time (s, ``time.perf_counter``), leg
        (``"centre>relay"``, ``"relay>centre"``, ``"relay>generator"``,
        ``"generator>relay"``) and the frame's bytes.
    """

    def __init__(self, upstream: int, on_command: Callable, on_report: Callable) -> None:
        self.upstream, self.on_command, self.on_report = upstream, on_command, on_report
        self.log: list[tuple[float, str, bytes]] = []
        self.server, self.tasks = None, set()

    async def start(self) -> int:
        self.server = await asyncio.start_server(self._serve, "127.0.0.1", 0)
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
        g_reader, g_writer = await asyncio.open_connection("127.0.0.1", self.upstream)
        try:
            await asyncio.gather(self._down(c_reader, c_writer, g_writer),
                                 self._up(g_reader, c_writer))
        except (ConnectionError, asyncio.IncompleteReadError):
            pass
        finally:
            for w in (c_writer, g_writer):
                w.close()

    async def _down(self, c_reader, c_writer, g_writer) -> None:
        """Centre to generator: commands (rewritten or dropped) and read requests."""
        buffer = bytearray()
        while data := await c_reader.read(65536):
            buffer.extend(data)
            for frame in frames(buffer):
                self._note("centre>relay", frame)
                values = write_values(frame)
                if values is not None:
                    values = self.on_command(values)
                    if values is None:
                        ack = write_ack(frame)
                        self._note("relay>centre", ack)
                        c_writer.write(ack)
                        await c_writer.drain()
                        continue
                    frame = with_write_values(frame, values)
                self._note("relay>generator", frame)
                g_writer.write(frame)
                await g_writer.drain()
        g_writer.close()          # the centre hung up: so does the relay, upstream

    async def _up(self, g_reader, c_writer) -> None:
        """Generator to centre: acknowledgements and reports (rewritten)."""
        buffer = bytearray()
        while data := await g_reader.read(65536):
            buffer.extend(data)
            for frame in frames(buffer):
                self._note("generator>relay", frame)
                values = read_values(frame)
                if values is not None:
                    frame = with_read_values(frame, self.on_report(values))
                self._note("relay>centre", frame)
                c_writer.write(frame)
                await c_writer.drain()


class Centre:
    """The control centre's Modbus client (a connection to ``port``)."""

    def __init__(self, port: int, timeout: float = 2.0) -> None:
        from pymodbus.client import ModbusTcpClient
        self.client = ModbusTcpClient("127.0.0.1", port=port, timeout=timeout, retries=0)
        if not self.client.connect():
            raise ConnectionError(f"the control centre could not connect to 127.0.0.1:{port}")

    def send(self, registers: list[int]) -> None:
        """Write one period's command (function 16 at 0)."""
        reply = self.client.write_registers(0, registers, device_id=1)
        if reply.isError():
            raise ConnectionError(f"the outstation refused the command: {reply}")

    def poll(self) -> list[int]:
        """Read the report (function 4 at 0)."""
        reply = self.client.read_input_registers(0, count=N_REPORT, device_id=1)
        if reply.isError():
            raise ConnectionError(f"the outstation refused the read: {reply}")
        return list(reply.registers)

    def close(self) -> None:
        self.client.close()
