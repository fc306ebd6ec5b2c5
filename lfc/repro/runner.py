"""Execute the notebooks with papermill: reproduce every figure, or sweep parameters.

Runs go to an executor: by default a thread pool (each papermill run drives its
own kernel process, so threads give real parallelism), ``jobs`` threads for
``reproduce`` and one per core for ``sweep``.  Any
``concurrent.futures.Executor`` can be passed, e.g. a Dask cluster's
``distributed.Client(address).get_executor()``.
"""

from __future__ import annotations

import ast
import hashlib
import itertools
import json
import os
import re
import shutil
import signal
import sys
import tempfile
import threading
import time
import warnings
from concurrent.futures import Executor, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd
from jupyter_client.manager import KernelManager
from tqdm.auto import tqdm

from lfc._validate import check_count
from lfc._files import WRITTEN_ENV, content_key, folder_lock, write_atomic
from lfc._pool import completed
from lfc.experiments.scenarios import ALL_PLANTS
from lfc.repro.manifest import CHAPTERS, ROOT
from lfc.repro.notebook import check_knobs, check_plant, check_type, figure_name, markdown_table
from lfc.warmup import compile_kernels

NOTEBOOKS_DIR = ROOT / "notebooks"
FIGURES = {c.name: c.notebook for c in CHAPTERS}          # name -> notebook
FIGURE_PLANTS = {c.name: c.plants for c in CHAPTERS}      # name -> plants it runs on
# Where no run has recorded its time yet: these first, in this order (the longest chapters
# of a full run and of --quick; their times: docs/reproducing.md's timing table)
LONGEST_FIRST = ("multiarea", "redteam", "wire", "coupled", "surface")
POSITIVE = {"duration", "Ts", "control_period", "alpha", "alphas", "dt"}


@dataclass
class RunOutcome:
    """What one notebook execution produced."""

    name: str
    ok: bool
    seconds: float
    claims: dict[str, bool]
    error: str = ""
    deviations: dict[str, str] = field(default_factory=dict)
    cached: bool = False            # nothing changed since its last run: not executed
    andes_seconds: float = 0.0      # ANDES' own CPU time in this run (s; 0 if cached)


_LIVE: set = set()                 # kernel managers whose kernel is running (stop_kernels)
_LIVE_LOCK = threading.Lock()


def stop_kernels(wait: float = 1.0) -> int:
    """Kill every kernel this process started that still runs, with its process
    group (the kernel's own worker processes); return how many.  Ctrl-C calls
    it.  A kernel being launched is waited for (up to ``wait`` s) until it has a
    process to kill: orphaned, it would live on until it noticed its parent gone."""
    with _LIVE_LOCK:
        live = list(_LIVE)
    deadline = time.monotonic() + wait
    for km in live:
        group = None
        while True:
            p = km.provisioner
            group = (getattr(p, "pgid", None) or getattr(p, "pid", None)) if p else None
            if group or time.monotonic() > deadline:
                break
            time.sleep(0.005)
        if group:
            try:
                os.killpg(group, signal.SIGKILL)
            except OSError:
                pass
        shutil.rmtree(km._socket_dir, ignore_errors=True)
    for pid in _kernel_children():      # launched, but not yet known to its manager
        group = os.getpgid(pid) if pid_exists(pid) else None
        try:
            if group and group != os.getpgrp():
                os.killpg(group, signal.SIGKILL)
            else:
                os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
    return len(live)


def pid_exists(pid: int) -> bool:
    """Whether a process ``pid`` exists."""
    try:
        os.kill(pid, 0)
    except OSError:
        return False
    return True


def _kernel_children() -> list[int]:
    """This process's child processes that are Jupyter kernels (Linux ``/proc``;
    elsewhere none): a kernel whose launch a Ctrl-C interrupted has a process
    before its manager knows it, and orphaned it would live on for seconds."""
    me, found = str(os.getpid()), []
    for proc in Path("/proc").glob("[0-9]*"):
        try:
            status = (proc / "status").read_text()
            parent = next(line.split()[1] for line in status.splitlines()
                          if line.startswith("PPid:"))
            if parent == me and b"ipykernel" in (proc / "cmdline").read_bytes():
                found.append(int(proc.name))
        except (OSError, StopIteration, IndexError):
            continue
    return found


