"""Issue "Field", item 5: the network detector (``lfc.wire.detect``) over a run's
frames and over its capture — silent on clean lockstep runs, each named attack seen by
the rule that should see it and when it starts, each rule's corner, its thresholds
checked, and the table of who detects what (``lfc.experiments.detection``)."""

from __future__ import annotations

import math
import struct

import pytest
import tiers
from hypothesis import given, settings
from hypothesis import strategies as st

import lfc
from lfc.wire import run_wire
from lfc.wire.run import transport
from lfc.wire.detect import COLUMNS, LEGS, RULES, Rules, detect
from lfc.wire.registers import command_registers

pytest.importorskip("pymodbus")

PARAMS, RELAYS = lfc.LFCParams(), lfc.RelaySettings()
RULES_10MS = Rules.for_area(0.01, PARAMS.k_i, RELAYS)
LOAD = lfc.Step(0.1, start=0.5)


def wire(attack, protocol: str, agc: str = "centre", duration: float = 2.0, **kw):
    return run_wire(PARAMS, duration=duration, attack=attack, protocol=protocol, agc=agc,
                    load=LOAD, **kw)


def test_the_default_thresholds_come_from_the_relays_and_the_agc_gain():
    assert RULES_10MS.wref_range == pytest.approx((RELAYS.uf2 - 1.0, RELAYS.of2 - 1.0))
    assert RULES_10MS.rate_limit == pytest.approx(PARAMS.k_i * 0.058)        # 0.116 pu/s
    assert Rules.for_area(0.01, rate_limit=0.5).rate_limit == 0.5


@pytest.mark.parametrize("kwargs, name", [
    ({"control_period": 0.0}, "control_period"), ({"rate_limit": math.nan}, "rate_limit"),
    ({"command_range": -1.0}, "command_range"), ({"wref_range": (0.01, 0.03)}, "wref_range"),
    ({"wref_range": (-0.05, math.inf)}, "wref_range"), ({"wref_range": 0.03}, "wref_range"),
    ({"rules": ("rate", "magic")}, "rules"), ({"rules": "rate"}, "rules")])
def test_bad_thresholds_are_refused_naming_them(kwargs, name):
    base = {"control_period": 0.01, "wref_range": (-0.05, 0.03), "rate_limit": 0.1}
    with pytest.raises(ValueError, match=name):
        Rules(**{**base, **kwargs})


def test_bad_taps_and_protocols_are_refused():
    with pytest.raises(ValueError, match="taps"):
        detect([], "modbus", RULES_10MS, taps=("plant",))
    with pytest.raises(ValueError, match="protocol"):
        detect([], "iec104", RULES_10MS)
    assert list(detect([], "modbus", RULES_10MS).columns) == COLUMNS


@pytest.mark.parametrize("protocol", ["modbus", "dnp3"])
@pytest.mark.parametrize("agc", ["centre", "generator"])
def test_a_clean_lockstep_run_raises_nothing(protocol, agc):
    """A legitimate 0.1 pu load step moves the AGC's commands: no rule fires at
    either tap, with or without the filter."""
    scc = lfc.SafetyFilter(PARAMS, RELAYS, alpha=20.0)
    assert detect(wire("none", protocol, agc, scc=scc).frames, protocol, RULES_10MS).empty


#: attack: (agc, the rules the substation tap raises, end to end)
SEEN = {"fig4": ("centre", {"rate"}, True), "fig4-weak": ("centre", {"rate"}, True),
        "fig5": ("generator", {"range"}, True), "fig5-told": ("centre", set(), True),
        "delay-2": ("centre", set(), True), "drop": ("centre", {"sequence"}, True)}


