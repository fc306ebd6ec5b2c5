"""DNP3 (IEEE 1815) on loopback: the generator outstation, the frame codec of the
man in the middle (:class:`lfc.wire.relay.Relay`) and the control centre's master
(``dnp3py`` 0.6, pure Python), on real sockets (127.0.0.1, ports the kernel
chooses).

The point list:

========================  =====  ======================  ================================
object                    index  field                   encoding
========================  =====  ======================  ================================
analog output (g41v4)     0      ``pc`` (pu)             binary64: bit for bit
direct operate            1      ``wref`` (pu)           binary64
                          2      ``ace`` (pu)            binary64
                          3      ``seq``                 binary64 of the period's index
analog input (g30v1,      0      ``dw_meas``             int32 counts of 3e-11 pu (±0.064)
static, read by a         1      ``rocof_meas``          counts of 1e-9 pu/s (±2.1)
range poll of 0-8)        2      ``pc_received``         counts of 1e-8 pu (±21)
                          3      ``u_ref``               counts of 1e-8 pu (±21)
                          4      ``u``                   counts of 1e-8 pu (±21)
                          5-8    ``flags``, ``trips``,   counts of 1
                                 ``link``, ``seq``
========================  =====  ======================  ================================

The commands travel as double-precision analog outputs, exactly; the reports as
the 32-bit integers a DNP3 outstation serves for static analog inputs (dnp3py
serves g30v1 only), scaled as above.  With the AGC at the generator (the paper's
local controller, ``agc="generator"``) the reports carry no physics and a run over
DNP3 equals the simulation bit for bit, as over Modbus; with the AGC at the
control centre the frequency it integrates is rounded to 1.5e-11 pu, and a run
equals the simulation to 8e-10 pu on Figs. 4 and 5 and 9e-9 pu on a red-team
square wave that trips (measured, ``tests/test_wire.py``), as long as the
frequency it is told stays within the point's range.  The frequency's range,
±0.064 pu (±3.8 Hz), holds both relay settings (OF2 +0.03, UF2 −0.058 pu); a
value beyond a point's range saturates at it.

The relay cuts the byte stream into DNP3 link frames (``05 64``, the length
byte, a CRC after the header and after every 16 bytes of data); a command is a
DIRECT_OPERATE request of g41v4, a report a RESPONSE carrying g30v1; a rewritten
frame gets new CRCs; a dropped command is answered with a forged RESPONSE
echoing it with status SUCCESS, carrying the session's internal indications and
next transport sequence number (the outstation's later frames renumbered after it).

The outstation answers only the control centre's link address and frames whose
direction bit says they come from a master, applies a command
whole or not at all and refuses a setpoint out of range with the protocol's status
codes (:class:`Outstation`); it serves each TCP connection on its own.
"""

from __future__ import annotations

import asyncio
import math
import struct
import threading
import time
from contextlib import nullcontext
from typing import Callable

from lfc._validate import check_flag, check_positive
from lfc.wire.registers import seq_problem, value_problem
from lfc.wire.relay import EventLoop, Relay  # noqa: F401  (this protocol's transport)

NAME, PORT = "DNP3", 20000
OUTSTATION, MASTER = 1, 2           # link addresses: the generator's and the control centre's
COMMAND_POINTS = ("pc", "wref", "ace", "seq")
REPORT_POINTS = (("dw_meas", 3e-11), ("rocof_meas", 1e-9), ("pc_received", 1e-8), ("u_ref", 1e-8),
                 ("u", 1e-8),
                 ("flags", 1.0), ("trips", 1.0), ("link", 1.0), ("seq", 1.0))
SELECT, OPERATE, DIRECT_OPERATE, RESPONSE = 3, 4, 5, 0x81
NO_SELECT = 2                       # a control status (IEEE 1815 table 11-9)
INT32 = 2 ** 31 - 1


def counts(report: dict) -> list[int]:
    """The report's fields as the int32 counts of the point list (saturated)."""
    return [max(-INT32, min(INT32, int(round(report[name] / scale))))
            for name, scale in REPORT_POINTS]


def from_counts(values: list[float]) -> dict:
    """The report of :func:`counts`'s counts."""
    out = {name: float(v) * scale for (name, scale), v in zip(REPORT_POINTS, values)}
    for name in ("flags", "trips", "link", "seq"):
        out[name] = int(out[name])
    return out


