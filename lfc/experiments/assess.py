"""Robustness and cost of safety: the paper's filter against the certified one
off the design model (estimation error, plant–model mismatch) and on
legitimate events (load steps), where every intervention is a false alarm."""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np
import pandas as pd

from lfc.experiments.redteam import severity
from lfc.experiments.scenarios import ATTACK_START
from lfc.filters import SafetyFilter
from lfc.model import LFCParams
from lfc.relays import RelaySettings
from lfc.signals import Step
from lfc.simulate import simulate

MISMATCHED = ("M", "D", "tau_g", "tau_t")
FilterFactory = Callable[[LFCParams], SafetyFilter | None]


def mismatched_plants(params: LFCParams, n: int, spread: float = 0.2,
                      seed: int = 0) -> list[LFCParams]:
    """``n`` plants whose M, D, τ_G and τ_T differ from ``params`` by factors drawn
    uniformly in [1 − spread, 1 + spread] (seeded)."""
    rng = np.random.default_rng(seed)
    return [replace(params, **{k: getattr(params, k) * rng.uniform(1 - spread, 1 + spread)
                               for k in MISMATCHED}) for _ in range(n)]


def _row(result, relays: RelaySettings) -> dict:
    m = result.metrics()
    mod = (result.controls.pc - result.controls.pc_ref).abs()
    return {"tripped": m["tripped"], "severity": float(severity(m, relays)),
            "active": m["scc_active_fraction"], "mean_mod": float(mod.mean()),
            "alarms": m["alarms"], "outside": int(result.alarms.outside.sum())}


def robustness(design: LFCParams, filters: dict[str, FilterFactory],
               plants: list[LFCParams], attacks: dict[str, Callable], *,
               duration: float, relays: RelaySettings | None = None,
               estimator: str | None = None, noise_std: tuple[float, float] = (0.0, 0.0),
               seed: int = 0) -> pd.DataFrame:
    """Every filter (built on ``design``) × plant × attack on P_c: one row each
    with ``tripped``, ``severity``, SCC activity and flagged calls."""
    relays = relays or RelaySettings()
    rows = []
    for fname, make in filters.items():
        filt = make(design)
        for i, plant in enumerate(plants):
            for aname, attack in attacks.items():
                r = simulate(plant, duration=duration, pc_attack=attack, scc=filt,
                             relays=relays, estimator=estimator, noise_std=noise_std,
                             seed=seed)
                rows.append({"filter": fname, "plant": i, "attack": aname, **_row(r, relays)})
    return pd.DataFrame(rows)


def load_step_cost(params: LFCParams, filters: dict[str, FilterFactory], steps: list[float],
                   *, duration: float = 30.0, relays: RelaySettings | None = None
                   ) -> pd.DataFrame:
    """Legitimate load steps (pu) with each filter (None: no SCC): false alarms,
    frequency nadir and the time to recover within 10 % of F (s after the step)."""
    relays = relays or RelaySettings()
    rows = []
    for fname, make in filters.items():
        filt = make(params)
        for step in steps:
            r = simulate(params, duration=duration, load=Step(step, ATTACK_START), scc=filt,
                         relays=relays)
            tr = r.trace
            outside = tr.t[(tr.dw_meas.abs() > 0.1 * relays.F) & (tr.t >= ATTACK_START)]
            rows.append({"filter": fname, "load_step": step, **_row(r, relays),
                         "nadir": float(tr.dw_meas.min()),
                         "recovery_s": float(outside.max() - ATTACK_START) if len(outside)
                         else 0.0})
    return pd.DataFrame(rows)
