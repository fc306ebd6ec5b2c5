"""The linear design models that best describe the ANDES testbed: the microgrid's
(:func:`fit_design_model`) and a grid's (:func:`fit_grid`).

Two small experiments on the testbed, a governor-command step and a load step
(``FIT_STEP`` pu each, separately, no SCC), record the applied command, the
load and the outputs ``dPm, dw, dw_meas, rocof_meas``.  The linear model
(python-control, :func:`lfc.model.lfc_model`) is driven by the same recorded
inputs, and its seven parameters (M, D, τ_G, τ_T, R, τ_ω, τ_ν) are fitted by
least squares on the outputs, each scaled by its peak.  The fit error is the
RMS of those scaled residuals per output.

The fit takes about 4 s (two ANDES runs), so :func:`fit_report` keeps it on disk:
``$LFC_CACHE_DIR`` (default ``~/.cache/lfc-scc``), one JSON file per case, named by a
hash of the case, the ANDES version, the package's source (a stale file never matches)
and ``$OPENBLAS_CORETYPE`` (a fit computed under another BLAS kernel differs in its last
bits: runs under two kernels, as ``reproduce --compare-blas`` makes, keep their own),
and holding a SHA-256 of its contents (a damaged file is recomputed with a
``RuntimeWarning`` that names it).

The fits of the cases the chapters use (:func:`committed_fits`) are
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

**A grid's two-area design model** (:class:`lfc.testbed.GridCase`: Kundur's or the IEEE
39-bus system). Two small experiments on the testbed
(:func:`lfc.testbed.grids.simulate_andes_grid`, AGC on, no filters): a ``GRID_FIT_STEP``
pu command step at area 0's generators and a ``GRID_FIT_STEP`` pu load step in area 1.
Each area's seven parameters are fitted as the microgrid's are (:func:`fit_params`), on
both experiments, with the area's recorded command and its recorded net disturbance
``dP_L + dP_tie`` as the inputs; the tie-line coefficient ``T`` by least squares of
``dP_tie,0(t) = T ∫ (dw_0 − dw_1) dt`` (rotor speeds). The model's errors are RMS
residuals over the response's peak. The start is the model the case's data imply
(:func:`lfc.testbed.grids.case_design`).

The turbines of both cases have a lead-lag (Kundur: T2 = 2.1 s over T3 = 7 s;
IEEE 39-bus: 1 s over 2.1 s) that the design model's single lag cannot
represent; the fitted model's errors say how much that costs.  The fit (two
ANDES runs of ``GRID_FIT_DURATION``) is cached on disk as the microgrid's is.
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
from scipy.integrate import cumulative_trapezoid
from scipy.optimize import least_squares

from lfc._files import cache_folder, cached, code_digest, write_atomic
from lfc._format import number
from lfc.model import LFCParams, lfc_matrices, lfc_model
from lfc.multiarea import MultiAreaParams
from lfc.signals import Step
from lfc.testbed.grids import GridCase, case_design
from lfc.testbed.microgrid import MicrogridCase

FIT_STEP = 0.02      # pu, small enough to stay linear
FIT_DURATION = 8.0   # s
FITTED = ("M", "D", "tau_g", "tau_t", "droop", "tau_w", "tau_rocof")
UNITS = {"M": "s", "D": "pu/pu", "tau_g": "s", "tau_t": "s", "droop": "pu", "tau_w": "s",
         "tau_rocof": "s"}
OUTPUTS = ("dPm", "dw", "dw_meas", "rocof_meas")
MISMATCH_WINDOW = 0.05   # s: equivalent_load's mean over it (five control periods)


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
    mismatch : float
        The fitted model's mismatch over the experiments it was fitted on, as load
        (pu): the largest swing of :func:`equivalent_load` (its largest value less
        its smallest) in one experiment.
    """

    params: LFCParams
    initial: LFCParams
    error: dict
    initial_error: dict
    mismatch: float

    def table(self) -> str:
        """Markdown table: parameters (initial, fitted; to the stable digits,
        :mod:`lfc._format`) and errors."""
        lines = ["| parameter | from case data | fitted |", "|---|---|---|"]
        lines += [f"| {n} ({UNITS[n]}) | {number(getattr(self.initial, n))} | "
                  f"{number(getattr(self.params, n))} |" for n in FITTED]
        lines += ["", "| output | error, case data | error, fitted |", "|---|---|---|"]
        lines += [f"| {n} | {100 * self.initial_error[n]:.2f} % | {100 * self.error[n]:.2f} % |"
                  for n in OUTPUTS]
        lines += ["", f"Mismatch as load over the fitting runs (the swing of the load that makes "
                      f"the fitted model reproduce the recorded rotor speed): "
                      f"{number(self.mismatch)} pu"]
        return "\n".join(lines)


