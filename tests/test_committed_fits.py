"""The fits committed with the package (``lfc/testbed/fitted/``, :mod:`lfc.testbed.fit`):
what the fit computes on this machine, read on every BLAS kernel, refused when damaged,
and part of the code digest that keys every stored result."""

import json
import shutil
import warnings

import pytest

pytest.importorskip("andes")

from lfc import _files  # noqa: E402
from lfc.testbed import fit as fitting  # noqa: E402
from lfc.testbed.fit import committed_fits, fit_numbers  # noqa: E402
from lfc.testbed.microgrid import MicrogridCase  # noqa: E402

COMMITTED = {fitting.committed_path(c.case, c.kind).stem: c for c in committed_fits()}

#: relative: the fit's own spread, measured on one machine fitting the same ANDES
#: records under two OpenBLAS kernels, reaches 1.9e-3 (the IEEE 39-bus system's
#: area-1 damping, weakly identified); a stale fit moves far more.
SPREAD = 1e-2


def _read(c):
    return fitting.read_committed(c.case, c.kind)


#: s, each fit computed on ANDES (measured on an AMD EPYC, an empty store)
FIT_SECONDS = {"grid-fit-ieee39": 182, "grid-fit-kundur": 71, "testbed-fit-microgrid": 15}


@pytest.mark.parametrize("name", sorted(COMMITTED))
def test_the_committed_fit_was_made_from_the_code_as_it_is(name):
    """Each committed fit records a digest of what it was computed from besides its
    case (:func:`lfc.testbed.fit.fit_inputs`: the plant side, ANDES and the packages
    under it, the fitting code, the design models and the generator side of the
    experiments): equal to today's, or the file may be stale.  ``python -m lfc fit``
    then fits again and compares, ``--write`` replaces it (the exhaustive tier fits
    each again: the next test)."""
    c = COMMITTED[name]
    assert fitting.committed_inputs(c.case, c.kind) == fitting.fit_inputs(), (
        f"{name}: the committed fit was made from other code or packages; run python -m lfc "
        f"fit (compare) and python -m lfc fit --write (replace)")


def test_the_inputs_digest_covers_the_fitting_code_and_the_plant(tmp_path):
    """An edit of any of ``FIT_FILES``, of a function of ``FIT_FUNCTIONS`` or of the
    plant side changes :func:`lfc.testbed.fit.fit_inputs`; one of a filter does not."""
    from lfc.testbed import stored_runs
    package = tmp_path / "lfc"
    shutil.copytree(stored_runs._PACKAGE, package,
                    ignore=shutil.ignore_patterns("__pycache__", "*.run"))
    before = fitting.fit_inputs(package)
    assert before == fitting.fit_inputs()
    for name in (*fitting.FIT_FILES, "testbed/loop.py"):
        path = package / name
        text = path.read_text()
        path.write_text(text + "\nEDITED = 1\n")
        assert fitting.fit_inputs(package) != before, name
        path.write_text(text)
    engine = package / "engine.py"
    text = engine.read_text()
    engine.write_text(text.replace("gstate[0] += increment", "gstate[0] -= increment", 1))
    assert fitting.fit_inputs(package) != before
    engine.write_text(text)
    certified = package / "filters" / "certified.py"
    certified.write_text(certified.read_text() + "\nEDITED = 1\n")
    assert fitting.fit_inputs(package) == before


@pytest.mark.exhaustive
@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.long(FIT_SECONDS[n]))
                                  for n in sorted(COMMITTED)])
def test_the_committed_fit_is_what_the_fit_computes_here(name):
    """Fitted again on ANDES, every fitted parameter and error lies within
    ``SPREAD`` of the committed one, and a grid's validated command range and the
    verdicts of its validation ladder are the same: the committed file is not
    stale (``python -m lfc fit --write`` writes it again when the fit changes)."""
    c = COMMITTED[name]
    committed = _read(c)
    assert committed is not None, f"{name}: no committed fit for the case as it is now"
    computed = c.kind.compute(c.case)
    old, new = fit_numbers(committed), fit_numbers(computed)
    assert set(old) == set(new)
    for key in old:
        assert new[key] == pytest.approx(old[key], rel=SPREAD, abs=1e-6), key
    if hasattr(committed, "validation"):
        assert computed.command_range == committed.command_range
        assert [(s, g, t) for s, g, _, t, _ in computed.validation] == \
            [(s, g, t) for s, g, _, t, _ in committed.validation]


def test_every_blas_kernel_reads_the_same_committed_fit_and_computes_nothing(monkeypatch):
    """The point of committing the fits: with ``OPENBLAS_CORETYPE`` naming another
    kernel (which keys the cache of computed fits, since each kernel's own fit
    differs: module docstring of :mod:`lfc.testbed.fit`) the design models are the
    committed ones, bit for bit, and no fit is computed.  That the runs on them then
    agree across kernels was measured in subprocesses (``docs/reproducing.md``)."""
    def refuse(case):
        raise AssertionError("a committed fit was computed again")

    for c in committed_fits():
        values = []
        for kernel in ("", "Sandybridge"):
            monkeypatch.setenv("OPENBLAS_CORETYPE", kernel)
            values.append(fitting.cached_fit(c.case, c.kind._replace(compute=refuse)))
        assert values[0] == values[1] and values[0] is not None


