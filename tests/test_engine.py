"""One engine: simulate and simulate_many agree row for row (noise, Kalman estimate,
per-row plants, every filter), and the package's layers hold (no import circle,
a light core)."""

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import lfc
from lfc import simulate_many
from same_metrics import same_metrics

P = lfc.LFCParams()
LFC = Path(lfc.__file__).parent


def test_batch_rows_equal_simulate_seed_for_seed_with_noise_kalman_and_own_plant():
    rows = pd.DataFrame({
        "waveform": ["sinusoid", "square", "step", "sinusoid", "step", "sinusoid"],
        "channel": ["pc", "pc", "wref", "pc", "load", "pc"],
        "amplitude": [0.5, 0.3, 0.04, 0.6, 0.1, 0.4],
        "freq_hz": [1.0, 0.4, 0.0, 0.8, 0.0, 1.0], "start": 1.0,
        "alpha": [20.0, 3.0, 20.0, np.nan, 20.0, 1.0], "Ts": 0.25,
        "method": ["paper", "paper", "paper", "paper", "paper", "certified"],
        "M": [np.nan, 3.2, 4.8, np.nan, 3.5, 3.2], "droop": [np.nan, 0.06, np.nan, 0.04, 0.05,
                                                              np.nan],
        "noise_w": [1e-4, 0.0, 2e-4, 1e-4, 1e-4, 0.0],
        "noise_rocof": [1e-3, 0.0, 1e-3, 0.0, 1e-3, 0.0], "seed": [3, 0, 7, 1, 2, 0]})
    res = simulate_many(P, rows, duration=10.0, chunk_size=4, progress=False)
    for i, row in rows.iterrows():
        plant = lfc.LFCParams(**{**vars(P), **{k: row[k] for k in ("M", "droop")
                                               if pd.notna(row[k])}})
        sig = (lfc.Step(row.amplitude, start=1.0) if row.waveform == "step" else
               {"sinusoid": lfc.Sinusoid, "square": lfc.Square}[row.waveform](
                   row.amplitude, row.freq_hz, start=1.0))
        channel = {"pc": "pc_attack", "wref": "wref_attack", "load": "load"}[row.channel]
        scc = None if np.isnan(row.alpha) else (
            lfc.SafetyFilter(P, method="certified") if row.method == "certified"
            else lfc.SafetyFilter(P, alpha=row.alpha, Ts=row.Ts))
        noise = (row.noise_w, row.noise_rocof)
        m = lfc.simulate(plant, duration=10.0, scc=scc, noise_std=noise, seed=int(row.seed),
                         estimator="kalman" if any(noise) else None, **{channel: sig}).metrics()
        assert same_metrics(m, res.loc[i]), i


def test_batch_rows_equal_simulate_with_noisy_relays_and_the_robust_filter():
    """Rows with ``relay_noise`` (the relays' own noise, seeded by ``seed``) and a
    certified filter declaring a box and the noise equal ``simulate``."""
    rows = pd.DataFrame({"waveform": "square", "channel": "pc", "amplitude": [1.0, 1.0, 0.6],
                         "freq_hz": 0.3, "start": 1.0, "alpha": 1.0, "Ts": 0.25,
                         "method": "certified", "noise_w": 1e-4, "noise_rocof": 1e-3,
                         "seed": [4, 5, 6], "relay_noise": [True, True, False],
                         "declare_noise": [False, True, True],
                         "uncertainty": [np.nan, 0.1, 0.1]})
    res = simulate_many(P, rows, duration=8.0, chunk_size=2, progress=False)
    for i, row in rows.iterrows():
        scc = lfc.SafetyFilter(P, method="certified",
                               uncertainty=0.0 if np.isnan(row.uncertainty) else row.uncertainty,
                               noise_std=(1e-4, 1e-3) if row.declare_noise else None)
        m = lfc.simulate(P, duration=8.0, scc=scc, noise_std=(1e-4, 1e-3), seed=int(row.seed),
                         estimator="kalman", relay_noise=bool(row.relay_noise),
                         pc_attack=lfc.Square(row.amplitude, 0.3, start=1.0)).metrics()
        r = res.loc[i]
        assert m["tripped"] == r.tripped and m["alarms"] == r.alarms, i
        assert m["max_abs_rocof_meas"] == r.max_abs_rocof_meas, i
    assert res.tripped[0] and not res.tripped[1:].any()   # undeclared noise trips; declared not


def test_relay_noise_needs_noise():
    with pytest.raises(ValueError, match="relay_noise"):
        lfc.simulate(P, duration=1.0, relay_noise=True)
    rows = pd.DataFrame({"waveform": "none", "channel": "pc", "amplitude": 0.0, "freq_hz": 0.0,
                         "start": 0.0, "alpha": np.nan, "Ts": 0.25, "relay_noise": [True]})
    with pytest.raises(ValueError, match="relay_noise"):
        simulate_many(P, rows, duration=1.0, progress=False)


