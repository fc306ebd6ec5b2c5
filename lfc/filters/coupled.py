"""A certificate for a whole grid: every area's filter knows the grid's state.

``lfc.filters.build("coupled", grid)`` (a grid's ``filters={a: "coupled"}``; every
area must have it) builds one :class:`CoupledFilter` for the grid, shared by
its areas.  It is the certified filter (:mod:`lfc.filters.certified`) on the
*coupled* model instead of one area's: the state is every area's five states
and the tie-line flows (a wide-area measurement system gives each area's filter
all of them, and every area's load), the outputs are every area's measured
frequency and ROCOF, the input is the vector of every area's command.

**Fixed order.**  At each control sample the areas decide one after another
(area 0 first).  Area ``k`` chooses its own command ``u_k`` with every other
area's command held at its latest value (the areas before ``k`` have decided
this period, the others hold last period's).  A vector of commands is
*certified* at a state if holding it for ever keeps every area's outputs inside
its relay limits in continuous time: checked at samples up to the horizon, each
limit tightened by a proven bound on how far an output moves between samples
(:func:`lfc.filters.bounds.intersample` on the coupled model), and after the
horizon by an invariant ellipsoid of the coupled model around the vector's
equilibrium (a Lyapunov one, or one shaped by a semidefinite program where the
Lyapunov one leaves no room: ``terminal``, :func:`shaped_terminal`).  Every condition is affine in ``u_k`` (the ellipsoid a convex
quadratic), so each area's admissible set is one interval and its command is
``u_ref`` clipped to it.  Two levels as in one area: a new command is
certified with the limits tightened twice; if none is, the area holds its
command and re-checks the current vector with the limits tightened once, which
passes whenever the vector was certified anew at some earlier sample and
nothing but the state has moved since (the same trajectory, seen later).  In a
period the last area to certify a new command certified the whole vector the
areas after it re-check, at the same state: their check passes.

**The tie-lines are states, not disturbances.**  The per-area certificate
(``"certified"``) bounds the tie-line flow's move as a load; here it is part of
the prediction, so a stiff tie (Kundur's T ≈ 98 pu) costs nothing.  A ring's
circulating flow (the sum of ``dP_l / T_l`` around a loop never changes) is a
zero eigenvalue of the line-flow model; the certificate works on the flows'
reachable subspace (:func:`reduced_model`), where the held grid is
asymptotically stable.

**Guarantee (proven).**  For the grid the filter was built for (its design
model; no box), with every area's state, tie-line flow and load known at each
control sample (exact), every area's command chosen by this filter in the fixed
order, a start from a state where the commands held are certified (e.g.
equilibrium), and loads whose total variation summed over the areas is at most
``recheck_bound`` within each control period (any area, any instant, either
sign): every area's OF2, UF2 and ROCOF relays stay untripped at every instant
up to the first control sample at which a filter flags ``outside`` — whatever
commands, frequency references and ACE signals an attacker sends to any subset
of the areas.  A new vector leaves room for a total load variation of
``load_bound`` from its certification on (each limit tightened by
``load_bound`` times the largest step response of any area's load on that
output, :func:`lfc.filters.responses.load_gains`), a held one for
``recheck_bound`` over the coming period (:func:`~lfc.filters.responses.period_step_gain`);
``outside`` is then flagged only if the loads moved by more than the new vector
left room for.  Proof and the tests that check it: ``docs/coupled-certificate.md``.

**With estimates** (``noise_std``, ``estimator="kalman"``): the areas share one
grid-wide Kalman filter (:class:`GridKalman`) that fuses every area's frequency,
ROCOF and tie-line export; its error is independent of every command and attack
(a noise part plus a part linear in the loads), and the certificate is tightened
by both.  Proven (theorem A'): if the loads' total variation over the run is at
most ``load_bound`` and the noise's part of the error lies in its ellipsoid at
``confidence`` at each certification, no relay trips.  Theorem B (a held check
proves the coming period safe) holds on an estimate only at the strict held
level.  The held re-check's level is a choice (``held_level``): ``"sharp"``
(default) flags ``outside`` early when the loads move beyond the bounds, and
sometimes with nothing wrong (measured); ``"widened"`` is proven (theorem C')
never to flag it while the loads' total variation over the run is at most
``load_bound - recheck_bound`` and the noise's part lies in its ellipsoid at the
certification and the re-check, and misses moderate excesses; ``"strict"`` is
proven (theorem B') to keep the coming period safe whenever its check passes, if
every control period's load variation so far is at most ``recheck_bound`` and the
noise's part lies in its ellipsoid, and flags ``outside`` most often.

**Where the model holds.**  Every command stays within ``±command_range`` of
the design model (:class:`lfc.multiarea.MultiAreaParams`; ∞ but for a model
fitted to ANDES, whose range :func:`lfc.testbed.grid_fit.validated_range`
measures).  Without it the filters certify, on a fitted model, commands that
push gigawatts over a tie the model treats as linear.

**Not covered.**  Other estimators (refused), plants other
than the design grid, an area without this filter.  On ANDES (``lfc.simulate``
of a ``GridCase``) the filters read each area's metered states and tie-line
export (:meth:`CoupledFilter.grid_state`), or on the estimate the grid Kalman
filter reads the metered frequency, ROCOF and exports, and the certificate (and
the estimate's error bound) is the fitted model's: measured there, not proven
(``tests/test_coupled_estimate.py::test_on_andes_the_coupled_filters_run_on_their_estimate``).  Without the command range a red-team
attack found against the IEEE 39-bus system's fitted model trips ROCOF on ANDES;
within it the winners trip nothing there, though ``outside`` is flagged
(``tests/test_coupled.py::test_on_andes_ieee39_the_red_teams_winner_leaves_the_certificate_only_beyond_the_range``).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm, solve_continuous_lyapunov

from lfc._jit import inline, jit, maxnum, minnum
from lfc._validate import (ParameterTypeError, as_float, check_array, check_index,
                           check_nonnegative, check_number, check_positive, check_range)
from lfc.filters.base import (ACTIVE, BIND_CERT, INVALID, MAX_ABS_INPUT, OUTSIDE, Layout,
                              METHOD_IDS, applied_flags, built_once, check_limits,
                              hold_invalid, valid_input)
from lfc.filters.bounds import curvature_gains, expm_at, intersample, merge_intervals, pair
from lfc.filters.certified import NUMERIC_MARGIN, grid, rate_bound
from lfc.filters.responses import load_gains, period_step_gain
from lfc.estimation import (LOAD_STD, check_noise_std, kf_correct, kf_predict, measurement_std,
                            steady_state_kalman)
from lfc.model import STATES, zoh
from lfc.multiarea import N_AREA_STATES, MultiAreaParams, discretize_grid, multiarea_matrices
from lfc.relays import RelaySettings

METHOD_ID = METHOD_IDS["coupled"]   # the engine's code for it (lfc.engine.generator_period)
DW, ROCOF = STATES.index("dw_meas"), STATES.index("rocof_meas")   # an area's measured outputs
#: header of the data array decide() reads
LAYOUT = Layout("n_s", "n_a", "n_r", "n_rows", "u_min", "u_max", "f_lim", "r_lim", "rho_new",
                "rho_held", "half_new", "half_held", "y0_f_new", "y0_r_new", "y0_f_held",
                "y0_r_held", "n_k", "lift")
(N_S, N_A, N_R, N_ROWS, U_MIN, U_MAX, F_LIM, R_LIM, RHO_NEW, RHO_HELD, HALF_NEW, HALF_HELD,
 Y0_F_NEW, Y0_R_NEW, Y0_F_HELD, Y0_R_HELD, N_K, LIFT) = LAYOUT.offsets()
HEAD = LAYOUT.size
EXPORT_STD = 1e-4    # pu: the grid Kalman filter's noise model of the metered tie-line exports


TERMINALS = ("auto", "lyapunov", "sdp")
AUTO_HORIZONS = (8.0, 12.0, 16.0, 20.0)   # s: horizon="auto"'s candidates, shortest first
AUTO_HELD_MAX = 1.0   # s: how long "auto" lets a legitimate step leave AGC waiting (it restores
                      # in about 20 s on the grids of docs/coupled-certificate.md)
ERROR_OFFSETS = 11   # instants in a control period at which the error lemma steps a load
BENDS = 11            # instants in a control period at which it bounds the steps' curvature
HELD_LEVELS = ("sharp", "widened", "strict")
OUTSIDE_WHY = {   # what an outside flag may mean: the exact state, then each held level
    None: "the loads moved by more than the bounds",
    "sharp": "the loads moved by more than the bounds, or the estimator has not yet seen a "
             "load step",
    "widened": "the loads moved by more than the bounds, or the estimate's noise left its "
               "ellipsoid",
    "strict": "the loads moved by more than the bounds, the estimator has not yet seen a "
              "load change, or the estimate's noise left its ellipsoid"}
Q_FLOORS = (1e-12, 1e-6, 1e-5, 1e-4)   # shaped_terminal's floors on Q's eigenvalues, in turn


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
        (:meth:`held_after_step` measures it; ``docs/coupled-certificate.md``,
        "With estimates", Cost).  :class:`CoupledFilter` also takes ``"auto"``:
        the shortest of :data:`AUTO_HORIZONS` whose certificate builds and holds
        a legitimate step at most :data:`AUTO_HELD_MAX` (1 s;
        :meth:`~CoupledFilter.held_after_step`).
    tightening : float
        How far (fraction of each limit) an output may move between two
        certificate samples, in [1e-4, 0.1]; sets their spacing.  Default 0.005.
    margin : float
        Extra fractional tightening of every limit, in [0, 1).  Default 0.
    u_min, u_max : float
        Limits on every area's command (pu), ``u_min <= 0 <= u_max``.
        :class:`CoupledFilter`'s default: ``∓params.command_range`` (the range
        its design model holds in, :class:`lfc.multiarea.MultiAreaParams`; ∓∞
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

    def __post_init__(self) -> None:
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


def reduced_model(params: MultiAreaParams) -> tuple[np.ndarray, ...]:
    """The grid on its tie-line flows' reachable subspace.

    The line flows ``P`` (n_l) move as ``P' = S w`` (``S``: each line's
    ``T_ij`` on its areas' frequencies), so from equilibrium they stay in the
    column space of ``S``, of dimension ``n_areas - 1`` for a connected grid;
    a ring's extra line adds a direction (the circulating flow) that never
    moves and is a zero eigenvalue of the full model.  With ``W`` an
    orthonormal basis of that space and ``P = W phi``, the reduced state is
    ``z = [area states; phi] = R x``.

    Returns
    -------
    A, Bu, Bl : ndarray
        Reduced ``z' = A z + Bu u + Bl p`` (every area's command ``u``, load ``p``).
    R : ndarray
        ``z = R x`` from the full state ``x`` of :func:`lfc.multiarea.multiarea_matrices`.
    """
    A_full, B_full = multiarea_matrices(params)
    n_a, m = params.n_areas, N_AREA_STATES
    head = m * n_a
    S = A_full[head:, :head]
    if S.shape[0]:
        basis, sv, _ = np.linalg.svd(S, full_matrices=False)
        W = basis[:, sv > 1e-9 * sv.max()]
    else:
        W = np.zeros((0, 0))
    R = np.zeros((head + W.shape[1], A_full.shape[0]))
    R[:head, :head] = np.eye(head)
    R[head:, head:] = W.T
    L = R.T                       # lift: x = L z on the reachable subspace (W orthonormal)
    return R @ A_full @ L, R @ B_full[:, :n_a], R @ B_full[:, n_a:], R


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
            steps = _load_error_steps(self.kalman, A, Bl, o.control_period)
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
    it in turn (:func:`_made_invariant`) and checked again.
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
        P = _invariant_inverse(A, _made_invariant(A, C, Q, room))
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


def _made_invariant(A: np.ndarray, C: np.ndarray, Q: np.ndarray,
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
    (:func:`_load_error_steps`), and what bounds it between its offsets and after
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


def _load_error_steps(kalman: GridKalman, A: np.ndarray, Bl: np.ndarray, period: float,
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


@inline
def _valid(x: np.ndarray, u: np.ndarray, p: np.ndarray, u_ref: float) -> bool:
    """Every number of the call finite and within ``MAX_ABS_INPUT``."""
    ok = valid_input(x, u_ref, 0.0)
    for j in range(len(u)):
        ok = ok and abs(u[j]) <= MAX_ABS_INPUT and abs(p[j]) <= MAX_ABS_INPUT
    return ok


@inline
def row_intervals(fd: np.ndarray, x: np.ndarray, u: np.ndarray, p: np.ndarray, k: int,
                  sums: np.ndarray) -> tuple:
    """The rows' part of :func:`_intervals`: ``(lo_f, hi_f, lo_r, hi_r, lo_held,
    hi_held)`` over the frequency rows (even), the ROCOF rows (odd), and all rows
    at the held level.  ``sums`` (at least n_rows) is scratch: each row's output,
    summed for all rows at once one column after another (the rows are stored
    column by column), so that LLVM runs the rows in SIMD lanes; each row's sum
    takes its terms in the same order as one row at a time would (the state's,
    then each area's command and load), so the intervals are the same bit for bit
    (``tests/test_coupled.py``); ``bench/bench_coupled.py --rows`` measures it against
    one row after another."""
    inf = np.inf
    n_s, n_a, n_rows = int(fd[N_S]), int(fd[N_A]), int(fd[N_ROWS])
    col = HEAD + 2 * n_rows           # the rows' columns: bound new, bound held, then these
    for r in range(n_rows):
        sums[r] = 0.0
    for c in range(n_s):
        xc, o = x[c], col + c * n_rows
        for r in range(n_rows):
            sums[r] += fd[o + r] * xc
    for j in range(n_a):
        uj, pj = u[j], p[j]
        ou, op = col + (n_s + j) * n_rows, col + (n_s + n_a + j) * n_rows
        for r in range(n_rows):
            sums[r] += fd[ou + r] * uj + fd[op + r] * pj
    u_k, hk = u[k], col + (n_s + k) * n_rows     # area k's command, its column
    for r in range(n_rows):
        sums[r] -= fd[hk + r] * u_k   # the rest of the output, without area k's command
    lo_f, hi_f, lo_r, hi_r, lo_h, hi_h = -inf, inf, -inf, inf, -inf, inf
    for parity in range(2):           # the frequency rows (even), then ROCOF's (odd)
        lo, hi = -inf, inf
        for r in range(parity, n_rows, 2):
            s, h = sums[r], fd[hk + r]
            bn, bh = fd[HEAD + r], fd[HEAD + n_rows + r]
            if h != 0.0:
                a1, a2, c1, c2 = (-bn - s) / h, (bn - s) / h, (-bh - s) / h, (bh - s) / h
                lo_n, hi_n, lo_hh, hi_hh = min(a1, a2), max(a1, a2), min(c1, c2), max(c1, c2)
            else:
                lo_n, hi_n = (-inf, inf) if abs(s) <= bn else (inf, -inf)
                lo_hh, hi_hh = (-inf, inf) if abs(s) <= bh else (inf, -inf)
            lo, hi = maxnum(lo, lo_n), minnum(hi, hi_n)
            lo_h, hi_h = maxnum(lo_h, lo_hh), minnum(hi_h, hi_hh)
        if parity == 0:
            lo_f, hi_f = lo, hi
        else:
            lo_r, hi_r = lo, hi
    return lo_f, hi_f, lo_r, hi_r, lo_h, hi_h


@inline
def _intervals(fd: np.ndarray, x: np.ndarray, u: np.ndarray, p: np.ndarray, k: int,
               sums: np.ndarray) -> tuple:
    """Area ``k``'s certified intervals for its command with the others at ``u``:
    ``(lo_f, hi_f, lo_r, hi_r, lo_held, hi_held)`` (pu; empty where ``lo > hi``),
    the first four for a new command (frequency and ROCOF rows apart, the
    equilibrium and ellipsoid in both), the last pair the held level; ``sums``
    scratch (:func:`row_intervals`)."""
    inf = np.inf
    n_s, n_a, n_r, n_rows = int(fd[N_S]), int(fd[N_A]), int(fd[N_R]), int(fd[N_ROWS])
    new_ok, held_ok = True, True
    for a in range(n_a):          # the current outputs: room for the first interval
        dw, rc = abs(x[N_AREA_STATES * a + DW]), abs(x[N_AREA_STATES * a + ROCOF])
        new_ok = new_ok and dw <= fd[Y0_F_NEW] and rc <= fd[Y0_R_NEW]
        held_ok = held_ok and dw <= fd[Y0_F_HELD] and rc <= fd[Y0_R_HELD]
    lo_f, hi_f, lo_r, hi_r, lo_h, hi_h = row_intervals(fd, x, u, p, k, sums)
    width, u_k = 2 + n_s + 2 * n_a, u[k]
    o = HEAD + n_rows * width
    w, c_k = 0.0, fd[o + k]          # the equilibrium frequency, every area's
    for j in range(n_a):
        w += fd[o + j] * u[j] + fd[o + n_a + j] * p[j]
    w -= c_k * u_k
    e0, e1 = (-fd[HALF_NEW] - w) / c_k, (fd[HALF_NEW] - w) / c_k
    g0, g1 = (-fd[HALF_HELD] - w) / c_k, (fd[HALF_HELD] - w) / c_k
    lo_e, hi_e, lo_eh, hi_eh = min(e0, e1), max(e0, e1), min(g0, g1), max(g0, g1)
    o += 2 * n_a                     # the ellipsoid: f = K'(z(T) - z_eq), |f| <= rho
    ke, keu, kel = o, o + n_r * n_s, o + n_r * n_s + n_r * n_a
    qa, qb, ff = 0.0, 0.0, 0.0
    for r in range(n_r):
        f = 0.0
        for c in range(n_s):
            f += fd[ke + r * n_s + c] * x[c]
        for j in range(n_a):
            f += fd[keu + r * n_a + j] * u[j] + fd[kel + r * n_a + j] * p[j]
        g = fd[keu + r * n_a + k]
        f -= g * u_k
        qa += g * g
        qb += 2.0 * g * f
        ff += f * f
    for held in (False, True):
        rho = fd[RHO_HELD] if held else fd[RHO_NEW]
        disc = qb * qb - 4.0 * qa * (ff - rho * rho)
        if disc < 0.0 or qa <= 0.0:
            q_lo, q_hi = (inf, -inf) if disc < 0.0 or ff > rho * rho else (-inf, inf)
        else:
            root = math.sqrt(disc)
            q_lo, q_hi = (-qb - root) / (2.0 * qa), (-qb + root) / (2.0 * qa)
        if held:
            lo_h, hi_h = max(lo_h, lo_eh, q_lo), min(hi_h, hi_eh, q_hi)
        else:
            lo_q, hi_q = max(lo_e, q_lo), min(hi_e, q_hi)
    if not new_ok:
        lo_f, hi_f, lo_r, hi_r = inf, -inf, inf, -inf
    if not held_ok:
        lo_h, hi_h = inf, -inf
    return (max(lo_f, lo_q), min(hi_f, hi_q), max(lo_r, lo_q), min(hi_r, hi_q), lo_h, hi_h)


@inline
def grid_estimate(fd: np.ndarray, A: np.ndarray, B: np.ndarray, C: np.ndarray,
                  gain: np.ndarray, ks: np.ndarray, y: np.ndarray, scratch: np.ndarray,
                  u: np.ndarray, predict: bool, xe: np.ndarray) -> np.ndarray:
    """One step of the grid Kalman filter (:class:`GridKalman`, matrices ``A, B,
    C, gain``, state ``ks``: prior, then posterior) at a control sample: predict
    from the last posterior with the commands ``u`` held over the period (if
    ``predict``), correct with the measurements ``y``; writes the full state of
    the estimate into ``xe`` (every area's five states, then the line flows) and
    returns the loads' estimate (a view).  ``scratch`` holds ``len(y)`` values."""
    if predict:
        kf_predict(A, B, ks, u)
    kf_correct(gain, C, ks, y, scratch)
    n_s, n_r, n_a, o = int(fd[N_S]), int(fd[N_R]), int(fd[N_A]), int(fd[LIFT])
    for i in range(n_s):
        acc = 0.0
        for c in range(n_r):
            acc += fd[o + i * n_r + c] * ks[1, c]
        xe[i] = acc
    return ks[1, n_r:n_r + n_a]


@jit
def decide(fd: np.ndarray, x: np.ndarray, u: np.ndarray, p: np.ndarray, k: int,
           u_ref: float, mem: np.ndarray, sums: np.ndarray) -> tuple:
    """Area ``k``'s call (module docstring): the grid's state ``x`` (every area's
    five states, then the line flows; pu), every area's latest command ``u``
    (``u[k]`` is area ``k``'s, held) and load ``p`` (pu), the incoming command
    ``u_ref``; ``mem[0]`` the command area ``k`` holds; ``sums`` scratch of
    :func:`rows_scratch` entries.  Returns what
    :func:`lfc.filters.dispatch.decide` does, for area ``k``'s outputs; compiled,
    as that one is, as a function of its own that the engine's loops link."""
    if not _valid(x, u, p, u_ref):
        return hold_invalid(mem, u_ref)
    lo_f, hi_f, lo_r, hi_r, lo_h, hi_h = _intervals(fd, x, u, p, k, sums)
    lo = max(lo_f, lo_r, fd[U_MIN])
    hi = min(hi_f, hi_r, fd[U_MAX])
    certified = lo <= hi
    flags = 0
    if certified:
        v = min(max(u_ref, lo), hi)
    else:                              # hold; the vector as it is, at the held level
        v = mem[0]
        if not lo_h <= v <= hi_h:
            flags |= OUTSIDE
    mem[0] = v
    flags |= applied_flags(v, u_ref, certified, fd[U_MIN], fd[U_MAX])
    dw, rc = x[N_AREA_STATES * k + DW], x[N_AREA_STATES * k + ROCOF]
    return (v, flags, fd[F_LIM] ** 2 - dw ** 2, fd[R_LIM] ** 2 - rc ** 2,
            min(v - lo_f, hi_f - v), min(v - lo_r, hi_r - v), dw, rc, lo, hi)


@jit
def decide_once(fd: np.ndarray, x: np.ndarray, u: np.ndarray, p: np.ndarray, k: int,
                u_ref: float, mem: np.ndarray) -> tuple:
    """:func:`decide`, callable from Python (:meth:`CoupledFilter.filter`)."""
    return decide(fd, x, u, p, k, u_ref, mem, np.empty(int(fd[N_ROWS])))


def rows_scratch(fd: np.ndarray) -> int:
    """How many entries of scratch :func:`decide` needs for the data ``fd``."""
    return int(fd[N_ROWS])


def auto_horizon(params: MultiAreaParams, relays: RelaySettings,
                 options: dict) -> tuple[float, dict[float, float | str]]:
    """``horizon="auto"`` (:class:`CoupledFilter`): the horizon chosen (s) and
    what each one tried gave (:meth:`CoupledFilter.held_after_step`'s seconds, or
    why it did not build)."""
    if options["horizon"] != "auto":
        raise ParameterTypeError(f"horizon must be a number of seconds in [0.2, 20] or "
                                 f"'auto', got {options['horizon']!r}")
    CoupledOptions(**{**options, "horizon": AUTO_HORIZONS[0]})   # the other options' errors
    tried: dict[float, float | str] = {}
    for h in AUTO_HORIZONS:
        try:
            filt = CoupledFilter(params, relays, **{**options, "horizon": h})
        except ValueError as err:
            tried[h] = str(err)
            continue
        tried[h] = filt.held_after_step()
        if tried[h] <= AUTO_HELD_MAX:
            return h, tried
    held = {h: s for h, s in tried.items() if not isinstance(s, str)}
    if not held:
        raise ValueError("horizon='auto': the certificate builds at none of "
                         + "; ".join(f"{h:g} s ({why})" for h, why in tried.items()))
    return min(held, key=lambda h: (held[h], h)), tried


class CoupledFilter:
    """The coupled certificate of one grid, shared by its areas (module docstring).

    Parameters
    ----------
    params : MultiAreaParams
        The grid it is built for.
    relays : RelaySettings
        The relays of every area.
    **options
        :class:`CoupledOptions`; ``horizon="auto"`` builds the certificate at each
        of :data:`AUTO_HORIZONS` (8, 12, 16, 20 s) in turn and keeps the first
        that builds and whose :meth:`held_after_step` is at most
        :data:`AUTO_HELD_MAX` (1 s: a legitimate step of ``load_bound -
        recheck_bound`` in any area leaves AGC waiting at most that long), or, if
        none is, the one that holds the least (the shortest of equals): the
        two-area preset keeps 8 s, Kundur as fitted to ANDES 16 s on the estimate of
        ``noise_std=(1e-4, 1e-3)`` (``tests/test_coupled_estimate.py``).

    Attributes
    ----------
    options : CoupledOptions
        The options it was built with (``horizon`` the one chosen).
    horizons : dict
        With ``horizon="auto"``: each horizon tried (s) and what it gave, the
        seconds :meth:`held_after_step` returned or, for one that did not build,
        the reason; else empty.

    Raises
    ------
    ValueError
        For an invalid option, a grid that is not stable with its commands held,
        or tightenings that leave nothing of the limits (the message says which);
        with ``horizon="auto"``, if no candidate builds (each one's reason).
    """

    method_id = METHOD_ID
    name = "coupled"

    def __init__(self, params: MultiAreaParams, relays: RelaySettings, **options) -> None:
        if not isinstance(params, MultiAreaParams):
            raise ParameterTypeError(f"params must be a MultiAreaParams, got "
                                     f"{type(params).__name__}")
        if not isinstance(relays, RelaySettings):
            raise ParameterTypeError(f"relays must be a RelaySettings, got {relays!r}")
        self.params, self.relays = params, relays
        # the model holds within its command range: the commands stay there
        options = {"u_min": -params.command_range, "u_max": params.command_range, **options}
        self.horizons: dict[float, float | str] = {}
        if isinstance(options.get("horizon"), str):
            options["horizon"], self.horizons = auto_horizon(params, relays, options)
        self.options = o = CoupledOptions(**options)
        self.cert = built_once(lambda: CoupledSet(params, relays, o), CoupledSet, params,
                               relays, o, store=True)
        self.data, self.kalman = self.cert.data, self.cert.kalman

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in vars(self.options).items())
        return f"CoupledFilter({self.params.n_areas} areas, {opts})"

    def grid_state(self, areas: np.ndarray, exports: np.ndarray) -> np.ndarray:
        """The state :meth:`filter` reads, from what a plant meters: each area's five
        states ``areas`` (n_areas, 5) and tie-line export ``exports`` (n_areas,; pu).
        The line flows are the ones of the reachable subspace with these exports
        (unique for a connected grid: least squares on ``incidence @ W phi =
        exports``)."""
        E, W = self.params.incidence(), self.cert.W
        flows = W @ np.linalg.lstsq(E @ W, np.asarray(exports, float), rcond=None)[0] \
            if W.size else np.zeros(0)
        return np.concatenate([np.asarray(areas, float).ravel(), flows])

    def check_period(self, control_period: float) -> None:
        """``ValueError`` unless the calls come every ``control_period`` s, the
        period its re-check was built for."""
        if not math.isclose(self.options.control_period, control_period, rel_tol=1e-9):
            raise ValueError(f"the coupled filter was built for control_period="
                             f"{self.options.control_period} s but the simulation calls it "
                             f"every {control_period} s; build it with "
                             f"control_period={control_period}")

    def filter(self, x: np.ndarray, u: np.ndarray, p: np.ndarray, area: int, u_ref: float,
               memory: np.ndarray) -> tuple[float, int, str]:
        """One call of area ``area``'s filter, as the engine makes it.

        Parameters
        ----------
        x : array_like, shape (n_states,)
            The grid's state (every area's five states, then the line flows; pu).
        u, p : array_like, shape (n_areas,)
            Every area's latest command and load (pu); ``u[area]`` is the one held.
        area : int
        u_ref : float
            The command area ``area`` receives (pu).
        memory : ndarray, shape (2,)
            The area's memory (``memory[0]``: the command it holds); updated.

        Returns
        -------
        u : float
            The command to apply (pu), always finite.
        flags : int
            The flag bits (:mod:`lfc.filters.base`).
        reason : str
            :meth:`reason` of the flags.
        """
        n = self.params.n_areas
        x, u, p = check_array("x", x), check_array("u", u), check_array("p", p)   # fresh copies
        if x.shape != (self.params.n_states,) or u.shape != (n,) or p.shape != (n,):
            raise ValueError(f"x must have {self.params.n_states} entries and u, p {n}, got "
                             f"shapes {x.shape}, {u.shape}, {p.shape}")
        area = check_index("area", area, n)
        check_number("u_ref", u_ref)
        if not (isinstance(memory, np.ndarray) and memory.dtype == np.float64
                and memory.shape == (2,) and memory.flags.writeable
                and np.isfinite(memory).all()):
            raise ValueError(f"memory must be a writable float64 array of shape (2,) with "
                             f"finite values (the area's memory, updated), got {memory!r:.80}")
        out = decide_once(self.data, x, u, p, area, as_float(u_ref), memory)
        return out[0], int(out[1]), self.reason(int(out[1]))

    def held_after_step(self, size: float | None = None, *, duration: float = 60.0) -> float:
        """How long (s) a legitimate load step leaves every area's AGC waiting: the
        grid's design model from equilibrium, every command held at 0, a step of
        ``size`` pu (default ``load_bound - recheck_bound``, the step theorem C
        rides) in one area, of either sign; returns the last control sample
        (time after the step, s; the largest over the areas and signs) at which
        some area's held command is not certifiable as a new one — until then
        the filter certifies no command near it, so a slowly moving AGC cannot
        move the command at all (it is held, nothing flagged).  0 if never within
        ``duration``; ``duration`` if still then.  Computed on the exact state (the
        estimate converges to it), about a second per area pair.  A diagnostic of the
        cost of safety (``docs/coupled-certificate.md``, "With estimates", Cost)."""
        o = self.options
        size = o.load_bound - o.recheck_bound if size is None else size
        check_range("size", size, 0.0, o.load_bound, closed=True)
        check_range("duration", duration, o.control_period, 3600.0, closed=True)
        size = float(size)
        g = self.params
        Ad, _, Bl = discretize_grid(g, o.control_period)
        u, n = np.zeros(g.n_areas), int(round(duration / o.control_period))
        memory = np.zeros(2)
        held = 0.0
        for j in range(g.n_areas):
            for sign in (1.0, -1.0):
                p = np.zeros(g.n_areas)
                p[j] = sign * size
                x = np.zeros(g.n_states)
                for k in range(1, n + 1):
                    x = Ad @ x + Bl @ p
                    for a in range(g.n_areas):
                        memory[0] = 0.0               # the held command; the call's own
                        lo, hi = decide_once(self.data, x, u, p, a, 0.0, memory)[-2:]
                        if not lo <= 0.0 <= hi:       # new interval (decide's last two)
                            held = max(held, k * o.control_period)
                            break
        return held

    def reason(self, flags: int) -> str:
        """What a call with these flag bits did, in words."""
        if flags & INVALID:
            return "invalid input (non-finite or beyond 1e6); last certified command held"
        if flags & OUTSIDE:
            level = None if self.kalman is None else self.options.held_level
            return (f"no command is certified and the vector held fails its own check "
                    f"({OUTSIDE_WHY[level]}); last certified command held")
        if flags & ACTIVE and not flags & BIND_CERT:
            return "no new command is certified from this state; last certified command held"
        return "command clipped to the certified interval" if flags & ACTIVE else ""