@pytest.mark.parametrize("protocol", ["modbus", "dnp3"])
@pytest.mark.parametrize("attack", sorted(SEEN))
def test_each_attack_is_seen_by_its_rule_from_its_start_and_never_before(protocol, attack):
    agc, local, end_to_end = SEEN[attack]
    alerts = detect(wire(attack, protocol, agc).frames, protocol, RULES_10MS)
    substation = alerts[alerts.tap == "substation"]
    assert set(substation.rule) == local
    assert (alerts.rule == "end-to-end").any() == end_to_end
    assert alerts.t.min() >= 1.0 - 1e-12          # every attack starts at 1 s
    if attack == "drop":    # 1-1.5 s: 50 periods lost; the centre got 50 forged answers
        forged = alerts.detail.str.contains("forged")
        assert forged.sum() == 50 and alerts[forged].t.between(1.0, 1.5).all()
        assert alerts.detail.str.contains("never received").sum() == 50


def test_a_report_before_the_first_command_is_not_attacked():
    """DNP3's startup integrity poll reads a report before any command: the attack on
    the reports acts from its own start (1 s), not at the run's last instant (the
    relay read period -1 as the last one: 'report 0 altered' before the fix)."""
    alerts = detect(wire("fig5-told", "dnp3").frames, "dnp3", RULES_10MS)
    assert alerts.t.min() == pytest.approx(1.0)


def test_the_capture_gives_the_detector_the_same_frames_on_a_grid(tmp_path):
    from lfc.wire.capture import read_frames, write_pcap
    grid = lfc.MultiAreaParams.two_area()
    run = run_wire(grid, duration=1.5, attack={1: "drop"}, protocol="dnp3")
    frames = read_frames(write_pcap(run.frames, tmp_path / "grid.pcap", protocol="dnp3"), "dnp3")
    assert [f[1:] for f in frames] == [f[1:] for f in run.frames]
    alerts = detect(frames, "dnp3", RULES_10MS)
    assert alerts.equals(detect(run.frames, "dnp3", RULES_10MS))
    assert set(alerts.area) == {1}


# ---- each rule at its corner, on frames built by hand -------------------------------

def _modbus_write(seq: int, txn: int, unit: int = 1, **values) -> bytes:
    regs = command_registers({"pc": 0.0, "wref": 0.0, "ace": 0.0, **values}, seq)
    pdu = struct.pack(">BHHB", 16, 0, len(regs), 2 * len(regs)) + struct.pack(
        f">{len(regs)}H", *regs)
    return struct.pack(">HHHB", txn, 0, len(pdu) + 1, unit) + pdu


def _writes(commands: list[dict], **kw) -> list:
    return [(0.01 * j, "relay>generator", _modbus_write(j, j, **{**c, **kw}), 0)
            for j, c in enumerate(commands)]


def test_the_rate_rule_at_its_limit():
    step = RULES_10MS.rate_limit * 0.01
    assert detect(_writes([{"pc": 0.0}, {"pc": step}]), "modbus", RULES_10MS).empty
    alerts = detect(_writes([{"pc": 0.0}, {"pc": 1.001 * step}]), "modbus", RULES_10MS)
    assert list(alerts.rule) == ["rate"] and alerts.period.iat[0] == 1


def test_the_range_rule_at_the_relays_band_and_the_command_range():
    low, high = RULES_10MS.wref_range
    assert detect(_writes([{"wref": low}, {"wref": high}]), "modbus",
                  Rules.for_area(0.01, rate_limit=1e9)).empty
    for values in ({"wref": math.nextafter(high, 1.0)}, {"wref": math.nextafter(low, -1.0)},
                   {"ace": 1.0 + 1e-12}):
        alerts = detect(_writes([values]), "modbus", RULES_10MS)
        assert list(alerts.rule) == ["range"], values


def test_the_sequence_rule_sees_a_gap_a_repeat_and_a_step_back():
    frames = _writes([{}] * 3)
    for seq in (4, 2, 1):        # a gap of one, a repeat, a step back
        alerts = detect(frames + [(0.05, "relay>generator", _modbus_write(seq, 3), 0)],
                        "modbus", RULES_10MS)
        assert "sequence" in set(alerts.rule), seq


