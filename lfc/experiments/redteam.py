"""A red team against the safety filters: search for the attack that comes
closest to tripping a relay.

Severity of a run: ``max(peak |ROCOF| / rocof_limit, peak |Δω̂| / F)`` (≥ 1
means a measured output reached a relay setting; ROCOF trips at once, OF2/UF2
after 160 ms).  Both searches evaluate a whole population of attacks per
generation with :func:`lfc.simulate_many` (``vectorized=True`` in scipy's
``differential_evolution``):

* :func:`family_search`: over the parameters of one waveform family
  (amplitude and frequency of sinusoids, squares, chirps on P_c and of squares
  on ω_ref; size of a bias or slope of a ramp on ω_ref);
* :func:`freeform_search`: a free-form attack on P_c, one value per control
  period, bounded by ``±amplitude``;
* :func:`coordinated_search`: an interconnected grid (:mod:`lfc.multiarea`),
  one family's parameters chosen separately for every area at once (a
  coordinated attack; families also on the ACE each area's AGC integrates, on what
  its sensors read (``SENSOR_FAMILIES``), and ``LOAD_FAMILIES``: a botnet's load,
  static or following the frequency; attacks on other channels, such as a blinded
  sensor, fixed in every run),
  severity the worst over the areas, with :func:`lfc.simulate_many`;
* :func:`lfc.experiments.adaptive.adaptive_search`: an attacker in the loop that
  reads every area's interval from its filter each period and pushes at its
  edges (certified, contract and coupled filters; not a waveform).

Both can search the plant and the noise too (``Search``): each attack's plant
anywhere in a box around the design model (M, D, τ_G, τ_T, R within
``±box``; the defender keeps the design model) and, with measurement noise
(the generator side then uses a Kalman estimate), its noise seed among
``n_seeds``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np
import pandas as pd
from scipy.optimize import differential_evolution

from lfc._format import number
from lfc._validate import (ParameterTypeError, check_array, check_count, check_flag,
                           check_multiple, check_number, check_pair, check_positive,
                           check_seed)
from lfc.engine import check_area_keys, check_attacks
from lfc.estimation import check_noise_std
from lfc.experiments.scenarios import ATTACK_START
from lfc.filters.base import check_choice
from lfc.filters.box import BOX
from lfc.linear_grid import area_filter, estimate_noise
from lfc.load_attacks import FollowingLoad
from lfc.model import LFCParams
from lfc.multiarea import MultiAreaParams
from lfc.relays import RelaySettings, relays_or_default
from lfc.run import simulate_many
from lfc.scenarios import Scenario
from lfc.sensors import Redundant
from lfc.signals import Step
from lfc.tables import scenario_signal, table_scenarios

# family -> (channel, waveform, bounds of (amplitude, freq_hz)); one bound: freq unused
FAMILIES = {
    "sinusoid on P_c": ("pc", "sinusoid", [(0.0, 3.0), (0.05, 3.0)]),
    "square on P_c": ("pc", "square", [(0.0, 3.0), (0.05, 3.0)]),
    "square on ω_ref": ("wref", "square", [(0.0, 1.0), (0.05, 3.0)]),
    "chirp on P_c": ("pc", "chirp", [(0.0, 3.0), (0.2, 3.0)]),
    "bias on ω_ref": ("wref", "step", [(-0.2, 0.2)]),
    "ramp on ω_ref": ("wref", "ramp", [(-0.05, 0.05)]),
}
# families of the coordinated search: the above, and a bias on the ACE an AGC integrates
MULTI_FAMILIES = {**FAMILIES, "bias on ACE": ("ace", "step", [(-3.0, 3.0)])}
# families on what the sensors read (outside every filter's threat model: searched apart):
# a lie added to the reading, or one that replaces it (lfc.sensor_attacks) — a meter's gain
# changed (the factor), a stuck meter (how long it stays stuck, s), the reports of an
# earlier moment played back (the lag, s, at most ATTACK_START: what was recorded)
SENSOR_FAMILIES = {
    "bias on dw_meas": ("dw_meas", "step", [(-0.1, 0.1)]),
    "sinusoid on dw_meas": ("dw_meas", "sinusoid", [(0.0, 0.1), (0.05, 3.0)]),
    "bias on rocof_meas": ("rocof_meas", "step", [(-1.0, 1.0)]),
    **{f"{kind} on {channel}": (channel, kind, bounds) for kind, bounds in (
        ("scale", [(-1.0, 3.0)]), ("freeze", [(0.1, 30.0)]),
        ("replay", [(0.01, ATTACK_START)])) for channel in ("dw_meas", "rocof_meas")},
}
_SINGLE = {**FAMILIES, **SENSOR_FAMILIES}   # what family_search and replay take
# the scenario keywords each channel's attack is given as (the others: attacks)
KEYWORD = {"load": ("loads",), "following": ("following_loads", "loads")}
# pu: the load a following botnet switches at once in every area it attacks, to start the
# loop moving from equilibrium (where the meter reads 0 and so would the load)
FOLLOWING_KICK = 0.01
# load-altering attacks on a grid (outside every filter's threat model beyond load_bound:
# searched apart): a step or a square wave on an area's load (pu), a ramp (slope pu/s, up
# to a size in pu, then held), or a load that follows the area's frequency meter
# (lfc.FollowingLoad: gain pu/pu, limit pu); every one from ATTACK_START
LOAD_FAMILIES = {
    "step on load": ("load", "step", [(-0.3, 0.3)]),
    "square on load": ("load", "square", [(0.0, 0.3), (0.05, 3.0)]),
    "ramp on load": ("load", "ramp", [(-2.0, 2.0), (0.0, 0.3)]),
    "following load": ("following", "gain", [(0.0, 20.0), (0.01, 0.3)]),
}
# the sensor families' waveforms told by one sensor (LIAR) of each area's redundant array
# (lfc.sensors.Redundant, the scenario's sensors): the search looks for the liar's worst lie
LIAR = 0
SPOOF_FAMILIES = {f"{name} of sensor {LIAR}": entry for name, entry in SENSOR_FAMILIES.items()
                  if entry[1] in ("step", "sinusoid")}
# what coordinated_search and its replay take
_GRID = {**MULTI_FAMILIES, **SENSOR_FAMILIES, **LOAD_FAMILIES, **SPOOF_FAMILIES}


READ_BY = {"none": (), "paper": ("alpha", "Ts"),
           "certified": ("uncertainty", "declare_noise", "sensor_bound")}


@dataclass(frozen=True)
class Defender:
    """A filter setting to attack: ``method`` "none", "paper" (with ``alpha``,
    ``Ts``; the default reading) or "certified" (with its plant box
    ``uncertainty``, with ``declare_noise`` the measurement noise covered, and with
    ``sensor_bound`` (pu, pu/s) the median of redundant sensors' error: give the search
    ``scenario={"sensors": Redundant(...)}``).  A field the method does not read keeps
    its default (else ``ValueError``)."""

    name: str
    method: str = "paper"
    alpha: float = 20.0
    Ts: float = 0.25
    uncertainty: float = 0.0
    declare_noise: bool = False
    sensor_bound: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str):
            raise ParameterTypeError(f"name must be a string, got {self.name!r}")
        check_choice("method", self.method, ("none", "paper", "certified"))
        check_positive("alpha", self.alpha)
        check_positive("Ts", self.Ts)
        check_number("uncertainty", self.uncertainty)
        if not 0.0 <= self.uncertainty < 1.0:
            raise ValueError(f"uncertainty must lie in [0, 1), got {self.uncertainty!r}")
        check_flag("declare_noise", self.declare_noise)
        if self.sensor_bound is not None:
            object.__setattr__(self, "sensor_bound",
                               check_pair("sensor_bound", self.sensor_bound, positive=True))
        unread = [f.name for f in fields(self)
                  if f.name not in ("name", "method", *READ_BY[self.method])
                  and getattr(self, f.name) != f.default]
        if unread:
            raise ValueError(f"Defender method {self.method!r} does not read "
                             f"{', '.join(unread)} (it reads "
                             f"{', '.join(READ_BY[self.method]) or 'nothing'}): "
                             f"leave {'it' if len(unread) == 1 else 'them'} at the default")

    def columns(self) -> dict:
        """The scenario-table columns that select this filter."""
        if self.method == "none":
            return {"alpha": np.nan, "Ts": self.Ts, "method": "paper"}
        bound = self.sensor_bound or (math.nan, math.nan)
        extra = ({"uncertainty": self.uncertainty, "declare_noise": self.declare_noise,
                  "sensor_bound_w": bound[0], "sensor_bound_rocof": bound[1]}
                 if self.method == "certified" else {})
        return {"alpha": self.alpha, "Ts": self.Ts, "method": self.method, **extra}


@dataclass(frozen=True)
class Search:
    """What the red team may choose besides the attack: the plant within ``±box``
    of the design model (relative, each of ``BOX``) and, when ``noise_std`` is
    not zero (pu, pu/s; the generator side uses a Kalman estimate), the noise
    seed among ``n_seeds``.  The default searches the attack only."""

    box: float = 0.0
    noise_std: tuple[float, float] = (0.0, 0.0)
    n_seeds: int = 1

    def __post_init__(self) -> None:
        check_number("box", self.box)
        if not 0.0 <= self.box < 1.0:
            raise ValueError(f"box must be in [0, 1), got {self.box!r}")
        object.__setattr__(self, "noise_std", check_noise_std("noise_std", self.noise_std))
        check_count("n_seeds", self.n_seeds)
        if self.n_seeds > 1 and not self.noisy:
            raise ValueError(f"n_seeds={self.n_seeds} needs noise_std > 0: without noise "
                             f"every seed gives the same run")

    @property
    def noisy(self) -> bool:
        return any(s > 0 for s in self.noise_std)

    def bounds(self) -> list[tuple[float, float]]:
        """Bounds of the extra search variables: plant factors, then the seed."""
        plant = [(1 - self.box, 1 + self.box)] * len(BOX) if self.box > 0 else []
        return plant + ([(0, self.n_seeds - 1)] if self.noisy and self.n_seeds > 1 else [])

    def columns(self, params: LFCParams, extra: np.ndarray) -> dict:
        """Scenario columns for the extra variables ``extra`` (k, S)."""
        out, k = {}, 0
        if self.box > 0:
            for k, name in enumerate(BOX):
                out[name] = getattr(params, name) * extra[k]
            k = len(BOX)
        if self.noisy:
            out["noise_w"], out["noise_rocof"] = self.noise_std
            out["seed"] = np.round(extra[k]).astype(int) if len(extra) > k else 0
        return out

    def describe(self, params: LFCParams, extra: np.ndarray) -> dict:
        """The plant factors and seed of a found attack, for the result row."""
        cols = self.columns(params, np.asarray(extra, float)[:, None])
        plant = ", ".join(f"{n} ×{float(extra[i]):.3f}" for i, n in enumerate(BOX)) \
            if self.box > 0 else "design model"
        factors = tuple(map(float, extra[:len(BOX)])) if self.box > 0 else ()
        return {"plant": plant, "plant_factors": factors,
                "seed": int(np.ravel(cols.get("seed", [0]))[0])}


def severity(results, relays: RelaySettings) -> np.ndarray:
    """Per run: max(peak |ROCOF| / rocof_limit, peak |Δω̂| / F).  ``results`` is a
    batch table or one run's metrics (anything indexed by the metric names)."""
    relays = relays_or_default(relays)
    return np.maximum(np.asarray(results["max_abs_rocof_meas"], float) / relays.rocof_limit,
                      np.asarray(results["max_abs_dw_meas"], float) / relays.F)


