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
relay - generator   relay 10.0.0.2              generator 10.0.0.3:PORT
==================  ==========================  ============================

Every frame is one TCP segment (sequence and acknowledgement numbers follow the
bytes sent), stamped with the wall-clock time it crossed the relay.  Written
with ``scapy`` (imported here only).
"""

from __future__ import annotations

from pathlib import Path

CENTRE, RELAY, GENERATOR = "10.0.0.1", "10.0.0.2", "10.0.0.3"
CLIENT_PORTS = {"centre>relay": 40001, "relay>generator": 40002}
BACK = {"centre>relay": "relay>centre", "relay>centre": "centre>relay",
        "relay>generator": "generator>relay", "generator>relay": "relay>generator"}


def _legs(port: int) -> dict[str, tuple[str, str, int, int]]:
    return {"centre>relay": (CENTRE, RELAY, 40001, port),
            "relay>centre": (RELAY, CENTRE, port, 40001),
            "relay>generator": (RELAY, GENERATOR, 40002, port),
            "generator>relay": (GENERATOR, RELAY, port, 40002)}


def _protocol(protocol: str):
    from lfc.wire.run import _transport
    return _transport(protocol)


def write_pcap(frames: list[tuple[float, str, bytes]], path: str | Path,
               protocol: str = "modbus", epoch: float = 0.0) -> Path:
    """Write ``frames`` (time s, leg, bytes) of a run over ``protocol`` to ``path``
    (pcap); times are offset so the first frame is at ``epoch`` s.  Returns the
    path."""
    from scapy.layers.inet import IP, TCP
    from scapy.layers.l2 import Ether
    from scapy.utils import wrpcap

    if not frames:
        raise ValueError("no frames to capture")
    legs = _legs(_protocol(protocol).PORT)
    t0 = frames[0][0]
    seq = {leg: 1000 for leg in legs}
    packets = []
    for t, leg, data in frames:
        src, dst, sport, dport = legs[leg]
        pkt = (Ether() / IP(src=src, dst=dst) /
               TCP(sport=sport, dport=dport, flags="PA", seq=seq[leg], ack=seq[BACK[leg]]) / data)
        pkt.time = epoch + (t - t0)
        seq[leg] += len(data)
        packets.append(pkt)
    path = Path(path)
    wrpcap(str(path), packets)
    return path


def read_commands(path: str | Path, protocol: str = "modbus") -> list[tuple[dict, int]]:
    """Every command the generator received, ``(values, seq)``, read back from a
    capture: Modbus/TCP with scapy's own dissector (function-16 writes), DNP3 with
    dnp3py's link-frame parser (the frame's CRCs checked)."""
    from scapy.layers.inet import IP, TCP
    from scapy.utils import rdpcap

    transport = _protocol(protocol)
    if protocol == "modbus":
        from scapy.contrib.modbus import ModbusADURequest  # noqa: F401  (binds port 502)

        from lfc.wire.registers import read_command
    out = []
    for pkt in rdpcap(str(path)):
        if TCP in pkt and pkt[IP].dst == GENERATOR and pkt[TCP].dport == transport.PORT:
            if protocol == "modbus":
                layer = pkt[TCP].payload.payload          # the ADU's PDU
                if getattr(layer, "funcCode", None) == 16:
                    out.append(read_command(list(layer.outputsValue)))
            else:
                command = transport.Codec.command(bytes(pkt[TCP].payload))
                if command is not None:
                    out.append(command)
    return out