def _ao_block(values: dict[str, float], seq: int) -> bytes:
    """The g41v4 object block of a command (qualifier 0x17: 1-byte count and indices)."""
    data = bytes([41, 4, 0x17, 4])
    for i, name in enumerate(COMMAND_POINTS):
        data += bytes([i]) + struct.pack("<d", float(seq if name == "seq" else values[name])) \
            + b"\x00"
    return data


def _user_data(frame: bytes) -> bytes:
    from dnp3.datalink.frame import DataLinkFrame
    return DataLinkFrame.from_bytes(frame).user_data


def _with_user_data(frame: bytes, user_data: bytes) -> bytes:
    from dnp3.datalink.frame import DataLinkFrame
    old = DataLinkFrame.from_bytes(frame)
    return DataLinkFrame(header=old.header, user_data=user_data).to_bytes()


class Codec:
    """DNP3 link frames for :class:`lfc.wire.relay.Relay` (its docstring)."""

    @staticmethod
    def cut(buffer: bytearray) -> list[bytes]:
        out = []
        while len(buffer) >= 10:
            if buffer[0] != 0x05 or buffer[1] != 0x64:
                raise ValueError("not a DNP3 link frame (start bytes 05 64 expected)")
            n = buffer[2] - 5                                   # user data bytes
            size = 10 + n + 2 * math.ceil(n / 16)
            if len(buffer) < size:
                break
            out.append(bytes(buffer[:size]))
            del buffer[:size]
        return out

    @staticmethod
    def command(frame: bytes) -> tuple[dict[str, float], int] | None:
        """The command of a DIRECT_OPERATE or a SELECT (the first half of a select
        before operate: its OPERATE is :meth:`downstream`'s)."""
        return Codec._block(frame, (DIRECT_OPERATE, SELECT))

    @staticmethod
    def _block(frame: bytes, functions: tuple[int, ...]) -> tuple[dict[str, float], int] | None:
        data = _user_data(frame)
        # transport byte, application control, function, then g41v4 with 4 points
        if len(data) < 7 or data[2] not in functions or tuple(data[3:6]) != (41, 4, 0x17):
            return None
        if len(data) < 7 + 10 * data[6]:                # cut short: not a command
            return None
        values = {}
        for k in range(data[6]):
            o = 7 + 10 * k
            if data[o] >= len(COMMAND_POINTS):
                return None
            values[COMMAND_POINTS[data[o]]] = struct.unpack("<d", data[o + 1:o + 9])[0]
        if set(values) != set(COMMAND_POINTS) or not math.isfinite(values["seq"]):
            return None                                   # a point missing: not a command
        seq = int(values.pop("seq"))
        return values, seq

    @staticmethod
    def with_command(frame: bytes, values: dict[str, float], seq: int) -> bytes:
        data = _user_data(frame)
        return _with_user_data(frame, data[:3] + _ao_block(values, seq))

    @staticmethod
    def downstream(frame: bytes, session: dict) -> bytes | None:
        """A frame of the centre's that is not a command as the outstation then gets it:
        an OPERATE carries what the man in the middle made of its SELECT
        (``session["command"]``), so that the two match; None (answer it, do not
        forward) when the SELECT was dropped."""
        if Codec._block(frame, (OPERATE,)) is None or "command" not in session:
            return frame
        command = session["command"]
        return None if command is None else Codec.with_command(frame, *command)

    @staticmethod
    def ack(frame: bytes, session: dict) -> bytes:
        """The outstation's RESPONSE echoing a dropped DIRECT_OPERATE, SELECT or OPERATE
        with status SUCCESS, as the session's own would be: its internal indications (the last
        response's) and the next transport sequence number; the outstation's later
        frames are renumbered after it (:meth:`upstream`)."""
        from dnp3.datalink.builder import build_unconfirmed_user_data
        from dnp3.datalink.frame import DataLinkFrame
        request = DataLinkFrame.from_bytes(frame)
        data = request.user_data
        iin = session.get("iin", b"\x00\x00")
        sequence = (session.get("sequence", -1) + 1) % 64
        session["sequence"] = sequence
        session["shift"] = session.get("shift", 0) + 1
        app = bytes([0xC0 | (data[1] & 0x0F), RESPONSE]) + iin + data[3:]
        reply = build_unconfirmed_user_data(destination=request.header.source,
                                            source=request.header.destination,
                                            dir_from_master=False,
                                            user_data=bytes([0xC0 | sequence]) + app)
        return reply.to_bytes()

    @staticmethod
    def upstream(frame: bytes, session: dict) -> bytes:
        """A frame of the outstation's: its internal indications kept for forged
        answers, its transport sequence shifted by the answers forged so far (the
        centre sees one sequence, as from one device)."""
        data = _user_data(frame)
        if not data:
            return frame
        if len(data) >= 5 and data[2] == RESPONSE:
            session["iin"] = bytes(data[3:5])
        shift = session.get("shift", 0)
        sequence = ((data[0] & 0x3F) + shift) % 64
        session["sequence"] = sequence
        if not shift:
            return frame
        return _with_user_data(frame, bytes([(data[0] & 0xC0) | sequence]) + data[1:])

    @staticmethod
    def _g30(data: bytes) -> int | None:
        """Offset of the g30v1 block's first point in a response's user data."""
        if len(data) < 8 or data[2] != RESPONSE or tuple(data[5:7]) != (30, 1):
            return None
        return 10 if data[7] == 0x00 else None        # qualifier 0x00: 1-byte start, stop

    @staticmethod
    def report(frame: bytes) -> dict | None:
        data = _user_data(frame)
        o = Codec._g30(data)
        if o is None:
            return None
        n = data[9] - data[8] + 1
        if n != len(REPORT_POINTS) or len(data) < o + 5 * n:
            return None
        return from_counts([struct.unpack("<i", data[o + 5 * k + 1:o + 5 * k + 5])[0]
                            for k in range(n)])

    @staticmethod
    def with_report(frame: bytes, report: dict) -> bytes:
        data = bytearray(_user_data(frame))
        o = Codec._g30(bytes(data))
        for k, c in enumerate(counts(report)):
            data[o + 5 * k + 1:o + 5 * k + 5] = struct.pack("<i", c)
        return _with_user_data(frame, bytes(data))


