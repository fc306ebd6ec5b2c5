"""Scenario tables for the attack-surface maps and the α–T_s trade-off.

Each function returns a table for :func:`lfc.simulate_many` (one row per
scenario; ``alpha`` NaN means no SCC).  All attacks and load steps start at
``lfc.experiments.scenarios.ATTACK_START``.
"""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd

from lfc._format import number
from lfc._validate import ParameterTypeError, check_sizes, is_sequence
from lfc.experiments.scenarios import ATTACK_START
from lfc.filters import CONFLICT_RULES, DEFAULT_READING, OUTSIDE_RULES, PREDICTIONS

NO_SCC = float("nan")
READINGS = [dict(zip(("outside_rule", "conflict", "prediction"), r))
            for r in itertools.product(OUTSIDE_RULES, CONFLICT_RULES, PREDICTIONS)]
ATTACK_KEY = ["waveform", "channel", "amplitude", "freq_hz"]


def _grid(**axes) -> None:
    """Raise unless every axis is a non-empty sequence (of numbers, or of strings
    for ``waveforms``): ``"sinusoid"`` is not a list of waveforms, nor 0.5 of
    amplitudes."""
    for name, values in axes.items():
        if name == "waveforms":
            if not is_sequence(values) or not values or not all(isinstance(w, str)
                                                                 for w in values):
                raise ParameterTypeError(f"waveforms must be a non-empty list of names such as "
                                         f"['sinusoid'], got {values!r}")
        else:
            check_sizes(name, values, empty=name == "alphas")     # no alphas: no SCC only


def _table(rows: list[dict]) -> pd.DataFrame:
    cols = ["waveform", "channel", "amplitude", "freq_hz", "start", "alpha", "Ts"]
    return pd.DataFrame(rows, columns=cols + [c for c in rows[0] if c not in cols])


def attack_map(waveforms: list[str], amplitudes: list[float], freqs: list[float],
               alphas: list[float], Ts: float = 0.25) -> pd.DataFrame:
    """Periodic attacks on P_c: every waveform × amplitude (pu) × frequency (Hz),
    without SCC and with the SCC for each alpha (1/s)."""
    _grid(waveforms=waveforms, amplitudes=amplitudes, freqs=freqs, alphas=alphas)
    return _table([{"waveform": w, "channel": "pc", "amplitude": a, "freq_hz": f,
                    "start": ATTACK_START, "alpha": al, "Ts": Ts}
                   for w, al, a, f in itertools.product(waveforms, [NO_SCC, *alphas],
                                                        amplitudes, freqs)])


def bias_map(biases: list[float], alphas: list[float], Ts: float = 0.25) -> pd.DataFrame:
    """Bias (step) attacks on the frequency reference ω_ref (pu), without SCC and
    with the SCC for each alpha."""
    _grid(biases=biases, alphas=alphas)
    return _table([{"waveform": "step", "channel": "wref", "amplitude": b, "freq_hz": 0.0,
                    "start": ATTACK_START, "alpha": al, "Ts": Ts}
                   for al, b in itertools.product([NO_SCC, *alphas], biases)])


def tradeoff(alphas: list[float], Ts_values: list[float], attack_amplitude: float,
             attack_freq: float, load_steps: list[float]) -> pd.DataFrame:
    """For every (alpha, T_s), and once without SCC: the Fig. 4 sinusoid on P_c
    (``event="attack"``) and load steps (``event="load"``, where every
    intervention is a false alarm)."""
    _grid(alphas=alphas, Ts_values=Ts_values, load_steps=load_steps)
    settings = [(NO_SCC, float("nan"))] + list(itertools.product(alphas, Ts_values))
    events = [("attack", "sinusoid", "pc", attack_amplitude, attack_freq)]
    events += [("load", "step", "load", s, 0.0) for s in load_steps]
    return _table([{"waveform": w, "channel": ch, "amplitude": a, "freq_hz": f,
                    "start": ATTACK_START, "alpha": al, "Ts": ts, "event": ev}
                   for (al, ts), (ev, w, ch, a, f) in itertools.product(settings, events)])


def reading_label(reading: dict) -> str:
    """"hold / frequency / incoming" (the paper filter's E9 / E10 / E5 readings)."""
    return " / ".join(reading[k] for k in ("outside_rule", "conflict", "prediction"))


def readings_table(attacks: pd.DataFrame, alphas: list[float], load_steps: list[float],
                   Ts: float = 0.25) -> pd.DataFrame:
    """Every attack of ``attacks`` (rows without SCC, e.g. the maps' tables with
    ``alphas=[]``) once without SCC and with the paper's filter at every reading
    (``READINGS``) and alpha; plus legitimate load steps (``event="load"``) with
    every reading and alpha, where every intervention is a false alarm."""
    loads = _table([{"waveform": "step", "channel": "load", "amplitude": s, "freq_hz": 0.0,
                     "start": ATTACK_START, "alpha": NO_SCC, "Ts": Ts} for s in load_steps])
    parts = [attacks.assign(event="attack", **DEFAULT_READING)]
    for reading, alpha in itertools.product(READINGS, alphas):
        parts += [attacks.assign(event="attack", alpha=alpha, Ts=Ts, **reading),
                  loads.assign(event="load", alpha=alpha, **reading)]
    return pd.concat(parts, ignore_index=True)


