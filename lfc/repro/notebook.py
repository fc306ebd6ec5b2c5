"""Small helpers that keep the notebooks' code cells short: results I/O, claims
(checked against :mod:`lfc.experiments.deviations`) and the README's generated tables."""

from __future__ import annotations

import ast
import json
import re
from collections.abc import Callable
from dataclasses import dataclass, replace
from numbers import Integral, Real
from pathlib import Path

import pandas as pd

from lfc._files import cache_folder, cached, content_key, note_written
from lfc._format import STABLE_DIGITS, count, number
from lfc._validate import check_number
from lfc.experiments.deviations import DEVIATIONS
from lfc.experiments.scenarios import ALL_PLANTS, PLANTS, check_plant, design_params
from lfc.model import LFCParams
from lfc.relays import RelaySettings
from lfc.result import Result

__all__ = ["PLANTS", "PLANT_LABELS", "cached_frame", "check_parameters", "check_plant",
           "figure_name", "markdown_table", "notebook_parameters", "readme_mismatches",
           "record_claims", "save_table", "setup", "sync_readme", "update_markdown_section",
           "write_metrics"]
PLANT_LABELS = {"linear": "linear model", "testbed": "ANDES testbed",
                "ieee39": "ANDES IEEE 39-bus"}


def _parameter_cells(namespace: dict) -> tuple[str, str]:
    """The sources of the notebook's parameters cell and of papermill's injected
    cell (``""`` when nothing was injected), from the kernel's input history
    (``In``): the injected cell starts with ``# Parameters`` and follows the
    parameters cell; without it the parameters cell is the first one run."""
    cells = [c for c in namespace.get("In", []) if c]
    injected = [i for i, c in enumerate(cells) if c.lstrip().startswith("# Parameters")]
    if injected and injected[-1] > 0:
        return cells[injected[-1] - 1], cells[injected[-1]]
    return (cells[0] if cells else ""), ""


def check_parameters(namespace: dict) -> None:
    """Fail fast on a name papermill injected that the notebook does not know, or
    of another kind than its default.

    Call as ``check_parameters(globals())`` in the first cell after the
    parameters: it reads the parameters cell and papermill's injected cell
    (:func:`_parameter_cells`) and raises ``ValueError`` listing the injected
    names the parameters cell does not assign (a typo would otherwise be
    ignored and the default used)."""
    defaults, injected = _parameter_cells(namespace)
    known = _assigned(defaults)
    unknown = sorted(_assigned(injected) - known)
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown} for this notebook; it takes "
                         f"{sorted(known)}")
    declared = _literals(defaults)
    for name in sorted(_assigned(injected)):
        if name in declared and name in namespace:
            check_type(name, namespace[name], declared[name], _papermill_hint(
                name, declared[name]))


def _papermill_hint(name: str, default: object) -> str:
    """How to give parameter ``name`` (default ``default``) on papermill's command
    line: ``-p`` types numbers and booleans but passes a list as a string."""
    if isinstance(default, (list, tuple)):
        example = ", ".join(repr(v) for v in list(default)[:2]) or "..."
        return (f"; with papermill give a list as YAML, -y \"{name}: [{example}]\" "
                f"(-p and -r pass it as a string)")
    return "; with papermill give it with -p (typed), not -r (raw string)"


def _literals(source: str) -> dict[str, object]:
    """The top-level assignments of ``source`` whose value is a literal."""
    values = {}
    for node in ast.parse(source).body:
        if isinstance(node, ast.Assign) and len(node.targets) == 1 \
                and isinstance(node.targets[0], ast.Name):
            try:
                values[node.targets[0].id] = ast.literal_eval(node.value)
            except ValueError:
                pass
    return values


