"""Fail when a tier's CPU time exceeds its budget: ``python .ci/budget.py REPORT BUDGET``.

REPORT is the JSON the test suite writes where ``LFC_TIER_REPORT`` points
(``tests/conftest.py``: the tier, its wall and CPU seconds); BUDGET a file whose first
line that is not a comment is the budget in CPU seconds."""

import json
import sys
from pathlib import Path

report = json.loads(Path(sys.argv[1]).read_text())
budget = float(next(line for line in Path(sys.argv[2]).read_text().splitlines()
                    if line.strip() and not line.lstrip().startswith("#")))
verdict = "within" if report["cpu"] <= budget else "OVER"
print(f"the {report['tier']} tier: {report['cpu']:.0f} s of CPU, {report['wall']:.0f} s wall; "
      f"{verdict} its budget of {budget:.0f} s of CPU ({sys.argv[2]})")
sys.exit(0 if report["cpu"] <= budget else 1)
