"""Command line: ``python -m lfc reproduce``, ``sweep`` (notebooks over a grid),
``batch`` (a scenario table through the batched simulator) and ``readme`` (copy the
generated tables of the last reproduce into the README)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from lfc.repro import runner
from lfc.repro.notebook import PLANTS


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m lfc", description=__doc__)
    sub = ap.add_subparsers(dest="command", required=True)
    rep = sub.add_parser("reproduce", help="regenerate the paper's figures (notebooks)")
    rep.add_argument("--only", nargs="+", choices=list(runner.FIGURES), metavar="NAME",
                     help=f"a subset of {list(runner.FIGURES)}")
    rep.add_argument("--plant", default="all", choices=(*PLANTS, "all"),
                     help="'all' (default): every plant each figure supports")
    rep.add_argument("--jobs", type=int, default=2, help="notebooks run in parallel")
    rep.add_argument("--figures-dir", type=Path, default=runner.ROOT / "figures")
    rep.add_argument("--build-dir", type=Path, default=runner.ROOT / "build")
    sw = sub.add_parser("sweep", help="run a notebook over a parameter grid")
    sw.add_argument("notebook", type=Path)
    sw.add_argument("-p", "--param", nargs="+", action="append", default=[],
                    metavar=("NAME", "VALUE"), help="a parameter and its values")
    sw.add_argument("--jobs", type=int, default=None, help="worker processes (default: cores)")
    sw.add_argument("--out", type=Path, default=None,
                    help="default build/sweeps/<notebook name>")
    sw.add_argument("--dask", metavar="ADDRESS", help="run on a Dask scheduler at ADDRESS")
    bt = sub.add_parser("batch", help="simulate a scenario table (CSV) with simulate_batch")
    bt.add_argument("scenarios", type=Path, help="CSV, one row per scenario (see lfc.batch)")
    bt.add_argument("--duration", type=float, required=True, help="simulated time (s)")
    bt.add_argument("--out", type=Path, required=True,
                    help="folder: per-chunk files (resume) and results.csv")
    bt.add_argument("--chunk-size", type=int, default=500)
    bt.add_argument("--dask", metavar="ADDRESS", help="run on a Dask scheduler at ADDRESS")
    rd = sub.add_parser("readme", help="copy figures/<name>.md into the README's "
                        "<!-- name:start --> sections (reproduce never edits the README)")
    rd.add_argument("--check", action="store_true",
                    help="only report sections that differ (exit 1 if any)")
    return ap


def _executor(address: str | None):
    """A Dask cluster's executor for ``--dask ADDRESS``, else None (the default pool)."""
    if not address:
        return None
    from distributed import Client
    return Client(address).get_executor()


def _batch(args) -> int:
    import pandas as pd

    from lfc.batch import simulate_batch
    from lfc.model import LFCParams
    if not args.scenarios.exists():
        raise ValueError(f"scenario table not found: {args.scenarios}")
    table = simulate_batch(LFCParams(), pd.read_csv(args.scenarios), duration=args.duration,
                           chunk_size=args.chunk_size, out=args.out / "chunks",
                           executor=_executor(args.dask))
    table.to_csv(args.out / "results.csv", index=False)
    print(f"{len(table)} scenarios, {int(table.tripped.sum())} tripped -> "
          f"{args.out / 'results.csv'}")
    return 0


def _readme(check: bool) -> int:
    from lfc.repro.notebook import readme_mismatches, sync_readme
    readme, tables = runner.ROOT / "README.md", runner.ROOT / "figures"
    if check:
        stale = readme_mismatches(readme, tables)
        print("README sections out of date: " + ", ".join(stale) if stale else
              "README tables match figures/")
        return 1 if stale else 0
    changed = sync_readme(readme, tables)
    print("updated README sections: " + ", ".join(changed) if changed else "README up to date")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        if args.command == "reproduce":
            outcomes = runner.reproduce(args.only, args.plant, args.jobs, args.figures_dir,
                                        args.build_dir)
            print(runner.summary_table(outcomes).to_string(index=False))
            notes = runner.deviation_notes(outcomes)
            if notes:
                print("\nDocumented deviations (README, 'Where the testbed differs'):")
                print("\n".join(f"- {n}" for n in notes))
            return 0 if all(o.ok for o in outcomes) else 1
        if args.command == "batch":
            return _batch(args)
        if args.command == "readme":
            return _readme(args.check)
        grid = {}
        for name, *values in args.param:
            if not values:
                raise ValueError(f"parameter {name!r} has no values")
            grid[name] = [runner.parse_value(v) for v in values]
        table = runner.sweep(args.notebook, grid, args.out, args.jobs,
                             executor=_executor(args.dask))
        print(table.to_string(index=False))
        return 0
    except (ValueError, RuntimeError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