def test_the_peer_and_status_rules():
    alerts = detect(_writes([{}, {}], unit=7), "modbus", RULES_10MS)
    assert set(alerts.rule) == {"peer"} and len(alerts) == 2
    exception = struct.pack(">HHHBBB", 1, 0, 3, 1, 16 | 0x80, 3)        # illegal value
    alerts = detect([(0.0, "generator>relay", exception, 0)], "modbus", RULES_10MS)
    assert list(alerts.rule) == ["status"] and "exception 3" in alerts.detail.iat[0]


def _dnp3(user_data: bytes, source: int = 1, destination: int = 2,
          from_master: bool = False) -> bytes:
    from dnp3.datalink.builder import build_unconfirmed_user_data
    return build_unconfirmed_user_data(destination=destination, source=source,
                                       dir_from_master=from_master,
                                       user_data=user_data).to_bytes()


@pytest.mark.parametrize("iin, raised", [(0x8000, False), (0x0000, False), (0x0004, True),
                                         (0x0001, True)])
def test_dnp3_internal_indications(iin, raised):
    """DEVICE_RESTART at start-up is normal, once cleared it is not; an error bit of
    IIN2 always raises."""
    pytest.importorskip("dnp3")

    def response(seq: int, iin: int) -> tuple:
        app = bytes([0xC0, 0x81, iin >> 8, iin & 0xFF])
        return (0.0, "generator>relay", _dnp3(bytes([0xC0 | seq]) + app), 0)

    frames = [response(0, 0x8000), response(1, 0x0000), response(2, iin)]
    alerts = detect(frames, "dnp3", RULES_10MS)
    restart_again = iin & 0x8000 != 0
    assert (not alerts.empty) == (raised or restart_again)
    assert set(alerts.rule) <= {"status"}


def test_dnp3_strangers_and_the_direction_bit():
    pytest.importorskip("dnp3")
    ok = (0.0, "relay>generator", _dnp3(b"\xc0\xc0\x01", 2, 1, True), 0)
    stranger = (0.0, "relay>generator", _dnp3(b"\xc1\xc1\x01", 9, 1, True), 0)
    wrong_way = (0.0, "relay>generator", _dnp3(b"\xc2\xc2\x01", 2, 1, False), 0)
    assert detect([ok], "dnp3", RULES_10MS).empty
    alerts = detect([ok, stranger, wrong_way], "dnp3", RULES_10MS)
    assert list(alerts.rule) == ["peer", "peer"]
    assert "9 -> 1" in alerts.detail.iat[0] and "direction" in alerts.detail.iat[1]


@settings(max_examples=tiers.examples(200), deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=2, max_size=30),
       st.floats(-0.058, 0.03), st.integers(0, 65535))
def test_legitimate_commands_raise_nothing(fractions, wref, first):
    """Any command stream a legitimate AGC can send — consecutive period counters,
    ``pc`` moving at most ``rate_limit`` per second, ``wref`` in the relays' band —
    raises no alert, whatever counter it starts from (the counters wrap at 65536)."""
    step = RULES_10MS.rate_limit * 0.01 * (1 - 1e-9)
    pc, frames = 0.0, []
    for j, f in enumerate(fractions):
        pc += f * step
        seq = (first + j) % 65536
        frames.append((0.01 * j, "relay>generator",
                       _modbus_write(seq, seq, pc=pc, wref=wref), 0))
    assert detect(frames, "modbus", RULES_10MS).empty


def test_every_rule_can_be_switched_off():
    frames = _writes([{"wref": 0.5}, {"wref": 0.5, "pc": 0.9}])
    assert set(detect(frames, "modbus", RULES_10MS).rule) == {"range", "rate"}
    only = Rules.for_area(0.01, rules=tuple(r for r in RULES if r != "range"))
    assert set(detect(frames, "modbus", only).rule) == {"rate"}


