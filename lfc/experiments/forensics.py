"""How well the operator's forensic estimate (:mod:`lfc.wire.forensics`) recovers
attacks run over the wire: random attacks of each family, their estimates, a
confusion table and the parameters' errors (chapter 11)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from lfc.wire.forensics import FAMILIES
from lfc.wire.run import run_wire


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
