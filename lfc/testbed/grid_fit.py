"""The two-area design model that best describes a grid on ANDES
(:class:`lfc.testbed.GridCase`: Kundur's or the IEEE 39-bus system).

Two small experiments on the testbed (:func:`lfc.testbed.simulate_andes_grid`,
AGC on, no filters): a ``FIT_STEP`` pu command step at area 0's generators and
a ``FIT_STEP`` pu load step in area 1.  Each area's seven parameters are fitted
as the microgrid's are (:func:`lfc.testbed.fit.fit_params`), on both
experiments, with the area's recorded command and its recorded net
disturbance ``dP_L + dP_tie`` as the inputs; the tie-line coefficient ``T`` by
least squares of ``dP_tie,0(t) = T ∫ (dw_0 − dw_1) dt`` (rotor speeds).  The
model's errors are RMS residuals over the response's peak.  The start is the
model the case's data imply (:func:`lfc.testbed.grid.case_design`).

The turbines of both cases have a lead-lag (Kundur: T2 = 2.1 s over T3 = 7 s;
IEEE 39-bus: 1 s over 2.1 s) that the design model's single lag cannot
represent; the fitted model's errors say how much that costs.  The fit (two
ANDES runs of ``FIT_DURATION``) is cached on disk as the microgrid's is
(:mod:`lfc.testbed.fit`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, NamedTuple

import numpy as np
from scipy.integrate import cumulative_trapezoid

from lfc._format import number
from lfc.multiarea import MultiAreaParams
from lfc.signals import Step
from lfc.testbed.case import MicrogridCase
from lfc.testbed.fit import (FITTED, MICROGRID_FIT, OUTPUTS, FitKind, FitReport, cached_fit,
                             check_report, decode_report, encode_report, fit_params)
from lfc.testbed.grid import GridCase, case_design

FIT_STEP = 0.02      # pu of the area base (36 MW in Kundur's), small enough to stay linear
FIT_DURATION = 30.0  # s: the turbines' 7 s lag settles
VALID_STEPS = (0.05, 0.1, 0.2, 0.4, 0.8)   # pu: the ladder of opposite command steps
VALID_RATIO = 2.0    # ANDES' peak |dw_meas| at most this times the model's, per area
VALID_DURATION = 10.0  # s: each rung's run (the inter-area swing peaks within 3 s)
# The measurement lags are the BusFreq / BusROCOF settings, known exactly: not fitted.
# Time constants stay >= 0.05 s: without that bound the fit trades the turbines'
# lead-lag for a governor lag of microseconds, a model too stiff to certify.
GRID_FITTED = ("M", "D", "tau_g", "tau_t", "droop")
LOWER = {"tau_g": 0.05, "tau_t": 0.05}


@dataclass(frozen=True)
class GridFit:
    """Result of :func:`fit_grid`.

    Attributes
    ----------
    areas : tuple of FitReport
        Each area's fit (parameters from the case data and fitted, errors).
    T : float
        Fitted tie-line coefficient (pu power per pu frequency per s, area base).
    tie_error : float
        RMS residual of the tie-line fit over its peak.
    command_range : float
        Each area's command magnitude (pu) within which the fitted model was
        found to describe ANDES (:func:`validated_range`).
    validation : tuple of tuple
        The ladder's rungs as run: ``(step, sign, ratio per area, tripped)``,
        ``step`` in pu (area 0's command ``sign * step``, area 1's the opposite),
        ``ratio`` ANDES' peak ``|dw_meas|`` over the model's.
    """

    areas: tuple[FitReport, ...]
    T: float
    tie_error: float
    command_range: float
    validation: tuple[tuple[float, int, tuple[float, ...], bool], ...]

    @property
    def params(self) -> MultiAreaParams:
        """The fitted two-area design model, with its command range."""
        return MultiAreaParams(areas=tuple(r.params for r in self.areas),
                               tie=((0, 1, self.T),), command_range=self.command_range)

    def validation_table(self) -> str:
        """Markdown: the ladder of :func:`validated_range`, one row per run."""
        rows = ["| step (pu) | area 0 / area 1 | ANDES' peak Δω over the model's, per area | "
                "ANDES tripped |",
                "|---|---|---|---|"]
        rows += [f"| {step:g} | {'+' if sign > 0 else '−'} / {'−' if sign > 0 else '+'} | "
                 f"{', '.join(f'{r:.2f}' for r in ratio)} | {tripped} |"
                 for step, sign, ratio, tripped in self.validation]
        return "\n".join(rows)

    def table(self) -> str:
        """Markdown: each area's fit table, then the tie-line's."""
        parts = [f"**Area {i}**\n\n{r.table()}" for i, r in enumerate(self.areas)]
        parts.append(f"**Tie-line**: T = {number(self.T)} pu, error {100 * self.tie_error:.2f} %")
        return "\n\n".join(parts)


def record_grid_experiments(case: GridCase, initial: MultiAreaParams) -> list:
    """The two experiments (module docstring), run with the design model
    ``initial``'s AGC: their :class:`MultiAreaResult`."""
    from lfc.testbed.grid_plant import simulate_andes_grid

    return [simulate_andes_grid(initial, duration=FIT_DURATION, case=case,
                                attacks={0: {"pc": Step(FIT_STEP, 1.0)}}),
            simulate_andes_grid(initial, duration=FIT_DURATION, case=case,
                                loads={1: Step(FIT_STEP, 1.0)})]


