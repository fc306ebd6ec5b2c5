"""A damaged numba cache file of this package is compiled again, not fatal.

numba reads its on-disk cache (``__pycache__/*.nbi`` index, ``*.nbc`` machine code)
with :mod:`pickle` and lets an ``UnpicklingError`` or ``EOFError`` out: one file cut
short (a full disk, a killed process, a copy interrupted) made every later call of
the function fail.  :func:`install` makes numba's cache file reader treat such a file
of this package as absent, with a ``RuntimeWarning`` naming it: the function is
compiled again and the file rewritten.  A file that names a class or module of this
package that no longer exists (renamed or moved since numba wrote it: its index keys
the compiled types, a kernel's named tuples among them) is stale, not damaged: a miss
without a warning.  Files of other packages are left to numba.
:mod:`lfc._jit`, through which every compiled function of the package goes, installs it.
"""

from __future__ import annotations

import functools
import pickle
import warnings
from pathlib import Path

from numba.core import caching

_PACKAGE = Path(__file__).resolve().parent
#: what a damaged pickle raises while being read
DAMAGED = (pickle.UnpicklingError, EOFError, ValueError, TypeError, AttributeError,
           IndexError, KeyError, ImportError)


def _ours(cache_file: caching.IndexDataCacheFile) -> bool:
    return Path(cache_file._index_path).resolve().is_relative_to(_PACKAGE)


def _damaged(cache_file: caching.IndexDataCacheFile, err: Exception) -> None:
    index = Path(cache_file._index_path)
    warnings.warn(f"damaged numba cache file of {index.stem} in {index.parent} "
                  f"({type(err).__name__}: {err}); compiling again", RuntimeWarning,
                  stacklevel=4)


def _stale(err: Exception) -> bool:
    """Whether unpickling failed on a name of this package that is gone (a class
    renamed, a module moved) rather than on damaged bytes."""
    if isinstance(err, ModuleNotFoundError):
        return (err.name or "").split(".")[0] == "lfc"
    return isinstance(err, AttributeError) and "on <module 'lfc" in str(err)


def _guarded(read, miss):
    """``read`` (a reader method of numba's cache file) returning ``miss()`` where a
    file of this package is damaged; numba treats that as a missing file (the
    index rewritten on save, the function compiled and its data file overwritten)."""
    @functools.wraps(read)
    def guarded(self, *args):
        try:
            return read(self, *args)
        except DAMAGED as err:
            if not _ours(self):
                raise
            if not _stale(err):
                _damaged(self, err)
            return miss()
    guarded.lfc_guarded = True
    return guarded


def install() -> None:
    """Guard numba's cache file reader (once per process; idempotent)."""
    cls = caching.IndexDataCacheFile
    # a damaged index reads as a fresh empty one (save fills it in), damaged data as none
    for name, miss in (("_load_index", dict), ("load", lambda: None)):
        if not getattr(getattr(cls, name), "lfc_guarded", False):
            setattr(cls, name, _guarded(getattr(cls, name), miss))
