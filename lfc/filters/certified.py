"""A safety filter with a guarantee: no command on P_c or ω_ref trips the relays.

``SafetyFilter(params, relays, method="certified", **options)`` uses this module
(:class:`CertifiedFilter`; options there).  The idea is an implicit
control-invariant set with a *hold* backup law:

* A command ``u`` is **certified** at state ``x`` if applying it and holding it
  for ever keeps both measured outputs (``dw_meas``, ``rocof_meas``) inside the
  relay limits *in continuous time*, for every plant of the declared box.  For
  one plant the held trajectory is affine in ``u``: ``y(t) = C e^{At}(x - x_eq)
  + C x_eq`` with ``x_eq = q_u u + q_p p``.  It is checked at samples up to
  the horizon (8 s), each limit tightened by ``D2 delta^2 / 8``, a proven bound
  on how far the output can move between two samples ``delta`` apart (``D2``
  bounds ``|y''|``: see :func:`intersample`); the samples are as sparse as a
  chosen tightening allows (``tightening``, :func:`merge_intervals`: 1 ms
  apart where the fast modes move, up to 0.1 s and more once they have
  decayed); after the horizon the deviation from the held
  command's equilibrium must lie in an ellipsoid ``e'Pe <= rho^2`` that the
  continuous-time dynamics never leave (``P`` a Lyapunov matrix) and on which
  the outputs stay inside the limits; the equilibrium itself must leave that
  room.  Each condition is an interval in ``u`` (the ellipsoid a convex
  quadratic), so the admissible set is one interval and the filter is
  ``u_ref`` clipped to it: no QP solver.
* **Two levels** make the hold always re-certifiable: new commands are
  certified with the limits tightened twice (``2 tau``), so their trajectory
  stays ``tau`` inside the limits in continuous time; the held command is
  re-checked with ``tau`` only, which its own trajectory always passes.  If
  no new command is certified the filter holds the last one (flag ``active``,
  binding ``"certified"``); if even that fails its check it still holds it and
  flags ``outside`` (its meaning: below).

**Guarantee (proven).** For every plant whose M, D, tau_g, tau_t and droop are among
the certified plants (``uncertainty``: the design model and the 32 corners of the
box), with the state known within the estimation bound (``noise_std``: the Kalman
filter's error ellipsoid at ``confidence``; ``sensor_bound``: the box the median of
redundant sensors stays in, :mod:`lfc.sensors`; exact state without either), a
command held between calls, a load that moves by at most ``load_bound`` from the
load ``p_load`` given to the filter when the command was certified (``load_kind``:
``"band"``, ``|dP_L(t) - p_load| <= load_bound`` at every instant after it, any
signal; ``"steps"``, the total variation of ``dP_L - p_load`` from the certification
on, its initial offset included, at most ``load_bound``: one step, a ramp or any
monotone change of at most ``load_bound``, at any instant; ``"period"``, ``|dP_L(t)
- p_k| <= load_bound`` within each control period from the load ``p_k`` given at its
start, the command applied then certified, new or held, for that period) and a start
from a state where some command is certified (e.g. equilibrium): the measured
frequency and ROCOF stay inside ``|dw_meas| <= F`` and ``|rocof_meas| <=
rocof_limit`` at every instant, whatever the incoming commands are — OF2, UF2 and
ROCOF never trip, for any relay sampling. No bound on ``|p_load|`` is needed: a
constant load only shifts the equilibrium (command ``u = p`` with ``dPg = dPm = p``
keeps both outputs at 0), so in the shifted coordinates ``(x - x_eq(p), u - p)``
every condition, the derivative bound included, is the same for every ``p``
(:func:`_derivative_bound`; ``tests/test_proven_recovery.py``). The load is covered
by tightening every limit by ``load_bound`` times the load-to-output gain of its
kind (:func:`load_gains`: the L1 norm of the impulse response for ``"band"``, exact
for the worst signal; the peak of the step response for ``"steps"``, exact for one
step, 3.7 times smaller on the default plant's ROCOF), and an error ``e_p`` in the
load estimate by the estimation bound; a bound that leaves nothing is rejected at
construction, naming what is left (:func:`largest_load_bound` finds the largest).
Not covered with ``noise_std``: the Kalman estimate's transient after a load step
(its error leaves the steady-state ellipsoid until the load estimate has caught up).
With ``trips_per_hour``, the limits are tightened further so that relays reading the
outputs through white Gaussian noise ``noise_std`` at ``relay_rate`` trip at most
that often (a union bound over an hour of samples).

**What ``outside`` means.**  On the design model (no ``uncertainty``) with the
exact state and ``load_kind`` ``"band"`` or ``"steps"`` (proven): never raised
while the load stays within its assumption since each certification, the load
given (``load_feedforward``) or not (taken for 0) — a flag means an assumption is
broken.  The held level adds back what such a load can have done since the
certification (the state holds its effect).  ``"band"``: the held command is
checked at the load given at its certification, ``s`` s ahead with room for
``load_bound int_s^inf |h|`` (:func:`~lfc.filters.responses.load_tails`), the
current outputs for ``load_bound int_0^inf |h|``, the terminal state for
:func:`~lfc.filters.bounds.band_moves_terminal`.  ``"steps"`` (theorem C of
``docs/coupled-certificate.md`` for one area): the rows for ``load_bound`` times
``sup |S|`` (the load given) or ``sup S - inf S`` (not given), the equilibrium for
the load's shift of it, the terminal set for
:func:`~lfc.filters.bounds.load_moves_terminal`; with ``recheck_bound``,
``load_bound - recheck_bound``.  A held command is also flagged when the load
given leaves the assumption, sampled at the calls (not on an estimate, nor with
``recheck_bound``).  ``"period"`` (a grid's areas, :mod:`lfc.linear_grid`), and
``"band"`` on an estimate: the held check is a re-certification at the load given
now with the whole band around it — passing it proves the hold for the coming
period (the grids' per-area guarantee rests on it); ``outside`` means only that it
could not be re-proven from this state, and is raised when the load has moved
within the band since the certification.  With a box or an estimate none is
proven.  No sampled filter flags a trip within one control period of an
assumption breaking; a load beyond a band that is not given shows only through
the state, possibly after a trip.  ``tests/test_proven_load.py`` pins each.

**A hold proven period by period** (``recheck_bound`` > 0, ``load_kind="steps"``).
Without it a held command is proven only while the load's total variation since
that command was *certified* stays within ``load_bound``; a disturbance that keeps
moving (an interconnected area's tie-line flow) can exceed it while a command is
held.  With it, the held command's re-check also leaves room for a total variation
of ``recheck_bound`` within the coming control period (each limit tightened by
``recheck_bound`` times the step response's peak over one period,
:func:`period_step_gain`; at most what ``load_bound`` takes, so a command certified
now passes its own re-check; and at most ``load_bound``, which covers a new command's
first period), so the guarantee above also holds under this assumption instead: at
every control sample the applied command is new (and the load's variation from then
on is within ``load_bound``) or held and re-checked without an ``outside`` flag, and
within each control period the load varies by at most ``recheck_bound`` — whatever
it did before.  Proven up to the first
``outside`` flag; ``tests/test_proven_load.py`` checks it at steps of exactly
``recheck_bound`` landing at every instant of every attack.  The filter must be
given the load (``load_feedforward=True``) or an estimate of it: a run without
either is refused (:func:`lfc.engine.check_load_measured`).

**Measured, not proven.**  Plants inside the box but not at its corners (the
held response is not monotone in the parameters): tested on random interior
plants by ``tests/test_robust.py``.  That the estimation error stays within its
bound (the Kalman filter's steady-state error covariance at the design model and
``control_period``): not at the box's corners (the model mismatch drives an error
that grows with the state: an audit measured it leaving the 99.99 % ellipsoid at
the weak corners, where only the held command's re-check prevented a trip) nor in
the estimate's transient after a load step.  No trip has been measured on the Kalman estimate
over the box (``tests/test_robust.py``: 16 seeds x 23 attacks, design model
and weakest corner; one seed x 23 attacks at all 32 corners, where some runs
flag ``outside``: the error left its bound and the filter said so).  Off the
box (the corners of a ±40 % box) the filter trips, and every trip measured
came after an ``outside`` flag (0.05–7.7 s before) on that set — not in
general (module docstring, "What ``outside`` means").  ``margin`` tightens both
limits by a fraction for anything else (no guarantee there).

``details`` of a :class:`~lfc.filters.base.FilterInfo`: the certified interval
``(lo, hi)`` (pu; ``lo > hi`` where none is certified).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import ClassVar

import numpy as np
from scipy.linalg import expm, solve_continuous_lyapunov

from lfc._jit import inline, maxnum, minnum
from lfc._validate import check_nonnegative, check_pair, check_positive, check_range
from lfc.estimation import KalmanFilter, check_noise_std, measurement_std
from lfc.filters.base import (ACTIVE, BIND_CERT, INVALID, OUTSIDE, Backend, Layout,
                              Options, applied_flags, built_once, check_limits, given,
                              hold_invalid, option, valid_input)
from lfc.filters.bounds import (band_moves_terminal, curvature_gains, expm_at, intersample,
                                load_moves_terminal, merge_intervals, pair, tie_step_bound)
from lfc.filters.box import box_plants
from lfc.filters.responses import (L1_HORIZON, load_gains, load_tails, peak_norm,
                                   period_step_gain)
from lfc.model import LFCParams, lfc_matrices, output_matrix
from lfc.relays import RelaySettings

GRID = ((0.05, 1e-3), (0.1, 2e-3), (0.2, 5e-3), (2.0, 1e-2), (60.0, 2e-2))  # (until, step) s
MIN_STEP, MAX_STEP = 1e-3, 0.1  # s: the sample spacing of adaptive_grid
LOAD_KINDS = ("band", "steps", "period")   # what load_bound bounds (module docstring)
LP_LOAD = 1.0          # pu: load range of _derivative_bound's programs (V does not depend on it)
NUMERIC_MARGIN = 1e-6  # relative tightening that absorbs floating-point differences
#: the data array decide() reads: a header, then one block per plant (the design model
#: and the box's corners), each a head, then per output (frequency, ROCOF) ``m`` rows in
#: each of its columns, then the terminal ellipsoid
LAYOUT = Layout("u_min", "u_max", "n_plants", "n_rows", "f_lim", "r_lim", "load_room",
                "held_at_certified_load")
U_MIN, U_MAX, N_PLANTS, N_ROWS, F_LIM, R_LIM, LOAD_ROOM, HELD_AT_CERTIFIED_LOAD = \
    LAYOUT.offsets()
HEAD = LAYOUT.size
BLOCK = Layout("eq_per_p", "eq_half", "eq_half_held", "rho", "rho_held", "a_quad", "y0_f",
               "y0_r", "y0_f_held", "y0_r_held")
(EQ_PER_P, EQ_HALF, EQ_HALF_HELD, RHO, RHO_HELD, A_QUAD, Y0_F, Y0_R, Y0_F_HELD,
 Y0_R_HELD) = BLOCK.offsets()
BLOCK_HEAD = BLOCK.size
#: a row's columns: a, b (new), a, b (held), the five of G, l
COLUMNS = Layout(("ab", 2), ("ab_held", 2), ("G", 5), "l")
COL_A, COL_A_HELD, COL_G, COL_L = COLUMNS.offsets()
N_COLS = COLUMNS.size
#: the terminal ellipsoid after the rows: E (5x5), el (5), eu (5), P (5x5)
ELLIPSOID = Layout(("E", 25), ("el", 5), ("eu", 5), ("P", 25))
ELL_E, ELL_EL, ELL_EU, ELL_P = ELLIPSOID.offsets()
ELL_SIZE = ELLIPSOID.size


def grid(horizon: float) -> np.ndarray:
    """Sample times (s) of the certificate: ``GRID``'s steps up to ``horizon``."""
    times, start = [], 0.0
    for until, step in GRID:
        end = min(until, horizon)
        times += [start + step * (k + 1) for k in range(int(round((end - start) / step)))]
        start = end
        if start >= horizon:
            break
    return np.array(times)