def check_type(name: str, value: object, default: object, hint: str = "") -> None:
    """Raise :class:`~lfc._validate.ParameterTypeError` (a ``TypeError`` and a
    ``ValueError``) unless a notebook parameter's ``value`` has its default's
    kind: True or False for a bool (papermill's ``-r check_claims False`` gives
    the string "False", which is truthy), an integer for an int, a finite
    number for a float, a string for a string, a non-empty list of the first
    element's kind for a list; None as a default allows anything.  ``hint`` is
    added to the message."""
    from lfc._validate import ParameterTypeError, conforms, is_finite, kind
    if default is None:
        return
    if isinstance(default, (list, tuple)):
        if not (isinstance(value, (list, tuple)) and value):
            raise ParameterTypeError(f"parameter {name!r} must be a non-empty list, got "
                                     f"{value!r}{hint}")
        for v in value if default else ():
            check_type(name, v, default[0], hint)
        return
    expected = type(default)
    ok = conforms(value, expected) and (expected is not float or is_finite(value))
    words = "a finite number" if expected is float else kind(expected)
    if not ok:
        raise ParameterTypeError(f"parameter {name!r} must be {words} like its default "
                                 f"{default!r}, got {value!r:.60} ({type(value).__name__})"
                                 f"{hint}")
    if expected is int and abs(value) >= 2 ** 63:
        raise ValueError(f"parameter {name!r} = {value!r:.40}... is too large "
                         f"(|value| < 2**63)")


def notebook_parameters(namespace: dict) -> dict:
    """The notebook's parameters and their values in this run (defaults and
    injected ones alike), for ``metrics.json``: nothing copied by hand."""
    defaults, injected = _parameter_cells(namespace)
    names = _assigned(defaults) | _assigned(injected)
    return {n: namespace[n] for n in sorted(names) if n in namespace}


def _assigned(source: str) -> set[str]:
    """Names assigned at the top level of ``source``."""
    names = set()
    for node in ast.parse(source).body:
        if isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names |= {t.id for t in targets if isinstance(t, ast.Name)}
    return names


def setup(plant: str, supported: tuple[str, ...] = PLANTS, *, M: float | None = None,
          relay_category: str = "III", rocof_limit: float | None = None
          ) -> tuple[LFCParams, RelaySettings]:
    """The design model of ``plant`` and its relays: a notebook's physical knobs.

    Parameters
    ----------
    plant : str
        ``"linear"`` or ``"testbed"``; ``supported``: those the notebook runs on.
    M : float, optional
        Inertia ``2H`` (s) of the linear model, in (0, 100]; None keeps the design
        model's (4 s; on the testbed the fitted one, which cannot be changed).
    relay_category : str
        IEEE 1547-2018 DER category of the relays (:meth:`RelaySettings.ieee1547`):
        ``"III"`` is the paper's Table 1.
    rocof_limit : float, optional
        ROCOF setting (pu/s) in place of the category's.

    Raises ``ValueError`` if the notebook does not run on ``plant``, or a knob is
    out of its range.
    """
    check_plant(plant)
    if plant not in supported:
        raise ValueError(f"plant must be one of {supported} for this notebook, got {plant!r}")
    relays = check_knobs(plant, M, relay_category, rocof_limit)
    params = design_params(plant)
    if M is not None:
        params = replace(params, M=M)
    return params, relays


def check_knobs(plant: str, M: float | None = None, relay_category: str = "III",
                rocof_limit: float | None = None) -> RelaySettings:
    """:func:`setup`'s checks of the physical knobs (before anything is built or run:
    ``python -m lfc sweep`` calls it for every point); the relays they give.

    Raises ``ValueError`` (a wrong type: ``TypeError``) naming the knob."""
    if M is not None and plant != "linear":
        raise ValueError("M is the linear model's; on the testbed the design model's "
                         "inertia is fitted to ANDES (leave M = None)")
    if M is not None:
        check_number("M", M)                 # a bool or a string is refused, not coerced
        if not 0.0 < M <= 100.0:
            raise ValueError(f"M must lie in (0, 100] s, got {M!r}")
    relays = RelaySettings.ieee1547(relay_category)
    if rocof_limit is not None:
        relays = replace(relays, rocof_limit=rocof_limit)
    return relays


def figure_name(base: str, plant: str) -> str:
    """File name of a figure: ``base`` on the linear plant, ``base_<plant>`` on another."""
    check_plant(plant, ALL_PLANTS)
    return base if plant == "linear" else f"{base}_{plant}"


