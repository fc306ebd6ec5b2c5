"""A run's Modbus/TCP traffic as a packet capture Wireshark and tshark decode.

Each leg of the relay's log (:attr:`lfc.wire.modbus.Relay.log`) becomes one TCP
conversation between made-up addresses, with the server side on port 502 (the
Modbus/TCP port, so the dissectors recognise it; the run itself used ports the
kernel chose on 127.0.0.1):

==================  ==========================  ============================
leg                 from                        to
==================  ==========================  ============================
centre - relay      control centre 10.0.0.1     relay 10.0.0.2:502
relay - generator   relay 10.0.0.2              generator 10.0.0.3:502
==================  ==========================  ============================

Every frame is one TCP segment (sequence and acknowledgement numbers follow the
bytes sent), stamped with the wall-clock time it crossed the relay.  Written
with ``scapy`` (imported here only).
"""

from __future__ import annotations

from pathlib import Path

CENTRE, RELAY, GENERATOR = "10.0.0.1", "10.0.0.2", "10.0.0.3"
PORT = 502
LEGS = {"centre>relay": (CENTRE, RELAY, 40001, PORT), "relay>centre": (RELAY, CENTRE, PORT, 40001),
        "relay>generator": (RELAY, GENERATOR, 40002, PORT),
        "generator>relay": (GENERATOR, RELAY, PORT, 40002)}


def write_pcap(frames: list[tuple[float, str, bytes]], path: str | Path,
               epoch: float = 0.0) -> Path:
    """Write ``frames`` (time s, leg, bytes) to ``path`` (pcap); times are offset
    so the first frame is at ``epoch`` s.  Returns the path."""
    from scapy.layers.inet import IP, TCP
    from scapy.layers.l2 import Ether
    from scapy.utils import wrpcap

    if not frames:
        raise ValueError("no frames to capture")
    t0 = frames[0][0]
    seq = {leg: 1000 for leg in LEGS}
    packets = []
    for t, leg, data in frames:
        src, dst, sport, dport = LEGS[leg]
        back = {"centre>relay": "relay>centre", "relay>centre": "centre>relay",
                "relay>generator": "generator>relay", "generator>relay": "relay>generator"}[leg]
        pkt = (Ether() / IP(src=src, dst=dst) /
               TCP(sport=sport, dport=dport, flags="PA", seq=seq[leg], ack=seq[back]) / data)
        pkt.time = epoch + (t - t0)
        seq[leg] += len(data)
        packets.append(pkt)
    path = Path(path)
    wrpcap(str(path), packets)
    return path


def read_commands(path: str | Path) -> list[list[int]]:
    """The registers of every command write (function 16) the generator received,
    read back from a capture with scapy's Modbus/TCP dissector."""
    from scapy.contrib.modbus import ModbusADURequest  # noqa: F401  (binds port 502)
    from scapy.layers.inet import IP, TCP
    from scapy.utils import rdpcap

    out = []
    for pkt in rdpcap(str(path)):
        if TCP in pkt and pkt[IP].dst == GENERATOR and pkt[TCP].dport == PORT:
            layer = pkt[TCP].payload.payload          # the ADU's PDU
            if getattr(layer, "funcCode", None) == 16:
                out.append(list(layer.outputsValue))
    return out
