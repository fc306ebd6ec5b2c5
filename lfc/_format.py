"""How generated tables print numbers: to the digits that are stable.

A full ``reproduce`` under two OpenBLAS kernels on one machine (SkylakeX, the
default here, and ``OPENBLAS_CORETYPE=Haswell``; ``python -m lfc reproduce
--compare-blas Haswell``) moved table values in their 4th significant digit:
the IEEE 39-bus fit's D 0.07113 against 0.07115 (a weakly identified parameter)
and the linear two-area ACE attack's severity 3.042 against 3.044 (the paper's
SCC switching at its boundary thousands of times), and a count of control
samples flagged on ANDES in its 4th (1551 against 1547).  Tables print
``STABLE_DIGITS`` = 3 significant digits, never rounding a value below 1 up to 1
(a severity of 0.9996 has not reached its relay setting), and counts of 1000 or
more rounded to as many, marked ``≈``.  A value that lies on a rounding
boundary can still print differently (0.0711 against 0.0712): ``--compare-blas``
lists it.
"""

from __future__ import annotations

import math

STABLE_DIGITS = 3


def number(value: float, digits: int = STABLE_DIGITS) -> str:
    """``value`` to ``digits`` significant digits (``"—"`` for NaN; a value of
    ``10**digits`` or more as :func:`count` prints it), with as many more as keep
    a value in (0, 1) below 1 and one in (-1, 0) above -1."""
    if math.isnan(value):
        return "—"
    if abs(value) >= 10 ** digits:                  # ≈1240, not 1.24e+03
        return count(round(value), digits)
    text = f"{value:.{digits}g}"
    while 0 < abs(value) < 1 <= abs(float(text)) and digits < 17:
        digits += 1
        text = f"{value:.{digits}g}"
    return text


def count(value: int, digits: int = STABLE_DIGITS) -> str:
    """An integer: exact below ``10**digits``, else rounded to ``digits``
    significant digits and marked ``≈`` (control samples flagged on ANDES moved
    from 1551 to 1547 between two BLAS kernels: both print ``≈1550``)."""
    value = int(value)
    if abs(value) < 10 ** digits:
        return str(value)
    return f"≈{round(value, digits - len(str(abs(value))))}"
