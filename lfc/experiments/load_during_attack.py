"""Legitimate load steps that land while an attack is being filtered.

The certified filter's guarantee covers a load that moves by at most
``load_bound`` (``load_kind="steps"``: one step, a ramp or any monotone change,
at any instant).  :func:`battery` checks it where it is weakest: each attack of
``ATTACKS`` (the Fig. 4 sinusoid, a large slow sinusoid, a square on ω_ref and
the Fig. 5 bias) with a load step of every size in ``steps`` and both signs at
``instants`` spread across the attack; ``attacks`` adds others (the red team's
winners, :func:`lfc.experiments.redteam.replay`).  :func:`tradeoff` prices a bound: the
same battery, the attacks alone (stopped?) and the load steps alone (how much
the filter alters legitimate AGC commands and delays the frequency's recovery);
:func:`bound_price` what a bound costs when nothing attacks (the room it takes
from the limits, the alarms it raises on legitimate load steps).
"""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd

from lfc._validate import (ParameterTypeError, check_array, check_finite, check_nonnegative,
                           check_positive, check_sizes)
from lfc.experiments.redteam import severity
from lfc.filters import SafetyFilter
from lfc.model import LFCParams
from lfc.relays import RelaySettings, relays_or_default
from lfc.run import simulate
from lfc.signals import Sinusoid, Square, Step

ATTACK_START = 1.0     # s
ATTACKS = {            # name: simulate keywords; each runs until the end
    "Fig. 4 sinusoid on P_c (0.5 pu, 1 Hz)": {"pc_attack": Sinusoid(0.5, 1.0, start=ATTACK_START)},
    "sinusoid on P_c (1.5 pu, 0.5 Hz)": {"pc_attack": Sinusoid(1.5, 0.5, start=ATTACK_START)},
    "square on ω_ref (0.5 pu, 0.3 Hz)": {"wref_attack": Square(0.5, 0.3, start=ATTACK_START)},
    "Fig. 5 bias on ω_ref (+0.04 pu)": {"wref_attack": Step(0.04, start=ATTACK_START)},
}
RESTORED = 1e-3        # pu: |Δω_meas| below which the frequency counts as restored (Fig. 6)


def _check_filter(name: str, scc: object) -> None:
    if scc is not None and not isinstance(scc, SafetyFilter):
        raise ParameterTypeError(f"{name} must be a SafetyFilter or None (no filter), got "
                                 f"{scc!r:.80} ({type(scc).__name__})")


def _check_attacks(attacks: object) -> None:
    if not isinstance(attacks, dict) or not all(isinstance(a, dict) for a in attacks.values()):
        raise ParameterTypeError(f"attacks must be a dict {{name: simulate keywords}}, got "
                                 f"{attacks!r:.80}")


def battery(params: LFCParams, scc: SafetyFilter | None, steps: tuple[float, ...], *,
            instants: np.ndarray | None = None, duration: float = 12.0,
            relays: RelaySettings | None = None, attacks: dict | None = None,
            **run) -> pd.DataFrame:
    """Every attack of ``attacks`` (default ``ATTACKS``; name: simulate keywords)
    with a load step of each size in ``steps`` (pu), both signs, at each of
    ``instants`` (s; default 20 from 1.5 to 10.5 s, while the attack runs).  ``run``: further :func:`lfc.simulate` keywords (an
    estimator, noise, ``load_feedforward``).  One row per run: ``attack``,
    ``step`` (pu, signed), ``t_step`` (s), ``tripped``, ``outside`` (samples
    flagged), ``severity`` (largest of the peaks over the relay settings)."""
    _check_filter("scc", scc)
    steps = check_sizes("steps", steps, nonnegative=True)
    check_positive("duration", duration)
    instants = np.linspace(1.5, 10.5, 20) if instants is None else \
        check_array("instants", instants, shape=(None,))
    if not (len(instants) and np.all((instants >= 0) & (instants < duration))):
        raise ValueError(f"instants must be times (s) in [0, duration = {duration}) at which "
                         f"a step lands, got {instants!r:.80}")
    attacks = ATTACKS if attacks is None else attacks
    _check_attacks(attacks)
    relays = relays_or_default(
        scc.relays if relays is None and scc is not None else relays)
    rows = []
    for (name, attack), size, sign, t in itertools.product(attacks.items(), steps, (1, -1),
                                                           instants):
        res = simulate(params, duration=duration, load=Step(sign * size, start=float(t)),
                       scc=scc, relays=relays, **attack, **run)
        m = res.metrics()
        rows.append({"attack": name, "step": sign * size, "t_step": float(t),
                     "tripped": m["tripped"], "outside": m["outside"],
                     "severity": float(severity(m, relays))})
    return pd.DataFrame(rows)


def recovery(params: LFCParams, scc: SafetyFilter | None, step: float, *,
             duration: float = 40.0, relays: RelaySettings | None = None) -> dict:
    """A load step of ``step`` pu at 1 s, no attack: ``recovery_s`` (s from the
    step until ``|Δω_meas|`` stays below ``RESTORED``; NaN if never),
    ``max_modification`` (pu, the largest change the filter made to the AGC's
    command), ``tripped``."""
    _check_filter("scc", scc)
    check_finite("step", step)
    if not duration > 1.0:
        raise ValueError(f"duration must be > 1 s (the step lands at 1 s), got {duration!r}")
    relays = relays_or_default(
        scc.relays if relays is None and scc is not None else relays)
    res = simulate(params, duration=duration, load=Step(step, start=1.0), scc=scc,
                   relays=relays)
    tr = res.trace
    above = tr.t[tr.dw_meas.abs() >= RESTORED]
    if not len(above):
        restored = 0.0
    elif float(above.max()) >= float(tr.t.iat[-1]) - 1e-9:
        restored = float("nan")                       # not restored within the run
    else:
        restored = float(above.max()) - 1.0
    m = res.metrics()
    return {"recovery_s": restored,
            "max_modification": m["max_abs_modification"], "tripped": m["tripped"]}