@dataclass(frozen=True)
class CertifiedOptions(Options):
    """Options of the certified filter (``method="certified"``; with ``uncertainty``
    the robust one); their role in the guarantee: :class:`CertifiedSet`."""

    horizon: float = option(8.0, "s", "[0.2, 20]", "look-ahead before the terminal ellipsoid")
    load_bound: float = option(0.0, "pu", ">= 0 (largest_load_bound: the most)",
                               "how far the load may move from the p_load given; 0 covers "
                               "none (nominal, like uncertainty=0); a bound costs room "
                               "and alarms (load_during_attack.bound_price)")
    load_kind: str = option("band", "", "'band', 'steps' or 'period'",
                            "'band': |dP_L - p_load| <= load_bound at every instant after "
                            "the certification; 'steps': its total variation since "
                            "certification (a step, a ramp); 'period': a band around the "
                            "load given at each call, within that control period (a grid)")
    recheck_bound: float = option(0.0, "pu", ">= 0, with load_kind 'steps'",
                                  "the load's total variation within one control period that "
                                  "the held command's re-check covers (a hold then stays "
                                  "proven period by period)")
    margin: float = option(0.0, "", "[0, 1)", "extra fractional tightening of both limits")
    uncertainty: float | dict = option(0.0, "", "[0, 1) or {name: (low, high)} factors",
                                       "the plant box: a relative half-width of M, D, tau_g, "
                                       "tau_t, droop, or factors of some")
    noise_std: tuple[float, float] | None = option(
        None, "pu, pu/s", "None or two numbers >= 0",
        "measurement noise std of the Kalman estimate given; None: the exact state")
    sensor_bound: tuple[float, float] | None = option(
        None, "pu, pu/s", "None or two numbers > 0 (not with noise_std)",
        "how far the fused frequency and ROCOF readings may be from the meters' state "
        "(lfc.sensors: the median of redundant sensors); None: the exact state")
    confidence: float = option(0.9999, "", "(0, 1)",
                               "probability the estimation error lies in the covered ellipsoid")
    trips_per_hour: float | None = option(None, "1/h", "None or > 0 (needs noise_std)",
                                          "false trips allowed for relays reading noisy outputs")
    relay_rate: float = option(1000.0, "Hz", "> 0", "relay sampling rate of trips_per_hour")
    tightening: float = option(0.005, "", "[1e-4, 0.1]",
                               "how far an output may move between two certificate samples")
    u_min: float = option(-math.inf, "pu", "< u_max", "actuator limit on the applied command")
    u_max: float = option(math.inf, "pu", "> u_min", "actuator limit on the applied command")
    control_period: float = option(0.01, "s", "(0, 1]",
                                   "period of the calls (the Kalman estimate's covariance)")

    COLUMNS: ClassVar[tuple[str, ...]] = ("uncertainty", "margin", "declare_noise",
                                          "trips_per_hour", "noise_w", "noise_rocof",
                                          "sensor_bound_w", "sensor_bound_rocof")

    def __post_init__(self) -> None:
        super().__post_init__()
        check_range("horizon", self.horizon, 0.2, 20.0, closed=True)
        check_range("tightening", self.tightening, 1e-4, 0.1, closed=True)
        check_nonnegative("load_bound", self.load_bound)
        if self.load_kind not in LOAD_KINDS:
            raise ValueError(f"load_kind must be one of {LOAD_KINDS}, got {self.load_kind!r}")
        check_nonnegative("recheck_bound", self.recheck_bound)
        if self.recheck_bound > 0 and self.load_kind != "steps":
            raise ValueError(f"recheck_bound={self.recheck_bound!r} needs load_kind='steps' "
                             f"(with 'period' the re-check already covers load_bound for "
                             f"the coming period; 'band' covers the whole hold)")
        if self.recheck_bound > self.load_bound:
            raise ValueError(f"recheck_bound={self.recheck_bound!r} must be <= load_bound="
                             f"{self.load_bound!r}: a new command's first period is covered "
                             f"by load_bound")
        check_range("confidence", self.confidence, 0.0, 1.0)
        check_positive("relay_rate", self.relay_rate)
        check_positive("control_period", self.control_period)
        if self.control_period > 1.0:
            raise ValueError(f"control_period must lie in (0, 1] s, got {self.control_period!r}")
        if not 0.0 <= self.margin < 1.0:
            raise ValueError(f"margin must be in [0, 1), got {self.margin!r}")
        if self.noise_std is not None:
            pair = check_pair("noise_std", self.noise_std, positive=True)
            check_noise_std("noise_std", pair)
            object.__setattr__(self, "noise_std", pair)
        if self.sensor_bound is not None:
            bound = check_pair("sensor_bound", self.sensor_bound, positive=True)
            if self.noise_std is not None:
                raise ValueError(f"sensor_bound={self.sensor_bound!r} and noise_std cover the "
                                 f"same error: give one of them")
            object.__setattr__(self, "sensor_bound", bound)
        defaults = {f.name: f.default for f in fields(self)}
        for name, needs, needed in (("confidence", "noise_std", self.noise_std),
                                    ("relay_rate", "trips_per_hour", self.trips_per_hour)):
            if needed is None and getattr(self, name) != defaults[name]:
                raise ValueError(f"{name}={getattr(self, name)!r} has no effect without "
                                 f"{needs}: give {needs} or leave {name} at its default")
        if self.trips_per_hour is not None:
            if self.noise_std is None:
                raise ValueError("trips_per_hour needs noise_std (the relays' measurement "
                                 "noise)")
            most = 3600.0 * self.relay_rate   # one trip per relay sample: no tightening left
            check_range("trips_per_hour", self.trips_per_hour, 0.0, most)
        check_limits(self.u_min, self.u_max)
        if not self.u_min <= 0.0 <= self.u_max:
            raise ValueError(f"u_min <= 0 <= u_max is required (the filter starts by holding "
                             f"the equilibrium command 0), got u_min={self.u_min!r}, "
                             f"u_max={self.u_max!r}")
        for name in ("load_bound", "recheck_bound", "margin", "u_min", "u_max",
                     "control_period"):
            object.__setattr__(self, name, float(getattr(self, name)))

    def to_columns(self) -> dict:
        """``uncertainty``, ``margin``, ``trips_per_hour`` (NaN: none),
        ``declare_noise`` (whether a noise model is declared: the row's noise) and
        ``sensor_bound_w``, ``sensor_bound_rocof`` (NaN: none)."""
        bound = self.sensor_bound or (math.nan, math.nan)
        return {"uncertainty": self.uncertainty, "margin": self.margin,
                "trips_per_hour": math.nan if self.trips_per_hour is None
                else self.trips_per_hour, "declare_noise": self.noise_std is not None,
                "sensor_bound_w": bound[0], "sensor_bound_rocof": bound[1]}

    @classmethod
    def from_columns(cls, row: dict) -> dict:
        """The plant box ``uncertainty``, ``margin``, ``trips_per_hour`` and, with
        ``declare_noise``, the noise model of the row's Kalman estimate
        (:func:`lfc.estimation.measurement_std` of ``noise_w``, ``noise_rocof``:
        pu, pu/s), and the redundant sensors' bound ``sensor_bound_w``,
        ``sensor_bound_rocof`` (pu, pu/s; both or neither)."""
        raw = tuple(float(row.get(c, 0.0)) for c in ("noise_w", "noise_rocof"))
        noise = measurement_std(raw)
        declared = bool(row.get("declare_noise", False)) and any(v > 0 for v in raw)
        box, rate, margin = row.get("uncertainty"), row.get("trips_per_hour"), row.get("margin")
        bound = tuple(row.get(c) for c in ("sensor_bound_w", "sensor_bound_rocof"))
        return {"uncertainty": float(box) if given(box) else 0.0,
                "margin": float(margin) if given(margin) else 0.0,
                "noise_std": noise if declared else None,
                "trips_per_hour": float(rate) if given(rate) else None,
                "sensor_bound": tuple(map(float, bound)) if any(map(given, bound)) else None}


