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

An area's sensors in a scenario are a :class:`Redundant`: the array, its honest
sensors' noise and what the liars add (``lfc.simulate(params, sensors=Redundant(...))``,
a :class:`lfc.Scenario`'s ``sensors={area: Redundant(...)}``, so also
:func:`lfc.simulate_many`, grids and the red team's fixed ``scenario``).  Every sensor
reads the same state, so the median's error, the spoofed and the beyond flags depend
only on the sensors' noise and lies, not on the state: the engine's scenario tables
(:class:`lfc.scenarios.Scenarios`) compute them at the control samples and give the
fused error as the area's sensor attack (what its AGC, its Kalman filter and, with the
exact state, its filter read; the relays read the plant) — exact, not an
approximation.  The run's alarm log has a row for each reading named a lie and each
sample beyond the statement (:func:`alarm_rows`).  The generator's own signals
(``dPg``, ``dPm``, ``dw``) are exact, as in every exact-state run.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from numbers import Integral

import numpy as np
import pandas as pd

from lfc._validate import ParameterTypeError, check_count, check_pair
from lfc.result import ALARM_COLUMNS
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
class Redundant:
    """An area's redundant sensors in a scenario: the ``array``, what its honest
    sensors' noise is and what its liars add.

    Parameters
    ----------
    array : SensorArray
        The sensors, their noise bound and how many may lie.
    lies : dict, optional
        ``{sensor: {"dw_meas" | "rocof_meas": signal}}``: added to that sensor's
        reading (pu, pu/s; any :class:`~lfc.signals.Signal` or callable of time, not a
        reading transform: these errors are computed without the state, and the
        proof covers any lie).  More than ``array.tolerate`` liars is allowed: the run
        shows what happens beyond the statement.
    noise : dict, optional
        ``{sensor: {channel: signal}}``: an honest sensor's noise as a waveform
        (within ``±array.bound`` at every control sample, checked when the run samples
        it: its corners, a sign flipping every sample, ...); channels not given draw
        uniformly within the bound from the scenario's ``seed`` (area ``a > 0``:
        ``(seed, a)``).

    Raises
    ------
    ValueError
        Naming the entry: a sensor outside ``[0, array.count)``, a channel not among
        ``CHANNELS``, or a reading transform.
    """

    array: SensorArray
    lies: dict = field(default_factory=dict)
    noise: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.array, SensorArray):
            raise ParameterTypeError(f"array must be a SensorArray, got "
                                     f"{type(self.array).__name__}")
        for name in ("lies", "noise"):
            entries = getattr(self, name)
            if not isinstance(entries, dict):
                raise ParameterTypeError(f"{name} must be a dict {{sensor: {{channel: "
                                         f"signal}}}}, got {entries!r:.80}")
            for sensor, channels in entries.items():
                if isinstance(sensor, bool) or not isinstance(sensor, Integral) \
                        or not 0 <= sensor < self.array.count:
                    raise ValueError(f"{name}: sensor must be an int in [0, "
                                     f"{self.array.count}), got {sensor!r}")
                if not isinstance(channels, dict) or set(channels) - set(CHANNELS):
                    raise ValueError(f"{name}[{sensor}] must be a dict with keys among "
                                     f"{CHANNELS}, got {channels!r:.80}")
                for channel, signal in channels.items():
                    if isinstance(signal, Reading):
                        raise ValueError(
                            f"{name}[{sensor}][{channel!r}]: a {type(signal).__name__} "
                            f"reads the state, which these errors are computed without; "
                            f"give it as a waveform of time (the proof covers any lie)")
                    if not callable(signal):
                        raise ParameterTypeError(f"{name}[{sensor}][{channel!r}] must be a "
                                                 f"signal (a callable of time), got "
                                                 f"{signal!r:.80}")

    def fused(self, times: np.ndarray, seed) -> Fused:
        """The median's error and the sensors named at the control samples ``times``
        (s): :func:`fuse` of every sensor's noise (``noise``, else uniform draws seeded
        by ``seed``, an int or a sequence of ints) plus its lies.  ``ValueError`` naming
        ``noise[sensor][channel]`` if it leaves ``±bound`` at a sample."""
        times = np.asarray(times, float)
        b = np.asarray(self.array.bound)
        honest = self.array.readings(times, None, seed)      # the drawn noise, no lie
        for sensor, channels in self.noise.items():
            for channel, signal in channels.items():
                c = CHANNELS.index(channel)
                values = np.broadcast_to(np.asarray(signal(times), float), times.shape)
                if not np.all(np.abs(values) <= b[c]):
                    raise ValueError(f"noise[{sensor}][{channel!r}] must stay within "
                                     f"±{b[c]} (the array's bound: an honest sensor's "
                                     f"noise) at every control sample; give a lie as lies")
                honest[:, sensor, c] = values
        return fuse(self.array, times, self.array.readings(times, self.lies, honest=honest))

    def attacks(self, fused: Fused) -> dict[str, Signal]:
        """The fused error as the area's sensor attacks, ``{"dw_meas": ...,
        "rocof_meas": ...}`` (pu, pu/s; :class:`~lfc.signals.Samples` at ``fused.t``)."""
        return {c: Samples(fused.t, fused.error[:, i]) for i, c in enumerate(CHANNELS)}


def alarm_rows(fused: Fused) -> pd.DataFrame:
    """The alarm log's rows (``ALARM_COLUMNS``: ``t`` and ``reason``, the rest empty)
    for each reading :func:`fuse` named a lie (``"spoofed: sensor k (channel)"``) and
    each sample beyond the statement (``"beyond: more than tolerate lie
    (channel)"``), in time order."""
    parts = [pd.DataFrame({"t": f.t.to_numpy(float), "reason": reason})
             for f, reason in ((fused.spoofed, "spoofed: sensor "
                                + fused.spoofed.sensor.astype(str) + " ("
                                + fused.spoofed.channel + ")"),
                               (fused.beyond, "beyond: more than tolerate lie ("
                                + fused.beyond.channel + ")"))
             if len(f)]
    rows = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(
        {"t": np.zeros(0), "reason": np.zeros(0, object)})
    rows = rows.sort_values("t", kind="stable").reset_index(drop=True)
    for column in ("infeasible", "outside", "invalid_input", "solver_error"):
        rows[column] = False
    rows["binding"] = ""
    return rows.reindex(columns=list(ALARM_COLUMNS))


def with_sensors(sensors: dict, attacks: dict, times: np.ndarray,
                 seed) -> tuple[dict, dict[int, pd.DataFrame]]:
    """``attacks`` (``{area: {channel: signal}}``) with each area's redundant sensors
    (``sensors``, ``{area: Redundant}``) as its sensor channels' attacks — the median's
    error at the control samples ``times`` (s), the noise drawn from ``seed`` in area 0
    and ``(seed, a)`` in area ``a``, as the measurement noise is — and each such area's
    alarm-log rows (:func:`alarm_rows`)."""
    attacks, logs = dict(attacks), {}
    for a, red in sensors.items():
        fused = red.fused(times, seed if a == 0 else (seed, a))
        attacks[a] = {**attacks.get(a, {}), **red.attacks(fused)}
        logs[a] = alarm_rows(fused)
    return attacks, logs
