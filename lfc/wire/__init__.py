"""The attack on a real industrial protocol: control centre, man in the middle and
generator talking Modbus/TCP or DNP3 over loopback sockets (:mod:`lfc.wire.run`),
the register map and point list (:mod:`lfc.wire.registers`,
:mod:`lfc.wire.dnp3`), the attacks as data (:mod:`lfc.wire.attacks`), the relay
(:mod:`lfc.wire.relay`) and one module per protocol (:mod:`lfc.wire.modbus`,
:mod:`lfc.wire.dnp3`), the operator's forensic estimate
(:mod:`lfc.wire.forensics`), captures (:mod:`lfc.wire.capture`) and a network
detector over them (:mod:`lfc.wire.detect`).  Needs
``pymodbus`` or ``dnp3py`` (imported when a run starts) and ``scapy`` for captures."""

from lfc.wire.attacks import ATTACKS, WireAttack
from lfc.wire.relay import Impairment
from lfc.wire.run import WireResult, run_wire

__all__ = ["ATTACKS", "Impairment", "WireAttack", "WireResult", "run_wire"]