#: The BLAS threads of every kernel :class:`IPCKernelManager` starts (``reproduce``,
#: ``sweep``, ``papermill --engine lfc``), unless the environment names them: one.
#: Runs go one per core, and OpenBLAS' default, a thread per core in each process,
#: oversubscribes the cores; its idle threads spin (``bench/records/test-suite.md``).
#: It also keeps a run's last bits independent of the machine's number of cores (a
#: threaded product sums in another order).
def _papermill():
    """papermill, imported where a notebook runs (its import takes seconds)."""
    import papermill
    return papermill


def __getattr__(name: str):
    """``runner.pm``: papermill, imported when first asked for."""
    if name == "pm":
        return _papermill()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


ONE_BLAS_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}


class IPCKernelManager(KernelManager):
    """A kernel that talks over local IPC sockets, not TCP: nothing leaves the
    machine, and the kernel has no reason to warn about unencrypted TCP.

    Each kernel's sockets live in a private temporary folder (jupyter_client's
    default, ``./kernel-ipc-N``, is shared: kernels started at once would pick
    the same sockets), removed when the kernel shuts down.
    """

    def __init__(self, **kwargs) -> None:
        self._socket_dir = tempfile.mkdtemp(prefix="lfc-kernel-")
        kwargs.setdefault("transport", "ipc")
        kwargs.setdefault("ip", os.path.join(self._socket_dir, "kernel"))
        super().__init__(**kwargs)

    async def _async_interrupt_kernel(self) -> None:
        """Interrupt a running cell, but not a kernel being shut down.

        jupyter_client sends SIGINT before every shutdown request; papermill
        shuts a kernel down only after its last cell, and a SIGINT that lands
        while the idle kernel handles a message makes it print "KeyboardInterrupt
        caught in kernel" (seen once in 13 notebooks).  The shutdown request, and
        the kill jupyter_client sends if it is not honoured, stop the kernel.
        """
        if not self.shutting_down:
            await super()._async_interrupt_kernel()

    #: added to the kernel's environment (execute's env), besides :data:`ONE_BLAS_THREAD`
    #: where the environment does not name a thread count
    extra_env: dict[str, str] = {}

    async def _async_launch_kernel(self, kernel_cmd: list[str], **kw) -> None:
        with _LIVE_LOCK:                 # before the launch: stop_kernels waits for it
            _LIVE.add(self)
        kw["env"] = {**ONE_BLAS_THREAD, **(kw.get("env") or os.environ), **self.extra_env}
        await super()._async_launch_kernel(kernel_cmd, **kw)

    async def _async_cleanup_resources(self, restart: bool = False) -> None:
        with _LIVE_LOCK:
            _LIVE.discard(self)
        await super()._async_cleanup_resources(restart=restart)
        if not restart:
            shutil.rmtree(self._socket_dir, ignore_errors=True)


def execute(notebook: Path, output: Path, parameters: dict,
            env: dict[str, str] | None = None) -> None:
    """Run ``notebook`` with papermill into ``output`` (the notebook's folder as
    cwd; figures inline, the kernel over IPC; ``env``: variables added to the
    kernel's environment)."""
    output.parent.mkdir(parents=True, exist_ok=True)
    manager = IPCKernelManager if not env else type(
        "RunKernelManager", (IPCKernelManager,), {"extra_env": dict(env)})
    import papermill as pm
    pm.execute_notebook(str(notebook), str(output), parameters=parameters,
                        cwd=str(notebook.parent), kernel_name="python3",
                        kernel_manager_class=manager, progress_bar=False,
                        log_output=False)


RESULT_FILES = ("claims.json", "deviations.json", "metrics.json")
CACHE_FILE = "cache.json"     # in a run's results folder: its key and the files it wrote


def run_key(notebook: Path, parameters: dict) -> str:
    """SHA-256 of what a notebook run's outputs depend on: the notebook, its
    parameters, and (:func:`lfc._files.content_key`) every source file of the
    package, the pinned environment, the Python version and the BLAS kernel asked
    for.  Its ANDES runs are among them: they depend on nothing else."""
    return content_key(notebook.read_bytes(), parameters)


