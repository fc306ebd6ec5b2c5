"""Getting ANDES ready: its one-off code generation and quiet logging."""

from __future__ import annotations

import contextlib
import logging
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

_CONFIGURED = False
LOAD_WARNINGS: dict[str, list[str]] = {}   # per "case (stage)": ANDES' warnings (quiet_load)


class _Stderr(logging.StreamHandler):
    """ANDES' stream handler (through ``tqdm.write``, which keeps progress bars
    whole), writing to ``sys.stderr`` as it is when a record comes, not as it was
    when the handler was made: ANDES' own binds the latter, so its warnings went
    to a stream that pytest or a kernel had since replaced."""

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:    # StreamHandler.__init__ sets it; always stderr
        pass

    def emit(self, record: logging.LogRecord) -> None:
        from tqdm import tqdm
        tqdm.write(self.format(record), file=self.stream)


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

    # a log_path, although no file is written: without one config_logger makes an empty
    # folder in the temp directory (get_log_dir), one per process, never removed
    andes.config_logger(stream_level=logging.WARNING, file=False,
                        log_path=tempfile.gettempdir())
    logger = logging.getLogger("andes")
    for h in logger.handlers[:]:
        if isinstance(h, logging.StreamHandler) and not isinstance(h, (logging.FileHandler,
                                                                        _Stderr)):
            mine = _Stderr()
            mine.setLevel(h.level)
            mine.setFormatter(h.formatter)
            logger.removeHandler(h)
            logger.addHandler(mine)
    # config_logger leaves the logger itself at DEBUG: every debug call in ANDES'
    # step loop then builds a record the handler drops (about 5 % of a run's time)
    logger.setLevel(logging.WARNING)
    if not (Path(get_pycode_path()) / "__init__.py").exists():
        import time

        from lfc._files import record_seconds, recorded_seconds
        last = recorded_seconds("andes-codegen")
        print("lfc.testbed: generating ANDES' model code once ("
              + (f"{last:.0f} s the last time" if last else "about 10 s")
              + ") ...", file=sys.stderr, flush=True)
        t0 = time.monotonic()
        andes.prepare(quick=True)
        record_seconds("andes-codegen", time.monotonic() - t0)
    _CONFIGURED = True


@contextlib.contextmanager
def quiet_load(case: str, stage: str) -> Iterator[None]:
    """Collect ANDES' warnings while ``case`` (its file's name without suffix,
    ``"ieee39_full"``) goes through ``stage`` (``"loading"``, ``"time-domain
    initialization"``): parameters it corrected, values outside its typical ranges
    (the IEEE 39-bus case gives about 170 lines per run), instead of printing
    them.  The first time in a process each case and stage prints one summary line
    to stderr; ``LOAD_WARNINGS["<case> (<stage>)"]`` keeps the messages."""
    key = f"{case} ({stage})"
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
        if messages and key not in LOAD_WARNINGS:
            print(f"ANDES: {len(messages)} warning(s) in {case}'s {stage} (parameters it "
                  f"corrected or found atypical; lfc.testbed.andes_setup.LOAD_WARNINGS"
                  f"[{key!r}] lists them)", file=sys.stderr, flush=True)
        if messages:
            LOAD_WARNINGS[key] = messages