def fit_grid(case: GridCase | None = None) -> GridFit:
    """Fit the two-area design model to the testbed (module docstring).

    Raises
    ------
    ValueError
        If ``case`` has more than two areas (one tie-line coefficient is fitted).
    """
    case = case or GridCase.kundur()
    if case.n_areas != 2:
        raise ValueError(f"the fit handles two areas (one tie-line), the case has "
                         f"{case.n_areas} (generators)")
    initial = case_design(case)
    runs = record_grid_experiments(case, initial)
    reports = []
    for a, area in enumerate(initial.areas):
        exps = []
        for r in runs:
            tr = r.trace
            exp = {"t": tr["t"].to_numpy(), "u": tr[f"pc_{a}"].to_numpy(),
                   "p_load": tr[f"p_net_{a}"].to_numpy()}
            exp.update({k: tr[f"{k}_{a}"].to_numpy() for k in OUTPUTS})
            exps.append(exp)
        reports.append(fit_params(area, exps, GRID_FITTED, LOWER))
    p, i = [], []
    for r in runs:
        tr = r.trace
        p.append(tr["p_tie_0"].to_numpy())
        i.append(cumulative_trapezoid(tr["dw_0"] - tr["dw_1"], tr["t"], initial=0.0))
    p, i = np.concatenate(p), np.concatenate(i)
    T = float(p @ i / (i @ i))
    error = float(np.sqrt(np.mean((p - T * i) ** 2)) / np.abs(p).max())
    fitted = MultiAreaParams(areas=tuple(r.params for r in reports), tie=((0, 1, T),))
    command_range, validation = validated_range(case, fitted)
    return GridFit(tuple(reports), T, error, command_range, validation)


def validated_range(case: GridCase, params: MultiAreaParams) -> tuple[float, tuple]:
    """How far the design model ``params`` describes ``case`` on ANDES (module
    docstring): ``(command_range, rungs)``, the largest rung of ``VALID_STEPS``
    (pu) at which, at it and below, opposite command steps of either sign trip
    nothing on ANDES and move each area's peak ``|dw_meas|`` at most
    ``VALID_RATIO`` times the model's (``FIT_STEP``, the fit's own step, if the
    first rung fails), and every rung run (:attr:`GridFit.validation`).  Stops
    at the first rung that fails; ANDES' runs stop at a trip, and one that does
    not converge counts as tripped."""
    from lfc.simulate_multiarea import simulate_grid_linear
    from lfc.testbed.grid_plant import simulate_andes_grid
    from lfc.testbed.loop import TestbedError

    valid, rungs = FIT_STEP, []
    for step in VALID_STEPS:
        for sign in (1, -1):
            attacks = {0: {"pc": Step(sign * step, 1.0)}, 1: {"pc": Step(-sign * step, 1.0)}}
            model = simulate_grid_linear(params, duration=VALID_DURATION, attacks=attacks)
            try:
                real = simulate_andes_grid(params, duration=VALID_DURATION, case=case,
                                           attacks=attacks, stop_on_trip=True)
                peaks, tripped = [a.metrics()["max_abs_dw_meas"] for a in real.areas], \
                    real.tripped
            except TestbedError:
                peaks, tripped = [math.inf] * params.n_areas, True
            ratio = tuple(float(p / m.metrics()["max_abs_dw_meas"])
                          for p, m in zip(peaks, model.areas))
            rungs.append((step, sign, ratio, bool(tripped)))
            if tripped or max(ratio) > VALID_RATIO:
                return valid, tuple(rungs)
        valid = step
    return valid, tuple(rungs)


