"""Redundant frequency and ROCOF sensors, some of which may lie.

A generator has several sources of its frequency — the governor's speed pickup, a PMU,
the relay's own meter — and ROCOF from each.  :class:`SensorArray` is ``count`` such
sensors, each reading the meters' state (``dw_meas`` pu, ``rocof_meas`` pu/s) plus its
own noise; an honest sensor's noise stays within ``bound`` (pu, pu/s), a spoofed one
reads anything.  :func:`fuse` takes, channel by channel, the median of the readings.

**Proven.**  With ``count >= 2 tolerate + 1`` sensors of which at most ``tolerate`` lie
in any way, the median is within ``bound`` of the meters' state: at least
``count - tolerate`` readings are honest, so at most ``tolerate`` lie on either side of
the median and it lies between two honest readings.  Every state consistent with
``count - tolerate`` honest readings is within ``bound`` of the median too, so the
certified filter built with ``sensor_bound=bound`` (its error ellipsoid holds that
box) keeps its guarantee on the fused readings: no relay trips, under its other
assumptions, however the liars lie.  A reading farther than ``2 bound`` from the median
is a lie (an honest one is within ``bound`` of the truth, the median too): it is named
(``spoofed``).  Fewer than ``count - tolerate`` readings within ``2 bound`` of the
median means more than ``tolerate`` lie (``beyond``): nothing is proven then.

Every sensor reads the same state, so the median's error, the spoofed and the beyond
flags depend only on the sensors' noise and lies, not on the state:
:func:`simulate_sensors` computes them at the control samples and runs the plant with
the fused error as the generator side's sensor attack (``dw_meas_attack``,
``rocof_meas_attack`` of :func:`lfc.simulate`: what the AGC and the filter read; the
relays read the plant).  The generator's own signals (``dPg``, ``dPm``, ``dw``) are
exact, as in every exact-state run.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from lfc._validate import check_count, check_pair, check_positive
from lfc.result import Result
from lfc.sensor_attacks import Reading
from lfc.signals import Samples, Signal

#: the channels each sensor reads: frequency (pu) and ROCOF (pu/s)
CHANNELS = ("dw_meas", "rocof_meas")


@dataclass(frozen=True)
class SensorArray:
    """``count`` redundant sensors of frequency and ROCOF, at most ``tolerate`` of them
    lying; an honest one's noise stays within ``±bound`` (pu, pu/s: the meters' own
    accuracy, no default — a PMU's is not a governor pickup's), drawn uniformly there.

    Raises
    ------
    ValueError
        ``count`` < ``2 tolerate + 1``, ``tolerate`` < 1, or a bound not > 0.
    """

    bound: tuple[float, float]
    count: int = 3
    tolerate: int = 1

    def __post_init__(self) -> None:
        check_count("count", self.count)
        check_count("tolerate", self.tolerate)
        if self.count < 2 * self.tolerate + 1:
            raise ValueError(f"count must be >= 2 tolerate + 1 = {2 * self.tolerate + 1} "
                             f"(a median outvotes tolerate liars), got {self.count!r}")
        object.__setattr__(self, "bound", check_pair("bound", self.bound, positive=True))

    def readings(self, times: np.ndarray, attacks: dict[int, dict[str, Signal]] | None,
                 seed: int = 0, honest: np.ndarray | None = None) -> np.ndarray:
        """Each sensor's error at ``times`` (s): its noise — ``honest`` (shape
        ``(len(times), count, 2)``, within ``±bound``: checked), else uniform draws
        seeded by ``seed`` — plus its attack, ``attacks[sensor][channel]`` (any
        :class:`~lfc.signals.Signal`, pu or pu/s); shape ``(len(times), count, 2)``."""
        times = np.asarray(times, float)
        b = np.asarray(self.bound)
        if honest is None:
            shape = (len(times), self.count, 2)
            honest = np.random.default_rng(seed).uniform(-1.0, 1.0, shape) * b
        honest = np.asarray(honest, float)
        if honest.shape != (len(times), self.count, 2) or np.any(np.abs(honest) > b):
            raise ValueError(f"honest must have shape {(len(times), self.count, 2)} and lie "
                             f"within ±bound {self.bound}")
        errors = honest.copy()
        for sensor, channels in (attacks or {}).items():
            if not 0 <= sensor < self.count:
                raise ValueError(f"attacks: sensor must be in [0, {self.count}), got {sensor!r}")
            for channel, signal in channels.items():
                if channel not in CHANNELS:
                    raise ValueError(f"attacks[{sensor}]: channel must be one of {CHANNELS}, "
                                     f"got {channel!r}")
                if isinstance(signal, Reading):
                    raise ValueError(f"attacks[{sensor}][{channel!r}]: a "
                                     f"{type(signal).__name__} reads the state, which these "
                                     f"errors are computed without; give its lie as a "
                                     f"waveform of time (the proof covers any lie)")
                errors[:, sensor, CHANNELS.index(channel)] += signal(times)
        return errors


@dataclass(frozen=True)
class Fused:
    """What :func:`fuse` found at each control sample.

    Attributes
    ----------
    t : ndarray
        The samples (s).
    error : ndarray
        ``(len(t), 2)``: the median's error on frequency (pu) and ROCOF (pu/s).
    spoofed : DataFrame
        ``t``, ``channel``, ``sensor``: a reading farther than ``2 bound`` from the
        median (a lie, when at most ``tolerate`` lie).
    beyond : DataFrame
        ``t``, ``channel``: fewer than ``count - tolerate`` readings agree with the median
        within ``2 bound`` (more than ``tolerate`` lie: nothing proven).
    """

    t: np.ndarray
    error: np.ndarray
    spoofed: pd.DataFrame
    beyond: pd.DataFrame


def fuse(array: SensorArray, t: np.ndarray, errors: np.ndarray) -> Fused:
    """The median of the sensors' ``errors`` (:meth:`SensorArray.readings`) at ``t``,
    channel by channel, and the sensors it names (module docstring)."""
    median = np.median(errors, axis=1)
    far = np.abs(errors - median[:, None, :]) > 2 * np.asarray(array.bound)
    k, sensor, channel = np.nonzero(far)
    spoofed = pd.DataFrame({"t": t[k], "channel": np.array(CHANNELS)[channel],
                            "sensor": sensor})
    k, channel = np.nonzero((~far).sum(axis=1) < array.count - array.tolerate)
    beyond = pd.DataFrame({"t": t[k], "channel": np.array(CHANNELS)[channel]})
    return Fused(t, median, spoofed, beyond)


@dataclass(frozen=True)
class SensorRun:
    """A run on redundant sensors: the plant's :class:`~lfc.Result` and :class:`Fused`."""

    result: Result
    fused: Fused

    @property
    def alarms(self) -> pd.DataFrame:
        """The run's alarm log: the filter's (``result.alarms``, ``ALARM_COLUMNS``) with
        a row for each reading named a lie (``reason`` ``"spoofed: sensor k
        (channel)"``) and each sample beyond the statement (``"beyond: more than
        tolerate lie (channel)"``), in time order (the filter's first at a tie)."""
        named = [pd.DataFrame({"t": f.t, "reason": reason})
                 for f, reason in ((self.fused.spoofed, "spoofed: sensor "
                                    + self.fused.spoofed.sensor.astype(str) + " ("
                                    + self.fused.spoofed.channel + ")"),
                                   (self.fused.beyond, "beyond: more than tolerate lie ("
                                    + self.fused.beyond.channel + ")"))
                 if len(f)]
        log = self.result.alarms
        if not named:
            return log
        return (pd.concat([log, *named], ignore_index=True)[log.columns]
                .sort_values("t", kind="stable").reset_index(drop=True))


