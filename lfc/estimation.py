"""A discrete Kalman filter for the LFC state (reproduction notes E7, E8).

The paper says the state is observable from the frequency and ROCOF
measurements and that a Kalman filter gives it, but does not design one.
This is the steady-state filter on the same model, discretized at the
controller period, with the applied command ``dPc`` as a known input and
(optionally) the unmeasured load change ``dPL`` as a random-walk state.
"""

from __future__ import annotations

import control as ct
import numpy as np

from lfc._validate import check_nonnegative, check_positive
from lfc.model import LFCParams, discretize, output_matrix


class KalmanFilter:
    """Steady-state Kalman filter (current-estimate form) on the LFC model.

    Parameters
    ----------
    params : LFCParams
        Design model.
    period : float
        Sample period (s) = controller period. Default 0.01.
    meas_std : tuple of float
        Standard deviations of the ``dw_meas`` (pu) and ``rocof_meas`` (pu/s)
        measurement noise, > 0. Default ``(1e-4, 1e-3)`` (6 mHz, 0.06 Hz/s).
    process_std : float
        Standard deviation per sample of the process noise on each model state
        (pu), > 0: how much the filter distrusts the model. Default 1e-4.
    estimate_load : bool
        Augment the state with ``dPL`` as a random walk (E7). Default True;
        otherwise the filter assumes ``dPL = 0``.
    load_std : float
        Random-walk intensity of ``dPL`` (pu per sqrt(s)), >= 0. Default 0.3.

    Raises
    ------
    ValueError
        On invalid parameters, or if the (augmented) model is not observable.
    """

    def __init__(self, params: LFCParams, period: float = 0.01, *,
                 meas_std: tuple[float, float] = (1e-4, 1e-3), process_std: float = 1e-4,
                 estimate_load: bool = True, load_std: float = 0.3) -> None:
        check_positive("period", period)
        if len(meas_std) != 2:
            raise ValueError(f"meas_std must be a pair (dw_meas, rocof_meas), got {meas_std!r}")
        for i, s in enumerate(meas_std):
            check_positive(f"meas_std[{i}]", s)
        check_positive("process_std", process_std)
        check_nonnegative("load_std", load_std)
        self.params, self.period, self.estimate_load = params, float(period), estimate_load
        self.meas_std = (float(meas_std[0]), float(meas_std[1]))
        Ad, Bd = discretize(params, period)
        C = output_matrix()
        q = np.full(5, process_std**2)
        if estimate_load:  # x_aug = [x; dPL], dPL[k+1] = dPL[k] + w
            Ad = np.block([[Ad, Bd[:, 1:2]], [np.zeros((1, 5)), np.ones((1, 1))]])
            Bd = np.vstack([Bd[:, 0:1], np.zeros((1, 1))])
            C = np.hstack([C, np.zeros((2, 1))])
            q = np.append(q, max(load_std**2 * period, 1e-12))
        else:
            Bd = Bd[:, 0:1]
        self.A, self.B, self.C = Ad, Bd, C
        self.n = Ad.shape[0]
        if np.linalg.matrix_rank(ct.obsv(Ad, C)) < self.n:
            raise ValueError("the LFC model is not observable from (dw_meas, rocof_meas)")
        R = np.diag(np.square(self.meas_std))
        _, P, _ = ct.dlqe(Ad, np.eye(self.n), C, np.diag(q), R)  # P: a-priori covariance
        self.gain = P @ C.T @ np.linalg.inv(C @ P @ C.T + R)
        self.reset()

    def __repr__(self) -> str:
        return (f"KalmanFilter(period={self.period}, meas_std={self.meas_std}, "
                f"estimate_load={self.estimate_load})")

    def reset(self) -> None:
        """Start from the equilibrium (all deviations zero)."""
        self._x_prior = np.zeros(self.n)

    def correct(self, y: np.ndarray) -> tuple[np.ndarray, float]:
        """Fuse a measurement ``y = [dw_meas, rocof_meas]`` (pu, pu/s).

        Returns
        -------
        x_hat : ndarray, shape (5,)
            Estimate of ``[dPg, dPm, dw, dw_meas, rocof_meas]``.
        p_load_hat : float
            Estimated load change (pu); 0 when ``estimate_load`` is False.
        """
        self._x_post = self._x_prior + self.gain @ (np.asarray(y, float) - self.C @ self._x_prior)
        pl = float(self._x_post[5]) if self.estimate_load else 0.0
        return self._x_post[:5].copy(), pl

    def predict(self, u: float) -> None:
        """Propagate the last corrected estimate over one period with command ``u`` (pu)."""
        self._x_prior = self.A @ self._x_post + self.B[:, 0] * u