def test_the_plant_need_not_be_the_design_model():
    """A row's own plant changes the run; the filter keeps the design model."""
    base = {"waveform": "square", "channel": "pc", "amplitude": 1.0, "freq_hz": 0.3,
            "start": 1.0, "alpha": 1.0, "Ts": 0.25, "method": "certified"}
    rows = pd.DataFrame([base, {**base, "M": 0.8 * P.M}])
    res = simulate_many(P, rows, duration=10.0, progress=False)
    assert res.max_abs_rocof_meas[1] > res.max_abs_rocof_meas[0]


@pytest.mark.parametrize("column, value, message", [
    ("M", 0.0, "column 'M' must be finite and > 0"), ("droop", -0.05, "'droop'"),
    ("noise_w", -1e-4, "column 'noise_w' must be finite and >= 0"),
    ("seed", 1.5, "column 'seed' must be integers >= 0")])
def test_bad_plant_and_noise_columns_name_the_column(column, value, message):
    row = pd.DataFrame([{"waveform": "none", "channel": "pc", "amplitude": 0.0, "freq_hz": 0.0,
                         "start": 0.0, "alpha": np.nan, "Ts": 0.25, column: value}])
    with pytest.raises(ValueError, match=message):
        simulate_many(P, row, duration=1.0, progress=False)


HEAVY = ("numpy", "pandas", "numba", "scipy", "control", "cvxpy", "matplotlib", "andes",
         "papermill", "nbformat", "jupyter_client", "dask", "distributed")


def test_import_lfc_loads_no_heavy_or_optional_package():
    """``import lfc`` imports none of them (each name is imported when first used);
    the first use imports the core and still none of the optional ones."""
    code = ("import sys, lfc; print(sorted(m for m in %r if m in sys.modules)); lfc.LFCParams; "
            "print(sorted(m for m in ('cvxpy', 'matplotlib', 'andes', 'papermill', 'dask', "
            "'distributed', 'scipy.stats', 'scipy.optimize') if m in sys.modules))" % (HEAVY,))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.split("\n")[:2] == ["[]", "[]"]


def test_the_command_lines_help_and_usage_errors_load_no_heavy_package():
    """``python -m lfc --help`` and a usage error parse the command line with the
    standard library and numpy alone (papermill, pandas, numba: where a command runs)."""
    code = ("import sys; from lfc.repro.cli import main; main(%r); "
            "print(sorted(m for m in %r if m in sys.modules))")
    for argv in (["--help"], ["reproduce", "--only", "nope"], ["sweep"]):
        out = subprocess.run([sys.executable, "-c", code % (argv, HEAVY)], capture_output=True,
                             text=True)
        assert out.stdout.strip().splitlines()[-1] == "['numpy']", (argv, out.stdout[-300:])


def test_the_package_namespace_is_the_one_it_documents():
    """Every name of ``lfc.__all__`` resolves (imported on first use), ``lfc.simulate``
    is the function (no submodule has its name), and a name the package does not have
    is an ``AttributeError``."""
    import importlib.util

    import lfc
    for name in lfc.__all__:
        assert getattr(lfc, name) is not None, name
    for name in ("simulate", "simulate_many"):      # the functions; no module shadows them
        assert importlib.util.find_spec(f"lfc.{name}") is None
    assert callable(lfc.simulate) and lfc.simulate.__module__ == "lfc.run"
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        lfc.nope  # noqa: B018


def _imports(path: Path) -> set[str]:
    """The lfc modules a file imports, anywhere in it."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("lfc"):
            found |= {node.module} | {f"{node.module}.{a.name}" for a in node.names}
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("lfc")}
    return found


def _module(path: Path) -> str:
    rel = path.relative_to(LFC.parent).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def test_layers_point_one_way_and_no_module_imports_itself_back():
    """Core (lfc.*) never imports experiments or reproduction; experiments never
    import reproduction; and the module-level import graph has no circle."""
    files = {_module(p): p for p in LFC.rglob("*.py")}
    layer = {m: 2 if m.startswith(("lfc.repro", "lfc.__main__")) else
             1 if m.startswith("lfc.experiments") else 0
             for m in files}
    for m, path in files.items():
        for dep in _imports(path):
            target = max((k for k in files if dep == k or dep.startswith(k + ".")), key=len,
                         default=None)
            assert target is None or layer[target] <= layer[m], f"{m} imports {target}"
    graph = {m: {d for d in (_top_level_imports(p)) if d in files and d != m}
             for m, p in files.items()}
    seen, stack = set(), set()

    def visit(m: str) -> None:
        assert m not in stack, f"import circle through {m}"
        if m in seen:
            return
        stack.add(m)
        for d in graph[m]:
            visit(d)
        stack.discard(m)
        seen.add(m)
    for m in graph:
        visit(m)


def _top_level_imports(path: Path) -> set[str]:
    names = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("lfc"):
            names |= {node.module} | {f"{node.module}.{a.name}" for a in node.names}
        elif isinstance(node, ast.Import):
            names |= {a.name for a in node.names if a.name.startswith("lfc")}
    return names
