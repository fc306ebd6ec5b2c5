"""The two-area design model that best describes the Kundur testbed.

Two small experiments on the testbed (:func:`lfc.testbed.simulate_kundur`,
AGC on, no filters): a ``FIT_STEP`` pu command step at area 0's generators and
a ``FIT_STEP`` pu load step in area 1.  Each area's seven parameters are fitted
as the microgrid's are (:func:`lfc.testbed.fit.fit_params`), on both
experiments, with the area's recorded command and its recorded net
disturbance ``dP_L + dP_tie`` as the inputs; the tie-line coefficient ``T`` by
least squares of ``dP_tie,0(t) = T ∫ (dw_0 − dw_1) dt`` (rotor speeds).  The
model's errors are RMS residuals over the response's peak.

The turbines of the case have a lead-lag (T2 = 2.1 s over T3 = 7 s) that the
design model's single lag cannot represent; the fitted model's errors say how
much that costs.  The fit (two ANDES runs, about 15 s) is cached on disk as the
microgrid's is (:mod:`lfc.testbed.fit`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.integrate import cumulative_trapezoid

from lfc.multiarea import MultiAreaParams
from lfc.signals import Step
from lfc.testbed.fit import (OUTPUTS, FitReport, cached_fit, decode_report, encode_report,
                             fit_params)
from lfc.testbed.kundur import KundurCase

FIT_STEP = 0.02      # pu of the area's base (36 MW), small enough to stay linear
FIT_DURATION = 30.0  # s: the turbines' 7 s lag settles
# The measurement lags are the BusFreq / BusROCOF settings, known exactly: not fitted.
# Time constants stay >= 0.05 s: without that bound the fit trades the turbines'
# lead-lag for a governor lag of microseconds, a model too stiff to certify.
KUNDUR_FITTED = ("M", "D", "tau_g", "tau_t", "droop")
LOWER = {"tau_g": 0.05, "tau_t": 0.05}


@dataclass(frozen=True)
class KundurFit:
    """Result of :func:`fit_kundur`.

    Attributes
    ----------
    areas : tuple of FitReport
        Each area's fit (parameters from the case data and fitted, errors).
    T : float
        Fitted tie-line coefficient (pu power per pu frequency per s, area base).
    tie_error : float
        RMS residual of the tie-line fit over its peak.
    """

    areas: tuple[FitReport, ...]
    T: float
    tie_error: float

    @property
    def params(self) -> MultiAreaParams:
        """The fitted two-area design model."""
        return MultiAreaParams(areas=tuple(r.params for r in self.areas),
                               tie=((0, 1, self.T),))

    def table(self) -> str:
        """Markdown: each area's fit table, then the tie-line's."""
        parts = [f"**Area {i}**\n\n{r.table()}" for i, r in enumerate(self.areas)]
        parts.append(f"**Tie-line**: T = {self.T:.4g} pu, error {100 * self.tie_error:.2f} %")
        return "\n\n".join(parts)


def record_kundur_experiments(case: KundurCase) -> list:
    """The two experiments (module docstring): their :class:`MultiAreaResult`."""
    from lfc.testbed.kundur_plant import simulate_kundur

    initial = case.design_params()
    return [simulate_kundur(initial, duration=FIT_DURATION, case=case,
                            attacks={0: {"pc": Step(FIT_STEP, 1.0)}}),
            simulate_kundur(initial, duration=FIT_DURATION, case=case,
                            loads={1: Step(FIT_STEP, 1.0)})]


def fit_kundur(case: KundurCase | None = None) -> KundurFit:
    """Fit the two-area design model to the testbed (module docstring)."""
    case = case or KundurCase()
    runs = record_kundur_experiments(case)
    initial = case.design_params()
    reports = []
    for a, area in enumerate(initial.areas):
        exps = []
        for r in runs:
            tr = r.trace
            exp = {"t": tr["t"].to_numpy(), "u": tr[f"pc_{a}"].to_numpy(),
                   "p_load": tr[f"p_net_{a}"].to_numpy()}
            exp.update({k: tr[f"{k}_{a}"].to_numpy() for k in OUTPUTS})
            exps.append(exp)
        reports.append(fit_params(area, exps, KUNDUR_FITTED, LOWER))
    p, i = [], []
    for r in runs:
        tr = r.trace
        p.append(tr["p_tie_0"].to_numpy())
        i.append(cumulative_trapezoid(tr["dw_0"] - tr["dw_1"], tr["t"], initial=0.0))
    p, i = np.concatenate(p), np.concatenate(i)
    T = float(p @ i / (i @ i))
    error = float(np.sqrt(np.mean((p - T * i) ** 2)) / np.abs(p).max())
    return KundurFit(tuple(reports), T, error)


def kundur_fit_report(case: KundurCase | None = None) -> KundurFit:
    """:func:`fit_kundur` of ``case`` (default ``KundurCase()``), computed once
    per process and case and cached on disk."""
    return _fitted(case or KundurCase())


def kundur_design(case: KundurCase | None = None) -> MultiAreaParams:
    """The fitted two-area design model of ``case`` (default ``KundurCase()``)."""
    return kundur_fit_report(case).params


def _encode(fit: KundurFit) -> dict:
    return {"areas": [encode_report(r) for r in fit.areas], "T": fit.T,
            "tie_error": fit.tie_error}


def _decode(data: dict) -> KundurFit:
    return KundurFit(tuple(decode_report(r) for r in data["areas"]), float(data["T"]),
                     float(data["tie_error"]))


@lru_cache(maxsize=4)
def _fitted(case: KundurCase) -> KundurFit:
    return cached_fit(case, "kundur-fit", fit_kundur, _encode, _decode)
