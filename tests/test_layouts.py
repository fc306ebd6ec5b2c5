"""Issue "One": every filter's packed data has a named layout, its offsets computed
(``lfc.filters.base.Layout``), none written by hand — and what a filter packs is what its
layout names."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import lfc
from lfc.filters import base, certified, contract, coupled_kernel, paper
from lfc.filters.base import Layout
from lfc.linear_grid import area_filter

P, RELAYS = lfc.LFCParams(), lfc.RelaySettings()
FILTERS = Path(lfc.__file__).parent / "filters"


def test_a_layout_computes_its_offsets_and_names_what_an_array_holds():
    layout = Layout("alpha", ("P", 10), "u_max")
    assert layout.offsets() == (0, 1, 11) and layout.size == 12
    data = np.arange(14.0)
    fields = layout.unpack(data, at=2)
    assert fields["alpha"] == 2.0 and fields["u_max"] == 13.0
    np.testing.assert_array_equal(fields["P"], np.arange(3.0, 13.0))
    assert repr(layout) == "Layout(alpha, ('P', 10), u_max)"
    with pytest.raises(ValueError, match="distinct names and sizes >= 1"):
        Layout("a", "a")
    with pytest.raises(ValueError, match="distinct names and sizes >= 1"):
        Layout(("a", 0))


def test_no_filter_module_writes_an_offset_by_hand():
    """No module of ``lfc/filters`` assigns names from ``range(...)`` or from a tuple
    of integer literals (the old ``P_, Q_, ... = 7, 17, ...``): offsets come from a
    ``Layout`` (flag bits, powers of two, are not offsets)."""
    found = []
    for path in sorted(FILTERS.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if not (isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Tuple)):
                continue
            value = node.value
            by_range = (isinstance(value, ast.Call) and isinstance(value.func, ast.Name)
                        and value.func.id == "range")
            literals = (isinstance(value, ast.Tuple) and len(value.elts) > 1
                        and all(isinstance(e, ast.Constant) and type(e.value) is int
                                for e in value.elts)
                        and not all(e.value > 0 and e.value & (e.value - 1) == 0
                                    for e in value.elts))
            if by_range or literals:
                found.append(f"{path.name}:{node.lineno}")
    assert found == []


def test_the_paper_filters_data_is_what_its_layout_names():
    f = lfc.SafetyFilter(P, RELAYS, alpha=3.0, Ts=0.25, outside_rule="push", u_min=-2.0)
    fields = paper.LAYOUT.unpack(f.data)
    assert len(f.data) == paper.LAYOUT.size
    assert (fields["alpha"], fields["u_min"], fields["u_max"], fields["push"]) == (
        3.0, -2.0, np.inf, 1.0)
    np.testing.assert_array_equal(fields["limits2"],
                                  np.array([RELAYS.F, RELAYS.rocof_limit]) ** 2)


def test_the_certified_filters_data_is_what_its_layouts_name():
    f = lfc.SafetyFilter(P, RELAYS, method="certified", uncertainty=0.2, u_max=3.0)
    head = certified.LAYOUT.unpack(f.data)
    n_plants, n = int(head["n_plants"]), int(head["n_rows"])
    assert n_plants == len(f.backend.cert.blocks) > 1               # the box's corners too
    assert (head["u_max"], head["f_lim"], head["r_lim"]) == (3.0, RELAYS.F,
                                                              RELAYS.rocof_limit)
    stride = certified.BLOCK.size + certified.COLUMNS.size * n + certified.ELLIPSOID.size
    assert len(f.data) == certified.LAYOUT.size + n_plants * stride
    block = certified.BLOCK.unpack(f.data, at=certified.LAYOUT.size)
    assert block["rho"] == f.backend.cert.blocks[0].rho["new"]
    ellipsoid = certified.ELLIPSOID.unpack(f.data, at=certified.LAYOUT.size + stride
                                           - certified.ELLIPSOID.size)
    np.testing.assert_array_equal(ellipsoid["P"], f.backend.cert.blocks[0].P.ravel())


def test_the_grid_filters_data_is_what_their_layouts_name():
    two = lfc.MultiAreaParams.two_area()
    box = area_filter(two, 0, "contract", RELAYS, 0.01)
    fields = contract.LAYOUT.unpack(box.data)
    assert (fields["f_lim"], fields["r_lim"]) == (RELAYS.F, RELAYS.rocof_limit)
    assert fields["half"] > 0 and fields["step"] > 0
    grid = area_filter(two, 0, "coupled", RELAYS, 0.01)
    head = coupled_kernel.LAYOUT.unpack(grid.data)
    assert (head["n_a"], head["f_lim"], head["r_lim"]) == (2, RELAYS.F, RELAYS.rocof_limit)
    assert head["n_s"] == two.n_states


def test_every_compiled_method_declares_its_layout():
    for module in (paper, certified, contract, coupled_kernel):
        assert isinstance(module.LAYOUT, base.Layout), module.__name__


def test_method_ids_are_given_by_registration_and_dispatch_to_their_modules_decision():
    """The compiled dispatchers' codes are given by ``register`` / ``register_grid``
    (``lfc.filters.dispatch.assign``), distinct; no module writes a code as a number; the
    dispatcher sends each code to its module's compiled decision, and a grid-wide code
    only to ``decide_grid``."""
    from lfc.filters import GRID_REGISTRY, REGISTRY, dispatch
    compiled = {n: b for n, b in REGISTRY.items() if b.jit} | GRID_REGISTRY
    codes = [b.method_id for b in compiled.values()]
    assert sorted(codes + [dispatch.PYTHON]) == list(range(len(compiled) + 1))
    assert dispatch.grid_wide_methods() == tuple(b.method_id for b in GRID_REGISTRY.values())
    for path in sorted(Path(lfc.__file__).parent.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Assign) and isinstance(node.value, (ast.Constant, ast.Dict)):
                names = {t.id for t in node.targets if isinstance(t, ast.Name)}
                assert not {"method_id", "METHOD_ID", "METHOD_IDS"} & names, \
                    f"{path}:{node.lineno}"
    x, mem = np.array([0.0, 0.0, 0.0, 0.01, 0.02]), np.zeros(base.MEMORY)
    for name, backend in REGISTRY.items():
        f = lfc.SafetyFilter(P, RELAYS, method=name)
        module = __import__(backend.__module__, fromlist=["decide"])
        mem[:] = 0.0
        got = dispatch.decide(f.method_id, f.data, x, 0.5, 0.0, mem)
        mem[:] = 0.0
        assert got == module.decide(f.data, x, 0.5, 0.0, mem), name


def test_a_compiled_method_is_registered_with_the_package_or_refused():
    """Codes are closed once ``lfc.filters`` is imported (the compiled dispatchers are
    written from them): a compiled method registered later, or one outside the package
    (its dispatch would not be cached with it), is refused saying what to do."""
    from lfc.filters import dispatch, register
    from lfc.filters.paper import PaperFilter

    class Late(PaperFilter):
        name = "late"
    Late.__module__ = "lfc.filters.paper"
    with pytest.raises(RuntimeError, match="given when lfc.filters is imported"):
        register(Late)
    Late.__module__ = "elsewhere"
    with pytest.raises(ValueError, match="must be a module of lfc, got Late of elsewhere"):
        dispatch.assign(Late)
    assert "late" not in lfc.filters.available()


def test_the_order_of_registration_is_part_of_the_compiled_codes_cache_stamp():
    """The codes compiled into the dispatcher follow the order of registration, so the
    one file that registers (``lfc.filters``; no other module of the package calls
    ``register``, ``register_grid`` or ``assign``) is in the cache stamp of the compiled
    code (``lfc._jit``: the files that name it): a reordering recompiles instead of
    running a cached dispatch to the wrong method."""
    root = Path(lfc.__file__).parent
    registering = {root / "filters" / "__init__.py"}
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.ImportFrom) and node.module in {"lfc.filters",
                                                                     "lfc.filters.dispatch"}
                    and {"register", "register_grid", "assign"} & {a.name for a in node.names}):
                registering.add(path)
    assert registering == {root / "filters" / "__init__.py"}
    assert "lfc._jit" in (root / "filters" / "__init__.py").read_text()


def test_build_is_the_one_way_to_build_a_filter_by_name():
    """``lfc.filters.build(kind, plant, area)``: a registered method with the options its
    backend takes in a grid (no if/else over the methods), ``"coupled"`` the grid's
    certificate, once per grid; a grid's ``filters={a: kind}`` builds through it."""
    from lfc.filters import build
    from lfc.filters.bounds import tie_step_bound
    three = lfc.MultiAreaParams.three_area()
    f = build("certified", three, 2, RELAYS)
    assert f.params == three.areas[2]
    assert f.options.load_bound == tie_step_bound(three, 2, RELAYS, 0.01)
    assert build("certified", P).options.load_bound == 0.0          # one area: its defaults
    assert build("paper", three, 1).options.alpha == 20.0
    box = build("contract", three, 0, RELAYS)
    assert box.options.half_width is not None
    two = lfc.MultiAreaParams.two_area()
    assert build("coupled", two, 0) is build("coupled", two, 1)      # one grid, one object
    with pytest.raises(ValueError, match=r"filters\[0\] must be one of \('paper', "
                                         r"'certified', 'contract', 'coupled'\)"):
        build("kalman", two)
    with pytest.raises(ValueError, match="'coupled' is a grid's certificate"):
        build("coupled", P)
    with pytest.raises(TypeError, match="plant must be an LFCParams or a MultiAreaParams"):
        build("paper", "two_area")


