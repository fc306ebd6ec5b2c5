"""The coupled certificate's sets, built once per grid: :class:`CoupledSet`.

Its options (:class:`CoupledOptions`), the reduced model of the grid
(:func:`reduced_model`: the tie-line flows' reachable subspace), the held grid a
vector of commands drives, the grid-wide Kalman filter (:class:`GridKalman`), the rows of the certificate's sample checks with their
tightenings, its terminal ellipsoid (:func:`shaped_terminal`) and the bound on the
estimate's error that a load leaves (:class:`LoadErrors`).  The proofs:
``docs/coupled-certificate.md``; the filter that uses them:
:mod:`lfc.filters.coupled`.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm, solve_continuous_lyapunov

from lfc._validate import (check_flag, check_nonnegative, check_number, check_positive,
                           check_range)
from lfc.estimation import LOAD_STD, check_noise_std, measurement_std, steady_state_kalman
from lfc.filters.base import check_limits
from lfc.filters.bounds import curvature_gains, expm_at, intersample, merge_intervals, pair
from lfc.filters.certified import NUMERIC_MARGIN, grid, rate_bound
from lfc.filters.coupled_kernel import DW, HEAD, LIFT, ROCOF
from lfc.filters.responses import load_gains, period_step_gain
from lfc.model import zoh
from lfc.multiarea import N_AREA_STATES, MultiAreaParams, reduced_model
from lfc.relays import RelaySettings

EXPORT_STD = 1e-4    # pu: the grid Kalman filter's noise model of the metered tie-line exports
ERROR_OFFSETS = 11   # instants in a control period at which the error lemma steps a load
BENDS = 11            # instants in a control period at which it bounds the steps' curvature
Q_FLOORS = (1e-12, 1e-6, 1e-5, 1e-4)   # shaped_terminal's floors on Q's eigenvalues, in turn
TERMINALS = ("auto", "lyapunov", "sdp")
HELD_LEVELS = ("sharp", "widened", "strict")


@dataclass(frozen=True)
class CoupledOptions:
    """Options of the coupled certificate (module docstring).

    Parameters
    ----------
    load_bound : float
        Total variation of the loads, summed over the areas, that a new vector
        of commands leaves room for from its certification on (pu), >= 0.
        Default 0.06 pu: a held vector's re-check absorbs ``load_bound -
        recheck_bound`` = 0.05 pu since its certification, one 0.05 pu step in
        any area.
    recheck_bound : float
        Total variation of the loads within one control period that the held
        vector's re-check covers (pu), in [0, ``load_bound``]; the guarantee's
        assumption.  Default 0.01 pu.
    horizon : float
        Look-ahead before the terminal ellipsoid (s), in [0.2, 20].  Default 8 s.
        On the estimate, a horizon that builds may still leave new vectors almost
        no radius (``data[RHO_NEW]``), which holds legitimate AGC after a load
        step: Kundur as fitted to ANDES needs 16 s, not the 12 that build
        (:meth:`lfc.filters.coupled.CoupledFilter.held_after_step` measures it;
        ``docs/coupled-certificate.md``, "With estimates", Cost).  :class:`~lfc.filters.coupled.CoupledFilter` also
        takes ``"auto"``: the shortest of :data:`lfc.filters.coupled.AUTO_HORIZONS`
        whose certificate builds and holds a legitimate step at most
        :data:`lfc.filters.coupled.AUTO_HELD_MAX` (1 s); its default on a model with
        a ``load_mismatch`` (and ``mismatch_budget``).
    tightening : float
        How far (fraction of each limit) an output may move between two
        certificate samples, in [1e-4, 0.1]; sets their spacing.  Default 0.005.
    margin : float
        Extra fractional tightening of every limit, in [0, 1).  Default 0.
    u_min, u_max : float
        Limits on every area's command (pu), ``u_min <= 0 <= u_max``.
        :class:`~lfc.filters.coupled.CoupledFilter`'s default:
        ``∓params.command_range`` (the range its design model holds in, :class:`lfc.multiarea.MultiAreaParams`; ∓∞
        but for a model fitted to ANDES).
    control_period : float
        Period of the calls (s), in (0, 1].  Default 0.01 s.
    noise_std : (float, float) or None
        The measurement noise (std of every area's ``dw_meas``, pu, and
        ``rocof_meas``, pu/s) of the grid Kalman estimate the filters are given
        (:class:`GridKalman`); None (default): the exact state and loads.  Each
        entry 0 or in :data:`lfc.estimation.STD`.
    confidence : float
        Probability, in (0, 1), that the estimate's error lies in the ellipsoid
        the certificate covers (chi-square of the error covariance's dimension).
        Default 0.9999.  Only with ``noise_std``.
    held_level : {"sharp", "widened", "strict"}
        The held re-check's level on the estimate (``docs/coupled-certificate.md``,
        "With estimates").  ``"sharp"`` (default): the exact state's, tightened by
        the noise's part of the error; it flags ``outside`` early when the loads
        move beyond the bounds, and sometimes with nothing wrong (just after a
        load step the estimator has not yet seen).  ``"widened"``: widened by what
        the error may move the re-check; proven never to flag ``outside`` while the
        loads' total variation is at most ``load_bound - recheck_bound`` and the
        noise's part lies in its ellipsoid (theorem C'), but blind to moderate
        excesses (a 0.1 pu step that trips, unflagged).  ``"strict"``: the sharp
        level, and on the rows of the coming control period (new and held) less
        what the loads may have moved the error if every period's load variation
        has been at most ``recheck_bound``; proven (theorem B') that a vector
        applied there keeps every output within its limit over the coming period
        while every period's variation is at most ``recheck_bound`` and the
        noise's part lies in its ellipsoid.  Only with ``noise_std``.
    terminal : {"auto", "lyapunov", "sdp"}
        The terminal ellipsoid: ``"lyapunov"`` solves ``A'P + PA = -W`` (W from
        the relay limits); ``"sdp"`` shapes it (:func:`shaped_terminal`) so that a
        load moves the state at the horizon as little as possible in its norm;
        ``"auto"`` (default) takes the Lyapunov one and the shaped one where the
        Lyapunov one leaves no room (a lightly damped area, chains of areas).
    mismatch_budget : bool
        Add the design model's ``load_mismatch`` (pu: how far a model fitted to
        ANDES is from it, as load, :class:`lfc.multiarea.MultiAreaParams`) to
        ``load_bound`` (default True: a new vector leaves room for the loads and the
        fit's mismatch; a held one's re-check absorbs ``load_bound -
        recheck_bound`` and the mismatch).  0 for a model that is its plant.
        :class:`~lfc.filters.coupled.CoupledFilter` applies it; ``False`` gives the
        certificate of ``load_bound`` alone.
    """

    load_bound: float = 0.06
    recheck_bound: float = 0.01
    horizon: float = 8.0
    tightening: float = 0.005
    margin: float = 0.0
    u_min: float = -math.inf
    u_max: float = math.inf
    control_period: float = 0.01
    noise_std: tuple[float, float] | None = None
    confidence: float = 0.9999
    held_level: str = "sharp"
    terminal: str = "auto"
    mismatch_budget: bool = True

    def __post_init__(self) -> None:
        check_flag("mismatch_budget", self.mismatch_budget)
        if self.terminal not in TERMINALS:
            raise ValueError(f"terminal must be one of {TERMINALS}, got {self.terminal!r}")
        check_nonnegative("load_bound", self.load_bound)
        check_nonnegative("recheck_bound", self.recheck_bound)
        if self.recheck_bound > self.load_bound:
            raise ValueError(f"recheck_bound={self.recheck_bound!r} must be <= load_bound="
                             f"{self.load_bound!r}: a new vector's first period is covered "
                             f"by load_bound")
        check_range("horizon", self.horizon, 0.2, 20.0, closed=True)
        check_range("tightening", self.tightening, 1e-4, 0.1, closed=True)
        check_number("margin", self.margin)
        if not 0.0 <= self.margin < 1.0:
            raise ValueError(f"margin must be in [0, 1), got {self.margin!r}")
        check_limits(self.u_min, self.u_max)
        if not self.u_min <= 0.0 <= self.u_max:
            raise ValueError(f"u_min <= 0 <= u_max is required (the filters start by holding "
                             f"the equilibrium commands 0), got u_min={self.u_min!r}, "
                             f"u_max={self.u_max!r}")
        check_positive("control_period", self.control_period)
        if self.control_period > 1.0:
            raise ValueError(f"control_period must lie in (0, 1] s, got "
                             f"{self.control_period!r}")
        if self.noise_std is not None:
            object.__setattr__(self, "noise_std", check_noise_std("noise_std", self.noise_std))
        check_range("confidence", self.confidence, 0.0, 1.0)
        if self.held_level not in HELD_LEVELS:
            raise ValueError(f"held_level must be one of {HELD_LEVELS}, got "
                             f"{self.held_level!r}")
        if self.noise_std is None and self.held_level != "sharp":
            raise ValueError(f"held_level={self.held_level!r} has no effect without noise_std "
                             f"(the exact state): leave it at its default")
        if self.noise_std is None and self.confidence != 0.9999:
            raise ValueError(f"confidence={self.confidence!r} has no effect without noise_std "
                             f"(the exact state): leave it at its default")


def held_grid(params: MultiAreaParams, needs: str) -> tuple[np.ndarray, ...]:
    """:func:`reduced_model`, and a ``ValueError`` (ending with ``needs``) unless
    the grid with every command held is asymptotically stable."""
    A, Bu, Bl, R = reduced_model(params)
    growth = float(np.max(np.linalg.eigvals(A).real))
    if growth >= 0:
        raise ValueError(f"the grid {params!r} with every command held is not "
                         f"asymptotically stable (eigenvalue real part {growth:.3g} 1/s); "
                         f"{needs}")
    return A, Bu, Bl, R


def output_rows(n_areas: int, n_states: int) -> np.ndarray:
    """``C`` (2 n_areas, n_states): area ``a``'s measured frequency (row ``2a``)
    and ROCOF (row ``2a + 1``)."""
    C = np.zeros((2 * n_areas, n_states))
    for a in range(n_areas):
        C[2 * a, N_AREA_STATES * a + DW] = C[2 * a + 1, N_AREA_STATES * a + ROCOF] = 1.0
    return C


class GridKalman:
    """The grid-wide steady-state Kalman filter the coupled filters share.

    On the reduced model (:func:`reduced_model`) discretized at the control
    period, with every area's load as a random walk (as
    :class:`lfc.estimation.KalmanFilter` does for one area), it fuses every
    area's ``dw_meas`` and ``rocof_meas`` and every area's metered tie-line
    export (the measurement the AGC already reads) at each control sample.
    The tie-line flows are states of its model, so the inter-area swing is
    predicted, not a disturbance to it.

    Parameters
    ----------
    params : MultiAreaParams
    period : float
        Control period (s).
    noise_std : (float, float)
        Measurement noise std of every area's ``dw_meas`` (pu) and ``rocof_meas``
        (pu/s); 0 takes :data:`lfc.estimation.DEFAULT_MEAS_STD`'s entry
        (:func:`lfc.estimation.measurement_std`).  Exports: ``EXPORT_STD`` pu.
    process_std : float
        Process noise std per sample on each model state (pu).  Default 1e-4,
        the single-area filter's.
    load_std : float
        Random-walk intensity of each load (pu per sqrt(s)).  Default
        :data:`lfc.estimation.LOAD_STD`.

    Attributes
    ----------
    A, B, C, gain : ndarray
        ``x+ = A x + B u`` (``x``: reduced states then loads, ``u``: every area's
        command), measurements ``C x`` (``dw_meas``, ``rocof_meas`` of each area in
        turn, then each area's export), the steady-state gain.
    posterior_covariance : ndarray
        The error covariance after each correction.
    n, n_y, n_u : int
        Number of states, measurements and inputs.
    """

    def __init__(self, params: MultiAreaParams, period: float, noise_std: tuple[float, float],
                 *, process_std: float = 1e-4, load_std: float = LOAD_STD) -> None:
        A, Bu, Bl, R = reduced_model(params)
        n_r, n_a, head = len(A), params.n_areas, N_AREA_STATES * params.n_areas
        Ad, Bd = zoh(A, np.hstack([Bu, Bl]), period)
        self.A = np.block([[Ad, Bd[:, n_a:]], [np.zeros((n_a, n_r)), np.eye(n_a)]])
        self.B = np.vstack([Bd[:, :n_a], np.zeros((n_a, n_a))])
        exports = np.zeros((n_a, n_r))
        exports[:, head:] = params.incidence() @ R[head:, head:].T
        self.C = np.hstack([np.vstack([output_rows(n_a, n_r), exports]),
                            np.zeros((3 * n_a, n_a))])
        meas = measurement_std(noise_std)
        r = np.concatenate([np.tile(np.square(meas), n_a), np.full(n_a, EXPORT_STD ** 2)])
        q = np.concatenate([np.full(n_r, process_std ** 2),
                            np.full(n_a, max(load_std ** 2 * period, 1e-12))])
        self.gain, self.posterior_covariance = steady_state_kalman(
            self.A, self.C, q, r, f"noise_std={tuple(noise_std)}, period={period}")
        self.n, self.n_y, self.n_u, self.period = len(self.A), 3 * n_a, n_a, float(period)

    def __repr__(self) -> str:
        return f"GridKalman({self.n} states, period={self.period})"


class CoupledSet:
    """The rows, equilibrium room and terminal ellipsoid of the coupled certificate.

    Parameters
    ----------
    params : MultiAreaParams
        The grid (its design model).
    relays : RelaySettings
        The same relays in every area.
    options : CoupledOptions

    Attributes
    ----------
    times : ndarray
        The certificate's sample times (s).
    budget : dict
        Each tightening of the limits, ``[frequency pu, ROCOF pu/s]`` (the largest
        over the areas): ``load``, ``re-check``, ``between samples``, ``estimate``.
    """

    def __init__(self, params: MultiAreaParams, relays: RelaySettings,
                 options: CoupledOptions) -> None:
        self.params, self.relays, self.options = params, relays, options
        o = options
        if np.linalg.matrix_rank(params.incidence()) != params.n_areas - 1:
            raise ValueError(f"the coupled certificate needs a connected grid (tie-lines "
                             f"reaching every area: one equilibrium frequency), got ties "
                             f"{params.tie!r} on {params.n_areas} areas; give separate grids "
                             f"a filter per area (\"certified\" or \"contract\")")
        A, Bu, Bl, R = held_grid(params, "the coupled certificate needs it")
        n_a, n_r = params.n_areas, len(A)
        C = output_rows(n_a, n_r)
        pair = np.array([relays.F, relays.rocof_limit]) * (1 - o.margin) * (1 - NUMERIC_MARGIN)
        limits = np.tile(pair, n_a)                                  # per output
        qu, ql = -np.linalg.solve(A, Bu), -np.linalg.solve(A, Bl)    # z_eq = qu u + ql p
        # the loads: the worst area's step response on each output, per pu of variation
        load = np.max([load_gains(A, Bl[:, j], C)["steps"] for j in range(n_a)], axis=0)
        again = np.max([period_step_gain(A, Bl[:, j], C, o.control_period)
                        for j in range(n_a)], axis=0)
        lim = limits - o.load_bound * load
        if np.any(lim <= 0):
            raise ValueError(f"load_bound={o.load_bound:g} pu takes the whole of a limit: "
                             f"{_worst(o.load_bound * load / limits)} of it; lower load_bound")
        if np.any(again > load):   # the proof's step (C) needs it: only by roundings
            raise ValueError("the loads' effect within one control period exceeds their "
                             "step response's peak; raise recheck_bound or lower "
                             "control_period")
        held = limits - o.recheck_bound * again
        fine = grid(o.horizon)
        gains = curvature_gains(A, C, fine)                          # (fine, outputs, n_r)
        E_ref = expm_at(A, fine[(fine <= 0.05) | (np.arange(len(fine)) % 4 == 0)])
        V = _rate(A, C, E_ref, limits)
        self.times = times = fine[merge_intervals(fine, (gains @ V) / limits, o.tightening)]
        E = expm_at(A, times)
        G = C @ E                                                    # y(t_k) = G z + Hu u + Hl p
        rest = np.eye(n_r)[None] - E
        Hu, Hl = C @ rest @ qu, C @ rest @ ql
        # the inter-sample bound, proven on these times for the states the rows allow
        sub = (times <= 0.05) | (np.arange(len(times)) % 3 == 0)
        V = _rate(A, C, E[sub], limits)
        tau = intersample(gains, V, fine, times)                     # (n, outputs)
        t_max, tau0 = tau.max(axis=0), tau[0]
        # the estimate's error e = (e_z, e_p) moves row k's output by G_k e_z + Hl_k e_p
        self.kalman = (GridKalman(params, o.control_period, o.noise_std)
                       if o.noise_std is not None else None)
        cov = self.kalman.posterior_covariance if self.kalman is not None else None
        from scipy.stats import chi2         # here: scipy.stats takes 0.3 s to import

        kappa_e = math.sqrt(chi2.ppf(o.confidence, len(cov))) if cov is not None else 0.0
        est, est0 = np.zeros(tau.shape), np.zeros(len(limits))
        ell, ell0 = np.zeros(tau.shape), np.zeros(len(limits))   # theorem B' (strict)
        load_rows, load_0 = np.broadcast_to(load, tau.shape), load
        g, g0 = np.zeros(tau.shape), np.zeros(len(limits))
        if cov is not None:
            w = np.concatenate([G, Hl], axis=2)                      # (n, outputs, n_r + n_a)
            est = kappa_e * np.sqrt(np.einsum("tij,jk,tik->ti", w, cov, w))
            w0 = np.hstack([C, np.zeros((len(C), n_a))])
            est0 = kappa_e * np.sqrt(np.einsum("ij,jk,ik->i", w0, cov, w0))
            # the loads' part of the error: a load path of total variation V before
            # the certification moves row i by at most V g_i, the loads after it by
            # at most V' load: with V + V' <= load_bound, max(g_i, load) covers both
            steps = load_error_steps(self.kalman, A, Bl, o.control_period)
            g, g0 = steps.sup(w), steps.sup(w0)
            load_rows, load_0 = np.maximum(load, g), np.maximum(load, g0)
            if o.held_level == "strict":     # the coming period's rows (theorem B')
                coming = np.arange(len(times)) <= np.searchsorted(times, o.control_period)
                ell[coming] = steps.total(w[coming])
                ell0 = steps.total(w0)
        self.budget = {"load": _by_kind(o.load_bound * load),
                       "re-check": _by_kind(o.recheck_bound * again),
                       "between samples": _by_kind(t_max + tau0),
                       "estimate": _by_kind(np.max(est + o.load_bound * (load_rows - load),
                                                   axis=0))}
        # the held level: theorem B's less the noise's part ("sharp"), or theorem
        # C''s ("widened"): wider by what the estimate's error may move a row at the
        # re-check, its noise's part and its loads' part (a total variation of at
        # most load_bound - recheck_bound, the assumption of C')
        # what the held level absorbs, NUMERIC_MARGIN more (a step of exactly that
        # size lands the equilibrium on the held level's boundary, where rounding
        # would decide)
        spent = (1.0 + NUMERIC_MARGIN) * (o.load_bound - o.recheck_bound)
        widened = o.held_level == "widened"
        bound_new = limits - o.load_bound * load_rows - t_max - tau - est   # (n, outputs)
        bound_held = held - t_max + (est + spent * g if widened else -est)
        y0_new = limits - o.load_bound * load_0 - t_max - tau0 - est0
        y0_held = held - tau0 + (est0 + spent * g0 if widened else -est0)
        if o.held_level == "strict":   # B': the coming period's rows, new and held, less
            # the error's loads' part at a variation of recheck_bound in every period
            bound_held -= o.recheck_bound * ell
            y0_held -= o.recheck_bound * ell0
            bound_new, y0_new = np.minimum(bound_new, bound_held), np.minimum(y0_new, y0_held)
        if np.any(bound_new <= 0) or np.any(y0_new <= 0) or np.any(bound_held <= 0):
            raise ValueError(f"the tightenings leave nothing of the relay limits: "
                             f"{self._describe()}; lower load_bound or tightening")
        n_rows = len(times) * 2 * n_a
        rows = np.concatenate([bound_new.reshape(-1, 1), bound_held.reshape(-1, 1),
                               (G @ R).reshape(n_rows, -1), Hu.reshape(n_rows, n_a),
                               Hl.reshape(n_rows, n_a)], axis=1)
        # the terminal ellipsoid, in coordinates where P is the identity: f = K' e
        scale = np.ones(n_r)
        for a in range(n_a):
            scale[N_AREA_STATES * a + 2:N_AREA_STATES * a + 5] = (lim[2 * a], lim[2 * a],
                                                                  lim[2 * a + 1])
        Eh = expm(A * times[-1])
        dw_u, dw_p = (C @ qu)[0], (C @ ql)[0]      # every area's equilibrium frequency
        # the held level absorbs what the loads may have moved since the vector was
        # certified (up to load_bound - recheck_bound): its equilibrium frequency
        # moves by at most that times |dw_p|, its state at the horizon by that times
        # kappa in the ellipsoid's norm (which only decreases along e^{At})
        dw_peak = float(np.max(np.abs(dw_p)))      # equilibrium frequency per pu of load
        drift = spent * dw_peak
        hold = held - t_max                                # room at each level, per output
        shapes = ("lyapunov", "sdp") if o.terminal == "auto" else (o.terminal,)
        for shape in shapes:
            if shape == "lyapunov":
                P = solve_continuous_lyapunov(A.T, -np.diag(scale ** -2.0))
            else:
                room = np.minimum(limits - o.load_bound * load - 2 * t_max, hold)
                try:
                    P = shaped_terminal(A, C, Eh @ ql, np.maximum(room, 1e-9 * limits))
                except ValueError as err:
                    advice = ("try terminal='lyapunov'" if o.terminal == "sdp" else
                              f"and the Lyapunov ellipsoid, tried first, leaves no room "
                              f"(tightenings: {self._describe()}); lower load_bound or "
                              f"tightening")
                    raise ValueError(f"{err}; {advice}") from None
            K = np.linalg.cholesky(P)                                    # P = K K'
            sigma = np.sqrt(np.einsum("ij,jk,ik->i", C, np.linalg.inv(P), C))
            kappa = float(np.max(np.linalg.norm(K.T @ Eh @ ql, axis=0)))
            # the estimate's error at the horizon (ellipsoid's norm) and in dw_eq: the
            # noise's part (err_*) comes off both levels' radii; the loads' part, per
            # pu of total variation before the certification (g_t, g_eq), moves each
            # output by at most g_eq + g_t sigma_o after the horizon, which shares
            # load_bound with the loads after it (g_o): the new level's room takes the
            # larger
            err_t, err_eq, g_t, g_eq = 0.0, 0.0, 0.0, 0.0
            if cov is not None:
                m = K.T @ Eh @ np.hstack([np.eye(n_r), -ql])
                err_t = kappa_e * math.sqrt(np.max(np.linalg.eigvalsh(m @ cov @ m.T)))
                err_eq = kappa_e * math.sqrt(dw_p @ cov[n_r:, n_r:] @ dw_p)
                g_t = steps.sup_norm(m)
                g_eq = float(np.max(steps.sup(np.concatenate([np.zeros(n_r), dw_p]))))
            after = np.tile([g_eq, 0.0], n_a) + g_t * sigma         # per output, per pu
            new = limits - o.load_bound * np.maximum(load, after) - 2 * t_max
            free = hold[0::2] - spent * kappa * sigma[0::2] - drift   # the held level's
            r = float(min(np.min(0.5 * new[0::2] / sigma[0::2]),
                          np.min(new[1::2] / sigma[1::2]),
                          np.min(hold[1::2] / sigma[1::2]) - spent * kappa,
                          np.min(0.5 * free / sigma[0::2])))
            h = float(min(np.min(new[0::2] - r * sigma[0::2]),
                          np.min(hold[0::2] - (r + spent * kappa) * sigma[0::2]) - drift))
            if r > 0 and h > 0:
                break
        self.terminal = shape
        if r <= 0 or h <= 0:
            why = (f"; a held vector's re-check absorbs load_bound - recheck_bound = "
                   f"{o.load_bound - o.recheck_bound:g} pu of load moved since its "
                   f"certification, which moves its state at the horizon by up to "
                   f"{spent * kappa * np.max(sigma[0::2]):.3g} pu of frequency in the "
                   f"terminal set's norm (terminal={shape!r}): lower load_bound - "
                   f"recheck_bound (0: no such absorption)" if spent > 0 else "")
            raise ValueError(f"the tightenings leave no room for the terminal set: "
                             f"{self._describe()}; lower load_bound or tightening{why}")
        # the held level: theorem C's less the noise's part ("sharp"), or C''s
        # ("widened"), which adds the error at the re-check (noise err_*, loads g_*)
        # to the error at the certification (the loads before it: g_*; the noise:
        # in the new level) and the loads' move after it (kappa, dw_peak)
        rho = {"new": r - err_t,
               "held": (r + err_t + spent * max(2 * g_t, kappa + g_t) if widened
                        else r + spent * kappa - err_t)}
        half = {"new": h - err_eq,
                "held": (h + err_eq + spent * max(2 * g_eq, dw_peak + g_eq) if widened
                         else h + drift - err_eq)}
        if rho["new"] <= 0 or half["new"] <= 0:
            raise ValueError(f"the estimate's error moves the state at the horizon by "
                             f"{err_t:.3g} in the terminal set's norm (radius {r:.3g}) and the "
                             f"equilibrium frequency by {err_eq:.3g} pu (room {h:.3g}); lower "
                             f"noise_std or confidence, or raise horizon (horizon='auto' "
                             f"tries 8 to 20 s)")
        lift = np.ascontiguousarray(R.T)            # x = R' z: the full state of a reduced one
        head = np.zeros(HEAD)
        head[:] = (len(R.T), n_a, n_r, n_rows, o.u_min, o.u_max, relays.F, relays.rocof_limit,
                   rho["new"], rho["held"], half["new"], half["held"], np.min(y0_new[0::2]),
                   np.min(y0_new[1::2]), np.min(y0_held[0::2]), np.min(y0_held[1::2]),
                   0 if cov is None else len(cov), 0)
        self.rows, self.n_rows = rows, n_rows
        # the rows column by column (row r's column c at HEAD + c n_rows + r): decide
        # sums every row at once, one column after another (row_intervals)
        body = [head, rows.T.ravel(), dw_u, dw_p, (K.T @ Eh @ R).ravel(),
                (-K.T @ Eh @ qu).ravel(), (-K.T @ Eh @ ql).ravel()]
        head[LIFT] = sum(len(b) for b in body)
        self.data = np.concatenate(body + [lift.ravel()])
        self.A, self.Bu, self.Bl, self.R, self.C = A, Bu, Bl, R, C
        self.W = R[N_AREA_STATES * n_a:, N_AREA_STATES * n_a:].T   # the reachable flows' basis

    def _describe(self) -> str:
        return ", ".join(f"{name} {pair(v)}" for name, v in self.budget.items())


def shaped_terminal(A: np.ndarray, C: np.ndarray, loads: np.ndarray,
                    room: np.ndarray) -> np.ndarray:
    """The terminal ellipsoid ``{z: z' P z <= 1}`` shaped by a semidefinite program.

    Minimises a bound ``t`` on ``kappa^2 = max_j loads_j' P loads_j`` (how far a
    unit load in area ``j``, ``loads[:, j]`` = its effect on the state at the
    horizon, moves it in the ellipsoid's norm): ``loads' P loads <= t I``, one
    linear matrix inequality for every area at once (``kappa^2`` is its largest
    diagonal entry, at most ``t``; 30 s for a ring of 10 areas, 59 states, where
    one inequality per area did not finish in 20 minutes), subject to every output's reach over the ellipsoid
    ``sqrt(c_i' P^-1 c_i) <= room_i`` (its room, pu or pu/s) and the norm
    decreasing along ``e^{At}`` at a rate of at least a tenth of the slowest
    mode's, ``A'P + PA <= -2 gamma P``: invariance, which the certificate's
    proof needs, checked on the result in floating point (``ValueError`` if it
    does not hold).  In ``Q = P^-1`` every condition is a linear matrix
    inequality (cvxpy, Clarabel); ``P = Q^-1``.

    The optimum drives ``Q`` towards singular in the directions no output or load
    constrains; behind some ties (two areas at T = 1 pu and 50 pu) the solver then
    returns an inaccurate ``Q`` whose inverse is not invariant in floating point.
    So ``Q``'s smallest eigenvalue is floored, at ``Q_FLOORS`` in turn (in the
    model's state units, pu^2), until the ellipsoid is invariant: a larger floor
    costs a larger ``t``, never soundness (the check is on the result).  Where no
    floor's ``Q`` is (the solver's falls short of the invariance inequality: behind
    T = 50 pu on an AMD EPYC's BLAS kernels, at every floor), each is moved inside
    it in turn (:func:`made_invariant`) and checked again.
    """
    import cvxpy as cp
    n = len(A)
    gamma = 0.1 * float(-np.max(np.linalg.eigvals(A).real))
    solved = []                               # each floor's Q, as the solver left it
    for floor in Q_FLOORS:
        Q, t = cp.Variable((n, n), symmetric=True), cp.Variable()
        cons = [Q >> floor * np.eye(n), A @ Q + Q @ A.T + 2 * gamma * Q << 0]
        cons += [cp.quad_form(c, Q) <= r ** 2 for c, r in zip(C, room)]
        cons += [cp.bmat([[t * np.eye(loads.shape[1]), loads.T], [loads, Q]]) >> 0]
        try:
            with warnings.catch_warnings():   # "inaccurate": the result is checked below
                warnings.filterwarnings("ignore", message="Solution may be inaccurate")
                cp.Problem(cp.Minimize(t), cons).solve(solver="CLARABEL")
        except cp.error.SolverError:
            continue
        if Q.value is None:
            continue
        solved.append(0.5 * (Q.value + Q.value.T))
        P = _invariant_inverse(A, solved[-1])
        if P is not None:
            return P
    for Q in solved:                          # none was: each moved inside, in turn
        P = _invariant_inverse(A, made_invariant(A, C, Q, room))
        if P is not None:
            return P
    raise ValueError(f"the shaped terminal ellipsoid's semidefinite program gives no ellipsoid "
                     f"invariant in floating point (Q's smallest eigenvalue floored at "
                     f"{', '.join(f'{f:g}' for f in Q_FLOORS)})")


def _invariant_inverse(A: np.ndarray, Q: np.ndarray) -> np.ndarray | None:
    """``P = Q^-1`` if ``A'P + PA`` is negative definite and ``P`` positive
    definite in floating point, else None."""
    P = np.linalg.inv(Q)
    P = 0.5 * (P + P.T)
    if np.max(np.linalg.eigvalsh(A.T @ P + P @ A)) < 0 and np.min(np.linalg.eigvalsh(P)) > 0:
        return P
    return None


def made_invariant(A: np.ndarray, C: np.ndarray, Q: np.ndarray,
                    room: np.ndarray) -> np.ndarray:
    """``Q`` moved off the boundary of the invariance inequality it was solved
    for: the solver's can fall short of ``A Q + Q A' <= 0`` (behind a stiff tie,
    T = 50 pu, by about 5e-7 on an AMD EPYC's BLAS kernels, where Intel's met it;
    behind T = 60 pu by 1.25e-5 there, more than its tolerance, and it did not
    build on Intel either), which leaves ``Q^-1`` not invariant in floating
    point.  The result is checked either way (:func:`_invariant_inverse`).  With
    ``X`` solving ``A X + X A' = -I`` (positive definite: ``A`` is stable),
    ``Q + e X`` has ``A Q + Q A'`` shifted down by ``e I``: ``e`` twice the
    largest eigenvalue's excess makes it negative definite; then the whole is
    scaled by at most 1 so that every output's reach stays within its room (a
    positive scale keeps the inequality)."""
    X = solve_continuous_lyapunov(A, -np.eye(len(A)))
    X = 0.5 * (X + X.T)
    lyap = A @ Q + Q @ A.T
    excess = float(np.max(np.linalg.eigvalsh(0.5 * (lyap + lyap.T))))
    e = 2.0 * max(excess, 0.0) + 1e-12 * float(np.max(np.abs(lyap)))
    moved = Q + e * X
    reach = np.einsum("ij,jk,ik->i", C, moved, C)
    return moved * min(1.0, float(np.min(room ** 2 / reach)))


@dataclass(frozen=True)
class LoadErrors:
    """The grid Kalman filter's error after a unit load step
    (:func:`load_error_steps`), and what bounds it between its offsets and after
    its last age.

    ``rows`` (ages x ``per_age``, n_k): ``e(m; d, j)`` for ages ``m = 1..M``, per age
    the offsets ``d`` (``spacing`` s apart) times the areas ``j``.  Between two
    offsets ``e`` leaves its linear interpolation by at most ``spacing^2 / 8 sup_d
    |e''|``, and ``e''(m; d, j) = D_m v(T - d, j)`` with ``D_m = Phi^(m-1) (I - K
    C)[:, :n_r]``, ``Phi = (I - K C) A`` and ``v(s, j) = A e^{As} Bl_j``: ``bends``
    holds ``D_m v(s, j)`` on a grid of ``s`` over the period (per age ``per_bend``
    rows); between its points ``v`` leaves its interpolation by at most ``ds^2 / 8
    sup |A^3 e^{As} Bl_j|``, which ``pads`` (ages,) carries in ``Q``'s norm below.

    Beyond the last age, in the norm ``||x||_Q = sqrt(x' Q x)`` of the solution of
    ``Phi' Q Phi - Q + I = 0``, each sample shrinks the error by at least ``ratio``:
    ``||Phi x||_Q^2 = ||x||_Q^2 - ||x||^2 + x' R x <= ratio^2 ||x||_Q^2`` with
    ``ratio^2 = 1 - (1 - ||R||) / lambda_max(Q)``, ``R`` the computed solution's
    residual; ``last`` is at least ``sup_(d,j) ||e(M; d, j)||_Q``, and ``half`` =
    ``Q^{-1/2}`` turns a norm into a bound: ``|w x| <= ||w Q^{-1/2}|| ||x||_Q``."""

    rows: np.ndarray
    per_age: int
    spacing: float
    bends: np.ndarray
    per_bend: int
    pads: np.ndarray
    last: float
    ratio: float
    half: np.ndarray

    def sup(self, w: np.ndarray) -> np.ndarray:
        """At least ``sup_(m,d,j) |w e(m; d, j)|`` per row of ``w`` (..., n_k), every
        age and every instant of the period included."""
        scale = np.linalg.norm(w @ self.half, axis=-1)
        between = self.spacing ** 2 / 8 * (_sup_abs(w, self.bends) + scale * self.pads.max())
        return np.maximum(_sup_abs(w, self.rows) + between, scale * self.ratio * self.last)

    def sup_norm(self, W: np.ndarray) -> float:
        """At least ``sup_(m,d,j) ||W e(m; d, j)||`` (``W`` a matrix): the larger
        end's norm plus ``spacing^2 / 8`` times ``sup ||W e''||``."""
        scale = float(np.linalg.norm(W @ self.half, 2))
        bend = float(np.max(np.linalg.norm(self.bends @ W.T, axis=1))
                     + scale * self.pads.max())
        return max(float(np.max(np.linalg.norm(self.rows @ W.T, axis=1)))
                   + self.spacing ** 2 / 8 * bend, scale * self.ratio * self.last)

    def total(self, w: np.ndarray) -> np.ndarray:
        """At least ``sum_m sup_(d,j) |w e(m; d, j)|`` per row of ``w`` (..., n_k),
        over every age: how far a load path whose variation within every control
        period is at most 1 moves ``w e`` (its steps of age ``m`` each by at most
        their variation times the age's largest response)."""
        scale = np.linalg.norm(w @ self.half, axis=-1)
        between = self.spacing ** 2 / 8 * (_age_max(w, self.bends, self.per_bend).sum(axis=-1)
                                           + scale * self.pads.sum())
        return (_age_max(w, self.rows, self.per_age).sum(axis=-1) + between
                + scale * self.last * self.ratio / (1.0 - self.ratio))


def load_error_steps(kalman: GridKalman, A: np.ndarray, Bl: np.ndarray, period: float,
                      offsets: int = ERROR_OFFSETS, tol: float = 1e-9) -> LoadErrors:
    """The grid Kalman filter's error (reduced states, then loads) at every
    control sample after a unit load step in any area at any instant: rows
    ``e(m; d, j)`` for ages ``m >= 1`` samples, ``offsets`` instants ``d`` in the
    period before the first (its ends included) and every area ``j``, until the
    error has decayed below ``tol`` of its largest.

    The true grid moves exactly as the filter's model except at the load's step:
    a step of area ``j``'s load at ``d`` s into a period adds
    ``int_0^{T-d} e^{As} ds Bl_j`` to the state at the next sample and 1 to the
    load, so the prior error jumps by that; then each sample multiplies the error
    by ``(I - K C)`` (correction) and ``A`` (prediction).  The error is linear in
    the load path (and independent of every command and attack), so a load path
    of total variation ``V`` moves any linear function ``w e`` of the error by at
    most ``V sup |w e(m; d, j)|`` over every age and instant
    (:meth:`LoadErrors.sup`)."""
    from scipy.linalg import solve_discrete_lyapunov

    n_r, n_a = len(A), Bl.shape[1]
    ikc = _correction(kalman)
    phi = ikc @ kalman.A
    Q = solve_discrete_lyapunov(phi.T, np.eye(len(phi)))
    Q = 0.5 * (Q + Q.T)
    residual = float(np.linalg.norm(phi.T @ Q @ phi - Q + np.eye(len(phi)), 2))
    lam, vec = np.linalg.eigh(Q)
    ratio2 = 1.0 - (1.0 - residual) / float(lam.max())
    if not (lam.min() > 0 and residual < 1.0 and ratio2 < 1.0):
        raise ValueError("the grid Kalman filter's error does not decay")
    root = vec @ np.diag(np.sqrt(lam)) @ vec.T                       # Q^{1/2}
    half = vec @ np.diag(lam ** -0.5) @ vec.T                        # Q^{-1/2}
    # v(s, j) = A e^{As} Bl_j on BENDS instants; between them v leaves its
    # interpolation by at most ds^2 / 8 sup ||A^3 e^{As} Bl_j||: on 1,000 instants,
    # times e^{||A|| u} (||e^{A(s + u)} x|| <= e^{||A|| u} ||e^{As} x||)
    s = np.linspace(0.0, period, BENDS)
    v = (A @ expm_at(A, s) @ Bl).transpose(1, 0, 2).reshape(n_r, -1)   # (n_r, BENDS n_a)
    fine = np.linspace(0.0, period, 1001)
    third = float(np.max(np.linalg.norm(A @ A @ A @ expm_at(A, fine) @ Bl, axis=1)))
    third *= math.exp(float(np.linalg.norm(A, 2)) * fine[1])
    jumps = []
    for d in np.linspace(0.0, period, offsets):
        block = np.zeros((n_r + n_a, n_r + n_a))
        block[:n_r, :n_r], block[:n_r, n_r:] = A, Bl
        integral = expm(block * (period - d))[:n_r, n_r:]           # int_0^{T-d} e^{As} ds Bl
        jumps.append(np.vstack([integral, np.eye(n_a)]))            # (n_k, n_a)
    e = ikc @ np.hstack(jumps)                                       # (n_k, offsets * n_a)
    drift = ikc[:, :n_r]                                             # D_m
    out, bends, pads, peak = [], [], [], 0.0
    for _ in range(100_000):
        out.append(e.T)
        bends.append((drift @ v).T)
        pads.append((s[1] ** 2 / 8) * np.linalg.norm(root @ drift, 2) * third)
        size = float(np.max(np.abs(e)))
        peak = max(peak, size)
        if size < tol * peak:
            break
        e, drift = phi @ e, phi @ drift
    else:
        raise ValueError("the grid Kalman filter's error does not decay")
    spacing = period / (offsets - 1)
    bend = np.linalg.norm(root @ drift @ v, axis=0).max() + pads[-1]
    last = float(np.max(np.linalg.norm(root @ e, axis=0))) + spacing ** 2 / 8 * bend
    return LoadErrors(np.vstack(out), offsets * n_a, spacing, np.vstack(bends), BENDS * n_a,
                      np.array(pads), last, math.sqrt(max(ratio2, 0.0)), half)


def _correction(kalman: GridKalman) -> np.ndarray:
    """``I - K C``: what a measurement update leaves of the estimate's error."""
    return np.eye(len(kalman.A)) - kalman.gain @ kalman.C


def _age_max(w: np.ndarray, rows: np.ndarray, per: int, chunk: int = 4096) -> np.ndarray:
    """``max |w row|`` over each age's block of ``per`` rows of ``rows``, for each row
    of ``w`` (shape ``(..., n_k)``): (..., ages), whole ages at a time."""
    step = max(1, chunk // per) * per
    return np.concatenate([np.max(np.abs(w @ rows[i:i + step].T)
                                  .reshape(*w.shape[:-1], -1, per), axis=-1)
                           for i in range(0, len(rows), step)], axis=-1)


def _sup_abs(w: np.ndarray, steps: np.ndarray, chunk: int = 4096) -> np.ndarray:
    """``max_s |w @ steps[s]|`` over the rows of ``steps``, for each row of ``w``
    (shape ``(..., n_k)``), a block of ``steps`` at a time (the whole product
    can take gigabytes)."""
    out = np.zeros(w.shape[:-1])
    for i in range(0, len(steps), chunk):
        np.maximum(out, np.max(np.abs(w @ steps[i:i + chunk].T), axis=-1), out=out)
    return out


def _by_kind(per_output: np.ndarray) -> np.ndarray:
    """The largest of an array over the outputs, per kind: ``[frequency pu, ROCOF pu/s]``."""
    return np.array([np.max(per_output[0::2]), np.max(per_output[1::2])])


def _worst(fraction: np.ndarray) -> str:
    return f"{100 * float(np.max(fraction)):.0f} %"


def _rate(A: np.ndarray, C: np.ndarray, E: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """``V >= |z'|`` entrywise over every state and command vector whose held
    outputs satisfy the untightened limits at the samples of ``E`` (``e^{At_k}``)
    and whose equilibrium frequency is inside its limit
    (:func:`~lfc.filters.certified.rate_bound`).

    In the deviation ``e = z - z_eq`` from the held vector's equilibrium ``z' =
    A e`` and the held outputs are ``C e^{At} e + w c`` with ``w`` the
    equilibrium frequency, the same in every area (``c``: 1 on the frequency
    outputs, 0 on ROCOF, whose equilibrium is 0): the programs are in ``(e, w)``
    only, whatever the commands and loads (in ``z`` they would be unbounded
    along the equilibria of opposite commands, where the rate is 0)."""
    n_r = A.shape[0]
    c = np.tile([1.0, 0.0], C.shape[0] // 2)
    rows = np.concatenate([C @ E, np.broadcast_to(c[None, :, None], (len(E), len(c), 1))],
                          axis=2).reshape(-1, n_r + 1)
    lim = np.tile(limits, len(E))
    a_ub = np.vstack([rows, -rows])
    bounds = [(None, None)] * n_r + [(-limits[0], limits[0])]
    return rate_bound(np.hstack([A, np.zeros((n_r, 1))]), a_ub, np.concatenate([lim, lim]),
                      bounds)