def _statuses(response) -> list[tuple[int, int]]:
    """``(index, status)`` of each analog output a control response echoes."""
    out = []
    for block in getattr(response, "objects", ()):
        if (block.header.group, block.header.variation) == (41, 4) and block.data:
            out += [(block.data[1 + 10 * k], block.data[10 + 10 * k])
                    for k in range(block.data[0]) if len(block.data) >= 11 + 10 * k]
    return out


class Outstation:
    """The generator's DNP3 outstation (address 1): the point list above.

    With ``select_before_operate`` it takes a command only as a SELECT of the four
    outputs followed, within ``select_timeout`` s, by an OPERATE of the same values
    (IEEE 1815 4.4.3; dnp3py matches them, answering NO_SELECT otherwise) and refuses a
    DIRECT_OPERATE with NOT_SUPPORTED; without it (default) it takes both.  The checks
    below apply to the SELECT and again to the OPERATE; an OPERATE that matches no
    SELECT is logged in ``rejected`` too.

    It answers only the control centre's address (2): a request from another source
    is logged and left unanswered.  A command is applied whole or not at all: one DIRECT_OPERATE
    request holding the four analog outputs, in order, whose values pass
    :func:`~lfc.wire.registers.setpoint_problem`.  A value out of range or not
    finite is answered OUT_OF_RANGE and stops the request (the later points are not
    operated, IEEE 1815 4.4.4.3); a point out of order (a request missing a point)
    is answered FORMAT_ERROR, as is every point after a refused one; nothing of a
    refused request is applied, and nothing carries over to the next request.  Each
    refused request is logged once in ``rejected`` (wall-clock time, the point
    refused, reason).  Each TCP connection is served on its own (:func:`_runner`):
    an outsider's connection does not close the control centre's."""

    def __init__(self, select_before_operate: bool = False,
                 select_timeout: float = 10.0) -> None:
        check_flag("select_before_operate", select_before_operate)
        check_positive("select_timeout", select_timeout)
        self.select_before_operate, self.select_timeout = select_before_operate, select_timeout
        self.inbox: tuple[dict, int, float] | None = None
        self.lock = threading.Lock()
        self.runner, self.task, self.loop, self.database = None, None, None, None
        self.rejected: list[tuple[float, str, str]] = []
        self._staged: dict[str, float] | None = {}     # None: this request was refused

    def _refuse(self, point: str, value: float, reason: str, result):
        with self.lock:
            self.rejected.append((time.perf_counter(), f"{point}={value!r}", reason))
        self._staged = None
        return result

    def _stage(self, index: int, value: float):
        """One point of the request under way checked and staged, or refused (logged)."""
        from dnp3.outstation.handler import CommandResult
        staged = self._staged
        if staged is None:            # a point after a refused one: not operated
            return CommandResult.format_error()
        if index >= len(COMMAND_POINTS):
            return self._refuse(f"index {index}", value, "no such point",
                                CommandResult.not_supported())
        point = COMMAND_POINTS[index]
        if list(staged) != list(COMMAND_POINTS[:index]):
            return self._refuse(point, value, f"out of order (after "
                                f"{list(staged) or 'nothing'})", CommandResult.format_error())
        problem = seq_problem(value) if point == "seq" else value_problem(point, value)
        if problem is not None:
            return self._refuse(point, value, problem, CommandResult.out_of_range())
        staged[point] = value
        return CommandResult.success()

    def _handler(self):
        from dnp3.outstation.handler import CommandResult, DefaultCommandHandler
        station = self

        class Handler(DefaultCommandHandler):
            def direct_operate_analog_output(self, index: int, value: float):
                if station.select_before_operate:
                    return station._refuse(f"index {index}", value, "DIRECT_OPERATE: this "
                                           "outstation takes select before operate only",
                                           CommandResult.not_supported())
                return station._stage(index, value)

            def select_analog_output(self, index: int, value: float):
                return station._stage(index, value)

            def operate_analog_output(self, index: int, value: float, select_sequence: int):
                return station._stage(index, value)
        return Handler()

    def _station(self, database, handler):
        """The outstation of dnp3py, its requests bounded: the command a request
        staged is applied after the request, whole, or dropped."""
        from dnp3.outstation import Outstation as Station
        from dnp3.outstation import OutstationConfig
        owner = self

        class Bounded(Station):
            def process_request(self, data: bytes, *, peer=None):
                # dnp3py answers any source; a device answers its master only
                if peer is not None and peer.source != MASTER:
                    with owner.lock:
                        owner.rejected.append((time.perf_counter(),
                                               f"a request from address {peer.source}",
                                               f"not the control centre's address ({MASTER})"))
                    return []
                return super().process_request(data, peer=peer)

            # dnp3py calls its command handler point by point; a request is the
            # unit of a command here (dnp3py is pinned in environment.txt)
            def _handle_direct_operate(self, request, **kwargs):
                return self._applying(super()._handle_direct_operate, request, kwargs)

            def _handle_operate(self, request, **kwargs):
                return self._applying(super()._handle_operate, request, kwargs)

            def _handle_select(self, request, **kwargs):
                owner._staged = {}
                try:
                    return super()._handle_select(request, **kwargs)
                finally:
                    owner._staged = {}

            def _applying(self, handle, request, kwargs):
                """``handle(request)``: a DIRECT_OPERATE or an OPERATE, applied whole
                or not at all; an OPERATE's points dnp3py answered NO_SELECT (no
                SELECT, another one's values, or one older than ``select_timeout``) are
                logged."""
                owner._staged = {}
                try:
                    response = handle(request, **kwargs)
                finally:
                    staged, owner._staged = owner._staged, {}
                if staged is not None and list(staged) == list(COMMAND_POINTS):
                    values = dict(staged)
                    seq = int(values.pop("seq"))
                    with owner.lock:
                        owner.inbox = (values, seq, time.perf_counter())
                refused = [COMMAND_POINTS[i] if i < len(COMMAND_POINTS) else f"index {i}"
                           for i, status in _statuses(response) if status == NO_SELECT]
                if refused:
                    with owner.lock:
                        owner.rejected.append((time.perf_counter(),
                                               f"OPERATE of {', '.join(refused)}",
                                               "no matching SELECT (NO_SELECT)"))
                return response

        return Bounded(database=database, handler=handler,
                       config=OutstationConfig(address=OUTSTATION, master_address=MASTER,
                                               select_timeout=self.select_timeout))

    async def start(self, host: str = "127.0.0.1") -> int:
        """Listen on ``host`` (a port the kernel chooses); return the port."""
        from dnp3.database import AnalogInputConfig, Database
        from dnp3.database.point import EventClass
        self.loop = asyncio.get_running_loop()
        self.database = Database()
        for i in range(len(REPORT_POINTS)):
            self.database.add_analog_input(i, AnalogInputConfig(event_class=EventClass.NONE))
        station = self._station(self.database, self._handler())
        self.runner = _runner(self)(outstation=station, host=host, port=0)
        self.task = asyncio.create_task(self.runner.run())
        for _ in range(500):
            if self.runner.local_address is not None:
                return self.runner.local_address[1]
            await asyncio.sleep(0.002)
        raise ConnectionError("the DNP3 outstation did not start listening")

    async def stop(self) -> None:
        if self.runner is not None:
            await self.runner.stop()
            self.task.cancel()
            await asyncio.gather(self.task, return_exceptions=True)

    def take(self) -> tuple[dict[str, float], int] | None:
        """The command that arrived since the last call, ``(values, seq)``, or None."""
        with self.lock:
            got, self.inbox = self.inbox, None
        return None if got is None else got[:2]

    def publish(self, report: dict) -> None:
        """The report the next poll returns (its fields as the point list's counts)."""
        async def update():
            for i, c in enumerate(counts(report)):
                self.database.update_analog_input(i, value=c)
        asyncio.run_coroutine_threadsafe(update(), self.loop).result(5.0)


