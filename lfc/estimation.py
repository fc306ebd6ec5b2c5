"""A discrete Kalman filter for the LFC state (reproduction notes E7, E8).

The paper says the state is observable from the frequency and ROCOF
measurements and that a Kalman filter gives it, but does not design one.
This is the steady-state filter on the same model, discretized at the
controller period, with the applied command ``dPc`` as a known input and
(optionally) the unmeasured load change ``dPL`` as a random-walk state.
"""

from __future__ import annotations

import numpy as np

from lfc._jit import inline
from lfc._validate import (ParameterTypeError, check_array, check_finite, check_flag,
                           check_integer, check_number, check_pair, check_range)
from lfc.model import LFCParams, discretize, output_matrix


@inline
def kf_correct(gain: np.ndarray, C: np.ndarray, xs: np.ndarray, y, e: np.ndarray) -> None:
    """``xs[1] = xs[0] + gain (y - C xs[0])`` (prior to posterior) for the
    measurements ``y`` (a tuple or array of ``C.shape[0]`` values); the filter has
    ``gain.shape[0]`` states; ``e`` (at least ``C.shape[0]``) is scratch space
    for the innovations."""
    n, n_y = gain.shape[0], C.shape[0]
    for m in range(n_y):
        acc = y[m]
        for k in range(n):
            acc -= C[m, k] * xs[0, k]
        e[m] = acc
    for k in range(n):
        acc = gain[k, 0] * e[0]
        for m in range(1, n_y):
            acc += gain[k, m] * e[m]
        xs[1, k] = xs[0, k] + acc


@inline
def kf_predict(A: np.ndarray, B: np.ndarray, xs: np.ndarray, u) -> None:
    """``xs[0] = A xs[1] + B u`` (posterior to the next prior, the commands ``u``
    (a tuple or array of ``B.shape[1]`` values) held)."""
    n, n_u = A.shape[0], B.shape[1]
    for i in range(n):
        acc = B[i, 0] * u[0]
        for j in range(1, n_u):
            acc += B[i, j] * u[j]
        for k in range(n):
            acc += A[i, k] * xs[1, k]
        xs[0, i] = acc


def steady_state_kalman(A: np.ndarray, C: np.ndarray, q: np.ndarray, r: np.ndarray,
                        what: str) -> tuple[np.ndarray, np.ndarray]:
    """The steady-state Kalman filter (current-estimate form) of ``x+ = A x + w``,
    ``y = C x + v`` with diagonal noise variances ``q`` (per state) and ``r``
    (per measurement): ``(gain, posterior covariance)``.

    Raises
    ------
    ValueError
        If the model is not observable from ``y``, or the Riccati equation has no
        finite solution the solver finds (``what`` names the noise models in the
        message).
    """
    import control as ct  # here, not at import: python-control loads matplotlib
    n = len(A)
    if np.linalg.matrix_rank(ct.obsv(A, C)) < n:
        raise ValueError(f"the model is not observable from its measurements ({what})")
    R = np.diag(r)
    try:
        _, P, _ = ct.dlqe(A, np.eye(n), C, np.diag(q), R)  # a-priori covariance
        gain = P @ C.T @ np.linalg.inv(C @ P @ C.T + R)
        cov = (np.eye(n) - gain @ C) @ P
        solved = np.isfinite(gain).all() and np.isfinite(cov).all()
    except (ValueError, ArithmeticError, np.linalg.LinAlgError, ct.ControlArgument):
        solved = False
    if not solved:
        raise ValueError(f"no steady-state Kalman gain for {what}: the Riccati solver fails "
                         f"on these noise models (tiny, or many decades apart); scale them "
                         f"up or bring them closer")
    return gain, cov


DEFAULT_MEAS_STD = (1e-4, 1e-3)   # pu, pu/s: a Kalman filter's noise model where none is given
# valid ranges: a noise model's standard deviations (pu, pu/s) and the sample period (s);
# beyond them the covariances over- or underflow double precision (1e300 squared is
# inf) or the sampled model loses the dynamics (a period of 10 s: unobservable)
STD = (1e-9, 1e2)
PERIOD = (1e-5, 1.0)
LOAD_STD = 0.01   # pu/sqrt(s): the load random walk's default intensity (KalmanFilter)


def check_noise_std(name: str, value: object) -> tuple[float, float]:
    """``value`` as a pair of measurement-noise standard deviations (pu, pu/s);
    raise unless each is 0 (no noise) or in ``STD`` (the range a Kalman filter
    is built for), naming ``name[i]``."""
    pair = check_pair(name, value)
    for i, s in enumerate(pair):
        if s != 0 and not STD[0] <= s <= STD[1]:
            raise ValueError(f"{name}[{i}] must be 0 (no noise) or lie in [{STD[0]}, {STD[1]}], "
                             f"got {s!r}")
    return pair


def measurement_std(noise_std: tuple[float, float]) -> tuple[float, float]:
    """The Kalman filter's measurement-noise model for measurement noise
    ``noise_std`` (pu, pu/s): each entry, or ``DEFAULT_MEAS_STD``'s where it is 0
    (a noise-free channel still needs a positive noise model)."""
    return tuple(float(s) if s > 0 else d for s, d in zip(noise_std, DEFAULT_MEAS_STD))


