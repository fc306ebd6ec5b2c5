"""A run's traffic as a packet capture Wireshark and tshark decode (Modbus/TCP or
DNP3).

Each leg of the relay's log (:attr:`lfc.wire.relay.Relay.log`) becomes one TCP
conversation between made-up addresses, with the server side on the protocol's
well-known port (502 for Modbus/TCP, 20000 for DNP3, so the dissectors
recognise it; the run itself used ports the kernel chose on 127.0.0.1):

==================  ==========================  ============================
leg                 from                        to
==================  ==========================  ============================
centre - relay      control centre 10.0.0.1     relay 10.0.0.2:PORT
relay - generator   relay 10.0.0.2              generator 10.0.0.(3 + area):PORT
==================  ==========================  ============================

(client ports 40001 + 2 area and 40002 + 2 area: one conversation per area and
leg).

Every frame is one TCP segment (sequence and acknowledgement numbers follow the
bytes sent), stamped with the wall-clock time it crossed the relay.  Written
with ``scapy`` (imported here only) as pcapng, whose section header and first
packet carry :data:`SYNTHESIZED` (Wireshark shows it under the capture file's
properties and as the packet's comment: ``tshark -Y frame.comment``), so the
file says what it is.  This capture is made from the relay's log;
``run_wire(capture=...)`` takes one from the loopback interface instead
(:mod:`lfc.wire.sniff`), and :func:`read_frames` reads either back.
"""

from __future__ import annotations

import struct
from pathlib import Path

from lfc.wire.network import LOOPBACK, VETH, host_index

CENTRE, RELAY = "10.0.0.1", "10.0.0.2"
#: what a synthesized capture says of itself (pcapng comments)
SYNTHESIZED = ("lfc: synthesized from the relay's log of a run, not captured: addresses, "
               "ports, TCP sequence numbers and the clock's epoch are made up and there are "
               "no handshakes; the payload bytes and their times at the relay are the run's. "
               "A capture from the sockets: run_wire(capture=...).")
BACK = {"centre>relay": "relay>centre", "relay>centre": "centre>relay",
        "relay>generator": "generator>relay", "generator>relay": "relay>generator"}


def generator_address(area: int) -> str:
    return f"10.0.0.{3 + area}"


def _legs(port: int, area: int) -> dict[str, tuple[str, str, int, int]]:
    gen, c, r = generator_address(area), 40001 + 2 * area, 40002 + 2 * area
    return {"centre>relay": (CENTRE, RELAY, c, port), "relay>centre": (RELAY, CENTRE, port, c),
            "relay>generator": (RELAY, gen, r, port), "generator>relay": (gen, RELAY, port, r)}


def _protocol(protocol: str):
    from lfc.wire.run import transport
    return transport(protocol)


def write_pcap(frames: list[tuple[float, str, bytes, int]], path: str | Path,
               protocol: str = "modbus", epoch: float = 0.0) -> Path:
    """Write ``frames`` (time s, leg, bytes, area: :attr:`lfc.wire.run.WireResult.frames`)
    of a run over ``protocol`` to ``path`` (pcapng, commented :data:`SYNTHESIZED`
    whatever the file's name); times are offset so the first frame is at ``epoch``
    s.  Returns the path."""
    from scapy.layers.inet import IP, TCP
    from scapy.layers.l2 import Ether

    if not frames:
        raise ValueError("no frames to capture")
    port = _protocol(protocol).PORT
    t0 = frames[0][0]
    seq: dict[tuple[str, int], int] = {}
    packets = []
    for t, leg, data, area in frames:
        src, dst, sport, dport = _legs(port, area)[leg]
        mine, theirs = seq.setdefault((leg, area), 1000), seq.setdefault((BACK[leg], area), 1000)
        pkt = (Ether() / IP(src=src, dst=dst) /
               TCP(sport=sport, dport=dport, flags="PA", seq=mine, ack=theirs) / data)
        pkt.time = epoch + (t - t0)
        seq[leg, area] = mine + len(data)
        packets.append(pkt)
    packets[0].comments = [SYNTHESIZED.encode()]
    path = Path(path)
    writer = _commented_writer(path, SYNTHESIZED)
    try:
        writer.write(packets)
    finally:
        writer.close()
    return path


