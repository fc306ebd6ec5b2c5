"""Files the package writes and later trusts: atomic writes, a lock for a folder
two runs may fill at once, and the digest of the code that produced them (a file
written by other code never matches)."""

from __future__ import annotations

import contextlib
import fcntl
import functools
import hashlib
import os
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path


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
    with open(folder / ".lock", "w") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


@functools.lru_cache(maxsize=None)
def code_digest(*packages: str) -> str:
    """SHA-256 of the package version and the core's source (``lfc/*.py``,
    ``lfc/filters/*.py``) plus ``lfc/<package>/*.py`` for each of ``packages``
    (e.g. ``"testbed"``; ``"*"``: every source file of the package): what stored
    results depend on besides their inputs."""
    from lfc import __version__
    root = Path(__file__).resolve().parent
    digest = hashlib.sha256(__version__.encode())
    paths = (sorted(root.rglob("*.py")) if "*" in packages else
             [p for folder in ("", "filters", *packages)
              for p in sorted((root / folder).glob("*.py"))])
    for path in paths:
        digest.update(path.relative_to(root).as_posix().encode() + path.read_bytes())
    return digest.hexdigest()
