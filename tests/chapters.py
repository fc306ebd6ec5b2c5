"""Each chapter's scenario built through the API, at the notebook's own defaults: what
the default tier checks the chapters' claims on, without executing a notebook
(``reproduce`` and the exhaustive tier execute them).

The parameters are read from each notebook's parameters cell (its literal defaults),
so a changed default is the scenario checked here too; the runs are built as the
notebook's cells build them, and the claims are the notebook's (one definition in
``lfc.experiments.claims``), asserted by ``record_claims`` as the notebook asserts
them (a documented deviation is a predicate on the run's metrics).

:func:`executed` runs a chapter's notebook once per test session, shared by the
workers (a lock and a folder the workers share): the exhaustive tier's chapter runs.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

import lfc
from lfc.experiments import claims as paper_claims
from lfc.experiments.scenarios import (ATTACK_START, MULTIAREA_AMPLITUDE, MULTIAREA_ATTACKED,
                                       simulator)
from lfc.repro.manifest import chapter
from lfc.repro.notebook import _literals, record_claims, setup

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"


def defaults(name: str) -> dict:
    """The literal defaults of chapter ``name``'s parameters cell."""
    cells = json.loads((NOTEBOOKS / chapter(name).notebook).read_text())["cells"]
    cell = next(c for c in cells if "parameters" in c["metadata"].get("tags", []))
    return _literals("".join(cell["source"]))


def _knobs(p: dict) -> dict:
    return {k: p[k] for k in ("M", "relay_category", "rocof_limit") if k in p}


def _run(p: dict, relays) -> dict:
    return dict(duration=p["duration"], relays=relays, control_period=p["control_period"],
                seed=p["seed"], noise_std=tuple(p["noise_std"]))


def tutorial(plant: str = "linear") -> tuple[dict, dict]:
    """Chapter 01: the attack with and without the SCC, and the printed QP's gap to
    the closed form (cvxpy), at the tutorial's state."""
    import cvxpy as cp

    from lfc.model import output_matrix
    p = defaults("tutorial")
    params, relays = setup(plant, supported=("linear",), **_knobs(p))
    dw, rocof = relays.F / 3, relays.rocof_limit / 3
    p_m = params.M * rocof + params.D * dw
    x = np.array([p_m, p_m, dw, dw, rocof])
    A, B = lfc.lfc_matrices(params)
    Ad, Bd = lfc.discretize(params, p["Ts"])
    C, limits = output_matrix(), np.array([relays.F, relays.rocof_limit])

    def predicted(u: float) -> np.ndarray:
        return C @ (Ad @ x + Bd @ np.array([u, 0.0]))

    u_ref = next(u for u in 0.6 / 2.0 ** np.arange(20) if np.all(np.abs(predicted(u)) < limits))
    y = predicted(u_ref)
    h = limits**2 - y**2
    dh_dx = -2 * y[:, None] * (C @ Ad)
    barrier = -np.log(h / (1 + h))
    u = cp.Variable()
    x_dot = A @ x + u * B[:, 0]
    b_dot = cp.hstack([-(dh_dx[i] @ x_dot) / (h[i] + h[i]**2) for i in range(2)])
    cp.Problem(cp.Minimize(0.5 * cp.square(u - u_ref)),
               [b_dot - p["alpha"] / barrier <= 0]).solve(solver=cp.CLARABEL)
    scc = lfc.SafetyFilter(params, relays, alpha=p["alpha"], Ts=p["Ts"])
    u_exact, _ = scc.filter(x, u_ref)
    signal = {"sinusoid": lfc.Sinusoid, "square": lfc.Square}[p["waveform"]]
    run = dict(**_run(p, relays), pc_attack=signal(p["amplitude"], p["freq_hz"], start=1.0))
    runs = {"no_scc": lfc.simulate(params, **run), "scc": lfc.simulate(params, scc=scc, **run)}
    return paper_claims.tutorial_claims(runs, qp_gap=abs(u.value - u_exact)), runs


def fig4(plant: str = "linear", **options) -> tuple[dict, dict]:
    """Chapter 02: Fig. 4's panels (a)-(d) (``options``: more simulation keywords)."""
    p = defaults("fig4")
    params, relays = setup(plant, **_knobs(p))
    simulate = simulator(plant)
    a_b, a_c = (p["alpha"], p["alpha"]) if p["alpha"] is not None else p["alphas"]
    attack = lfc.Sinusoid(p["amplitude"], p["freq_hz"], start=ATTACK_START)
    weak = lfc.Sinusoid(p["weak_amplitude"], p["freq_hz"], start=ATTACK_START)
    scc_b = lfc.SafetyFilter(params, relays, alpha=a_b, Ts=p["Ts"])
    scc_c = lfc.SafetyFilter(params, relays, alpha=a_c, Ts=p["Ts"])
    run = {**_run(p, relays), **options}
    runs = {"a": simulate(params, pc_attack=attack, **run),
            "b": simulate(params, pc_attack=attack, scc=scc_b, **run),
            "c": simulate(params, pc_attack=attack, scc=scc_c, **run),
            "d": simulate(params, pc_attack=weak, scc=scc_c, **run)}
    return paper_claims.fig4_claims(runs, alphas=(a_b, a_c)), runs


