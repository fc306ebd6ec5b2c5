"""``python -m lfc``: the command line (:mod:`lfc.repro.cli`)."""

import os
import signal
import sys

from lfc.repro.cli import INTERRUPTED, main


def _terminated(signum, frame):
    """SIGTERM (a CI job cancelled, ``kill``) stops everything as Ctrl-C does."""
    raise KeyboardInterrupt


signal.signal(signal.SIGTERM, _terminated)
code = main()
if code == INTERRUPTED:
    # Ctrl-C: the kernels and workers are stopped (cli.main); a papermill thread
    # may still wait on its dead kernel's socket, and joining it would hang the
    # exit, so leave at once (every file is written atomically: nothing partial).
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
sys.exit(code)
