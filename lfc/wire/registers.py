"""The register map of the generator outstation, and how numbers travel in it.

Modbus/TCP carries 16-bit registers.  Every quantity is an IEEE 754 binary64
(float64) in four consecutive registers, most significant word first (each
word big-endian, as Modbus sends every register): a pu value crosses the wire
bit for bit, which is what lets a run over the wire equal ``lfc.simulate``.
The period counter and the bit fields are one register each.

=========  ====  ========  ======  =====================================================
block      addr  count     type    meaning
=========  ====  ========  ======  =====================================================
holding    0     4         f64     ``pc``: the governor command (pu): the AGC's output
                                   (``agc="centre"``) or a supplement added to the local
                                   integrator's (``agc="generator"``; sent 0; the
                                   channel of ``pc_attack`` in ``lfc.simulate``)
holding    4     4         f64     ``wref``: the frequency reference (pu) the local
                                   integrator tracks (``agc="generator"``: the channel
                                   of ``wref_attack``; sent 0)
holding    8     4         f64     ``ace``: added to the tie-line export the AGC reads
                                   (pu; ``ace_attack``; sent 0; one area: unused)
holding    12    1         u16     ``seq``: the control period's index, modulo 65536
input      0     1         u16     ``seq``: the period the report belongs to
input      1     4         f64     ``dw_meas``: measured frequency deviation (pu)
input      5     4         f64     ``rocof_meas``: measured ROCOF (pu/s)
input      9     4         f64     ``pc_received``: ``pc`` as it arrived (pu)
input      13    4         f64     ``u_ref``: the command the filter received (pu; with
                                   ``agc="generator"`` the local integrator's output
                                   plus ``pc``)
input      17    4         f64     ``u``: the command applied (pu)
input      21    1         u16     ``flags``: the filter's flag bits (lfc.filters.base)
input      22    1         u16     ``trips``: relays tripped in the period (bit 0 OF2,
                                   1 UF2, 2 ROCOF)
input      23    1         u16     ``link``: 1 if no command arrived for the period
                                   (the generator held the last one)
=========  ====  ========  ======  =====================================================
"""

from __future__ import annotations

import math
import struct

from lfc.filters.base import MAX_ABS_INPUT

COMMAND = ("pc", "wref", "ace")        # holding registers, four each from 0
SEQ = 12                               # holding register of the period counter
N_COMMAND = 13                         # registers written each period (FC16 at 0)
REPORT = ("dw_meas", "rocof_meas", "pc_received", "u_ref", "u")   # input registers, four each from 1
FLAGS, TRIPS, LINK = 21, 22, 23
N_REPORT = 24                          # registers read each period (FC4 at 0)


def encode(values: list[float]) -> list[int]:
    """Each float as four 16-bit registers (binary64, most significant word first)."""
    return list(struct.unpack(f">{4 * len(values)}H", struct.pack(f">{len(values)}d", *values)))


def decode(registers: list[int]) -> list[float]:
    """The floats of :func:`encode`'s registers (a multiple of four)."""
    n = len(registers) // 4
    return list(struct.unpack(f">{n}d", struct.pack(f">{4 * n}H", *registers[:4 * n])))


def command_registers(values: dict[str, float], seq: int) -> list[int]:
    """The 13 holding registers of one period's command."""
    return encode([values[c] for c in COMMAND]) + [seq % 65536]


def setpoint_problem(values: dict[str, float], seq: float) -> str | None:
    """Why an outstation refuses a command (its protocol's range error), or None:
    a value of ``pc``, ``wref`` or ``ace`` that is not finite or is beyond
    ``MAX_ABS_INPUT`` (1e6 pu: what no measurement or command comes near, the
    filters' invalid input), or a sequence number that is not an integer in
    [0, 65535].  Both protocols check with this one rule."""
    for name in COMMAND:
        if name not in values:
            return f"{name} missing (a command carries {', '.join(COMMAND)} and seq at once)"
        problem = value_problem(name, values[name])
        if problem is not None:
            return problem
    return seq_problem(seq)


def value_problem(name: str, value: float) -> str | None:
    """Why ``value`` cannot be command ``name``'s (not finite, or beyond
    ``MAX_ABS_INPUT`` pu), or None."""
    if isinstance(value, float | int) and math.isfinite(value) and abs(value) <= MAX_ABS_INPUT:
        return None
    return f"{name}={value!r:.30} is not a finite value within ±{MAX_ABS_INPUT:g} pu"


def seq_problem(seq: float) -> str | None:
    """Why ``seq`` cannot be a period's sequence number (an integer in [0, 65535])."""
    if isinstance(seq, float | int) and math.isfinite(seq) and seq == int(seq) \
            and 0 <= seq <= 0xFFFF:
        return None
    return f"seq={seq!r:.30} is not an integer in [0, 65535]"


def _well_formed(registers: list[int], n: int) -> bool:
    """Whether ``registers`` are ``n`` values of 16 bits."""
    return len(registers) == n and all(isinstance(r, int) and 0 <= r <= 0xFFFF
                                       for r in registers)


def read_command(registers: list[int]) -> tuple[dict[str, float], int] | None:
    """``(values, seq)`` of :func:`command_registers`'s registers; None for a
    malformed write (not ``N_COMMAND`` registers of 16 bits), which the
    generator side then counts as a command that did not arrive."""
    if not _well_formed(registers, N_COMMAND):
        return None
    return dict(zip(COMMAND, decode(registers[:SEQ]))), registers[SEQ]


def report_registers(seq: int, values: dict[str, float], flags: int, trips: int,
                     link: int) -> list[int]:
    """The 24 input registers of one period's report."""
    return [seq % 65536] + encode([values[c] for c in REPORT]) + [int(flags) & 0xFFFF,
                                                                   int(trips), int(link)]


def read_report(registers: list[int]) -> dict | None:
    """The fields of :func:`report_registers`'s registers; None for a malformed
    response (not ``N_REPORT`` registers of 16 bits)."""
    if not _well_formed(registers, N_REPORT):
        return None
    out = dict(zip(REPORT, decode(registers[1:FLAGS])))
    out.update(seq=registers[0], flags=registers[FLAGS], trips=registers[TRIPS],
               link=registers[LINK])
    return out
