"""Survey (not a timing benchmark): which attack families beat the paper's SCC.

84 attacks, 30 s each: sinusoids 0.1-1.5 Hz x 0.25-2 pu, squares, chirps and
ramps on P_c, and the same shapes scaled by 0.05 on w_ref.  Prints, per channel
and family, how many of those that trip without SCC still trip with the SCC
(alpha = 3 and 20).  The README quotes its totals.

Run: python bench/attack_family_survey.py
"""

from __future__ import annotations

import dataclasses
import itertools

import pandas as pd

from lfc import Chirp, LFCParams, Ramp, SafetyFilter, Sinusoid, Square, simulate
from lfc.signals import Signal

WREF_SCALE = 0.05  # w_ref attacks: the same shapes, 5 % of the P_c amplitude


def attacks() -> list[tuple[str, Signal]]:
    """(family, signal) for the survey grid on P_c."""
    out = [("sinusoid", Sinusoid(a, f, start=1))
           for f, a in itertools.product([0.1, 0.2, 0.4, 0.8, 1.0, 1.5], [0.25, 0.5, 1.0, 2.0])]
    out += [("square", Square(a, f, start=1))
            for f, a in itertools.product([0.2, 0.4, 1.0], [0.1, 0.3, 0.5])]
    out += [("chirp", Chirp(a, 0.1, f1, start=1, stop=25))
            for a, f1 in itertools.product([0.25, 0.5, 1.0], [1.0, 3.0])]
    out += [("ramp", Ramp(s, start=1)) for s in (0.02, 0.05, 0.1)]
    return out


def scaled(sig: Signal, k: float) -> Signal:
    """The same attack with its amplitude (or slope) multiplied by ``k``."""
    field = "slope" if isinstance(sig, Ramp) else "amplitude"
    return dataclasses.replace(sig, **{field: getattr(sig, field) * k})


def main() -> None:
    p = LFCParams()
    rows = []
    for channel, k in (("pc_attack", 1.0), ("wref_attack", WREF_SCALE)):
        for family, sig in attacks():
            kw = {channel: scaled(sig, k)}
            row = {"channel": channel, "family": family,
                   "no_scc": simulate(p, duration=30, **kw).metrics()["tripped"]}
            for a in (3.0, 20.0):
                row[f"alpha={a:g}"] = simulate(p, duration=30, scc=SafetyFilter(p, alpha=a),
                                               **kw).metrics()["tripped"]
            rows.append(row)
    df = pd.DataFrame(rows)
    tripping = df[df.no_scc]
    print(tripping.groupby(["channel", "family"])[["alpha=3", "alpha=20"]]
          .agg(["sum", "count"]).to_string())
    print(f"trip without SCC: {len(tripping)} of {len(df)}")
    for col in ("alpha=3", "alpha=20"):
        print(f"still trip with SCC {col}: {tripping[col].sum()} "
              f"({tripping[col].mean():.0%})")


if __name__ == "__main__":
    main()
