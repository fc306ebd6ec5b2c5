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

