"""Modbus/TCP on loopback: the generator outstation, the frame codec of the man in
the middle (:class:`lfc.wire.relay.Relay`) and the control centre's client
(pymodbus 3.16), on real sockets (127.0.0.1, ports the kernel chooses).

The outstation is a pymodbus server whose device calls back on every access:
a write of the command registers (function 16) lands in its inbox, a read of
the input registers (function 4) returns its latest report
(:mod:`lfc.wire.registers`).  The relay cuts the byte stream into Modbus/TCP
frames by the MBAP header's length field; a command is a function-16 write at
address 0, a report a function-4 response; a dropped write is answered with a
forged acknowledgement, so the control centre sees nothing.
"""

from __future__ import annotations

import asyncio
import struct
import threading
import time
from contextlib import nullcontext
from typing import Callable

from lfc._validate import check_positive
from lfc.wire.registers import (N_COMMAND, N_REPORT, command_registers, read_command,
                                read_report, report_registers, setpoint_problem)

NAME, PORT = "Modbus/TCP", 502        # the protocol's name and its well-known port (captures)

from lfc.wire.relay import EventLoop, Relay  # noqa: F401  (this protocol's transport)

WRITE, READ = 16, 4          # function codes: write multiple registers, read input registers


class Outstation:
    """The generator's Modbus server: device 1, 13 holding and 24 input registers
    (:mod:`lfc.wire.registers`).

    ``inbox`` holds the last command's registers and the wall-clock time it
    arrived (``time.perf_counter``); :meth:`take` returns it decoded;
    :meth:`publish` sets the report the next read returns.  A command is applied
    only whole: one write of the 13 holding registers at address 0 (function 16)
    whose values pass :func:`~lfc.wire.registers.setpoint_problem`.  Any other write
    is refused with Modbus exception 2 (illegal data address: a partial write, one
    elsewhere, a single-register write) or 3 (illegal data value) and logged in
    ``rejected`` (wall-clock time, what was written, reason), as is every exception
    pymodbus answers itself (a write past the registers' end, an unknown function);
    the command slot keeps what it held.  A connection that sends nothing for
    ``idle_timeout`` s (None: never) is closed, as a device frees its few sockets, and
    logged in ``rejected`` too; default 60 s, the setting suggested for Modbus polling
    (industrialmonitordirect.com, "Modbus/TCP server client disconnect detection").

    Raises
    ------
    ValueError
        ``idle_timeout`` neither None nor > 0 (s).
    """

    def __init__(self, idle_timeout: float | None = 60.0) -> None:
        if idle_timeout is not None:
            check_positive("idle_timeout", idle_timeout)
        self.idle_timeout = idle_timeout
        self._seen: dict[object, float] = {}     # connection -> last data (monotonic, s)
        self._watchdog = None
        self.inbox: tuple[list[int], float] | None = None
        self.report = [0] * N_REPORT
        self.lock = threading.Lock()
        self.server = None
        self.rejected: list[tuple[float, str, str]] = []
        self._request: tuple[int, int, int] = (0, 0, 0)
        self._refused = False             # the request under way was refused and logged

    def _log(self, what: str, reason: str) -> None:
        """One row of ``rejected``: now (wall clock), what was refused, why."""
        with self.lock:
            self.rejected.append((time.perf_counter(), what, reason))

    def _refuse(self, function_code: int, address: int, count: int, reason: str, code):
        self._log(f"function {function_code}: {count} register(s) at {address}", reason)
        self._refused = True
        return code

    def _trace(self, sending: bool, pdu):
        """pymodbus' view of every request and answer: an exception answered to a
        request :meth:`_action` did not refuse (one pymodbus refused itself, e.g. a
        write past the registers' end) is logged in ``rejected`` too."""
        if not sending:
            self._request = (pdu.function_code, getattr(pdu, "address", 0),
                             getattr(pdu, "count", 0))
            self._refused = False
        elif pdu.isError() and not self._refused:
            function_code, address, count = self._request
            self._refuse(function_code, address, count,
                         f"refused by pymodbus itself (exception {int(pdu.exception_code)}: "
                         f"outside the device's registers or functions)", None)
        return pdu

    async def _action(self, function_code: int, start_address: int, address: int, count: int,
                      current_registers: list[int], set_values):
        from pymodbus.constants import ExcCodes
        if set_values is not None:                       # a write, of any function
            if function_code != WRITE or address != 0 or count != N_COMMAND:
                return self._refuse(function_code, address, count,
                                    f"not the whole command (function {WRITE} of {N_COMMAND} "
                                    f"registers at 0)", ExcCodes.ILLEGAL_ADDRESS)
            command = read_command(list(set_values))
            problem = "malformed registers" if command is None else setpoint_problem(*command)
            if problem is not None:
                return self._refuse(function_code, address, count, problem,
                                    ExcCodes.ILLEGAL_VALUE)
            with self.lock:
                self.inbox = (list(set_values), time.perf_counter())
        elif function_code == READ:
            with self.lock:
                for i in range(count):
                    current_registers[address - start_address + i] = self.report[address + i]

    def publish(self, report: dict) -> None:
        """The report the next read returns (:func:`lfc.wire.registers.report_registers`'s
        fields)."""
        registers = report_registers(report["seq"], report, report["flags"], report["trips"],
                                     report["link"])
        with self.lock:
            self.report = registers

    def take(self) -> tuple[dict[str, float], int] | None:
        """The command that arrived since the last call, ``(values, seq)``, or None."""
        with self.lock:
            got, self.inbox = self.inbox, None
        return None if got is None else read_command(got[0])

    async def start(self, host: str = "127.0.0.1") -> int:
        """Listen on ``host`` (a port the kernel chooses); return the port."""
        from pymodbus.server import ModbusTcpServer
        from pymodbus.simulator import DataType, SimData, SimDevice

        def block(n):
            return [SimData(0, count=n, datatype=DataType.REGISTERS)]

        bits = [SimData(0, count=1, datatype=DataType.BITS)]
        device = SimDevice(id=1, simdata=(bits, bits, block(N_COMMAND), block(N_REPORT)),
                           action=self._action)
        self.server = ModbusTcpServer(device, address=(host, 0), trace_pdu=self._trace)
        if self.idle_timeout is not None:
            self.server.callback_new_connection = self._stamping(
                self.server.callback_new_connection)
            self._watchdog = asyncio.get_running_loop().create_task(self._close_idle())
        await self.server.listen()
        return self.server.transport.sockets[0].getsockname()[1]

    def _stamping(self, new_connection):
        """pymodbus' connection factory, each connection's data stamped with its time."""
        def made():
            handler = new_connection()
            receive = handler.callback_data

            def stamped(data: bytes, addr=None) -> int:
                self._seen[handler] = time.monotonic()
                return receive(data, addr)
            handler.callback_data = stamped
            self._seen[handler] = time.monotonic()
            return handler
        return made

    async def _close_idle(self) -> None:
        """Every quarter of ``idle_timeout``: close the connections idle for longer."""
        while True:
            await asyncio.sleep(self.idle_timeout / 4)
            now = time.monotonic()
            for handler, seen in list(self._seen.items()):
                if handler.transport is None:                 # gone by itself
                    del self._seen[handler]
                elif now - seen > self.idle_timeout:
                    del self._seen[handler]
                    peer = handler.transport.get_extra_info("peername")
                    self._log(f"connection from {peer}",
                              f"idle for more than {self.idle_timeout:g} s: closed")
                    handler.close()

    async def stop(self) -> None:
        if self._watchdog is not None:
            self._watchdog.cancel()
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
    """The registers a function-16 request at address 0 writes, else None (also
    for a frame shorter than its register count says)."""
    if len(frame) < 13 or frame[7] != WRITE:
        return None
    address, count = struct.unpack(">HH", frame[8:12])
    if len(frame) < 13 + 2 * count:
        return None
    return list(struct.unpack(f">{count}H", frame[13:13 + 2 * count])) if address == 0 else None


