"""Files the package writes and later trusts: atomic writes, a lock for a folder
two runs may fill at once, and the digest of the code that produced them (a file
written by other code never matches)."""

from __future__ import annotations

import base64
import contextlib
import fcntl
import functools
import hashlib
import json
import os
import pickle
import sys
import time
import uuid
import warnings
import zlib
from collections.abc import Callable, Iterator
from importlib import metadata
from pathlib import Path
from typing import Any


#: the environment variable naming the file a notebook run lists what it wrote in
WRITTEN_ENV = "LFC_WRITTEN"


def note_written(path: Path | str) -> None:
    """Add ``path``'s name to the list in the file ``$LFC_WRITTEN`` names (the
    runner's record of what one notebook run wrote into the figures folder, which
    concurrent runs share); nothing without it."""
    log = os.environ.get(WRITTEN_ENV)
    if log:
        with open(log, "a", encoding="utf-8") as f:
            f.write(Path(path).name + "\n")


def replace_atomic(path: Path, write: Callable[[Path], None]) -> None:
    """Call ``write`` on a unique temporary file, then rename it onto ``path``: a
    reader never sees half a file, and concurrent writers never share a
    temporary name."""
    tmp = path.with_name(f"{path.name}.{os.getpid()}.{uuid.uuid4().hex}.tmp")
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically (:func:`replace_atomic`)."""
    replace_atomic(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


@contextlib.contextmanager
def folder_lock(folder: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``folder`` (a ``.lock`` file in it; created if
    missing) while the block runs: a second run that wants the same folder waits,
    then finds the first one's results.  Released when the process ends, however."""
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / ".lock", "w") as handle, _held(handle):
        yield


@contextlib.contextmanager
def _held(handle) -> Iterator[None]:
    """An exclusive ``flock`` on the open file ``handle`` while the block runs."""
    fcntl.flock(handle, fcntl.LOCK_EX)
    try:
        yield
    finally:
        fcntl.flock(handle, fcntl.LOCK_UN)


@functools.lru_cache(maxsize=None)
def code_digest(*packages: str) -> str:
    """SHA-256 of the package version and the core's source (``lfc/*.py``,
    ``lfc/filters/*.py``) plus ``lfc/<package>/*.py`` and the data committed in
    its subfolders (``lfc/testbed/fitted/*.json``) for each of ``packages`` (e.g.
    ``"testbed"``; ``"*"``: every source and data file of the package): what
    stored results depend on besides their inputs."""
    from lfc import __version__
    root = Path(__file__).resolve().parent
    digest = hashlib.sha256(__version__.encode())
    for path in digested_files(*packages):
        digest.update(path.relative_to(root).as_posix().encode() + path.read_bytes())
    return digest.hexdigest()


def digested_files(*packages: str) -> list[Path]:
    """The files :func:`code_digest` hashes for ``packages``, in its order."""
    root = Path(__file__).resolve().parent
    if "*" in packages:
        return sorted(p for p in root.rglob("*") if p.suffix in (".py", ".json"))
    return [p for folder in ("", "filters", *packages)
            for pattern in ("*.py", "*/*.json") for p in sorted((root / folder).glob(pattern))]


# -- stored results: a JSON payload and its SHA-256, named by a key of their inputs -----
def content_key(*parts: object) -> str:
    """SHA-256 of ``parts`` (bytes as they are, anything else as sorted JSON) and
    of what every result here depends on besides its inputs: every source file of
    the package (:func:`code_digest`), the pinned environment (``environment.txt``)
    and the numerical packages installed (:func:`installed`; a machine may hold
    others than the pins), the Python version and the BLAS kernel asked for
    (``OPENBLAS_CORETYPE``)."""
    digest = hashlib.sha256()
    for part in parts:
        digest.update(part if isinstance(part, bytes)
                      else json.dumps(part, sort_keys=True, default=str).encode())
    digest.update(code_digest("*").encode())
    env = Path(__file__).resolve().parents[1] / "environment.txt"
    digest.update(env.read_bytes() if env.exists() else b"")
    digest.update(f"{sys.version}|{os.environ.get('OPENBLAS_CORETYPE', '')}|"
                  f"{installed()}".encode())
    return digest.hexdigest()


@functools.lru_cache(maxsize=None)
def installed() -> str:
    """The installed versions of the packages stored results are computed with."""
    versions = []
    for name in ("numpy", "scipy", "numba", "andes"):
        try:
            versions.append(f"{name} {metadata.version(name)}")
        except metadata.PackageNotFoundError:
            versions.append(f"{name} absent")
    return ", ".join(versions)


def cache_folder() -> Path:
    """Where stored results are kept: ``$LFC_CACHE_DIR``, default ``~/.cache/lfc-scc``."""
    return Path(os.environ.get("LFC_CACHE_DIR") or Path.home() / ".cache" / "lfc-scc")


#: The layout of a stored file (:func:`write_stored`).  A file of another layout (another
#: ``format``, or 0.3's: ``payload`` and ``sha256`` alone) was written by another version
#: of the package: it is stale, not damaged, and is computed again without a warning.
STORED_FORMAT = "lfc-scc stored 2"


