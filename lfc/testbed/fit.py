"""The linear design model that best describes the ANDES testbed.

Two small experiments on the testbed, a governor-command step and a load step
(``FIT_STEP`` pu each, separately, no SCC), record the applied command, the
load and the outputs ``dPm, dw, dw_meas, rocof_meas``.  The linear model
(python-control, :func:`lfc.model.lfc_model`) is driven by the same recorded
inputs, and its seven parameters (M, D, τ_G, τ_T, R, τ_ω, τ_ν) are fitted by
least squares on the outputs, each scaled by its peak.  The fit error is the
RMS of those scaled residuals per output.

The fit takes about 4 s (two ANDES runs), so :func:`fit_report` keeps it on
disk: ``$LFC_CACHE_DIR`` (default ``~/.cache/lfc-scc``), one JSON file per
case, named by a hash of the case, the ANDES version, the package's source
(a stale file never matches) and ``$OPENBLAS_CORETYPE`` (a fit computed under
another BLAS kernel differs in its last bits: runs under two kernels, as
``reproduce --compare-blas`` makes, keep their own), and holding a SHA-256 of its contents (a damaged
file is recomputed with a ``RuntimeWarning`` that names it).

The fits of the cases the chapters use (:func:`lfc.testbed.grid_fit.committed_fits`) are
committed with the package (``lfc/testbed/fitted/``, written by ``python -m lfc fit
--write``) and read before any cache: every machine and every BLAS kernel then
simulates the same design models.  Computed on each, they differ beyond their last
bits: the fit's valley is flat in the weakly identified damping, so where the
optimizer stops moves with the rounding of the simulation inside it (measured on
one machine, the same ANDES records fitted under two OpenBLAS kernels: the IEEE
39-bus fit's area-1 ``D`` 0.31169 against 0.31227, the microgrid's ``M`` 1.6e-7
apart), and a run in which the paper's SCC loses control amplifies that (the IEEE
39-bus system, α = 20, single attack: severity 1.30 against 2.47 on each kernel's
own fit; 1.2956043076 against 1.2956043071 on one fit).  A committed fit is
used only for the case it was made for (its ``repr``) and the ANDES version it
was made with; any other case is fitted as above.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import warnings
from dataclasses import asdict, dataclass, replace
from functools import lru_cache, partial
from pathlib import Path
from typing import Any, Callable, NamedTuple

import control as ct
import numpy as np
from scipy.optimize import least_squares

from lfc._files import cache_folder, cached, code_digest, write_atomic
from lfc._format import number
from lfc.model import LFCParams, lfc_model
from lfc.signals import Step
from lfc.testbed.case import MicrogridCase

FIT_STEP = 0.02      # pu, small enough to stay linear
FIT_DURATION = 8.0   # s
FITTED = ("M", "D", "tau_g", "tau_t", "droop", "tau_w", "tau_rocof")
UNITS = {"M": "s", "D": "pu/pu", "tau_g": "s", "tau_t": "s", "droop": "pu", "tau_w": "s",
         "tau_rocof": "s"}
OUTPUTS = ("dPm", "dw", "dw_meas", "rocof_meas")


@dataclass(frozen=True)
class FitReport:
    """Result of :func:`fit_design_model`.

    Attributes
    ----------
    params : LFCParams
        The fitted design model.
    initial : LFCParams
        The model the case's data imply (the starting point).
    error : dict
        Output name -> RMS residual / peak of the testbed response, fitted model.
    initial_error : dict
        The same for ``initial``.
    """

    params: LFCParams
    initial: LFCParams
    error: dict
    initial_error: dict

    def table(self) -> str:
        """Markdown table: parameters (initial, fitted; to the stable digits,
        :mod:`lfc._format`) and errors."""
        lines = ["| parameter | from case data | fitted |", "|---|---|---|"]
        lines += [f"| {n} ({UNITS[n]}) | {number(getattr(self.initial, n))} | "
                  f"{number(getattr(self.params, n))} |" for n in FITTED]
        lines += ["", "| output | error, case data | error, fitted |", "|---|---|---|"]
        lines += [f"| {n} | {100 * self.initial_error[n]:.2f} % | {100 * self.error[n]:.2f} % |"
                  for n in OUTPUTS]
        return "\n".join(lines)


def record_experiments(case: MicrogridCase) -> list[dict[str, np.ndarray]]:
    """Run the two small-step experiments on the testbed.

    Returns a list of dicts with ``t`` (s), ``u`` (applied command, pu),
    ``p_load`` (pu) and the ``OUTPUTS`` on a uniform grid.
    """
    from lfc.testbed.plant import simulate_microgrid

    params = case.design_params()
    runs = [simulate_microgrid(params, duration=FIT_DURATION, case=case,
                               pc_attack=Step(FIT_STEP, 1.0)),
            simulate_microgrid(params, duration=FIT_DURATION, case=case,
                               load=Step(FIT_STEP, 1.0))]
    out = []
    for r in runs:
        tr = r.trace  # times already rounded to 1 ns by the testbed: a uniform grid
        data = {"t": tr["t"].to_numpy(), "u": tr["pc"].to_numpy(),
                "p_load": tr["p_load"].to_numpy()}
        data.update({k: tr[k].to_numpy() for k in OUTPUTS})
        out.append(data)
    return out


def _respond(params: LFCParams, exp: dict[str, np.ndarray]) -> np.ndarray:
    """Linear-model outputs (rows ``OUTPUTS``) for the experiment's inputs."""
    sys = lfc_model(params)
    resp = ct.forced_response(sys, exp["t"], np.vstack([exp["u"], exp["p_load"]]))
    states = resp.states  # dPg, dPm, dw, dw_meas, rocof_meas
    return states[1:5]


