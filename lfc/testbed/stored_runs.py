"""ANDES runs kept on disk, read back by a later scenario that would run the same.

A grid run on ANDES is a function of its plant-side inputs (the case, loads,
relays, times) and of the commands its generator sides return at every control
sample (:attr:`lfc.testbed.loop.AndesLoop.samples`).  A finished run is stored
under a key of every argument of its :func:`~lfc.testbed.grids.simulate_andes_grid`
call but its ``filters`` (:func:`scenario_keys`) and of the code that turns commands
into the plant's record (:func:`plant_digest`: the ANDES adapter, the grid cases, the
relays, the load signals, and the versions of ANDES and the numerical packages under
it).  A later call with the same key replays each stored run's samples through its
own generator sides, and where they return the same commands, bit for bit, at every
sample, its result is that run with its own generator sides' records: equal to
running it, without ANDES.  A call whose filters act differently runs, and its run is
stored beside the others.  So an edit of a filter, the engine or a notebook never
makes a stored run stale; an edit of the plant side makes every one.

Two places are searched, in this order:

* ``$LFC_CACHE_DIR/andes-runs/`` (:func:`lfc._files.cache_folder`), this machine's
  runs, per BLAS kernel (``OPENBLAS_CORETYPE``): at most ``LIMIT`` bytes, the oldest
  removed first, each file with its SHA-256 (a damaged one is run again, with a
  warning);
* the recordings committed with the package (``lfc/testbed/recordings/``, ``RECORDINGS``):
  the runs the test suite's default tier and the chapters replay, recorded on one
  machine, read on every machine and kernel (as the committed fits are).  A run
  is written there, too, when ``$LFC_ANDES_RECORD`` is ``write``
  (:func:`recording`).  ``tests/test_stored_runs.py`` checks that every recording is
  of the plant side as it is now; the exhaustive tier, that ANDES given a
  recording's commands computes its record.

``LFC_ANDES_RUNS=off`` in the environment turns both off (every call runs ANDES);
``LFC_ANDES_RECORDINGS=off`` the recordings alone.
The files are pickles: keep ``$LFC_CACHE_DIR`` a folder only you can write to.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import io
import lzma
import os
import pickle
import struct
import sys
import types
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

from lfc._files import cache_folder, pickled, prune, read_stored, unpickled, write_stored

#: bytes: the most the folder keeps (the oldest files are removed first); a
#: 20 s run of a two-area grid at 5 ms is about 0.5 MB, of 120 s 3 MB
LIMIT = 512 * 2**20

#: the environment variable that turns the store off (``off``)
SWITCH = "LFC_ANDES_RUNS"
#: the environment variable that writes every run ANDES computes into ``RECORDINGS``
RECORD = "LFC_ANDES_RECORD"
#: the environment variable that leaves the committed recordings unread (``off``)
READ_RECORDINGS = "LFC_ANDES_RECORDINGS"
#: the committed recordings
RECORDINGS = Path(__file__).resolve().parent / "recordings"
_MAGIC = b"lfc-andes-recording 2\n"

#: the modules whose functions and classes a key may name: their code is covered
#: by the key (the package's sources, the installed numerical packages)
_TRUSTED = ("lfc", "numpy", "pandas", "builtins", "copyreg", "collections", "_codecs")

_PACKAGE = Path(__file__).resolve().parents[1]
#: per kind of plant, the code that turns a run's commands into its record: files of the
#: package (the ANDES adapter, the relays and the load signals, the compiled helpers they
#: use) and definitions of other modules (``module:name``: the case and its builder, the
#: plant, its run, the record, the microgrid's over-current relay), each with every
#: top-level definition of its module it names (:func:`source_digest`); ANDES' own code
#: is keyed by its version (``PLANT_PACKAGES``)
PLANT_CODE = {
    "grid": ("_jit.py", "relays.py", "signals.py", "testbed/loop.py", "lfc.engine:sample_signal",
             "lfc.testbed.grids:GridCase", "lfc.testbed.grids:build_grid",
             "lfc.testbed.grids:GridPlant", "lfc.testbed.grids:_run",
             "lfc.testbed.grids:_Shared"),
    "microgrid": ("_jit.py", "relays.py", "signals.py", "testbed/loop.py",
                  "lfc.engine:sample_signal", "lfc.testbed.microgrid:MicrogridCase",
                  "lfc.testbed.microgrid:build_system", "lfc.testbed.microgrid:MicrogridPlant",
                  "lfc.testbed.microgrid:_run", "lfc.testbed.microgrid:MicrogridRun",
                  "lfc.testbed.microgrid:OvercurrentRelay",
                  "lfc.testbed.microgrid:phase_a_current"),
}
#: the installed packages a run depends on
PLANT_PACKAGES = ("andes", "kvxopt", "numba", "numpy", "scipy", "sympy")


def same_float(a: float, b: float) -> bool:
    """``a`` and ``b`` are the same float, bit for bit (0.0 is not -0.0): a replayed
    command equals the recorded one."""
    return struct.pack("<d", a) == struct.pack("<d", b)


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


def recording() -> bool:
    """Whether a run ANDES computes is also written to ``RECORDINGS``
    (``$LFC_ANDES_RECORD`` is ``write``; unset: no).

    Raises
    ------
    ValueError
        For any other value.
    """
    value = os.environ.get(RECORD, "").strip().lower()
    if value not in ("", "write"):
        raise ValueError(f"{RECORD} must be 'write' (or unset), got {os.environ[RECORD]!r}")
    return value == "write"


def recordings_read() -> bool:
    """Whether the committed recordings are read (``$LFC_ANDES_RECORDINGS`` unset or
    ``on``; ``off``: not, as when recording)."""
    value = os.environ.get(READ_RECORDINGS, "").strip().lower()
    if value not in ("", "on", "off"):
        raise ValueError(f"{READ_RECORDINGS} must be 'on' or 'off' (or unset: on), got "
                         f"{os.environ[READ_RECORDINGS]!r}")
    return value != "off" and not recording()


def plant_digest(root: Path = _PACKAGE, kind: str = "grid") -> str:
    """SHA-256 of the plant side of ``kind`` (``"grid"`` or ``"microgrid"``): the code
    ``PLANT_CODE[kind]`` names under ``root`` (the package: :func:`source_digest`), the
    versions of ``PLANT_PACKAGES`` and Python's."""
    if kind not in PLANT_CODE:
        raise ValueError(f"kind must be one of {tuple(PLANT_CODE)}, got {kind!r}")
    if root == _PACKAGE:
        return _package_digest(kind)
    return _plant_digest(str(root), kind)


