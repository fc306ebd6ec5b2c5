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
with ``scapy`` (imported here only).
"""

from __future__ import annotations

from pathlib import Path

CENTRE, RELAY = "10.0.0.1", "10.0.0.2"
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
    of a run over ``protocol`` to ``path`` (pcap); times are offset so the first
    frame is at ``epoch`` s.  Returns the path."""
    from scapy.layers.inet import IP, TCP
    from scapy.layers.l2 import Ether
    from scapy.utils import wrpcap

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
    path = Path(path)
    wrpcap(str(path), packets)
    return path


def read_frames(path: str | Path) -> list[tuple[float, str, bytes, int]]:
    """The frames of a capture :func:`write_pcap` wrote, as a run holds them
    (time s, leg, bytes, area: :attr:`lfc.wire.run.WireResult.frames`; the time is
    the capture's), for the detector (:func:`lfc.wire.detect.detect`).  A packet
    between other addresses, or without a payload, is not one of the run's legs and
    is left out."""
    from scapy.layers.inet import IP, TCP
    from scapy.utils import rdpcap

    def area_of(address: str) -> int | None:
        head, _, last = address.rpartition(".")
        return int(last) - 3 if head == "10.0.0" and last.isdigit() and int(last) >= 3 \
            else None

    out = []
    for pkt in rdpcap(str(path)):
        if IP not in pkt or TCP not in pkt or not bytes(pkt[TCP].payload):
            continue
        src, dst = pkt[IP].src, pkt[IP].dst
        if src == CENTRE and dst == RELAY:
            leg, area = "centre>relay", (pkt[TCP].sport - 40001) // 2
        elif src == RELAY and dst == CENTRE:
            leg, area = "relay>centre", (pkt[TCP].dport - 40001) // 2
        elif src == RELAY and area_of(dst) is not None:
            leg, area = "relay>generator", area_of(dst)
        elif dst == RELAY and area_of(src) is not None:
            leg, area = "generator>relay", area_of(src)
        else:
            continue
        out.append((float(pkt.time), leg, bytes(pkt[TCP].payload), area))
    return out


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