def _hash(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _written(folder: Path, log: Path) -> dict[str, str]:
    """The files of ``folder`` a run listed in ``log`` (:func:`lfc._files.note_written`:
    concurrent runs share the folder, so its modification times do not say whose a
    file is) and their hashes."""
    try:
        names = sorted(set(log.read_text(encoding="utf-8").split()))
    except OSError:
        return {}
    return {name: _hash(folder / name) for name in names if (folder / name).is_file()}


def _from_cache(results: Path, key: str, figures: Path) -> bool:
    """Whether the last run into ``results`` had this ``key``, succeeded, and every
    file it wrote (figures, tables, results, the executed notebook) is still there
    unchanged: a damaged or stale file means a run."""
    try:
        record = json.loads((results / CACHE_FILE).read_text())
        return record["key"] == key and all(
            (folder / name).is_file() and _hash(folder / name) == digest
            for folder, files in ((figures, record["figures"]), (results, record["results"]))
            for name, digest in files.items())
    except (OSError, ValueError, KeyError, TypeError):
        return False


def last_seconds(results: Path) -> float:
    """The wall time (s) the last successful run into ``results`` took; 0 without one."""
    try:
        return float(json.loads((results / CACHE_FILE).read_text())["seconds"])
    except (OSError, ValueError, KeyError, TypeError):
        return 0.0


def submission_order(runs: list[tuple[str, str]], seconds: list[float]) -> list[int]:
    """The order in which to submit ``runs`` ((chapter, plant) pairs), so that the
    pool is never idle at the end: longest first by their last recorded wall times
    ``seconds`` (0: none), then the chapters of ``LONGEST_FIRST``, then the rest in
    the manifest's order."""
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    return sorted(range(len(runs)),
                  key=lambda i: (-seconds[i], rank.get(runs[i][0], len(rank))))


def _run_one(name: str, notebook: Path, results: Path, parameters: dict,
             cache: bool = True) -> RunOutcome:
    """Execute one notebook; its claims are read only from files this run wrote
    (under the results folder's lock: a concurrent run of the same notebook into
    the same folder waits for this one, then runs on its own).

    With ``cache``, a run whose :func:`run_key` equals the last successful run's
    into the same folder, and whose files are all still there unchanged, is not
    executed: its outcome is read back and marked ``cached``; and the notebook's
    grid runs on ANDES are read back where stored (:mod:`lfc.testbed.stored_runs`).
    Without it, every ANDES run runs."""
    t0 = time.perf_counter()
    figures = Path(parameters["figures_dir"])
    key = run_key(notebook, parameters)
    with folder_lock(results):
        if cache and _from_cache(results, key, figures):
            claims = read_json(results / "claims.json")
            deviations = read_json(results / "deviations.json")
            return RunOutcome(name, True, time.perf_counter() - t0, claims, "", deviations,
                              cached=True)
        last = last_seconds(results)
        tqdm.write(f"{name}: executing {notebook.name}"
                   + (f" (its last run took {last:.0f} s)" if last else ""), file=sys.stderr)
        (results / CACHE_FILE).unlink(missing_ok=True)
        for stale in RESULT_FILES:  # never report a claim an earlier run computed
            (results / stale).unlink(missing_ok=True)
        from lfc.testbed.loop import CLOCK_ENV   # here: lfc.testbed imports control, 1 s
        from lfc.testbed.stored_runs import SWITCH

        error = ""
        written = (results / WRITTEN_LOG).resolve()
        written.unlink(missing_ok=True)
        clock = results / ANDES_CLOCK     # every ANDES run of the notebook adds a line
        clock.unlink(missing_ok=True)
        try:
            execute(notebook, results / notebook.name, parameters,
                    env={CLOCK_ENV: str(clock.resolve()), WRITTEN_ENV: str(written),
                         **({} if cache else {SWITCH: "off"})})
            ok = True
        except _papermill().PapermillExecutionError as err:
            ok, error = False, f"{err.ename}: {err.evalue}"
        andes = andes_seconds(clock)
        claims = read_json(results / "claims.json")
        deviations = read_json(results / "deviations.json")
        held = (not parameters.get("check_claims", True)        # a quick run: not checked
                or all(v or c in deviations for c, v in claims.items()))
        if ok and held:
            files = [results / f for f in (*RESULT_FILES, notebook.name)]
            record = {"key": key, "figures": _written(figures, written) if figures.is_dir()
                      else {}, "results": {p.name: _hash(p) for p in files if p.is_file()},
                      "seconds": round(time.perf_counter() - t0, 1)}   # submission_order
            write_atomic(results / CACHE_FILE, json.dumps(record, indent=1))
    return RunOutcome(name, ok and held, time.perf_counter() - t0, claims, error, deviations,
                      andes_seconds=andes)


ANDES_CLOCK = "andes_seconds.txt"   # in a run's results folder (lfc.testbed.loop.CLOCK_ENV)
WRITTEN_LOG = "written.txt"         # in a run's results folder: what it wrote (WRITTEN_ENV)


def andes_seconds(clock: Path) -> float:
    """The CPU seconds ANDES took in one notebook run: the sum of the lines its
    ANDES runs appended to ``clock`` (0 if it ran none; a line cut short by a
    killed process is not a number and is left out)."""
    try:
        lines = clock.read_text(encoding="ascii", errors="replace").split()
    except FileNotFoundError:
        return 0.0
    return sum(float(x) for x in lines if re.fullmatch(r"\d+\.\d+", x))


def read_json(path: Path) -> dict:
    """A results file of a notebook run (``claims.json``, ...), ``{}`` if absent."""
    return json.loads(path.read_text()) if path.exists() else {}


def _progress(futures: dict, desc: str) -> list:
    """The futures' results as they finish, with a progress bar.  On Ctrl-C the
    queued runs are cancelled and the running kernels killed before the
    ``KeyboardInterrupt`` goes on: nothing keeps running."""
    done = []
    try:
        with tqdm(total=len(futures), desc=desc, unit="run") as bar:
            for fut in completed(futures):
                done.append(fut.result())
                bar.update(1)
    except KeyboardInterrupt:
        for fut in futures:
            fut.cancel()
        stop_kernels()
        raise
    return done


def reproduce(only: list[str] | None = None, plant: str = "all", jobs: int = 2,
              figures_dir: Path = ROOT / "figures", build_dir: Path = ROOT / "build",
              executor: Executor | None = None, *, cache: bool = True,
              quick: bool = False) -> list[RunOutcome]:
    """Execute every figure notebook (or ``only`` those) with its claims checked,
    on ``plant`` (``"linear"``, ``"testbed"``, ``"ieee39"`` or ``"all"``: every
    plant each notebook supports, ``FIGURE_PLANTS``), ``jobs`` at a time.

    Figures go to ``figures_dir``; executed notebooks, ``metrics.json`` and
    ``claims.json`` to ``build_dir/reproduce/<name>[_<plant>]/``.  With
    ``cache``, a notebook whose inputs and code are unchanged since its last
    successful run, and whose outputs are intact, is not run again
    (:func:`_run_one`).  ``quick`` runs every chapter on the linear model with
    its short parameters (the tests' runs), claims not checked, into
    ``build_dir/quick/`` (its figures in ``build_dir/quick/figures``, never
    ``figures/``): a look at every figure in about a minute.
    """
    names = only or list(FIGURES)
    unknown = [n for n in names if n not in FIGURES]
    if unknown:
        raise ValueError(f"unknown figure(s) {unknown}; choose from {list(FIGURES)}")
    if plant != "all":
        check_plant(plant, ALL_PLANTS)
    check_count("jobs", jobs)
    if quick:
        if plant not in ("all", "linear"):
            raise ValueError(f"quick runs the linear model only; got plant={plant!r}")
        plant, build_dir = "linear", Path(build_dir) / "quick"
        figures_dir = build_dir / "figures"
        Path(figures_dir).mkdir(parents=True, exist_ok=True)
    runs = [(n, p) for n in names for p in FIGURE_PLANTS[n] if plant in ("all", p)]
    if not runs:
        raise ValueError(f"none of {names} runs on plant {plant!r} (see FIGURE_PLANTS)")
    if any(p != "linear" for _, p in runs):
        _prepare_testbed()
    global COMPILED_IN_RUN
    if jobs > 1 and len(runs) > 1:     # kernels started on a cold cache would each compile
        COMPILED_IN_RUN = compile_kernels()
    pool = executor or ThreadPoolExecutor(max_workers=jobs)
    futures = {}
    labels = [figure_name(n, p) for n, p in runs]
    short = {c.name: c.short for c in CHAPTERS}
    folders = [Path(build_dir).resolve() / "reproduce" / label for label in labels]
    order = submission_order(runs, [last_seconds(f) for f in folders])
    for (name, run_plant), label, results in ((runs[i], labels[i], folders[i]) for i in order):
        params = {**(short[name] if quick else {}),
                  "figures_dir": str(Path(figures_dir).resolve()), "results_dir": str(results),
                  "plant": run_plant, "check_claims": not quick}
        futures[pool.submit(_run_one, label, NOTEBOOKS_DIR / FIGURES[name], results,
                            params, cache)] = label
    outcomes = _progress(futures, "reproduce")
    if executor is None:
        pool.shutdown()
    return sorted(outcomes, key=lambda o: labels.index(o.name))


def differences(a: list[RunOutcome], b: list[RunOutcome], tables_a: Path, tables_b: Path,
                labels: tuple[str, str] = ("A", "B")) -> list[str]:
    """What differs between two reproduce runs of the same notebooks: each claim
    whose verdict differs, each notebook that ran in one only, and each generated
    table (``*.md`` of ``tables_b``) whose text differs from ``tables_a``'s (the
    first differing row).  Empty when every verdict and every table cell agree."""
    out = []
    by_name = {o.name: o for o in a}
    for o in b:
        other = by_name.get(o.name)
        if other is None or bool(other.ok) != bool(o.ok):
            out.append(f"{o.name}: ran {'ok' if other and other.ok else 'not ok'} on "
                       f"{labels[0]}, {'ok' if o.ok else 'not ok'} on {labels[1]}")
            continue
        for claim in sorted(set(o.claims) | set(other.claims)):
            va, vb = other.claims.get(claim), o.claims.get(claim)
            if va != vb:
                out.append(f"{o.name}: claim {claim!r}: {va} on {labels[0]}, {vb} on {labels[1]}")
    for table in sorted(Path(tables_b).glob("*.md")):
        mine = Path(tables_a) / table.name
        rows_b = table.read_text().splitlines()
        rows_a = mine.read_text().splitlines() if mine.exists() else []
        if rows_a != rows_b:
            k = next((i for i, (x, y) in enumerate(zip(rows_a, rows_b)) if x != y),
                     min(len(rows_a), len(rows_b)))
            row_a = rows_a[k] if k < len(rows_a) else "(none)"
            row_b = rows_b[k] if k < len(rows_b) else "(none)"
            out.append(f"table {table.name}, line {k + 1}: {row_a!r} on {labels[0]}, "
                       f"{row_b!r} on {labels[1]}")
    return out


def rerun_with_blas(core: str, only: list[str] | None, plant: str, jobs: int,
                    build_dir: Path) -> tuple[list[RunOutcome], Path]:
    """The same notebooks again with the BLAS kernel ``OPENBLAS_CORETYPE=core``
    (e.g. ``"Haswell"``, ``"SkylakeX"``, ``"Zen"``; the kernels inherit it), into
    ``build_dir/blas-<core>/``: their outcomes and figures folder, for
    :func:`differences` against the first run."""
    if not (isinstance(core, str) and re.fullmatch(r"[A-Za-z0-9]+", core)):
        raise ValueError(f"core must be an OpenBLAS core type such as 'Haswell', got {core!r}")
    folder = Path(build_dir) / f"blas-{core}"
    before = os.environ.get("OPENBLAS_CORETYPE")
    os.environ["OPENBLAS_CORETYPE"] = core
    try:
        outcomes = reproduce(only, plant, jobs, folder / "figures", folder)
    finally:
        if before is None:
            os.environ.pop("OPENBLAS_CORETYPE", None)
        else:
            os.environ["OPENBLAS_CORETYPE"] = before
    return outcomes, folder / "figures"


def _prepare_testbed() -> None:
    """Generate ANDES' code once in this process, not in parallel kernels."""
    from lfc.testbed import prepare_andes
    prepare_andes()


def summary_table(outcomes: list[RunOutcome]) -> pd.DataFrame:
    """One row per claim: figure, claim, reproduced (yes/no); the notebooks'
    times are :func:`times_table`."""
    rows = []
    for o in outcomes:
        claims = o.claims or {o.error or "notebook did not run": False}
        for claim, ok in claims.items():
            verdict = "yes" if ok else ("no (documented)" if claim in o.deviations else "no")
            rows.append({"figure": o.name, "claim": claim, "reproduced": verdict})
    return pd.DataFrame(rows)


def times_table(outcomes: list[RunOutcome]) -> pd.DataFrame:
    """Wall time of each notebook run (s), longest first, and whether it ran or
    was read from the cache."""
    return (pd.DataFrame([{"notebook": o.name, "wall time (s)": round(o.seconds, 1),
                           "ANDES (s)": round(o.andes_seconds, 1),
                           "run": "cached (unchanged)" if o.cached else "executed"}
                          for o in outcomes])
            .sort_values("wall time (s)", ascending=False, ignore_index=True))


TIMING_FILES = {False: "timing.md", True: "timing_rerun.md"}   # in build/reproduce/
TIMES_FILE = "times.json"      # in build/: the last run of each command, for the README
COMPILED_IN_RUN = False        # whether this process's reproduce compiled the loops


def record_time(build_dir: Path, command: str, wall: float, cpu: float, note: str) -> None:
    """Keep how long ``command`` (``"python -m lfc reproduce"``, ``"python -m pytest"``,
    ...; ``", again"`` appended for a run that read back what an earlier one left: its
    notebooks, the compiled loops) took in its last complete run — wall and CPU seconds, the machine's cores, the
    commit, the date and ``note`` (what the run did) — in ``build/times.json``, which
    ``python -m lfc readme`` writes into the README (:func:`times_section`)."""
    import json
    import subprocess
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                            capture_output=True, text=True).stdout.strip() or "unknown"
    path = Path(build_dir) / TIMES_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    with folder_lock(path.parent / ".times"):
        times = read_json(path)
        times[command] = {"wall": round(wall, 1), "cpu": round(cpu, 1), "cores": os.cpu_count(),
                          "commit": commit, "date": time.strftime("%Y-%m-%d"), "note": note}
        write_atomic(path, json.dumps(times, indent=1, sort_keys=True) + "\n")


