"""Every notebook through papermill with short parameters; reproduce and sweep."""

import json
import subprocess

import pandas as pd
import pytest

from lfc.repro import runner
from lfc.repro.cli import main
from lfc.repro.notebook import figure_name, record_claims
from lfc.simulate import METRIC_KEYS

SHORT = {"duration": 3.0}
PANELS = {"tutorial": {"no_scc", "scc"}, "fig4": {"a", "b", "c", "d"},
          "fig5": {"no_scc", "scc"}, "fig6": {"no_scc", "scc"}, "fig7": {"no_scc", "scc"},
          "kalman": {"no_scc", "scc_true", "scc_kalman"}}
FIGURE_FILES = {"tutorial": "tutorial_attack", "fig4": "fig4_rocof_attack",
                "fig5": "fig5_bias_attack", "fig6": "fig6_load_step", "fig7": "fig7_fault",
                "kalman": "kalman_scc"}
EXTRA_METRICS = {"fig7": {"oc_trip_t"}}
RUNS = [(name, plant) for name, plants in runner.FIGURE_PLANTS.items() for plant in plants
        if name not in ("surface", "redteam")]
SMALL_SURFACE = {"amplitudes": [0.1, 0.5], "freqs": [0.5, 1.0], "biases": [0.02, 0.04],
                 "tradeoff_alphas": [20.0], "tradeoff_Ts": [0.25], "load_steps": [0.1, 0.25],
                 "readings_load_steps": [0.1], "duration": 10.0, "jobs": 1,
                 "check_claims": False}


@pytest.mark.parametrize("name, plant", RUNS)
def test_notebook_runs_and_writes_figure_and_metrics(name, plant, tmp_path):
    nb = runner.NOTEBOOKS_DIR / runner.FIGURES[name]
    runner.execute(nb, tmp_path / nb.name, {**SHORT, "check_claims": False, "plant": plant,
                                            "figures_dir": str(tmp_path / "fig"),
                                            "results_dir": str(tmp_path / "res")})
    for ext in ("png", "pdf"):
        path = tmp_path / "fig" / f"{figure_name(FIGURE_FILES[name], plant)}.{ext}"
        assert path.stat().st_size > 1000
    metrics = json.loads((tmp_path / "res" / "metrics.json").read_text())
    assert set(metrics) == PANELS[name]
    for panel in metrics.values():
        assert set(panel) == set(METRIC_KEYS) | {"parameters"} | EXTRA_METRICS.get(name, set())
        assert panel["parameters"]["duration"] == 3.0
        assert panel["parameters"]["plant"] == plant
    assert json.loads((tmp_path / "res" / "claims.json").read_text())


def test_attack_surface_notebook_writes_maps_tables_and_claims(tmp_path):
    nb = runner.NOTEBOOKS_DIR / runner.FIGURES["surface"]
    runner.execute(nb, tmp_path / nb.name, {**SMALL_SURFACE, "figures_dir": str(tmp_path / "fig"),
                                            "results_dir": str(tmp_path / "res")})
    for name in ("readings", "attack_surface", "bias_surface", "alpha_ts_tradeoff"):
        assert (tmp_path / "fig" / f"{name}.png").stat().st_size > 1000
    surface = pd.read_csv(tmp_path / "res" / "surface.csv")
    assert len(surface) == 2 * 3 * 2 * 2  # waveforms x (no SCC, 2 alphas) x amplitudes x freqs
    assert len(pd.read_csv(tmp_path / "res" / "bias.csv")) == 3 * 2
    assert len(pd.read_csv(tmp_path / "res" / "tradeoff.csv")) == 2 * 3
    # 12 readings x 2 alphas: every attack (8 periodic, 2 biases) and the load step
    assert len(pd.read_csv(tmp_path / "res" / "readings.csv")) == 10 + 24 * 11
    table = (tmp_path / "fig" / "readings.md").read_text()
    assert table.count("hold / frequency / incoming") == 2      # one row per alpha
    # claims about the default grid are computed on this small one, not asserted
    claims = json.loads((tmp_path / "res" / "claims.json").read_text())
    assert {"the default reading stops the most tripping attacks of the maps, at every alpha",
            "E12: every load step above the no-SCC threshold trips ROCOF with every SCC setting"
            } <= set(claims)


SMALL_RED_TEAM = {"families": ["square on P_c"], "family_maxiter": 2, "family_popsize": 3,
                  "search_duration": 4.0, "n_seeds": 2, "freeform_attack_duration": 0.2,
                  "freeform_duration": 2.0, "freeform_maxiter": 1, "map_amplitudes": [0.5, 1.0],
                  "map_freqs": [0.3, 1.0], "plant_steps": [5e-4, 1e-3], "n_interior": 1,
                  "n_box_attacks": 2, "box_duration": 5.0, "n_noise_seeds": 2,
                  "margins": [0.1, 0.3], "load_steps": [0.1], "testbed": False,
                  "check_claims": False}