def show_fit(plant, directory: str | Path) -> str:
    """The fit of an ANDES grid case's design model, as a markdown table saved as
    ``<case>_fit.md`` in ``directory``; for a linear plant, its own design model, a
    sentence that says so (nothing saved)."""
    from lfc.run import runner_of
    if runner_of(plant).design is None:
        return "The plant is its own design model: nothing is fitted."
    from lfc.testbed import grid_fit_report
    table = grid_fit_report(plant).table()
    save_table(table, directory, f"{plant.name}_fit")
    return table


def write_metrics(results_dir: str | Path, runs: dict[str, Result],
                  parameters: dict, extra: dict[str, dict] | None = None) -> Path:
    """Write ``metrics.json``: each run name -> ``Result.metrics()`` plus
    ``parameters`` and that run's ``extra`` entries (e.g. ``oc_trip_t``)."""
    out = Path(results_dir)
    out.mkdir(parents=True, exist_ok=True)
    extra = extra or {}
    data = {name: {**r.metrics(), **extra.get(name, {}), "parameters": parameters}
            for name, r in runs.items()}
    path = out / "metrics.json"
    path.write_text(json.dumps(data, indent=2, sort_keys=False))
    return path


@dataclass(frozen=True)
class Verdict:
    """A chapter's claims as the page shows them (a markdown table, readable in
    the notebook's file too).

    Attributes
    ----------
    table : pandas.DataFrame
        ``claim``, ``reproduced`` (``"yes"``, ``"no (documented)"`` or ``"no"``)
        and ``why not`` (a documented deviation's explanation, with this run's
        numbers; empty otherwise).
    """

    table: pd.DataFrame

    def _repr_markdown_(self) -> str:
        return markdown_table(self.table)

    def __repr__(self) -> str:
        return self._repr_markdown_()


def record_claims(results_dir: str | Path, claims: dict[str, bool], check: bool,
                  plant: str = "linear", metrics: dict[str, dict] | None = None
                  ) -> Verdict:
    """Write ``claims.json`` (claim -> holds) and ``deviations.json`` (failed
    claims that match a documented :class:`Deviation`: claim -> why, with this
    run's numbers from ``metrics``); return the :class:`Verdict` for the page.

    With ``check``, raise ``AssertionError`` on a failed claim that is not a
    documented deviation or fails in another way than documented, and on a
    documented deviation that now holds (so ``docs/testbed.md`` is updated).
    Without it, the verdict's column reads "holds in this run (not checked)"
    instead of "reproduced".
    """
    out = Path(results_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "claims.json").write_text(json.dumps({k: bool(v) for k, v in claims.items()},
                                                indent=2))
    known = {d.claim: d for d in DEVIATIONS if d.plant == plant and d.claim in claims}
    if known and metrics is None:
        raise ValueError("metrics are needed to check this notebook's documented deviations")
    deviations = {c: d.explain(metrics) for c, d in known.items()
                  if not claims[c] and d.matches(metrics)}
    (out / "deviations.json").write_text(json.dumps(deviations, indent=2))
    failed = [k for k, ok in claims.items() if not ok and k not in deviations]
    stale = [k for k in known if claims[k]]
    if check and (failed or stale):
        raise AssertionError("claim(s) not reproduced: " + "; ".join(failed) if failed else
                             "documented deviation(s) no longer observed, update DEVIATIONS "
                             "and docs/testbed.md: " + "; ".join(stale))
    verdict = ["yes" if ok else "no (documented)" if k in deviations else "no"
               for k, ok in claims.items()]
    # unchecked (a run at other parameters, or --quick): the claims are the paper's at
    # its parameters, so the column says what this run found, not "reproduced"
    column = "reproduced" if check else "holds in this run (not checked)"
    return Verdict(pd.DataFrame({"claim": list(claims), column: verdict,
                                 "why not": [deviations.get(k, "") for k in claims]}))


def markdown_table(table, digits: int = STABLE_DIGITS) -> str:
    """A pandas DataFrame as a GitHub markdown table; floats to ``digits``
    significant digits and integers of 1000 or more to as many (:mod:`lfc._format`:
    the digits that are stable across BLAS kernels; a value below 1 never
    printed as 1)."""
    def cell(v) -> str:
        if isinstance(v, bool) or not isinstance(v, Real):      # numpy's bool is no Real
            return str(v).replace("|", "\\|")
        return count(v, digits) if isinstance(v, Integral) else number(float(v), digits)
    lines = ["| " + " | ".join(map(str, table.columns)) + " |",
             "|" + "---|" * len(table.columns)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |"
              for row in table.itertuples(index=False)]
    return "\n".join(lines)