def test_the_chapters_detection_claims_hold_at_its_defaults():
    """Chapter 11's table (every named attack, both protocols, lockstep, the
    notebook's duration and filter) and its claims (``detection_claims``)."""
    import chapters

    from lfc.experiments.claims import detection_claims
    from lfc.experiments.detection import detection_table
    p = chapters.defaults("wire")
    scc = lfc.SafetyFilter(PARAMS, RELAYS, alpha=p["alpha"])
    table = detection_table(PARAMS, scc, duration=p["detection_duration"], progress=False)
    claims = detection_claims(table)
    assert all(claims.values()), claims
    assert not table.tripped.any()
    verdicts = table.groupby("attack")["detected by"].agg(set).to_dict()
    assert verdicts == {"none": {"neither"}, "fig4": {"traffic and SCC"},
                        "fig4-weak": {"traffic only"}, "fig5": {"traffic only"},
                        "fig5-told": {"SCC only"}, "delay-2": {"neither"},
                        "drop": {"traffic and SCC"}}
    with pytest.raises(ValueError, match="attacks"):
        detection_table(PARAMS, scc, attacks=("fig9",), progress=False)


def test_a_frame_not_of_the_protocol_is_malformed_and_a_capture_of_another_is_refused():
    good = _writes([{}, {}])
    garbage = (0.02, "relay>generator", b"\x00\x02\x00\x07\x00\x09\x01\x10\x00", 0)
    alerts = detect(good + [garbage], "modbus", RULES_10MS)
    assert list(alerts.rule) == ["malformed"]
    with pytest.raises(ValueError, match="none is a dnp3 frame"):
        detect(good, "dnp3", RULES_10MS)
    pytest.importorskip("dnp3")
    bad_crc = bytearray(_dnp3(b"\xc0\xc0\x01", 2, 1, True))
    bad_crc[-1] ^= 0xFF
    ok = (0.0, "relay>generator", _dnp3(b"\xc1\xc1\x01", 2, 1, True), 0)
    alerts = detect([ok, (0.0, "relay>generator", bytes(bad_crc), 0)], "dnp3", RULES_10MS)
    assert list(alerts.rule) == ["malformed"]


def test_the_command_line_reads_a_capture(tmp_path, capsys):
    from lfc.repro.cli import main
    pcap = tmp_path / "drop.pcap"
    assert main(["wire", "--attack", "drop", "--agc", "centre", "--filter", "none",
                 "--duration", "2", "--pcap", str(pcap)]) == 0
    assert main(["detect", str(pcap), "--csv", str(tmp_path / "alerts.csv")]) == 0
    out = capsys.readouterr().out
    assert "end-to-end" in out and "sequence" in out
    import pandas as pd
    assert len(pd.read_csv(tmp_path / "alerts.csv")) == 151
    assert main(["detect", str(tmp_path / "missing.pcap")]) == 2
    assert main(["detect", str(pcap), "--protocol", "dnp3"]) == 2


def test_an_attacker_under_the_rate_limit_evades_the_substation_tap():
    """The rules' limit, pinned (a finding, not a guarantee): a ramp on the command
    just under ``rate_limit`` (0.1 pu/s) moves the generator's command by 0.2 pu in 2 s
    and raises nothing at the substation tap; only the two taps compared see it."""
    ramp = [{"op": "add", "field": "pc", "signal": {"kind": "ramp", "slope": 0.1,
                                                     "start": 1.0}}]
    run = wire(ramp, "modbus", "generator", duration=3.0)
    alerts = detect(run.frames, "modbus", RULES_10MS)
    assert alerts[alerts.tap == "substation"].empty
    assert (alerts.rule == "end-to-end").any()
    assert run.exchanges.received.max() == pytest.approx(0.2, abs=0.002)


def _can_sniff() -> bool:
    import socket
    try:
        socket.socket(socket.AF_PACKET, socket.SOCK_RAW).close()
        return True
    except (PermissionError, AttributeError, OSError):
        return False


needs_sniff = pytest.mark.skipif(not _can_sniff(), reason="a raw packet socket needs root "
                                 "or CAP_NET_RAW (Linux)")


