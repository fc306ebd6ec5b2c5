"""Command line: ``python -m lfc reproduce``, ``sweep`` (notebooks over a grid),
``batch`` (a scenario table through the batched simulator), ``book`` (the executed
notebooks as HTML), ``readme`` (copy the generated tables of the last reproduce
into the README and the appendices in ``docs/``) and ``fit`` (the committed ANDES fits,
computed again on this machine and compared)."""

from __future__ import annotations

import argparse
import json
import re
import resource
import sys
import time
from pathlib import Path

from lfc._validate import check_folder
from lfc.experiments.scenarios import ALL_PLANTS
from lfc.repro import manifest


class _Parser(argparse.ArgumentParser):
    """argparse, with a usage error as one line on stderr (exit 2)."""

    def error(self, message: str):
        self.exit(2, f"error: {message} (python -m lfc --help)\n")


def _count(flag: str):
    """The argument type of ``flag``: an integer >= 1."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = 0
        if value < 1:
            raise argparse.ArgumentTypeError(f"{flag} must be an integer >= 1, got {text!r}")
        return value
    return parse


def _folder(text: str) -> Path:
    """``--out`` and the other folders: a non-empty path (``''`` would mean the
    current directory)."""
    try:
        return check_folder("a folder", text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def _core(text: str) -> str:
    """``--compare-blas``: an OpenBLAS core type name (letters and digits)."""
    if not re.fullmatch(r"[A-Za-z0-9]+", text):
        raise argparse.ArgumentTypeError(f"--compare-blas must be an OpenBLAS core type such "
                                         f"as Haswell, got {text!r}")
    return text


_jobs = _count("--jobs")


def _parser() -> argparse.ArgumentParser:
    ap = _Parser(prog="python -m lfc", description=__doc__)
    sub = ap.add_subparsers(dest="command", required=True)
    rep = sub.add_parser("reproduce", help="regenerate the paper's figures (notebooks)")
    names = [c.name for c in manifest.CHAPTERS]
    rep.add_argument("--only", nargs="+", choices=names, metavar="NAME",
                     help=f"a subset of {names}")
    rep.add_argument("--plant", default="all", choices=(*ALL_PLANTS, "all"),
                     help="'all' (default): every plant each figure supports")
    rep.add_argument("--jobs", type=_jobs, default=2, help="notebooks run in parallel")
    rep.add_argument("--figures-dir", type=_folder, default=manifest.ROOT / "figures")
    rep.add_argument("--build-dir", type=_folder, default=manifest.ROOT / "build")
    rep.add_argument("--quick", action="store_true",
                     help="every chapter on the linear model with its short parameters, "
                          "claims not checked, figures into BUILD_DIR/quick/figures "
                          "(about a minute)")
    rep.add_argument("--no-cache", dest="cache", action="store_false",
                     help="run every notebook, even those unchanged since their last "
                          "successful run, and every ANDES run, even those stored "
                          "(default: those are read back)")
    rep.add_argument("--compare-blas", metavar="CORE", type=_core,
                     help="then run the same notebooks again with OPENBLAS_CORETYPE=CORE "
                          "(e.g. Haswell) into BUILD_DIR/blas-CORE and list every claim "
                          "and table cell that differs (exit 1 if any)")
    sw = sub.add_parser(
        "sweep", help="run a notebook over a parameter grid",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n"
               "  Fig. 4 at two gains and three amplitudes, 6 runs on 2 processes\n"
               "    python -m lfc sweep notebooks/02_fig4_rocof_attack.ipynb \\\n"
               "        -p alpha 3 20 -p amplitude 0.3 0.5 1.0 --jobs 2\n"
               "  Fig. 6's load step at three sizes on the linear model, into build/steps\n"
               "    python -m lfc sweep notebooks/04_fig6_load_step.ipynb \\\n"
               "        -p load_step 0.05 0.1 0.2 --out build/steps\n"
               "writes OUT/sweep.csv (a row per run and panel: parameters and metrics)\n"
               "and each run's executed notebook and figures in its own folder of OUT\n"
               "(a rerun skips finished runs); the paper's claims are not asserted\n"
               "(check_claims False) unless -p check_claims True; a list parameter\n"
               "takes one value per -p, as Python or YAML: -p edge_durations '[10, 30]';\n"
               "plot it with\n"
               "    python -m lfc plot-sweep OUT/sweep.csv -x amplitude -y max_abs_rocof_meas "
               "--by alpha")
    sw.add_argument("notebook", type=Path,
                    help="the chapter to run, e.g. notebooks/02_fig4_rocof_attack.ipynb; its "
                         "parameters are the names in its cell tagged 'parameters'")
    sw.add_argument("-p", "--param", nargs="+", action="append", default=[],
                    metavar=("NAME", "VALUE"),
                    help="a parameter and its values (repeating a name adds values)")
    sw.add_argument("--jobs", type=_jobs, default=None,
                    help="worker processes (default: cores)")
    sw.add_argument("--out", type=_folder, default=None,
                    help="default build/sweeps/<notebook name>")
    sw.add_argument("--dask", metavar="ADDRESS", help="run on a Dask scheduler at ADDRESS")
    ps = sub.add_parser(
        "plot-sweep", help="plot a sweep's table: a metric against a parameter",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example: the peak ROCOF of Fig. 4's panels against the attack amplitude,\n"
               "one line per gain, the ROCOF relay setting dashed\n"
               "  python -m lfc plot-sweep build/sweeps/02_fig4_rocof_attack/sweep.csv \\\n"
               "      -x amplitude -y max_abs_rocof_meas --by alpha")
    ps.add_argument("table", type=Path, help="a sweep.csv written by python -m lfc sweep")
    ps.add_argument("-x", required=True, help="the parameter on the horizontal axis")
    ps.add_argument("-y", required=True, help="the metric (a column of the table)")
    ps.add_argument("--by", help="a second parameter: one line per value (and panel)")
    ps.add_argument("--out", type=Path, default=None,
                    help="figure path without extension (.png and .pdf written; default "
                         "beside the table: sweep_<y>_vs_<x>)")
    bt = sub.add_parser("batch", help="simulate a scenario table (CSV) with simulate_many")
    bt.add_argument("scenarios", type=Path, help="CSV, one row per scenario (see lfc.tables)")
    bt.add_argument("--duration", type=float, required=True, help="simulated time (s)")
    bt.add_argument("--out", type=_folder, required=True,
                    help="folder: per-chunk files (resume) and results.csv")
    bt.add_argument("--chunk-size", type=_count("--chunk-size"), default=500,
                    help="scenarios per chunk (>= 1)")
    bt.add_argument("--dask", metavar="ADDRESS", help="run on a Dask scheduler at ADDRESS")
    bk = sub.add_parser("book", help="render the last reproduce's notebooks as HTML in "
                        "build/book/ (executing any that are missing)")
    bk.add_argument("--only", nargs="+", choices=names, metavar="NAME",
                    help=f"a subset of {names}")
    bk.add_argument("--figures-dir", type=_folder, default=manifest.ROOT / "figures")
    bk.add_argument("--build-dir", type=_folder, default=manifest.ROOT / "build")
    bk.add_argument("--pdf", action="store_true",
                    help="also print the book to build/book/lfc-scc-book.pdf (needs Chromium)")
    wr = sub.add_parser(
        "wire", help="runs over Modbus/TCP or DNP3 on loopback or network namespaces: "
        "control centre, man in the middle, generator",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example: Fig. 4's attack injected in the frames, with and without the\n"
               "paper's filter, and the traffic as a capture Wireshark decodes\n"
               "  python -m lfc wire --attack fig4 --filter none paper --pcap build/fig4.pcap\n"
               "attacks: a name (fig4, fig4-weak, fig5, fig5-told, delay-2, drop, none) or a\n"
               "JSON file holding a list of operations (lfc.wire.attacks); fig5-told and\n"
               "delay-2 act with --agc centre.")
    wr.add_argument("--protocol", choices=("modbus", "dnp3"), default="modbus")
    wr.add_argument("--attack", default="fig4",
                    help="a name of lfc.wire.attacks.ATTACKS or a JSON file (default fig4)")
    wr.add_argument("--filter", nargs="+", choices=("none", "paper", "certified"),
                    default=["none", "paper"], help="one run per filter (paper: alpha = 20)")
    wr.add_argument("--duration", type=float, default=10.0, help="simulated time (s)")
    wr.add_argument("--agc", choices=("generator", "centre"), default="generator",
                    help="where the integrator runs: at the generator (the paper's local "
                         "controller; default) or the control centre's AGC")
    wr.add_argument("--realtime", action="store_true",
                    help="the plant at the wall clock (default: lockstep, one control period "
                         "per exchanged command)")
    wr.add_argument("--delay", type=float, default=0.0,
                    help="the network's one-way delay between the centre and the substation "
                         "(ms; made in the relay, as tc netem would)")
    wr.add_argument("--jitter", type=float, default=0.0,
                    help="a uniform draw in [-jitter, jitter] added to each frame's delay (ms)")
    wr.add_argument("--loss", type=float, default=0.0,
                    help="the share of frames lost once and sent again after TCP's 200 ms "
                         "retransmission timeout (%%)")
    wr.add_argument("--select-before-operate", action="store_true",
                    help="DNP3: every command a SELECT, then an OPERATE of the same values; "
                         "the outstation takes nothing else")
    wr.add_argument("--pcap", type=Path,
                    help="write the last run's traffic here, made from the relay's log")
    wr.add_argument("--network", choices=("loopback", "namespaces"), default="loopback",
                    help="where the parties sit: each at its own loopback address (default) "
                         "or in network namespaces of their own joined by veth links, made "
                         "for the run and removed after it (root; lfc.wire.network)")
    wr.add_argument("--capture", type=Path,
                    help="capture the last run's traffic from the network here (root or "
                         "CAP_NET_RAW): handshakes, addresses, ports, IP ids and times are "
                         "the kernel's")
    dt = sub.add_parser(
        "detect", help="the network detector (lfc.wire.detect) over a capture written by "
        "lfc wire --pcap: its alerts per area, tap and rule",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example: the drop attack, captured, then read by the detector\n"
               "  python -m lfc wire --attack drop --agc centre --filter none "
               "--pcap build/drop.pcap\n"
               "  python -m lfc detect build/drop.pcap --csv build/drop-alerts.csv\n"
               "thresholds: the default area's (lfc.LFCParams, lfc.RelaySettings): wref within "
               "the relays'\nband, pc moving at most k_i x 0.058 pu/s (Rules.for_area).")
    dt.add_argument("capture", type=Path, help="a pcap written by lfc wire --pcap")
    dt.add_argument("--protocol", choices=("modbus", "dnp3"), default="modbus")
    dt.add_argument("--taps", nargs="+", choices=("substation", "centre"),
                    default=["substation", "centre"],
                    help="the taps the detector has (end-to-end needs both; default both)")
    dt.add_argument("--period", type=float, default=0.01,
                    help="the control period the capture was made at (s; default 0.01)")
    dt.add_argument("--csv", type=Path, help="write every alert here")
    ft = sub.add_parser("fit", help="fit the committed design models to ANDES again on this "
                        "machine and compare them with lfc/testbed/fitted/ (about 5 min)")
    how = ft.add_mutually_exclusive_group()
    how.add_argument("--write", action="store_true",
                     help="write the fits computed here as the committed ones")
    how.add_argument("--save", type=Path, metavar="FILE",
                     help="also write the fits computed here to FILE (JSON), before a change "
                          "of the fitting code, for --restamp after it")
    how.add_argument("--restamp", type=Path, metavar="FILE",
                     help="if every fit computed here equals FILE's (--save) bit for bit, "
                          "stamp the committed fits with the code as it is now, their numbers "
                          "left as they are (exit 1 and stamp nothing otherwise)")
    rd = sub.add_parser("readme", help="copy figures/<name>.md into the <!-- name:start --> "
                        "sections of the README and docs/*.md, and the last full reproduce's "
                        "timing (build/reproduce/timing*.md; reproduce never edits them)")
    rd.add_argument("--check", action="store_true",
                    help="only report sections that differ (exit 1 if any)")
    return ap


def _executor(address: str | None):
    """A Dask cluster's executor for ``--dask ADDRESS``, else None (the default pool)."""
    if not address:
        return None
    from distributed import Client
    try:
        return Client(address, timeout="5s").get_executor()
    except (OSError, TimeoutError) as err:
        raise ValueError(f"cannot reach the Dask scheduler at {address!r}: {err}") from err


