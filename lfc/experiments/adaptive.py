"""An attacker that reads the filters (issue "Rigor", item 5).

Every other attack here is a waveform fixed before the run.  This one is a
white-box adversary in the loop: at each control period it learns, for every
area, the interval of commands the area's filter will pass now (by asking the
filter itself, on the state and memory it has: the certified interval, the
paper's constraint interval, the contract's box) and sends a command at one of
its edges — or ``inset`` of the interval's width inside it, where the filter
passes it unchanged and raises no alarm.  Which edge: the one a lookahead of
``lookahead`` control periods on the true plant (every area pinned at its chosen
edge, the filters and AGC in the loop) says brings a relay closest to its
setting, scored as ``max(2 w |dw_meas| / F, 2 (1 - w) |ROCOF| / limit)`` with
``w`` = ``frequency_weight``; the choice is made again every period (a receding
horizon).  Between ``start`` and ``stop``; outside, the command channels carry
nothing.

The plant is the linear grid of :mod:`lfc.lockstep` (one area is a grid of one),
the generator sides :class:`lfc.testbed.loop.GeneratorSides` — the engine's own
compiled code, so a filter reads here exactly what it reads in
:func:`lfc.simulate`.  :func:`adaptive_search` is the red team's search over the
attacker's three parameters.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import differential_evolution

from lfc._validate import (ParameterTypeError, check_count, check_number, check_positive,
                           check_seed)
from lfc.engine import CTRL_COLUMNS, check_area_keys
from lfc.filters import SafetyFilter
from lfc.filters.coupled import check_coupled
from lfc.generator import GeneratorSide
from lfc.linear_area import check_timing
from lfc.linear_grid import area_filter, estimate_noise
from lfc.lockstep import LinearGrid
from lfc.model import LFCParams
from lfc.multiarea import MultiAreaParams, as_grid
from lfc.relays import RelaySettings, relays_or_default
from lfc.result import Result

PROBE = 1e3      # pu: a command beyond every interval, which each filter clips to its edge
U_REF = CTRL_COLUMNS.index("u_ref")
BOUNDS = {"lookahead": (1.0, 10.0), "inset": (0.0, 0.2), "frequency_weight": (0.0, 1.0)}


@dataclass(frozen=True)
class AdaptiveAttack:
    """The attacker's policy (module docstring).

    Parameters
    ----------
    lookahead : int
        Control periods simulated ahead for each choice of edges, in [1, 100].
    inset : float
        How far inside the edge the command is sent, a fraction of the
        interval's width in [0, 0.5); 0: on the edge (the filter clips what goes
        beyond it, so the edge is what the plant gets either way).
    frequency_weight : float
        Weight of frequency against ROCOF in the lookahead's score, in [0, 1].
    start, stop : float
        When the attack acts (s); ``stop`` may be ``inf``.
    """

    lookahead: int = 10
    inset: float = 0.0
    frequency_weight: float = 0.5
    start: float = 1.0
    stop: float = math.inf

    def __post_init__(self) -> None:
        check_count("lookahead", self.lookahead)
        if self.lookahead > 100:
            raise ValueError(f"lookahead must lie in [1, 100] control periods, got "
                             f"{self.lookahead!r}")
        check_number("inset", self.inset)
        if not 0.0 <= self.inset < 0.5:
            raise ValueError(f"inset must lie in [0, 0.5), got {self.inset!r}")
        check_number("frequency_weight", self.frequency_weight)
        if not 0.0 <= self.frequency_weight <= 1.0:
            raise ValueError(f"frequency_weight must lie in [0, 1], got "
                             f"{self.frequency_weight!r}")
        check_number("start", self.start)
        check_number("stop", self.stop)
        if not 0.0 <= self.start < self.stop:
            raise ValueError(f"start and stop must satisfy 0 <= start < stop, got "
                             f"{self.start!r}, {self.stop!r}")


def _choices(n_areas: int) -> list[np.ndarray]:
    """The edge patterns tried each period: every sign vector up to three areas;
    beyond, all up, all down and the two alternations."""
    if n_areas <= 3:
        return [np.array([1.0 if (k >> a) & 1 else -1.0 for a in range(n_areas)])
                for k in range(2 ** n_areas)]
    alt = np.array([(-1.0) ** a for a in range(n_areas)])
    return [np.ones(n_areas), -np.ones(n_areas), alt, -alt]


class _Loop:
    """The plant and the generator sides, advanced a control period at a time, and
    copied for the attacker's lookahead without copying what never changes (the
    filters' data)."""

    def __init__(self, plant: LinearGrid, sides, gens: list[GeneratorSide]) -> None:
        self.plant, self.sides, self.gens = plant, sides, gens

    def branch(self) -> _Loop:
        memo = {}
        for gen in self.gens:
            for shared in (gen.scc, gen.data, gen.ka, gen.kb, gen.kc, gen.kg, gen.tc,
                           gen.noise, *gen.signals[:4]):
                memo[id(shared)] = shared
        for shared in (self.plant.A, self.plant.Bu, self.plant.Bl, self.plant.p,
                       self.plant.inc, self.plant.t):
            memo[id(shared)] = shared
        return copy.deepcopy(self, memo)

    def period(self, j: int, pc: np.ndarray, watch: bool = True) -> np.ndarray:
        """Control sample ``j`` with the command channels ``pc``; returns the
        commands the filters passed (pu).  ``watch``: the relays too."""
        for a, gen in enumerate(self.gens):
            gen.receive(j, float(pc[a]))
        u = self.sides.sample(j, self.plant.measured(j))
        self.plant.advance(j, u, watch)
        return u