def tradeoff(params: LFCParams, filters: dict[str, SafetyFilter | None], bounds: dict[str, float],
             *, instants: np.ndarray | None = None, relays: RelaySettings | None = None,
             attacks: dict | None = None, **run) -> pd.DataFrame:
    """One row per filter (name: filter, its ``load_bound`` in ``bounds``): over
    the battery with steps 0.02 pu up to the bound (and 0.02 pu for a bound of
    0), ``runs``, ``trips``, ``outside_runs``, ``worst_severity``; the attacks
    alone, ``attacks_stopped`` (of those that trip without a filter); a
    legitimate step of the bound (or 0.1 pu), ``max_modification`` (pu) and
    ``recovery_s`` against ``recovery_s_no_filter``.  ``attacks``: as in
    :func:`battery`."""
    if not isinstance(filters, dict) or not isinstance(bounds, dict):
        raise ParameterTypeError("filters and bounds must be dicts keyed by the filter's name")
    for name, scc in filters.items():
        _check_filter(f"filters[{name!r}]", scc)
        if name not in bounds:
            raise ValueError(f"bounds has no load_bound for filter {name!r} (give 0 for none)")
        check_nonnegative(f"bounds[{name!r}]", bounds[name])
    attacks = ATTACKS if attacks is None else attacks
    _check_attacks(attacks)
    relays = relays_or_default(relays)
    rows = []
    bare = {name: simulate(params, duration=12.0, relays=relays, **a).metrics()["tripped"]
            for name, a in attacks.items()}
    for name, scc in filters.items():
        bound = bounds[name]
        steps = tuple(s for s in (0.02, 0.05, 0.1, 0.15, 0.2) if s < bound - 1e-9) + \
            ((bound,) if bound > 0 else (0.02,))
        table = battery(params, scc, steps, instants=instants, relays=relays,
                        attacks=attacks, **run)
        stopped = sum(not simulate(params, duration=12.0, scc=scc, relays=relays,
                                   **a).metrics()["tripped"]
                      for n, a in attacks.items() if bare[n])
        size = bound if bound > 0 else 0.1              # a legitimate step of the bound
        legit = recovery(params, scc, size, relays=relays)
        rows.append({"filter": name, "load_bound": bound, "runs": len(table),
                     "trips": int(table.tripped.sum()),
                     "outside_runs": int((table.outside > 0).sum()),
                     "worst_severity": float(table.severity.max()),
                     "attacks_stopped": f"{stopped}/{sum(bare.values())}",
                     "max_modification": legit["max_modification"],
                     "recovery_s": legit["recovery_s"],
                     "recovery_s_no_filter": recovery(params, None, size,
                                                      relays=relays)["recovery_s"]})
    return pd.DataFrame(rows)


def bound_price(params: LFCParams, bounds: tuple[float, ...], steps: tuple[float, ...], *,
                options: dict | None = None, relays: RelaySettings | None = None,
                **run) -> pd.DataFrame:
    """What a ``load_bound`` (``load_kind="steps"``; 0: no load covered) costs when
    nothing attacks: one row per bound, the certified filter with ``options``
    (e.g. the robust configuration's ``uncertainty`` and ``noise_std``),
    ``room_freq`` and ``room_rocof`` (the fraction of F and of the ROCOF setting
    the load's tightening leaves, design plant) and, for each legitimate load
    step in ``steps`` (pu, alone, at 1 s, 41 s run; ``run``: :func:`lfc.simulate`
    keywords such as the estimator), ``alarms <step>`` (control periods with an
    alarm) and whether any run tripped (``tripped``)."""
    bounds = check_sizes("bounds", bounds, nonnegative=True)
    steps = check_sizes("steps", steps, empty=True)
    if options is not None and not isinstance(options, dict):
        raise ParameterTypeError(f"options must be a dict of certified-filter options, got "
                                 f"{options!r:.80}")
    relays = relays_or_default(relays)
    fixed = sorted({"load_bound", "load_kind"} & set(options or {}))
    if fixed:
        raise ValueError(f"options must not set {fixed}: bound_price varies load_bound "
                         f"('steps') itself, one row per entry of bounds")
    rows = []
    for bound in bounds:
        scc = SafetyFilter(params, relays, method="certified", **(options or {}),
                           **({"load_kind": "steps", "load_bound": bound} if bound else {}))
        gain = scc.cert.blocks[0].load_gain
        room = 1.0 - bound * gain / np.array([relays.F, relays.rocof_limit])
        row = {"load_bound": bound, "room_freq": float(room[0]), "room_rocof": float(room[1]),
               "tripped": False}
        for step in steps:
            m = simulate(params, duration=41.0, load=Step(step, start=1.0), scc=scc,
                         relays=relays, **run).metrics()
            row[f"alarms {step:g}"] = int(m["alarms"])
            row["tripped"] = row["tripped"] or bool(m["tripped"])
        rows.append(row)
    return pd.DataFrame(rows)