class _Checked:
    """A connection's channel as the outstation reads it: each link frame's direction
    bit is checked before dnp3py's parser (which drops the link header) sees it.  A
    frame marked as coming from an outstation (DIR = 0) is logged in ``owner``'s
    ``rejected`` and dropped; bytes that are not DNP3 link frames pass to dnp3py's
    parser, which resynchronizes on the next start bytes.  A connection its peer
    resets ends as one it closes (an empty read), not as a transport error."""

    def __init__(self, channel, owner: Outstation) -> None:
        self.channel, self.owner, self.buffer = channel, owner, bytearray()

    async def read(self, n: int) -> bytes:
        from dnp3.transport_io.channel import ChannelError
        while True:
            try:
                data = await self.channel.read(n)
            except ChannelError as err:
                if isinstance(err.__cause__, ConnectionResetError):
                    return b""
                raise
            if not data:
                return data
            self.buffer.extend(data)
            try:
                frames = Codec.cut(self.buffer)
            except ValueError:             # not a link frame: dnp3py's parser skips it
                out = bytes(self.buffer)
                self.buffer.clear()
                return out
            kept = [f for f in frames if self._from_a_master(f)]
            if kept:
                return b"".join(kept)

    def _from_a_master(self, frame: bytes) -> bool:
        if frame[3] & 0x80:
            return True
        source = struct.unpack("<H", frame[6:8])[0]
        with self.owner.lock:
            self.owner.rejected.append((time.perf_counter(), f"a frame from address {source}",
                                        "direction bit 0 (an outstation's) on a request"))
        return False

    async def write_all(self, data: bytes) -> None:
        await self.channel.write_all(data)

    async def close(self) -> None:
        await self.channel.close()