def _errors(params: LFCParams, exps: list[dict]) -> np.ndarray:
    """Scaled residuals per output, stacked over experiments: shape (4, n)."""
    res = []
    for exp in exps:
        model = _respond(params, exp)
        data = np.vstack([exp[k] for k in OUTPUTS])
        scale = np.abs(data).max(axis=1, keepdims=True)
        res.append((model - data) / scale)
    return np.hstack(res)


def fit_design_model(case: MicrogridCase | None = None) -> FitReport:
    """Fit the linear LFC parameters to the testbed (see the module docstring)."""
    case = case or MicrogridCase()
    return fit_params(case.design_params(), record_experiments(case))


def fit_params(initial: LFCParams, exps: list[dict[str, np.ndarray]],
               fitted: tuple[str, ...] = FITTED, lower: dict | None = None) -> FitReport:
    """Least-squares fit of the parameters ``fitted`` (the others stay at
    ``initial``'s), started at ``initial``, to experiments (dicts of ``t``,
    ``u``, ``p_load`` and the ``OUTPUTS``, as :func:`record_experiments`
    returns); ``lower`` maps a parameter to its lower bound (default 0)."""
    lower = lower or {}

    def with_values(log_theta: np.ndarray) -> LFCParams:
        return replace(initial, **dict(zip(fitted, np.exp(log_theta))))

    theta0 = np.log([getattr(initial, n) for n in fitted])
    floor = [math.log(lower[n]) if n in lower else -np.inf for n in fitted]
    sol = least_squares(lambda th: _errors(with_values(th), exps).ravel(), theta0,
                        bounds=(floor, np.inf), x_scale=1.0, xtol=1e-10, ftol=1e-10)
    fitted = with_values(sol.x)

    def rms(p: LFCParams) -> dict:
        e = _errors(p, exps)
        return {k: float(np.sqrt(np.mean(e[i] ** 2))) for i, k in enumerate(OUTPUTS)}

    return FitReport(fitted, initial, rms(fitted), rms(initial))