def _minutes(seconds: float) -> str:
    m, s = divmod(round(seconds), 60)
    return f"{m} min {s} s" if m else f"{s} s"


def times_section(times: dict) -> str:
    """The README's ``times`` section: each command's last complete run (:func:`record_time`)."""
    order = [f"{c}{again}" for c in ("python -m lfc reproduce",
                                     "python -m lfc reproduce --plant linear",
                                     "python -m lfc reproduce --quick", "python -m pytest",
                                     "python -m pytest --exhaustive") for again in ("", ", again")]
    lines = [f"- `{c.removesuffix(', again')}`{' again' if c.endswith(', again') else ''}: "
             f"**{_minutes(t['wall'])}** wall, {_minutes(t['cpu'])} of CPU on "
             f"{t['cores']} cores ({t['note']}; commit {t['commit']}, {t['date']})"
             for c in order + sorted(set(times) - set(order)) if (t := times.get(c))]
    return ("The last complete run of each command on this repository's machine, written by "
            "`python -m lfc readme` from `build/times.json`:\n\n" + "\n".join(lines) + "\n")


def timing_table(outcomes: list[RunOutcome], wall: float, cpu: float, jobs: int) -> str:
    """A full run's timing as markdown, for the README's ``timing`` (a run that
    executed every notebook) or ``timing_rerun`` section (one that read any back):
    the machine, the commit, wall and CPU time (s), ANDES' own computing and the
    floor it sets on ``jobs`` cores (s), each notebook's time."""
    import subprocess
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                            capture_output=True, text=True).stdout.strip() or "unknown"
    cached = sum(o.cached for o in outcomes)
    head = (f"`python -m lfc reproduce --jobs {jobs}` at commit {commit} on "
            f"{os.cpu_count()} cores, {time.strftime('%Y-%m-%d')}: **{wall:.0f} s wall**, "
            f"{cpu:.0f} s CPU; {len(outcomes) - cached} notebook runs executed, {cached} read "
            f"back unchanged.")
    andes = sum(o.andes_seconds for o in outcomes)
    if andes > 0:
        floor = andes / jobs
        head += (f" ANDES' own computing (loading, initializing and stepping its cases, "
                 f"not our per-step callback): {andes:.0f} s CPU, {andes / cpu:.0%} of the "
                 f"run's; on {jobs} cores it alone takes at least {floor:.0f} s: this run "
                 f"took {wall / floor:.2f}× that floor.")
    return head + "\n\n" + markdown_table(times_table(outcomes), digits=4) + "\n"