def _runner(owner: Outstation):
    """dnp3py's TCP runner serving every connection on its own: its own closes the
    connection it holds when another arrives (DNP3 over TCP is point to point), so
    anyone who connects to the port hangs up the control centre.  Each connection
    has its own link and transport state and its own peer id (the outstation tells
    its masters apart by them), and its frames' direction bits are checked
    (:class:`_Checked`, logged in ``owner``)."""
    from dnp3.outstation import OutstationTcpRunner
    from dnp3.transport_io.channel import ChannelClosedError
    from dnp3.transport_io.tcp_server import serve

    class EveryConnection(OutstationTcpRunner):
        async def _handle_connection(self, channel) -> None:
            await super()._handle_connection(_Checked(channel, owner))

        async def run(self) -> None:
            self._shutdown.clear()
            self._server = await serve(self.host, self.port)
            tasks: set[asyncio.Task] = set()
            try:
                while not self._shutdown.is_set():
                    try:
                        channel = await asyncio.wait_for(self._server.accept(), timeout=1.0)
                    except TimeoutError:
                        continue
                    except ChannelClosedError:
                        break
                    task = asyncio.create_task(self._handle_connection(channel))
                    tasks.add(task)
                    task.add_done_callback(tasks.discard)
            finally:
                for task in list(tasks):
                    task.cancel()
                await asyncio.gather(*tasks, return_exceptions=True)
                await self._server.stop()

    return EveryConnection


