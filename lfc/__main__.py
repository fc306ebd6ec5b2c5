"""``python -m lfc``: the command line (:mod:`lfc.repro.cli`)."""

import os
import signal
import sys

from lfc.repro.cli import INTERRUPTED, main


_MAIN = os.getpid()


def _terminated(signum, frame):
    """SIGTERM (a CI job cancelled, ``kill``) stops everything as Ctrl-C does; a
    forked worker (which inherits this handler) is terminated as by default."""
    if os.getpid() != _MAIN:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        os.kill(os.getpid(), signal.SIGTERM)
        return
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