def deviation_notes(outcomes: list[RunOutcome]) -> list[str]:
    """One line per documented deviation of this run: figure, claim, why (with its numbers)."""
    return [f"{o.name}: {claim}: {why}" for o in outcomes for claim, why in o.deviations.items()]


# -- sweeps -------------------------------------------------------------------------
def parse_value(text: str) -> object:
    """A command-line value: a Python literal if it parses as one, else the string."""
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


def validate_parameters(notebook: Path, parameters: dict[str, list]) -> dict:
    """Fail before any run: unknown names, values listed twice, wrong types
    (an integer parameter takes integers; a list takes a non-empty list of its
    default's element type), non-finite numbers, non-positive times or gains.

    Returns the notebook's parameters as papermill inspects them."""
    import papermill as pm
    known = pm.inspect_notebook(str(notebook))
    for name, values in parameters.items():
        if name not in known:
            raise ValueError(f"unknown parameter {name!r} for {notebook.name}; "
                             f"known: {sorted(known)}")
        if not isinstance(values, (list, tuple)) or not values:
            raise ValueError(f"parameter {name!r} needs a non-empty list of values, "
                             f"got {values!r}")
        for value in values:
            for v in value if isinstance(value, list) else [value]:
                if isinstance(v, int) and not isinstance(v, bool) and abs(v) > 2 ** 1023:
                    raise ValueError(f"parameter {name!r} has an integer of about "
                                     f"{int(v.bit_length() * 0.30103)} digits, too large "
                                     f"for a float")
        seen = [value_key(v) for v in values]
        twice = sorted({repr(v) for v, k in zip(values, seen) if seen.count(k) > 1})
        if twice:
            raise ValueError(f"parameter {name!r} lists {', '.join(twice)} more than once "
                             f"(one point)")
        default = parse_value(known[name]["default"])
        for value in values:
            check_type(name, value, default)
            if name in POSITIVE:
                for v in value if isinstance(value, list) else [value]:
                    if not (isinstance(v, (int, float)) and v > 0):
                        raise ValueError(f"parameter {name!r} must be > 0, got {value!r}")
            if name == "plant":
                check_plant(value, ALL_PLANTS)
    knobs = [k for k in ("plant", "M", "relay_category", "rocof_limit") if k in known]
    if set(knobs) & set(parameters) - {"plant"}:   # every point's knobs, before any kernel
        values = [parameters.get(k, [parse_value(known[k]["default"])]) for k in knobs]
        for point in itertools.product(*values):
            check_knobs(**dict(zip(knobs, point)))
    return known


