"""Issue "Field": the outstations behave like devices under hostile traffic — a command
is applied whole or not at all, a value out of range or not finite is refused with the
protocol's own code, a stranger's frames are not commands, nothing carries over, and
every refusal is logged with its reason.  Each test failed before the fix it pins
(``KeyError: 'pc'`` in ``Link.deliver`` for a one-point DNP3 command; ``ValueError:
cannot convert float NaN to integer`` once a NaN setpoint was answered SUCCESS; a
one-register Modbus write that discarded the period's command)."""

from __future__ import annotations

import math
import struct

import pytest

from lfc.wire.registers import N_COMMAND, command_registers, encode

COMMAND = {"pc": 0.25, "wref": -0.001, "ace": 0.0}

pytest.importorskip("pymodbus")


@pytest.fixture
def modbus():
    """A Modbus outstation on loopback and a pymodbus client of it (no relay)."""
    from pymodbus.client import ModbusTcpClient

    from lfc.wire import modbus as mb
    loop = mb.EventLoop()
    station = mb.Outstation()
    port = loop.run(station.start())
    client = ModbusTcpClient("127.0.0.1", port=port, timeout=5)
    assert client.connect()
    yield station, client
    client.close()
    loop.run(station.stop())
    loop.close()


def test_modbus_applies_a_command_only_whole(modbus):
    station, client = modbus
    assert not client.write_registers(0, command_registers(COMMAND, 7), device_id=1).isError()
    whole = command_registers({**COMMAND, "pc": 0.5}, 8)
    assert not client.write_registers(0, whole, device_id=1).isError()
    for address, registers in ((0, whole[:1]), (1, whole), (4, whole[:4]), (0, whole[:12])):
        reply = client.write_registers(address, registers, device_id=1)
        assert reply.isError() and reply.exception_code == 2, (address, len(registers))
    reply = client.write_register(12, 9, device_id=1)                 # function 6
    assert reply.isError() and reply.exception_code == 2
    assert station.take() == ({**COMMAND, "pc": 0.5}, 8)              # the last whole one
    assert station.take() is None
    # logged by the outstation, the write past the block's end too (13 registers at 1),
    # which pymodbus itself refuses (exception 2) before the device sees it (it was not
    # logged before)
    whole_only = f"not the whole command (function 16 of {N_COMMAND} registers at 0)"
    assert [r[1:] for r in station.rejected] == [
        ("function 16: 1 register(s) at 0", whole_only),
        (f"function 16: {N_COMMAND} register(s) at 1", "refused by pymodbus itself (exception "
         "2: outside the device's registers or functions)"),
        ("function 16: 4 register(s) at 4", whole_only),
        ("function 16: 12 register(s) at 0", whole_only),
        ("function 6: 1 register(s) at 12", whole_only)]


@pytest.mark.parametrize("value", [math.nan, math.inf, -1e300, 2e6])
def test_modbus_refuses_a_value_out_of_range_with_an_illegal_value(modbus, value):
    station, client = modbus
    registers = encode([value, 0.0, 0.0]) + [3]
    reply = client.write_registers(0, registers, device_id=1)
    assert reply.isError() and reply.exception_code == 3
    assert station.take() is None
    assert "pc=" in station.rejected[-1][2] and "not a finite value" in station.rejected[-1][2]


@pytest.fixture
def dnp3():
    """A DNP3 outstation on loopback (its requests handed to it directly)."""
    pytest.importorskip("dnp3")
    from lfc.wire import dnp3 as dn
    loop = dn.EventLoop()
    station = dn.Outstation()
    loop.run(station.start())
    yield station
    loop.run(station.stop())
    loop.close()


