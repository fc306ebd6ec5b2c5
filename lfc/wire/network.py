"""Where the parties of a run over the wire sit: each at its own address on loopback
(the default), or in network namespaces of their own joined by virtual Ethernet links.

An address :class:`Plan` gives the control centre's address and, per area ``a``, its
relay's (where the centre connects to), the relay's on the generator's side (where it
connects to the outstation from) and the outstation's, each ending in ``a + 1``:

===============  ===========  ===============  ====================  ===============
plan             centre       relay ``a``      relay ``a`` upstream  generator ``a``
===============  ===========  ===============  ====================  ===============
:data:`LOOPBACK` 127.0.0.1    127.0.1.(a+1)    127.0.1.(a+1)         127.0.2.(a+1)
:data:`VETH`     10.200.0.1   10.200.1.(a+1)   10.201.1.(a+1)        10.201.2.(a+1)
===============  ===========  ===============  ====================  ===============

:class:`Namespaces` makes the second (root, Linux): three network namespaces, the
control centre's, the substation's (every area's relay, the man in the middle) and
the generators', and two veth pairs, centre–substation (10.200.0.0/16) and
substation–generators (10.201.0.0/16); the man in the middle is then the one path
between the centre and the generators, and a capture on the substation's two links
holds each frame as it crossed the link it crossed (:class:`lfc.wire.sniff.Capture`).
They are removed when the run ends, whatever it raised, and those of a run killed
before it could remove them when the next run makes its own.

A socket belongs to the namespace of the thread that created it (Linux's
``setns``, per thread); :meth:`Namespaces.inside` moves the creating threads there for
the time a party opens its sockets.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import subprocess
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from itertools import count

CLONE_NEWNET = 0x40000000
NETNS_DIR = "/var/run/netns"
PARTIES = ("centre", "substation", "generators")
_runs = count()
_libc = None


@dataclass(frozen=True)
class Plan:
    """Addresses of a run's parties (module docstring): the centre's, and the
    prefixes (three octets) of the relays', the relays' on the generators' side and
    the generators'."""

    centre: str
    relays: str
    relays_upstream: str
    generators: str

    def relay(self, area: int) -> str:
        """Where area ``area``'s relay listens (the centre connects to it)."""
        return f"{self.relays}.{area + 1}"

    def relay_upstream(self, area: int) -> str:
        """Where area ``area``'s relay connects to its outstation from."""
        return f"{self.relays_upstream}.{area + 1}"

    def generator(self, area: int) -> str:
        """Where area ``area``'s outstation listens."""
        return f"{self.generators}.{area + 1}"

    def leg(self, src: str, dst: str) -> tuple[str, int] | None:
        """The leg and area of a packet from ``src`` to ``dst`` under this plan, else
        None."""
        to_relay, from_relay = host_index(dst, self.relays, 1), host_index(src, self.relays, 1)
        if src == self.centre and to_relay is not None:
            return "centre>relay", to_relay
        if dst == self.centre and from_relay is not None:
            return "relay>centre", from_relay
        up, gen = host_index(src, self.relays_upstream, 1), host_index(dst, self.generators, 1)
        if up is not None and up == gen:
            return "relay>generator", up
        gen, up = host_index(src, self.generators, 1), host_index(dst, self.relays_upstream, 1)
        if up is not None and up == gen:
            return "generator>relay", up
        return None


def host_index(address: str, prefix: str, first: int) -> int | None:
    """``n - first`` for the address ``prefix.n`` with ``n >= first``, else None."""
    head, _, tail = address.rpartition(".")
    return int(tail) - first if head == prefix and tail.isdigit() and int(tail) >= first \
        else None


#: every party on loopback (all of 127.0.0.0/8 is this machine's)
LOOPBACK = Plan("127.0.0.1", "127.0.1", "127.0.1", "127.0.2")
#: the parties in namespaces of their own (:class:`Namespaces`)
VETH = Plan("10.200.0.1", "10.200.1", "10.201.1", "10.201.2")
NETWORKS = ("loopback", "namespaces")


class Loopback:
    """Every party on this machine's loopback interface (:data:`LOOPBACK`)."""

    name, plan, interfaces = "loopback", LOOPBACK, ("lo",)

    def __enter__(self) -> Loopback:
        return self

    def __exit__(self, *exc) -> None:
        return None

    def inside(self, party: str, loop=None):
        """A block in which ``party`` opens its sockets: here, anywhere."""
        return nullcontext()