def _batch(args) -> int:
    import pandas as pd

    from lfc.run import simulate_many
    from lfc.model import LFCParams
    if not args.scenarios.is_file():
        raise ValueError(f"scenario table not found (or not a file): {args.scenarios}")
    try:
        scenarios = pd.read_csv(args.scenarios)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as err:
        raise ValueError(f"cannot read the scenario table {args.scenarios}: {err}") from err
    table = simulate_many(LFCParams(), scenarios, duration=args.duration,
                           chunk_size=args.chunk_size, out=args.out / "chunks",
                           executor=_executor(args.dask))
    table.to_csv(args.out / "results.csv", index=False)
    print(f"{len(table)} scenarios, {int(table.tripped.sum())} tripped -> "
          f"{args.out / 'results.csv'}")
    return 0


def _wire(args) -> int:
    import json

    import pandas as pd

    from lfc.filters import SafetyFilter
    from lfc.model import LFCParams
    from lfc.relays import RelaySettings
    from lfc.wire import ATTACKS, run_wire
    from lfc.wire.capture import write_pcap
    attack = args.attack
    if attack not in ATTACKS:
        path = Path(attack)
        if not path.is_file():
            raise ValueError(f"--attack must be one of {sorted(ATTACKS)} or a JSON file, got "
                             f"{attack!r}")
        try:
            attack = json.loads(path.read_text())
        except json.JSONDecodeError as err:
            raise ValueError(f"cannot read the attack {path}: {err}") from err
    from lfc.wire import Impairment
    impairment = Impairment(delay=args.delay / 1e3, jitter=args.jitter / 1e3,
                            loss=args.loss / 100) if args.delay or args.loss else None
    params, relays = LFCParams(), RelaySettings()
    filters = {"none": None, "paper": lambda: SafetyFilter(params, relays, alpha=20.0),
               "certified": lambda: SafetyFilter(params, relays, method="certified")}
    rows, run = [], None
    for k, name in enumerate(args.filter):
        scc = filters[name]() if filters[name] else None
        last = k == len(args.filter) - 1
        run = run_wire(params, duration=args.duration, attack=attack, scc=scc,
                       protocol=args.protocol, agc=args.agc,
                       mode="realtime" if args.realtime else "lockstep",
                       capture=args.capture if last else None, impairment=impairment,
                       select_before_operate=args.select_before_operate,
                       network=args.network)
        rows.append(run.table())
    print(pd.concat(rows, ignore_index=True).to_string(index=False))
    if args.pcap:
        args.pcap.parent.mkdir(parents=True, exist_ok=True)
        write_pcap(run.frames, args.pcap, args.protocol)
        print(f"capture of the last run ({len(run.frames)} frames): {args.pcap}")
    if args.capture:
        dissector = "mbtcp" if args.protocol == "modbus" else "dnp3"
        ports = ",".join(str(p) for pair in run.settings["ports"] for p in pair)
        ports = f"-o {dissector}.tcp.port:{ports}"
        print(f"the last run captured from the {args.network} network: {args.capture}\n"
              f"decode it with: tshark -r {args.capture} {ports}")
    return 0