def operate(station, points: list[tuple[int, float]], source: int = 2,
            function: str = "direct_operate", seq: int = 1) -> list[int] | None:
    """DIRECT_OPERATE (or ``function`` ``"select"``, ``"operate"``) of g41v4 ``points``
    (index, value) in one request from link address ``source``: the statuses the
    outstation answered, one per point (None: no answer)."""
    from dnp3.application import builder
    from dnp3.application.fragment import ObjectBlock
    from dnp3.application.qualifiers import ObjectHeader
    from dnp3.outstation.peer import PeerId
    data = bytes([len(points)]) + b"".join(bytes([i]) + struct.pack("<d", v) + b"\x00"
                                             for i, v in points)
    request = getattr(builder, f"build_{function}_request")(
        objects=(ObjectBlock(header=ObjectHeader(group=41, variation=4, qualifier=0x17),
                             data=data),), seq=seq)
    responses = station.runner.outstation.process_request(
        request.to_bytes(), peer=PeerId(source=source, connection=1))
    if not responses:
        return None
    block = responses[0].objects[0].data
    return [block[1 + 10 * k + 9] for k in range(block[0])]


WHOLE = [(0, 0.25), (1, -0.001), (2, 0.0), (3, 7.0)]


def test_dnp3_applies_a_command_only_whole_and_in_order(dnp3):
    station = dnp3
    assert operate(station, WHOLE) == [0, 0, 0, 0]
    assert station.take() == (COMMAND, 7)
    assert operate(station, [(3, 8.0)]) == [3]                          # seq alone
    assert operate(station, [(0, 0.5), (1, 0.0)]) == [0, 0]             # no seq
    assert operate(station, [(2, 0.0), (3, 9.0)]) == [3, 3]             # not carried over
    assert operate(station, [(1, 0.0), (0, 0.5), (2, 0.0), (3, 9.0)])[0] == 3
    assert station.take() is None
    assert all("out of order" in r[2] for r in station.rejected)


@pytest.mark.parametrize("point, value", [(0, math.nan), (1, math.inf), (2, -1e300),
                                          (3, 70000.0), (3, 1.5), (0, 2e6)])
def test_dnp3_refuses_a_value_out_of_range_and_operates_nothing_after_it(dnp3, point, value):
    station = dnp3
    points = list(WHOLE)
    points[point] = (point, value)
    statuses = operate(station, points)
    assert statuses[:point] == [0] * point and statuses[point] == 12     # OUT_OF_RANGE
    assert station.take() is None
    assert "not" in station.rejected[-1][2]
    assert operate(station, WHOLE) == [0] * 4
    assert station.take() == (COMMAND, 7)                                # the next is whole


def test_dnp3_answers_only_the_control_centres_address(dnp3):
    station = dnp3
    assert operate(station, WHOLE, source=7) is None
    assert station.take() is None
    assert station.rejected[-1][1:] == ("a request from address 7",
                                        "not the control centre's address (2)")
    assert operate(station, WHOLE) == [0] * 4
    assert station.take() == (COMMAND, 7)


def test_a_run_reports_what_its_outstations_refused():
    """``WireResult.rejected``: empty on a clean run (every command whole and in range)."""
    import lfc
    from lfc.wire.run import run_wire
    result = run_wire(lfc.LFCParams(), duration=0.2, attack="fig4", protocol="modbus")
    assert list(result.rejected.columns) == ["time", "area", "what", "reason"]
    assert result.rejected.empty and (result.exchanges.link == 0).all()


def test_dnp3_keeps_serving_its_master_while_an_outsider_connects():
    """An outsider's connection to the outstation's port once closed the control
    centre's (dnp3py serves one connection) and the run ended in a response
    timeout; the outstation now serves each connection on its own."""
    import socket

    pytest.importorskip("dnp3")
    from lfc.wire import dnp3 as dn
    loop = dn.EventLoop()
    station = dn.Outstation()
    port = loop.run(station.start())
    centre = dn.Centre(port, loop, timeout=2.0)
    try:
        centre.send(COMMAND, 1)
        assert station.take() == (COMMAND, 1)
        outsiders = [socket.create_connection(("127.0.0.1", port)) for _ in range(3)]
        outsiders[0].sendall(b"\x05\x64garbage" * 10)
        centre.send({**COMMAND, "pc": 0.5}, 2)
        assert station.take() == ({**COMMAND, "pc": 0.5}, 2)
        assert centre.poll()["seq"] == 0
        for s in outsiders:
            s.close()
    finally:
        centre.close()
        loop.run(station.stop())
        loop.close()


