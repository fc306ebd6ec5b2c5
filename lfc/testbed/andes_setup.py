"""Getting ANDES ready: its one-off code generation and quiet logging."""

from __future__ import annotations

import logging
import sys
from pathlib import Path

_CONFIGURED = False


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
