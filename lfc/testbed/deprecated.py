"""The testbed's entry points of release 0.3, deprecated (removed in 0.5): each
warns and runs what :func:`lfc.simulate` or :func:`lfc.simulate_many` of the
case runs, with ``params`` as the design model."""

from __future__ import annotations

import warnings

from lfc.model import LFCParams
from lfc.multiarea import MultiAreaParams


def _warn(old: str, new: str) -> None:
    warnings.warn(f"lfc.testbed.{old} is deprecated and will be removed in 0.5; use "
                  f"lfc.{new} (the same keywords)", DeprecationWarning, stacklevel=3)


def simulate_testbed(params: LFCParams, **kwargs):
    """Deprecated: ``lfc.simulate(MicrogridCase(), design=params, ...)``."""
    _warn("simulate_testbed", "simulate(MicrogridCase(), design=params, ...)")
    from lfc.testbed.plant import simulate_microgrid
    return simulate_microgrid(params, **kwargs)


def simulate_grid(params: MultiAreaParams, **kwargs):
    """Deprecated: ``lfc.simulate(GridCase.kundur(), design=params, ...)``."""
    _warn("simulate_grid", "simulate(GridCase.kundur(), design=params, ...)")
    from lfc.testbed.grid_plant import simulate_andes_grid
    return simulate_andes_grid(params, **kwargs)


def simulate_grid_batch(params: MultiAreaParams, scenarios: list[dict], **kwargs):
    """Deprecated: ``lfc.simulate_many(GridCase.kundur(), scenarios, design=params, ...)``."""
    _warn("simulate_grid_batch", "simulate_many(GridCase.kundur(), scenarios, design=params, ...)")
    from lfc.testbed.grid_plant import simulate_andes_grid_table
    return simulate_andes_grid_table(params, scenarios, **kwargs)
