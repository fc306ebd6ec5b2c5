"""Frequency protection at the generator: settings, safe set and relay logic.

Defaults are IEEE 1547-2018 Category III as in the paper's Table 1.  OF2 and
UF2 clear after 160 ms continuously beyond the threshold (a pickup timer that
resets when the signal returns, erratum E11); the ROCOF row has no time in the
paper, which says the relay trips "when the ROCOF first intersects the dashed
lines": delay 0 by default, configurable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lfc._jit import inline, jit
from lfc._validate import (ParameterTypeError, check_array, check_count, check_number,
                           check_range, in_engine_types)

RELAY_NAMES = ("OF2", "UF2", "ROCOF")
TIME_TOL = 1e-9  # s, tolerance when comparing elapsed pickup time to a delay
MAX_ROCOF_LIMIT = 10.0   # pu/s: the largest ROCOF setting (RelaySettings)
MAX_DELAY = 1e4          # s: the longest clearing time
#: IEEE 1547-2018's ROCOF ride-through by DER category (Hz/s): I, II, III.
IEEE1547_ROCOF_HZ_PER_S = {"I": 0.5, "II": 2.0, "III": 3.0}


def relays_or_default(relays: object) -> "RelaySettings":
    """``relays``, or the default ``RelaySettings()`` for None, its settings in the
    engine's types (:func:`~lfc._validate.in_engine_types`: a ``Fraction`` or a numpy
    scalar setting as a float); anything else (``0``, ``"x"``) is a
    :class:`~lfc._validate.ParameterTypeError`, not the default."""
    if relays is None:
        return RelaySettings()
    if not isinstance(relays, RelaySettings):
        raise ParameterTypeError(f"relays must be a RelaySettings or None, got {relays!r:.80} "
                                 f"({type(relays).__name__})")
    return in_engine_types(relays)


@dataclass(frozen=True)
class RelaySettings:
    """Relay thresholds and clearing times.

    Parameters
    ----------
    of2 : float
        Over-frequency threshold (pu of nominal), in (1, 2]. Default 1.03.
    uf2 : float
        Under-frequency threshold (pu), in (0, 1). Default 0.942.
    of2_delay, uf2_delay : float
        Clearing times (s), in [0, 1e4]. Default 0.16.
    rocof_limit : float
        ROCOF threshold (pu/s), in (0, ``MAX_ROCOF_LIMIT`` = 10] (600 Hz/s at 60 Hz:
        beyond any relay; a larger one overflows the filters' barrier arithmetic, so
        "ROCOF off" is 10). Default 0.05 (3 Hz/s at 60 Hz).
    rocof_delay : float
        ROCOF clearing time (s), in [0, 1e4]. Default 0.
    """

    of2: float = 1.03
    uf2: float = 0.942
    of2_delay: float = 0.16
    uf2_delay: float = 0.16
    rocof_limit: float = 0.05
    rocof_delay: float = 0.0

    def __post_init__(self) -> None:
        for name, low, high in (("of2", 1.0, 2.0), ("rocof_limit", 0.0, MAX_ROCOF_LIMIT)):
            value = getattr(self, name)
            check_number(name, value)
            if not low < value <= high:
                raise ValueError(f"{name} must lie in ({low}, {high}], got {value!r}")
        check_range("uf2", self.uf2, 0.0, 1.0)
        for name in ("of2_delay", "uf2_delay", "rocof_delay"):
            check_range(name, getattr(self, name), 0.0, MAX_DELAY, closed=True)

    @classmethod
    def ieee1547(cls, category: str = "III", nominal_hz: float = 60.0) -> "RelaySettings":
        """The relays of an IEEE 1547-2018 DER of ``category`` (``"I"``, ``"II"`` or
        ``"III"``).

        OF2 and UF2 are the paper's Table 1 (1.03 and 0.942 pu, 160 ms: the
        standard's 62.0 Hz and 56.5 Hz defaults, the same in every category, as the
        paper rounds them); the ROCOF setting is the category's ride-through
        (0.5, 2.0, 3.0 Hz/s, as ``nominal_hz``'s pu/s), so ``ieee1547("III")`` is
        the default ``RelaySettings()`` (the paper's Cat. III, 0.05 pu/s at 60 Hz).

        Raises
        ------
        ValueError
            If ``category`` is not one of them, or ``nominal_hz`` is not in [1, 1000] Hz.
        TypeError
            If ``category`` is not a string.
        """
        if not isinstance(category, str):
            raise ParameterTypeError(f"category must be a string, one of "
                                     f"{tuple(IEEE1547_ROCOF_HZ_PER_S)}, got {category!r}")
        if category not in IEEE1547_ROCOF_HZ_PER_S:
            raise ValueError(f"category must be one of {tuple(IEEE1547_ROCOF_HZ_PER_S)} "
                             f"(IEEE 1547-2018), got {category!r}")
        check_range("nominal_hz", nominal_hz, 1.0, 1000.0, closed=True)
        return cls(rocof_limit=IEEE1547_ROCOF_HZ_PER_S[category] / nominal_hz)

    @property
    def F(self) -> float:
        """Symmetric frequency-deviation bound ``min(OF2 - 1, 1 - UF2)`` (pu)."""
        return min(self.of2 - 1.0, 1.0 - self.uf2)

    def in_safe_set(self, dw_meas: np.ndarray, rocof_meas: np.ndarray) -> np.ndarray:
        """True where ``(dw_meas, rocof_meas)`` lies inside the relay-safe set S."""
        dw = np.asarray(dw_meas)
        return ((dw <= self.of2 - 1) & (dw >= self.uf2 - 1)
                & (np.abs(rocof_meas) <= self.rocof_limit))

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """``(limits, delays)`` in ``RELAY_NAMES`` order: the thresholds on
        ``dw_meas`` (``of2 - 1``, ``uf2 - 1``, pu) and ``|rocof_meas|`` (pu/s), and
        the clearing times (s)."""
        return (np.array([self.of2 - 1.0, self.uf2 - 1.0, self.rocof_limit]),
                np.array([self.of2_delay, self.uf2_delay, self.rocof_delay]))


@inline
def relay_sample(t: float, dw: float, rocof: float, limits: np.ndarray, delays: np.ndarray,
                 start: np.ndarray, due: np.ndarray) -> int:
    """Feed one sample to the OF2, UF2 and ROCOF pickup timers; return the relays
    that trip at it as bits (``1 << RELAY_NAMES.index(name)``).

    ``limits`` = ``(of2 - 1, uf2 - 1, rocof_limit)`` (pu, pu/s) and ``delays`` (s)
    come from :meth:`RelaySettings.arrays`; ``start`` (time the signal went
    beyond, NaN if it is not) and ``due`` (the delay has run out) are each
    relay's state, updated in place.  A relay trips at the sample where its
    signal has been beyond the threshold for its delay; the timer resets when
    the signal returns, and a later excursion trips it again.
    """
    beyond = (dw > limits[0], dw < limits[1], abs(rocof) > limits[2])
    trips = 0
    for r in range(3):
        if not beyond[r]:
            start[r], due[r] = np.nan, 0.0
            continue
        if math.isnan(start[r]):
            start[r] = t
        now = t - start[r] >= delays[r] - TIME_TOL
        if now and due[r] == 0.0:
            trips |= 1 << r
        due[r] = 1.0 if now else 0.0
    return trips


@jit
def _relay_block(t: np.ndarray, dw: np.ndarray, rocof: np.ndarray, limits: np.ndarray,
                 delays: np.ndarray, start: np.ndarray, due: np.ndarray) -> np.ndarray:
    """:func:`relay_sample` over a block of samples (T, n); trip bits (T, n)."""
    out = np.zeros(dw.shape, np.int64)
    for j in range(dw.shape[1]):
        for k in range(dw.shape[0]):
            out[k, j] = relay_sample(t[k], dw[k, j], rocof[k, j], limits, delays, start[j],
                                     due[j])
    return out


@dataclass
class RelayBank:
    """OF2, UF2 and ROCOF relays with pickup timers, for N scenarios at once.

    Feed blocks of samples in time order with :meth:`update`; each call
    returns the trips in that block.  A relay trips when its signal has been
    beyond the threshold continuously for its delay; the timer resets when the
    signal returns, and a later excursion can trip it again (every trip is
    reported; the generator is not disconnected, so runs can show the SCC's
    continuity as the paper does).  The timers are :func:`relay_sample`, the
    same code the engine runs.

    Parameters
    ----------
    settings : RelaySettings
    n : int
        Number of independent scenarios (columns of the sample blocks).
    """

    settings: RelaySettings
    n: int = 1
    _start: np.ndarray = field(init=False, repr=False)
    _due: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.settings, RelaySettings):
            raise ParameterTypeError(f"settings must be a RelaySettings, got "
                                     f"{self.settings!r:.80}")
        check_count("n", self.n)
        self._start = np.full((self.n, 3), np.nan)
        self._due = np.zeros((self.n, 3))
        self._last = -np.inf

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
            One entry per trip, in time order (relays in ``RELAY_NAMES`` order).
        """
        t = check_array("t", t, shape=(None,))
        if np.any(np.diff(t) <= 0) or (len(t) and not t[0] > self._last):
            raise ValueError("t must be increasing, continuing the previous block (after "
                             f"{self._last} s)")
        want = (len(t), self.n) if self.n > 1 else None
        dw = check_array("dw_meas", dw_meas)
        rc = check_array("rocof_meas", rocof_meas)
        for name, arr in (("dw_meas", dw), ("rocof_meas", rc)):
            if arr.size != len(t) * self.n:
                raise ValueError(f"{name} must have shape {want or (len(t),)}, got {arr.shape}")
        dw, rc = dw.reshape(len(t), self.n), rc.reshape(len(t), self.n)
        if len(t):
            self._last = float(t[-1])
        limits, delays = self.settings.arrays()
        bits = _relay_block(t, dw, rc, limits, delays, self._start, self._due)
        return [(name, int(k), int(j)) for k, j in zip(*np.nonzero(bits))
                for r, name in enumerate(RELAY_NAMES) if bits[k, j] >> r & 1]
