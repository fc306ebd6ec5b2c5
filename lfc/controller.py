"""The generator-side loop shared by every plant: noise, estimator, local
integral controller, attacks, SCC and the alarm log.

One :class:`GeneratorSide` serves one run.  The plant (the linear model in
:mod:`lfc.simulate` or the ANDES testbed in :mod:`lfc.testbed`) calls
:meth:`GeneratorSide.step` once per control period with its state in the design
model's coordinates and applies the returned command until the next call.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
import pandas as pd

from lfc._validate import check_nonnegative
from lfc.cbf import SafetyFilter
from lfc.estimation import KalmanFilter
from lfc.model import LFCParams

SignalLike = Callable[[np.ndarray], np.ndarray]
ALARM_COLUMNS = ("t", "u_ref", "u", "binding", "h_freq", "h_rocof", "margin_freq",
                 "margin_rocof", "infeasible", "outside", "invalid_input", "solver_error",
                 "reason")


def sample_signal(signal: SignalLike | None, t: np.ndarray, name: str) -> np.ndarray:
    """Evaluate an attack or load signal at times ``t`` (s); zeros for None.

    Raises ``ValueError`` naming ``name`` if it is not callable or returns
    non-finite values.
    """
    if signal is None:
        return np.zeros_like(t)
    if not callable(signal):
        raise ValueError(f"{name} must be a callable of time (see lfc.signals), got {signal!r}")
    values = np.broadcast_to(np.asarray(signal(t), float), t.shape).copy()
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{name} returned non-finite values")
    return values


def make_noise(noise_std: tuple[float, float], n: int, seed: int) -> np.ndarray:
    """Seeded white noise for ``n`` controller readings of (dw_meas, rocof_meas):
    shape (n, 2), std ``noise_std`` (pu, pu/s).  Raises ``ValueError`` unless it
    is a pair of values >= 0."""
    if len(noise_std) != 2:
        raise ValueError(f"noise_std must be a pair (dw_meas, rocof_meas), got {noise_std!r}")
    for i, s in enumerate(noise_std):
        check_nonnegative(f"noise_std[{i}]", s)
    return np.random.default_rng(seed).standard_normal((n, 2)) * np.asarray(noise_std, float)


def make_estimator(estimator: object, params: LFCParams, control_period: float,
                   noise_std: tuple[float, float]) -> KalmanFilter | None:
    """None, a fresh Kalman filter for ``"kalman"``, or the given one reset."""
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


class GeneratorSide:
    """Everything at the generator that runs every control period.

    Parameters
    ----------
    params : LFCParams
        Design model (the local controller's gain ``k_i`` is read from it).
    scc : SafetyFilter or None
    kf : KalmanFilter or None
        None gives the SCC the plant's state as it is.
    tc : ndarray
        Control sample times (s), uniform with step ``period``.
    pc_attack, wref_attack : ndarray
        The attacks sampled at ``tc`` (pu).
    noise : ndarray, shape (len(tc), 2)
        Noise added to the controller's (dw_meas, rocof_meas) readings.
    load_feedforward : bool
        Without an estimator, give the SCC the true load (E7) instead of 0.
    """

    def __init__(self, params: LFCParams, scc: SafetyFilter | None, kf: KalmanFilter | None,
                 tc: np.ndarray, pc_attack: np.ndarray, wref_attack: np.ndarray,
                 noise: np.ndarray, load_feedforward: bool) -> None:
        self.params, self.scc, self.kf = params, scc, kf
        if scc is not None:
            scc.reset()  # a filter with memory (method="certified") starts afresh
        self.tc, self.pc_attack, self.wref = tc, pc_attack, wref_attack
        self.noise, self.load_feedforward = noise, load_feedforward
        self.period = float(tc[1] - tc[0]) if len(tc) > 1 else 0.0
        self.rows = np.full((len(tc), 6), np.nan)  # pc_ref, pc, active, dw^, rocof^, pL^
        self.alarms: list[dict] = []
        self.pc_int = 0.0
        self.n_done = 0

    def step(self, j: int, x: np.ndarray, p_load: float) -> float:
        """Control sample ``j``: read the plant state ``x`` (design-model
        coordinates, pu) and the true load (pu), return the command to hold (pu)."""
        y = x[3:5] + self.noise[j]
        if self.kf is not None:
            x_hat, pl_hat = self.kf.correct(y)
        else:
            x_hat, pl_hat = x, (float(p_load) if self.load_feedforward else 0.0)
        u_ref = self.pc_int + self.pc_attack[j]
        u, active = self._filter(float(self.tc[j]), x_hat, u_ref, pl_hat)
        self.pc_int += self.params.k_i * self.period * (self.wref[j] - y[0])
        if self.kf is not None:
            self.kf.predict(u)
        self.rows[j] = (u_ref, u, active, x_hat[3], x_hat[4], pl_hat)
        self.n_done = j + 1
        return u

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

    def held(self, t: np.ndarray) -> np.ndarray:
        """Index of the control sample whose command is held at each time ``t``."""
        idx = np.searchsorted(self.tc, np.asarray(t) + 1e-9, side="right") - 1
        return np.clip(idx, 0, max(self.n_done - 1, 0))

    def add_to_trace(self, trace: pd.DataFrame) -> None:
        """Add ``pc_ref``, ``pc``, ``wref`` and ``scc_active`` (held values) to ``trace``."""
        k = self.held(trace["t"].to_numpy())
        trace.insert(1, "pc_ref", self.rows[k, 0])
        trace.insert(2, "pc", self.rows[k, 1])
        trace["wref"] = self.wref[k]
        trace["scc_active"] = self.rows[k, 2].astype(bool)

    def controls(self, t_end: float) -> pd.DataFrame:
        """One row per control sample taken up to ``t_end`` (s)."""
        n = min(self.n_done, int(np.searchsorted(self.tc, t_end + 1e-9, side="right")))
        r = self.rows[:n]
        return pd.DataFrame({"t": self.tc[:n], "pc_ref": r[:, 0], "pc": r[:, 1],
                             "scc_active": r[:, 2].astype(bool), "dw_hat": r[:, 3],
                             "rocof_hat": r[:, 4], "p_load_hat": r[:, 5]})

    def alarm_log(self, t_end: float) -> pd.DataFrame:
        """The alarms raised up to ``t_end`` (s), columns ``ALARM_COLUMNS``."""
        alarms = pd.DataFrame(self.alarms, columns=list(ALARM_COLUMNS))
        return alarms[alarms["t"] <= t_end + 1e-9].reset_index(drop=True)