def design_model(case: MicrogridCase | None = None) -> LFCParams:
    """The fitted design model of ``case`` (default ``MicrogridCase()``),
    computed once per process and case."""
    return fit_report(case).params


def fit_report(case: MicrogridCase | None = None) -> FitReport:
    """:func:`fit_design_model` of ``case``, computed once per process and case."""
    return _fitted(case or MicrogridCase())


@lru_cache(maxsize=4)
def _fitted(case: MicrogridCase) -> FitReport:
    return cached_fit(case, MICROGRID_FIT)



def _cache_path(case: object, kind: str = "testbed-fit") -> Path:
    """The cache file of ``case``'s fit (module docstring)."""
    import andes

    # a fit computed under another BLAS kernel differs in its last bits: not shared
    blas = os.environ.get("OPENBLAS_CORETYPE", "")
    key = hashlib.sha256((repr(case) + andes.__version__ + code_digest("testbed") + blas).encode())
    return cache_folder() / f"{kind}-{key.hexdigest()[:16]}.json"


def encode_report(report: FitReport) -> dict:
    """``report`` as JSON data (:func:`decode_report` inverts it exactly)."""
    return {"params": asdict(report.params), "initial": asdict(report.initial),
            "error": report.error, "initial_error": report.initial_error}


def decode_report(data: dict) -> FitReport:
    return FitReport(LFCParams(**data["params"]), LFCParams(**data["initial"]),
                     data["error"], data["initial_error"])


def check_report(report: FitReport) -> None:
    """Raise ``ValueError`` unless a fit is physically sane: its models valid
    (:class:`LFCParams` checks every parameter) and its errors finite and >= 0."""
    for name in ("error", "initial_error"):
        value = getattr(report, name)
        if not (isinstance(value, dict) and all(math.isfinite(v) and v >= 0
                                                for v in value.values())):
            raise ValueError(f"{name} must map each output to a finite number >= 0, got "
                             f"{value!r}")


class FitKind(NamedTuple):
    """One kind of fit: how it is computed, stored and checked (the microgrid's,
    :data:`MICROGRID_FIT`, and the grids', :data:`lfc.testbed.grid_fit.GRID_FIT`).

    Attributes
    ----------
    name : str
        The prefix of its files' names (cache and committed).
    compute : callable
        ``compute(case)``: the fit, run on ANDES.
    encode, decode : callable
        The fit as JSON data and back, exactly.
    check : callable
        ``check(case, fit)`` raises ``ValueError`` unless the fit is sane for ``case``.
    """

    name: str
    compute: Callable[[Any], Any]
    encode: Callable[[Any], dict]
    decode: Callable[[dict], Any]
    check: Callable[[Any, Any], None]


def _check_microgrid(case: MicrogridCase, report: FitReport) -> None:
    check_report(report)


#: The microgrid's fit (:func:`fit_design_model`).
MICROGRID_FIT = FitKind("testbed-fit", fit_design_model, encode_report, decode_report,
                        _check_microgrid)


def cached_fit(case: object, kind: FitKind) -> Any:
    """``kind.compute(case)``: the committed fit of ``case`` (:func:`read_committed`)
    if there is one, else read from its cache file (:func:`_cache_path`), or
    computed and written there when the file is absent, damaged (its checksum)
    or not physically sane (``kind.check(case, fit)`` raises ``ValueError``)."""
    committed = read_committed(case, kind)
    if committed is not None:
        return committed
    return cached(_cache_path(case, kind.name), lambda: kind.compute(case), kind.encode,
                  kind.decode, partial(kind.check, case))


#: Where the committed fits are (module docstring): one JSON file per kind and case.
FITTED_DIR = Path(__file__).resolve().parent / "fitted"


def committed_path(case: object, kind: FitKind) -> Path:
    """The committed fit file of ``case`` (``<kind's name>-<case name>.json``; a
    case without a name, the microgrid, is ``microgrid``)."""
    return FITTED_DIR / f"{kind.name}-{getattr(case, 'name', 'microgrid')}.json"