def record_experiments(case: MicrogridCase) -> list[dict[str, np.ndarray]]:
    """Run the two small-step experiments on the testbed.

    Returns a list of dicts with ``t`` (s), ``u`` (applied command, pu),
    ``p_load`` (pu) and the ``OUTPUTS`` on a uniform grid.
    """
    from lfc.testbed.microgrid import simulate_microgrid

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


def equivalent_load(params: LFCParams, t: np.ndarray, u: np.ndarray, p_load: np.ndarray,
                    dw: np.ndarray, window: float = MISMATCH_WINDOW) -> np.ndarray:
    """The design model's mismatch with a recorded run, as load: the load ``d`` (pu)
    that, added to the recorded ``p_load``, makes the model ``params`` reproduce the
    recorded rotor speed ``dw`` (pu), given the recorded command ``u`` (pu), on average
    over each ``window`` s.

    The model's governor and turbine (:func:`lfc.model.lfc_matrices`' first two
    rows), driven by ``u`` and ``dw``, give its mechanical power ``dPm``; its swing
    equation ``M dw' = dPm - D dw - (p_load + d)``, integrated over the window ending at
    each sample (trapezoids), gives ``d``'s mean over it.  The integral form reads a
    step of the load, which a record samples on either side of its instant, as a
    step, not as a spike (a derivative's differences would add half the step for one
    sample).  The samples are at the times ``t`` (s): a uniform grid but perhaps the
    last (a run's end); the signals are interpolated onto the uniform grid, and ``d``
    is returned on it from ``window`` on.  Zero, to the trapezoids' error, when the
    record is the model's own.
    """
    t = np.asarray(t, float)
    dt = t[1] - t[0]
    grid = t[0] + dt * np.arange(int(math.floor((t[-1] - t[0]) / dt + 1e-9)) + 1)
    u, p_load, dw = (np.interp(grid, t, np.asarray(v, float)) for v in (u, p_load, dw))
    A, B = lfc_matrices(params)
    governor = ct.ss(A[:2, :2], np.column_stack([B[:2, 0], A[:2, 2]]), [[0.0, 1.0]], 0.0)
    dpm = np.ravel(ct.forced_response(governor, grid, np.vstack([u, dw])).outputs)
    net = cumulative_trapezoid(dpm - params.D * dw - p_load, grid, initial=0.0)
    n = max(1, int(round(window / dt)))
    return (net[n:] - net[:-n] - params.M * (dw[n:] - dw[:-n])) / (n * dt)


def swing(values: np.ndarray) -> float:
    """The largest change of a signal between two of its samples: its maximum less its
    minimum (the total load variation :func:`equivalent_load` stands for)."""
    return float(np.max(values) - np.min(values))


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

    mismatch = max(swing(equivalent_load(fitted, e["t"], e["u"], e["p_load"], e["dw"]))
                   for e in exps)
    return FitReport(fitted, initial, rms(fitted), rms(initial), mismatch)


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
            "error": report.error, "initial_error": report.initial_error,
            "mismatch": report.mismatch}


def decode_report(data: dict) -> FitReport:
    return FitReport(LFCParams(**data["params"]), LFCParams(**data["initial"]),
                     data["error"], data["initial_error"], float(data["mismatch"]))


def check_report(report: FitReport) -> None:
    """Raise ``ValueError`` unless a fit is physically sane: its models valid
    (:class:`LFCParams` checks every parameter), its errors and its mismatch finite
    and >= 0."""
    if not (math.isfinite(report.mismatch) and report.mismatch >= 0):
        raise ValueError(f"mismatch must be a finite number >= 0 (pu), got "
                         f"{report.mismatch!r}")
    for name in ("error", "initial_error"):
        value = getattr(report, name)
        if not (isinstance(value, dict) and all(math.isfinite(v) and v >= 0
                                                for v in value.values())):
            raise ValueError(f"{name} must map each output to a finite number >= 0, got "
                             f"{value!r}")


