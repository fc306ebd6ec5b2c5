"""The plant box of the robust filter: the parameters it may cover (``BOX``) and
the plants a certificate is built for (:func:`box_plants`)."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace
from numbers import Real

import numpy as np

from lfc._validate import is_sequence
from lfc.model import LFCParams

BOX = ("M", "D", "tau_g", "tau_t", "droop")  # the parameters an uncertainty box may cover


def box_plants(params: LFCParams, uncertainty: float | dict) -> list[LFCParams]:
    """The design model and the corners of the declared parameter box.

    ``uncertainty``: a relative half-width for all of ``BOX`` (0.2: each within
    ±20 %), or a dict naming some of them with ``(low, high)`` factors.
    """
    if isinstance(uncertainty, dict):
        unknown = [k for k in uncertainty if k not in BOX]
        if unknown:
            raise ValueError(f"uncertainty names unknown parameter(s) "
                             f"{', '.join(map(repr, unknown))}; choose from {BOX}")
        factors = {}
        for name, pair in uncertainty.items():
            numbers = (is_sequence(pair) and len(pair) == 2 and all(_is_real(v) for v in pair))
            low, high = (float(pair[0]), float(pair[1])) if numbers else (math.nan, math.nan)
            if not (0 < low <= 1 <= high < math.inf):
                raise ValueError(f"uncertainty[{name!r}] must be factors (low, high) with "
                                 f"0 < low <= 1 <= high, got {pair!r}")
            factors[name] = (float(low), float(high))
    else:
        if not _is_box_width(uncertainty):
            raise ValueError(f"uncertainty must be a relative half-width in [0, 1) or a dict "
                             f"of factors, got {uncertainty!r}")
        factors = {name: (1 - uncertainty, 1 + uncertainty) for name in BOX} \
            if uncertainty > 0 else {}
    corners = [replace(params, **{n: getattr(params, n) * f for n, f in zip(factors, combo)})
               for combo in itertools.product(*factors.values())]
    return [params] + [c for c in corners if c != params]


def _is_real(value: object) -> bool:
    return isinstance(value, Real) and not isinstance(value, (bool, np.bool_))


def _is_box_width(value: object) -> bool:
    return _is_real(value) and 0.0 <= value < 1.0
