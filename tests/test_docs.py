"""docs/architecture.md: its examples run, and the example filter passes the
conformance suite every registered filter passes (tests/test_conformance.py)."""

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
