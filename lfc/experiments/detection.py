"""Who detects an attack on the wire: the network detector at the substation tap
(:mod:`lfc.wire.detect`), the two taps compared end to end, the safety filter's
alarms — per attack and protocol, with the false alarms of clean runs (chapter 11)."""

from __future__ import annotations

import math

import pandas as pd
from tqdm.auto import tqdm

from lfc.model import LFCParams
from lfc.relays import RelaySettings
from lfc.signals import Signal, Step
from lfc.wire.attacks import ATTACKS
from lfc.wire.detect import Rules, detect
from lfc.wire.run import PROTOCOLS, run_wire

#: where the integrator runs for each named attack: at the generator (the paper's
#: reading, the chapter's Fig. 4 and 5 runs) for the attacks on the command and the
#: reference; at the centre for the clean run and the attacks on what the centre's
#: AGC sends (a delay, a drop) or is told (fig5-told), where they act
AGC_OF = {"fig4": "generator", "fig4-weak": "generator", "fig5": "generator"}
VERDICTS = ("traffic and SCC", "traffic only", "SCC only", "neither")


def detection_table(params: LFCParams, scc, *, attacks: tuple[str, ...] = tuple(ATTACKS),
                    protocols: tuple[str, ...] = PROTOCOLS, duration: float = 3.0,
                    load: Signal | None = Step(0.1, start=0.5), mode: str = "lockstep",
                    noise_std: tuple[float, float] = (0.0, 0.0), seed: int = 0,
                    relays: RelaySettings | None = None, rules: Rules | None = None,
                    progress: bool = True) -> pd.DataFrame:
    """Each named attack (:data:`lfc.wire.attacks.ATTACKS`) run over each protocol
    against ``scc``, and who saw it.

    Parameters
    ----------
    params : LFCParams
        The area.
    scc : SafetyFilter or None
        The generator's filter.
    attacks, protocols : tuple of str
        The attacks (``"none"``: a clean run) and protocols run.
    duration : float
        Simulated time of each run (s).
    load : Signal or None
        The area's load (pu) where the AGC runs at the centre (``AGC_OF``), so that
        its commands move: a legitimate step the clean run must not alarm on.
    mode : str
        ``"lockstep"`` or ``"realtime"`` (:func:`lfc.wire.run_wire`).
    noise_std, seed
        The measurement noise (:func:`lfc.simulate`).
    relays : RelaySettings, optional
    rules : Rules, optional
        The detector's thresholds (default :meth:`Rules.for_area` of ``params``).
    progress : bool
        Show a progress bar over the runs.

    Returns
    -------
    DataFrame
        One row per protocol and attack: ``agc`` (where the integrator ran,
        ``AGC_OF``), ``substation (s)`` (the first alert at the generator's tap,
        simulated time; NaN: none), ``substation rules`` (the rules that raised
        any), ``substation alerts``, ``end-to-end (s)`` (the first disagreement
        between the two taps), ``SCC alarm (s)`` (the filter's first alarm),
        ``tripped`` and ``detected by`` (who raised anything, the substation tap
        and the filter: ``VERDICTS``; on a clean run anything raised is a false
        alarm).
    """
    relays = relays or RelaySettings()
    control_period = 0.01
    rules = rules or Rules.for_area(control_period, params.k_i, relays)
    unknown = set(attacks) - set(ATTACKS)
    if unknown:
        raise ValueError(f"attacks must be among {sorted(ATTACKS)}, got {sorted(unknown)}")
    rows = []
    runs = [(p, a) for p in protocols for a in attacks]
    for protocol, attack in tqdm(runs, desc="detection", unit="run", disable=not progress):
        agc = AGC_OF.get(attack, "centre")
        run = run_wire(params, duration=duration, attack=attack, scc=scc, protocol=protocol,
                       agc=agc, load=load if agc == "centre" else None, mode=mode,
                       noise_std=noise_std, seed=seed, relays=relays,
                       control_period=control_period)
        alerts = detect(run.frames, protocol, rules)
        local = alerts[alerts.tap == "substation"]
        both = alerts[alerts.rule == "end-to-end"]
        traffic, alarm = not local.empty, not run.alarm_log.empty
        verdict = ("traffic and SCC" if traffic and alarm else "traffic only" if traffic
                   else "SCC only" if alarm else "neither")
        rows.append({"protocol": protocol, "attack": attack, "agc": agc,
                     "substation (s)": _first(local), "substation rules":
                     ", ".join(sorted(set(local.rule))), "substation alerts": len(local),
                     "end-to-end (s)": _first(both),
                     "SCC alarm (s)": float(run.alarm_log.t.min()) if alarm else math.nan,
                     "tripped": run.tripped, "detected by": verdict})
    return pd.DataFrame(rows)


def _first(alerts: pd.DataFrame) -> float:
    return float(alerts.t.min()) if not alerts.empty else math.nan