class Namespaces:
    """The parties in network namespaces of their own (module docstring), made on
    entering and removed on leaving.

    Parameters
    ----------
    n_areas : int
        Areas whose relays and generators get addresses (1 to 250).

    Raises
    ------
    PermissionError
        On entering, where namespaces cannot be made (not root, no ``ip``, a
        container without ``CAP_SYS_ADMIN``), saying so and naming the fallback,
        ``network="loopback"``.
    """

    name, plan = "namespaces", VETH
    #: the substation's two links, where a capture sees every frame once
    interfaces = ("to-centre", "to-gens")

    def __init__(self, n_areas: int = 1) -> None:
        if not 1 <= n_areas <= 250:
            raise ValueError(f"n_areas must be in [1, 250], got {n_areas!r}")
        self.n_areas = n_areas
        tag = f"lfc{os.getpid()}-{next(_runs)}"
        self.names = {party: f"{tag}-{party}" for party in PARTIES}
        self._made: list[str] = []

    def __enter__(self) -> Namespaces:
        if shutil.which("ip") is None:
            raise PermissionError("network='namespaces' needs iproute2's ip (Debian's "
                                  "iproute2); network='loopback' runs without it")
        _remove_orphans()
        try:
            self._make()
        except BaseException:
            self.__exit__()
            raise
        return self

    def __exit__(self, *exc) -> None:
        for name in reversed(self._made):
            subprocess.run(["ip", "netns", "delete", name], capture_output=True)
        self._made.clear()

    def _make(self) -> None:
        c, s, g = (self.names[p] for p in PARTIES)
        for name in (c, s, g):
            self._ip("netns", "add", name)
            self._made.append(name)
            self._ip("-n", name, "link", "set", "lo", "up")
        for here, there, near, far in ((c, s, "to-subst", "to-centre"),
                                       (s, g, "to-gens", "to-subst")):
            self._ip("-n", here, "link", "add", near, "type", "veth", "peer", "name", far,
                     "netns", there)
        plan, n = self.plan, self.n_areas
        addresses = {(c, "to-subst"): [plan.centre],
                     (s, "to-centre"): [plan.relay(a) for a in range(n)],
                     (s, "to-gens"): [plan.relay_upstream(a) for a in range(n)],
                     (g, "to-subst"): [plan.generator(a) for a in range(n)]}
        for (name, device), ips in addresses.items():
            for ip in ips:
                self._ip("-n", name, "addr", "add", f"{ip}/16", "dev", device)
            self._ip("-n", name, "link", "set", device, "up")

    def _ip(self, *args: str) -> None:
        done = subprocess.run(["ip", *args], capture_output=True, text=True)
        if done.returncode:
            raise PermissionError(
                f"network='namespaces': `ip {' '.join(args)}` failed ({done.stderr.strip()}): "
                f"making namespaces needs root (or CAP_SYS_ADMIN and CAP_NET_ADMIN); "
                f"network='loopback' runs without them")

    @contextmanager
    def inside(self, party: str, loop=None):
        """A block in which the calling thread, and the event loop's thread ``loop``
        (an :class:`~lfc.wire.relay.EventLoop`) if given, open their sockets in
        ``party``'s namespace (one of ``PARTIES``); both return to where they were."""
        if party not in self.names:
            raise ValueError(f"party must be one of {PARTIES}, got {party!r}")
        path = os.path.join(NETNS_DIR, self.names[party])
        with entered(path):
            if loop is None:
                yield
                return
            saved = loop.run(_in_loop(_enter, path))
            try:
                yield
            finally:
                loop.run(_in_loop(_leave, saved))


def _remove_orphans() -> None:
    """Remove the namespaces of runs whose process is gone (killed before it could
    remove its own): named ``lfc<pid>-<run>-<party>``."""
    if not os.path.isdir(NETNS_DIR):
        return
    for name in os.listdir(NETNS_DIR):
        pid = name[3:].split("-", 1)[0]
        if name.startswith("lfc") and pid.isdigit() and not _alive(int(pid)):
            subprocess.run(["ip", "netns", "delete", name], capture_output=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:      # alive, another user's
        pass
    return True


@contextmanager
def entered(path: str):
    """A block in which the calling thread is in the network namespace ``path`` (a
    file under ``/var/run/netns``): the sockets it creates are that namespace's."""
    saved = _enter(path)
    try:
        yield
    finally:
        _leave(saved)


def _setns(fd: int) -> None:
    global _libc
    _libc = _libc or ctypes.CDLL(None, use_errno=True)
    if _libc.setns(fd, CLONE_NEWNET) != 0:
        raise PermissionError(f"setns: {os.strerror(ctypes.get_errno())}")


def _enter(path: str) -> int:
    """Move the calling thread into the namespace ``path``; return a descriptor of
    the one it left."""
    saved = os.open("/proc/thread-self/ns/net", os.O_RDONLY)
    target = os.open(path, os.O_RDONLY)
    try:
        _setns(target)
    except BaseException:
        os.close(saved)
        raise
    finally:
        os.close(target)
    return saved


def _leave(saved: int) -> None:
    """Move the calling thread back to the namespace ``saved`` (from :func:`_enter`)."""
    try:
        _setns(saved)
    finally:
        os.close(saved)


async def _in_loop(function, argument):
    """``function(argument)`` on the event loop's own thread."""
    return function(argument)
