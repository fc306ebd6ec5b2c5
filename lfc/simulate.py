"""Closed-loop simulation of the LFC plant, local controller, SCC and relays.

Timing: the plant is advanced exactly (zero-order hold) every ``dt``; the
local controller, the network command (with any attack) and the SCC run every
``control_period`` and hold their command in between.  Relays watch the
measured signals at every plant step.  Trips are recorded and the run goes on
(as in the paper, "to show the SCC's continuity") unless ``stop_on_trip``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from lfc._validate import check_multiple, check_positive
from lfc.cbf import SafetyFilter
from lfc.controller import (ALARM_COLUMNS, GeneratorSide, SignalLike, make_estimator,
                            make_noise, sample_signal)
from lfc.estimation import KalmanFilter
from lfc.model import STATES, LFCParams, block_propagator, discretize
from lfc.relays import RelayBank, RelaySettings

__all__ = ["ALARM_COLUMNS", "METRIC_KEYS", "SimResult", "check_timing", "simulate"]
METRIC_KEYS = ("tripped", "first_trip", "max_abs_dw_meas", "max_abs_rocof_meas",
               "scc_active_fraction", "max_abs_modification", "alarms")


@dataclass
class SimResult:
    """Outcome of one simulation.

    Attributes
    ----------
    trace : DataFrame
        Every plant step: ``t`` (s), ``pc_ref`` and ``pc`` (incoming and applied
        command, pu), the states ``dPg, dPm, dw, dw_meas`` (pu) and
        ``rocof_meas`` (pu/s), ``p_load`` (pu), ``wref`` (pu) and
        ``scc_active`` (bool).
    controls : DataFrame
        Every controller sample: ``t``, ``pc_ref``, ``pc``, ``scc_active``, and
        the SCC's view of the state ``dw_hat``, ``rocof_hat`` and ``p_load_hat``.
    trips : DataFrame
        Every relay trip: ``relay`` and ``t`` (s).
    alarms : DataFrame
        Every SCC alarm (an intervention or a flagged condition), columns
        ``ALARM_COLUMNS``: the paper's log for learning attacker strategies.
    settings : dict
        What the run was called with (JSON-serializable).
    line_trips : DataFrame
        Line protection operations (ANDES testbed only): ``line``, ``trip_t``
        (relay decision, s) and ``open_t`` (breaker open, s).
    """

    trace: pd.DataFrame
    controls: pd.DataFrame
    trips: pd.DataFrame
    alarms: pd.DataFrame
    settings: dict = field(default_factory=dict)
    line_trips: pd.DataFrame = field(
        default_factory=lambda: pd.DataFrame(columns=["line", "trip_t", "open_t"]))

    def metrics(self) -> dict:
        """Summary numbers (JSON-serializable), keys ``METRIC_KEYS``."""
        first = None
        if len(self.trips):
            row = self.trips.sort_values("t", kind="stable").iloc[0]
            first = {"relay": str(row["relay"]), "t": float(row["t"])}
        mod = (self.controls["pc"] - self.controls["pc_ref"]).abs()
        return {
            "tripped": bool(len(self.trips) > 0),
            "first_trip": first,
            "max_abs_dw_meas": float(self.trace["dw_meas"].abs().max()),
            "max_abs_rocof_meas": float(self.trace["rocof_meas"].abs().max()),
            "scc_active_fraction": float(self.controls["scc_active"].mean()),
            "max_abs_modification": float(mod.max()) if len(mod) else 0.0,
            "alarms": int(len(self.alarms)),
        }

    def save(self, directory: str | Path) -> Path:
        """Write ``trace.csv``, ``controls.csv``, ``trips.csv``, ``alarms.csv``,
        ``line_trips.csv``, ``metrics.json`` and ``settings.json`` into
        ``directory`` (created)."""
        out = Path(directory)
        out.mkdir(parents=True, exist_ok=True)
        for name in ("trace", "controls", "trips", "alarms", "line_trips"):
            getattr(self, name).to_csv(out / f"{name}.csv", index=False)
        (out / "metrics.json").write_text(json.dumps(self.metrics(), indent=2))
        (out / "settings.json").write_text(json.dumps(self.settings, indent=2, default=str))
        return out


def check_timing(duration: float, dt: float, control_period: float) -> int:
    """Validate a run's timing (s); return plant steps per control period."""
    check_positive("duration", duration)
    return check_multiple("control_period", control_period, "dt", dt)