@needs_sniff
@pytest.mark.parametrize("protocol", ["modbus", "dnp3"])
def test_a_capture_of_the_loopback_interface_holds_the_runs_own_frames(protocol, tmp_path):
    """``run_wire(capture=...)`` records the sockets' traffic from ``lo``: every party
    at its own address, each TCP connection opened by a handshake and closed by FINs,
    nothing dropped, and the frames read back from the segments equal the relay's log
    leg by leg, in order (across legs the kernel's order and the relay's may differ
    by a frame in flight), so the detector raises the same alerts from either."""
    from scapy.layers.inet import IP, TCP
    from scapy.utils import rdpcap

    from lfc.wire.capture import read_frames
    path = tmp_path / "run.pcap"
    run = wire("drop", protocol, duration=1.5, capture=path)
    frames = read_frames(path, protocol)

    def legs(frames: list) -> dict:
        return {leg: [f[2] for f in frames if f[1] == leg] for leg in sorted(LEGS)}

    def alerts(frames: list) -> list:
        table = detect(frames, protocol, RULES_10MS)
        return sorted(zip(table.area, table.tap, table.rule, table.detail))

    assert legs(frames) == legs(run.frames) and len(frames) == len(run.frames)
    assert alerts(frames) == alerts(run.frames)
    packets = rdpcap(str(path))
    syn = [p for p in packets if p[TCP].flags == "S"]
    fin = [p for p in packets if "F" in str(p[TCP].flags)]
    assert {(p[IP].src, p[IP].dst) for p in syn} == {("127.0.0.1", "127.0.1.1"),
                                                     ("127.0.1.1", "127.0.2.1")}
    assert len(fin) >= 2 and packets[0][TCP].flags == "S"
    assert sorted(p[TCP].dport for p in syn) == sorted(run.settings["ports"][0])
    assert len({p[IP].id for p in packets}) > len(packets) // 2      # the kernel's IP ids


@needs_sniff
@pytest.mark.skipif(__import__("shutil").which("tshark") is None,
                    reason="tshark (Debian's tshark package) is not installed")
@pytest.mark.parametrize("protocol, dissector", [("modbus", "mbtcp"), ("dnp3", "dnp3")])
def test_tshark_decodes_the_capture_with_no_malformed_frame(protocol, dissector, tmp_path):
    """Wireshark's own dissectors (tshark, told the run's ports) decode every frame the
    relay logged, and find nothing malformed and no expert error."""
    import subprocess

    path = tmp_path / "run.pcap"
    run = wire("fig4", protocol, duration=1.0, capture=path)
    decode = ["-o", f"{dissector}.tcp.port:" + ",".join(map(str, run.settings["ports"][0]))]

    def lines(display_filter: str) -> list[str]:
        out = subprocess.run(["tshark", "-r", str(path), *decode, "-Y", display_filter],
                             capture_output=True, text=True, check=True).stdout
        return out.splitlines()

    decoded = lines(dissector)
    assert len(decoded) == len(run.frames)
    assert not any("Unable to classify" in line for line in decoded)   # query or response
    assert lines("_ws.malformed || _ws.expert.severity >= error") == []


@pytest.mark.skipif(__import__("shutil").which("tshark") is None,
                    reason="tshark (Debian's tshark package) is not installed")
def test_wireshark_reads_that_a_synthesized_capture_is_synthesized(tmp_path):
    """A capture written from the relay's log (``write_pcap``) says so to Wireshark's
    tools: capinfos prints it as the capture's comment, tshark as the first packet's
    (``frame.comment``), and the frames still decode with nothing malformed."""
    import subprocess

    from lfc.wire.capture import SYNTHESIZED, write_pcap
    run = wire("fig4", "modbus", duration=0.5)
    path = write_pcap(run.frames, tmp_path / "run.pcap")

    def out(*command: str) -> str:
        return subprocess.run(command, capture_output=True, text=True, check=True).stdout

    assert f"Capture comment:     {SYNTHESIZED}" in out("capinfos", str(path))
    assert out("tshark", "-r", str(path), "-Y", "frame.comment", "-T", "fields", "-e",
               "frame.number", "-e", "frame.comment").splitlines() == [f"1\t{SYNTHESIZED}"]
    assert out("tshark", "-r", str(path), "-Y", "_ws.malformed || _ws.expert.severity >= "
               "error") == ""
    assert len(out("tshark", "-r", str(path), "-Y", "mbtcp").splitlines()) == len(run.frames)


