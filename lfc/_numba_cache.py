"""A damaged numba cache file of this package is compiled again, not fatal.

numba reads its on-disk cache (``__pycache__/*.nbi`` index, ``*.nbc`` machine code)
with :mod:`pickle` and lets an ``UnpicklingError`` or ``EOFError`` out: one file cut
short (a full disk, a killed process, a copy interrupted) made every later call of
the function fail.  :func:`install` makes numba's cache file reader treat such a file
of this package as absent, with a ``RuntimeWarning`` naming it: the function is
compiled again and the file rewritten.  Files of other packages are left to numba.
:mod:`lfc.engine`, through which every compiled run goes, installs it.
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


def _guard_index(load_index):
    @functools.wraps(load_index)
    def guarded(self):
        try:
            return load_index(self)
        except DAMAGED as err:
            if not _ours(self):
                raise
            _damaged(self, err)
            return {}                   # as numba treats a missing index: rewritten on save
    guarded.lfc_guarded = True
    return guarded


def _guard_load(load):
    @functools.wraps(load)
    def guarded(self, key):
        try:
            return load(self, key)
        except DAMAGED as err:
            if not _ours(self):
                raise
            _damaged(self, err)
            return None                 # a miss: compiled, and the data file overwritten
    guarded.lfc_guarded = True
    return guarded


def install() -> None:
    """Guard numba's cache file reader (once per process; idempotent)."""
    cls = caching.IndexDataCacheFile
    if not getattr(cls._load_index, "lfc_guarded", False):
        cls._load_index = _guard_index(cls._load_index)
    if not getattr(cls.load, "lfc_guarded", False):
        cls.load = _guard_load(cls.load)
