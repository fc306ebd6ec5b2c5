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
Lyapunov one leaves no room: ``terminal``, :func:`~lfc.filters.coupled_set.shaped_terminal`).  Every condition is affine in ``u_k`` (the ellipsoid a convex
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
reachable subspace (:func:`~lfc.multiarea.reduced_model`), where the held grid is
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
grid-wide Kalman filter (:class:`~lfc.filters.coupled_set.GridKalman`) that fuses every area's frequency,
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
fitted to ANDES, whose range :func:`lfc.testbed.fit.validated_range`
measures).  Without it the filters certify, on a fitted model, commands that
push gigawatts over a tie the model treats as linear.

**The fit's mismatch.**  A model fitted to ANDES also carries its distance from
ANDES as load (``MultiAreaParams.load_mismatch``: :func:`lfc.testbed.fit.grid_mismatch`
over the fit's records within the command range).  By default
(``mismatch_budget``) the filter adds it to ``load_bound`` and chooses its horizon
with it (``horizon="auto"`` unless given), and refuses command limits beyond the
range, where the mismatch was not measured (there a red-team attack on the IEEE
39-bus system trips ROCOF on ANDES with no flag:
``tests/test_coupled.py::test_on_andes_ieee39_the_red_teams_winner_leaves_the_certificate_only_beyond_the_range``).
The theorems then hold on the model with the larger budget; on ANDES the
statement is measured, assuming the mismatch stays within the budget, as it did
over the fit's records.

**Not covered.**  Other estimators (refused), plants other
than the design grid, an area without this filter, a sensor that lies (measured: a
frequency meter stuck from 1 s and an honest load step within ``load_bound`` trip through
these filters on the estimate, unflagged, where the certified ones trip nothing:
``tests/test_sensor_attacks.py::test_finding_a_stuck_frequency_meter_and_an_honest_load_step_trip_through_the_coupled_filter``).  On ANDES (``lfc.simulate``
of a ``GridCase``) the filters read each area's metered states and tie-line
export (:meth:`CoupledFilter.grid_state`), or on the estimate the grid Kalman
filter reads the metered frequency, ROCOF and exports, and the certificate (and
the estimate's error bound) is the fitted model's: measured there, not proven
(``tests/test_coupled_estimate.py::test_on_andes_the_coupled_filters_run_on_their_estimate``).  Within the command range and with the
fit's mismatch in the budget, the red team's winners trip nothing there and flag
nothing
(``tests/test_coupled.py::test_on_andes_ieee39_the_red_teams_winner_leaves_the_certificate_only_beyond_the_range``).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from lfc._jit import inline
from lfc._validate import (ParameterTypeError, as_float, check_array, check_index,
                           check_number, check_range)
from lfc.filters.base import ACTIVE, BIND_CERT, INVALID, OUTSIDE, built_once
from lfc.filters.coupled_kernel import N_R, decide_once, grid_estimate, rows_scratch
from lfc.filters.coupled_kernel import decide as decide_rows
from lfc.filters.coupled_set import CoupledOptions, CoupledSet
from lfc.multiarea import N_AREA_STATES, MultiAreaParams, discretize_grid
from lfc.relays import RelaySettings

AUTO_HORIZONS = (8.0, 12.0, 16.0, 20.0)   # s: horizon="auto"'s candidates, shortest first
AUTO_HELD_MAX = 1.0   # s: how long "auto" lets a legitimate step leave AGC waiting (it restores
                      # in about 20 s on the grids of docs/coupled-certificate.md)
OUTSIDE_WHY = {   # what an outside flag may mean: the exact state, then each held level
    None: "the loads moved by more than the bounds",
    "sharp": "the loads moved by more than the bounds, or the estimator has not yet seen a "
             "load step",
    "widened": "the loads moved by more than the bounds, or the estimate's noise left its "
               "ellipsoid",
    "strict": "the loads moved by more than the bounds, the estimator has not yet seen a "
              "load change, or the estimate's noise left its ellipsoid"}


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
        ``noise_std=(1e-4, 1e-3)`` without its fit's mismatch, 8 s with it
        (``tests/test_coupled_estimate.py``).  On a model with a ``load_mismatch``
        and ``mismatch_budget`` (the default) the horizon's default is ``"auto"``,
        and ``u_min``/``u_max`` beyond its ``command_range`` are refused.

    Attributes
    ----------
    options : CoupledOptions
        The options it was built with (``horizon`` the one chosen).
    horizons : dict
        With ``horizon="auto"``: each horizon tried (s) and what it gave, the
        seconds :meth:`held_after_step` returned or, for one that did not build,
        the reason; else empty.
    mismatch : float
        The load budget (pu) added to ``options.load_bound`` for the design model's
        ``load_mismatch`` (0 without ``mismatch_budget``); its ``repr`` names both.

    Raises
    ------
    ValueError
        For an invalid option, a grid that is not stable with its commands held,
        or tightenings that leave nothing of the limits (the message says which);
        with ``horizon="auto"``, if no candidate builds (each one's reason).
    """

    #: a grid-wide method: its decision is :func:`decide_grid`, its ``method_id`` the code
    #: :func:`lfc.filters.dispatch.assign` gives it
    name, grid_wide = "coupled", True

    def __init__(self, params: MultiAreaParams, relays: RelaySettings, **options) -> None:
        if not isinstance(params, MultiAreaParams):
            raise ParameterTypeError(f"params must be a MultiAreaParams, got "
                                     f"{type(params).__name__}")
        if not isinstance(relays, RelaySettings):
            raise ParameterTypeError(f"relays must be a RelaySettings, got {relays!r}")
        self.params, self.relays = params, relays
        # the model holds within its command range: the commands stay there; a fitted
        # model's mismatch is a load budget, and its horizon is chosen with it
        fitted = params.load_mismatch > 0 and options.get("mismatch_budget", True)
        options = {"u_min": -params.command_range, "u_max": params.command_range,
                   "horizon": "auto" if fitted else CoupledOptions.horizon, **options}
        self.horizons: dict[float, float | str] = {}
        if isinstance(options.get("horizon"), str):
            options["horizon"], self.horizons = auto_horizon(params, relays, options)
        self.options = o = CoupledOptions(**options)
        self.mismatch = params.load_mismatch if o.mismatch_budget else 0.0
        if self.mismatch and max(-o.u_min, o.u_max) > params.command_range:
            raise ValueError(f"u_min={o.u_min:g}, u_max={o.u_max:g} pu reach beyond the design "
                             f"model's command_range (±{params.command_range:g} pu), where its "
                             f"load_mismatch ({self.mismatch:.4g} pu) was not measured: keep the "
                             f"commands within it, or give mismatch_budget=False (the "
                             f"certificate without the fit's mismatch)")
        built = dataclasses.replace(o, load_bound=o.load_bound + self.mismatch)
        self.cert = built_once(lambda: CoupledSet(params, relays, built), CoupledSet, params,
                               relays, built, store=True)
        self.data, self.kalman = self.cert.data, self.cert.kalman

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in vars(self.options).items())
        return (f"CoupledFilter({self.params.n_areas} areas, {opts}; load budget "
                f"{self.options.load_bound:g} + fit mismatch {self.mismatch:.4g} pu)")

    def scratch_size(self) -> int:
        """The scratch entries :func:`decide_grid` needs inside a simulation."""
        return rows_scratch(self.data)

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

    def check_estimator(self, estimator, noise_std: tuple[float, float]) -> None:
        """``ValueError`` unless the filter is given what its certificate covers: the
        exact state (``estimator=None``) if built without ``noise_std``; its own grid
        Kalman filter (``"kalman"``) on measurement noise ``noise_std`` no larger than
        it was built for, if with it."""
        estimates = self.kalman is not None
        if estimator is None and estimates:
            raise ValueError("the coupled filter was built with noise_std (it covers its grid "
                             "Kalman estimate): give estimator='kalman'")
        if estimator is not None and not (estimates and isinstance(estimator, str)
                                          and estimator == "kalman"):
            raise ValueError(f"estimator={estimator!r}: the coupled filter reads the grid's "
                             f"exact state (a wide-area measurement); give estimator=None, or "
                             f"build it with noise_std and give estimator='kalman' (its own "
                             f"grid-wide Kalman filter)")
        built_for = self.options.noise_std
        if estimates and any(s > b for s, b in zip(noise_std, built_for)):
            raise ValueError(f"noise_std={tuple(noise_std)} exceeds the noise the coupled "
                             f"filter was built for ({built_for}): its error bound would not "
                             f"hold; build it with noise_std={tuple(noise_std)}")

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
            fit = (f", or the plant left the model by more than the fit's mismatch "
                   f"({self.mismatch:.3g} pu as load)" if self.mismatch else "")
            return (f"no command is certified and the vector held fails its own check "
                    f"({OUTSIDE_WHY[level]}{fit}); last certified command held")
        if flags & ACTIVE and not flags & BIND_CERT:
            return "no new command is certified from this state; last certified command held"
        return "command clipped to the certified interval" if flags & ACTIVE else ""


def check_coupled(filters: dict, grid: MultiAreaParams, estimator,
                  noise_std: tuple[float, float] = (0.0, 0.0)) -> None:
    """``ValueError`` unless a coupled filter (:mod:`lfc.filters.coupled`), if any,
    is the same one at every area, built for a grid of the design's areas and
    tie-lines, and given what its certificate covers: the exact state
    (``estimator=None``) if it was built without ``noise_std``, its own grid
    Kalman filter (``estimator="kalman"``) if with it, on measurement noise no
    larger than it was built for (its guarantee needs all three)."""
    coupled = [f for f in filters.values() if isinstance(f, CoupledFilter)]
    if not coupled:
        return
    if len(filters) != grid.n_areas or any(f is not coupled[0] for f in filters.values()):
        raise ValueError("a coupled filter must be the same CoupledFilter at every area (its "
                         "certificate holds every other area's command; an area without it "
                         "would move its command freely)")
    built = coupled[0].params
    if built.n_areas != grid.n_areas or [t[:2] for t in built.tie] != [t[:2] for t in grid.tie]:
        raise ValueError(f"the coupled filter was built for {built!r}, not for this grid's "
                         f"{grid.n_areas} areas and tie-lines {grid.tie}")
    coupled[0].check_estimator(estimator, noise_std)


@inline
def decide_grid(fd: np.ndarray, grid: tuple, estimate: tuple, first: bool, u_ref: float,
                mem: np.ndarray, x_hat: np.ndarray) -> tuple:
    """The coupled certificate's call at one area of the grid ``grid``
    (:class:`lfc.engine.GridView`), as :func:`lfc.filters.dispatch.decide_grid` makes
    it.  On the filter's grid Kalman estimate (``estimate``'s index >= 0, its matrices
    :class:`lfc.engine.Estimate`'s) area 0's call steps the estimator (predicting from
    the last sample unless ``first``) and every area reads it; the state the filter
    sees is written to ``x_hat`` (5,).  Returns the ten values of
    :func:`lfc.filters.coupled_kernel.decide` and the load it assumed for the area (pu)."""
    area, grid_x, grid_u, grid_p, ym, xe, ks, sums = grid
    est, ka, kb, kc, kg, _ = estimate
    if est >= 0:       # the grid's Kalman filter (state ks, area 0's), stepped by area 0
        if area == 0:
            grid_p = grid_estimate(fd, ka, kb, kc, kg, ks, ym[:kc.shape[0]],
                                   ym[kc.shape[0]:], grid_u, not first, xe)
        else:
            grid_p = ks[1, int(fd[N_R]):int(fd[N_R]) + len(grid_u)]
        grid_x = xe
        for r in range(N_AREA_STATES):
            x_hat[r] = xe[N_AREA_STATES * area + r]
    u, flags, h0, h1, m0, m1, q0, q1, d0, d1 = decide_rows(fd, grid_x, grid_u, grid_p,
                                                           area, u_ref, mem, sums)
    return u, flags, h0, h1, m0, m1, q0, q1, d0, d1, grid_p[area]
