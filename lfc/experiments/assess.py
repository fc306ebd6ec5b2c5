"""The cost of safety: the filters on legitimate events (load steps), where every
intervention is a false alarm."""

from __future__ import annotations

from typing import Callable

import pandas as pd

from lfc._validate import check_number, check_sizes
from lfc.experiments.redteam import severity
from lfc.experiments.scenarios import ATTACK_START
from lfc.filters import SafetyFilter
from lfc.model import LFCParams
from lfc.relays import RelaySettings, relays_or_default
from lfc.signals import Step
from lfc.run import simulate

FilterFactory = Callable[[LFCParams], SafetyFilter | None]


def _row(result, relays: RelaySettings) -> dict:
    m = result.metrics()
    mod = (result.controls.pc - result.controls.pc_ref).abs()
    return {"tripped": m["tripped"], "severity": float(severity(m, relays)),
            "active": m["scc_active_fraction"], "mean_mod": float(mod.mean()),
            "alarms": m["alarms"], "outside": int(result.alarms.outside.sum())}


def load_step_cost(params: LFCParams, filters: dict[str, FilterFactory], steps: list[float],
                   *, duration: float = ATTACK_START + 40.0, relays: RelaySettings | None = None,
                   estimator: str | None = None, noise_std: tuple[float, float] = (0.0, 0.0),
                   seed: int = 0) -> pd.DataFrame:
    """Legitimate load steps (pu, at ``ATTACK_START``) with each filter (None: no
    SCC), on the true state or an estimate (``estimator``, ``noise_std``,
    ``seed`` as in :func:`lfc.simulate`): false alarms (control periods with an
    alarm), the frequency nadir (pu), the time to recover within 10 % of F
    (s after the step) and ``final_abs_dw_hat``, the frequency deviation the
    generator side sees at the end (pu; the estimate with ``estimator``)."""
    relays = relays_or_default(relays)
    check_number("duration", duration)
    if not duration > ATTACK_START:
        raise ValueError(f"duration must be > ATTACK_START ({ATTACK_START} s, when the steps "
                         f"land), got {duration!r}")
    steps = check_sizes("steps", steps)
    rows = []
    for fname, make in filters.items():
        filt = make(params)
        for step in steps:
            r = simulate(params, duration=duration, load=Step(step, ATTACK_START), scc=filt,
                         relays=relays, estimator=estimator, noise_std=noise_std, seed=seed)
            tr = r.trace
            outside = tr.t[(tr.dw_meas.abs() > 0.1 * relays.F) & (tr.t >= ATTACK_START)]
            seen = r.controls.dw_hat if estimator is not None else tr.dw_meas
            rows.append({"filter": fname, "load_step": step, **_row(r, relays),
                         "nadir": float(tr.dw_meas.min() if step > 0 else tr.dw_meas.max()),
                         "recovery_s": float(outside.max() - ATTACK_START) if len(outside)
                         else 0.0, "final_abs_dw_hat": float(abs(seen.iloc[-1]))})
    return pd.DataFrame(rows)