def _commented_writer(path: Path, comment: str):
    """A scapy pcapng writer whose section header block carries ``comment``
    (option 1, ``opt_comment``; scapy writes none)."""
    from scapy.utils import PcapNgWriter

    class Writer(PcapNgWriter):
        def _write_block_shb(self) -> None:
            text = comment.encode()
            body = self.endian_magic + struct.pack(self.endian + "HHq", 1, 0, -1)
            options = (struct.pack(self.endian + "HH", 1, len(text)) + self._add_padding(text)
                       + struct.pack(self.endian + "HH", 0, 0))
            self.f.write(self.build_block(b"\x0A\x0D\x0D\x0A", body, options))

    return Writer(str(path))


def read_frames(path: str | Path, protocol: str = "modbus") -> list[tuple[float, str, bytes, int]]:
    """The frames of a capture of a run over ``protocol`` — one :func:`write_pcap`
    wrote from the relay's log, or one taken from the loopback interface
    (``run_wire(capture=...)``) — as a run holds them (time s, leg, bytes, area:
    :attr:`lfc.wire.run.WireResult.frames`; the time is the capture's, of the packet
    that completed the frame), for the detector (:func:`lfc.wire.detect.detect`).
    Each TCP stream's payload is joined in capture order and cut into the protocol's
    frames, so a frame split over segments, or segments holding several, read the
    same.  A packet between addresses of neither plan is left out."""
    from scapy.layers.inet import IP, TCP
    from scapy.utils import rdpcap

    codec = _protocol(protocol).Codec
    streams: dict[tuple, bytearray] = {}
    out = []
    for pkt in rdpcap(str(path)):
        if IP not in pkt or TCP not in pkt:
            continue
        payload = bytes(pkt[TCP].payload)
        where = _leg(pkt[IP].src, pkt[IP].dst, pkt[TCP].sport, pkt[TCP].dport)
        if not payload or where is None:
            continue
        key = (pkt[IP].src, pkt[TCP].sport, pkt[IP].dst, pkt[TCP].dport)
        buffer = streams.setdefault(key, bytearray())
        buffer.extend(payload)
        out += [(float(pkt.time), *where[:1], frame, where[1]) for frame in codec.cut(buffer)]
    return out


def _leg(src: str, dst: str, sport: int, dport: int) -> tuple[str, int] | None:
    """The leg and area of a packet from ``src:sport`` to ``dst:dport``: the synthesized
    capture's addresses (module docstring), or a real network's
    (:mod:`lfc.wire.network`: the loopback plan or the namespaces')."""
    if src == CENTRE and dst == RELAY:                     # synthesized
        return "centre>relay", (sport - 40001) // 2
    if src == RELAY and dst == CENTRE:
        return "relay>centre", (dport - 40001) // 2
    if src == RELAY and host_index(dst, "10.0.0", 3) is not None:
        return "relay>generator", host_index(dst, "10.0.0", 3)
    if dst == RELAY and host_index(src, "10.0.0", 3) is not None:
        return "generator>relay", host_index(src, "10.0.0", 3)
    return LOOPBACK.leg(src, dst) or VETH.leg(src, dst)


def read_commands(path: str | Path, protocol: str = "modbus",
                  area: int = 0) -> list[tuple[dict, int]]:
    """Every command ``area``'s generator received, ``(values, seq)``, read back
    from a capture: Modbus/TCP with scapy's own dissector (function-16 writes),
    DNP3 with dnp3py's link-frame parser (the frame's CRCs checked)."""
    from scapy.layers.inet import IP, TCP
    from scapy.utils import rdpcap

    transport = _protocol(protocol)
    if protocol == "modbus":
        from scapy.contrib.modbus import ModbusADURequest  # noqa: F401  (binds port 502)

        from lfc.wire.registers import read_command
    out = []
    for pkt in rdpcap(str(path)):
        if TCP in pkt and pkt[IP].dst == generator_address(area) \
                and pkt[TCP].dport == transport.PORT:
            if protocol == "modbus":
                layer = pkt[TCP].payload.payload          # the ADU's PDU
                command = (read_command(list(layer.outputsValue))
                           if getattr(layer, "funcCode", None) == 16 else None)
                if command is not None:
                    out.append(command)
            else:
                command = transport.Codec.command(bytes(pkt[TCP].payload))
                if command is not None:
                    out.append(command)
    return out