class Centre:
    """The control centre's DNP3 master (address 2), connected to ``host:port`` through
    ``loop`` (an :class:`~lfc.wire.relay.EventLoop`).

    On connecting it does what a master does (IEEE 1815 5.1): an integrity poll,
    then, as the outstation's internal indications ask, a time synchronization
    (a WRITE of g50v1, the wall clock) and the clearing of DEVICE_RESTART (a WRITE
    of g80v1 index 7).  ``startup_iin`` holds the indications the last start-up
    found, ``iin`` the latest response's.  With ``select_before_operate`` a command
    is a SELECT, then an OPERATE of the same block.  A connection that fails (reset,
    closed) is made again and started up again, as a real master's is: the period's
    command is lost, the report read on the new connection; each is kept in
    ``reconnects`` (the period's ``seq`` and what failed).  ``inside``: ``() ->
    context manager``, the block it connects again in (its namespace,
    :mod:`lfc.wire.network`)."""

    def __init__(self, port: int, loop: EventLoop, timeout: float = 10.0,
                 host: str = "127.0.0.1", select_before_operate: bool = False,
                 inside: Callable = nullcontext) -> None:
        check_flag("select_before_operate", select_before_operate)
        self.select_before_operate = select_before_operate
        self.loop, self.where, self.inside = loop, (host, port, timeout), inside
        self.reconnects: list[tuple[int, str]] = []
        self.seq = 0
        self._connect()

    def _connect(self) -> None:
        """Connect, then the start-up: an integrity poll, time and restart as asked."""
        from dnp3.master import DefaultSOEHandler, Master, MasterConfig, MasterTcpRunner
        host, port, timeout = self.where
        self.handler = DefaultSOEHandler()
        self.master = Master(handler=self.handler,
                             config=MasterConfig(address=MASTER, outstation_address=OUTSTATION))
        self.runner = MasterTcpRunner(master=self.master, host=host, port=port,
                                      response_timeout=timeout)
        self.loop.run(self.runner.open())
        self.iin = 0
        self.startup_iin = self._request(self.master.build_integrity_poll())
        self._start_up()

    def _request(self, request) -> int:
        """Send ``request``; the internal indications of its last response."""
        responses = self.loop.run(self.runner.request(request))
        self.iin = int(responses[-1].iin) if responses else self.iin
        return self.iin

    def _call(self, make) -> bool:
        """Send the requests ``make()`` builds; False after the connection failed and was
        made again (a master's request sequence starts over on it)."""
        from dnp3.master.tcp_runner import LinkError
        from dnp3.transport_io.channel import ChannelError
        try:
            for request in make():
                self._request(request)
            return True
        except (LinkError, ChannelError, ConnectionError, asyncio.IncompleteReadError) as err:
            self.reconnects.append((self.seq, f"{type(err).__name__}: {err}"[:200]))
            try:
                self.loop.run(self.runner.close())
            except (ChannelError, ConnectionError):
                pass                             # what was left of it is gone
            with self.inside():
                self._connect()
            return False

    def _start_up(self) -> None:
        from dnp3.application.builder import build_write_request
        from dnp3.application.fragment import ObjectBlock
        from dnp3.application.qualifiers import ObjectHeader
        from dnp3.core.flags import IIN
        blocks = []
        if self.iin & IIN.NEED_TIME:
            ms = int(time.time() * 1000)
            blocks.append(ObjectBlock(header=ObjectHeader(group=50, variation=1, qualifier=0x07),
                                      data=bytes([1]) + ms.to_bytes(6, "little")))
        if self.iin & IIN.DEVICE_RESTART:
            blocks.append(ObjectBlock(header=ObjectHeader(group=80, variation=1, qualifier=0x00),
                                      data=bytes([7, 7, 0])))
        if blocks:
            self._request(build_write_request(tuple(blocks),
                                              seq=self.master.next_request_sequence()))

    def send(self, values: dict[str, float], seq: int) -> None:
        """DIRECT_OPERATE the four analog outputs (g41v4), or SELECT and OPERATE them."""
        from dnp3.application.builder import (build_direct_operate_request,
                                              build_operate_request, build_select_request)
        from dnp3.application.fragment import ObjectBlock
        from dnp3.application.qualifiers import ObjectHeader
        self.seq = seq
        objects = (ObjectBlock(header=ObjectHeader(group=41, variation=4, qualifier=0x17),
                               data=_ao_block(values, seq)[3:]),)
        builders = ((build_select_request, build_operate_request) if self.select_before_operate
                    else (build_direct_operate_request,))
        self._call(lambda: (build(objects=objects, seq=self.master.next_request_sequence())
                            for build in builders))

    def poll(self) -> dict:
        """Read the report (a range poll of g30v1, points 0-8; again on a new connection
        if it failed)."""
        def read():
            return (self.master.build_range_poll(30, 1, 0, len(REPORT_POINTS) - 1),)
        self._call(read) or self._call(read)
        points = self.handler.analog_inputs
        return from_counts([points[i].value for i in range(len(REPORT_POINTS))])

    def close(self) -> None:
        self.loop.run(self.runner.close())