#: the package's files and functions whose code a fit depends on besides the plant
#: side's (:func:`lfc.testbed.stored_runs.plant_digest`): the fitting, the design
#: models, the microgrid's plant, and the generator side that runs the experiments
#: without a filter (AGC and the local integrator)
FIT_FILES = ("model.py", "multiarea.py", "testbed/case.py", "testbed/fit.py",
             "testbed/grid_fit.py", "testbed/grid_plant.py", "testbed/plant.py",
             "testbed/protection.py")
FIT_FUNCTIONS = ("lfc.engine:agc_step", "lfc.engine:generator_period",
                 "lfc.engine:GeneratorSide")


def fit_inputs(root: Path | None = None) -> str:
    """SHA-256 of what a committed fit was computed from besides its case: the plant
    side (:func:`~lfc.testbed.stored_runs.plant_digest`: ANDES and the packages under
    it included) and ``FIT_FILES`` and ``FIT_FUNCTIONS`` under ``root`` (the package).
    A committed fit whose ``inputs`` differ may be stale: ``python -m lfc fit``
    compares it with a new fit, ``--write`` replaces it."""
    from lfc.testbed import stored_runs
    root = root or Path(__file__).resolve().parents[1]
    parts = (stored_runs.plant_digest(root, "grid"), stored_runs.plant_digest(root, "microgrid"),
             stored_runs.source_digest(root, FIT_FILES, FIT_FUNCTIONS))
    return hashlib.sha256("".join(parts).encode()).hexdigest()


def _stamp(case: object) -> dict:
    """What a committed fit was made for: the case and the ANDES version."""
    import andes

    return {"case": repr(case), "andes": andes.__version__}


def committed_inputs(case: object, kind: FitKind) -> str | None:
    """The ``inputs`` (:func:`fit_inputs`) the committed fit of ``case`` was made with;
    None without a committed fit or a record of them."""
    path = committed_path(case, kind)
    try:
        return json.loads(path.read_text(encoding="utf-8")).get("inputs")
    except (OSError, ValueError, AttributeError):
        return None


def read_committed(case: object, kind: FitKind) -> Any:
    """The committed fit of ``case`` (:func:`write_committed`), or None if there
    is none, or it was made for another case or ANDES version (then the fit is
    computed), or it is damaged (its SHA-256) or not sane (``kind.check``
    raises ``ValueError``), the last two with a ``RuntimeWarning`` naming the file."""
    path = committed_path(case, kind)
    if not path.exists():
        return None
    try:
        stored = json.loads(path.read_text(encoding="utf-8"))
        if {k: stored.get(k) for k in ("case", "andes")} != _stamp(case):
            return None
        text = json.dumps(stored["fit"], sort_keys=True)
        if hashlib.sha256(text.encode()).hexdigest() != stored["sha256"]:
            raise ValueError("checksum mismatch")
        value = kind.decode(stored["fit"])
        kind.check(case, value)
        return value
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
        warnings.warn(f"damaged committed fit {path} ({err}); computing the fit instead "
                      f"(python -m lfc fit --write writes it again)", RuntimeWarning,
                      stacklevel=2)
        return None


def write_committed(case: object, kind: FitKind, value: Any) -> Path:
    """Write ``value``, the fit of ``case``, as its committed fit (readable JSON:
    the case, the ANDES version, the fit and the fit's SHA-256); its path."""
    data = kind.encode(value)
    text = json.dumps(data, sort_keys=True)
    stored = {**_stamp(case), "made_by": "python -m lfc fit --write", "fit": data,
              "inputs": fit_inputs(), "sha256": hashlib.sha256(text.encode()).hexdigest()}
    path = committed_path(case, kind)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, json.dumps(stored, indent=1, sort_keys=True) + "\n")
    return path
