"""docs/architecture.md: its examples run, and the example filter passes the
conformance suite every registered filter passes (tests/test_conformance.py); every
command of ``bench/`` the documentation names exists, with its flags."""

import ast
import inspect
import re

import pytest
import test_conformance as conformance

from lfc.filters import REGISTRY
from lfc.repro import runner

DOC = runner.ROOT / "docs" / "architecture.md"


def blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S)


def test_the_readme_links_the_architecture_page():
    assert "docs/architecture.md" in (runner.ROOT / "README.md").read_text()


def test_the_new_plant_example_runs():
    pytest.importorskip("andes")
    plant_block = next(b for b in blocks() if "class RotorMeteredGrid" in b)
    exec(compile(plant_block, str(DOC), "exec"), {})


def test_the_new_filter_example_runs_and_passes_the_conformance_suite():
    filter_block = next(b for b in blocks() if "class ClipFilter" in b)
    try:
        exec(compile(filter_block, str(DOC), "exec"), {})
        assert "clip" in REGISTRY
        checks = [f for name, f in vars(conformance).items() if name.startswith("test_")
                  and "method" in inspect.signature(f).parameters]
        assert len(checks) >= 7
        for check in checks:
            check(method="clip")
    finally:
        REGISTRY.pop("clip", None)
        conformance._BUILT.pop("clip", None)


def test_every_bench_command_the_documentation_names_exists_with_its_flags():
    """A ``python bench/<script>.py --flag`` in the README, ``docs/``,
    ``bench/README.md`` or a notebook names a script of ``bench/``, and each flag
    is one the script's docstring lists on its ``Run:`` line: a table the
    documentation quotes can be printed again by the command it names."""
    root = runner.ROOT
    texts = [root / "README.md", root / "bench" / "README.md",
             *sorted((root / "docs").glob("*.md")), *sorted((root / "notebooks").glob("*.ipynb"))]
    named = {m for path in texts
             for m in re.findall(r"python bench/(\w+\.py)((?: --[\w-]+)*)", path.read_text())}
    assert len({script for script, _ in named}) >= 10
    for script, flags in sorted(named):
        source = root / "bench" / script
        assert source.exists(), f"{script}: no such script in bench/"
        doc = ast.get_docstring(ast.parse(source.read_text())) or ""
        run = doc[doc.find("Run:"):].split("\n\n")[0] if "Run:" in doc else ""
        for flag in flags.split():
            assert f"[{flag}]" in run, f"{script} {flag}: not on its docstring's Run: line"
