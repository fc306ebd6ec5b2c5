"""Compiling the engine's two loops into numba's on-disk cache, in parallel.

The engine's loops — :func:`lfc.engine.run_kernel`, the scalar reference, and
:func:`lfc.lanes.run_lanes` — are compiled once per change of the compiled
sources (about a minute of CPU on 2 cores: ``bench/records/compile.md``); then every
process loads them from the cache (:mod:`lfc._jit`) in a fraction of a second.  But
a process that starts while the cache is cold compiles its own copy: parallel work
started on a cold cache (the test suite's workers, ``reproduce``'s kernels) would
compile the same loops once per process.  :func:`compile_kernels` compiles each loop
once, in its own process, before such work starts; :func:`start_compiling` does it in
the background while the caller goes on (the test suite collects meanwhile).

How long the last compilation took is kept in ``$LFC_CACHE_DIR/timings.json``
(:func:`lfc._files.recorded_seconds`): the progress line's estimate.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from multiprocessing import get_context

LOOPS = ("scalar", "lanes")
#: s: the estimate before any compilation was recorded (bench/records/compile.md)
FIRST_ESTIMATE = 60.0


class Compiling:
    """Both loops compiling in the background; :meth:`result` waits for them (and
    raises what a compilation raised)."""

    def __init__(self, pool: ProcessPoolExecutor | None, futures: list[Future],
                 started: float) -> None:
        self._pool, self._futures, self._started = pool, futures, started
        #: whether anything is compiled (False: both loops were in the cache)
        self.compiled = pool is not None

    def result(self) -> None:
        if self._pool is None:
            return
        try:
            for future in self._futures:
                future.result()
        finally:
            self._pool.shutdown()
            self._pool = None
        from lfc._files import record_seconds
        record_seconds("compile", time.monotonic() - self._started)


def _cached() -> bool:
    from lfc.engine import run_kernel
    from lfc.lanes import run_lanes
    return all(_in_cache(loop) for loop in (run_kernel, run_lanes))


def start_compiling(say: Callable[[str], None] | None = None) -> Compiling:
    """Start compiling both loops, each in a fresh process, both at once, and return
    at once; nothing when both are in the cache already.  ``say`` (default: a line on
    stderr) hears what starts, with the estimate."""
    if _cached():
        return Compiling(None, [], 0.0)
    from lfc._files import recorded_seconds
    estimate = recorded_seconds("compile") or FIRST_ESTIMATE
    (say or _stderr)(f"compiling the engine's 2 loops into numba's cache, once per change "
                     f"of the compiled code (about {estimate:.0f} s)")
    pool = ProcessPoolExecutor(len(LOOPS), mp_context=get_context("spawn"))
    return Compiling(pool, [pool.submit(compile_loop, loop) for loop in LOOPS],
                     time.monotonic())


def compile_kernels(say: Callable[[str], None] | None = None) -> bool:
    """Compile both loops (:func:`start_compiling`) and wait for them; nothing when
    both are in the cache already (a rerun of ``reproduce`` pays no start-up).
    Whether anything was compiled."""
    pending = start_compiling(say)
    pending.result()
    return pending.compiled


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _in_cache(dispatcher) -> bool:
    """Whether numba's on-disk index holds machine code of ``dispatcher`` for the
    current sources (its stamp, :mod:`lfc._jit`); read through numba's private
    cache object (numba is pinned in ``environment.txt``), so any failure to
    read it counts as not cached."""
    try:
        return bool(dispatcher._cache._cache_file._load_index())
    except Exception:       # noqa: BLE001 - an unreadable cache is a cold one
        return False


def compile_loop(loop: str) -> None:
    """Compile one loop (``"scalar"`` or ``"lanes"``) by running a 0.1 s scenario
    with the certified filter through it."""
    import pandas as pd

    from lfc import LFCParams, simulate_many
    if loop not in LOOPS:
        raise ValueError(f"loop must be one of {LOOPS}, got {loop!r}")
    row = {"waveform": "sinusoid", "channel": "pc", "amplitude": 0.1, "freq_hz": 0.5,
           "start": 0.0, "alpha": 20.0, "Ts": 0.25, "method": "certified"}
    simulate_many(LFCParams(), pd.DataFrame([row]), duration=0.1, progress=False,
                  lanes=loop == "lanes")