def test_dnp3_drops_a_request_whose_direction_bit_is_an_outstations():
    """A DIRECT_OPERATE in a link frame marked as coming from an outstation (DIR = 0)
    was applied (dnp3py's runner drops the link header before the outstation sees
    it); it is now logged and dropped, and the same request with DIR = 1 is applied."""
    import socket

    pytest.importorskip("dnp3")
    from dnp3.application.builder import build_direct_operate_request
    from dnp3.application.fragment import ObjectBlock
    from dnp3.application.qualifiers import ObjectHeader
    from dnp3.datalink.builder import build_unconfirmed_user_data

    from lfc.wire import dnp3 as dn
    data = bytes([len(WHOLE)]) + b"".join(bytes([i]) + struct.pack("<d", v) + b"\x00"
                                          for i, v in WHOLE)

    def frame(seq: int, from_master: bool) -> bytes:
        request = build_direct_operate_request(
            objects=(ObjectBlock(header=ObjectHeader(group=41, variation=4, qualifier=0x17),
                                 data=data),), seq=seq)
        return build_unconfirmed_user_data(
            destination=dn.OUTSTATION, source=dn.MASTER, dir_from_master=from_master,
            user_data=bytes([0xC0 | seq]) + request.to_bytes()).to_bytes()

    loop = dn.EventLoop()
    station = dn.Outstation()
    port = loop.run(station.start())
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=2.0) as sock:
            sock.sendall(frame(1, from_master=False))
            sock.settimeout(0.3)
            with pytest.raises(TimeoutError):
                sock.recv(4096)                   # no answer
            assert station.take() is None
            assert station.rejected[-1][1:] == ("a frame from address 2",
                                                "direction bit 0 (an outstation's) on a request")
            sock.settimeout(2.0)
            sock.sendall(frame(2, from_master=True))
            assert sock.recv(4096)[:2] == b"\x05\x64"
            assert station.take() == (COMMAND, 7)
    finally:
        loop.run(station.stop())
        loop.close()


@pytest.mark.parametrize("protocol", ["dnp3", "modbus"])
def test_a_forged_answer_looks_like_the_sessions_own(protocol):
    """The ``drop`` attack answers the commands it swallows itself.  Its DNP3 answers
    carried IIN 0x0000 and transport sequence 0 where the outstation's carried its
    internal indications (0x9000: restarted, needs time) and an incrementing sequence
    — a detector's first rule.  Now the centre sees one device: the indications of
    the session in every answer, and one transport sequence (the outstation's later
    frames renumbered after each forged one); over Modbus a forged acknowledgement
    echoes the write's transaction id."""
    import lfc
    from lfc.wire.run import run_wire
    run = run_wire(lfc.LFCParams(), duration=2.0, attack="drop", protocol=protocol)
    to_centre = [f[2] for f in run.frames if f[1] == "relay>centre"]
    forged = int(run.exchanges.link.sum())
    assert forged == 50                                     # 1.0 s to 1.5 s, every period
    if protocol == "modbus":
        asked = {f[2][:2] for f in run.frames if f[1] == "centre>relay"}
        assert all(f[:2] in asked for f in to_centre)
        return
    from lfc.wire.dnp3 import RESPONSE, _user_data
    data = [_user_data(f) for f in to_centre]
    answers = [d for d in data if len(d) > 5 and d[2] == RESPONSE and d[5] == 41]
    assert len(answers) == 200                         # every command answered, 50 forged
    assert {bytes(d[3:5]) for d in answers} == {b"\x00\x00"}   # after the master's start-up
    sequence = [d[0] & 0x3F for d in data if d]
    assert all((b - a) % 64 == 1 for a, b in zip(sequence, sequence[1:]))


def test_the_dnp3_master_starts_up_as_a_master_does():
    """Every DNP3 response carried DEVICE_RESTART and NEED_TIME for the whole run:
    nobody cleared them.  The master now polls, syncs the time and clears the
    restart on connecting."""
    pytest.importorskip("dnp3")
    from lfc.wire import dnp3 as dn
    loop = dn.EventLoop()
    station = dn.Outstation()
    centre = dn.Centre(loop.run(station.start()), loop)
    try:
        assert centre.startup_iin == 0x90 and centre.iin == 0
        centre.send(COMMAND, 1)
        assert centre.poll()["seq"] == 0 and centre.iin == 0
    finally:
        centre.close()
        loop.run(station.stop())
        loop.close()