def test_a_capture_without_the_right_to_sniff_says_what_to_do_instead(monkeypatch, tmp_path):
    import socket as socket_module

    def refused(*args, **kwargs):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(socket_module, "socket", refused)
    with pytest.raises(PermissionError, match="write_pcap"):
        wire("none", "modbus", duration=0.1, capture=tmp_path / "x.pcap")
    with pytest.raises(ValueError, match="capture"):
        wire("none", "modbus", duration=0.1, capture=7)


# ---- the network between the centre and the substation (lfc.wire.Impairment) -------

@pytest.mark.parametrize("kwargs, name", [
    ({"delay": -0.001}, "delay"), ({"delay": 11.0}, "delay"), ({"delay": math.nan}, "delay"),
    ({"delay": 0.01, "jitter": 0.02}, "jitter"), ({"loss": 1.0}, "loss"),
    ({"loss": -0.1}, "loss"), ({"rto": 0.0}, "rto"), ({"seed": -1}, "seed")])
def test_bad_network_settings_are_refused_naming_them(kwargs, name):
    from lfc.wire import Impairment
    with pytest.raises(ValueError, match=name):
        Impairment(**kwargs)
    with pytest.raises(ValueError, match="impairment"):
        wire("none", "modbus", duration=0.1, impairment={"delay": 0.01})


@pytest.mark.parametrize("protocol", ["modbus", "dnp3"])
def test_in_lockstep_the_network_changes_nothing_but_time(protocol):
    """Delay, jitter and loss (each lost frame sent again 20 ms later) at their
    corners: the run, its frames and its alarms equal the run without them."""
    from lfc.wire import Impairment
    scc = lfc.SafetyFilter(PARAMS, RELAYS, alpha=20.0)
    base = wire("fig4", protocol, "generator", duration=1.5, scc=scc)
    slow = wire("fig4", protocol, "generator", duration=1.5, scc=scc,
                impairment=Impairment(delay=0.002, jitter=0.002, loss=0.3, rto=0.02))
    assert slow.sim.trace.equals(base.sim.trace)
    codec = transport(protocol).Codec

    def carried(run, leg: str) -> list:     # the commands and reports (DNP3's time
        return [codec.command(f[2]) or codec.report(f[2])     # sync carries the clock)
                for f in run.frames if f[1] == leg]

    for leg in LEGS:               # leg by leg: a held frame lets the other legs' pass
        assert carried(slow, leg) == carried(base, leg)
    assert slow.alarm_log.equals(base.alarm_log)
    assert slow.exchanges.write_ms.median() > base.exchanges.write_ms.median() + 2.0


def test_in_real_time_a_delay_of_half_a_period_loses_every_command():
    """The measured effect on the outcome (a finding, pinned): the centre reads the
    last report, then writes, each a round trip, from half a period before each tick,
    so a one-way delay of 6 ms at a 10 ms period brings every command after its tick
    (2 ms already brings 499 of 500: docs/wire.md) — the generator holds its last
    command throughout, Fig. 4's attack never reaches it, the link flag is up every
    period."""
    from lfc.wire import Impairment
    run = wire("fig4", "modbus", "generator", duration=1.0, mode="realtime",
               impairment=Impairment(delay=0.006))
    assert (run.exchanges.link == 1).all()
    assert run.exchanges.received.abs().max() == 0.0
    assert run.exchanges.write_ms.median() >= 12.0          # a round trip: twice the delay