def tracked_changes() -> str:
    """``git status`` of the tracked files (empty when nothing changed)."""
    out = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                         cwd=runner.ROOT, capture_output=True, text=True)
    if out.returncode:
        pytest.skip("not a git checkout")
    return out.stdout


def test_red_team_notebook_writes_results_figures_and_the_comparison_table(tmp_path):
    before = tracked_changes()
    nb = runner.NOTEBOOKS_DIR / runner.FIGURES["redteam"]
    runner.execute(nb, tmp_path / nb.name, {**SMALL_RED_TEAM,
                                            "figures_dir": str(tmp_path / "fig"),
                                            "results_dir": str(tmp_path / "res")})
    for name in ("red_team", "certified_vs_paper", "robust_box"):
        assert (tmp_path / "fig" / f"{name}.png").stat().st_size > 1000
    red = pd.read_csv(tmp_path / "res" / "red_team.csv")
    assert set(red.defender) == {"paper α=20", "certified", "robust"}
    table = (tmp_path / "fig" / "comparison.md").read_text()
    assert "| certified filter |" in table and "| robust filter" in table
    assert "µs" not in table   # no run-to-run latencies
    claims = json.loads((tmp_path / "res" / "claims.json").read_text())
    # a small run: the claims that hold whatever the budget (the robust filter's)
    for claim, value in claims.items():
        if claim.startswith("robust filter: no") or "any plant step" in claim:
            assert value, claim
    assert tracked_changes() == before   # the README and every tracked file untouched


@pytest.mark.parametrize("name", ["tutorial", "kalman"])
def test_linear_only_notebooks_refuse_the_testbed(name, tmp_path):
    nb = runner.NOTEBOOKS_DIR / runner.FIGURES[name]
    with pytest.raises(runner.pm.PapermillExecutionError, match="for this notebook"):
        runner.execute(nb, tmp_path / nb.name, {"plant": "testbed", "results_dir": str(tmp_path),
                                                "figures_dir": str(tmp_path)})


def fig5_metrics(relay: str, peak: float) -> dict:
    trip = {"relay": relay, "t": 15.6}
    return {"no_scc": {"first_trip": trip, "max_abs_dw_meas": 0.0376},
            "scc": {"first_trip": trip, "max_abs_dw_meas": peak}}


def test_documented_deviations_are_predicates_on_the_run(tmp_path):
    claim = "with SCC no relay trips"  # a documented deviation on the testbed (Fig. 5)
    record_claims(tmp_path, {claim: False}, check=True, plant="testbed",
                  metrics=fig5_metrics("OF2", 0.0361))
    why = json.loads((tmp_path / "deviations.json").read_text())[claim]
    assert "1.0361 pu" in why and "15.60 s" in why        # the run's own numbers
    for relay, peak in (("ROCOF", 0.0361), ("OF2", 0.045)):  # failed another way: not covered
        with pytest.raises(AssertionError, match="not reproduced"):
            record_claims(tmp_path, {claim: False}, check=True, plant="testbed",
                          metrics=fig5_metrics(relay, peak))
    with pytest.raises(AssertionError, match="claim"):
        record_claims(tmp_path, {claim: False}, check=True, plant="linear")
    with pytest.raises(AssertionError, match="no longer observed"):
        record_claims(tmp_path, {claim: True}, check=True, plant="testbed",
                      metrics=fig5_metrics("OF2", 0.0361))


def test_reproduce_never_reports_claims_of_an_earlier_run(tmp_path, monkeypatch):
    results = tmp_path / "build" / "reproduce" / "fig4"
    results.mkdir(parents=True)
    (results / "claims.json").write_text(json.dumps({"a claim of an earlier run": True}))

    def fails_early(notebook, output, parameters):
        raise runner.pm.PapermillExecutionError(0, 1, "", "ImportError", "broken", [])
    monkeypatch.setattr(runner, "execute", fails_early)
    outcome, = runner.reproduce(["fig4"], "linear", figures_dir=tmp_path / "fig",
                                build_dir=tmp_path / "build")
    assert not outcome.ok and outcome.claims == {} and "ImportError" in outcome.error
    assert list(runner.summary_table([outcome]).reproduced) == ["no"]


def test_a_broken_claim_fails_the_notebook(tmp_path):
    nb = runner.NOTEBOOKS_DIR / runner.FIGURES["fig4"]
    with pytest.raises(runner.pm.PapermillExecutionError, match="claim"):
        runner.execute(nb, tmp_path / nb.name, {"amplitude": 0.1, "duration": 3.0,
                                                "figures_dir": str(tmp_path),
                                                "results_dir": str(tmp_path)})


