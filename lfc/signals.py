"""Attack and load waveforms: callables of time (s) returning pu.

Every signal is zero before ``start`` and accepts a float or a numpy array of
times; a float in gives a float out.  Each waveform is one compiled function
(:func:`value_at`), used both when a signal is called and inside the engine, so
the simulators and the plots see exactly the same numbers.  A signal is
described to the engine by :meth:`Signal.spec`: a waveform code, six float
parameters and, for :class:`Samples`, its sample times and values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from lfc._jit import inline, jit
from lfc._validate import check_array, check_finite, check_number, check_positive

# waveform codes of Signal.spec() and value_at(); GRID: values given on the engine's grid
NONE, SINUSOID, SQUARE, STEP, RAMP, CHIRP, SAMPLES, GRID = range(8)
N_PARAMS = 6
SignalLike = Callable[[np.ndarray], np.ndarray]   # a Signal, or any callable of time (s)


@inline
def value_at(kind: int, params: np.ndarray, row: int, t: float, st: np.ndarray,
             sv: np.ndarray, o: int, n: int) -> float:
    """The value (pu) at time ``t`` (s) of waveform ``kind`` with parameters
    ``params[row]``.

    The parameters are ``(amplitude or value or slope, frequency or f0 (Hz),
    start, stop (s), phase (rad) or f1 (Hz), unused)``; ``st[o:o+n]``,
    ``sv[o:o+n]`` the sample times and values of ``SAMPLES``.  ``GRID`` is not
    evaluated here (the engine indexes it).
    """
    a, f, start = params[row, 0], params[row, 1], params[row, 2]
    stop, extra = params[row, 3], params[row, 4]
    if kind == NONE or kind == GRID or t < start:
        return 0.0
    if kind == STEP:
        return a if t < stop else 0.0
    if kind == RAMP:
        return a * (min(t, stop) - start)
    if kind == SAMPLES:
        last = o + n - 1
        if t >= st[last]:
            return sv[last]
        lo, hi = o, last          # st[lo] <= t < st[hi]: bisect, then np.interp's formula
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if st[mid] <= t:
                lo = mid
            else:
                hi = mid
        return (sv[hi] - sv[lo]) / (st[hi] - st[lo]) * (t - st[lo]) + sv[lo]
    if t >= stop:
        return 0.0
    tau = t - start
    if kind == SINUSOID:
        return a * math.sin(2 * math.pi * f * tau + extra)
    if kind == SQUARE:
        return a if (tau * f) % 1.0 < 0.5 else -a
    rate = (extra - f) / (stop - start)    # CHIRP: f0 = f, f1 = extra
    return a * math.sin(2 * math.pi * (f * tau + 0.5 * rate * tau**2))


@jit
def _values(kind: int, p: np.ndarray, t: np.ndarray, st: np.ndarray, sv: np.ndarray
            ) -> np.ndarray:
    out = np.empty(t.shape)
    params = p.reshape(1, -1)
    for i in range(t.size):
        out.flat[i] = value_at(kind, params, 0, t.flat[i], st, sv, 0, len(st))
    return out


_EMPTY = np.zeros(1)


def _check_window(start: float, stop: float) -> None:
    check_finite("start", start)
    check_number("stop", stop)
    if not stop > start:
        raise ValueError(f"stop must be > start ({start}), got {stop!r}")


class Signal:
    """Base class: subclasses describe themselves with :meth:`spec`."""

    def spec(self) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
        """``(kind, params (6,), sample times, sample values)`` for the engine."""
        raise NotImplementedError  # pragma: no cover - abstract

    def __call__(self, t: float | np.ndarray) -> float | np.ndarray:
        arr = check_array("t", t)             # times (s): a string or a bool is refused
        kind, p, st, sv = self.spec()
        out = _values(kind, p, arr.reshape(-1), st, sv).reshape(arr.shape)
        return float(out) if arr.ndim == 0 else out


def _params(*values: float) -> np.ndarray:
    p = np.zeros(N_PARAMS)
    p[:len(values)] = values
    return p


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

    def spec(self):
        return SINUSOID, _params(self.amplitude, self.freq_hz, self.start, self.stop,
                                 self.phase), _EMPTY, _EMPTY


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

    def spec(self):
        return SQUARE, _params(self.amplitude, self.freq_hz, self.start, self.stop), \
            _EMPTY, _EMPTY


@dataclass(frozen=True)
class Step(Signal):
    """``value`` (pu) from ``start`` (s) on — a bias attack or a load step — or,
    with a finite ``stop`` (s), a pulse on ``[start, stop)``."""

    value: float
    start: float = 0.0
    stop: float = math.inf

    def __post_init__(self) -> None:
        check_finite("value", self.value)
        _check_window(self.start, self.stop)

    def spec(self):
        return STEP, _params(self.value, 0.0, self.start, self.stop), _EMPTY, _EMPTY


@dataclass(frozen=True)
class Ramp(Signal):
    """``slope * (t - start)`` (pu, slope in pu/s), holding its value after ``stop``."""

    slope: float
    start: float = 0.0
    stop: float = math.inf

    def __post_init__(self) -> None:
        check_finite("slope", self.slope)
        _check_window(self.start, self.stop)

    def spec(self):
        return RAMP, _params(self.slope, 0.0, self.start, self.stop), _EMPTY, _EMPTY


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

    def spec(self):
        return CHIRP, _params(self.amplitude, self.f0_hz, self.start, self.stop,
                              self.f1_hz), _EMPTY, _EMPTY


@dataclass(frozen=True, eq=False)
class Samples(Signal):
    """Replay of a recorded signal: linear interpolation between samples.

    Zero before the first sample time, the last value after the last one.  Two
    replays are equal when their sample times and values are.

    Parameters
    ----------
    t : array_like
        Sample times (s), strictly increasing, finite.
    values : array_like
        Values (pu), same length as ``t``, finite.
    """

    t: np.ndarray
    values: np.ndarray

    def __post_init__(self) -> None:
        t = check_array("t", self.t, ndim=1)
        v = check_array("values", self.values, ndim=1)
        if t.size == 0 or t.size != v.size:
            raise ValueError(f"t and values must be non-empty and of equal length, "
                             f"got {t.size} and {v.size}")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
            raise ValueError("t and values must be finite")
        if np.any(np.diff(t) <= 0):
            raise ValueError("t must be strictly increasing")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "values", v)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Samples):
            return NotImplemented
        return bool(np.array_equal(self.t, other.t) and np.array_equal(self.values, other.values))

    def __hash__(self) -> int:
        return hash((self.t.tobytes(), self.values.tobytes()))

    def spec(self):
        return SAMPLES, _params(0.0, 0.0, float(self.t[0]), math.inf), self.t, self.values