@functools.lru_cache(maxsize=None)
def _package_digest(kind: str) -> str:
    """:func:`plant_digest` of the package itself, computed once per process."""
    return _plant_digest(str(_PACKAGE), kind)


def _plant_digest(root: str, kind: str) -> str:
    digest = hashlib.sha256(f"python {sys.version_info[:2]}".encode())
    code = PLANT_CODE[kind]
    digest.update(source_digest(Path(root), tuple(c for c in code if ":" not in c),
                                tuple(c for c in code if ":" in c)).encode())
    for package in PLANT_PACKAGES:
        try:
            digest.update(f"{package} {metadata.version(package)}".encode())
        except metadata.PackageNotFoundError:
            digest.update(f"{package} absent".encode())
    return digest.hexdigest()


def source_digest(root: Path, files: tuple[str, ...], functions: tuple[str, ...] = ()) -> str:
    """SHA-256 of the code of the files ``files`` under ``root`` (the package) and of
    ``functions`` (``module:name``, a top-level function, class or assignment of the
    package) with every top-level definition of the same module they name, and those
    name, and so on: of their syntax trees without docstrings (an edit of a comment or a
    docstring leaves it as it is, an edit of the code changes it)."""
    digest = hashlib.sha256()
    for name in files:
        digest.update(name.encode() + _code(ast.parse((root / name).read_text())).encode())
    for name in functions:
        module, function = name.split(":")
        path = root / (module.split(".", 1)[1].replace(".", "/") + ".py")
        for used, node in _definitions(path, function):
            digest.update(f"{module}:{used}".encode() + _code(node).encode())
    return digest.hexdigest()