class FitKind(NamedTuple):
    """One kind of fit: how it is computed, stored and checked (the microgrid's,
    :data:`MICROGRID_FIT`, and the grids', :data:`GRID_FIT`).

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
FIT_FILES = ("model.py", "multiarea.py", "testbed/fit.py", "testbed/grids.py",
             "testbed/microgrid.py")
FIT_FUNCTIONS = ("lfc.engine:agc_step", "lfc.engine:generator_period",
                 "lfc.generator:GeneratorSide")


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


def restamp_committed(case: object, kind: FitKind) -> Path:
    """Stamp the committed fit of ``case`` with today's :func:`fit_inputs`, the fit
    left as it is: after a change of the code that leaves what the fit computes as it
    was, bit for bit (``python -m lfc fit --restamp``, which checks that first); its
    path."""
    path = committed_path(case, kind)
    stored = json.loads(path.read_text(encoding="utf-8"))
    stored["inputs"] = fit_inputs()
    write_atomic(path, json.dumps(stored, indent=1, sort_keys=True) + "\n")
    return path


GRID_FIT_STEP = 0.02      # pu of the area base (36 MW in Kundur's), small enough to stay linear
GRID_FIT_DURATION = 30.0  # s: the turbines' 7 s lag settles
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
        The ladder's rungs as run: ``(step, sign, ratio per area, tripped,
        mismatch)``, ``step`` in pu (area 0's command ``sign * step``, area 1's the
        opposite), ``ratio`` ANDES' peak ``|dw_meas|`` over the model's,
        ``mismatch`` the run's :func:`grid_mismatch` (pu; ∞ for a run that did not
        converge).
    load_mismatch : float
        The fitted model's mismatch with ANDES as load (pu, summed over the areas):
        the largest :func:`grid_mismatch` over the two fitting experiments and the
        ladder's rungs within ``command_range``.  The model's ``load_mismatch``.
    """

    areas: tuple[FitReport, ...]
    T: float
    tie_error: float
    command_range: float
    validation: tuple[tuple[float, int, tuple[float, ...], bool, float], ...]
    load_mismatch: float

    @property
    def params(self) -> MultiAreaParams:
        """The fitted two-area design model, with its command range and its mismatch."""
        return MultiAreaParams(areas=tuple(r.params for r in self.areas),
                               tie=((0, 1, self.T),), command_range=self.command_range,
                               load_mismatch=self.load_mismatch)

    def validation_table(self) -> str:
        """Markdown: the ladder of :func:`validated_range`, one row per run."""
        rows = ["| step (pu) | area 0 / area 1 | ANDES' peak Δω over the model's, per area | "
                "ANDES tripped | mismatch as load (pu) |",
                "|---|---|---|---|---|"]
        rows += [f"| {step:g} | {'+' if sign > 0 else '−'} / {'−' if sign > 0 else '+'} | "
                 f"{', '.join(f'{r:.2f}' for r in ratio)} | {tripped} | {mismatch:.3f} |"
                 for step, sign, ratio, tripped, mismatch in self.validation]
        return "\n".join(rows)

    def table(self) -> str:
        """Markdown: each area's fit table, then the tie-line's."""
        parts = [f"**Area {i}**\n\n{r.table()}" for i, r in enumerate(self.areas)]
        parts.append(f"**Tie-line**: T = {number(self.T)} pu, error {100 * self.tie_error:.2f} %")
        parts.append(f"**Command range**: ±{self.command_range:g} pu; **mismatch as load** "
                     f"within it (summed over the areas): {number(self.load_mismatch)} pu")
        return "\n\n".join(parts)


def grid_mismatch(params: MultiAreaParams, run: Any) -> float:
    """A grid run's mismatch with the design model ``params`` as load (pu): each
    area's :func:`equivalent_load` from its recorded command, net disturbance (load
    plus tie-line export) and rotor speed, its :func:`swing`, summed over the areas
    (the certificates' ``load_bound`` is the loads' variation summed over the areas)."""
    tr = run.trace
    return sum(swing(equivalent_load(area, tr["t"].to_numpy(), tr[f"pc_{a}"].to_numpy(),
                                     tr[f"p_net_{a}"].to_numpy(), tr[f"dw_{a}"].to_numpy()))
               for a, area in enumerate(params.areas))


def record_grid_experiments(case: GridCase, initial: MultiAreaParams) -> list:
    """The two experiments (module docstring), run with the design model
    ``initial``'s AGC: their :class:`Result`."""
    from lfc.testbed.grids import simulate_andes_grid

    return [simulate_andes_grid(initial, duration=GRID_FIT_DURATION, case=case,
                                attacks={0: {"pc": Step(GRID_FIT_STEP, 1.0)}}),
            simulate_andes_grid(initial, duration=GRID_FIT_DURATION, case=case,
                                loads={1: Step(GRID_FIT_STEP, 1.0)})]


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
    within = [rung[4] for rung in validation if rung[0] <= command_range]
    load_mismatch = max([grid_mismatch(fitted, r) for r in runs] + within)
    return GridFit(tuple(reports), T, error, command_range, validation, load_mismatch)