def read_stored(path: Path, decode: Callable[[dict], Any],
                check: Callable[[Any], None] = lambda value: None) -> Any:
    """The value stored at ``path`` (:func:`write_stored`); None if absent, of
    another layout (:data:`STORED_FORMAT`: another version's file), damaged (its
    SHA-256), sealed for another request (the file name it was written under, which
    names its request: a file copied or swapped from another name is not read back)
    or not sane (``check`` raises ``ValueError``), the last three with a
    ``RuntimeWarning`` naming the file."""
    if not path.exists():
        return None
    try:
        stored = json.loads(path.read_text())
        if isinstance(stored, dict) and (stored.get("format", STORED_FORMAT) != STORED_FORMAT
                                         or set(stored) == {"payload", "sha256"}):
            return None        # another version's layout (0.3's had no "format"): stale
        payload = stored["payload"]
        if hashlib.sha256(payload.encode()).hexdigest() != stored["sha256"]:
            raise ValueError("checksum mismatch")
        sealed = json.loads(payload)
        if not isinstance(sealed, dict) or sealed.get("seal") != path.name:
            raise ValueError(f"written for another request "
                             f"({sealed.get('seal') if isinstance(sealed, dict) else None!r})")
        value = decode(sealed["value"])
        check(value)
        return value
    except (OSError, ValueError, KeyError, TypeError, AttributeError, RecursionError) as err:
        warnings.warn(f"damaged cache file {path} ({err}); computing it again", RuntimeWarning,
                      stacklevel=2)
        return None


def write_stored(path: Path, value: Any, encode: Callable[[Any], dict]) -> None:
    """Store ``encode(value)`` (JSON) sealed with ``path``'s name (which names the
    request it answers: the callers' names are keys of every input) and with its
    SHA-256, atomically; a file that cannot be written is skipped with a
    ``RuntimeWarning``."""
    payload = json.dumps({"seal": path.name, "value": encode(value)}, sort_keys=True)
    text = json.dumps({"format": STORED_FORMAT, "payload": payload,
                       "sha256": hashlib.sha256(payload.encode()).hexdigest()})
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, text)
    except OSError as err:
        warnings.warn(f"could not write cache file {path} ({err})", RuntimeWarning,
                      stacklevel=2)


def cached(path: Path, compute: Callable[[], Any], encode: Callable[[Any], dict],
           decode: Callable[[dict], Any], check: Callable[[Any], None] = lambda value: None
           ) -> Any:
    """``compute()`` read from ``path`` (:func:`read_stored`), or computed and
    stored there (:func:`write_stored`) when the file is absent, damaged or not
    sane — by one process at a time: another that wants the same file meanwhile
    waits for it and reads it.  ``path`` must name everything the value depends on (a key of its
    inputs and of the sources: :func:`code_digest`), so that a stale file is
    never found."""
    with _computing(path):       # another process computing it: wait, then read its result
        value = read_stored(path, decode, check)
        if value is None:
            value = compute()
            write_stored(path, value, encode)
    return value


def kept(path: Path, make: Callable[[], Any], after: float, limit: float) -> Any:
    """``make()`` read from ``path`` (pickled, :func:`read_stored`), or built and
    written there if building took at least ``after`` seconds (a value that cannot
    be pickled warns and is not written); then the oldest files of the folder are
    removed until it holds at most ``limit`` bytes.  Pickles: ``path``'s folder
    must be writable by its owner alone."""
    made = read_stored(path, unpickled)
    if made is None:
        start = time.perf_counter()
        made = make()
        if time.perf_counter() - start >= after:
            try:
                write_stored(path, made, pickled)
            except (pickle.PicklingError, TypeError, AttributeError) as err:
                warnings.warn(f"cannot store {type(made).__name__} ({err}); it will be built "
                              f"again in the next process", RuntimeWarning, stacklevel=4)
            prune(path.parent, limit)
    return made


def prune(folder: Path, limit: float) -> None:
    """Remove the least recently written files of ``folder`` until it holds at most
    ``limit`` bytes (files of earlier code are never read again)."""
    files = []
    for f in folder.glob("*.json"):
        with contextlib.suppress(OSError):        # another process removed it meanwhile
            stat = f.stat()
            files.append((stat.st_mtime, stat.st_size, f))
    total = 0
    for _, size, f in sorted(files, reverse=True):
        total += size
        if total > limit:
            f.unlink(missing_ok=True)


def pickled(value: object) -> dict:
    """``value`` as a JSON payload for :func:`write_stored`: pickled, compressed
    (zlib: a trace of floats shrinks by about a quarter), base64."""
    data = zlib.compress(pickle.dumps(value, protocol=5), 6)
    return {"pickle": base64.b64encode(data).decode("ascii")}


def unpickled(payload: dict) -> object:
    """The value :func:`pickled` stored (for :func:`read_stored`); ``ValueError``
    if it cannot be read back."""
    try:
        return pickle.loads(zlib.decompress(base64.b64decode(payload["pickle"])))
    except (pickle.UnpicklingError, zlib.error, EOFError, AttributeError,
            ImportError) as err:
        raise ValueError(f"cannot unpickle: {err}") from err


@contextlib.contextmanager
def _computing(path: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``<path>.lock`` while the block runs (two processes
    that want the same result compute it once); without a writable folder, no lock."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handle = open(path.with_name(path.name + ".lock"), "w")
    except OSError:
        yield
        return
    with handle, _held(handle):
        yield


# -- how long long phases took, for the next run's progress estimates ----------------------
def record_seconds(phase: str, seconds: float) -> None:
    """Keep how long ``phase`` (``"compile"``, ``"andes-codegen"``, ...) took, in
    ``$LFC_CACHE_DIR/timings.json`` (best effort: an unwritable folder keeps nothing)."""
    path = cache_folder() / "timings.json"
    with contextlib.suppress(OSError, ValueError):
        with _computing(path):
            times = json.loads(path.read_text()) if path.exists() else {}
            times[phase] = round(float(seconds), 1)
            write_atomic(path, json.dumps(times, sort_keys=True))


def recorded_seconds(phase: str) -> float | None:
    """How long ``phase`` took the last time it was recorded (s); None if never (or
    the file is damaged)."""
    try:
        value = json.loads((cache_folder() / "timings.json").read_text()).get(phase)
        return float(value) if value is not None else None
    except (OSError, ValueError, TypeError, AttributeError):
        return None
