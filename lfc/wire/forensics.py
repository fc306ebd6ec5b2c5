"""What the operator learns from the alarms: an estimate of the attack.

The paper (section III) says the filter's alarms let operators learn the
attacker's strategy.  Here that is a computation on the control centre's alarm
log (:attr:`lfc.wire.run.WireResult.alarm_log`) and its own record of what it
sent: at each alarm the generator reports the command it received, so the
difference from the command sent is a sample of what the man in the middle
added.  The samples are fitted by each family and the simplest family that
fits as well as the best (within 5 % of its residual, plus 1e-6 pu) is the
estimate:

============  ==================================  =======================================
family        model of the added command           parameters estimated
============  ==================================  =======================================
bias          ``b``                                ``amplitude`` = b
ramp          ``s (t - t0)``                       ``slope``, ``start`` = t0
delay         ``sent(t - N T) - sent(t)``           ``periods`` = N (1 to 100)
sinusoid      ``A sin(2 pi f (t - t0))``           ``amplitude``, ``freq_hz``, ``start``
square        ``A sign(sin(2 pi f (t - t0)))``     ``amplitude``, ``freq_hz``, ``start``
============  ==================================  =======================================

Alarms whose received command equals the one sent (within 1e-9 pu) point
elsewhere: the family is ``"reports or reference"`` (the frequency the AGC is
told, or its reference, falsified); alarms that are all link losses,
``"drop"``; no alarm, ``"none"`` (the attack, if any, never made the filter
act).  ``start`` of a bias or a delay is the first alarm (an upper bound); of a
periodic attack, the latest of its fitted phase's instants before the first
alarm.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

FAMILIES = ("none", "drop", "reports or reference", "bias", "ramp", "delay", "sinusoid",
            "square")
FREQS = np.round(np.arange(0.05, 5.0001, 0.01), 6)    # Hz searched for periodic attacks


def estimate_attack(alarm_log: pd.DataFrame, sent: np.ndarray, period: float) -> dict:
    """The attack's family and parameters (module docstring).

    Parameters
    ----------
    alarm_log : DataFrame
        The control centre's alarm log (``t``, ``sent``, ``reported_received``,
        ``link``).
    sent : ndarray
        Every command the centre sent, one per control period (pu).
    period : float
        The control period (s).

    Returns
    -------
    dict
        ``family`` and, where they apply, ``amplitude`` (pu), ``slope`` (pu/s),
        ``freq_hz``, ``periods``, ``start`` (s), ``rms`` (pu, the fit's residual),
        ``samples`` (alarms used).
    """
    if alarm_log.empty:
        return {"family": "none", "samples": 0}
    if alarm_log.link.astype(bool).all():
        return {"family": "drop", "start": float(alarm_log.t.iat[0]),
                "samples": len(alarm_log)}
    log = alarm_log[~alarm_log.link.astype(bool)]
    t = log.t.to_numpy(float)
    d = (log.reported_received - log.sent).to_numpy(float)
    first = float(t[0])
    if np.max(np.abs(d)) < 1e-9:
        return {"family": "reports or reference", "start": first, "samples": len(t)}
    fits = [_bias(t, d, first), _ramp(t, d), _delay(t, d, sent, period, first),
            _periodic(t, d, first, square=False), _periodic(t, d, first, square=True)]
    best = min(f["rms"] for f in fits)
    for fit in fits:                   # simplest first
        if fit["rms"] <= 1.05 * best + 1e-6:
            return {**fit, "samples": len(t)}
    raise AssertionError("unreachable: the best fit passes its own test")


def _rms(r: np.ndarray) -> float:
    return float(np.sqrt(np.mean(r ** 2)))


def _bias(t, d, first) -> dict:
    b = float(np.mean(d))
    return {"family": "bias", "amplitude": b, "start": first, "rms": _rms(d - b)}


def _ramp(t, d) -> dict:
    if len(t) < 2 or np.ptp(t) == 0:
        return {"family": "ramp", "rms": math.inf}
    slope, icpt = np.polyfit(t, d, 1)
    return {"family": "ramp", "slope": float(slope),
            "start": float(-icpt / slope) if slope else math.nan,
            "rms": _rms(d - (slope * t + icpt))}


def _delay(t, d, sent, period, first) -> dict:
    j = np.round(t / period).astype(int)
    best = {"family": "delay", "rms": math.inf}
    for n in range(1, 101):
        back = np.maximum(j - n, 0)
        rms = _rms(d - (sent[back] - sent[j]))
        if rms < best["rms"]:
            best = {"family": "delay", "periods": n, "start": first, "rms": rms}
    return best


def _periodic(t, d, first, square: bool) -> dict:
    family = "square" if square else "sinusoid"
    best = {"family": family, "rms": math.inf}
    for f in FREQS:
        w = 2 * math.pi * f
        if square:       # phase on a grid of 1/50 of a period: sign waves are not linear
            for phase in np.arange(50) / 50 * 2 * math.pi:
                s = np.where(np.sin(w * t - phase) >= 0, 1.0, -1.0)
                a = float(s @ d / len(d))
                rms = _rms(d - a * s)
                if rms < best["rms"]:
                    best = {"family": family, "amplitude": abs(a), "freq_hz": float(f),
                            "phase": phase + (math.pi if a < 0 else 0.0), "rms": rms}
        else:
            basis = np.column_stack([np.sin(w * t), np.cos(w * t)])
            coef, *_ = np.linalg.lstsq(basis, d, rcond=None)
            rms = _rms(d - basis @ coef)
            if rms < best["rms"]:
                best = {"family": family, "amplitude": float(np.hypot(*coef)),
                        "freq_hz": float(f), "phase": -math.atan2(coef[1], coef[0]),
                        "rms": rms}
    if square and math.isfinite(best["rms"]):    # refine the phase to 1/5000 of a period
        w, coarse = 2 * math.pi * best["freq_hz"], best["phase"]
        for phase in coarse + np.linspace(-1, 1, 201) * 2 * math.pi / 50:
            s = np.where(np.sin(w * t - phase) >= 0, 1.0, -1.0)
            a = float(s @ d / len(d))
            rms = _rms(d - a * s)
            if rms < best["rms"]:
                best.update(amplitude=abs(a), phase=phase + (math.pi if a < 0 else 0.0),
                            rms=rms)
    if math.isfinite(best["rms"]):      # A sin(w t - phase) = A sin(w (t - t0)): t0 = phase / w
        cycle = 1.0 / best["freq_hz"]
        t0 = (best.pop("phase") / (2 * math.pi * best["freq_hz"])) % cycle
        best["start"] = float(t0 + math.floor((first - t0) / cycle) * cycle)
    return best


def random_attack(family: str, rng: np.random.Generator) -> tuple[list[dict], dict, dict]:
    """One attack of ``family`` with random parameters: ``(wire attack, true
    parameters, extra run_wire keywords)`` (ranges in :func:`accuracy`)."""
    start = float(np.round(rng.uniform(0.5, 2.0), 2))
    if family in ("sinusoid", "square"):
        amp = float(rng.uniform(0.3, 1.0) if family == "sinusoid" else rng.uniform(0.2, 0.6))
        freq = float(np.round(rng.uniform(0.2, 2.0 if family == "sinusoid" else 1.0), 2))
        sig = {"kind": family, "amplitude": amp, "freq_hz": freq, "start": start}
        return ([{"op": "add", "field": "pc", "signal": sig}],
                {"amplitude": amp, "freq_hz": freq, "start": start}, {})
    if family == "bias":
        amp = float(rng.choice([-1, 1]) * rng.uniform(0.2, 0.6))
        return [{"op": "bias", "field": "pc", "value": amp, "start": start}], \
            {"amplitude": amp, "start": start}, {}
    if family == "ramp":
        slope = float(rng.uniform(0.05, 0.3))
        return ([{"op": "add", "field": "pc", "signal": {"kind": "ramp", "slope": slope,
                                                         "start": start}}],
                {"slope": slope, "start": start}, {})
    if family == "delay":
        n = int(rng.integers(1, 6))
        from lfc.signals import Step
        return [{"op": "delay", "field": "pc", "periods": n, "start": start}], \
            {"periods": n, "start": start}, {"load": Step(0.1, start=0.5), "agc": "centre"}
    if family == "reports or reference":
        amp = -float(rng.uniform(0.02, 0.06))
        return ([{"op": "bias", "field": "dw_meas", "value": amp, "start": start}],
                {"amplitude": amp, "start": start}, {"agc": "centre"})
    raise ValueError(f"family must be one of {FAMILIES[3:] + ('reports or reference',)}, "
                     f"got {family!r}")


ATTACKED = ("sinusoid", "square", "bias", "ramp", "delay", "reports or reference")


def accuracy(params, scc, *, draws: int = 5, seed: int = 0,
             duration: float = 10.0) -> tuple[pd.DataFrame, pd.DataFrame]:
    """How well :func:`estimate_attack` recovers attacks over the wire: ``draws``
    random attacks of each family of ``ATTACKED`` (sinusoid 0.3-1 pu at 0.2-2
    Hz, square 0.2-0.6 pu at 0.2-1 Hz, bias ±0.2-0.6 pu, ramp 0.05-0.3 pu/s on the
    command; a delay of 1-5 periods of the AGC's commands during a 0.1 pu load
    step and a bias of 0.02-0.06 pu on the frequency the AGC is told, both with
    the AGC at the control centre (``run_wire(agc="centre")``, where they act);
    each starting in 0.5-2 s), run against ``scc``.

    Returns
    -------
    confusion : DataFrame
        True family (rows) against estimated family (columns), counts.
    errors : DataFrame
        One row per run: true and estimated family, alarms, and the estimate's
        errors: ``amplitude`` (relative), ``freq_hz`` (Hz), ``start`` (s).
    """
    from lfc.wire.run import run_wire
    rng = np.random.default_rng(seed)
    rows = []
    for family in ATTACKED:
        for _ in range(draws):
            spec, truth, extra = random_attack(family, rng)
            run = run_wire(params, duration=duration, attack=spec, scc=scc, **extra)
            est = run.forensics()
            row = {"true": family, "estimated": est["family"], "alarms": est["samples"]}
            if "amplitude" in truth and "amplitude" in est:
                row["amplitude error"] = abs(est["amplitude"] - abs(truth["amplitude"])
                                             if family in ("sinusoid", "square")
                                             else est["amplitude"] - truth["amplitude"]
                                             ) / abs(truth["amplitude"])
            if "freq_hz" in truth and "freq_hz" in est:
                row["freq error (Hz)"] = abs(est["freq_hz"] - truth["freq_hz"])
            if "start" in est:
                row["start error (s)"] = abs(est["start"] - truth["start"])
            rows.append(row)
    errors = pd.DataFrame(rows)
    confusion = pd.crosstab(errors["true"], errors["estimated"]).reindex(
        index=list(ATTACKED), fill_value=0)
    return confusion, errors
