"""Attack and load waveforms: callables of time (s) returning pu.

Every signal is zero before ``start`` and accepts a float or a numpy array of
times; a float in gives a float out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lfc._validate import check_finite, check_positive


def _check_window(start: float, stop: float) -> None:
    check_finite("start", start)
    if not (isinstance(stop, (int, float)) and stop > start):
        raise ValueError(f"stop must be > start ({start}), got {stop!r}")


class Signal:
    """Base class: subclasses implement ``_eval(t_array) -> array``."""

    def __call__(self, t: float | np.ndarray) -> float | np.ndarray:
        arr = np.asarray(t, dtype=float)
        out = self._eval(arr)
        return float(out) if arr.ndim == 0 else out

    def _eval(self, t: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError


@dataclass(frozen=True)
class _Periodic(Signal):
    """A periodic wave of peak ``amplitude`` (pu) and ``freq_hz`` (Hz) on ``[start, stop)``."""

    amplitude: float
    freq_hz: float
    start: float = 0.0
    stop: float = math.inf

    def __post_init__(self) -> None:
        check_finite("amplitude", self.amplitude)
        check_positive("freq_hz", self.freq_hz)
        _check_window(self.start, self.stop)

    def _eval(self, t: np.ndarray) -> np.ndarray:
        on = (t >= self.start) & (t < self.stop)
        return np.where(on, self._wave(t - self.start), 0.0)

    def _wave(self, tau: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError


@dataclass(frozen=True)
class Sinusoid(_Periodic):
    """``amplitude * sin(2 pi freq_hz (t - start) + phase)`` on ``[start, stop)``.

    Parameters
    ----------
    amplitude : float
        Peak value (pu).
    freq_hz : float
        Frequency (Hz), > 0.
    start, stop : float
        Active window (s); zero outside.
    phase : float
        Phase at ``start`` (rad).
    """

    phase: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        check_finite("phase", self.phase)

    def _wave(self, tau: np.ndarray) -> np.ndarray:
        return self.amplitude * np.sin(2 * np.pi * self.freq_hz * tau + self.phase)


@dataclass(frozen=True)
class Square(_Periodic):
    """Square wave of peak ``amplitude`` (pu), +amplitude first, on ``[start, stop)``.

    Parameters
    ----------
    amplitude : float
        Peak value (pu).
    freq_hz : float
        Frequency (Hz), > 0.
    start, stop : float
        Active window (s); zero outside.
    """

    def _wave(self, tau: np.ndarray) -> np.ndarray:
        cycle = np.mod(tau * self.freq_hz, 1.0)
        return np.where(cycle < 0.5, self.amplitude, -self.amplitude)


@dataclass(frozen=True)
class Step(Signal):
    """``value`` (pu) from ``start`` (s) on: a bias attack or a load step."""

    value: float
    start: float = 0.0

    def __post_init__(self) -> None:
        check_finite("value", self.value)
        check_finite("start", self.start)

    def _eval(self, t: np.ndarray) -> np.ndarray:
        return np.where(t >= self.start, self.value, 0.0)


@dataclass(frozen=True)
class Ramp(Signal):
    """``slope * (t - start)`` (pu, slope in pu/s), holding its value after ``stop``."""

    slope: float
    start: float = 0.0
    stop: float = math.inf

    def __post_init__(self) -> None:
        check_finite("slope", self.slope)
        _check_window(self.start, self.stop)

    def _eval(self, t: np.ndarray) -> np.ndarray:
        return self.slope * (np.clip(t, self.start, self.stop) - self.start)


@dataclass(frozen=True)
class Chirp(Signal):
    """Linear frequency sweep from ``f0_hz`` at ``start`` to ``f1_hz`` at ``stop``.

    ``amplitude * sin(2 pi (f0 tau + (f1 - f0) tau^2 / (2 T)))`` with
    ``tau = t - start``, ``T = stop - start``; zero outside ``[start, stop)``.
    """

    amplitude: float
    f0_hz: float
    f1_hz: float
    start: float = 0.0
    stop: float = 10.0

    def __post_init__(self) -> None:
        check_finite("amplitude", self.amplitude)
        check_positive("f0_hz", self.f0_hz)
        check_positive("f1_hz", self.f1_hz)
        _check_window(self.start, self.stop)
        if not math.isfinite(self.stop):
            raise ValueError(f"stop must be finite for a Chirp, got {self.stop!r}")

    def _eval(self, t: np.ndarray) -> np.ndarray:
        on = (t >= self.start) & (t < self.stop)
        tau = t - self.start
        rate = (self.f1_hz - self.f0_hz) / (self.stop - self.start)
        wave = self.amplitude * np.sin(2 * np.pi * (self.f0_hz * tau + 0.5 * rate * tau**2))
        return np.where(on, wave, 0.0)


@dataclass(frozen=True)
class Samples(Signal):
    """Replay of a recorded signal: linear interpolation between samples.

    Zero before the first sample time, the last value after the last one.

    Parameters
    ----------
    t : array_like
        Sample times (s), strictly increasing, finite.
    values : array_like
        Values (pu), same length as ``t``, finite.
    """

    t: np.ndarray = field(compare=False)
    values: np.ndarray = field(compare=False)

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=float).ravel()
        v = np.asarray(self.values, dtype=float).ravel()
        if t.size == 0 or t.size != v.size:
            raise ValueError(f"t and values must be non-empty and of equal length, "
                             f"got {t.size} and {v.size}")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
            raise ValueError("t and values must be finite")
        if np.any(np.diff(t) <= 0):
            raise ValueError("t must be strictly increasing")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "values", v)

    def _eval(self, t: np.ndarray) -> np.ndarray:
        return np.where(t >= self.t[0], np.interp(t, self.t, self.values), 0.0)
