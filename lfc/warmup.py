"""Compiling the engine's two loops into numba's on-disk cache, in parallel.

The engine's loops — :func:`lfc.engine._run`, the scalar reference, and
:func:`lfc.engine._run_lanes` — take about 50 s each to compile (measured on
the 2-core machine of ``bench/README.md``), once per change of the compiled
sources; then every process loads them from the cache (:mod:`lfc._jit`) in a
fraction of a second.  But a process that starts while the cache is cold
compiles its own copy: parallel work started on a cold cache (the test suite's
workers, ``reproduce``'s kernels) compiled the same loops once per process
(measured: 10 tests of the suite took 60–170 s each that take under 1 s warm).
:func:`compile_kernels` compiles each loop once, in its own process, before
such work starts.
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

LOOPS = ("scalar", "lanes")


def compile_kernels() -> None:
    """Compile both loops, each in a fresh process, both at once; nothing when
    both are in the cache already (a rerun of ``reproduce`` pays no start-up)."""
    from lfc import engine
    if all(_in_cache(loop) for loop in (engine._run, engine._run_lanes)):
        return
    with ProcessPoolExecutor(len(LOOPS), mp_context=get_context("spawn")) as pool:
        list(pool.map(compile_loop, LOOPS))


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
