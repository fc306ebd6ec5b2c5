"""The check that a run's metrics equal a row of simulate_many (one metric set)."""

import math

from lfc.result import METRIC_KEYS


def same_metrics(metrics: dict, row) -> bool:
    """``Result.metrics()`` equals a ``simulate_many`` row: the same keys, the
    same values (floats to 1e-12 relative: the loop sums the modification as it
    goes, pandas pairwise; None where the row has NaN or None: no trip)."""
    if list(metrics) != list(METRIC_KEYS):
        return False
    for key in METRIC_KEYS:
        a, b = metrics[key], row[key]
        missing_b = b is None or (isinstance(b, float) and math.isnan(b))
        if a is None or missing_b:
            if not (a is None and missing_b):
                return False
        elif isinstance(a, (bool, str)):
            if a != b:
                return False
        elif not math.isclose(a, float(b), rel_tol=1e-12, abs_tol=1e-15):
            return False
    return True