def value_key(value: object) -> object:
    """What makes two values of a parameter the same point: a number's value (3
    and 3.0 are one point), anything else its ``repr``."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    return repr(value)


def run_id(point: dict) -> str:
    """Folder name of one grid point, e.g. ``alpha=3__Ts=0.25``."""
    return "__".join(re.sub(r"[^\w.=+-]", "_", f"{k}={v}") for k, v in point.items())


def sweep(notebook: str | Path, grid: dict[str, list], out: Path | None = None,
          jobs: int | None = None, executor: Executor | None = None) -> pd.DataFrame:
    """Run ``notebook`` over the Cartesian ``grid``; resume-safe; return the table.

    Runs go to ``executor`` (default: ``jobs`` threads, one per core if None;
    each notebook runs in its own kernel process, so threads suffice, and a
    forked process pool would deadlock on the kernel managers' threads).

    ``out`` belongs to one notebook (``out/sweep.json`` names it and every point
    swept into it): a sweep of another notebook into it is refused; a sweep of the
    same notebook adds its points, and ``sweep.csv`` holds every finished point of
    the folder (the earlier ones are not run again).

    Each run writes into ``out/<run_id>/`` (executed notebook, figures,
    ``metrics.json``) and a ``done.json`` marker last, holding the run's key (the
    notebook, the point and the code: :func:`run_key`), so an interrupted sweep
    rerun skips finished runs and repeats nothing, and a folder run by another
    notebook or other code is run again, not read.  Claims are not asserted
    (``check_claims=False``) unless the grid sets it.  The table, one row per
    run and panel with the parameters as columns, is written to ``out/sweep.csv``.
    """
    notebook = Path(notebook).resolve()
    if not notebook.is_file():
        raise ValueError(f"notebook not found: {notebook}")
    if jobs is not None:
        check_count("jobs", jobs)
    known = validate_parameters(notebook, grid)
    if "testbed" in grid.get("plant", []) or known.get("plant", {}).get("default") == '"testbed"':
        _prepare_testbed()
    if out is not None and not str(out).strip():
        raise ValueError("out must name a folder, got an empty path")
    out = Path(out or ROOT / "build" / "sweeps" / notebook.stem).resolve()
    points = [dict(zip(grid, combo)) for combo in itertools.product(*grid.values())]
    earlier = _claim_folder(out, notebook, points)
    keys = {run_id(p): run_key(notebook, {"check_claims": False, **p}) for p in earlier}
    todo = [(p, out / run_id(p)) for p in points
            if not _finished(out / run_id(p), keys[run_id(p)])]
    workers = jobs or os.cpu_count() or 1
    if len(todo) > 1 and workers > 1:
        compile_kernels()            # once, not in every kernel that finds the cache cold
    pool = executor or ThreadPoolExecutor(max_workers=workers)
    futures = {}
    for point, folder in todo:
        params = {"check_claims": False, **point, "figures_dir": str(folder),
                  "results_dir": str(folder)}
        futures[pool.submit(_sweep_one, notebook, folder, params, point,
                            keys[run_id(point)])] = point
    failures = [r for r in _progress(futures, f"sweep {notebook.stem}") if r]
    if executor is None:
        pool.shutdown()
    table = collect(out, earlier, keys)
    write_atomic(out / "sweep.csv", table.to_csv(index=False))
    if failures:
        raise RuntimeError(f"{len(failures)} run(s) failed: " + "; ".join(failures))
    return table


def _claim_folder(out: Path, notebook: Path, points: list[dict]) -> list[dict]:
    """Every point of ``out``'s sweep (``sweep.json``): the earlier sweeps' into it,
    then ``points``' new ones, written back.  ``ValueError`` if ``out`` holds another
    notebook's sweep."""
    manifest = out / "sweep.json"
    earlier: list[dict] = []
    if manifest.exists():
        try:
            held = json.loads(manifest.read_text())
            name, earlier = held["notebook"], list(held["points"])
        except (OSError, ValueError, KeyError, TypeError, RecursionError) as err:
            raise ValueError(f"out={str(out)!r}: its sweep.json is unreadable ({err}); remove "
                             f"it, or choose another folder") from None
        if name != notebook.name:
            raise ValueError(f"out={str(out)!r} holds a sweep of {name}, not of "
                             f"{notebook.name}: choose another folder")
    seen = {run_id(p) for p in earlier}
    every = earlier + [p for p in points if run_id(p) not in seen]
    out.mkdir(parents=True, exist_ok=True)
    write_atomic(manifest, json.dumps({"notebook": notebook.name, "points": every},
                                      default=str))
    return every