def test_reproduce_only_fig4(tmp_path, capsys):
    code = main(["reproduce", "--only", "fig4", "--plant", "linear",
                 "--figures-dir", str(tmp_path / "fig"),
                 "--build-dir", str(tmp_path / "build")])
    out = capsys.readouterr().out
    assert code == 0 and "(a) attack trips ROCOF without SCC" in out
    rows = [line for line in out.splitlines() if line.strip().startswith("fig4")]
    assert len(rows) == 5 and all(line.split()[-2] == "yes" for line in rows)
    assert (tmp_path / "fig" / "fig4_rocof_attack.png").exists()
    assert (tmp_path / "build" / "reproduce" / "fig4" / "02_fig4_rocof_attack.ipynb").exists()


def test_sweep_table_and_resume(tmp_path):
    nb = runner.NOTEBOOKS_DIR / runner.FIGURES["fig4"]
    out = tmp_path / "sweep"
    grid = {"alpha": [3.0, 20.0], "duration": [2.0]}
    table = runner.sweep(nb, grid, out)
    assert len(table) == 8 and set(table.panel) == {"a", "b", "c", "d"}
    assert set(table.alpha) == {3.0, 20.0}
    assert {"first_trip_relay", "first_trip_t", "max_abs_rocof_meas"} <= set(table.columns)
    assert (out / "sweep.csv").exists()
    done = {p: p.stat().st_mtime_ns for p in out.glob("*/done.json")}
    # interrupt: one run lost its marker; the rerun repeats only that one
    lost = out / runner.run_id({"alpha": 3.0, "duration": 2.0}) / "done.json"
    lost.unlink()
    again = runner.sweep(nb, grid, out)
    assert again.equals(table)
    for path, mtime in done.items():
        if path != lost:
            assert path.stat().st_mtime_ns == mtime
    assert lost.exists()


@pytest.mark.parametrize("args, message", [
    (["-p", "alpah", "3"], "unknown parameter 'alpah'"),
    (["-p", "duration", "-1"], "'duration' must be > 0"),
    (["-p", "amplitude", "big"], "'amplitude' must be a finite number"),
    (["-p", "amplitude", "nan"], "'amplitude' must be a finite number"),
    (["-p", "amplitude", "0.5", "-p", "amplitude", "0.5"], "lists 0.5 more than once"),
    (["-p", "amplitude", "0.5", "0.5"], "lists 0.5 more than once"),
    (["-p", "seed", "1.5"], "'seed' must be an integer"),
    (["-p", "edge_durations", "[]"], "must be a non-empty list"),
    (["-p", "edge_durations", "['a']"], "must be a finite number"),
    (["-p", "alpha", "3", "--jobs", "0"], "--jobs must be an integer >= 1"),
    (["-p", "plant", "simscape"], "plant must be one of"),
    (["-p", "plant", "linear", "testbed", "simscape"], "plant must be one of"),
])
def test_sweep_rejects_bad_parameters_before_running(args, message, tmp_path, capsys):
    nb = str(runner.NOTEBOOKS_DIR / runner.FIGURES["fig4"])
    assert main(["sweep", nb, *args, "--out", str(tmp_path / "s")]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "s").exists()


def test_a_repeated_parameter_adds_its_values(tmp_path):
    from lfc.repro.cli import _grid
    assert _grid([["alpha", "3"], ["alpha", "20"], ["Ts", "0.25"]]) == {"alpha": [3, 20],
                                                                        "Ts": [0.25]}


def test_a_notebook_run_directly_fails_fast_on_an_unknown_parameter(tmp_path):
    """papermill itself ignores a name the notebook does not take (it injects it
    anyway); the notebook's first cell refuses it."""
    nb = runner.NOTEBOOKS_DIR / runner.FIGURES["kalman"]
    with pytest.raises(runner.pm.PapermillExecutionError, match="unknown parameter.*alpah"):
        runner.pm.execute_notebook(str(nb), str(tmp_path / "out.ipynb"),
                                   parameters={"alpah": 3.0, "results_dir": str(tmp_path)},
                                   cwd=str(nb.parent), progress_bar=False)
    executed = json.loads((tmp_path / "out.ipynb").read_text())
    ran = [c for c in executed["cells"] if c["cell_type"] == "code" and c.get("outputs")]
    assert len(ran) == 1        # the error is in the first cell after the parameters


def test_reproduce_rejects_unknown_figure():
    with pytest.raises(ValueError, match="unknown figure"):
        runner.reproduce(["fig9"])
