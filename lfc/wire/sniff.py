"""A run's traffic as the network carried it.

:class:`Capture` reads every packet of the run's network with a raw packet socket
(``AF_PACKET``: root or ``CAP_NET_RAW``) while a run talks, each stamped by the
kernel when it crossed the interface (``SO_TIMESTAMPNS``), and writes those of the
run's connections as a pcap (nanosecond timestamps, Ethernet framing): the
handshakes, the ports the kernel chose, the IP ids, the segments as TCP cut them
and the closing FINs are the network's own.  On loopback (``lo``, which shows each
packet twice, going out and coming in: kept once) or, with the parties in
namespaces of their own (:class:`lfc.wire.network.Namespaces`), on the
substation's two links (each packet crosses one of them once).  The parties'
addresses are the network's plan (:mod:`lfc.wire.network`); the ports are random,
so Wireshark and tshark decode the protocol when told the ports
(``-o mbtcp.tcp.port:P1,P2`` or ``-o dnp3.tcp.port:P1,P2``, the ports in
:attr:`lfc.wire.WireResult.settings` ``["ports"]``; Modbus/TCP tells a query from a
response by that port).
"""

from __future__ import annotations

import socket
import struct
import threading
import time
import warnings
from pathlib import Path

from lfc.wire.network import Loopback

ETH_P_ALL, ETH_P_IP = 0x0003, 0x0800
SOL_PACKET, PACKET_STATISTICS = 263, 6        # Linux: packets seen and dropped by the socket
SO_RCVBUFFORCE = 33                          # Linux: a receive buffer beyond rmem_max (root)
BUFFER = 64 * 2 ** 20                         # bytes the kernel holds while the reader is late
SO_TIMESTAMPNS = 35                  # Linux: the kernel's receive time, as a timespec
PACKET_OUTGOING = 4                  # lo shows each packet twice: outgoing, then incoming
PCAP_NS_MAGIC, LINKTYPE_ETHERNET = 0xA1B23C4D, 1


class Capture:
    """Capture the run's network while the ``with`` block runs (module docstring).

    Parameters
    ----------
    network : Loopback or Namespaces, optional
        The run's network (:mod:`lfc.wire.network`), entered; default: loopback.

    Raises
    ------
    PermissionError
        Without root or ``CAP_NET_RAW``, naming the alternative.
    """

    def __init__(self, network=None) -> None:
        self.network = network or Loopback()
        self.packets: list[tuple[int, bytes]] = []      # (ns since the epoch, frame)
        self.dropped = 0                 # packets the kernel dropped: the reader was late
        self._stop = threading.Event()
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None

    def __enter__(self) -> Capture:
        try:
            with self.network.inside("substation"):
                sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW,
                                     socket.htons(ETH_P_ALL))
        except PermissionError as err:
            raise PermissionError(
                "capture: reading the network's interfaces needs root or CAP_NET_RAW; "
                "without them, lfc.wire.capture.write_pcap(result.frames, path) writes a "
                "capture made from the relay's log") from err
        if self.network.interfaces == ("lo",):
            sock.bind(("lo", 0))
        try:
            sock.setsockopt(socket.SOL_SOCKET, SO_RCVBUFFORCE, BUFFER)
        except OSError:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, BUFFER)
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        sock.getsockopt(SOL_PACKET, PACKET_STATISTICS, 8)        # counting from here
        sock.settimeout(0.05)
        self._sock = sock
        self._thread = threading.Thread(target=self._read, daemon=True, name="lfc-sniff")
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        time.sleep(0.05)                 # the last FINs and ACKs
        self._stop.set()
        self._thread.join(5.0)
        self.dropped = struct.unpack("II", self._sock.getsockopt(SOL_PACKET, PACKET_STATISTICS,
                                                                 8))[1]
        self._sock.close()

    def _read(self) -> None:
        while not self._stop.is_set():
            try:
                data, ancillary, _, address = self._sock.recvmsg(65535, 64)
            except (TimeoutError, socket.timeout):
                continue
            except OSError:
                return
            if address[0] not in self.network.interfaces \
                    or (address[0] == "lo" and address[2] == PACKET_OUTGOING):
                continue
            stamp = time.time_ns()
            for level, kind, value in ancillary:
                if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS:
                    sec, nsec = struct.unpack("qq", value[:16])
                    stamp = sec * 1_000_000_000 + nsec
            self.packets.append((stamp, data))

    def write(self, path: str | Path, ports: set[int]) -> Path:
        """Write the captured TCP packets from or to any of ``ports`` to ``path``
        (pcap, nanosecond timestamps); return the path.  If the kernel dropped
        packets while the capture ran (its reader fell ``BUFFER`` bytes
        behind), the capture may miss some of the run's: a ``RuntimeWarning`` says
        how many were dropped."""
        if self.dropped:
            warnings.warn(f"the capture dropped {self.dropped} packets (the reader fell "
                          f"behind): {path} may miss some of the run's", RuntimeWarning,
                          stacklevel=2)
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        kept = [(t, p) for t, p in self.packets if _tcp_ports(p) & ports]
        with open(path, "wb") as f:
            f.write(struct.pack("<IHHiIII", PCAP_NS_MAGIC, 2, 4, 0, 0, 65535,
                                LINKTYPE_ETHERNET))
            for stamp, packet in kept:
                sec, nsec = divmod(stamp, 1_000_000_000)
                f.write(struct.pack("<IIII", sec, nsec, len(packet), len(packet)) + packet)
        return path


def _tcp_ports(packet: bytes) -> set[int]:
    """The source and destination ports of an Ethernet frame carrying IPv4 TCP, else
    the empty set."""
    if len(packet) < 34 or struct.unpack(">H", packet[12:14])[0] != ETH_P_IP \
            or packet[23] != socket.IPPROTO_TCP:
        return set()
    start = 14 + 4 * (packet[14] & 0x0F)
    if len(packet) < start + 4:
        return set()
    return set(struct.unpack(">HH", packet[start:start + 4]))