def with_write_values(frame: bytes, registers: list[int]) -> bytes:
    """``frame`` (a function-16 request) writing ``registers`` instead."""
    return frame[:13] + struct.pack(f">{len(registers)}H", *registers)


def write_ack(frame: bytes) -> bytes:
    """The server's answer to a function-16 request, as the relay forges it."""
    return frame[:4] + struct.pack(">H", 6) + frame[6:8] + frame[8:12]


def read_values(frame: bytes) -> list[int] | None:
    """The registers of a function-4 response, else None (also for a frame
    shorter than its byte count says)."""
    if len(frame) < 9 or frame[7] != READ:
        return None
    n = frame[8] // 2
    if len(frame) < 9 + 2 * n:
        return None
    return list(struct.unpack(f">{n}H", frame[9:9 + 2 * n]))


def with_read_values(frame: bytes, registers: list[int]) -> bytes:
    return frame[:9] + struct.pack(f">{len(registers)}H", *registers)


class Codec:
    """Modbus/TCP frames for :class:`lfc.wire.relay.Relay` (its docstring: one
    signature for every protocol)."""

    cut = staticmethod(frames)

    @staticmethod
    def ack(frame: bytes, session: dict) -> bytes:
        """The acknowledgement of a write (its transaction id echoed, as a server's)."""
        return write_ack(frame)

    @staticmethod
    def upstream(frame: bytes, session: dict) -> bytes:
        return frame

    @staticmethod
    def downstream(frame: bytes, session: dict) -> bytes:
        return frame

    @staticmethod
    def command(frame: bytes) -> tuple[dict[str, float], int] | None:
        values = write_values(frame)
        return None if values is None else read_command(values)

    @staticmethod
    def with_command(frame: bytes, values: dict[str, float], seq: int) -> bytes:
        return with_write_values(frame, command_registers(values, seq))

    @staticmethod
    def report(frame: bytes) -> dict | None:
        values = read_values(frame)
        return None if values is None else read_report(values)

    @staticmethod
    def with_report(frame: bytes, report: dict) -> bytes:
        return with_read_values(frame, report_registers(report["seq"], report, report["flags"],
                                                        report["trips"], report["link"]))


