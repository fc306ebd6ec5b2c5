"""ANDES runs kept on disk, read back by a later scenario that would run the same.

A grid run on ANDES is a function of its plant-side inputs (the case, loads,
relays, times) and of the commands its generator sides return at every control
sample (:attr:`lfc.testbed.loop.AndesLoop.samples`).  A finished run is stored
under a key of every argument of its :func:`~lfc.testbed.grid_plant.simulate_andes_grid`
call but its ``filters`` (:func:`scenario_keys`); a later call with the same key
replays each stored run's samples through its own generator sides, and where
they return the same commands, bit for bit, at every sample, its result is
that run with its own generator sides' records: equal to running it, without
ANDES.  A call whose filters act differently runs, and its run is stored beside
the others.

Where: ``$LFC_CACHE_DIR/andes-runs/`` (:func:`lfc._files.cache_folder`), at most
``LIMIT`` bytes, the oldest removed first; each file with its SHA-256 (a damaged
one is run again, with a warning).  The key covers the sources of the package,
the environment and ``OPENBLAS_CORETYPE`` (:func:`lfc._files.content_key`), so
a run of other code is never found.  ``LFC_ANDES_RUNS=off`` in the environment
turns the store off (every call runs ANDES).  The files are pickles: keep
``$LFC_CACHE_DIR`` a folder only you can write to.
"""

from __future__ import annotations

import hashlib
import io
import os
import pickle
import types
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from lfc._files import (cache_folder, content_key, pickled, prune, read_stored, unpickled,
                        write_stored)

#: bytes: the most the folder keeps (the oldest files are removed first); a
#: 20 s run of a two-area grid at 5 ms is about 0.5 MB, of 120 s 3 MB
LIMIT = 512 * 2**20

#: the environment variable that turns the store off (``off``)
SWITCH = "LFC_ANDES_RUNS"

#: the modules whose functions and classes a key may name: their code is covered
#: by the key (the package's sources, the installed numerical packages)
_TRUSTED = ("lfc", "numpy", "pandas", "builtins", "copyreg", "collections", "_codecs")


def enabled() -> bool:
    """The store is on, unless ``$LFC_ANDES_RUNS`` is ``off`` (``on`` or unset: on).

    Raises
    ------
    ValueError
        For any other value (a typo would otherwise leave it on, unnoticed).
    """
    value = os.environ.get(SWITCH, "").strip().lower()
    if value not in ("", "on", "off"):
        raise ValueError(f"{SWITCH} must be 'on' or 'off' (or unset: on), got "
                         f"{os.environ[SWITCH]!r}")
    return value != "off"


def scenario_keys(call: dict[str, Any]) -> tuple[bytes | None, str | None]:
    """A call's two keys, from one pickle of its arguments but ``filters``.

    Returns
    -------
    share : bytes or None
        The pickle: calls of one process with equal ones differ in their filters
        alone, and share a run (:func:`~lfc.testbed.grid_plant.simulate_andes_grid_table`).
        None for a call that shares with none: one over a ``network`` (its link
        has a state of its own), or one whose arguments do not pickle.
    store : str or None
        The key its runs are stored under: the pickle with
        :func:`lfc._files.content_key`.  None where ``share`` is, when the store
        is off (:func:`enabled`), or when the pickle names a function or class
        from outside the package, numpy and pandas (a notebook's own signal: its
        code is not in the key, and an edited one would find the old run).
    """
    on = enabled()                      # a typo in the switch is refused first
    if call.get("network") is not None:
        return None, None
    buffer = io.BytesIO()
    pickler = _KeyPickler(buffer)
    try:
        pickler.dump({k: v for k, v in sorted(call.items()) if k != "filters"})
    except (pickle.PicklingError, TypeError, AttributeError):
        return None, None
    share = buffer.getvalue()
    covered = on and not pickler.outside
    return share, (content_key("andes-run", share) if covered else None)


class _KeyPickler(pickle.Pickler):
    """A pickler that notes (in ``outside``) whether it named a function or class
    from outside ``_TRUSTED``."""

    def __init__(self, file: io.BytesIO) -> None:
        super().__init__(file, protocol=5)
        self.outside = False

    def reducer_override(self, obj: object) -> object:
        if isinstance(obj, (type, types.FunctionType, types.BuiltinFunctionType,
                            types.MethodType)):
            module = getattr(obj, "__module__", None) or ""
            self.outside |= module.split(".")[0] not in _TRUSTED
        return NotImplemented


def stored(key: str) -> Iterator[Any]:
    """Every run stored under ``key``, oldest first, each read when it is asked
    for (a damaged file is left out, with a warning)."""
    folder = cache_folder() / "andes-runs"
    for path in sorted(folder.glob(f"{key}-*.json"), key=_mtime):
        run = read_stored(path, unpickled)
        if run is not None:
            yield run


def store(key: str, run: Any, commands: bytes) -> None:
    """Keep ``run`` under ``key``, named by its ``commands`` (the bytes of every
    command it applied): a run with the same key and commands is the same run."""
    folder = cache_folder() / "andes-runs"
    name = hashlib.sha256(commands).hexdigest()[:16]
    write_stored(folder / f"{key}-{name}.json", run, pickled)
    prune(folder, LIMIT)


def _mtime(path: Path) -> float:
    try:
        return path.stat().st_mtime
    except OSError:                 # another process removed it meanwhile
        return 0.0