def simulate_sensors(params, array: SensorArray, *, duration: float,
                     attacks: dict[int, dict[str, Signal]] | None = None, seed: int = 0,
                     honest: np.ndarray | None = None, control_period: float = 0.01,
                     **scenario) -> SensorRun:
    """One area's run (:func:`lfc.simulate` of ``params``, exact state) whose AGC and
    filter read the median of ``array``'s sensors, each with its noise (``seed`` or
    ``honest``) and ``attacks[sensor][channel]`` (:meth:`SensorArray.readings`).

    ``scenario``: :func:`lfc.simulate`'s other keywords (``scc``, ``pc_attack``,
    ``load``, ...); not ``estimator``, ``dw_meas_attack`` or ``rocof_meas_attack``
    (the sensors set them).  Give the certified filter ``sensor_bound=array.bound``
    for the proven statement (module docstring).

    Raises
    ------
    ValueError
        A keyword the sensors set, or what :meth:`SensorArray.readings` refuses.
    """
    from lfc.run import simulate
    taken = {"estimator", "dw_meas_attack", "rocof_meas_attack"} & set(scenario)
    if taken:
        raise ValueError(f"simulate_sensors sets {sorted(taken)} itself (the fused readings); "
                         f"do not give them")
    check_positive("duration", duration)
    t = np.arange(int(round(duration / control_period)) + 1) * control_period
    fused = fuse(array, t, array.readings(t, attacks, seed, honest))
    result = simulate(params, duration=duration, control_period=control_period,
                      dw_meas_attack=Samples(t, fused.error[:, 0]),
                      rocof_meas_attack=Samples(t, fused.error[:, 1]), **scenario)
    return SensorRun(result, fused)
