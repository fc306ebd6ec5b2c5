"""Attacks on the wire: what the man in the middle does to each frame, as data.

An attack is a list of operations (dicts, so a YAML or JSON file, or a red-team
winner, is one), applied in order to every period's values.  Each names a
``field``: a command field the control centre writes (``pc``, ``wref``,
``ace``; :mod:`lfc.wire.registers`) or a report field it reads back
(``dw_meas``, ``rocof_meas``, ``pc_received``, ``u_ref``, ``u``: the operator's view, and what the
AGC integrates).  ``start`` and ``stop`` (s) bound every operation (default: the
whole run).

========  =========================================  ================================
``op``    keys                                       effect on ``field`` in the window
========  =========================================  ================================
add       ``signal``: ``{"kind": "sinusoid" |        ``+= signal(t)`` (an attack of
          "square" | "step" | "ramp" | "chirp",      :mod:`lfc.signals`, its own
          ...its parameters}``                       window inside ``signal``)
scale     ``factor``                                 ``*= factor``
bias      ``value`` (pu)                             ``+= value``
delay     ``periods`` (>= 1)                         the value sent ``periods`` earlier
replay    ``record`` (s, < ``start``)                the value sent at ``record + (t -
                                                     start)``: a recorded window replayed
freeze    (none)                                     the value sent in the last period
                                                     before ``start`` (a stuck meter)
drop      (command fields only; ``field`` omitted)   the frame is not forwarded: the
                                                     generator holds its last command
                                                     and flags the link
reset     (``field`` omitted)                        the command is not forwarded and
                                                     the connection is reset (a TCP
                                                     RST both ways): the control
                                                     centre reconnects, the generator
                                                     holds and flags the link
========  =========================================  ================================

The paper's attacks on the wire: Fig. 4's sinusoid on the command is ``add`` on
``pc``; Fig. 5's bias on the frequency reference is ``add`` on ``wref`` where the
integrator runs at the generator (``run_wire(agc="generator")``, the paper's
local controller), and, where the AGC runs at the control centre and no
reference is sent, a bias of the opposite sign on the frequency it is told
(``add`` on ``dw_meas``): the integrator sees ``wref - dw_meas`` either way, bit
for bit (:data:`ATTACKS`, :func:`from_simulate`).
"""

from __future__ import annotations

import math

from lfc import signals
from lfc._validate import as_float, check_finite, check_integer, check_number
from lfc.wire.registers import COMMAND, REPORT
from lfc.wire.relay import RESET

OPS = ("add", "scale", "bias", "delay", "replay", "freeze", "drop", "reset")
SIGNALS = {"sinusoid": signals.Sinusoid, "square": signals.Square, "step": signals.Step,
           "ramp": signals.Ramp, "chirp": signals.Chirp, "samples": signals.Samples}
SCALE = {"sinusoid": "amplitude", "square": "amplitude", "step": "value", "ramp": "slope",
         "chirp": "amplitude", "samples": "values"}     # the parameter a signal scales with
ATTACKS = {
    "none": [],
    "fig4": [{"op": "add", "field": "pc",
              "signal": {"kind": "sinusoid", "amplitude": 0.5, "freq_hz": 1.0, "start": 1.0}}],
    "fig4-weak": [{"op": "add", "field": "pc",
                   "signal": {"kind": "sinusoid", "amplitude": 0.1, "freq_hz": 1.0,
                              "start": 1.0}}],
    "fig5": [{"op": "add", "field": "wref",
              "signal": {"kind": "step", "value": 0.04, "start": 1.0}}],
    "fig5-told": [{"op": "add", "field": "dw_meas",
                   "signal": {"kind": "step", "value": -0.04, "start": 1.0}}],
    "delay-2": [{"op": "delay", "field": "pc", "periods": 2, "start": 1.0}],
    "drop": [{"op": "drop", "start": 1.0, "stop": 1.5}],
}


def signal_spec(signal: signals.Signal, sign: float = 1.0) -> dict:
    """The dict of an :mod:`lfc.signals` attack (:func:`signal_from_spec` inverts
    it), times ``sign`` (±1: negation is exact in floating point)."""
    import dataclasses
    kind = next((k for k, cls in SIGNALS.items() if type(signal) is cls), None)
    if kind is None:
        raise ValueError(f"signal must be one of {sorted(SIGNALS)} of lfc.signals, got "
                         f"{signal!r:.80}")
    out = {"kind": kind}
    for f in dataclasses.fields(signal):
        v = getattr(signal, f.name)
        out[f.name] = [float(x) for x in v] if hasattr(v, "__len__") else float(v)
    key = SCALE[kind]
    out[key] = ([sign * x for x in out[key]] if isinstance(out[key], list)
                else sign * out[key])
    return out


def from_simulate(pc_attack: signals.Signal | None = None,
                  wref_attack: signals.Signal | None = None,
                  agc: str = "generator") -> list[dict]:
    """The wire attack that reproduces :func:`lfc.simulate`'s ``pc_attack`` and
    ``wref_attack`` (e.g. a red-team winner, :func:`lfc.experiments.redteam.replay`)
    for ``run_wire(agc=agc)``: the first added to the command in the frames, the
    second to the reference sent (``agc="generator"``) or, negated, to the
    frequency the control centre's AGC is told (``agc="centre"``)."""
    ops = []
    if pc_attack is not None:
        ops.append({"op": "add", "field": "pc", "signal": signal_spec(pc_attack)})
    if wref_attack is not None:
        ops.append({"op": "add", "field": "wref", "signal": signal_spec(wref_attack)}
                   if agc == "generator" else
                   {"op": "add", "field": "dw_meas", "signal": signal_spec(wref_attack, -1.0)})
    return ops