def _detect(args) -> int:
    from lfc.model import LFCParams
    from lfc.wire.capture import read_frames
    from lfc.wire.detect import Rules, detect
    if not args.capture.is_file():
        raise ValueError(f"capture: no such file {args.capture}")
    rules = Rules.for_area(args.period, LFCParams().k_i)
    frames = read_frames(args.capture, args.protocol)
    alerts = detect(frames, args.protocol, rules, taps=tuple(args.taps))
    print(f"{len(frames)} frames of the run's legs in {args.capture}; {len(alerts)} alerts")
    if not alerts.empty:
        summary = alerts.groupby(["area", "tap", "rule"]).agg(
            alerts=("t", "size"), first_s=("t", "min"), first=("detail", "first"))
        print(summary.to_string())
    if args.csv:
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        alerts.to_csv(args.csv, index=False)
        print(f"every alert: {args.csv}")
    return 0


def _readme(check: bool) -> int:
    from lfc.repro import runner
    from lfc.repro.notebook import documents, readme_mismatches, sync_readme, \
        update_markdown_section
    tables = runner.ROOT / "figures"
    docs = documents(runner.ROOT)
    if check:
        stale = [f"{d.name}: {name}" for d in docs for name in readme_mismatches(d, tables)]
        print("sections out of date: " + ", ".join(stale) if stale else
              "generated sections match figures/")
        return 1 if stale else 0
    for name in runner.TIMING_FILES.values():     # the last full runs' timing, where measured
        timing = runner.ROOT / "build" / "reproduce" / name
        for doc in docs:
            if timing.exists() and f"<!-- {name[:-3]}:start -->" in doc.read_text():
                update_markdown_section(doc, name[:-3], timing.read_text())
                print(f"{doc.name} section {name[:-3]} from {timing}")
    times = runner.read_json(runner.ROOT / "build" / runner.TIMES_FILE)
    if times:                                     # each command's last complete run
        update_markdown_section(docs[0], "times", runner.times_section(times))
        print(f"README.md section times from build/{runner.TIMES_FILE}")
    changed = [f"{d.name}: {name}" for d in docs for name in sync_readme(d, tables)]
    print("updated sections: " + ", ".join(changed) if changed else "every section up to date")
    return 0