def test_the_setpoint_range_holds_at_its_corners(modbus, dnp3):
    """±1e6 pu (``MAX_ABS_INPUT``) is applied, the next float beyond it refused; a
    sequence number 0 and 65535 is applied, -1 and 65536 refused — on both protocols
    (Modbus's sequence register is 16 bits: it cannot carry the others)."""
    from lfc.filters.base import MAX_ABS_INPUT
    station, client = modbus
    edge, beyond = MAX_ABS_INPUT, math.nextafter(MAX_ABS_INPUT, math.inf)
    for sign in (1.0, -1.0):
        values = {**COMMAND, "wref": sign * edge}
        assert not client.write_registers(0, command_registers(values, 65535),
                                          device_id=1).isError()
        assert station.take() == (values, 65535)
        reply = client.write_registers(0, encode([0.0, sign * beyond, 0.0]) + [0],
                                       device_id=1)
        assert reply.isError() and reply.exception_code == 3 and station.take() is None
    for point, value, status in ((1, edge, 0), (1, -edge, 0), (1, beyond, 12),
                                 (1, -beyond, 12), (3, 0.0, 0), (3, 65535.0, 0),
                                 (3, -1.0, 12), (3, 65536.0, 12)):
        points = list(WHOLE)
        points[point] = (point, value)
        assert operate(dnp3, points)[point] == status, (point, value)
        assert (dnp3.take() is None) == (status != 0)


def test_modbus_closes_a_connection_idle_for_its_timeout_and_logs_it():
    """A device frees its few sockets: an outsider's connection that sends nothing for
    ``idle_timeout`` is closed (its next read sees the end of the stream) and logged in
    ``rejected``, while the control centre's, writing every 0.1 s, stays open and its
    commands land; a timeout that is not > 0 is refused naming it."""
    import socket
    import time

    from pymodbus.client import ModbusTcpClient

    from lfc.wire import modbus as mb
    for bad in (0.0, -1.0, math.nan):
        with pytest.raises(ValueError, match="idle_timeout"):
            mb.Outstation(idle_timeout=bad)
    loop = mb.EventLoop()
    station = mb.Outstation(idle_timeout=0.4)
    port = loop.run(station.start())
    centre = ModbusTcpClient("127.0.0.1", port=port, timeout=5)
    try:
        assert centre.connect()
        outsider = socket.create_connection(("127.0.0.1", port))
        outsider.settimeout(5.0)
        for seq in range(12):                                      # 1.2 s, busy
            reply = centre.write_registers(0, command_registers(COMMAND, seq), device_id=1)
            assert not reply.isError(), seq
            time.sleep(0.1)
        assert outsider.recv(16) == b""                            # closed by the device
        assert station.take() == (COMMAND, 11)
        assert [r[2] for r in station.rejected] == ["idle for more than 0.4 s: closed"]
        assert station.rejected[0][1].startswith("connection from ('127.0.0.1', ")
    finally:
        centre.close()
        loop.run(station.stop())
        loop.close()


@pytest.fixture
def sbo():
    """A DNP3 outstation that takes select before operate only (select timeout 0.2 s)."""
    pytest.importorskip("dnp3")
    from lfc.wire import dnp3 as dn
    loop = dn.EventLoop()
    station = dn.Outstation(select_before_operate=True, select_timeout=0.2)
    loop.run(station.start())
    yield station
    loop.run(station.stop())
    loop.close()