def readings_summary(results: pd.DataFrame) -> pd.DataFrame:
    """Per reading and alpha: the attacks (of those that trip without SCC) the
    filter stops, per waveform and in all, trips it causes, and its false alarms
    (control periods with an alarm) and trips on the load steps."""
    attacks = results[results.event == "attack"]
    base = attacks[attacks.alpha.isna()].set_index(ATTACK_KEY).tripped
    rows = []
    keys = ["outside_rule", "conflict", "prediction", "alpha"]
    for key, grp in attacks[attacks.alpha.notna()].groupby(keys, sort=False):
        g = grp.set_index(ATTACK_KEY)
        tripping, tripped = base.loc[g.index].to_numpy(), g.tripped.to_numpy()
        wave = g.index.get_level_values("waveform")
        loads = results[(results.event == "load")
                        & (results[keys] == pd.Series(dict(zip(keys, key)))).all(axis=1)]
        reading = dict(zip(keys[:3], key[:3]))
        rows.append({"reading": reading_label(reading), "default": reading == DEFAULT_READING,
                     "alpha": key[3],
                     **{f"{w} stopped": int((tripping & ~tripped & (wave == w)).sum())
                        for w in dict.fromkeys(wave)},
                     "stopped": int((tripping & ~tripped).sum()),
                     "of tripping": int(tripping.sum()),
                     "caused": int((~tripping & tripped).sum()),
                     "load-step alarms": int(loads.alarms.sum()),
                     "load-step trips": int(loads.tripped.sum())})
    return pd.DataFrame(rows)


def amplitude_scan(waveform: str, amplitudes: list[float], freq_hz: float,
                   alphas: list[float], Ts: float = 0.25) -> pd.DataFrame:
    """One waveform on P_c at one frequency over ``amplitudes`` (pu), without SCC
    and with the SCC for each alpha (for :func:`first_failures`)."""
    return attack_map([waveform], list(amplitudes), [freq_hz], list(alphas), Ts)


def first_failures(results: pd.DataFrame) -> pd.DataFrame:
    """Per SCC setting of an :func:`amplitude_scan`: the smallest amplitude (pu)
    that trips a relay, its first relay, and how many amplitudes of the scan trip
    (NaN and 0 if none does).  Where the scan's first amplitude already trips, the
    edge lies at or below it, and the smallest amplitude is the text ``"≤ a (the
    scan's first)"``, not a number that would read as the edge."""
    rows = []
    for alpha, grp in results.groupby(results.alpha.fillna(-1.0), sort=False):
        tripped = grp[grp.tripped].sort_values("amplitude", kind="stable")
        first = tripped.iloc[0] if len(tripped) else None
        smallest = np.nan if first is None else float(first.amplitude)
        if smallest <= grp.amplitude.min():
            smallest = f"≤ {number(smallest)} (the scan's first)"
        rows.append({"SCC": scc_label(np.nan if alpha < 0 else alpha),
                     "smallest amplitude that trips (pu)": smallest,
                     "first relay": first.first_trip_relay if first is not None else "none",
                     "amplitudes that trip": f"{len(tripped)} of {len(grp)}"})
    return pd.DataFrame(rows)


def scc_label(alpha: float) -> str:
    """"no SCC" or "SCC α=<alpha>"."""
    return "no SCC" if np.isnan(alpha) else f"SCC α={alpha:g}"


def stopped_summary(results: pd.DataFrame) -> pd.DataFrame:
    """Per waveform and SCC setting: attacks that trip without SCC, and how many
    of those the SCC stops."""
    base = results[results.alpha.isna()].set_index(["waveform", "amplitude", "freq_hz"])
    rows = []
    for (w, al), grp in results[results.alpha.notna()].groupby(["waveform", "alpha"]):
        g = grp.set_index(["waveform", "amplitude", "freq_hz"])
        tripping = base.loc[g.index, "tripped"].to_numpy()
        rows.append({"waveform": w, "SCC": scc_label(al), "trip without SCC": int(tripping.sum()),
                     "stopped": int((tripping & ~g.tripped.to_numpy()).sum()),
                     "caused by SCC": int((~tripping & g.tripped.to_numpy()).sum())})
    return pd.DataFrame(rows)


def tradeoff_summary(results: pd.DataFrame, relays, e12_limit: float
                     ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per event and (alpha, T_s): peak |ROCOF| and |Δω̂| over the relay settings,
    SCC active fraction and mean |modification|.  Load steps are aggregated over
    the sizes below ``e12_limit`` (worst ratio, mean intervention): legitimate
    events, where every intervention is a false alarm.

    Returns
    -------
    (summary, baseline) : the SCC settings, and the no-SCC values indexed by event.
    """
    legit = results[(results.event == "attack") | (results.amplitude < e12_limit)]
    table = legit.assign(rocof_ratio=legit.max_abs_rocof_meas / relays.rocof_limit,
                         dw_ratio=legit.max_abs_dw_meas / relays.F)
    table = table.assign(worst_ratio=table[["rocof_ratio", "dw_ratio"]].max(axis=1),
                         event=table.event.map({"attack": "attack on P_c",
                                                "load": "load steps below E12 (false alarms)"}))
    agg = {"rocof_ratio": "max", "dw_ratio": "max", "worst_ratio": "max",
           "scc_active_fraction": "mean", "mean_abs_modification": "mean"}
    names = {"scc_active_fraction": "active", "mean_abs_modification": "mean_mod"}
    scc = table[table.alpha.notna()].groupby(["event", "alpha", "Ts"], as_index=False)
    baseline = table[table.alpha.isna()].groupby("event").agg(agg).rename(columns=names)
    return scc.agg(agg).rename(columns=names), baseline