class Centre:
    """The control centre's Modbus client (a connection to ``host:port``; ``loop`` is
    not used: the client is synchronous).  A command the outstation refuses (an
    exception response: what reached it was not what was sent) is kept in
    ``refused`` (its period's ``seq`` and the exception), and the run goes on: the
    generator holds its last command, as a real master's would.  A connection that
    fails (reset, closed) is made again, as a real master's is: the period's command
    is lost, the report read on the new connection; each is kept in ``reconnects``
    (the period's ``seq`` and what failed).  ``inside``: ``() -> context manager``, the
    block it connects again in (its namespace, :mod:`lfc.wire.network`)."""

    def __init__(self, port: int, loop: EventLoop | None = None, timeout: float = 10.0,
                 host: str = "127.0.0.1", inside: Callable = nullcontext) -> None:
        from pymodbus.client import ModbusTcpClient
        self.client = ModbusTcpClient(host, port=port, timeout=timeout, retries=0)
        self.where, self.inside = f"{host}:{port}", inside
        self._connect()
        self.refused: list[tuple[int, str]] = []
        self.reconnects: list[tuple[int, str]] = []
        self.seq = 0

    def _connect(self) -> None:
        if not self.client.connect():
            raise ConnectionError(f"the control centre could not connect to {self.where}")

    def _call(self, request):
        """``request()``, or None after the connection failed and was made again."""
        from pymodbus.exceptions import ModbusException
        try:
            return request()
        except (ModbusException, OSError) as err:
            self.reconnects.append((self.seq, f"{type(err).__name__}: {err}"[:200]))
            self.client.close()
            with self.inside():
                self._connect()
            return None

    def send(self, values: dict[str, float], seq: int) -> None:
        """Write one period's command (function 16 at 0)."""
        self.seq = seq
        reply = self._call(lambda: self.client.write_registers(
            0, command_registers(values, seq), device_id=1))
        if reply is not None and reply.isError():
            self.refused.append((seq, str(reply)))

    def poll(self) -> dict:
        """Read the report (function 4 at 0; again on a new connection if it failed)."""
        def read():
            return self.client.read_input_registers(0, count=N_REPORT, device_id=1)
        reply = self._call(read) or read()
        if reply.isError():
            raise ConnectionError(f"the outstation refused the read: {reply}")
        report = read_report(list(reply.registers))
        if report is None:
            raise ConnectionError(f"the report read is malformed: {reply.registers!r:.80}")
        return report

    def close(self) -> None:
        self.client.close()