def validated_range(case: GridCase, params: MultiAreaParams) -> tuple[float, tuple]:
    """How far the design model ``params`` describes ``case`` on ANDES (module
    docstring): ``(command_range, rungs)``, the largest rung of ``VALID_STEPS``
    (pu) at which, at it and below, opposite command steps of either sign trip
    nothing on ANDES and move each area's peak ``|dw_meas|`` at most
    ``VALID_RATIO`` times the model's (``GRID_FIT_STEP``, the fit's own step, if the
    first rung fails), and every rung run (:attr:`GridFit.validation`, with each
    run's :func:`grid_mismatch`).  Stops
    at the first rung that fails; ANDES' runs stop at a trip, and one that does
    not converge counts as tripped."""
    from lfc.linear_grid import simulate_grid_linear
    from lfc.testbed.grids import simulate_andes_grid
    from lfc.testbed.loop import TestbedError

    valid, rungs = GRID_FIT_STEP, []
    for step in VALID_STEPS:
        for sign in (1, -1):
            attacks = {0: {"pc": Step(sign * step, 1.0)}, 1: {"pc": Step(-sign * step, 1.0)}}
            model = simulate_grid_linear(params, duration=VALID_DURATION, attacks=attacks)
            try:
                real = simulate_andes_grid(params, duration=VALID_DURATION, case=case,
                                           attacks=attacks, stop_on_trip=True)
                peaks, tripped = [a.metrics()["max_abs_dw_meas"] for a in real.areas], \
                    real.tripped
                mismatch = grid_mismatch(params, real)
            except TestbedError:
                peaks, tripped, mismatch = [math.inf] * params.n_areas, True, math.inf
            ratio = tuple(float(p / m.metrics()["max_abs_dw_meas"])
                          for p, m in zip(peaks, model.areas))
            rungs.append((step, sign, ratio, bool(tripped), mismatch))
            if tripped or max(ratio) > VALID_RATIO:
                return valid, tuple(rungs)
        valid = step
    return valid, tuple(rungs)


def grid_fit_report(case: GridCase | None = None) -> GridFit:
    """:func:`fit_grid` of ``case`` (default ``GridCase.kundur()``), computed
    once per process and case and cached on disk."""
    return _grid_fitted(case or GridCase.kundur())


def grid_design(case: GridCase | None = None) -> MultiAreaParams:
    """The fitted two-area design model of ``case`` (default ``GridCase.kundur()``)."""
    return grid_fit_report(case).params


def _encode(fit: GridFit) -> dict:
    return {"areas": [encode_report(r) for r in fit.areas], "T": fit.T,
            "tie_error": fit.tie_error, "command_range": fit.command_range,
            "validation": [[s, g, list(r), t, m] for s, g, r, t, m in fit.validation],
            "load_mismatch": fit.load_mismatch}


def _decode(data: dict) -> GridFit:
    return GridFit(tuple(decode_report(r) for r in data["areas"]), float(data["T"]),
                   float(data["tie_error"]), float(data["command_range"]),
                   tuple((float(s), int(g), tuple(map(float, r)), bool(t), float(m))
                         for s, g, r, t, m in data["validation"]),
                   float(data["load_mismatch"]))


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
    if fit.command_range not in (GRID_FIT_STEP,) + VALID_STEPS or not fit.validation:
        raise ValueError(f"command_range must be GRID_FIT_STEP or a rung of VALID_STEPS, with the "
                         f"rungs run, got {fit.command_range!r} and {len(fit.validation)} rungs")
    if not (math.isfinite(fit.load_mismatch) and fit.load_mismatch >= 0):
        raise ValueError(f"load_mismatch must be a finite number >= 0 (pu), got "
                         f"{fit.load_mismatch!r}")


#: The grids' fit (:func:`fit_grid`).
GRID_FIT = FitKind("grid-fit", fit_grid, _encode, _decode, _check)


@lru_cache(maxsize=4)
def _grid_fitted(case: GridCase) -> GridFit:
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
    errors and mismatches, and a grid's tie-line coefficient, its error, its command range
    and its mismatch as load."""
    if isinstance(fit, FitReport):
        return {**{n: float(getattr(fit.params, n)) for n in FITTED},
                **{f"error {k}": float(v) for k, v in fit.error.items()},
                "mismatch": fit.mismatch}
    numbers = {}
    for a, report in enumerate(fit.areas):
        numbers.update({f"area {a} {n}": float(getattr(report.params, n)) for n in GRID_FITTED})
        numbers.update({f"area {a} error {k}": float(v) for k, v in report.error.items()})
        numbers[f"area {a} mismatch"] = report.mismatch
    return {**numbers, "T": fit.T, "tie_error": fit.tie_error,
            "command_range": fit.command_range, "load_mismatch": fit.load_mismatch}