def save_table(text: str, directory: str | Path, name: str) -> Path:
    """Write a generated markdown table to ``directory/name.md`` (beside the
    figures; the README or an appendix in ``docs/`` shows it between
    ``<!-- name:start -->`` markers)."""
    path = Path(directory) / f"{name}.md"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text.strip() + "\n")
    note_written(path)
    return path


RUN_SECTIONS = ("timing", "timing_rerun", "times")   # sections runs' timings fill


def documents(root: str | Path) -> list[Path]:
    """The markdown files with generated sections: the README and the appendices
    (``docs/*.md``)."""
    return [Path(root) / "README.md", *sorted((Path(root) / "docs").glob("*.md"))]

_SECTION = re.compile(r"<!-- ([\w-]+):start -->\n(.*?)<!-- \1:end -->", re.S)


def readme_mismatches(readme: str | Path, tables_dir: str | Path) -> list[str]:
    """Names of the README's generated sections that differ from (or lack) their
    table ``tables_dir/<name>.md``."""
    doc = Path(readme).read_text()
    bad = []
    for name, body in _SECTION.findall(doc):
        if name in RUN_SECTIONS:     # a measured run's timing, not a generated table
            continue
        table = Path(tables_dir) / f"{name}.md"
        if not table.exists() or table.read_text().strip() != body.strip():
            bad.append(name)
    return bad


def sync_readme(readme: str | Path, tables_dir: str | Path) -> list[str]:
    """Copy each generated table into its section of the markdown file ``readme`` (the
    README or an appendix); return the names changed.

    Raises ``ValueError`` if a section has no table file."""
    changed = readme_mismatches(readme, tables_dir)
    for name in changed:
        table = Path(tables_dir) / f"{name}.md"
        if not table.exists():
            raise ValueError(f"{Path(readme).name} section {name!r} has no table {table}")
        update_markdown_section(readme, name, table.read_text())
    return changed


def update_markdown_section(path: str | Path, name: str, text: str) -> None:
    """Replace what lies between ``<!-- name:start -->`` and ``<!-- name:end -->``
    in the markdown file ``path`` with ``text`` (how notebooks regenerate the
    README's tables).  Raises ``ValueError`` if the markers are missing."""
    path = Path(path)
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    doc = path.read_text()
    if start not in doc or end not in doc:
        raise ValueError(f"{path} has no {start} ... {end} section")
    head, rest = doc.split(start, 1)
    path.write_text(f"{head}{start}\n{text.strip()}\n{end}{rest.split(end, 1)[1]}")


def cached_frame(name: str, inputs: dict, compute: Callable[[], pd.DataFrame]) -> pd.DataFrame:
    """``compute()``, kept on disk: a later call with the same ``inputs`` reads it
    back instead of computing it again.

    For a scan that a sweep over other parameters would otherwise redo on every
    run (chapter 02's edge scan).  The frame is stored as JSON with its SHA-256
    (:func:`lfc._files.cached`) in ``$LFC_CACHE_DIR`` (default
    ``~/.cache/lfc-scc``), in a file named by ``name`` and a key of ``inputs``
    (JSON-encodable, or their ``str``) and of the package's sources, the pinned
    environment, Python and the BLAS kernel (:func:`lfc._files.content_key`): a
    stale file is never found, a damaged one is recomputed with a warning.  The
    frame read back equals the one computed: values, column names, dtypes and
    index."""
    def encode(frame: pd.DataFrame) -> dict:
        return {"columns": list(frame.columns), "index": frame.index.tolist(),
                "dtypes": [str(t) for t in frame.dtypes],
                "data": frame.astype(object).where(frame.notna(), None).to_numpy().tolist()}

    def decode(data: dict) -> pd.DataFrame:
        frame = pd.DataFrame(data["data"], columns=data["columns"], index=data["index"])
        return frame.astype(dict(zip(frame.columns, data["dtypes"])))

    path = cache_folder() / f"{name}-{content_key(name, inputs)[:16]}.json"
    return cached(path, compute, encode, decode)
