"""The ways this package compiles a function with numba, and how it caches them.

``jit``: compiled once, cached on disk (``__pycache__``), no GIL; a compiled
caller links its machine code.  ``inline``: the same, and inlined into its
compiled callers at numba's level — for the small functions the engine calls
every step, where a call's overhead would cost more than the work.  Inlining
at numba's level types and compiles the callee again inside every caller, so a
large function called once per control period (a filter's decision,
:func:`lfc.filters.dispatch.decide`) is ``jit``: inlined there, every filter was
compiled into both of the engine's loops (bench/records/compile.md).
``kernel``: the engine's loop, compiled without numba's reference counting
(``_nrt=False``): it allocates nothing (its caller passes every array, including
its scratch space), so it needs none, and counting references on every array the
inlined functions touch would cost about half of its time.

``maxnum`` / ``minnum``: LLVM's ``maxnum`` / ``minnum`` of two floats (the larger
/ smaller; a NaN argument is ignored).  Written with Python's ``max`` / ``min``,
a running maximum over an array is not vectorized by LLVM; with these it is.

``choose(c, a, b)``: ``a`` if ``c`` else ``b`` (float64), as LLVM's ``select``, which
evaluates both.  Written ``a if c else b``, numba makes it a branch; stored where the
other value was loaded from, LLVM then stores under a mask (``vmaskmovpd``), which an
AMD Zen 3 executes several times slower than a store.  The engine's lanes
(``lfc.lanes._lane_step``) use it, and write to a second buffer.  What each of the
three saves: ``bench/records/compile.md``.

The cache.  numba keys a cached function on its own source file only, but these
functions inline each other across modules (the engine inlines the filters), so
an edit of one file would leave its callers' machine code stale.  Importing this
module registers a cache locator for this package's functions whose stamp is a
hash of every source file that names this module: the ones that compile code, and
``lfc.filters``, whose order of registration gives the compiled dispatcher's codes
(:func:`lfc.filters.dispatch.assign`).  Any edit recompiles them all
(:mod:`lfc.warmup` compiles the loops once).  It applies to functions in this package
only; so does the guard it installs against a damaged cache file (:mod:`lfc._numba_cache`).
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

import numba as nb
from llvmlite import ir
from numba.core import caching, types
from numba.extending import intrinsic

from lfc import _numba_cache

_PACKAGE = Path(__file__).resolve().parent


@functools.lru_cache(maxsize=1)
def _compiled_sources_digest() -> bytes:
    """Hash of every source file of this package that names this module (module
    docstring)."""
    digest = hashlib.sha256(nb.__version__.encode())
    for path in sorted(_PACKAGE.rglob("*.py")):
        text = path.read_bytes()
        if b"lfc._jit" in text or path == Path(__file__).resolve():
            digest.update(path.relative_to(_PACKAGE).as_posix().encode() + text)
    return digest.digest()


class _PackageCacheLocator(caching.InTreeCacheLocator):
    """numba's ``__pycache__`` locator, stamped with :func:`_compiled_sources_digest`."""

    def get_source_stamp(self):
        return _compiled_sources_digest()

    @classmethod
    def from_function(cls, py_func, py_file):
        if not Path(py_file).resolve().is_relative_to(_PACKAGE):
            return None
        return super().from_function(py_func, py_file)


if _PackageCacheLocator not in caching.CacheImpl._locator_classes:
    caching.CacheImpl._locator_classes.insert(0, _PackageCacheLocator)
_numba_cache.install()   # a damaged cache file of a compiled function: compiled again

jit = nb.njit(cache=True, nogil=True)
inline = nb.njit(cache=True, nogil=True, inline="always")
kernel = nb.njit(cache=True, nogil=True, _nrt=False)


def _float_intrinsic(name: str):
    """A numba intrinsic calling the LLVM intrinsic ``name`` on two float64s."""
    @intrinsic
    def call(typingctx, a, b):
        def codegen(context, builder, signature, args):
            double = ir.DoubleType()
            fn = builder.module.declare_intrinsic(name, [double],
                                                  ir.FunctionType(double, [double, double]))
            return builder.call(fn, args)
        return types.float64(types.float64, types.float64), codegen
    return call


maxnum = _float_intrinsic("llvm.maxnum")
minnum = _float_intrinsic("llvm.minnum")


@intrinsic
def choose(typingctx, c, a, b):
    """``a`` if ``c`` else ``b``, both evaluated: LLVM's ``select`` (module docstring)."""
    def codegen(context, builder, signature, args):
        return builder.select(args[0], args[1], args[2])
    return types.float64(types.boolean, types.float64, types.float64), codegen
