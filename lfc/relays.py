"""Frequency protection at the generator: settings, safe set and relay logic.

Defaults are IEEE 1547-2018 Category III as in the paper's Table 1.  OF2 and
UF2 clear after 160 ms continuously beyond the threshold (a pickup timer that
resets when the signal returns, erratum E11); the ROCOF row has no time in the
paper, which says the relay trips "when the ROCOF first intersects the dashed
lines": delay 0 by default, configurable.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lfc._validate import check_nonnegative, check_positive, check_range

RELAY_NAMES = ("OF2", "UF2", "ROCOF")
_TIME_TOL = 1e-9  # s, tolerance when comparing elapsed pickup time to a delay


@dataclass(frozen=True)
class RelaySettings:
    """Relay thresholds and clearing times.

    Parameters
    ----------
    of2 : float
        Over-frequency threshold (pu of nominal), > 1. Default 1.03.
    uf2 : float
        Under-frequency threshold (pu), in (0, 1). Default 0.942.
    of2_delay, uf2_delay : float
        Clearing times (s), >= 0. Default 0.16.
    rocof_limit : float
        ROCOF threshold (pu/s), > 0. Default 0.05 (3 Hz/s at 60 Hz).
    rocof_delay : float
        ROCOF clearing time (s), >= 0. Default 0.
    """

    of2: float = 1.03
    uf2: float = 0.942
    of2_delay: float = 0.16
    uf2_delay: float = 0.16
    rocof_limit: float = 0.05
    rocof_delay: float = 0.0

    def __post_init__(self) -> None:
        check_range("of2", self.of2, 1.0, np.inf)
        check_range("uf2", self.uf2, 0.0, 1.0)
        check_positive("rocof_limit", self.rocof_limit)
        for name in ("of2_delay", "uf2_delay", "rocof_delay"):
            check_nonnegative(name, getattr(self, name))

    @property
    def F(self) -> float:
        """Symmetric frequency-deviation bound ``min(OF2 - 1, 1 - UF2)`` (pu)."""
        return min(self.of2 - 1.0, 1.0 - self.uf2)

    def in_safe_set(self, dw_meas: np.ndarray, rocof_meas: np.ndarray) -> np.ndarray:
        """True where ``(dw_meas, rocof_meas)`` lies inside the relay-safe set S."""
        dw = np.asarray(dw_meas)
        return ((dw <= self.of2 - 1) & (dw >= self.uf2 - 1)
                & (np.abs(rocof_meas) <= self.rocof_limit))

    def thresholds(self) -> dict[str, tuple[str, float, float]]:
        """Map relay name to (measured signal, threshold on it, delay in s)."""
        return {
            "OF2": ("dw_meas", self.of2 - 1.0, self.of2_delay),
            "UF2": ("dw_meas", self.uf2 - 1.0, self.uf2_delay),
            "ROCOF": ("abs_rocof_meas", self.rocof_limit, self.rocof_delay),
        }


@dataclass
class RelayBank:
    """OF2, UF2 and ROCOF relays with pickup timers, for N scenarios at once.

    Feed blocks of samples in time order with :meth:`update`; each call
    returns the trips in that block.  A relay trips when its signal has been
    beyond the threshold continuously for its delay; the timer resets when the
    signal returns, and a later excursion can trip it again (every trip is
    reported; the generator is not disconnected, so runs can show the SCC's
    continuity as the paper does).

    Parameters
    ----------
    settings : RelaySettings
    n : int
        Number of independent scenarios (columns of the sample blocks).
    """

    settings: RelaySettings
    n: int = 1
    _run_start: dict = field(init=False, repr=False)
    _tripped_run: dict = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._run_start = {r: np.full(self.n, np.nan) for r in RELAY_NAMES}
        self._tripped_run = {r: np.zeros(self.n, bool) for r in RELAY_NAMES}

    def _beyond(self, name: str, dw_meas: np.ndarray, rocof_meas: np.ndarray
                ) -> np.ndarray:
        s = self.settings
        if name == "OF2":
            return dw_meas > s.of2 - 1.0
        if name == "UF2":
            return dw_meas < s.uf2 - 1.0
        return np.abs(rocof_meas) > s.rocof_limit

    def update(self, t: np.ndarray, dw_meas: np.ndarray, rocof_meas: np.ndarray
               ) -> list[tuple[str, int, int]]:
        """Process a block of samples.

        Parameters
        ----------
        t : ndarray, shape (T,)
            Sample times (s), increasing, continuing the previous block.
        dw_meas, rocof_meas : ndarray, shape (T, n) or (T,) when n == 1
            Measured frequency deviation (pu) and ROCOF (pu/s).

        Returns
        -------
        list of (relay, sample index in block, scenario index)
            One entry per trip, in no particular order.
        """
        t = np.asarray(t, float)
        dw = np.asarray(dw_meas, float).reshape(len(t), self.n)
        rc = np.asarray(rocof_meas, float).reshape(len(t), self.n)
        delays = {"OF2": self.settings.of2_delay, "UF2": self.settings.uf2_delay,
                  "ROCOF": self.settings.rocof_delay}
        trips = []
        for name in RELAY_NAMES:
            beyond = self._beyond(name, dw, rc)
            tripped = self._scan(t, beyond, name, delays[name])
            for k, j in zip(*np.nonzero(tripped)):
                trips.append((name, int(k), int(j)))
        return trips

    def _scan(self, t: np.ndarray, beyond: np.ndarray, name: str, delay: float
              ) -> np.ndarray:
        """Vectorized pickup timer over a block; updates the carried state."""
        prev = np.vstack([~np.isnan(self._run_start[name])[None, :], beyond[:-1]])
        onset = beyond & ~prev
        start = np.where(onset, t[:, None], np.nan)
        start[0] = np.where(onset[0], t[0], self._run_start[name])
        start = _ffill(start)
        start = np.where(beyond, start, np.nan)
        due = beyond & (t[:, None] - start >= delay - _TIME_TOL)
        prev_due = np.vstack([self._tripped_run[name][None, :], due[:-1]])
        tripped = due & ~prev_due
        self._run_start[name] = start[-1]
        self._tripped_run[name] = due[-1]
        return tripped


def _ffill(a: np.ndarray) -> np.ndarray:
    """Forward-fill NaNs along axis 0 (rows), column by column."""
    idx = np.where(~np.isnan(a), np.arange(a.shape[0])[:, None], 0)
    np.maximum.accumulate(idx, axis=0, out=idx)
    return np.take_along_axis(a, idx, axis=0)