class CertifiedSet:
    """The certified-command intervals for a design model and a box of plants.

    Parameters
    ----------
    params : LFCParams
        Design model.
    relays : RelaySettings
    horizon : float
        Look-ahead before the terminal ellipsoid (s), in [0.2, 20] (longer adds
        samples where the held command no longer moves ROCOF, whose steady state
        is 0: the ellipsoid covers them).  Default 8 s: long enough for the weakly
        damped corners of a ±20 % box (damping 0.09) to settle toward it.
    load_bound : float
        How far the load may move from the ``p_load`` given (pu), >= 0.
    load_kind : {"band", "steps", "period"}
        What ``load_bound`` bounds (module docstring): the deviation from the load
        given at the certification (default), its total variation since then, or
        the deviation from the load given at each call within that control period
        (a grid's tie-line flow: the held command re-certified every period).
    margin : float
        Extra fractional tightening of both limits, in [0, 1).
    uncertainty : float or dict
        The plant box (:func:`box_plants`); 0: the design model only.
    noise_std : (float, float) or None
        Measurement noise std of ``(dw_meas, rocof_meas)`` (pu, pu/s) of the
        Kalman estimate the filter is given; None: the exact state.
    confidence : float
        Probability that the Kalman error lies in the ellipsoid the certificate
        covers (its covariance's chi-square quantile), in (0, 1).
    trips_per_hour : float or None
        With ``noise_std``: relays read the outputs through that noise at
        ``relay_rate``; tighten the limits so that they trip at most this often.
    relay_rate : float
        Relay sampling rate (Hz) of ``trips_per_hour``. Default 1 kHz.
    tightening : float
        How far (fraction of each limit) an output may move between two samples
        of the design model's certificate, in [1e-4, 0.1]; sets the sample spacing
        (:func:`adaptive_grid`).  Default 0.005: new commands lose at most about
        1 % of each limit to sampling, with about 300 samples over 8 s.
    u_min, u_max : float
        Actuator limits (pu).
    """

    def __init__(self, params: LFCParams, relays: RelaySettings, **options) -> None:
        o = self.options = CertifiedOptions.build("certified", options)
        self.params, self.relays = params, relays
        self.load_bound, self.margin, self.uncertainty = o.load_bound, o.margin, o.uncertainty
        self.noise_std, self.confidence, self.trips_per_hour = o.noise_std, o.confidence, \
            o.trips_per_hour
        self.u_min, self.u_max = o.u_min, o.u_max
        self.plants = box_plants(params, o.uncertainty)
        _check_stable(self.plants)
        cov = (_estimate_covariance(params, o.noise_std, o.control_period)
               if o.noise_std is not None else _sensor_cover(o.sensor_bound))
        from scipy.stats import chi2, norm   # here: scipy.stats takes 0.3 s to import

        self.kappa = (math.sqrt(chi2.ppf(o.confidence, len(cov))) if o.noise_std is not None
                      else 0.0 if cov is None else 1.0)
        limits = np.array([relays.F, relays.rocof_limit]) * (1 - o.margin) * (1 - NUMERIC_MARGIN)
        if o.trips_per_hour is not None:
            kappa_r = -norm.ppf(o.trips_per_hour / (2 * 3600 * o.relay_rate))
            limits = limits - kappa_r * np.asarray(o.noise_std, float)
        fine = grid(o.horizon)
        gains = [curvature_gains(lfc_matrices(p)[0], output_matrix(), fine) for p in self.plants]
        self.times = _design_grid(params, fine, gains, limits, o.tightening)
        self.blocks = [_PlantBlock(p, self.times, fine, g, limits, self.load_bound,
                                   o.load_kind, cov, self.kappa,
                                   (o.recheck_bound, o.control_period))
                       for p, g in zip(self.plants, gains)]
        self.n_rows = 2 * len(self.times)
        # the held command's load monitor: how far the load given may move from the one
        # given at its certification within the assumptions (none on an estimate, nor
        # with recheck_bound, whose hold is proven period by period however far it moved)
        monitored = cov is None and o.recheck_bound == 0 and o.load_kind != "period"
        self.load_room = o.load_bound * (1 + NUMERIC_MARGIN) + 1e-12 if monitored else math.inf
        self.tau = max(b.tau for b in self.blocks)   # largest inter-sample tightening (pu, pu/s)

    def pack(self) -> np.ndarray:
        """The data array :func:`decide` reads (layout in the module's constants)."""
        head = np.zeros(HEAD)
        head[:] = (self.u_min, self.u_max, len(self.blocks), self.n_rows,
                   self.relays.F, self.relays.rocof_limit, self.load_room,
                   float(self.blocks[0].held_at_certified_load))
        return np.concatenate([head] + [b.pack() for b in self.blocks])