def fig5(plant: str = "linear", **options) -> tuple[dict, dict]:
    """Chapter 03: Fig. 5's bias on the frequency reference."""
    p = defaults("fig5")
    params, relays = setup(plant, **_knobs(p))
    simulate = simulator(plant)
    scc = lfc.SafetyFilter(params, relays, alpha=p["alpha"], Ts=p["Ts"])
    run = dict(**_run(p, relays), wref_attack=lfc.Step(p["bias"], start=ATTACK_START),
               **options)
    runs = {"no_scc": simulate(params, **run), "scc": simulate(params, scc=scc, **run)}
    return paper_claims.fig5_claims(runs, relays), runs


def fig6(plant: str = "linear", **options) -> tuple[dict, dict]:
    """Chapter 04: Fig. 6's legitimate load step."""
    p = defaults("fig6")
    params, relays = setup(plant, **_knobs(p))
    simulate = simulator(plant)
    scc = lfc.SafetyFilter(params, relays, alpha=p["alpha"], Ts=p["Ts"])
    run = dict(**_run(p, relays), load=lfc.Step(p["load_step"], start=ATTACK_START),
               **options)
    runs = {"no_scc": simulate(params, **run), "scc": simulate(params, scc=scc, **run)}
    return paper_claims.fig6_claims(runs), runs


def fig7(plant: str = "testbed", **options) -> tuple[dict, dict]:
    """Chapter 05: Fig. 7's fault at B5, on ANDES."""
    from lfc.testbed import FaultSpec, MicrogridCase
    p = defaults("fig7")
    params, _ = setup(plant, supported=("testbed",))
    relays = lfc.RelaySettings(rocof_delay=p["rocof_delay"])
    scc = lfc.SafetyFilter(params, relays, alpha=p["alpha"], Ts=p["Ts"])
    run = dict(**_run(p, relays), fault=FaultSpec(p["fault_bus"], p["fault_t"], p["fault_xf"]),
               **options)
    case = MicrogridCase()
    runs = {"no_scc": lfc.simulate(case, design=params, **run),
            "scc": lfc.simulate(case, design=params, scc=scc, **run)}
    return paper_claims.fig7_claims(runs), runs


def kalman(plant: str = "linear") -> tuple[dict, dict]:
    """Chapter 07: the SCC on the true state and on a Kalman estimate."""
    p = defaults("kalman")
    params, relays = setup(plant, supported=("linear",), **_knobs(p))
    scc = lfc.SafetyFilter(params, relays, alpha=p["alpha"], Ts=p["Ts"])
    run = dict(duration=p["duration"], relays=relays, seed=p["seed"],
               control_period=p["control_period"], noise_std=(p["noise_w"], p["noise_rocof"]),
               pc_attack=lfc.Sinusoid(p["amplitude"], p["freq_hz"], start=ATTACK_START))
    runs = {"no_scc": lfc.simulate(params, **run),
            "scc_true": lfc.simulate(params, scc=scc, **run),
            "scc_kalman": lfc.simulate(params, scc=scc, estimator="kalman", **run)}
    kal = runs["scc_kalman"]
    truth = kal.trace.set_index("t").loc[kal.controls.t]
    rms = (float(np.sqrt(np.mean((kal.controls.dw_hat.to_numpy()
                                  - truth.dw_meas.to_numpy())**2))),
           float(np.sqrt(np.mean((kal.controls.rocof_hat.to_numpy()
                                  - truth.rocof_meas.to_numpy())**2))))
    return paper_claims.kalman_claims(runs, rms, (p["noise_w"], p["noise_rocof"])), runs


