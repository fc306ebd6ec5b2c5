"""The attack on a real industrial protocol: control centre, man in the middle and
generator talking Modbus/TCP over loopback sockets (:mod:`lfc.wire.run`), the
register map (:mod:`lfc.wire.registers`), the attacks as data
(:mod:`lfc.wire.attacks`) and the transport (:mod:`lfc.wire.modbus`).  Needs
``pymodbus`` (imported when a run starts)."""

from lfc.wire.attacks import ATTACKS, WireAttack
from lfc.wire.run import WireResult, run_wire

__all__ = ["ATTACKS", "WireAttack", "WireResult", "run_wire"]