def _design_grid(params: LFCParams, fine: np.ndarray, gains: list[np.ndarray],
                 limits: np.ndarray, tightening: float) -> np.ndarray:
    """The certificate's sample times: the coarsest subset of the graded grid
    ``fine`` on which every plant's outputs move at most ``tightening`` times
    their limits between samples (:func:`merge_intervals`), for the design
    model's derivative bound (on every 4th sample of ``fine`` after 0.05 s).
    Only the spacing comes from here: each plant's inter-sample bound is then
    proven on these times (:class:`_PlantBlock`)."""
    A, B = lfc_matrices(params)
    C = output_matrix()
    q = -np.linalg.solve(A, B)
    ref = fine[(fine <= 0.05) | (np.arange(len(fine)) % 4 == 0)]
    E = expm_at(A, ref)
    rest = np.eye(5)[None] - E
    V = _derivative_bound(A, B, C, C @ E, C @ rest @ q[:, 0], C @ rest @ q[:, 1], limits, q)
    envelope = np.max([g @ V for g in gains], axis=0) / limits
    return fine[merge_intervals(fine, envelope, tightening)]


class _PlantBlock:
    """The rows, equilibrium room and terminal ellipsoid of one plant.

    Attributes read by the cvxpy reference (:mod:`lfc.filters.cvxpy_certified`),
    per level (``"new"``, ``"held"``): ``bounds`` (n, 2) the limits at each
    sample, ``y0`` (2,) on the current outputs, ``eq_half`` on the command
    around ``eq_per_p * p``, ``rho`` the terminal ellipsoid's radius in ``P``.
    """

    def __init__(self, plant: LFCParams, times: np.ndarray, fine: np.ndarray,
                 gains: np.ndarray, limits: np.ndarray, load: float, load_kind: str,
                 cov: np.ndarray | None, kappa: float, recheck: tuple[float, float]) -> None:
        A, B = lfc_matrices(plant)
        C = output_matrix()
        q = -np.linalg.solve(A, B)                       # x_eq = q[:, 0] u + q[:, 1] p
        gains_of_kind = load_gains(A, B[:, 1], C)
        gain = gains_of_kind["band" if load_kind == "period" else load_kind]
        self.load_gain = gain                             # per pu of load_bound
        lim = limits - load * gain                        # the load covered
        if np.any(lim <= 0):
            most = float(np.min(limits / gain))
            steps = gains_of_kind["steps"]
            hint = (f"; load_kind='steps' (one step, a ramp or any monotone change) takes "
                    f"{pair(steps)} per pu and allows < {float(np.min(limits / steps)):.4g} pu"
                    if load_kind != "steps" else "")
            raise ValueError(f"load_bound={load:g} pu is too large: with load_kind="
                             f"{load_kind!r} it takes {load:g} x {pair(gain)} of the limits "
                             f"{pair(limits)} (frequency pu, ROCOF pu/s) of plant {plant!r}; "
                             f"it must be < {most:.4g} pu before any other tightening "
                             f"(largest_load_bound gives the most that can be built){hint}")
        E = expm_at(A, times)                            # (n, 5, 5)
        G = C @ E                                         # y(t_k) = G x + hu u + hl p
        rest = np.eye(5)[None] - E
        hu, hl = C @ rest @ q[:, 0], C @ rest @ q[:, 1]
        if np.any(np.abs(hu) < 1e-15):
            raise ValueError("the held command has no effect on an output at some sample of "
                             "the horizon (a plant far from the design); shorten horizon")
        sub = (times <= 0.05) | (np.arange(len(times)) % 3 == 0)   # fewer rows: a superset
        V = _derivative_bound(A, B, C, G[sub], hu[sub], hl[sub], limits, q)
        tau = intersample(gains, V, fine, times)          # (n, 2) per sample
        t_max, tau0 = tau.max(axis=0), tau[0]
        self.tau = float(np.max(t_max / limits))
        if cov is not None:                    # the state and load estimates' error
            est = _error_bound(A, C, q[:, 1], cov, kappa)
            lim = lim - est
        else:
            est = np.zeros(2)
        # the held command's re-check (module docstring, "What outside means"): "period"
        # re-certifies at the load given now; "band" checks at the load given at the
        # certification with room for what the band did since, s ahead at most
        # load_bound int_s^inf |h|; "steps" (theorem C) with room for the load's total
        # variation times sup |S| (the load given) or sup S - inf S (not given), less
        # recheck_bound's room for the coming period; on an estimate (nothing proven)
        # "band" re-certifies as "period" does, at the latest estimate of the load
        self.held_at_certified_load = since = load_kind == "band" and cov is None
        if since:
            held = lim + load * load_tails(A, B[:, 1], C, times)   # (n, 2)
        elif load_kind == "steps":
            held = lim + load * (gain if recheck[0] > 0 else gains_of_kind["swing"])
        else:
            held = lim
        # recheck_bound: the held command's trajectory must leave room for the load's
        # variation within the coming period, whose effect until the next sample is at
        # most its total variation times the step response's peak over one period
        again = recheck[0] * period_step_gain(A, B[:, 1], C, recheck[1])
        if np.any(again > load * gain):   # recheck <= load: only by the gains' roundings
            raise ValueError(f"recheck_bound={recheck[0]:g} pu takes {pair(again)} of the "
                             f"limits in one period, more than load_bound={load:g} pu takes "
                             f"({pair(load * gain)}): a command certified now would fail "
                             f"its own re-check; raise load_bound or lower recheck_bound")
        held = held - again
        self.budget = {"limits": limits, "load": load * gain, "estimate": est,
                       "between samples": t_max + tau0, "re-check": again}
        # new commands: every sample tau_max plus its own tau inside, so that the
        # trajectory stays tau_max inside between samples; the held one: tau_max
        self.plant, self.times = plant, times
        self.bounds = {"new": lim - t_max - tau, "held": np.broadcast_to(held - t_max, tau.shape)}
        self.rows = {level: _rows(hu, b) for level, b in self.bounds.items()}
        self.G = (G / hu[..., None]).reshape(-1, 5)       # rows normalized by hu
        self.l = (hl / hu).ravel()
        # the current outputs: for [0, t_1] to stay tau_max (new) or 0 (held) inside;
        # "band": they hold what the load did since, at most load_bound int_0^inf |h|
        self.y0 = {"new": lim - t_max - tau0,
                   "held": (lim + load * gain if since else held) - tau0}
        if np.any(self.y0["new"] <= 0):
            raise ValueError(f"the tightenings leave nothing of the relay limits: "
                             f"{self._budget()}; lower load_bound, noise_std, "
                             f"trips_per_hour or margin")
        spent = load - recheck[0] if load_kind == "steps" else 0.0
        self._terminal(A, B[:, 1], C, q, times[-1],
                       {"new": lim, "held": np.min(np.atleast_2d(held), axis=0)}, t_max, cov,
                       kappa, spent=spent, load_given=recheck[0] > 0,
                       band=load if since else 0.0)

    def _terminal(self, A, bl, C, q, horizon, lims, t_max, cov, kappa, *, spent,
                  load_given, band) -> None:
        """Continuous-time Lyapunov ellipsoid around the held command's equilibrium,
        the room that leaves the equilibrium, and ``e_T = E x + eu u + el p``.

        The new level's ellipsoid takes at most half of the frequency's room and its
        equilibrium the rest.  The held level absorbs what a load within the
        assumptions did since the certification: ``"steps"`` (``spent`` pu,
        ``load_bound`` less ``recheck_bound``) moves the equilibrium frequency by at
        most ``spent |dw_p|`` and ``e_T`` by ``spent`` times :func:`load_moves_terminal`
        in ``P``'s norm (``load_given``: with ``recheck_bound``), ``"band"`` (``band``
        pu) ``e_T`` by ``band`` times :func:`band_moves_terminal`; so a command
        certified at the new level passes the held one (exact state, this plant).
        Where the held rows' room fits a wider pair the held level takes it.  It need
        not fit the limits: a held command is proven by its certification (with
        ``recheck_bound``, period by period by its rows), not by this check."""
        lim_new = lims["new"] - 2 * t_max
        scale = np.array([1.0, 1.0, lim_new[0], lim_new[0], lim_new[1]])
        self.P = solve_continuous_lyapunov(A.T, -np.diag(scale ** -2.0))
        sigma = np.sqrt(np.einsum("ij,jk,ik->i", C, np.linalg.inv(self.P), C))
        self.E = expm(A * horizon)
        self.eu, self.el = -self.E @ q[:, 0], -self.E @ q[:, 1]
        self.a_quad = float(self.eu @ self.P @ self.eu)
        dw_u, dw_p = (C @ q)[0]
        error, eq_error = 0.0, 0.0
        if cov is not None:   # the estimates' error moves e_T by [E, el] e, dw_eq by dw_p e_p
            half = np.linalg.cholesky(cov)
            m = np.column_stack([self.E, self.el]) @ half
            error = kappa * math.sqrt(np.max(np.linalg.eigvalsh(m.T @ self.P @ m)))
            eq_error = kappa * math.sqrt(cov[5, 5]) * abs(dw_p / dw_u)
        self.eq_per_p = -dw_p / dw_u
        room = lims["new"] - 2 * t_max
        r = float(min(0.5 * room[0] / sigma[0], room[1] / sigma[1]))
        if r <= 0:
            raise ValueError(f"the tightenings leave no room for the terminal set: "
                             f"{self._budget()}; lower load_bound, noise_std, "
                             f"trips_per_hour or margin")
        h = room[0] - r * sigma[0]
        moved = (spent * load_moves_terminal(A, bl, self.E, self.P, load_given=load_given)
                 + band * band_moves_terminal(A, bl, self.E, self.P))
        drift = spent * abs(dw_p)
        # the held level: theorem C's, NUMERIC_MARGIN wider (a command certified on the
        # new level's boundary, with a load of exactly the bound since, lands on it), or
        # the largest pair that fits the held rows' room if that is wider
        wide = 1.0 + NUMERIC_MARGIN
        hold = lims["held"] - t_max
        r_fit = float(min(0.5 * hold[0] / sigma[0], hold[1] / sigma[1]))
        self.rho = {"new": r - error, "held": max((r + moved) * wide, r_fit) - error}
        self.eq_half = {"new": h / abs(dw_u) - eq_error,
                        "held": max((h + drift) * wide, hold[0] - r_fit * sigma[0])
                        / abs(dw_u) - eq_error}
        if self.rho["new"] <= 0:
            raise ValueError(f"the estimation error moves the state at the horizon by "
                             f"{error:.3g} in the terminal set's norm, more than the radius "
                             f"{self.rho['new'] + error:.3g} the other tightenings leave "
                             f"({self._budget()}); lower load_bound, noise_std or confidence")

    def _budget(self) -> str:
        """Each tightening of the limits, for an error message (pu; pu/s)."""
        return ", ".join(f"{name} {pair(v)}" for name, v in self.budget.items())

    def pack(self) -> np.ndarray:
        """Header, then per output (frequency, ROCOF) its rows column by column
        (``a`` and ``b`` new, ``a`` and ``b`` held, the five columns of ``G``,
        ``l``; contiguous, so the compiled loop vectorizes), then the ellipsoid."""
        head = np.zeros(BLOCK_HEAD)
        head[:] = (self.eq_per_p, self.eq_half["new"], self.eq_half["held"], self.rho["new"],
                   self.rho["held"], self.a_quad, *self.y0["new"], *self.y0["held"])
        new, held = self.rows["new"], self.rows["held"]
        parts = [head]
        for o in range(2):   # rows alternate frequency, ROCOF: take every other one
            parts += [new[0][o::2], new[1][o::2], held[0][o::2], held[1][o::2],
                      *self.G[o::2].T, self.l[o::2]]
        out = np.concatenate(parts + [self.E.ravel(), self.el, self.eu, self.P.ravel()])
        if len(out) != BLOCK_HEAD + N_COLS * len(self.l) + ELL_SIZE:   # the layout above
            raise RuntimeError("the certified filter's data layout is inconsistent")
        return out