# -- the package's shape (issue "One"): what a reader can hold in mind -------------------
PACKAGE = Path(lfc.__file__).parent


def _sources():
    for path in sorted(PACKAGE.rglob("*.py")):
        yield path.relative_to(PACKAGE.parent).as_posix(), path.read_text()


def test_no_module_is_longer_than_900_lines():
    long = {name: n for name, text in _sources() if (n := len(text.splitlines())) > 900}
    assert long == {}


def test_no_function_takes_more_than_12_positional_parameters():
    """The kernel's arrays travel as named tuples (``lfc.engine.Plants``, ``Rows``, ...,
    and the generator side's ``Channels``, ``Estimate``, ``Controller``, ``Memory``), not
    as positions."""
    wide = set()
    for name, text in _sources():
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                params = [a.arg for a in node.args.posonlyargs + node.args.args]
                if len([p for p in params if p not in ("self", "cls")]) > 12:
                    wide.add(f"{name}:{node.name}")
    assert wide == set()


def test_no_private_name_is_imported_from_another_module():
    """A name one module keeps to itself (``_name``) is not another module's to use (a
    module private to the package, ``lfc._jit``, is the package's)."""
    found = set()
    for name, text in _sources():
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("lfc"):
                found |= {(name, alias.name) for alias in node.names
                          if alias.name.startswith("_") and not alias.name.startswith("__")
                          and not (PACKAGE / f"{alias.name}.py").exists()}
    assert found == set()