def _definitions(path: Path, name: str) -> list[tuple[str, ast.AST]]:
    """The top-level function, class or assignment ``name`` of the file ``path`` and
    every top-level definition it names, directly or through another, by name."""
    tops: dict[str, ast.AST] = {}
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            tops[node.name] = node
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            for target in node.targets if isinstance(node, ast.Assign) else [node.target]:
                if isinstance(target, ast.Name):
                    tops[target.id] = node
    if name not in tops:
        raise ValueError(f"{path} defines no function, class or assignment {name!r}")
    found, todo = {}, [name]
    while todo:
        used = todo.pop()
        if used in found:
            continue
        found[used] = tops[used]
        todo += [n.id for n in ast.walk(tops[used])
                 if isinstance(n, ast.Name) and n.id in tops and n.id not in found]
    return sorted(found.items(), key=lambda item: item[0])


def _code(tree: ast.AST) -> str:
    """``tree`` dumped without its docstrings (comments are not in a syntax tree)."""
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                and body and isinstance(body[0], ast.Expr)
                and isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str)):
            node.body = body[1:] or [ast.Pass()]
    return ast.dump(tree)


def scenario_keys(call: dict[str, Any], kind: str = "grid") -> tuple[bytes | None, str | None]:
    """A call's two keys, from one pickle of its arguments but ``filters``, on a plant
    of ``kind`` (:func:`plant_digest`).

    Returns
    -------
    share : bytes or None
        The pickle: calls of one process with equal ones differ in their filters
        alone, and share a run (:func:`~lfc.testbed.grids.simulate_andes_grid_table`).
        None for a call that shares with none: one over a ``network`` (its link has
        a state of its own), or one whose arguments do not pickle.
    store : str or None
        The key its runs are stored under: the pickle with :func:`plant_digest`.
        None where ``share`` is, when the store is off (:func:`enabled`) and nothing is
        being recorded (:func:`recording`), or when the pickle names a function or
        class from outside the package, numpy and pandas (a notebook's own signal: its
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
    covered = (on or recording()) and not pickler.outside
    return share, (_key(share, kind) if covered else None)


def _key(share: bytes, kind: str) -> str:
    prefix = b"andes-run" if kind == "grid" else f"andes-run {kind}".encode()
    return hashlib.sha256(prefix + share + plant_digest(kind=kind).encode()).hexdigest()


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


def _machine_folder() -> Path:
    """This machine's store, per BLAS kernel (one kernel's runs differ from
    another's in the last bits)."""
    kernel = os.environ.get("OPENBLAS_CORETYPE", "").strip() or "default"
    return cache_folder() / "andes-runs" / kernel


def stored(key: str) -> Iterator[Any]:
    """Every run stored under ``key``, this machine's oldest first, then the
    recordings', each read when it is asked for (a damaged file is left out, with
    a warning); none while recording (every run is computed, to be recorded)."""
    if recording():
        return
    for path in sorted(_machine_folder().glob(f"{key}-*.json"), key=_mtime):
        run = read_stored(path, unpickled)
        if run is not None:
            yield run
    if not recordings_read():
        return
    for path in sorted(RECORDINGS.glob(f"{key}-*.run")):
        try:
            yield read_recording(path).run
        except (OSError, ValueError, lzma.LZMAError, pickle.UnpicklingError, EOFError,
                AttributeError, ImportError) as err:
            warnings.warn(f"{err}; running ANDES instead", RuntimeWarning, stacklevel=2)