def _score(plant: LinearGrid, k0: int, k1: int, relays: RelaySettings, weight: float) -> float:
    m, n_a = 5, plant.n_a
    seen = plant.xs[k0:k1 + 1, :m * n_a].reshape(-1, n_a, m)
    return max(2 * weight * float(np.max(np.abs(seen[:, :, 3]))) / relays.F,
               2 * (1 - weight) * float(np.max(np.abs(seen[:, :, 4]))) / relays.rocof_limit)


def run_adaptive(params: LFCParams | MultiAreaParams, filters, attack: AdaptiveAttack, *,
                 duration: float, design: LFCParams | MultiAreaParams | None = None,
                 loads: dict | None = None, relays: RelaySettings | None = None,
                 estimator=None, noise_std: tuple[float, float] = (0.0, 0.0), seed: int = 0,
                 dt: float = 1e-3, control_period: float = 0.01, anti_windup: bool = True,
                 load_feedforward: bool | None = None) -> Result:
    """Run the adaptive attacker against ``filters``.

    Parameters
    ----------
    params : LFCParams or MultiAreaParams
        The plant.
    filters : SafetyFilter, str or dict
        One area: a :class:`~lfc.filters.SafetyFilter` or a method name (built
        on ``design``); a grid: ``{area: kind or filter}`` as in
        :func:`lfc.simulate` (:func:`lfc.linear_grid.area_filter`:
        ``"certified"``, ``"coupled"``, ``"contract"``).  Not the paper's SCC:
        its output is not a clip to an interval (it predicts with the incoming
        command, so a larger one may pass less), so it has no edge to read
        (``ValueError``; the waveform families of
        :mod:`lfc.experiments.redteam` attack it).
    attack : AdaptiveAttack
    design : LFCParams or MultiAreaParams, optional
        The generator sides' design model (default ``params``): another plant
        tests a filter's parameter box.
    duration, loads, relays, estimator, noise_std, seed, dt, control_period, anti_windup
        As in :func:`lfc.simulate` (``loads``: ``{area: signal}``).
    load_feedforward : bool, optional
        Give each filter its area's true net disturbance; default as
        :func:`lfc.simulate` (True on a grid, False on one area).

    Returns
    -------
    Result
        As :func:`lfc.simulate` returns; ``settings["attack"]`` names the policy.
    """
    if not isinstance(attack, AdaptiveAttack):
        raise ValueError(f"attack must be an AdaptiveAttack, got {attack!r}")
    check_positive("duration", duration)
    check_seed("seed", seed)
    relays = relays_or_default(relays)
    single = isinstance(params, LFCParams)
    if not single and not isinstance(params, MultiAreaParams):
        raise ParameterTypeError(f"params must be an LFCParams or a MultiAreaParams, got "
                         f"{type(params).__name__}")
    ratio = (check_timing(duration, dt, control_period) if single else
             check_timing(duration, dt, control_period, params.n_areas, params.n_states))
    design = params if design is None else design
    if type(design) is not type(params):
        raise ValueError(f"design must be of the plant's type ({type(params).__name__}), got "
                         f"{type(design).__name__}")
    grid, model = as_grid(params), as_grid(design)
    n_a = grid.n_areas
    if single:
        scc = (SafetyFilter(design, relays, method=filters) if isinstance(filters, str)
               else filters)
        built = {0: scc}
    else:
        estimate = estimate_noise(estimator, noise_std)
        built = {a: area_filter(model, a, f, relays, control_period, estimate)
                 for a, f in check_area_keys(filters, n_a, "filters").items()}
        check_coupled(built, model, estimator, noise_std)
    missing = [a for a in range(n_a) if built.get(a) is None]
    paper = [a for a, f in built.items() if getattr(f, "method", None) == "paper"]
    if missing or paper:
        why = (f"area(s) {paper} have the paper's SCC, whose output is not a clip to an "
               f"interval (it predicts with the incoming command)" if paper else
               f"area(s) {missing} have none")
        raise ValueError(f"filters: the adaptive attacker reads every area's interval, so "
                         f"every area needs a certified, contract or coupled filter; {why}")
    loads = {0: loads} if single and not isinstance(loads, dict) else check_area_keys(
        loads or {}, n_a, "loads")
    feedforward = (not single) if load_feedforward is None else load_feedforward
    n_steps = int(round(duration / dt))
    n_ctrl = -(-n_steps // ratio)
    tc = np.arange(n_ctrl) * control_period
    k_freq, k_tie = model.agc_gains()
    gens = [GeneratorSide(model.areas[a], built.get(a), estimator, noise_std,
                          seed if a == 0 else (seed, a), tc, None, None,
                          feedforward and built.get(a) is not None, control_period,
                          k_agc=(float(k_freq[a]), float(k_tie[a])), anti_windup=anti_windup,
                          network=True)
            for a in range(n_a)]
    from lfc.testbed.loop import GeneratorSides
    loop = _Loop(LinearGrid(grid, loads, n_steps, ratio, dt, relays), GeneratorSides(gens), gens)
    choices = _choices(n_a)
    for j in range(n_ctrl):
        t = float(tc[j])
        pc = np.zeros(n_a)
        if attack.start <= t < attack.stop:
            pc = _choose(loop, j, n_ctrl, ratio, choices, attack, relays)
        loop.period(j, pc)
    plant = loop.plant
    if not np.isfinite(plant.xs).all():
        raise ValueError("the plant became non-finite under the adaptive attack, no filter "
                         "standing in the way")
    settings = {"params": repr(params), "design": repr(design), "relays": vars(relays),
                "duration": duration,
                "dt": dt, "control_period": control_period, "seed": seed,
                "noise_std": list(noise_std), "attack": repr(attack),
                "scc": repr(built), "load": repr(loads), "anti_windup": anti_windup,
                "feedforward": feedforward, "estimator": repr(estimator)}
    return plant.result(single, tc, [gen.ctrl for gen in gens], built, settings)


def _choose(loop: _Loop, j: int, n_ctrl: int, ratio: int, choices: list[np.ndarray],
            attack: AdaptiveAttack, relays: RelaySettings) -> np.ndarray:
    """The command channels of period ``j``: each area at the edge of its filter's
    interval the lookahead scores highest (``inset`` inside it)."""
    k0, best, pick = j * ratio, -math.inf, choices[0]
    horizon = min(n_ctrl, j + attack.lookahead)
    upper = lower = base = None
    for signs in choices:
        trial = loop.branch()
        first = trial.period(j, signs * PROBE, watch=False)
        if np.all(signs > 0):      # every filter's upper edge, and what the integrator adds
            upper = first          # (the command channel is summed with it into u_ref)
            base = np.array([g.ctrl[j, U_REF] for g in trial.gens]) - PROBE
        elif np.all(signs < 0):
            lower = first
        for i in range(j + 1, horizon):
            trial.period(i, signs * PROBE, watch=False)
        score = _score(trial.plant, k0, min(horizon * ratio, trial.plant.n_steps), relays,
                       attack.frequency_weight)
        if score > best:
            best, pick = score, signs
    width = upper - lower
    target = np.where(pick > 0, upper - attack.inset * width, lower + attack.inset * width)
    return target - base


def adaptive_search(params: LFCParams | MultiAreaParams, filters, *, duration: float = 10.0,
                    maxiter: int = 2, popsize: int = 3, seed: int = 0,
                    scenario: dict | None = None) -> dict:
    """The red team's adaptive family: differential evolution over the attacker's
    ``lookahead``, ``inset`` and ``frequency_weight`` (``BOUNDS``), maximizing the
    worst relay severity over the areas (:func:`lfc.experiments.redteam.severity`),
    ``scenario`` the other keywords of :func:`run_adaptive`.  Returns the found
    parameters (``theta``), its ``severity``, ``tripped`` and the ``outside`` samples
    over the areas."""
    from lfc.experiments.redteam import severity
    check_count("maxiter", maxiter)
    check_count("popsize", popsize)
    scenario = dict(scenario or {})
    relays = relays_or_default(scenario.get("relays"))
    cache: dict[tuple, dict] = {}

    def run(theta: np.ndarray) -> dict:
        key = tuple(np.round(theta, 12))
        if key not in cache:
            attack = AdaptiveAttack(lookahead=int(round(theta[0])), inset=float(theta[1]),
                                    frequency_weight=float(theta[2]))
            r = run_adaptive(params, filters, attack, duration=duration, **scenario)
            areas = r.areas
            metrics = [a.metrics() for a in areas]
            cache[key] = {"theta": [float(v) for v in theta],
                          "severity": float(max(severity(m, relays) for m in metrics)),
                          "tripped": bool(any(m["tripped"] for m in metrics)),
                          "outside": int(sum(m["outside"] for m in metrics))}
        return cache[key]

    found = differential_evolution(lambda th: -run(th)["severity"], list(BOUNDS.values()),
                                   maxiter=maxiter, popsize=popsize, seed=seed, polish=False,
                                   tol=0.0, init="sobol")
    return run(found.x)
