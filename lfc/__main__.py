"""``python -m lfc``: the command line (:mod:`lfc.repro.cli`)."""

import sys

from lfc.repro.cli import main

sys.exit(main())