def multiarea(plant: str = "linear", **options) -> tuple[dict, dict]:
    """Chapter 09: a load step and three attacks with no filters, the paper's SCC at its
    barrier gains, the certified filters and the coupled certificate at every area (on
    ANDES through the stored runs and the committed recordings,
    ``lfc.testbed.stored_runs``); the claims and each area's metrics as
    ``metrics.json`` holds them (what the documented deviations read:
    on ANDES the certified filters' runs on the fitted model itself, and each area's
    ``load_bound``).  ``options``: more keywords of every ANDES run (``step``)."""
    from lfc.experiments.deviations import multiarea_records
    from lfc.filters.bounds import tie_step_bound
    p = defaults("multiarea")
    relays = lfc.RelaySettings()
    amplitude = MULTIAREA_AMPLITUDE[plant] if p["amplitude"] is None else p["amplitude"]
    attacked = MULTIAREA_ATTACKED[plant] if p["attacked_area"] is None else p["attacked_area"]
    if plant == "linear":
        params = getattr(lfc.MultiAreaParams, p["grid"])()
    else:
        from lfc.testbed import GridCase, grid_design
        case = GridCase.kundur() if plant == "testbed" else GridCase.ieee39()
        params = grid_design(case)

    def simulate_all(scenarios: dict, **common) -> dict:
        if plant == "linear":
            return {name: lfc.simulate(params, **kw, **common) for name, kw in scenarios.items()}
        return dict(zip(scenarios, lfc.simulate_many(case, list(scenarios.values()),
                                                     design=params, jobs=1, progress=False,
                                                     keep="results", **common, **options)))

    def paper_scc(alpha: float) -> dict:
        return {a: lfc.SafetyFilter(area, relays, alpha=alpha)
                for a, area in enumerate(params.areas)}

    defences = {"none": {}, **{f"paper α={a:g}": paper_scc(a) for a in p["paper_alphas"]},
                "certified": {a: "certified" for a in range(params.n_areas)},
                "coupled": {a: "coupled" for a in range(params.n_areas)}}
    load_runs = simulate_all({name: {"filters": f} for name, f in defences.items()},
                             duration=p["load_duration"], relays=relays,
                             loads={0: lfc.Step(p["load_step"], start=ATTACK_START)})
    sinusoid = lfc.Sinusoid(amplitude, p["freq_hz"], start=ATTACK_START)
    bias = lfc.Step(p["ace_bias"], start=ATTACK_START)
    attack_sets = {"single": {attacked: {"pc": sinusoid}},
                   "coordinated": {a: {"pc": sinusoid} for a in range(params.n_areas)},
                   "ACE": {a: {"ace": bias} for a in range(params.n_areas)}}
    batch = simulate_all({(name, kind): {"attacks": attacks, "filters": filters}
                          for name, attacks in attack_sets.items()
                          for kind, filters in defences.items()},
                         duration=p["duration"], relays=relays)
    attack_runs = {name: {kind: batch[name, kind] for kind in defences} for name in attack_sets}
    load_bounds = [tie_step_bound(params, a, relays, 0.01) for a in range(params.n_areas)]
    model_runs = {} if plant == "linear" else {
        name: lfc.simulate(params, attacks=attacks, filters=defences["certified"],
                           duration=p["duration"], relays=relays)
        for name, attacks in attack_sets.items()}
    flat, extra = multiarea_records(load_runs, attack_runs, model_runs, load_bounds)
    metrics = {name: {**area.metrics(), **extra[name]} for name, area in flat.items()}
    return paper_claims.multiarea_claims(load_runs, attack_runs), metrics


BUILDERS = {"tutorial": tutorial, "fig4": fig4, "fig5": fig5, "fig6": fig6, "fig7": fig7,
            "kalman": kalman}


def checked(name: str, plant: str, folder: Path, metrics: dict | None = None) -> dict:
    """Chapter ``name``'s claims on ``plant``, asserted as the notebook asserts them
    (``record_claims``: a claim that fails is a documented deviation or an error) into
    ``folder``; the claims."""
    claims, runs = BUILDERS[name](plant)
    record_claims(folder, claims, True, plant,
                  metrics or {k: r.metrics() for k, r in runs.items()})
    return claims


def executed(name: str, base: Path, parameters: dict | None = None) -> Path:
    """Chapter ``name`` executed at its defaults (``parameters`` override them) on the
    linear model, once per test session: the first worker to ask runs it under a lock
    in ``base`` (a folder the workers share), the others read its results folder."""
    import hashlib

    from lfc._files import folder_lock
    from lfc.repro import runner
    key = hashlib.sha1(json.dumps([name, parameters or {}], sort_keys=True).encode())
    out = base / f"{name}-{key.hexdigest()[:10]}"
    with folder_lock(out):
        if not (out / "claims.json").exists():
            nb = runner.NOTEBOOKS_DIR / chapter(name).notebook
            runner.execute(nb, out / nb.name, {"figures_dir": str(out),
                                               "results_dir": str(out), **(parameters or {})})
    return out


def shared_folder(config, tmp_path_factory) -> Path:
    """A folder every worker of this test session shares (pytest-xdist's run id)."""
    run = getattr(config, "workerinput", {}).get("testrunuid") or str(os.getpid())
    base = tmp_path_factory.getbasetemp()
    base = base.parent if hasattr(config, "workerinput") else base
    folder = base / f"chapters-{run}"
    folder.mkdir(parents=True, exist_ok=True)
    return folder