INTERRUPTED = 130   # exit code after Ctrl-C (128 + SIGINT)


def _fit(write: bool, save: Path | None = None, restamp: Path | None = None) -> int:
    """``python -m lfc fit``: each committed fit computed again (ANDES), its
    numbers beside the committed ones with their relative difference; with
    ``write``, the computed fits become the committed ones; with ``save``, they are
    also written to that file; with ``restamp``, the committed fits are stamped with
    today's code (:func:`lfc.testbed.fit.restamp_committed`) if every computed fit
    equals that file's, bit for bit (else exit 1, nothing stamped)."""
    from lfc.testbed.fit import (committed_fits, committed_path, fit_numbers, read_committed,
                                 restamp_committed, write_committed)

    reference = json.loads(restamp.read_text(encoding="utf-8")) if restamp else None
    computed_fits, differ = {}, []
    for c in committed_fits():
        name = committed_path(c.case, c.kind).name
        print(f"{name}: fitting on ANDES ...", flush=True)
        computed = c.kind.compute(c.case)
        computed_fits[name] = json.loads(json.dumps(c.kind.encode(computed)))
        committed = read_committed(c.case, c.kind)
        old = fit_numbers(committed) if committed is not None else {}
        rows = [f"  {k:<24} {old[k] if k in old else float('nan'):>22.15g} {v:>22.15g} "
                f"{abs(v - old[k]) / max(abs(old[k]), 1e-300) if k in old else float('nan'):>9.2g}"
                for k, v in fit_numbers(computed).items()]
        print(f"  {'':<24} {'committed':>22} {'computed here':>22} {'rel. diff':>9}")
        print("\n".join(rows))
        if write:
            print(f"  written: {write_committed(c.case, c.kind, computed)}")
        if reference is not None and reference.get(name) != computed_fits[name]:
            differ.append(name)
    if save:
        save.write_text(json.dumps(computed_fits, indent=1, sort_keys=True) + "\n")
        print(f"the fits computed here: {save}")
    if reference is not None:
        if differ:
            print(f"not stamped: the fit of {', '.join(differ)} differs from {restamp}'s "
                  f"(a refit: python -m lfc fit --write)")
            return 1
        for c in committed_fits():
            print(f"stamped with the code as it is: {restamp_committed(c.case, c.kind)}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the exit code (2: a usage or input error,
    printed as one line on stderr; 130: interrupted)."""
    try:
        args = _parser().parse_args(argv)
    except SystemExit as done:          # --help (0) or a usage error (2), already printed
        return int(done.code or 0)
    try:
        from lfc.repro import runner          # (papermill: not for --help or a usage error)
        if args.command == "reproduce":
            t0 = time.perf_counter()
            outcomes = runner.reproduce(args.only, args.plant, args.jobs, args.figures_dir,
                                        args.build_dir, cache=args.cache, quick=args.quick)
            wall = time.perf_counter() - t0
            if args.quick:
                failed = [o.name for o in outcomes if not o.ok]
                print(f"quick: {len(outcomes) - len(failed)} of {len(outcomes)} chapters ran "
                      f"on the linear model with short parameters (claims not checked); "
                      f"figures in {args.build_dir / 'quick' / 'figures'}"
                      + (f"; failed: {', '.join(failed)}" if failed else ""))
            else:
                print(runner.summary_table(outcomes).to_string(index=False))
            cached = sum(o.cached for o in outcomes)
            cpu = sum(getattr(resource.getrusage(who), f) for f in ("ru_utime", "ru_stime")
                      for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
            if not (args.quick or args.only) and args.plant == "all":   # a full run
                path = (args.build_dir / "reproduce"      # a rerun keeps the full run's
                        / runner.TIMING_FILES[cached > 0])
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(runner.timing_table(outcomes, wall, cpu, args.jobs))
                print(f"timing: {path} (python -m lfc readme copies it into "
                      "docs/reproducing.md)")
            if not args.only and args.plant in ("all", "linear") and all(o.ok for o in outcomes):
                command = "python -m lfc reproduce" + (" --quick" if args.quick else (
                    " --plant linear" if args.plant == "linear" else "")) + (
                    ", again" if cached else "")       # a first run and a rerun, apart
                runner.record_time(args.build_dir, command, wall, cpu,
                                   f"{len(outcomes) - cached} notebooks executed, {cached} "
                                   f"read back" + ("; the loops compiled in the run"
                                                   if runner.COMPILED_IN_RUN else ""))
            print(f"\nNotebooks ({wall:.0f} s wall on {args.jobs} jobs"
                  + (f"; {cached} of {len(outcomes)} unchanged since their last run, read "
                     f"back from build/ — --no-cache reruns them" if cached else "") + "):")
            print(runner.times_table(outcomes).to_string(index=False))
            notes = runner.deviation_notes(outcomes)
            if notes:
                print("\nDocumented deviations (docs/testbed.md, 'Where the testbed differs'):")
                print("\n".join(f"- {n}" for n in notes))
            ok = all(o.ok for o in outcomes)
            if args.compare_blas:
                again, tables = runner.rerun_with_blas(args.compare_blas, args.only,
                                                       args.plant, args.jobs, args.build_dir)
                diff = runner.differences(outcomes, again, args.figures_dir, tables,
                                          ("this machine's kernel", args.compare_blas))
                print(f"\nUnder OPENBLAS_CORETYPE={args.compare_blas}: "
                      + ("every claim and table cell agrees" if not diff else
                         f"{len(diff)} difference(s)"))
                print("\n".join(f"- {d}" for d in diff))
                ok = ok and not diff
            return 0 if ok else 1
        if args.command == "batch":
            return _batch(args)
        if args.command == "readme":
            return _readme(args.check)
        if args.command == "fit":
            return _fit(args.write, args.save, args.restamp)
        if args.command == "wire":
            return _wire(args)
        if args.command == "detect":
            return _detect(args)
        if args.command == "plot-sweep":
            return _plot_sweep(args)
        if args.command == "book":
            from lfc.repro.book import PDF_NAME, build_book
            index = build_book(args.only, args.build_dir, args.figures_dir, pdf=args.pdf)
            print(f"the book: {index}")
            if args.pdf:
                print(f"its PDF: {index.with_name(PDF_NAME)}")
            return 0
        table = runner.sweep(args.notebook, _grid(args.param), args.out, args.jobs,
                             executor=_executor(args.dask))
        print(table.to_string(index=False))
        return 0
    except (ValueError, RuntimeError, OSError) as err:
        if _by_ctrl_c(err):
            return _interrupted()
        print(f"error: {_one_line(err)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return _interrupted()


def _by_ctrl_c(err: BaseException) -> bool:
    """Whether ``err`` was raised while a Ctrl-C unwound (a lock released twice as the
    ``KeyboardInterrupt`` left a ``with`` block: "release unlocked lock")."""
    seen = err.__context__
    while seen is not None:
        if isinstance(seen, KeyboardInterrupt):
            return True
        seen = seen.__context__
    return False


def _interrupted() -> int:
    """Stop the kernels this process started; say what is kept; the exit code 130."""
    started = sys.modules.get("lfc.repro.runner")     # no runner imported: no kernels
    if started is not None:
        started.stop_kernels()
    print("interrupted: finished runs and chunks are kept; rerun the same command to "
          "resume", file=sys.stderr)
    return INTERRUPTED


def _plot_sweep(args) -> int:
    import matplotlib
    import pandas as pd
    matplotlib.use("Agg")
    from lfc.repro.plotting import save_figure, sweep_figure
    if not args.table.is_file():
        raise ValueError(f"sweep table not found: {args.table}")
    if args.out is not None and not str(args.out).strip(" ."):
        raise ValueError(f"--out must name a file (without suffix), got {str(args.out)!r}")
    fig = sweep_figure(pd.read_csv(args.table), args.x, args.y, args.by)
    out = args.out or args.table.parent / f"sweep_{args.y}_vs_{args.x}"
    save_figure(fig, out.parent, out.name)
    print(f"the figure: {out}.png (and .pdf)")
    return 0


def _grid(params: list[list[str]]) -> dict[str, list]:
    """The sweep grid of ``-p NAME VALUE...`` options: a repeated name adds its
    values (a value given twice is refused by :func:`runner.validate_parameters`)."""
    from lfc.repro.runner import parse_value
    grid: dict[str, list] = {}
    for name, *values in params:
        if not values:
            raise ValueError(f"parameter {name!r} has no values")
        grid.setdefault(name, []).extend(parse_value(v) for v in values)
    return grid


def _one_line(err: BaseException) -> str:
    """The error's message on one line."""
    return " ".join(str(err).split()) or type(err).__name__


if __name__ == "__main__":
    sys.exit(main())
