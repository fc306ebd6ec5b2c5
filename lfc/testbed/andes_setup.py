"""Getting ANDES ready: its one-off code generation and quiet logging."""

from __future__ import annotations

import contextlib
import logging
import sys
from collections.abc import Iterator
from pathlib import Path

_CONFIGURED = False
LOAD_WARNINGS: dict[str, list[str]] = {}   # per case: ANDES' warnings (quiet_load)


def prepare_andes() -> None:
    """Make ANDES usable without side effects in timed or parallel code.

    ANDES generates numerical code for its models on first use (≈ 10 s, into
    ``~/.andes/pycode``; nothing is downloaded).  Do it here, once, with a
    message, instead of inside the first simulation; and route ANDES' log to
    warnings only, without the DEBUG log file it otherwise writes to the temp
    folder.  Safe to call repeatedly.
    """
    global _CONFIGURED
    if _CONFIGURED:
        return
    import andes
    from andes.utils.paths import get_pycode_path

    andes.config_logger(stream_level=logging.WARNING, file=False)
    # config_logger leaves the logger itself at DEBUG: every debug call in ANDES'
    # step loop then builds a record the handler drops (about 5 % of a run's time)
    logging.getLogger("andes").setLevel(logging.WARNING)
    if not (Path(get_pycode_path()) / "__init__.py").exists():
        print("lfc.testbed: generating ANDES' model code once (about 10 s) ...",
              file=sys.stderr, flush=True)
        andes.prepare(quick=True)
    _CONFIGURED = True


@contextlib.contextmanager
def quiet_load(case: str) -> Iterator[None]:
    """Collect ANDES' warnings while case ``case`` is loaded, set up or initialized
    (parameters it corrected, values outside its typical ranges: the IEEE 39-bus
    case gives about 170 lines per run) instead of printing them: the first time
    in a process each ``case`` prints one summary line to stderr, and
    ``LOAD_WARNINGS[case]`` keeps the messages."""
    logger = logging.getLogger("andes")
    messages: list[str] = []

    class Collect(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            messages.append(record.getMessage())

    handlers, collect = logger.handlers[:], Collect(logging.WARNING)
    for h in handlers:
        logger.removeHandler(h)
    logger.addHandler(collect)
    try:
        yield
    finally:
        logger.removeHandler(collect)
        for h in handlers:
            logger.addHandler(h)
        if messages and case not in LOAD_WARNINGS:
            print(f"ANDES: {len(messages)} warning(s) in {case} (parameters it corrected "
                  f"or found atypical; lfc.testbed.andes_setup.LOAD_WARNINGS[{case!r}] lists "
                  f"them)", file=sys.stderr, flush=True)
        if messages:
            LOAD_WARNINGS[case] = messages