MAX_TABLE_VALUES = 10**8   # attack values in one piecewise table (0.8 GB)
EDGE = 0.05   # a trip verdict with an area's severity within ±5 % of 1 is "at the edge"


def trip_verdict(tripped: dict, severities: dict, band: float = EDGE) -> str:
    """How many areas tripped, and whether that count is at the edge: the areas
    whose severity lies within ``band`` (relative) of 1, with their severities
    (``"1, at the edge: area 1 at 1.03"``).  Near 1 the moment a relay trips
    moves with the last bits of the arithmetic (under two BLAS kernels one area
    trips or two: ``bench/records/reproduce.md``), so such a count is reported with
    its margin, not as a plain number.

    ``tripped`` and ``severities`` map each area to its verdict and severity."""
    n = sum(bool(v) for v in tripped.values())
    near = {a: s for a, s in severities.items() if abs(s - 1.0) <= band}
    if not near:
        return str(n)
    return f"{n}, at the edge: " + ", ".join(f"area {a} at {number(s)}"
                                             for a, s in sorted(near.items()))


def _waveform_columns(waveform: str, first, second) -> dict:
    """The scenario-table columns of a family's waveform for its searched parameters
    (arrays or numbers): ``amplitude`` and ``freq_hz``, from ``ATTACK_START`` — but a
    ``"freeze"``'s one parameter is how long the meter stays stuck (its ``stop``)."""
    if waveform == "freeze":
        return {"amplitude": 0.0 * first, "freq_hz": 0.0 * first, "start": ATTACK_START,
                "stop": ATTACK_START + first}
    return {"amplitude": first, "freq_hz": second, "start": ATTACK_START}


