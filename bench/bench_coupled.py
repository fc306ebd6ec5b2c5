"""Benchmark: what the coupled certificate and the contract cost per area and
control period, and how their conservatism grows with the number of areas.

Prints, from one run on this machine, for rings of 2 (the two-area preset), 4, 6
and 10 areas (the three-area preset's areas in turn, T = 2 pu) and for the
two-area preset with stiffer ties (T = 2, 10, 30 pu): the construction time, the
certificate's size (samples, rows), its tightenings of the frequency and ROCOF
limits (load, between samples), and the median time of one filter call per area
and control period inside the engine: a 20 s run with a coordinated sinusoid on
every area's command with the filter, minus the same run without it, divided by
the calls (goal <= 1 ms at 10 areas).  Reference: the per-area certified filter
(``"certified"``, built once) on the same run, where it builds.  Where the
coupled filter's defaults do not build the row uses ``load_bound = recheck_bound
= 0.05`` and says so; a row whose terminal set is the shaped one
(``terminal="auto"`` chose it) says so too.  The decentralized certificate by
contract (``"contract"``, :mod:`lfc.filters.contract`) on the same grids: each
area's box (pu) and rate (pu/s) — its conservatism — its design time and its
time per call: one clip, too short to resolve as a difference of run times, so
measured on ``filter_batch`` of 10^6 commands (the same compiled call), median
of 3.

With ``--rows``: only the filter's pass over its rows (``row_intervals``), which
sums all rows at once, one column after another, against the way it did before
2026-11-29, kept here as the reference: one row after another, on the rows
stored row by row.  Checks that both give the same intervals bit for bit on
1,000 random calls, then prints the median time per call of each (two-area
preset, three-area preset, rings of 4 and 6) and the ratio.

Run: python bench/bench_coupled.py [--rows]
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time

import numba as nb
import numpy as np

import lfc
from lfc import MultiAreaParams
from lfc._jit import maxnum, minnum
from lfc.filters.base import clear_built
from lfc.filters.bounds import pair
from lfc.filters.contract import contract_design
from lfc.filters.coupled import CoupledFilter
from lfc.filters.coupled_kernel import row_intervals
from lfc.linear_grid import area_filter

DURATION, REPEAT = 20.0, 3
THREE = MultiAreaParams.three_area()


def ring(n: int) -> MultiAreaParams:
    if n == 2:
        return MultiAreaParams.two_area()
    return MultiAreaParams(areas=tuple(THREE.areas[i % 3] for i in range(n)),
                           tie=tuple((i, (i + 1) % n, 2.0) for i in range(n)))


def run_time(grid: MultiAreaParams, filters: dict | None) -> float:
    attack = {a: {"pc": lfc.Sinusoid(1.0, 0.5, start=1.0)} for a in range(grid.n_areas)}
    times = []
    for _ in range(REPEAT):
        t0 = time.perf_counter()
        lfc.simulate(grid, duration=DURATION, attacks=attack, filters=filters)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def batch_call(filt: lfc.SafetyFilter, n: int = 10**6) -> float:
    """Median time of one call of ``filt`` in ``filter_batch`` over ``n`` random
    commands (s)."""
    rng = np.random.default_rng(0)
    x, u = np.zeros((n, 5)), rng.normal(0.0, 0.5, n)
    filt.filter_batch(x[:10], u[:10])                 # compile
    times = []
    for _ in range(REPEAT):
        t0 = time.perf_counter()
        filt.filter_batch(x, u)
        times.append(time.perf_counter() - t0)
    return statistics.median(times) / n


def row(name: str, grid: MultiAreaParams) -> None:
    relays = lfc.RelaySettings()
    clear_built()        # time the construction, not a set this process built already
    t0 = time.perf_counter()
    try:
        filt = CoupledFilter(grid, relays)
    except ValueError:     # where the defaults do not build (a finding): nothing absorbed
        t0 = time.perf_counter()
        filt = CoupledFilter(grid, relays, load_bound=0.05, recheck_bound=0.05)
        name += " (defaults do not build; load_bound = recheck_bound = 0.05)"
    built = time.perf_counter() - t0
    if filt.cert.terminal == "sdp":
        name += " (shaped terminal set)"
    calls = grid.n_areas * DURATION / 0.01
    bare = run_time(grid, None)
    per_call = (run_time(grid, {a: filt for a in range(grid.n_areas)}) - bare) / calls
    try:
        per_area = {a: area_filter(grid, a, "certified", relays, 0.01)
                    for a in range(grid.n_areas)}
        ref = f"{1e6 * (run_time(grid, per_area) - bare) / calls:.2f} µs"
    except ValueError:
        ref = "does not build"
    t0 = time.perf_counter()
    share = contract_design(grid, relays)
    designed = time.perf_counter() - t0
    contract_call = batch_call(area_filter(grid, 0, "contract", relays, 0.01))
    b = filt.cert.budget
    print(f"| {name} | {built:.1f} s | {len(filt.cert.times)} / {filt.cert.n_rows} | "
          f"{pair(b['load'])} | {pair(b['between samples'])} | {1e6 * per_call:.1f} µs | "
          f"{ref} | "
          f"±{share.half_width.min():.3g} pu, {share.rate.min():.3g} pu/s | {designed:.1f} s | "
          f"{1e9 * contract_call:.0f} ns |", flush=True)


@nb.njit(nogil=True)
def rows_one_by_one(rows: np.ndarray, n_s: int, x: np.ndarray, u: np.ndarray, p: np.ndarray,
                    k: int) -> tuple:
    """The reference: ``row_intervals`` as it was, one row after another
    (``rows`` (n_rows, 2 + n_s + 2 n_a): bound new, bound held, then the state's,
    the commands' and the loads' gains)."""
    inf = np.inf
    n_a = len(u)
    lo_f, hi_f, lo_r, hi_r, lo_h, hi_h = -inf, inf, -inf, inf, -inf, inf
    u_k = u[k]
    for r in range(rows.shape[0]):
        row = rows[r]
        s = 0.0
        for c in range(n_s):
            s += row[2 + c] * x[c]
        for j in range(n_a):
            s += row[2 + n_s + j] * u[j] + row[2 + n_s + n_a + j] * p[j]
        h = row[2 + n_s + k]
        s -= h * u_k
        bn, bh = row[0], row[1]
        if h != 0.0:
            a1, a2, c1, c2 = (-bn - s) / h, (bn - s) / h, (-bh - s) / h, (bh - s) / h
            lo_n, hi_n, lo_hh, hi_hh = min(a1, a2), max(a1, a2), min(c1, c2), max(c1, c2)
        else:
            lo_n, hi_n = (-inf, inf) if abs(s) <= bn else (inf, -inf)
            lo_hh, hi_hh = (-inf, inf) if abs(s) <= bh else (inf, -inf)
        if r % 2 == 0:
            lo_f, hi_f = maxnum(lo_f, lo_n), minnum(hi_f, hi_n)
        else:
            lo_r, hi_r = maxnum(lo_r, lo_n), minnum(hi_r, hi_n)
        lo_h, hi_h = maxnum(lo_h, lo_hh), minnum(hi_h, hi_hh)
    return lo_f, hi_f, lo_r, hi_r, lo_h, hi_h


@nb.njit(nogil=True)
def _columns(fd, x, u, p, k, sums):
    return row_intervals(fd, x, u, p, k, sums)


@nb.njit(nogil=True)
def _repeat(column_pass: bool, fd, rows, n_s, x, u, p, sums, n: int) -> float:
    acc = 0.0
    for i in range(n):
        k = i % len(u)
        acc += (_columns(fd, x, u, p, k, sums)[0] if column_pass
                else rows_one_by_one(rows, n_s, x, u, p, k)[0])
    return acc


def rows_main() -> None:
    """``--rows`` (module docstring)."""
    print("the row pass per call, median of 5 x 2,000 calls: column by column (the "
          "filter's) against row after row (the reference)")
    print("| grid | rows | row after row | column by column | ratio |")
    print("|---|---|---|---|---|")
    for name, grid in (("two-area", ring(2)), ("three-area", THREE), ("ring of 4", ring(4)),
                       ("ring of 6", ring(6))):
        cert = CoupledFilter(grid, lfc.RelaySettings()).cert
        fd, rows, n_s = cert.data, np.ascontiguousarray(cert.rows), grid.n_states
        sums = np.zeros(cert.n_rows)
        rng = np.random.default_rng(0)
        for _ in range(1000):
            x = rng.normal(size=n_s) * 10.0 ** rng.uniform(-4, 0)
            u, p = rng.normal(size=grid.n_areas) * 0.3, rng.normal(size=grid.n_areas) * 0.05
            k = int(rng.integers(grid.n_areas))
            one = rows_one_by_one(rows, n_s, x, u, p, k)
            if np.array(one).tobytes() != np.array(_columns(fd, x, u, p, k, sums)).tobytes():
                raise AssertionError(f"{name}: the two passes differ at x={x}, u={u}, p={p}")
        times = {}
        for column_pass in (False, True):
            _repeat(column_pass, fd, rows, n_s, x, u, p, sums, 10)
            runs = []
            for _ in range(5):
                t0 = time.perf_counter()
                _repeat(column_pass, fd, rows, n_s, x, u, p, sums, 2000)
                runs.append((time.perf_counter() - t0) / 2000)
            times[column_pass] = statistics.median(runs)
        print(f"| {name} | {cert.n_rows} | {1e6 * times[False]:.2f} µs | "
              f"{1e6 * times[True]:.2f} µs | {times[False] / times[True]:.2f}x |", flush=True)


def main() -> None:
    os.environ["LFC_CACHE_DIR"] = tempfile.mkdtemp(prefix="lfc-bench-")   # nothing stored read
    ring(2)
    lfc.simulate(ring(2), duration=0.1, filters={0: "coupled", 1: "coupled"})   # compile
    print(f"coupled certificate, {DURATION:g} s runs, median of {REPEAT}; tightenings "
          f"(frequency pu, ROCOF pu/s) of the limits ({lfc.RelaySettings().F:.3g}, "
          f"{lfc.RelaySettings().rocof_limit:.3g})")
    print("| grid | build | samples / rows | load tightening | between samples | "
          "per call | per-area certified, per call | contract: box, rate | contract: design | "
          "contract: per call (batch) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n in (2, 4, 6, 10):
        row(f"ring of {n}" if n > 2 else "two-area", ring(n))
    for T in (10.0, 30.0):
        row(f"two-area, T = {T:g} pu", MultiAreaParams.two_area(T=T))


if __name__ == "__main__":
    rows_main() if sys.argv[1:] == ["--rows"] else main()
