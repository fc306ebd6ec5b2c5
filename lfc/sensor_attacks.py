"""Attacks on what a sensor reports that depend on what it reads: scale, freeze, replay.

A lie that is a waveform of time (a bias, a sinusoid: any :mod:`lfc.signals`
signal) is added to the honest reading.  The attacks here transform the reading
itself, as a compromised meter or a man in the middle of the sensor's link
would (Teixeira et al., Automatica 2015; Mo and Sinopoli, replay attacks,
Allerton 2009).  Inside its window ``[start, stop)`` (s):

=============  =========================================================
:class:`Scale` the report is ``factor`` times the honest reading (a meter's
               gain changed; ``factor`` 0 reports nothing moving, < 0 the
               wrong sign)
:class:`Freeze` the report stays what it was at the last sample before
               ``start`` (a stuck meter)
:class:`Replay` the report of ``lag`` s earlier: the window ``[start - lag,
               start)`` recorded and played back, looped when the attack
               lasts longer than ``lag``
=============  =========================================================

Each is given to :func:`lfc.simulate` (and a :class:`lfc.Scenario`) as a
``dw_meas_attack`` or ``rocof_meas_attack`` (an area's ``attacks={a: {"dw_meas":
...}}`` on a grid).  The engine applies it at every control sample
(:func:`lfc.engine.sensor_reading`) wherever the generator side reads that
sensor: the AGC's integrator, the Kalman filter, a coupled filter's grid
estimate and, with the exact state, the filter (its state plus the report minus
the honest reading); the relays read the plant.  A report is the reading with
the controller's measurement noise, so a replay plays back the noise recorded.
Not a function of time, these are not evaluated on their own (calling one raises
``TypeError``), and they are not given to :func:`lfc.sensors.simulate_sensors`,
whose sensors' lies are waveforms (its guarantee covers any lie whatever).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lfc._validate import check_finite
from lfc.signals import N_PARAMS, Signal

#: the engine's codes for the three, after lfc.signals' waveform codes (0 ... 7): a kind
#: at or above SCALE is a reading transform
SCALE, FREEZE, REPLAY = 8, 9, 10


def _window(start: float, stop: float) -> None:
    check_finite("start", start)
    if not start >= 0.0:
        raise ValueError(f"start must be >= 0 s, got {start!r}")
    if not (isinstance(stop, (int, float)) and stop > start):
        raise ValueError(f"stop must be a number > start ({start} s; math.inf: never), "
                         f"got {stop!r}")


class Reading(Signal):
    """A transform of the reading (base class); described to the engine by
    :meth:`spec`."""

    def __call__(self, t):
        raise TypeError(f"{type(self).__name__} transforms what a sensor reads: it is not a "
                        f"function of time; give it to lfc.simulate as dw_meas_attack or "
                        f"rocof_meas_attack")

    def _spec(self, kind: int, value: float, lag: float):
        p = np.zeros(N_PARAMS)
        p[0], p[2], p[3], p[5] = value, self.start, self.stop, lag
        return kind, p, np.zeros(0), np.zeros(0)


@dataclass(frozen=True)
class Scale(Reading):
    """The report is ``factor`` (finite) times the honest reading on ``[start, stop)``.

    Raises
    ------
    ValueError
        Naming the parameter, for a value out of its range (``start`` >= 0 s,
        ``stop`` > ``start``).
    """

    factor: float
    start: float = 0.0
    stop: float = math.inf

    def __post_init__(self) -> None:
        check_finite("factor", self.factor)
        _window(self.start, self.stop)

    def spec(self):
        """``(SCALE, (factor, 0, start, stop, 0, 0), [], [])``."""
        return self._spec(SCALE, self.factor, 0.0)


@dataclass(frozen=True)
class Freeze(Reading):
    """The report holds its value of the last sample before ``start`` on ``[start, stop)``
    (from ``start`` 0: the first sample's).

    Raises
    ------
    ValueError
        For ``start`` < 0 s or ``stop`` <= ``start``.
    """

    start: float = 0.0
    stop: float = math.inf

    def __post_init__(self) -> None:
        _window(self.start, self.stop)

    def spec(self):
        """``(FREEZE, (0, 0, start, stop, 0, 0), [], [])``."""
        return self._spec(FREEZE, 0.0, 0.0)


@dataclass(frozen=True)
class Replay(Reading):
    """The report of ``lag`` s earlier on ``[start, stop)``: ``[start - lag, start)``
    played back, looped.

    ``lag`` is rounded to whole control periods by the engine (at least one: a
    lag of one period is :class:`Freeze`).

    Raises
    ------
    ValueError
        Naming the parameter: ``lag`` must be > 0 s and <= ``start`` (the
        recording is made during the run), ``stop`` > ``start``.
    """

    lag: float
    start: float = 0.0
    stop: float = math.inf

    def __post_init__(self) -> None:
        check_finite("lag", self.lag)
        _window(self.start, self.stop)
        if not 0.0 < self.lag <= self.start:
            raise ValueError(f"lag must be > 0 s and <= start ({self.start} s: the recording "
                             f"is made during the run), got {self.lag!r}")

    def spec(self):
        """``(REPLAY, (0, 0, start, stop, 0, lag), [], [])``."""
        return self._spec(REPLAY, 0.0, self.lag)


def lag_samples(kind: int, lag: float, period: float) -> int:
    """The control samples a reading transform of ``kind`` looks back: 1 for
    :class:`Freeze`, ``lag`` (s) in whole ``period`` s (at least 1) for :class:`Replay`,
    0 for :class:`Scale`."""
    if kind == FREEZE:
        return 1
    if kind == REPLAY:
        return max(1, round(lag / period))
    return 0