def _family_table(family: str, theta: np.ndarray, defender: Defender) -> pd.DataFrame:
    channel, waveform, bounds = _SINGLE[family]
    amp = theta[0]
    freq = theta[1] if len(bounds) > 1 else np.zeros_like(amp)
    return pd.DataFrame({"waveform": waveform, "channel": channel,
                         **_waveform_columns(waveform, amp, freq), **defender.columns()})


def check_search(*, duration: float, seed: int, maxiter: int, popsize: int,
                 relays: RelaySettings | None = None, search: Search | None = None) -> None:
    """Raise ``ValueError``/``TypeError`` naming the first invalid argument of a
    search: ``duration`` (s) must end after the attacks start (``ATTACK_START``),
    ``seed`` an integer >= 0, ``maxiter`` and ``popsize`` integers >= 1."""
    check_positive("duration", duration)
    if duration <= ATTACK_START:
        raise ValueError(f"duration must be > ATTACK_START ({ATTACK_START} s, when every "
                         f"attack starts), got {duration!r}: no attack would run")
    check_seed("seed", seed)
    check_count("maxiter", maxiter)
    check_count("popsize", popsize)
    if relays is not None and not isinstance(relays, RelaySettings):
        raise ParameterTypeError(f"relays must be a RelaySettings or None, got {relays!r:.80}")
    if search is not None and not isinstance(search, Search):
        raise ParameterTypeError(f"search must be a Search, got {search!r:.80}")