def _sweep_one(notebook: Path, folder: Path, params: dict, point: dict, key: str) -> str:
    """One run of a sweep, under its folder's lock: a concurrent sweep of the same
    point waits and then finds it finished."""
    with folder_lock(folder):
        if _finished(folder, key):
            return ""
        try:
            execute(notebook, folder / notebook.name, params)
        except _papermill().PapermillExecutionError as err:
            return f"{run_id(point)}: {err.ename}: {err.evalue}"
        write_atomic(folder / "done.json", json.dumps({"point": point, "key": key,
                                                        "metrics": _sha256(folder)}))
    return ""


def _sha256(folder: Path) -> str:
    """SHA-256 of a run's ``metrics.json``: ``done.json`` seals the run's results
    with it, so a metrics file swapped from another run, emptied or edited is not
    read back."""
    return hashlib.sha256((folder / "metrics.json").read_bytes()).hexdigest()


def _finished(folder: Path, key: str) -> bool:
    """Whether a sweep run finished with the run's ``key`` (:func:`run_key`): its
    ``done.json`` (written last) holding that key and the SHA-256 of its
    ``metrics.json``, a mapping of at least one panel to its metrics.  A damaged
    run (a metrics file changed, swapped from another run or emptied), or one of
    another notebook or other code, is reported and run again."""
    if not (folder / "done.json").exists():
        return False
    why = "done.json or metrics.json unreadable"
    try:
        done = json.loads((folder / "done.json").read_text())
        metrics = json.loads((folder / "metrics.json").read_text())
        if not (isinstance(done, dict) and done.get("key") == key):
            why = "made by another notebook, other parameters or other code"
        elif done.get("metrics") != _sha256(folder):
            why = "metrics.json is not the one this run wrote"
        elif (isinstance(metrics, dict) and metrics
              and all(isinstance(m, dict) for m in metrics.values())):
            return True
        else:
            why = "metrics.json holds no panel's metrics"
    except (OSError, ValueError, RecursionError):
        pass
    warnings.warn(f"sweep run {folder} is stale or damaged ({why}); running it again",
                  stacklevel=3)
    (folder / "done.json").unlink(missing_ok=True)
    return False


def collect(out: Path, points: list[dict], keys: dict[str, str]) -> pd.DataFrame:
    """One row per finished run and panel (its key in ``keys``, by :func:`run_id`):
    parameters, panel name, flat metrics."""
    rows = []
    for point in points:
        folder = out / run_id(point)
        if not _finished(folder, keys[run_id(point)]):
            continue
        for panel, m in json.loads((folder / "metrics.json").read_text()).items():
            flat = {k: v for k, v in m.items() if k != "parameters"}
            rows.append({**{k: str(v) if isinstance(v, list) else v for k, v in point.items()},
                         "run": run_id(point), "panel": panel, **flat})
    return pd.DataFrame(rows)
