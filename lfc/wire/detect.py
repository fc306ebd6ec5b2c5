"""A network detector over a run's traffic: rules an operator could deploy at a tap.

A tap sees one side of the man in the middle: the **substation** tap the generator's
LAN (legs ``relay>generator`` and ``generator>relay``: what the generator receives and
answers), the **centre** tap the control centre's (``centre>relay``, ``relay>centre``:
what the centre sends and is told).  Frames come from a run
(:attr:`lfc.wire.run.WireResult.frames`) or a capture
(:func:`lfc.wire.capture.read_frames`).  Every rule reads only what its tap carries;
``end-to-end`` alone compares the two taps (a utility that keeps both logs).

=============  ========  ===================================================================
rule           tap       raises when
=============  ========  ===================================================================
range          each      a command's ``wref`` lies outside the relays' band ``(uf2 - 1,
                         of2 - 1)`` (such a reference orders a trip), or ``pc`` or ``ace``
                         beyond ``command_range`` (pu)
rate           each      ``pc`` moves between consecutive commands faster than ``rate_limit``
                         (pu/s) — by default the fastest a legitimate AGC moves it, ``k_i ×
                         max(of2 - 1, 1 - uf2)`` (its integral gain times the largest
                         frequency deviation no relay trips at)
sequence       each      a command's period counter is not the previous one's plus 1 (a gap:
                         commands lost or dropped; a repeat or a step back: a replay or an
                         injection); the protocol's own counters likewise (the Modbus
                         transaction id of the requests, DNP3's transport sequence on each
                         direction)
status         each      the generator reports a refusal or a restart: a Modbus exception
                         response; a DNP3 response whose internal indications carry an
                         error of IIN2 (function not supported, object unknown, parameter
                         error) or a DEVICE_RESTART once one was cleared
peer           each      a frame from or to a station not in the map: a DNP3 link address
                         other than the centre's (2) and the generator's (1), a frame with
                         the wrong direction bit, a Modbus unit id other than 1
malformed      each      a frame that is not the protocol's: a Modbus/TCP frame whose MBAP
                         protocol id is not 0 or whose length disagrees with its bytes, a DNP3
                         frame without the start bytes ``05 64`` or whose CRCs fail
end-to-end     both      a command the centre sent that the generator did not receive
                         identically (lost or altered), a report the centre read that the
                         generator did not send (altered), an acknowledgement the centre got
                         that the generator never sent (forged)
=============  ========  ===================================================================

Every alert carries the control period it concerns (``period``: the counter of the
command it is about, or, for a frame that carries none, the period under way on that
stream — the last command's, or the one after the last report's) and its simulated
time ``t = period × control_period``.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import pandas as pd

from lfc._validate import check_finite, check_positive, is_sequence
from lfc.relays import RelaySettings

TAPS = ("substation", "centre")
RULES = ("range", "rate", "sequence", "status", "peer", "malformed", "end-to-end")
LEGS = {"centre>relay": ("centre", "request"), "relay>centre": ("centre", "response"),
        "relay>generator": ("substation", "request"),
        "generator>relay": ("substation", "response")}
COLUMNS = ["period", "t", "area", "tap", "rule", "detail"]
IIN2_ERRORS = 0x07            # IIN2.0-2: function not supported, object unknown, parameter error
DEVICE_RESTART = 0x80         # IIN1.7


@dataclass(frozen=True)
class Rules:
    """The detector's thresholds (module docstring).

    Parameters
    ----------
    control_period : float
        The command period (s) the rates are measured over.
    wref_range : tuple of float
        ``(low, high)``, pu: the frequency references no relay trips at
        (:meth:`for_area`: ``(uf2 - 1, of2 - 1)``).
    rate_limit : float
        The fastest ``pc`` moves legitimately (pu/s).
    command_range : float
        The largest ``|pc|`` and ``|ace|`` (pu).
    rules : tuple of str
        The rules that raise alerts (default: every one of ``RULES``).
    """

    control_period: float
    wref_range: tuple[float, float]
    rate_limit: float
    command_range: float = 1.0
    rules: tuple[str, ...] = RULES

    def __post_init__(self) -> None:
        for name in ("control_period", "rate_limit", "command_range"):
            check_positive(name, getattr(self, name))
        if not is_sequence(self.wref_range) or len(self.wref_range) != 2:
            raise ValueError(f"wref_range must be a pair (low, high), got {self.wref_range!r}")
        for i, v in enumerate(self.wref_range):
            check_finite(f"wref_range[{i}]", v)
        if not self.wref_range[0] < 0.0 < self.wref_range[1]:
            raise ValueError(f"wref_range must be (low, high) with low < 0 < high, got "
                             f"{self.wref_range!r}")
        unknown = set(self.rules) - set(RULES)
        if isinstance(self.rules, str) or unknown:
            raise ValueError(f"rules must be a tuple of {RULES}, got {self.rules!r}")

    @classmethod
    def for_area(cls, control_period: float, k_i: float = 2.0,
                 relays: RelaySettings | None = None, **kwargs) -> Rules:
        """The rules of an area with AGC integral gain ``k_i`` (pu/(pu s), the
        default :class:`lfc.LFCParams`') and relay settings ``relays``
        (:class:`lfc.RelaySettings`' defaults): ``wref_range`` is the relays' band
        ``(uf2 - 1, of2 - 1)`` and ``rate_limit`` the fastest the AGC's integrator
        moves its command while no frequency relay trips, ``k_i × max(of2 - 1, 1 -
        uf2)`` (0.116 pu/s by default).  ``kwargs`` override either or set the rest."""
        relays = relays or RelaySettings()
        band = (relays.uf2 - 1.0, relays.of2 - 1.0)
        kwargs.setdefault("wref_range", band)
        kwargs.setdefault("rate_limit", k_i * max(-band[0], band[1]))
        return cls(control_period, **kwargs)


@dataclass
class _Frame:
    wall: float
    area: int
    tap: str
    direction: str
    kind: str                     # "command", "report", "ack" or "other"
    seq: int | None = None        # the period counter the frame carries
    values: dict | None = None
    counter: int | None = None    # Modbus transaction id, DNP3 transport sequence
    modulus: int = 1
    iin: int | None = None        # DNP3's internal indications
    exception: int | None = None  # a Modbus exception response's code
    stranger: str | None = None   # why the frame's addressing is not the map's
    malformed: str | None = None  # why the frame is not the protocol's


def _modbus(data: bytes) -> dict:
    from lfc.wire import modbus
    if len(data) < 8 or data[2:4] != b"\x00\x00" or \
            struct.unpack(">H", data[4:6])[0] != len(data) - 6:
        return {"malformed": f"not a Modbus/TCP frame ({data[:8].hex()})"}
    out: dict = {"counter": struct.unpack(">H", data[:2])[0], "modulus": 65536}
    if data[6] != 1:
        out["stranger"] = f"Modbus unit id {data[6]} (the generator's is 1)"
    if len(data) >= 9 and data[7] & 0x80:
        out["exception"] = data[8]
    out.update(_carried(modbus.Codec, data))
    if "kind" not in out and data[7] == modbus.WRITE and len(data) == 12:
        out.update(kind="ack")
    return out


def _carried(codec, data: bytes) -> dict:
    """The command or report a frame carries, as ``_Frame`` fields (none: ``{}``)."""
    command = codec.command(data)
    if command is not None:
        return {"kind": "command", "values": command[0], "seq": command[1]}
    report = codec.report(data)
    if report is not None:
        return {"kind": "report", "values": report, "seq": report["seq"]}
    return {}


def _dnp3(data: bytes, direction: str) -> dict:
    from lfc.wire import dnp3
    if len(data) < 10 or data[:2] != b"\x05\x64":
        return {"malformed": f"not a DNP3 link frame ({data[:10].hex()})"}
    out: dict = {"modulus": 64}
    control, dest, src = data[3], *struct.unpack("<HH", data[4:8])
    request = direction == "request"
    want = (dnp3.OUTSTATION, dnp3.MASTER) if request else (dnp3.MASTER, dnp3.OUTSTATION)
    if (dest, src) != want:
        out["stranger"] = f"DNP3 link {src} -> {dest} (the map's: {want[1]} -> {want[0]})"
    elif bool(control & 0x80) != request:
        out["stranger"] = f"DNP3 direction bit {control >> 7} on a {direction}"
    try:
        user = dnp3._user_data(data)
    except Exception as err:             # noqa: BLE001  (a frame dnp3py's parser refuses)
        return {**out, "malformed": f"DNP3 frame refused by the parser: {err}"}
    if user:
        out["counter"] = user[0] & 0x3F
    out.update(_carried(dnp3.Codec, data))
    if len(user) >= 5 and user[2] == dnp3.RESPONSE:
        out["iin"] = user[3] << 8 | user[4]
        # the echo of a command: g41v4, then point 3 (seq) at 9 + 30: index, value, status
        if out.get("kind") is None and tuple(user[5:8]) == (41, 4, 0x17) \
                and len(user) >= 49 and user[39] == 3:
            echo = struct.unpack("<d", user[40:48])[0]
            out.update(kind="ack", seq=int(echo) if math.isfinite(echo) else None)
    return out


def parse(frames: list, protocol: str) -> list[_Frame]:
    """Each frame ``(wall-clock s, leg, bytes, area)`` as the detector reads it."""
    if protocol not in ("modbus", "dnp3"):
        raise ValueError(f"protocol must be 'modbus' or 'dnp3', got {protocol!r}")
    out = []
    for wall, leg, data, area in frames:
        if leg not in LEGS:
            raise ValueError(f"frames: leg must be one of {sorted(LEGS)}, got {leg!r}")
        tap, direction = LEGS[leg]
        fields = _modbus(data) if protocol == "modbus" else _dnp3(data, direction)
        out.append(_Frame(wall, area, tap, direction, **{"kind": "other", **fields}))
    if out and all(f.malformed for f in out):
        raise ValueError(f"frames: none is a {protocol} frame (the first: "
                         f"{out[0].malformed}); is protocol right?")
    return out


def detect(frames: list, protocol: str, rules: Rules,
           taps: tuple[str, ...] = TAPS) -> pd.DataFrame:
    """The alerts the rules raise on ``frames`` seen at ``taps`` (module docstring).

    Parameters
    ----------
    frames : list of (float, str, bytes, int)
        Wall-clock time (s), leg, bytes and area of every frame
        (:attr:`lfc.wire.run.WireResult.frames`, :func:`lfc.wire.capture.read_frames`).
    protocol : str
        ``"modbus"`` or ``"dnp3"``.
    rules : Rules
    taps : tuple of str
        The taps the detector has: ``("substation",)``, ``("centre",)`` or both
        (``end-to-end`` needs both).

    Returns
    -------
    DataFrame
        One row per alert: ``period``, ``t`` (s, simulated: ``period ×
        control_period``), ``area``, ``tap``, ``rule``, ``detail``; sorted by
        ``t``, then area and tap.
    """
    if not taps or set(taps) - set(TAPS):
        raise ValueError(f"taps must be a non-empty tuple of {TAPS}, got {taps!r}")
    parsed = [f for f in parse(frames, protocol) if f.tap in taps]
    alerts: list[tuple] = []
    streams: dict[tuple[int, str], list[_Frame]] = {}
    for f in parsed:
        streams.setdefault((f.area, f.tap), []).append(f)
    for (area, tap), stream in sorted(streams.items()):
        alerts += _one_tap(stream, area, tap, rules)
    if "end-to-end" in rules.rules and set(taps) == set(TAPS):
        for area in sorted({f.area for f in parsed}):
            alerts += _end_to_end(streams.get((area, "centre"), []),
                                  streams.get((area, "substation"), []), area)
    table = pd.DataFrame(alerts, columns=["period", "area", "tap", "rule", "detail"])
    table.insert(1, "t", table.period.astype(float) * rules.control_period)
    return table.sort_values(["t", "area", "tap"], kind="stable").reset_index(drop=True)[
        COLUMNS]


def _one_tap(stream: list[_Frame], area: int, tap: str, rules: Rules) -> list[tuple]:
    on = set(rules.rules)
    out: list[tuple] = []
    period = 0
    last_command: _Frame | None = None
    counters: dict[str, int] = {}
    restarted: bool | None = None

    def alert(rule: str, detail: str) -> None:      # at the period under way
        if rule in on:
            out.append((period, area, tap, rule, detail))

    for f in stream:
        if f.seq is not None and f.kind == "command":
            period = f.seq

        if f.malformed is not None:
            alert("malformed", f.malformed)
            continue
        if f.stranger is not None:
            alert("peer", f.stranger)
        if f.counter is not None and (f.direction == "request" or f.modulus == 64):
            before = counters.get(f.direction)
            if before is not None and f.counter != (before + 1) % f.modulus:
                alert("sequence", f"{f.direction} counter {f.counter} after {before}")
            counters[f.direction] = f.counter
        if f.exception is not None:
            alert("status", f"Modbus exception {f.exception}")
        if f.iin is not None:
            if f.iin & IIN2_ERRORS:
                alert("status", f"IIN 0x{f.iin:04x}: an error of IIN2")
            restart = bool(f.iin >> 8 & DEVICE_RESTART)
            if restart and restarted is False:
                alert("status", f"IIN 0x{f.iin:04x}: DEVICE_RESTART again")
            restarted = restart if restarted is not False else False
        if f.kind == "report" and f.seq is not None:
            period = f.seq + 1     # the period's exchange is over: what follows is the next
        if f.kind != "command":
            continue
        v = f.values
        low, high = rules.wref_range
        if not low <= v["wref"] <= high:
            alert("range", f"wref {v['wref']:+.4g} pu outside the relays' band "
                           f"[{low:.4g}, {high:.4g}]")
        for name in ("pc", "ace"):
            if abs(v[name]) > rules.command_range:
                alert("range", f"{name} {v[name]:+.4g} pu beyond ±{rules.command_range:g}")
        if last_command is not None:
            gap = (f.seq - last_command.seq) % 65536
            if gap != 1:
                alert("sequence", f"command {f.seq} after {last_command.seq}")
            rate = abs(v["pc"] - last_command.values["pc"]) / (
                max(gap, 1) * rules.control_period)
            if rate > rules.rate_limit:
                alert("rate", f"pc moved at {rate:.3g} pu/s (limit {rules.rate_limit:.3g})")
        last_command = f
    return out


def _end_to_end(centre: list[_Frame], substation: list[_Frame], area: int) -> list[tuple]:
    out: list[tuple] = []
    got = _by_occurrence(substation, "command")
    published = _by_occurrence(substation, "report")
    acks = _ack_keys(substation)
    for key, f in _by_occurrence(centre, "command").items():
        if key not in got:
            out.append((f.seq, area, "both", "end-to-end",
                        f"command {f.seq} sent, never received"))
        elif got[key].values != f.values:
            changed = sorted(k for k in f.values if got[key].values.get(k) != f.values[k])
            out.append((f.seq, area, "both", "end-to-end",
                        f"command {f.seq} altered ({', '.join(changed)})"))
    for key, f in _by_occurrence(centre, "report").items():
        theirs = published[key].values if key in published else {}
        if theirs != f.values:
            changed = sorted(k for k in f.values if theirs.get(k) != f.values[k])
            out.append((f.seq, area, "both", "end-to-end",
                        f"report {f.seq} altered ({', '.join(changed)})"))
    for key, period in _ack_keys(centre).items():
        if key not in acks:
            out.append((period, area, "both", "end-to-end",
                        f"acknowledgement of command {period} forged"))
    return out


def _by_occurrence(stream: list[_Frame], kind: str) -> dict[tuple[int, int], _Frame]:
    """The frames of ``kind``, keyed by their counter and its occurrence (the
    second report numbered 0 is ``(0, 1)``): the same key on both taps is the same
    frame, forwarded."""
    out: dict[tuple[int, int], _Frame] = {}
    seen: dict[int, int] = {}
    for f in stream:
        if f.kind == kind and f.seq is not None:
            n = seen[f.seq] = seen.get(f.seq, -1) + 1
            out[f.seq, n] = f
    return out


def _ack_keys(stream: list[_Frame]) -> dict:
    """Each acknowledgement's key (DNP3: the command it echoes; Modbus: its
    transaction id) and the period it acknowledges."""
    out, period = {}, 0
    for f in stream:
        if f.kind in ("command", "report") and f.seq is not None:
            period = f.seq
        if f.kind == "ack":
            out[f.seq if f.seq is not None else f.counter] = (
                f.seq if f.seq is not None else period)
    return out
