"""The over-current relay on line B6–B5 and the line current it reads."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lfc._validate import check_nonnegative, check_positive

IEC_SI_K, IEC_SI_A = 0.14, 0.02  # IEC 60255-151 standard inverse: t = TMS k / ((I/Is)^a - 1)


@dataclass(frozen=True)
class OvercurrentSettings:
    """IEC 60255-151 standard-inverse relay with an instantaneous element.

    Parameters
    ----------
    pickup : float
        Inverse-time pickup Is (pu of the 2.5 MVA / 27.6 kV current base,
        1 pu = 52.3 A). Default 0.5 pu (26 A), five times the feeder's load.
    tms : float
        Time multiplier setting. Default 0.05.
    instantaneous : float
        Instantaneous (definite-time) element pickup (pu). Default 2.5 pu
        (131 A), above any load or motor-start current of the feeder.
    instantaneous_delay : float
        Its operating time (s). Default 0.02 s (about one cycle).
    breaker_time : float
        Trip command to open contacts (s). Default 0.05 s (3 cycles).
    """

    pickup: float = 0.5
    tms: float = 0.05
    instantaneous: float = 2.5
    instantaneous_delay: float = 0.02
    breaker_time: float = 0.05

    def __post_init__(self) -> None:
        check_positive("pickup", self.pickup)
        check_positive("tms", self.tms)
        check_nonnegative("instantaneous_delay", self.instantaneous_delay)
        check_nonnegative("breaker_time", self.breaker_time)
        if not self.instantaneous > self.pickup:
            raise ValueError(f"instantaneous must be > pickup ({self.pickup}), "
                             f"got {self.instantaneous}")

    def operate_time(self, current: np.ndarray | float) -> np.ndarray:
        """Relay operating time (s) for a constant current (pu); inf below pickup."""
        i = np.asarray(current, float)
        ratio = np.maximum(i / self.pickup, 1.0)
        with np.errstate(divide="ignore"):
            t_inv = np.where(i > self.pickup, self.tms * IEC_SI_K / (ratio ** IEC_SI_A - 1),
                             np.inf)
        return np.where(i >= self.instantaneous, np.minimum(t_inv, self.instantaneous_delay),
                        t_inv)


class OvercurrentRelay:
    """Stateful relay fed one current sample per plant step.

    The inverse-time element integrates ``dt / operate_time(I)`` while I is
    above pickup and resets below it; the instantaneous element is a
    definite-time timer.  Either reaching its time issues the trip at ``trip_t``;
    the breaker opens ``breaker_time`` later (``open_t``).
    """

    def __init__(self, settings: OvercurrentSettings) -> None:
        self.settings = settings
        self.trip_t: float | None = None
        self._acc = 0.0
        self._inst_start: float | None = None
        self._t_prev: float | None = None

    @property
    def open_t(self) -> float | None:
        """When the breaker opens (s), None before a trip."""
        return None if self.trip_t is None else self.trip_t + self.settings.breaker_time

    def update(self, t: float, current: float) -> None:
        """Feed the current magnitude (pu) at time ``t`` (s)."""
        s = self.settings
        dt = 0.0 if self._t_prev is None else t - self._t_prev
        self._t_prev = t
        if self.trip_t is not None:
            return
        self._acc = self._acc + dt / float(s.operate_time(current)) if current > s.pickup else 0.0
        if current >= s.instantaneous:
            self._inst_start = t if self._inst_start is None else self._inst_start
        else:
            self._inst_start = None
        inst_due = self._inst_start is not None and t - self._inst_start >= s.instantaneous_delay
        if self._acc >= 1.0 or inst_due:
            self.trip_t = t


def phase_a_current(t: np.ndarray, phasor: np.ndarray, *, f_nominal: float, i_base: float,
                    fs: float = 3000.0) -> tuple[np.ndarray, np.ndarray]:
    """Instantaneous phase-A current reconstructed from its phasor.

    ``i_a(t) = √2 · i_base · |I(t)| · cos(2π f_nominal t + ∠I(t))``, with |I|
    and the unwrapped angle interpolated linearly onto a uniform grid.

    Parameters
    ----------
    t : ndarray
        Times of the phasor samples (s), increasing.
    phasor : ndarray of complex
        Line current phasor (pu, rms, on the synchronously rotating frame).
    f_nominal : float
        Hz.
    i_base : float
        A rms per pu.
    fs : float
        Sample rate of the waveform (Hz).

    Returns
    -------
    (t_fine, i_a) : seconds and amperes (instantaneous)
    """
    t = np.asarray(t, float)
    t_fine = np.arange(t[0], t[-1], 1.0 / fs)
    mag = np.interp(t_fine, t, np.abs(phasor))
    ang = np.interp(t_fine, t, np.unwrap(np.angle(phasor)))
    return t_fine, math.sqrt(2) * i_base * mag * np.cos(2 * np.pi * f_nominal * t_fine + ang)
