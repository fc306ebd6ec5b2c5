"""Results that must not depend on the BLAS kernel (issue "Hardened", item 6).

The linear chapters' scenarios — Figs. 4–6 with the paper's SCC at both α, the
certified and robust filters, the load-step threshold, a two-area ACE attack and
a small map — run in two subprocesses under two OpenBLAS core types; every
verdict (tripped, which relay, alarms, outside) must be equal and every number
equal to the digits the tables report (1e-6 relative).  ``.ci/run`` also reruns
the filter and engine tests under a second core type.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FLAGS = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
CORES = ["Haswell", "SkylakeX" if "avx512f" in FLAGS else "Sandybridge"]

SCRIPT = r"""
import json
import lfc
from lfc.experiments.scenarios import (ATTACK_START, FIG4_AMPLITUDE, FIG4_FREQ, FIG5_BIAS,
                                       FIG6_LOAD)
from lfc.experiments.surface import attack_map

P, R = lfc.LFCParams(), lfc.RelaySettings()
fig4 = lfc.Sinusoid(FIG4_AMPLITUDE, FIG4_FREQ, start=ATTACK_START)
fig5 = lfc.Step(FIG5_BIAS, start=ATTACK_START)
runs = {}
for a in (3.0, 20.0):
    f = lfc.SafetyFilter(P, R, alpha=a)
    runs[f"fig4 a={a}"] = lfc.simulate(P, duration=10.0, pc_attack=fig4, scc=f)
    runs[f"fig5 a={a}"] = lfc.simulate(P, duration=30.0, wref_attack=fig5, scc=f)
    runs[f"fig6 a={a}"] = lfc.simulate(P, duration=30.0, load=lfc.Step(FIG6_LOAD, 1.0), scc=f)
cert = lfc.SafetyFilter(P, R, method="certified")
robust = lfc.SafetyFilter(P, R, method="certified", uncertainty=0.2, noise_std=(1e-4, 1e-3))
runs["certified fig4 1.5"] = lfc.simulate(P, duration=10.0, scc=cert,
                                          pc_attack=lfc.Sinusoid(1.5, 0.5, start=1.0))
runs["robust kalman"] = lfc.simulate(P, duration=10.0, scc=robust, estimator="kalman",
                                     noise_std=(1e-4, 1e-3), seed=3, pc_attack=fig4)
two = lfc.MultiAreaParams.two_area()
grid = lfc.simulate(two, duration=15.0, attacks={0: {"ace": lfc.Step(-2.5, start=1.0)}},
                    filters={0: "paper", 1: "paper"})
out = {name: r.metrics() for name, r in runs.items()}
out.update({f"two-area ace, area {i}": m for i, m in enumerate(grid.metrics())})
table = lfc.simulate_many(P, attack_map(["sinusoid", "square"], [0.3, 1.0, 2.0],
                                        [0.2, 1.0], alphas=[3.0, 20.0]),
                          duration=10.0, progress=False, chunk_size=100)
out["map"] = {"tripped": table.tripped.tolist(), "alarms": table.alarms.tolist(),
              "rocof": table.max_abs_rocof_meas.tolist()}
out["E12 threshold"] = {"value": P.M * R.rocof_limit}
print("RESULT" + json.dumps(out))
"""


def _run(core: str) -> dict:
    env = {**os.environ, "OPENBLAS_CORETYPE": core, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-2000:]
    line = next(x for x in done.stdout.splitlines() if x.startswith("RESULT"))
    return json.loads(line.removeprefix("RESULT"))


def _same(a, b, where: str) -> None:
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            _same(a[k], b[k], f"{where}/{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{where}[{i}]")
    elif isinstance(a, float) and isinstance(b, float):
        assert a == pytest.approx(b, rel=1e-6, abs=1e-12), (where, a, b)
    else:
        assert a == b, (where, a, b)        # verdicts: bools, relays, counts


@pytest.mark.exhaustive
@pytest.mark.skipif("avx2" not in FLAGS, reason="needs an x86 CPU with AVX2 (Haswell kernels)")
def test_the_linear_chapters_verdicts_and_numbers_do_not_depend_on_the_blas_kernel():
    first, second = (_run(core) for core in CORES)
    _same(first, second, "")


def test_compare_blas_lists_each_claim_and_table_cell_that_differs(tmp_path):
    """``reproduce --compare-blas``'s comparison: a flipped claim, a notebook
    that failed on one kernel only and a changed table row are each reported;
    identical runs give nothing."""
    from lfc.repro.runner import RunOutcome, differences
    a_dir, b_dir = tmp_path / "a", tmp_path / "b"
    a_dir.mkdir(), b_dir.mkdir()
    table = "| attack | severity |\n|---|---|\n| single | 1.032 |\n"
    (a_dir / "t.md").write_text(table)
    (b_dir / "t.md").write_text(table)
    a = [RunOutcome("fig4", True, 1.0, {"trips": True}), RunOutcome("fig5", True, 1.0, {})]
    assert differences(a, a, a_dir, b_dir) == []
    (b_dir / "t.md").write_text(table.replace("1.032", "1.22"))
    b = [RunOutcome("fig4", True, 1.0, {"trips": False}), RunOutcome("fig5", False, 1.0, {})]
    diff = differences(a, b, a_dir, b_dir, ("here", "Haswell"))
    assert diff == ["fig4: claim 'trips': True on here, False on Haswell",
                    "fig5: ran ok on here, not ok on Haswell",
                    "table t.md, line 3: '| single | 1.032 |' on here, '| single | 1.22 |' "
                    "on Haswell"]


def test_compare_blas_refuses_a_core_name_before_running_anything(capsys):
    from lfc.repro.cli import main
    assert main(["reproduce", "--compare-blas", "Has well"]) == 2
    assert "--compare-blas must be an OpenBLAS core type" in capsys.readouterr().err


def test_tables_print_the_stable_digits_and_never_round_up_to_a_setting():
    from lfc._format import number
    assert [number(v) for v in (3.042, 3.044, 0.3118, 0.3121)] == ["3.04", "3.04", "0.312",
                                                                   "0.312"]
    assert number(0.9996) == "0.9996" and number(-0.99996) == "-0.99996"
    assert number(1234.5) == "≈1230" and number(float("nan")) == "—"
    from lfc._format import count
    assert count(1551) == count(1547) == "≈1550" and count(999) == "999"


def test_a_trip_count_near_a_setting_is_reported_at_the_edge_with_its_margin():
    """The IEEE 39-bus row that flipped between two BLAS kernels (one area tripped
    or two) reads "at the edge" on both, naming the severities it rests on."""
    from lfc.experiments.redteam import trip_verdict
    assert trip_verdict({0: False, 1: True}, {0: 0.951, 1: 1.032}) == \
        "1, at the edge: area 0 at 0.951, area 1 at 1.03"
    assert trip_verdict({0: True, 1: True}, {0: 1.22, 1: 1.033}) == \
        "2, at the edge: area 1 at 1.03"
    assert trip_verdict({0: True, 1: False}, {0: 2.5, 1: 0.5}) == "1"
