"""The ways this package compiles a function with numba.

``jit``: compiled once, cached on disk (``__pycache__``), no GIL.  ``inline``:
the same, and inlined into its compiled callers — for the small functions the
engine calls every step, where a call's overhead would cost more than the work.
``kernel``: the engine's loop, compiled without numba's reference counting
(``_nrt=False``): it allocates nothing (its caller passes every array, including
its scratch space), so it needs none, and counting references on every array the
inlined functions touch cost two thirds of its time (measured: 28.8 against 14.1 ns
per scenario-step with the paper's filter; ``bench/bench_batch.py``).
"""

import numba as nb

jit = nb.njit(cache=True, nogil=True)
inline = nb.njit(cache=True, nogil=True, inline="always")
kernel = nb.njit(cache=True, nogil=True, _nrt=False)