def test_dnp3_select_before_operate_applies_only_an_operate_matching_its_select(sbo):
    """IEEE 1815's select before operate (``select_before_operate=True``): a SELECT
    applies nothing; the OPERATE of the same values applies the command whole.  Refused
    and logged, nothing applied: a DIRECT_OPERATE (NOT_SUPPORTED, 4); an OPERATE with no
    SELECT (NO_SELECT, 2: an outsider's lone OPERATE); an OPERATE whose values differ
    from its SELECT's (a man in the middle who rewrites only the OPERATE); an OPERATE
    later than the select timeout."""
    import time
    station = sbo
    assert operate(station, WHOLE)[0] == 4 and station.take() is None
    assert "select before operate only" in station.rejected[-1][2]
    assert operate(station, WHOLE, function="select") == [0] * 4
    assert station.take() is None                                      # selected only
    assert operate(station, WHOLE, function="operate", seq=2) == [0] * 4
    assert station.take() == (COMMAND, 7)
    assert operate(station, WHOLE, function="operate", seq=3) == [2] * 4   # used up
    assert station.rejected[-1][1:] == ("OPERATE of pc, wref, ace, seq",
                                        "no matching SELECT (NO_SELECT)")
    assert operate(station, WHOLE, function="select", seq=4) == [0] * 4
    rewritten = [(0, 0.5)] + WHOLE[1:]
    assert operate(station, rewritten, function="operate", seq=5)[0] == 2
    assert station.take() is None and "NO_SELECT" in station.rejected[-1][2]
    assert operate(station, WHOLE, function="select", seq=6) == [0] * 4
    time.sleep(0.3)
    assert operate(station, WHOLE, function="operate", seq=7) == [2] * 4
    assert station.take() is None


def test_an_outstation_checks_its_select_options():
    pytest.importorskip("dnp3")
    from lfc.wire import dnp3 as dn
    with pytest.raises(ValueError, match="select_timeout"):
        dn.Outstation(select_timeout=0.0)
    with pytest.raises(TypeError, match="select_before_operate"):
        dn.Outstation(select_before_operate="yes")


@pytest.mark.parametrize("protocol", ["modbus", "dnp3"])
def test_the_control_centre_connects_again_after_a_reset(protocol):
    """A man in the middle that resets the connection (``reset``: a TCP RST both ways
    instead of forwarding the command of 1 s): the control centre connects again (DNP3:
    and starts up again), the period's command is lost — the run is the one that drops
    it, bit for bit — and the reconnection is logged with what failed.  Before, the
    first failed request ended the run."""
    import numpy as np

    import lfc
    from lfc.wire import run_wire
    params, load = lfc.LFCParams(), lfc.Step(0.05, start=0.5)
    reset = run_wire(params, duration=2.0, protocol=protocol, load=load,
                     attack=[{"op": "reset", "start": 1.0, "stop": 1.005}])
    dropped = run_wire(params, duration=2.0, protocol=protocol, load=load,
                       attack=[{"op": "drop", "start": 1.0, "stop": 1.005}])
    a, b = reset.sim.trace.to_numpy(float), dropped.sim.trace.to_numpy(float)
    assert np.array_equal(np.isnan(a), np.isnan(b)) and np.array_equal(a[~np.isnan(a)],
                                                                       b[~np.isnan(b)])
    assert reset.exchanges.link.tolist() == dropped.exchanges.link.tolist()
    assert reset.exchanges.link.sum() == 1
    assert reset.reconnects[["t", "area", "seq"]].values.tolist() == [[1.0, 0, 100]]
    assert "reset" in reset.reconnects.reason.iat[0].lower()
    assert dropped.reconnects.empty and reset.rejected.empty


@pytest.mark.parametrize("protocol", ["modbus", "dnp3"])
def test_a_reset_storm_loses_its_commands_and_nothing_else(protocol):
    """Every command reset for half a second under Fig. 4's attack, the certified filter
    at the generator: 50 reconnections, 50 periods flagged, no trip, within 30 s."""
    import time

    import lfc
    from lfc.wire import run_wire
    from lfc.wire.attacks import ATTACKS
    params = lfc.LFCParams()
    t0 = time.perf_counter()
    run = run_wire(params, duration=3.0, protocol=protocol,
                   scc=lfc.SafetyFilter(params, method="certified"),
                   attack=[{"op": "reset", "start": 1.0, "stop": 1.495}, *ATTACKS["fig4"]])
    assert time.perf_counter() - t0 < 30.0
    assert len(run.reconnects) == 50 and run.exchanges.link.sum() == 50
    assert not run.tripped


def test_reset_takes_no_field():
    from lfc.wire.attacks import WireAttack
    with pytest.raises(ValueError, match="reset takes no field"):
        WireAttack([{"op": "reset", "field": "pc"}])