def grid_fit_report(case: GridCase | None = None) -> GridFit:
    """:func:`fit_grid` of ``case`` (default ``GridCase.kundur()``), computed
    once per process and case and cached on disk."""
    return _fitted(case or GridCase.kundur())


def grid_design(case: GridCase | None = None) -> MultiAreaParams:
    """The fitted two-area design model of ``case`` (default ``GridCase.kundur()``)."""
    return grid_fit_report(case).params


def _encode(fit: GridFit) -> dict:
    return {"areas": [encode_report(r) for r in fit.areas], "T": fit.T,
            "tie_error": fit.tie_error, "command_range": fit.command_range,
            "validation": [[s, g, list(r), t] for s, g, r, t in fit.validation]}


def _decode(data: dict) -> GridFit:
    return GridFit(tuple(decode_report(r) for r in data["areas"]), float(data["T"]),
                   float(data["tie_error"]), float(data["command_range"]),
                   tuple((float(s), int(g), tuple(map(float, r)), bool(t))
                         for s, g, r, t in data["validation"]))


def _check(case: GridCase, fit: GridFit) -> None:
    """Raise ``ValueError`` unless a (cached) fit is sane for ``case``: one area
    fit per area, each sane (:func:`check_report`), a tie-line coefficient finite
    and > 0, a tie-line error finite and >= 0."""
    if len(fit.areas) != case.n_areas:
        raise ValueError(f"the fit has {len(fit.areas)} areas, the case {case.n_areas}")
    for report in fit.areas:
        check_report(report)
    if not (math.isfinite(fit.T) and fit.T > 0):
        raise ValueError(f"T must be a finite number > 0, got {fit.T!r}")
    if not (math.isfinite(fit.tie_error) and fit.tie_error >= 0):
        raise ValueError(f"tie_error must be a finite number >= 0, got {fit.tie_error!r}")
    if fit.command_range not in (FIT_STEP,) + VALID_STEPS or not fit.validation:
        raise ValueError(f"command_range must be FIT_STEP or a rung of VALID_STEPS, with the "
                         f"rungs run, got {fit.command_range!r} and {len(fit.validation)} rungs")


#: The grids' fit (:func:`fit_grid`).
GRID_FIT = FitKind("grid-fit", fit_grid, _encode, _decode, _check)


@lru_cache(maxsize=4)
def _fitted(case: GridCase) -> GridFit:
    return cached_fit(case, GRID_FIT)


class Committed(NamedTuple):
    """A fit committed with the package (:mod:`lfc.testbed.fit`): its case and kind."""

    case: Any
    kind: FitKind


def committed_fits() -> tuple[Committed, ...]:
    """The fits committed with the package: the microgrid's and the two grids'."""
    return (Committed(MicrogridCase(), MICROGRID_FIT),
            *(Committed(case, GRID_FIT) for case in (GridCase.kundur(), GridCase.ieee39())))


def fit_numbers(fit: FitReport | GridFit) -> dict[str, float]:
    """A fit's numbers by name: each fitted parameter (per area for a grid), the
    errors, and a grid's tie-line coefficient, its error and its command range."""
    if isinstance(fit, FitReport):
        return {**{n: float(getattr(fit.params, n)) for n in FITTED},
                **{f"error {k}": float(v) for k, v in fit.error.items()}}
    numbers = {}
    for a, report in enumerate(fit.areas):
        numbers.update({f"area {a} {n}": float(getattr(report.params, n)) for n in GRID_FITTED})
        numbers.update({f"area {a} error {k}": float(v) for k, v in report.error.items()})
    return {**numbers, "T": fit.T, "tie_error": fit.tie_error,
            "command_range": fit.command_range}
