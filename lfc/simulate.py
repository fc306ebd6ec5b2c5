"""Closed-loop simulation of the LFC plant, local controller, SCC and relays.

Timing: the plant is advanced exactly (zero-order hold) every ``dt``; the
local controller, the network command (with any attack) and the SCC run every
``control_period`` and hold their command in between.  Relays watch the
measured signals at every plant step.  Trips are recorded and the run goes on
(as in the paper, "to show the SCC's continuity") unless ``stop_on_trip``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd

from lfc._validate import check_nonnegative, check_positive
from lfc.cbf import SafetyFilter
from lfc.estimation import KalmanFilter
from lfc.model import STATES, LFCParams, block_propagator, discretize
from lfc.relays import RelayBank, RelaySettings

SignalLike = Callable[[np.ndarray], np.ndarray]
METRIC_KEYS = ("tripped", "first_trip", "max_abs_dw_meas", "max_abs_rocof_meas",
               "scc_active_fraction", "max_abs_modification", "alarms")
ALARM_COLUMNS = ("t", "u_ref", "u", "binding", "h_freq", "h_rocof", "margin_freq",
                 "margin_rocof", "infeasible", "outside", "invalid_input", "solver_error",
                 "reason")


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
    """

    trace: pd.DataFrame
    controls: pd.DataFrame
    trips: pd.DataFrame
    alarms: pd.DataFrame
    settings: dict = field(default_factory=dict)

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
        ``metrics.json`` and ``settings.json`` into ``directory`` (created)."""
        out = Path(directory)
        out.mkdir(parents=True, exist_ok=True)
        for name in ("trace", "controls", "trips", "alarms"):
            getattr(self, name).to_csv(out / f"{name}.csv", index=False)
        (out / "metrics.json").write_text(json.dumps(self.metrics(), indent=2))
        (out / "settings.json").write_text(json.dumps(self.settings, indent=2, default=str))
        return out


def _check_timing(duration: float, dt: float, control_period: float) -> int:
    check_positive("duration", duration)
    check_positive("dt", dt)
    check_positive("control_period", control_period)
    ratio = control_period / dt
    if abs(ratio - round(ratio)) > 1e-9 * ratio or round(ratio) < 1:
        raise ValueError(f"control_period must be a positive integer multiple of dt "
                         f"({dt}), got {control_period}")
    return int(round(ratio))


def _make_estimator(estimator: object, params: LFCParams, control_period: float,
                    noise_std: tuple[float, float]) -> KalmanFilter | None:
    if estimator is None:
        return None
    if estimator == "kalman":
        meas = tuple(s if s > 0 else d for s, d in zip(noise_std, (1e-4, 1e-3)))
        return KalmanFilter(params, control_period, meas_std=meas)
    if isinstance(estimator, KalmanFilter):
        if not math.isclose(estimator.period, control_period):
            raise ValueError(f"estimator.period ({estimator.period}) must equal "
                             f"control_period ({control_period})")
        estimator.reset()
        return estimator
    raise ValueError(f"estimator must be None, 'kalman' or a KalmanFilter, got {estimator!r}")


def _sample(signal: SignalLike | None, t: np.ndarray, name: str) -> np.ndarray:
    if signal is None:
        return np.zeros_like(t)
    if not callable(signal):
        raise ValueError(f"{name} must be a callable of time (see lfc.signals), got {signal!r}")
    values = np.broadcast_to(np.asarray(signal(t), float), t.shape).copy()
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{name} returned non-finite values")
    return values


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
    ratio = _check_timing(duration, dt, control_period)
    if len(noise_std) != 2:
        raise ValueError(f"noise_std must be a pair (dw_meas, rocof_meas), got {noise_std!r}")
    for i, s in enumerate(noise_std):
        check_nonnegative(f"noise_std[{i}]", s)
    relays = relays if relays is not None else RelaySettings()
    kf = _make_estimator(estimator, params, control_period, noise_std)
    loop = _Loop(params, scc, kf, ratio, dt, int(round(duration / dt)),
                 np.random.default_rng(seed), np.asarray(noise_std, float), load_feedforward)
    loop.run(pc_attack, wref_attack, load, RelayBank(relays), stop_on_trip)
    settings = {"params": vars(params), "relays": vars(relays), "duration": duration,
                "dt": dt, "control_period": control_period, "seed": seed,
                "noise_std": list(noise_std), "scc": repr(scc), "estimator": repr(estimator),
                "pc_attack": repr(pc_attack), "wref_attack": repr(wref_attack),
                "load": repr(load), "stop_on_trip": stop_on_trip,
                "load_feedforward": load_feedforward}
    return loop.result(settings)


class _Loop:
    """State of one closed-loop run (internal to :func:`simulate`)."""

    def __init__(self, params: LFCParams, scc: SafetyFilter | None,
                 kf: KalmanFilter | None, ratio: int, dt: float, n_steps: int,
                 rng: np.random.Generator, noise_std: np.ndarray,
                 load_feedforward: bool) -> None:
        self.params, self.scc, self.kf, self.ratio, self.dt = params, scc, kf, ratio, dt
        self.n_steps, self.load_feedforward = n_steps, load_feedforward
        self.n_ctrl = -(-n_steps // ratio)
        self.t = np.arange(n_steps + 1) * dt
        self.tc = np.arange(self.n_ctrl) * ratio * dt
        Ad, Bd = discretize(params, dt)
        self.Phi, self.Gu, self.Gl = block_propagator(Ad, Bd, ratio)
        self.noise = rng.standard_normal((self.n_ctrl, 2)) * noise_std
        self.X = np.zeros((n_steps + 1, 5))
        self.ctrl = np.full((self.n_ctrl, 6), np.nan)  # pc_ref, pc, active, dw^, rocof^, pL^
        self.alarms: list[dict] = []
        self.trips: list[tuple[str, float]] = []
        self.end = n_steps  # last plant sample index kept

    def run(self, pc_attack, wref_attack, load, bank: RelayBank, stop_on_trip: bool) -> None:
        pc_att = _sample(pc_attack, self.tc, "pc_attack")
        wref = _sample(wref_attack, self.tc, "wref_attack")
        self.p_load = _sample(load, self.t, "load")
        self.wref = wref
        pc_int = 0.0
        for j in range(self.n_ctrl):
            k0 = j * self.ratio
            x = self.X[k0]
            y = x[3:5] + self.noise[j]
            x_hat, pl_hat = self._estimate(x, y, k0)
            u_ref = pc_int + pc_att[j]
            u, active = self._filter(self.tc[j], x_hat, u_ref, pl_hat)
            pc_int += self.params.k_i * self.ratio * self.dt * (wref[j] - y[0])
            if self.kf is not None:
                self.kf.predict(u)
            self.ctrl[j] = (u_ref, u, active, x_hat[3], x_hat[4], pl_hat)
            k1 = min(k0 + self.ratio, self.n_steps)
            self._advance(k0, k1, u)
            if stop_on_trip and self._check_relays(bank, k0 + (j > 0), k1 + 1):
                self.end = int(np.searchsorted(self.t, self.trips[0][1]))
                return
        if not stop_on_trip:
            self._check_relays(bank, 0, self.n_steps + 1)

    def _estimate(self, x: np.ndarray, y: np.ndarray, k: int) -> tuple[np.ndarray, float]:
        if self.kf is not None:
            return self.kf.correct(y)
        return x, (float(self.p_load[k]) if self.load_feedforward else 0.0)

    def _filter(self, t: float, x_hat: np.ndarray, u_ref: float, pl_hat: float
                ) -> tuple[float, bool]:
        if self.scc is None:
            return u_ref, False
        u, info = self.scc.filter(x_hat, u_ref, pl_hat)
        if info.alarm:
            self.alarms.append({"t": t, "u_ref": u_ref, "u": u, "binding": ";".join(info.binding),
                                "h_freq": info.h_freq, "h_rocof": info.h_rocof,
                                "margin_freq": info.margin_freq,
                                "margin_rocof": info.margin_rocof,
                                "infeasible": info.infeasible, "outside": info.outside,
                                "invalid_input": info.invalid_input,
                                "solver_error": info.solver_error, "reason": info.reason})
        return u, info.active

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

    def result(self, settings: dict) -> SimResult:
        end = self.end
        stopped = end < self.n_steps
        n_ctrl = min(end // self.ratio + 1, self.n_ctrl)
        ctrl = self.ctrl[:n_ctrl]
        held = np.minimum(np.arange(end + 1) // self.ratio, self.n_ctrl - 1)  # control sample
        trace = pd.DataFrame({"t": self.t[: end + 1]})
        trace["pc_ref"], trace["pc"] = self.ctrl[held, 0], self.ctrl[held, 1]
        for i, name in enumerate(STATES):
            trace[name] = self.X[: end + 1, i]
        trace["p_load"], trace["wref"] = self.p_load[: end + 1], self.wref[held]
        trace["scc_active"] = self.ctrl[held, 2].astype(bool)
        controls = pd.DataFrame({"t": self.tc[:n_ctrl], "pc_ref": ctrl[:, 0], "pc": ctrl[:, 1],
                                 "scc_active": ctrl[:, 2].astype(bool), "dw_hat": ctrl[:, 3],
                                 "rocof_hat": ctrl[:, 4], "p_load_hat": ctrl[:, 5]})
        trips = pd.DataFrame(self.trips, columns=["relay", "t"])
        alarms = pd.DataFrame(self.alarms, columns=list(ALARM_COLUMNS))
        if stopped:
            alarms = alarms[alarms["t"] <= self.t[end]]
        return SimResult(trace, controls, trips, alarms, settings)