def signal_from_spec(spec: dict) -> signals.Signal:
    """The :mod:`lfc.signals` attack a dict describes (``{"kind": ..., params}``)."""
    if not isinstance(spec, dict) or spec.get("kind") not in SIGNALS:
        raise ValueError(f"signal must be a dict with kind among {sorted(SIGNALS)}, got "
                         f"{spec!r}")
    params = {k: v for k, v in spec.items() if k != "kind"}
    try:
        return SIGNALS[spec["kind"]](**params)
    except TypeError as err:
        raise ValueError(f"signal {spec!r}: {err}") from err


class WireAttack:
    """A man in the middle's policy (module docstring), checked at construction.

    Parameters
    ----------
    spec : list of dict or str
        The operations, or the name of one of :data:`ATTACKS`.
    """

    def __init__(self, spec: list[dict] | str) -> None:
        if isinstance(spec, str):
            if spec not in ATTACKS:
                raise ValueError(f"attack must be a list of operations or one of "
                                 f"{sorted(ATTACKS)}, got {spec!r}")
            spec = ATTACKS[spec]
        if not isinstance(spec, list):
            raise ValueError(f"attack must be a list of operations (dicts), got {spec!r}")
        self.spec, self.ops = spec, [self._check(k, op) for k, op in enumerate(spec)]
        self.sent: list[dict[str, float]] = []      # every period's command as sent
        self.told: list[dict[str, float]] = []      # every period's report as sent

    def __repr__(self) -> str:
        return f"WireAttack({self.spec!r})"

    @staticmethod
    def _check(k: int, op: object) -> dict:
        if not isinstance(op, dict) or op.get("op") not in OPS:
            raise ValueError(f"attack[{k}] must be a dict with op among {OPS}, got {op!r}")
        kind, field = op["op"], op.get("field")
        fields = COMMAND + REPORT
        if kind in ("drop", "reset"):
            if field is not None:
                raise ValueError(f"attack[{k}]: {kind} takes no field (the whole frame)")
        elif field not in fields:
            raise ValueError(f"attack[{k}].field must be one of {fields} for {kind}, got "
                             f"{field!r}")
        for key in ("start", "stop", "record"):
            if key in op:
                check_number(f"attack[{k}].{key}", op[key])
        out = dict(op, start=as_float(op.get("start", 0.0)),     # 10**400: inf, no overflow
                   stop=as_float(op.get("stop", math.inf)))
        if not out["stop"] > out["start"] >= 0.0:
            raise ValueError(f"attack[{k}]: need 0 <= start < stop, got {op!r:.200}")
        if kind == "add":
            out["signal"] = signal_from_spec(op.get("signal"))
        elif kind in ("scale", "bias"):
            key = "factor" if kind == "scale" else "value"
            check_finite(f"attack[{k}].{key}", op.get(key))
        elif kind == "delay":
            out["periods"] = check_integer(f"attack[{k}].periods", op.get("periods"), 1)
        elif kind == "replay":
            if not 0.0 <= as_float(op.get("record", -1.0)) < out["start"]:
                raise ValueError(f"attack[{k}].record must lie in [0, start), got "
                                 f"{op.get('record')!r}")
        return out

    def command(self, j: int, t: float, period: float,
                values: dict[str, float]) -> dict[str, float] | str | None:
        """Period ``j``'s command (time ``t``, s) as forwarded, None (dropped) or
        ``RESET`` (dropped, the connection reset)."""
        self.sent.append(dict(values))
        out = dict(values)
        for op in self.ops:
            if not op["start"] <= t < op["stop"]:
                continue
            if op["op"] in ("drop", "reset"):
                return None if op["op"] == "drop" else RESET
            if op["field"] in COMMAND:
                out[op["field"]] = self._apply(op, j, t, period, out[op["field"]])
        return out

    def report(self, j: int, t: float, period: float,
               values: dict[str, float]) -> dict[str, float]:
        """Period ``j``'s report (time ``t``, s) as the control centre reads it."""
        self.told.append(dict(values))
        out = dict(values)
        for op in self.ops:
            if op["start"] <= t < op["stop"] and op.get("field") in REPORT:
                out[op["field"]] = self._apply(op, j, t, period, out[op["field"]])
        return out

    def _apply(self, op: dict, j: int, t: float, period: float, value: float) -> float:
        kind = op["op"]
        if kind == "add":
            return value + float(op["signal"](t))
        if kind == "scale":
            return value * op["factor"]
        if kind == "bias":
            return value + op["value"]
        history = self.sent if op["field"] in COMMAND else self.told
        if kind == "delay":
            back = op["periods"]
        elif kind == "freeze":          # back to the last period before start
            back = j - int(math.ceil(op["start"] / period - 1e-9)) + 1
        else:                           # replay
            back = int(round((op["start"] - op["record"]) / period))
        return history[max(j - back, 0)][op["field"]]