class KalmanFilter:
    """Steady-state Kalman filter (current-estimate form) on the LFC model.

    Parameters
    ----------
    params : LFCParams
        Design model.
    period : float
        Sample period (s) = controller period, in ``PERIOD`` = [1e-5, 1] s.
        Default 0.01.
    meas_std : tuple of float
        Standard deviations of the ``dw_meas`` (pu) and ``rocof_meas`` (pu/s)
        measurement noise, each in ``STD`` = [1e-9, 100]. Default ``(1e-4, 1e-3)``
        (6 mHz, 0.06 Hz/s).
    process_std : float
        Standard deviation per sample of the process noise on each model state
        (pu), in ``STD``: how much the filter distrusts the model. Default 1e-4.
    estimate_load : bool
        Augment the state with ``dPL`` as a random walk (E7). Default True;
        otherwise the filter assumes ``dPL = 0``.
    load_std : float
        Random-walk intensity of ``dPL`` (pu per sqrt(s)), in [0, 100]. Default 0.01: the
        estimate still tracks a 0.1 pu load step to 90 % within 0.15 s at the default
        noise, and its steady-state error is small (std 0.003 pu), which the
        certified filter's estimation bound depends on (``tests/test_estimation.py``).
        Only with ``estimate_load`` (otherwise leave it at the default).

    Attributes
    ----------
    gain : ndarray
        Steady-state Kalman gain (n x 2).
    posterior_covariance : ndarray
        Steady-state error covariance after each correction (n x n): states, then
        the load when ``estimate_load``.

    Raises
    ------
    ValueError
        On invalid parameters, if the (augmented) model is not observable, or if
        the Riccati equation has no finite solution the solver can find (noise
        models many decades apart; the message names them).
    """

    def __init__(self, params: LFCParams, period: float = 0.01, *,
                 meas_std: tuple[float, float] = DEFAULT_MEAS_STD, process_std: float = 1e-4,
                 estimate_load: bool = True, load_std: float = LOAD_STD) -> None:
        if not isinstance(params, LFCParams):
            raise ParameterTypeError(f"params must be an LFCParams, got {params!r:.80}")
        check_range("period", period, *PERIOD, closed=True)
        meas_std = check_pair("meas_std", meas_std, positive=True)
        for i, s in enumerate(meas_std):
            check_range(f"meas_std[{i}]", s, *STD, closed=True)
        check_range("process_std", process_std, *STD, closed=True)
        check_range("load_std", load_std, 0.0, STD[1], closed=True)
        estimate_load = check_flag("estimate_load", estimate_load)
        if not estimate_load and load_std != LOAD_STD:
            raise ValueError(f"load_std={load_std!r} has no effect with estimate_load=False "
                             f"(no load state to drive): leave it at its default")
        period = float(period)        # a numpy float32 is not a timebase python-control takes
        self.params, self.period, self.estimate_load = params, period, estimate_load
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
        self.A, self.B, self.C = Ad, np.ascontiguousarray(Bd[:, 0:1]), C
        self.n, self.n_y, self.n_u = Ad.shape[0], 2, 1
        self.gain, self.posterior_covariance = steady_state_kalman(
            Ad, C, q, np.square(self.meas_std),
            f"meas_std={self.meas_std}, process_std={process_std}, load_std={load_std}, "
            f"period={period}")
        self.reset()

    def __repr__(self) -> str:
        return (f"KalmanFilter(period={self.period}, meas_std={self.meas_std}, "
                f"estimate_load={self.estimate_load})")

    def reset(self) -> None:
        """Start from the equilibrium (all deviations zero)."""
        self._xs = np.zeros((2, self.n))   # prior, posterior

    def correct(self, y: np.ndarray) -> tuple[np.ndarray, float]:
        """Fuse a measurement ``y = [dw_meas, rocof_meas]`` (pu, pu/s).

        Returns
        -------
        x_hat : ndarray, shape (5,)
            Estimate of ``[dPg, dPm, dw, dw_meas, rocof_meas]``.
        p_load_hat : float
            Estimated load change (pu); 0 when ``estimate_load`` is False.
        """
        y = check_array("y", y, shape=(2,))
        if not np.all(np.isfinite(y)):
            raise ValueError(f"y must be finite (a NaN would poison every later estimate), "
                             f"got {y}")
        kf_correct(self.gain, self.C, self._xs, (float(y[0]), float(y[1])), np.zeros(2))
        pl = float(self._xs[1, 5]) if self.estimate_load else 0.0
        return self._xs[1, :5].copy(), pl

    def predict(self, u: float) -> None:
        """Propagate the last corrected estimate over one period with command ``u`` (pu)."""
        check_finite("u", u)
        kf_predict(self.A, self.B, self._xs, (float(u),))


def run_confidence(confidence: float, certifications: int) -> float:
    """A lower bound on the probability that the noise's part of the estimate's
    error lies in its ellipsoid at every one of a run's ``certifications`` (control
    samples), each with probability at least ``confidence``: the union bound ``1 -
    certifications (1 - confidence)``, at least 0 (no independence assumed).

    The probabilistic guarantees on an estimate (the certified filter's, and the
    coupled certificate's A', B', C') hold at each certification with probability
    ``confidence``; a run's figure is this one (docs/guarantees.md)."""
    _check_probability("confidence", confidence)
    check_integer("certifications", certifications, 1)
    return max(0.0, 1.0 - certifications * (1.0 - confidence))


def confidence_for_run(run: float, certifications: int) -> float:
    """The per-certification ``confidence`` whose union bound over ``certifications``
    control samples is ``run`` (:func:`run_confidence`): ``1 - (1 - run) /
    certifications``.  For example 0.99 over a minute at 10 ms: ``1 - 1.67e-6``."""
    _check_probability("run", run)
    check_integer("certifications", certifications, 1)
    confidence = 1.0 - (1.0 - run) / certifications
    while run_confidence(confidence, certifications) < run:   # rounding: never below run
        confidence = float(np.nextafter(confidence, 1.0))
    return confidence


def _check_probability(name: str, value: object) -> None:
    check_number(name, value)
    if not 0.0 < value < 1.0:
        raise ValueError(f"{name} must lie in (0, 1), got {value!r}")