def simulate(params: LFCParams, *, duration: float, pc_attack: SignalLike | None = None,
             wref_attack: SignalLike | None = None, load: SignalLike | None = None,
             scc: SafetyFilter | None = None, relays: RelaySettings | None = None,
             estimator: str | KalmanFilter | None = None,
             noise_std: tuple[float, float] = (0.0, 0.0), seed: int = 0, dt: float = 1e-3,
             control_period: float = 0.01, stop_on_trip: bool = False,
             load_feedforward: bool = False) -> SimResult:
    """Simulate the closed loop from equilibrium.

    Parameters
    ----------
    params : LFCParams
        Plant (and local controller) parameters.
    duration : float
        Simulated time (s), > 0.
    pc_attack : callable, optional
        Added to the governor command dPc that arrives from the network (pu).
    wref_attack : callable, optional
        Corrupts the frequency reference dw_ref of the local integral
        controller ``d dPc/dt = k_i (dw_ref - dw_meas)`` (pu).
    load : callable, optional
        Load change dPL (pu).
    scc : SafetyFilter, optional
        The safety filter; None runs without SCC.
    relays : RelaySettings, optional
        Default IEEE 1547 Cat. III.
    estimator : None, "kalman" or KalmanFilter
        None gives the SCC the true state; "kalman" a Kalman filter's estimate
        (its measurement-noise model taken from ``noise_std`` where > 0).
    noise_std : (float, float)
        Std of white noise on the controller's ``dw_meas`` (pu) and
        ``rocof_meas`` (pu/s) readings. The relays see the noise-free signals.
    seed : int
        Seed of the noise generator.
    dt : float
        Plant step (s). Default 1 ms.
    control_period : float
        Controller/SCC period (s), an integer multiple of ``dt``. Default 10 ms.
    stop_on_trip : bool
        End the run at the first relay trip.
    load_feedforward : bool
        With ``estimator=None``, give the SCC the true dPL (an idealized load
        measurement) instead of 0 (E7: dPL is not measured at the generator).

    Returns
    -------
    SimResult
    """
    ratio = check_timing(duration, dt, control_period)
    relays = relays if relays is not None else RelaySettings()
    loop = _Loop(params, ratio, dt, int(round(duration / dt)))
    noise = make_noise(noise_std, loop.n_ctrl, seed)
    kf = make_estimator(estimator, params, control_period, noise_std)
    gen = GeneratorSide(params, scc, kf, loop.tc, sample_signal(pc_attack, loop.tc, "pc_attack"),
                        sample_signal(wref_attack, loop.tc, "wref_attack"), noise,
                        load_feedforward)
    loop.run(gen, load, RelayBank(relays), stop_on_trip)
    settings = {"params": vars(params), "relays": vars(relays), "duration": duration,
                "dt": dt, "control_period": control_period, "seed": seed,
                "noise_std": list(noise_std), "scc": repr(scc), "estimator": repr(estimator),
                "pc_attack": repr(pc_attack), "wref_attack": repr(wref_attack),
                "load": repr(load), "stop_on_trip": stop_on_trip,
                "load_feedforward": load_feedforward}
    return loop.result(gen, settings)


class _Loop:
    """The linear plant of one closed-loop run (internal to :func:`simulate`)."""

    def __init__(self, params: LFCParams, ratio: int, dt: float, n_steps: int) -> None:
        self.ratio, self.dt, self.n_steps = ratio, dt, n_steps
        self.n_ctrl = -(-n_steps // ratio)
        self.t = np.arange(n_steps + 1) * dt
        self.tc = np.arange(self.n_ctrl) * ratio * dt
        Ad, Bd = discretize(params, dt)
        self.Phi, self.Gu, self.Gl = block_propagator(Ad, Bd, ratio)
        self.X = np.zeros((n_steps + 1, 5))
        self.trips: list[tuple[str, float]] = []
        self.end = n_steps  # last plant sample index kept

    def run(self, gen: GeneratorSide, load, bank: RelayBank, stop_on_trip: bool) -> None:
        self.p_load = sample_signal(load, self.t, "load")
        for j in range(self.n_ctrl):
            k0 = j * self.ratio
            u = gen.step(j, self.X[k0], self.p_load[k0])
            k1 = min(k0 + self.ratio, self.n_steps)
            self._advance(k0, k1, u)
            if stop_on_trip and self._check_relays(bank, k0 + (j > 0), k1 + 1):
                self.end = int(np.searchsorted(self.t, self.trips[0][1]))
                return
        if not stop_on_trip:
            self._check_relays(bank, 0, self.n_steps + 1)

    def _advance(self, k0: int, k1: int, u: float) -> None:
        m = k1 - k0
        pl = np.zeros(self.ratio)
        pl[:m] = self.p_load[k0:k1]
        block = self.Phi @ self.X[k0] + self.Gu * u + self.Gl @ pl
        self.X[k0 + 1:k1 + 1] = block.reshape(self.ratio, 5)[:m]

    def _check_relays(self, bank: RelayBank, k0: int, k1: int) -> bool:
        """Feed plant samples ``k0:k1`` to the relays; True if any tripped."""
        found = bank.update(self.t[k0:k1], self.X[k0:k1, 3], self.X[k0:k1, 4])
        for relay, k, _ in sorted(found, key=lambda r: r[1]):
            self.trips.append((relay, float(self.t[k0 + k])))
        return bool(found)

    def result(self, gen: GeneratorSide, settings: dict) -> SimResult:
        end = self.end
        trace = pd.DataFrame({"t": self.t[: end + 1]})
        for i, name in enumerate(STATES):
            trace[name] = self.X[: end + 1, i]
        trace["p_load"] = self.p_load[: end + 1]
        gen.add_to_trace(trace)
        t_end = float(self.t[end])
        trips = pd.DataFrame(self.trips, columns=["relay", "t"])
        return SimResult(trace, gen.controls(t_end), trips, gen.alarm_log(t_end), settings)