def test_the_engine_imports_no_particular_filter():
    """The compiled loop and the generator side reach every filter, an area's or a
    grid-wide one, through ``lfc.filters.dispatch`` (``decide``, ``decide_grid``,
    ``grid_wide``): a new filter is its module and its registration, not an edit of
    the engine."""
    allowed = {"lfc.filters", "lfc.filters.base", "lfc.filters.dispatch"}
    for name in ("lfc/engine.py", "lfc/lanes.py", "lfc/generator.py"):
        tree = ast.parse((PACKAGE.parent / name).read_text())
        used = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
                and (node.module or "").startswith("lfc.filters")}
        assert used <= allowed, (name, used - allowed)


def test_the_multi_area_chapter_runs_every_plant_without_a_branch_on_it():
    """Notebook 09 builds its plant by name, takes the plant's design model from
    :func:`lfc.design_of` and runs every scenario through the two entry points: no
    ``if`` (statement or expression) on ``plant``, and no private name imported."""
    import nbformat
    notebook = nbformat.read(PACKAGE.parent / "notebooks" / "09_multi_area.ipynb", 4)
    code = "\n".join(c.source for c in notebook.cells if c.cell_type == "code")
    tree = ast.parse("\n".join(line for line in code.splitlines()
                               if not line.lstrip().startswith(("%", "!"))))
    branches = [ast.unparse(node.test) for node in ast.walk(tree)
                if isinstance(node, (ast.If, ast.IfExp))
                and "plant" in {n.id for n in ast.walk(node.test) if isinstance(n, ast.Name)}]
    assert branches == []
    private = [alias.name for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
               for alias in node.names if alias.name.startswith("_")]
    assert private == []