def store(key: str, run: Any, commands: bytes, share: bytes, about: dict,
          kind: str = "grid") -> None:
    """Keep ``run`` under ``key``, named by its ``commands`` (the bytes of every
    command it applied): a run with the same key and commands is the same run.
    With ``$LFC_ANDES_RECORD=write``, also as a recording (``share``: the call's
    pickle, kept in it; ``about``: its ``case`` and ``duration``, s, for its header)."""
    name = f"{key}-{hashlib.sha256(commands).hexdigest()[:16]}"
    folder = _machine_folder()
    write_stored(folder / f"{name}.json", run, pickled)
    prune(folder, LIMIT)
    if recording():
        write_recording(RECORDINGS / f"{name}.run",
                        Recording(plant_digest(kind=kind), share, run, machine(), kind),
                        about)


@dataclass(frozen=True)
class Recording:
    """A committed run: the plant side's digest it was recorded with, the call's
    pickle (its arguments but its filters), the run (``grid_plant._Shared``) and the
    machine that computed it (:func:`machine`)."""

    plant: str
    call: bytes
    run: Any
    machine: str
    kind: str = "grid"


def machine() -> str:
    """What decides the last bits of a run: the CPU numba compiles for (name and
    features) and the versions of numpy, scipy, numba and ANDES."""
    import llvmlite.binding as llvm

    def installed(name: str) -> str:
        try:
            return metadata.version(name)
        except metadata.PackageNotFoundError:
            return "-"

    features = hashlib.sha1(llvm.get_host_cpu_features().flatten().encode()).hexdigest()[:12]
    libs = " ".join(f"{n}={installed(n)}" for n in ("numpy", "scipy", "numba", "andes"))
    return f"{llvm.get_host_cpu_name()} {features} {libs}"


def write_recording(path: Path, rec: Recording, about: dict) -> None:
    """Write ``rec`` to ``path``: a header line, a line of JSON (its kind of plant and
    ``about``: the case and the run's duration, s: :func:`recording_header`), the
    SHA-256 of the rest, then the pickle compressed with LZMA (about half the size of
    the raw trace)."""
    import json

    from lfc._files import replace_atomic
    head = json.dumps({"kind": rec.kind, **about}, sort_keys=True).encode()
    body = lzma.compress(pickle.dumps(rec, protocol=5), preset=9)
    path.parent.mkdir(parents=True, exist_ok=True)
    replace_atomic(path, lambda tmp: tmp.write_bytes(
        _MAGIC + head + b"\n" + hashlib.sha256(head + body).hexdigest().encode() + b"\n"
        + body))


def recording_header(path: Path) -> dict:
    """A recording's kind of plant, case and duration (s), read without its body."""
    import json
    with open(path, "rb") as f:
        if f.readline() != _MAGIC:
            raise ValueError(f"{path} is not a recording")
        return json.loads(f.readline())


def read_recording(path: Path) -> Recording:
    """The recording at ``path``.

    Raises
    ------
    ValueError
        If the file is not a recording or is damaged (its SHA-256): a committed
        file is never read back wrong.
    """
    data = path.read_bytes()
    magic, _, rest = data.partition(b"\n")
    head, _, rest = rest.partition(b"\n")
    digest, _, body = rest.partition(b"\n")
    if magic + b"\n" != _MAGIC or hashlib.sha256(head + body).hexdigest().encode() != digest:
        raise ValueError(f"damaged recording {path} (its header or SHA-256); write it "
                         f"again: LFC_ANDES_RECORD=write (docs/testbed.md)")
    rec = pickle.loads(lzma.decompress(body))   # checked: the committed bytes
    if not isinstance(rec, Recording):
        raise ValueError(f"{path} holds no recording")
    return rec


def recordings() -> list[Path]:
    """The committed recordings."""
    return sorted(RECORDINGS.glob("*.run"))


def _mtime(path: Path) -> float:
    try:
        return path.stat().st_mtime
    except OSError:                 # another process removed it meanwhile
        return 0.0