def _search(table_of, n_attack, bounds, params, relays, duration, seed, maxiter, popsize,
            search: Search, control_period: float = 0.01, fixed: Scenario | None = None):
    """Differential evolution maximizing severity over the attack's ``n_attack``
    variables and ``search``'s extra ones (runs at ``control_period``, s), every run
    also with ``fixed``'s signals (:func:`_with_fixed`); returns (best theta, severity,
    row)."""
    if not isinstance(params, LFCParams):
        raise ParameterTypeError(f"params must be an LFCParams (one area; a grid: "
                                 f"coordinated_search), got {type(params).__name__}")
    check_search(duration=duration, seed=seed, maxiter=maxiter, popsize=popsize,
                 relays=relays, search=search)
    extra = search.bounds()
    integrality = [False] * (n_attack + len(extra))
    if search.noisy and search.n_seeds > 1:
        integrality[-1] = True

    def table(theta: np.ndarray) -> pd.DataFrame:
        theta = np.asarray(theta, float)
        return table_of(theta[:n_attack]).assign(**search.columns(params, theta[n_attack:]))

    def runs(theta: np.ndarray):
        if fixed is None:
            return table(theta)
        return [_with_fixed(sc, fixed) for sc in table_scenarios(
            table(theta), params, duration=duration, relays=relays,
            control_period=control_period)]

    def objective(theta: np.ndarray) -> np.ndarray:
        chunks = {} if fixed else {"chunk_size": max(1, -(-theta.shape[1] // 2))}  # a table's
        res = simulate_many(params, runs(theta), duration=duration, relays=relays,
                             progress=False, control_period=control_period, **chunks)
        return -severity(res, relays)

    sol = differential_evolution(objective, list(bounds) + extra, seed=seed, maxiter=maxiter,
                                 popsize=popsize, vectorized=True, updating="deferred",
                                 polish=False, tol=0, integrality=integrality)
    best = simulate_many(params, runs(sol.x[:, None]), duration=duration, relays=relays,
                          progress=False, control_period=control_period)
    return sol.x, float(severity(best, relays)[0]), best.iloc[0]


#: what a single-area search's ``scenario`` may fix in every run: signals on the channels
#: the searched family leaves alone, or redundant sensors with their liars (the rest of a
#: run is the table's: filter, noise, plant)
FIXED_KEYS = {"pc": "pc_attack", "wref": "wref_attack", "load": "load",
              "dw_meas": "dw_meas_attack", "rocof_meas": "rocof_meas_attack",
              "following": "following_load", "sensors": "sensors"}


def _fixed_scenario(scenario: dict | None, channel: str) -> Scenario | None:
    """``scenario`` (:func:`lfc.simulate`'s keywords of an area, ``FIXED_KEYS``' values)
    as a :class:`Scenario`, or None; ``ValueError`` for another key or the family's own
    channel."""
    if scenario is None:
        return None
    if not isinstance(scenario, dict):
        raise ParameterTypeError(f"scenario must be a dict of lfc.simulate keywords or None, "
                                 f"got {scenario!r:.80}")
    allowed = set(FIXED_KEYS.values()) - {FIXED_KEYS[channel]}
    wrong = sorted(set(scenario) - allowed)
    if wrong:
        raise ValueError(f"scenario may fix {sorted(allowed)} (the family searches "
                         f"{FIXED_KEYS[channel]!r}; filter, noise and plant come from the "
                         f"defender and the search), got {wrong}")
    return Scenario.for_area(**scenario)


def _with_fixed(scenario: Scenario, fixed: Scenario) -> Scenario:
    """``scenario`` (one table row's) with ``fixed``'s signals added (on other channels)."""
    attacks = {**fixed.attacks.get(0, {}), **scenario.attacks.get(0, {})}
    return replace(scenario, attacks={0: attacks} if attacks else {},
                   loads=scenario.loads or fixed.loads,
                   following_loads=scenario.following_loads or fixed.following_loads,
                   sensors=fixed.sensors)


def family_search(params: LFCParams, defender: Defender, family: str, *,
                  relays: RelaySettings | None = None, duration: float = 10.0,
                  seed: int = 0, maxiter: int = 15, popsize: int = 10,
                  search: Search = Search(), scenario: dict | None = None) -> dict:
    """Worst attack of one family (``FAMILIES``, or ``SENSOR_FAMILIES``: what a sensor
    reads) against ``defender`` (see module docstring), over the plants and noise
    seeds ``search`` allows.

    ``scenario``: signals every run shares on the channels the family leaves alone, as
    :func:`lfc.simulate`'s keywords of an area (``FIXED_KEYS``' values): a load step the
    defender must ride through while its meter lies (``{"load": lfc.Step(0.2, start=2)}``
    with ``"freeze on rocof_meas"``), or a blinded sensor under a searched command attack
    (``{"rocof_meas_attack": Freeze(start=0.9)}`` with ``"square on P_c"``).  The result
    has the samples the filter flagged ``outside`` besides the severity and the trip."""
    if not isinstance(defender, Defender):
        raise ParameterTypeError(f"defender must be a Defender, got {defender!r:.80}")
    check_choice("family", family, tuple(_SINGLE))
    fixed = _fixed_scenario(scenario, _SINGLE[family][0])
    relays = relays_or_default(relays)
    bounds = _SINGLE[family][2]
    theta, sev, row = _search(lambda th: _family_table(family, th, defender), len(bounds),
                              bounds, params, relays, duration, seed, maxiter, popsize, search,
                              fixed=fixed)
    return {"defender": defender.name, "search": family, "severity": sev,
            "tripped": bool(row.tripped), "first_trip": row.first_trip_relay,
            "outside": int(row.outside),
            "attack": ", ".join(f"{v:.4g}" for v in theta[:len(bounds)]),
            "theta": tuple(map(float, theta[:len(bounds)])),
            **search.describe(params, theta[len(bounds):])}


def replay(found, duration: float) -> dict:
    """The :func:`lfc.simulate` keywords that replay a found attack: a result (a
    dict, or a row of a table of them) of
    :func:`family_search` (its ``search`` family and ``theta``) or of
    :func:`freeform_search` (its ``values`` and ``sample_period``), as a
    ``pc_attack``, ``wref_attack``, ``dw_meas_attack`` or ``rocof_meas_attack``
    signal starting at ``ATTACK_START``;
    ``duration`` (s) ends a chirp, as in the search's runs."""
    def entry(key: str):
        if not isinstance(found, (dict, pd.Series)) or key not in found.keys():
            raise ValueError(f"found must be a result of family_search or freeform_search "
                             f"(a dict with {key!r}), got {found!r:.80}")
        return found[key]
    check_number("duration", duration)
    if not duration > ATTACK_START:
        raise ValueError(f"duration must be > ATTACK_START ({ATTACK_START} s, when the attack "
                         f"starts), got {duration!r}")
    kind = entry("search")
    if isinstance(kind, str) and kind in _SINGLE:
        theta = check_array("found['theta']", entry("theta"),
                            shape=(len(_SINGLE[kind][2]),))
        row = _family_table(kind, theta[:, None], Defender("replay")).iloc[0]
        channel = row["channel"]
    elif isinstance(kind, str) and kind.startswith("free-form"):
        values = check_array("found['values']", entry("values"), shape=(None,))
        check_positive("found['sample_period']", entry("sample_period"))
        row = _samples_table(values[:, None], entry("sample_period"),
                             Defender("replay")).iloc[0]
        channel = "pc"
    else:
        raise ValueError(f"found['search'] must be one of {list(_SINGLE)} or a free-form "
                         f"search, got {kind!r}")
    return {f"{channel}_attack": scenario_signal(row, duration)}


def _samples_table(values: np.ndarray, period: float, defender: Defender) -> pd.DataFrame:
    """One ``"samples"`` scenario per column of ``values`` (n_values, S)."""
    return pd.DataFrame({"waveform": "samples", "channel": "pc", "amplitude": 1.0,
                         "freq_hz": 0.0, "start": ATTACK_START,
                         "values": [tuple(v) for v in values.T], "sample_period": period,
                         **defender.columns()})


def freeform_search(params: LFCParams, defender: Defender, *, amplitude: float = 2.0,
                    relays: RelaySettings | None = None, attack_duration: float = 2.0,
                    duration: float = 6.0, control_period: float = 0.01, seed: int = 0,
                    maxiter: int = 20, popsize: int = 1, search: Search = Search()) -> dict:
    """Worst free-form attack on P_c: one value in ``±amplitude`` per control
    period for ``attack_duration`` s (then held), run for ``duration`` s, over
    the plants and noise seeds ``search`` allows; the result's ``values`` (pu,
    one per control period from ``ATTACK_START``) replay it on its ``plant``."""
    if not isinstance(defender, Defender):
        raise ParameterTypeError(f"defender must be a Defender, got {defender!r:.80}")
    check_positive("amplitude", amplitude)
    n = check_multiple("attack_duration", attack_duration, "control_period", control_period)
    check_number("duration", duration)
    if attack_duration > duration - ATTACK_START + 1e-9:
        raise ValueError(f"attack_duration ({attack_duration} s) must end within the run: "
                         f"the attack starts at {ATTACK_START} s and duration is {duration} s")
    relays = relays_or_default(relays)
    theta, sev, row = _search(lambda v: _samples_table(v, control_period, defender), n,
                              [(-amplitude, amplitude)] * n, params, relays, duration, seed,
                              maxiter, popsize, search, control_period)
    values = theta[:n]
    return {"defender": defender.name, "search": f"free-form on P_c (±{amplitude:g} pu)",
            "severity": sev, "tripped": bool(row.tripped), "first_trip": row.first_trip_relay,
            "attack": f"{n} values, max |value| {np.abs(values).max():.3g} pu",
            "values": tuple(map(float, values)), "sample_period": control_period,
            **search.describe(params, theta[n:])}


def coordinated_search(params: MultiAreaParams, filters: dict, family: str, *,
                       relays: RelaySettings | None = None, duration: float = 20.0,
                       seed: int = 0, maxiter: int = 5, popsize: int = 5,
                       jobs: int = 2, control_period: float = 0.01,
                       scenario: dict | None = None) -> dict:
    """Worst coordinated attack of one family (``MULTI_FAMILIES``, ``SENSOR_FAMILIES``:
    what the sensors read, ``LOAD_FAMILIES``: a botnet's load, or ``SPOOF_FAMILIES``:
    the lie of sensor ``LIAR`` of each area's redundant sensors, which ``scenario``'s
    ``sensors`` gives) on an interconnected grid: differential
    evolution over the family's parameters in every area at once (an area may get
    amplitude 0: single-area attacks are included), maximizing the worst
    :func:`severity` over the areas.

    ``filters`` is :func:`lfc.simulate`'s ``{area: "paper" |
    "certified" | "coupled" | filter}``, built once for the controller period
    ``control_period`` (s).  ``scenario``: more keys of every run (e.g.
    ``{"estimator": "kalman", "noise_std": (1e-4, 1e-3)}``, or ``attacks`` on other
    channels than the family's — a sensor blinded by :mod:`lfc.sensor_attacks` while
    the search attacks the command; not ``filters``, nor what the family sets).
    Returns the family, the worst severity,
    the area it is reached in, whether any area tripped, the samples any filter
    flagged ``outside`` (summed over the areas), the attack per area (text) and its
    parameters ``theta`` (:func:`coordinated_scenario` rebuilds it).
    """
    if not isinstance(params, MultiAreaParams):
        raise ParameterTypeError(f"params must be a MultiAreaParams (a grid; one area: "
                                 f"family_search), got {type(params).__name__}")
    filters = check_area_keys(filters, params.n_areas, "filters")
    check_choice("family", family, tuple(_GRID))
    scenario = {} if scenario is None else dict(scenario)
    channel = _GRID[family][0]
    sets = {"filters", *KEYWORD.get(channel, ())}
    if sets & set(scenario):
        raise ValueError(f"scenario must not set {' or '.join(sorted(sets))} (the search "
                         f"sets them), got keys {sorted(scenario)}")
    fixed = check_attacks(scenario.pop("attacks", None), params.n_areas)
    if any(channel in channels for channels in fixed.values()):
        raise ValueError(f"scenario's attacks must not be on {channel!r} (the family "
                         f"{family!r} searches it), got {fixed!r:.120}")
    if family in SPOOF_FAMILIES:                     # its liars' arrays, checked first
        spoofed({"attacks": {a: {} for a in range(params.n_areas)}},
                scenario.get("sensors"), params.n_areas)
    check_search(duration=duration, seed=seed, maxiter=maxiter, popsize=popsize, relays=relays)
    check_count("jobs", jobs)
    relays = relays_or_default(relays)
    bounds = _GRID[family][2]
    k, n = len(bounds), params.n_areas
    noise = estimate_noise(scenario.get("estimator"), scenario.get("noise_std", (0.0, 0.0)))
    filters = {a: area_filter(params, a, f, relays, control_period, noise)   # built once,
               for a, f in filters.items()}                                # not per generation

    def with_fixed(found: dict) -> dict:
        if family in SPOOF_FAMILIES:
            found = {**found, "sensors": spoofed(found, scenario.get("sensors"), n)}
            del found["attacks"]
        attacks = found.get("attacks", {})
        merged = {a: {**fixed.get(a, {}), **attacks.get(a, {})} for a in range(n)}
        return {**found, "attacks": {a: c for a, c in merged.items() if c}}

    def run(thetas: np.ndarray) -> pd.DataFrame:
        out = simulate_many(
            params, [{**scenario, **with_fixed(coordinated_scenario(family, th, n, duration)),
                      "filters": filters} for th in thetas.T],
            duration=duration, relays=relays, jobs=jobs, control_period=control_period)
        out["severity"] = severity(out, relays)
        return out

    def objective(thetas: np.ndarray) -> np.ndarray:
        return -run(thetas).groupby("scenario").severity.max().to_numpy()

    sol = differential_evolution(objective, list(bounds) * n, seed=seed, maxiter=maxiter,
                                 popsize=popsize, vectorized=True, updating="deferred",
                                 polish=False, tol=0)
    best = run(sol.x[:, None])
    worst = best.loc[best.severity.idxmax()]
    return {"search": family, "severity": float(worst.severity), "area": int(worst.area),
            "tripped": bool(best.tripped.any()), "outside": int(best.outside.sum()),
            "attack": "; ".join(f"area {a}: " + ", ".join(f"{v:.4g}" for v in
                                                           sol.x[k * a:k * (a + 1)])
                                for a in range(n)),
            "theta": tuple(float(v) for v in sol.x)}


def coordinated_scenario(family: str, theta, n_areas: int, duration: float) -> dict:
    """The scenario keywords of :func:`lfc.simulate` for parameters ``theta`` of
    ``family`` in each of ``n_areas`` areas, as :func:`coordinated_search` runs them
    (its result's ``search`` and ``theta`` replay its winner, e.g. on ANDES):
    ``attacks`` for ``MULTI_FAMILIES``, ``loads`` or ``following_loads`` for
    ``LOAD_FAMILIES`` (with a following load, ``loads`` holds its
    ``FOLLOWING_KICK`` in every area it attacks); ``duration`` (s) ends a chirp.  For
    ``SPOOF_FAMILIES`` the ``attacks`` are sensor ``LIAR``'s lies: :func:`spoofed` puts
    them into the search's redundant sensors, as the search does."""
    check_choice("family", family, tuple(_GRID))
    channel, waveform, bounds = _GRID[family]
    k = len(bounds)
    theta = np.asarray(theta, float)
    if theta.shape != (k * n_areas,):
        raise ValueError(f"theta must hold {k} parameters per area ({k * n_areas} for "
                         f"{n_areas} areas), got shape {theta.shape}")
    if channel == "following":
        attacked = [a for a in range(n_areas) if theta[k * a] != 0.0]
        return {"following_loads": {a: FollowingLoad(float(theta[k * a]), float(
                    theta[k * a + 1]), start=ATTACK_START) for a in range(n_areas)},
                "loads": {a: Step(FOLLOWING_KICK, start=ATTACK_START) for a in attacked}}

    def row(a: int) -> dict:
        first, second = theta[k * a], theta[k * a + 1] if k > 1 else 0.0
        if channel == "load" and waveform == "ramp":   # slope (pu/s) to a size (pu), held
            held = first != 0.0 and second > 0.0
            return {"waveform": "ramp", "amplitude": float(first) if held else 0.0,
                    "freq_hz": 0.0, "start": ATTACK_START,
                    "stop": ATTACK_START + second / abs(first) if held else math.inf}
        return {"waveform": waveform, **_waveform_columns(waveform, float(first),
                                                           float(second))}
    signals = {a: scenario_signal(row(a), duration) for a in range(n_areas)}
    if channel == "load":
        return {"loads": signals}
    return {"attacks": {a: {channel: signal} for a, signal in signals.items()}}


def spoofed(found: dict, sensors: dict | None, n_areas: int) -> dict:
    """``sensors`` (``{area: Redundant}``, one per area) with the attacks of ``found``
    (:func:`coordinated_scenario` of a ``SPOOF_FAMILIES`` family) as sensor ``LIAR``'s
    lies, added to any it tells already; ``ValueError`` unless every area has its
    redundant sensors."""
    sensors = sensors or {}
    if set(sensors) != set(range(n_areas)) or not all(
            isinstance(r, Redundant) for r in sensors.values()):
        raise ValueError(f"a spoofed sensor's family needs scenario['sensors'] = {{area: "
                         f"lfc.sensors.Redundant}} for each of the {n_areas} areas, got "
                         f"{sensors!r:.120}")
    out = {}
    for a, red in sensors.items():
        lies = {**red.lies, LIAR: {**red.lies.get(LIAR, {}), **found["attacks"][a]}}
        out[a] = replace(red, lies=lies)
    return out


def coordinated_attacks(family: str, theta, n_areas: int, duration: float) -> dict:
    """The ``attacks`` argument of :func:`lfc.simulate` for ``theta`` of ``family``
    (``MULTI_FAMILIES``: attacks on the signals): :func:`coordinated_scenario`'s."""
    check_choice("family", family, tuple(MULTI_FAMILIES))
    return coordinated_scenario(family, theta, n_areas, duration)["attacks"]


def piecewise_attack_table(*, n: int, amplitude: float, duration: float, seed: int,
                           control_period: float = 0.01) -> pd.DataFrame:
    """``n`` seeded random piecewise-constant attacks on P_c (values in
    ``±amplitude`` held for 0.05–2 s), paper filter α = 20 — a reproducible
    batch of red-team attacks for tests."""
    check_count("n", n)
    check_seed("seed", seed)
    check_positive("amplitude", amplitude)
    check_number("duration", duration)
    check_positive("control_period", control_period)
    if not ATTACK_START < duration < math.inf:
        raise ValueError(f"duration must be finite and > ATTACK_START ({ATTACK_START} s), got "
                         f"{duration!r}")
    steps = int(round((duration - ATTACK_START) / control_period))
    if steps * n > MAX_TABLE_VALUES:
        raise ValueError(f"duration / control_period x n = {steps * n:.3g} attack values, more "
                         f"than a table holds ({MAX_TABLE_VALUES:.0e}, about "
                         f"{8 * MAX_TABLE_VALUES / 2**30:.0f} GiB); lower duration or n, or "
                         f"raise control_period")
    rng = np.random.default_rng(seed)
    values = np.empty((steps, n))
    for j in range(n):
        k = 0
        while k < steps:
            hold = int(rng.integers(5, 200))
            values[k:k + hold, j] = rng.uniform(-amplitude, amplitude)
            k += hold
    return _samples_table(values, control_period, Defender("paper α=20"))