def _rows(hu: np.ndarray, lim: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(a, b)``: ``-lim <= G x + hu u + hl p <= lim`` reads
    ``a_i - s_i <= u <= b_i - s_i`` with ``s = (G x + hl p) / hu``; ``lim`` is (2,)
    or one pair per sample (n, 2)."""
    lim = np.broadcast_to(lim, hu.shape)
    up, dn = lim / hu, -lim / hu
    return np.minimum(up, dn).ravel(), np.maximum(up, dn).ravel()


def _error_bound(A: np.ndarray, C: np.ndarray, q_p: np.ndarray, cov: np.ndarray,
                 kappa: float) -> np.ndarray:
    """How far the estimates' error ``e = (e_x, e_p)`` can move each output, at any
    time of a held trajectory with a constant true load: the true trajectory is
    the estimated one plus ``w(t) e`` with ``w(t) = [C e^{At}, C (I - e^{At}) q_p]``,
    so over the error ellipsoid ``e' cov^-1 e <= kappa^2`` the shift is at most
    ``kappa sup_t ||w(t) L||`` (``cov = L L'``): an enclosure
    (:func:`~lfc.filters.responses.peak_norm`) from a grid of 0.1 ms to 0.2 s,
    1 ms to 2 s and 10 ms to ``L1_HORIZON`` (finest where the fast modes move)."""
    t = np.concatenate([np.arange(0.0, 0.2, 1e-4), np.arange(0.2, 2.0, 1e-3),
                        np.arange(2.0, L1_HORIZON + 1e-9, 1e-2)])
    L = np.linalg.cholesky(cov)
    M = np.hstack([np.eye(len(A)), -q_p[:, None]]) @ L
    offset = np.hstack([np.zeros((len(C), len(A))), (C @ q_p)[:, None]]) @ L
    return kappa * peak_norm(A, C, M, offset, t)


def _derivative_bound(A: np.ndarray, B: np.ndarray, C: np.ndarray, G: np.ndarray,
                      hu: np.ndarray, hl: np.ndarray, limits: np.ndarray,
                      q: np.ndarray) -> np.ndarray:
    """``V >= |x'|`` entrywise, ``x' = A x + B [u; p]``, over every state and
    command whose held outputs satisfy the untightened limits at the samples of
    ``G, hu, hl`` (a superset of the certified ones) and the equilibrium's
    frequency inside the limit: ten linear programs.

    The value does not depend on the load ``p``: with ``x = x' + x_eq(p, p)`` and
    ``u = u' + p`` (the equilibrium of command ``p`` under load ``p``, where both
    outputs are 0: ``dw_eq = (u - p) / (D + 1/droop)``), neither the constraints
    nor ``x' = A x' + B_u u'`` contain ``p``.  The programs fix ``|p| <= LP_LOAD``
    only to stay well posed; ``V`` bounds the derivative for every load."""
    Gz = np.concatenate([G.reshape(-1, 5), hu.reshape(-1, 1), hl.reshape(-1, 1)], axis=1)
    lim = np.tile(limits, len(G))
    dw_u, dw_p = (C @ q)[0]
    eq = np.array([[0, 0, 0, 0, 0, dw_u, dw_p], [0, 0, 0, 0, 0, -dw_u, -dw_p]])
    a_ub = np.vstack([Gz, -Gz, eq])
    b_ub = np.concatenate([lim, lim, [limits[0], limits[0]]])
    bounds = [(None, None)] * 6 + [(-LP_LOAD, LP_LOAD)]
    return rate_bound(np.hstack([A, B]), a_ub, b_ub, bounds)


def rate_bound(M: np.ndarray, a_ub: np.ndarray, b_ub: np.ndarray,
               bounds: list[tuple]) -> np.ndarray:
    """``V_i = max |M_i v|`` over ``a_ub v <= b_ub`` within ``bounds`` (two linear
    programs per row of ``M``): the rate of change ``x' = M v`` of a state and
    input ``v`` over a polytope."""
    from scipy.optimize import linprog    # here: 0.14 s to import, only a build needs it

    V = np.zeros(len(M))
    for i in range(len(M)):
        for sign in (1.0, -1.0):
            res = linprog(-sign * M[i], A_ub=a_ub, b_ub=b_ub, bounds=bounds, method="highs")
            if res.status != 0:   # unbounded or numerically hopeless: parameters too extreme
                raise ValueError(f"the certificate cannot bound the state's rate of change for "
                                 f"these parameters (linear program: {res.message}); check "
                                 f"params and relays for extreme values")
            V[i] = max(V[i], -res.fun)
    return V


def largest_load_bound(params: LFCParams, relays: RelaySettings, *, tol: float = 1e-3,
                       **options) -> float:
    """The largest ``load_bound`` (pu, within ``tol``) for which the certified
    filter with ``options`` can be built: bisection on construction, from 0 (a
    ``ValueError`` if even that cannot be built) up to where the load alone takes a
    whole limit at some plant.  ``tol`` must lie in [1e-9, 1] pu (finer is below
    what the construction resolves, and the bisection would not end).  Ten or so
    constructions: the answer is kept (:func:`built_once`, on disk too)."""
    check_range("tol", tol, 1e-9, 1.0, closed=True)
    return built_once(lambda: _bisect_load_bound(params, relays, tol, options),
                      "largest_load_bound", params, relays, tol, sorted(options.items()),
                      store=True)


def _bisect_load_bound(params: LFCParams, relays: RelaySettings, tol: float,
                       options: dict) -> float:
    def builds(bound: float) -> bool:
        try:
            CertifiedSet(params, relays, **{**options, "load_bound": bound})
        except ValueError:
            return False
        return True

    unloaded = CertifiedSet(params, relays, **{**options, "load_bound": 0.0})
    gains = np.max([b.load_gain for b in unloaded.blocks], axis=0)
    lo, hi = 0.0, float(np.min(np.array([relays.F, relays.rocof_limit]) / gains))
    while hi - lo > tol and 0.5 * (lo + hi) not in (lo, hi):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if builds(mid) else (lo, mid)
    return lo


def _estimate_covariance(params: LFCParams, noise_std: tuple[float, float],
                         period: float) -> np.ndarray:
    """The steady-state error covariance (6 x 6: states and load) of the Kalman
    filter ``simulate(estimator="kalman", noise_std=noise_std,
    control_period=period)`` uses."""
    return KalmanFilter(params, period, meas_std=noise_std).posterior_covariance


def _sensor_cover(bound: tuple[float, float] | None) -> np.ndarray | None:
    """An ellipsoid ``e' cov^-1 e <= 1`` holding every error of the fused readings,
    ``|e_dw_meas| <= bound[0]``, ``|e_rocof_meas| <= bound[1]``, the other states and the
    load exact: ``cov`` = diag(0, 0, 0, 2 b0^2, 2 b1^2, 0) (a box's corner is on it), the
    zeros 1e-30 so that it factors."""
    if bound is None:
        return None
    return np.diag([1e-30, 1e-30, 1e-30, 2 * bound[0] ** 2, 2 * bound[1] ** 2, 1e-30])


def _check_stable(plants: list[LFCParams]) -> None:
    """``ValueError`` unless every plant of the box is asymptotically stable (the
    hold backup law needs it: an unstable plant has no certified command)."""
    for plant in plants:
        growth = float(np.max(np.linalg.eigvals(lfc_matrices(plant)[0]).real))
        if growth >= 0:
            raise ValueError(f"uncertainty: the plant {plant!r} of the box is unstable "
                             f"(eigenvalue real part {growth:.3g} 1/s >= 0); narrow the box")


class CertifiedFilter(Backend):
    """The certified filter (method ``"certified"``), options
    :class:`CertifiedOptions`: clip to the certified interval of
    :class:`CertifiedSet`, or hold the last certified command."""

    name, Options = "certified", CertifiedOptions

    @classmethod
    def grid_options(cls, grid, area: int, relays: RelaySettings,
                     control_period: float) -> dict:
        """In a grid: ``load_bound`` the tie-line's move in one period
        (:func:`~lfc.filters.bounds.tie_step_bound`) with ``load_kind="period"``
        (re-certified every period) and the grid's ``command_range`` as the actuator
        limits (where a fitted model describes its plant)."""
        span = grid.command_range
        return {"load_bound": tie_step_bound(grid, area, relays, control_period),
                "load_kind": "period", "u_min": -span, "u_max": span}

    def __init__(self, params: LFCParams, relays: RelaySettings,
                 options: CertifiedOptions) -> None:
        super().__init__(params, relays, options)
        self.cert = built_once(lambda: CertifiedSet(params, relays, **options.as_dict()),
                               CertifiedSet, params, relays, options, store=True)
        self.data = self.cert.pack()

    def reason(self, flags: int) -> str:
        if flags & INVALID:
            return ("invalid input (non-finite or beyond 1e6: a corrupted message); last "
                    "certified command held")
        if flags & OUTSIDE:
            return ("nothing is certified and the last command fails its own check (exact "
                    "state, design model: the load moved beyond load_bound; with a box or "
                    "an estimate also a plant outside it, a larger estimation error, or the "
                    "check's conservatism); last certified command held")
        if flags & ACTIVE and not flags & BIND_CERT:
            return "no new command is certified from this state; last certified command held"
        return "command clipped to the certified interval" if flags & ACTIVE else ""

    def details(self, d0: float, d1: float, flags: int) -> dict:
        return {"interval": (d0, d1)}


@inline
def _output_interval(fd: np.ndarray, r0: int, m: int, x: np.ndarray, p: float,
                     held: bool) -> tuple:
    """The interval one output's ``m`` rows (from ``fd[r0]``) allow: ``(lo, hi)``."""
    a0 = r0 + (COL_A_HELD if held else COL_A) * m
    g0 = r0 + COL_G * m
    a, b = fd[a0:a0 + m], fd[a0 + m:a0 + 2 * m]        # views: the loop reads them in step
    g_0, g_1, g_2 = fd[g0:g0 + m], fd[g0 + m:g0 + 2 * m], fd[g0 + 2 * m:g0 + 3 * m]
    g_3, g_4 = fd[g0 + 3 * m:g0 + 4 * m], fd[g0 + 4 * m:g0 + 5 * m]
    l0 = r0 + COL_L * m
    g_l = fd[l0:l0 + m]
    x0, x1, x2, x3, x4 = x[0], x[1], x[2], x[3], x[4]
    lo, hi = -np.inf, np.inf
    for i in range(m):   # maxnum, minnum: vectorized by LLVM (lfc._jit)
        s = g_0[i] * x0 + g_1[i] * x1 + g_2[i] * x2 + g_3[i] * x3 + g_4[i] * x4 + g_l[i] * p
        lo, hi = maxnum(lo, a[i] - s), minnum(hi, b[i] - s)
    return lo, hi


@inline
def _block_interval(fd: np.ndarray, b0: int, n: int, x: np.ndarray, p: float,
                    held: bool) -> tuple:
    """One plant's certified interval per output, ``(lo_f, hi_f, lo_r, hi_r)``
    (pu; empty where ``lo > hi``), at the level for new commands or the held one."""
    inf = np.inf
    if (abs(x[3]) > fd[b0 + (Y0_F_HELD if held else Y0_F)]
            or abs(x[4]) > fd[b0 + (Y0_R_HELD if held else Y0_R)]):
        return inf, -inf, inf, -inf                       # the current outputs too close
    m = n // 2
    lo_f, hi_f = _output_interval(fd, b0 + BLOCK_HEAD, m, x, p, held)
    lo_r, hi_r = _output_interval(fd, b0 + BLOCK_HEAD + N_COLS * m, m, x, p, held)
    centre = fd[b0 + EQ_PER_P] * p                        # room at the equilibrium
    half = fd[b0 + (EQ_HALF_HELD if held else EQ_HALF)]
    lo_f, hi_f = max(lo_f, centre - half), min(hi_f, centre + half)
    t0 = b0 + BLOCK_HEAD + N_COLS * n                     # terminal ellipsoid
    el = t0 + ELL_EL                                      # e = E x + el p
    e0, e1, e2, e3, e4 = (p * fd[el], p * fd[el + 1], p * fd[el + 2], p * fd[el + 3],
                          p * fd[el + 4])
    for k in range(5):
        e0 += fd[t0 + ELL_E + k] * x[k]
        e1 += fd[t0 + ELL_E + 5 + k] * x[k]
        e2 += fd[t0 + ELL_E + 10 + k] * x[k]
        e3 += fd[t0 + ELL_E + 15 + k] * x[k]
        e4 += fd[t0 + ELL_E + 20 + k] * x[k]
    e = (e0, e1, e2, e3, e4)
    rho = fd[b0 + (RHO_HELD if held else RHO)]
    qb, qc = 0.0, -rho * rho
    for r in range(5):
        pe = 0.0
        for k in range(5):
            pe += fd[t0 + ELL_P + 5 * r + k] * e[k]
        qb += 2.0 * pe * fd[t0 + ELL_EU + r]
        qc += pe * e[r]
    a_quad = fd[b0 + A_QUAD]
    disc = qb * qb - 4 * a_quad * qc
    if disc < 0:
        return inf, -inf, inf, -inf
    root = math.sqrt(disc)
    e_lo, e_hi = (-qb - root) / (2 * a_quad), (-qb + root) / (2 * a_quad)
    return max(lo_f, e_lo), min(hi_f, e_hi), max(lo_r, e_lo), min(hi_r, e_hi)


@inline
def _interval(fd: np.ndarray, x: np.ndarray, p: float, held: bool) -> tuple:
    """The interval certified for every plant, per output: ``(lo_f, hi_f, lo_r, hi_r)``."""
    inf = np.inf
    n = int(fd[N_ROWS])
    stride = BLOCK_HEAD + N_COLS * n + ELL_SIZE
    lo_f, hi_f, lo_r, hi_r = -inf, inf, -inf, inf
    for j in range(int(fd[N_PLANTS])):
        a, b, c, d = _block_interval(fd, HEAD + j * stride, n, x, p, held)
        lo_f, hi_f, lo_r, hi_r = max(lo_f, a), min(hi_f, b), max(lo_r, c), min(hi_r, d)
        if max(lo_f, lo_r) > min(hi_f, hi_r):   # already empty: the other plants can't help
            break
    return lo_f, hi_f, lo_r, hi_r


@inline
def decide(fd: np.ndarray, x: np.ndarray, u_ref: float, p: float, mem: np.ndarray) -> tuple:
    """One call of the certified filter (module docstring).

    ``fd`` is :meth:`CertifiedSet.pack`'s data, ``mem[0]`` the last certified
    command (held when no new one is certified), ``mem[1]`` the load given at the
    last call, ``mem[2]`` its total variation since the certification (sampled: at
    most the true one): a held command is flagged ``outside`` if it fails its check
    or, with ``load_kind="steps"``, that variation exceeds ``load_bound`` (a breach of
    the assumptions; not with ``noise_std`` or ``recheck_bound``).  Returns ``(u, flags, h_freq,
    h_rocof, margin_freq, margin_rocof, y_freq, y_rocof, lo, hi)``; the margins
    are the distances from ``u`` to the ends of each relay's own interval.
    """
    if not valid_input(x, u_ref, p):
        return hold_invalid(mem, u_ref)
    lo_f, hi_f, lo_r, hi_r = _interval(fd, x, p, False)
    lo = max(lo_f, lo_r, fd[U_MIN])
    hi = min(hi_f, hi_r, fd[U_MAX])
    certified = lo <= hi
    flags = 0
    if certified:
        u = min(max(u_ref, lo), hi)
        mem[1], mem[2] = p, 0.0             # the load given now, its move since
    else:                                   # hold; check the held command at its own level
        u = mem[0]
        if fd[HELD_AT_CERTIFIED_LOAD] > 0:  # "band": at the load given at the certification
            lo_f, hi_f, lo_r, hi_r = _interval(fd, x, mem[1], True)
            moved = abs(p - mem[1])         # how far the load given left it
        else:
            lo_f, hi_f, lo_r, hi_r = _interval(fd, x, p, True)
            moved = mem[2] + abs(p - mem[1])    # the load given's total variation, sampled
            mem[1], mem[2] = p, moved
        if not (max(lo_f, lo_r) <= u <= min(hi_f, hi_r)) or moved > fd[LOAD_ROOM]:
            flags |= OUTSIDE
    mem[0] = u
    flags |= applied_flags(u, u_ref, certified, fd[U_MIN], fd[U_MAX])
    m_f = min(u - lo_f, hi_f - u)
    m_r = min(u - lo_r, hi_r - u)
    return (u, flags, fd[F_LIM] ** 2 - x[3] ** 2, fd[R_LIM] ** 2 - x[4] ** 2, m_f, m_r, x[3],
            x[4], lo, hi)