def test_a_damaged_committed_fit_warns_and_another_case_is_fitted(monkeypatch, tmp_path):
    c = COMMITTED["grid-fit-kundur"]
    source, real = fitting.committed_path(c.case, c.kind), _read(c)
    monkeypatch.setattr(fitting, "FITTED_DIR", tmp_path)
    path = tmp_path / source.name
    shutil.copy(source, path)
    assert real is not None and _read(c) == real                             # a sane copy
    stored = json.loads(path.read_text())
    stored["fit"]["T"] *= 1.01                                               # a changed value
    path.write_text(json.dumps(stored))
    with pytest.warns(RuntimeWarning, match="damaged committed fit .*grid-fit-kundur.*checksum"):
        assert _read(c) is None
    path.write_text("{")                                                     # half a file
    with pytest.warns(RuntimeWarning, match="damaged committed fit"):
        assert _read(c) is None
    # another case (or another ANDES version) has no committed fit: fitted, no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert fitting.read_committed(MicrogridCase(droop=0.04), fitting.MICROGRID_FIT) is None


def test_the_committed_fits_are_part_of_the_code_digest():
    """Every stored result (notebook runs, ANDES runs, fits) is keyed by the code
    digest: a changed committed fit changes the design models, so it is in it."""
    files = sorted(fitting.FITTED_DIR.glob("*.json"))
    assert {f.stem for f in files} == set(COMMITTED)
    for packages in (("testbed",), ("*",)):
        assert set(files) <= set(_files.digested_files(*packages))


def test_python_m_lfc_fit_compares_and_write_replaces(monkeypatch, tmp_path, capsys):
    """``python -m lfc fit`` prints each committed number beside the one fitted
    here with their relative difference and writes nothing; ``--write`` replaces
    the committed file, which is then read back (the fit stubbed: a real one
    takes minutes on ANDES)."""
    import dataclasses

    from lfc.repro import cli

    c = COMMITTED["testbed-fit-microgrid"]
    committed = _read(c)
    moved = dataclasses.replace(committed, params=dataclasses.replace(
        committed.params, M=committed.params.M * 1.001))
    shutil.copy(fitting.committed_path(c.case, c.kind), tmp_path)
    monkeypatch.setattr(fitting, "FITTED_DIR", tmp_path)
    monkeypatch.setattr(fitting, "committed_fits",
                        lambda: (c._replace(kind=c.kind._replace(compute=lambda case: moved)),))
    assert cli.main(["fit"]) == 0
    row = next(line for line in capsys.readouterr().out.splitlines()
               if line.split()[:1] == ["M"])
    assert float(row.split()[-1]) == pytest.approx(1e-3, rel=1e-6)
    assert _read(c) == committed                                  # nothing written
    assert cli.main(["fit", "--write"]) == 0
    assert "written" in capsys.readouterr().out
    assert _read(c) == moved


def test_python_m_lfc_fit_restamps_only_a_fit_that_computes_what_it_computed(
        monkeypatch, tmp_path, capsys):
    """``--save FILE`` writes the fits computed here; ``--restamp FILE`` after a change
    of the fitting code stamps the committed fits with today's inputs, their numbers
    untouched, when every fit computed again equals FILE's bit for bit — a fit that
    moved by one part in 10^16 is not stamped (exit 1, the file as it was): a refit."""
    import dataclasses
    import math

    from lfc.repro import cli

    c = COMMITTED["testbed-fit-microgrid"]
    committed = _read(c)
    source = fitting.committed_path(c.case, c.kind)
    shutil.copy(source, tmp_path)
    monkeypatch.setattr(fitting, "FITTED_DIR", tmp_path)
    path = tmp_path / source.name

    def fitting_to(value):
        monkeypatch.setattr(fitting, "committed_fits", lambda: (
            c._replace(kind=c.kind._replace(compute=lambda case: value)),))

    fitting_to(committed)
    reference = tmp_path / "before.json"
    assert cli.main(["fit", "--save", str(reference)]) == 0
    stored = json.loads(path.read_text())
    stored["inputs"] = "an older code's"
    path.write_text(json.dumps(stored, indent=1, sort_keys=True) + "\n")
    moved = dataclasses.replace(committed, params=dataclasses.replace(
        committed.params, M=math.nextafter(committed.params.M, math.inf)))
    fitting_to(moved)
    assert cli.main(["fit", "--restamp", str(reference)]) == 1
    assert "not stamped" in capsys.readouterr().out
    assert json.loads(path.read_text())["inputs"] == "an older code's"
    fitting_to(committed)
    assert cli.main(["fit", "--restamp", str(reference)]) == 0
    after = json.loads(path.read_text())
    assert after["inputs"] == fitting.fit_inputs()
    assert {k: v for k, v in after.items() if k != "inputs"} == \
        {k: v for k, v in stored.items() if k != "inputs"}
    assert _read(c) == committed
