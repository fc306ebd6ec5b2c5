"""A certificate by contract: each area keeps its command in a box and moves it
no faster than a rate, and certifies against its neighbours' boxes and rates.

``filters={a: "contract" for every area}`` in :func:`lfc.simulate` (each area's
share of :func:`contract_design`), or ``SafetyFilter(params, method="contract")``
for one area.  The decentralized certificate of the Coupled issue, built on what
an area can promise: not its frequency (with its command held, an area's
tie-line flow settles only when its frequency equals a weighted mean of its
neighbours', so a neighbour at ``B`` drags it to ``B`` with gain one plus
overshoot — ``docs/coupled-certificate.md``, "The decentralized certificate"),
but what it *injects*: its governor command.

**The contract.**  Area ``j`` applies commands within ``[-a_j, a_j]`` (pu, a
deviation from its schedule) that move by at most ``r_j T`` at each control
sample (``T`` the control period; ``r_j`` in pu/s).  Its filter enforces both
alone: the command is ``u_ref`` clipped to ``[-a_j, a_j]`` and to within
``r_j T`` of the last one, so the contract holds whatever an attacker sends to
that area, and the interval is never empty.

**The certificate** (:func:`contract_design`).  On the grid with every command
an input (the tie-line flows states of the model, not disturbances), every area's
measured frequency and ROCOF is, from an equilibrium,
``y_o = sum_j h_oj * u_j + sum_j s^L_oj * dp_j``.  A command held between samples
is a sum of steps ``du_k`` at the samples, ``|du_k| <= r_j T``.  Each command's
share of ROCOF and of frequency is the smaller of two bounds (:func:`rocof_bound`,
:func:`frequency_bound`).  By the box: ``a_j int |h_oj|`` (the L1 norm,
:func:`~lfc.filters.responses.load_gains` ``"band"``: any signal within the box).
By the rate: for ROCOF ``r_j T sup_phi sum_k |s_oj(phi + k T)|`` with ``s_oj`` the
step response, which settles to 0 (:func:`~lfc.filters.responses.rate_gains`);
for frequency ``|s_oj(inf)| a_j + r_j T sup_phi sum_k |s_oj(phi + k T) -
s_oj(inf)|`` (the settled part plus what the steps move around it: no resonance
faster than the rate allows).  Loads whose total
variation summed over the areas is ``V`` move ``y_o`` by at most ``V max_j sup
|s^L_oj|`` (``"steps"``).  The rates are the largest with the ROCOF bounds within
``rocof_limit`` at the widest boxes (the grid's ``command_range``: a model fitted
to ANDES describes it only there; none on the linear presets, where the rates
alone bound ROCOF); then the boxes, at most that range, at those rates with the
frequency bounds within ``F`` (each time the common value by bisection, the
others by a linear program), each limit times ``1 - margin`` with room for a
total load variation ``load_bound``.  On Kundur's fitted model the range binds:
a box of ±0.1 pu keeps ROCOF within a third of its limit at any rate, so the
contract is the box alone.

**Guarantee (proven).**  For the design grid, starting from an equilibrium
with every area's filter keeping its contract (this filter at every area, with
its area's share), and loads whose total variation over the run, summed over
the areas, is at most ``load_bound``: no area's OF2, UF2 or ROCOF relay trips,
at any instant — whatever commands, frequency references and ACE signals an
attacker sends to any subset of the areas, at any moment.  No filter needs a
state, an estimate, a tie-line flow or a message: the proof uses only the
contracts.  The filter never flags ``outside``; an invalid input holds the last
command (inside the contract) and flags ``invalid_input``.

**The price.**  The contract also limits legitimate control: an area's AGC
cannot follow a load larger than its box or faster than its rate (the command
stops there; with ``anti_windup`` the AGC does not wind up behind it).  The
boxes and rates shrink with the number of areas and where the ties are stiff
(chapter 10's scaling figure); on a lightly damped area the rate's bound keeps
the box large (0.36 pu on two areas at ratio 0.03, where the L1 norm alone
gives 0.019 pu).

**Not covered.**  Plants other than the design grid; a start away from
equilibrium (its free response is not bounded); an area without the contract
(the others cannot see it).  On ANDES the contracts are the fitted model's:
measured there, not proven.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from lfc._jit import inline
from lfc._validate import (ParameterTypeError, check_flag, check_nonnegative, check_number,
                           check_positive)
from lfc.filters.base import (ACTIVE, BIND_CERT, INVALID, MAX_ABS_INPUT, Backend, Layout,
                              Options, built_once, given, hold_invalid, option,
                              valid_input)
from lfc.filters.certified import NUMERIC_MARGIN
from lfc.filters.coupled_set import held_grid, output_rows
from lfc.filters.responses import load_gains, rate_gains
from lfc.model import LFCParams
from lfc.multiarea import MultiAreaParams, as_grid
from lfc.relays import RelaySettings

#: the data array decide() reads: the box's half-width and step (pu), the relay limits
LAYOUT = Layout("half", "step", "f_lim", "r_lim")
HALF, STEP, F_LIM, R_LIM = LAYOUT.offsets()


@dataclass(frozen=True)
class Contract:
    """Every area's contract on a grid and what it proves (:func:`contract_design`).

    Attributes
    ----------
    half_width : ndarray (n_areas,)
        Each area's box ``[-a_j, a_j]`` on its command (pu).
    rate : ndarray (n_areas,)
        Each area's rate ``r_j`` (pu/s): its command moves at most ``r_j T`` per
        control period ``T``.
    frequency_gain : ndarray (n_areas, n_areas)
        ``[i, j]``: how far a command of area ``j`` within ±1 pu can move area
        ``i``'s measured frequency (pu per pu; the L1 norm).
    settled_gain : ndarray (n_areas, n_areas)
        ``[i, j]``: area ``i``'s frequency per pu of area ``j``'s command once
        settled (pu per pu; the step response's final value).
    transient_gain : ndarray (n_areas, n_areas)
        ``[i, j]``: how far a command of area ``j`` moving by at most 1 pu/s can
        move area ``i``'s frequency away from its settled part (pu per pu/s).
    rocof_gain : ndarray (n_areas, n_areas)
        ``[i, j]``: how far a command of area ``j`` moving by at most 1 pu/s can
        move area ``i``'s measured ROCOF (pu/s per pu/s).
    rocof_box_gain : ndarray (n_areas, n_areas)
        ``[i, j]``: how far a command of area ``j`` within ±1 pu can move area
        ``i``'s measured ROCOF (pu/s per pu; the L1 norm); ``inf`` on a grid
        without a ``command_range``, whose boxes are never small enough for this
        bound to be the smaller (not computed).
    load_gain : ndarray (n_areas, 2)
        Per area, frequency and ROCOF moved per pu of the loads' total variation.
    limits : ndarray (2,)
        The relay limits kept (``F``, ``rocof_limit`` times ``1 - margin``).
    bound : ndarray (n_areas, 2)
        The proven bound on each area's measured frequency (pu) and ROCOF (pu/s).
    load_bound, control_period : float
        The loads' total variation covered (pu) and the control period (s).
    command_range : float
        The widest box the design allowed (pu): the grid's ``command_range``
        (where a fitted model describes its plant), or ``MAX_ABS_INPUT``.
    """

    half_width: np.ndarray
    rate: np.ndarray
    frequency_gain: np.ndarray
    settled_gain: np.ndarray
    transient_gain: np.ndarray
    rocof_gain: np.ndarray
    rocof_box_gain: np.ndarray
    load_gain: np.ndarray
    limits: np.ndarray
    bound: np.ndarray
    load_bound: float
    control_period: float
    command_range: float

    def use(self) -> np.ndarray:
        """The fraction of each limit the bound takes (n_areas, 2), at most 1."""
        return self.bound / self.limits


def frequency_bound(box_gain: np.ndarray, settled: np.ndarray, transient: np.ndarray,
                    half: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """Per output, the most commands within boxes ``half`` moving at rates
    ``rate`` move it: each command's share is the smaller of its box bound
    ``box_gain a`` and its settled-plus-transient bound ``settled a + transient r``
    (both hold; module docstring)."""
    return np.minimum(box_gain * half, settled * half + transient * rate).sum(axis=1)


def rocof_bound(box_gain: np.ndarray, settled: np.ndarray, moving: np.ndarray,
                half: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """Per output, the most commands within boxes ``half`` moving at rates
    ``rate`` move ROCOF: each command's share is the smaller of its box bound
    ``box_gain a`` and its rate bound ``moving r``, plus ``settled a`` (ROCOF's
    step response settles to 0: rounding)."""
    return (np.minimum(box_gain * half, moving * rate) + settled * half).sum(axis=1)


def _largest(gains: np.ndarray, room: np.ndarray, upper: float) -> np.ndarray:
    """The largest ``x`` in ``[0, upper]`` with ``gains @ x <= room``: the
    smallest entry as large as possible, then the sum at that smallest (two
    linear programs)."""
    from scipy.optimize import linprog    # here: 0.14 s to import, only a design needs it

    n = gains.shape[1]
    first = linprog(np.r_[np.zeros(n), -1.0],
                    A_ub=np.block([[gains, np.zeros((len(gains), 1))],
                                    [-np.eye(n), np.ones((n, 1))]]),
                    b_ub=np.r_[room, np.zeros(n)], bounds=[(0, upper)] * (n + 1),
                    method="highs")
    if first.status != 0:   # pragma: no cover - x = 0 is feasible and room bounds it
        raise ValueError(f"the contract's linear program failed: {first.message}")
    second = linprog(-np.ones(n), A_ub=gains, b_ub=room,
                     bounds=[(first.x[-1] * (1 - 1e-9), upper)] * n, method="highs")
    if second.status != 0:  # pragma: no cover
        raise ValueError(f"the contract's linear program failed: {second.message}")
    return second.x * (1 - NUMERIC_MARGIN)


def _largest_of_smaller(first: np.ndarray, first_offset: np.ndarray, second: np.ndarray,
                        second_offset: np.ndarray, room: np.ndarray, upper: float
                        ) -> np.ndarray:
    """The largest ``x`` in ``[0, upper]`` with, per output ``o``,
    ``sum_j min(first_oj x_j + first_offset_oj, second_oj x_j + second_offset_oj)
    <= room_o`` (each command's share bounded by the smaller of two bounds, both
    growing with ``x_j``): the common ``x`` as large as possible (bisection), then,
    each share taken by the bound smaller there (a valid bound for every ``x``,
    so the constraint becomes linear), the others as large as possible
    (:func:`_largest`)."""
    def bound(x: float) -> np.ndarray:
        return np.minimum(first * x + first_offset, second * x + second_offset)

    def fits(x: float) -> bool:
        return bool(np.all(bound(x).sum(axis=1) <= room))

    lo, hi = 0.0, min(1.0, upper)
    while fits(hi) and hi < upper:
        lo, hi = hi, min(2.0 * hi, upper)
    if fits(hi):
        lo = hi
    for _ in range(100 if lo < hi else 0):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    by_first = first * lo + first_offset <= second * lo + second_offset
    offset = np.where(by_first, first_offset, second_offset).sum(axis=1)
    return np.minimum(_largest(np.where(by_first, first, second), room - offset, upper), upper)


def contract_design(params: MultiAreaParams | LFCParams, relays: RelaySettings, *,
                    control_period: float = 0.01, load_bound: float = 0.06,
                    margin: float = 0.0, mismatch_budget: bool = True) -> Contract:
    """Every area's contract on ``params`` (module docstring): the largest rates
    that keep every measured ROCOF within ``rocof_limit``, then the largest boxes
    that keep every measured frequency within ``F`` at those rates, each with room
    for loads of total variation ``load_bound`` (and, with ``mismatch_budget``, the
    grid's ``load_mismatch``: a fitted model's distance from its plant as load),
    every box within the grid's ``command_range`` (pu; where a fitted model
    describes its plant).

    Parameters
    ----------
    params : MultiAreaParams or LFCParams
        The design grid (one area: an ``LFCParams``).
    relays : RelaySettings
    control_period : float
        Period of the filters' calls (s, > 0): a command steps at most ``r T``.
    load_bound : float
        Total variation of the loads over a run, summed over the areas (pu,
        >= 0; default 0.06, the coupled certificate's).
    margin : float
        Extra fractional tightening of both limits, in [0, 1).
    mismatch_budget : bool
        Add ``params.load_mismatch`` (a :class:`MultiAreaParams`'; 0 for a model
        that is its plant) to ``load_bound`` (default True).  The contract's
        ``load_bound`` is the sum.

    Raises
    ------
    ValueError
        If the grid with its commands held is not asymptotically stable (a
        command within any box can drive it away), or the loads alone take a
        whole limit.
    """
    check_flag("mismatch_budget", mismatch_budget)
    check_nonnegative("load_bound", load_bound)
    if mismatch_budget:
        load_bound = load_bound + getattr(params, "load_mismatch", 0.0)
    return built_once(lambda: _design(params, relays, control_period, load_bound, margin),
                      "contract_design", params, relays, control_period, load_bound,
                      margin)


def _design(params: MultiAreaParams | LFCParams, relays: RelaySettings, control_period: float,
            load_bound: float, margin: float) -> Contract:
    """:func:`contract_design`, built (shared by every caller, its arrays read-only)."""
    check_positive("control_period", control_period)
    check_nonnegative("load_bound", load_bound)
    check_number("margin", margin)
    if not 0.0 <= margin < 1.0:
        raise ValueError(f"margin must be in [0, 1), got {margin!r}")
    if not isinstance(relays, RelaySettings):
        raise ParameterTypeError(f"relays must be a RelaySettings, got {relays!r:.80}")
    grid = as_grid(params)
    A, Bu, Bl, _ = held_grid(grid, "a command within any box can drive it away, so no "
                                   "contract certifies it")
    n_a = grid.n_areas
    C = output_rows(n_a, len(A))
    limits = np.array([relays.F, relays.rocof_limit]) * (1 - margin) * (1 - NUMERIC_MARGIN)
    reach = min(grid.command_range, MAX_ABS_INPUT)    # pu: the most a command can be
    box_gain = np.array([load_gains(A, Bu[:, j], C[0::2])["band"] for j in range(n_a)]).T
    # the box's bound on ROCOF matters only within a range (at 1e6 pu it never binds)
    rocof_box_gain = (np.array([load_gains(A, Bu[:, j], C[1::2])["band"] for j in range(n_a)]).T
                      if math.isfinite(grid.command_range) else np.full((n_a, n_a), np.inf))
    gains = [rate_gains(A, Bu[:, j], C, control_period) for j in range(n_a)]
    moving = np.array([g for g, _ in gains]).T        # (outputs, areas): per pu/s
    settled = np.array([s for _, s in gains]).T       # (outputs, areas): per pu
    load = np.max([load_gains(A, Bl[:, j], C)["steps"] for j in range(n_a)],
                  axis=0).reshape(n_a, 2)
    room = limits - load_bound * load
    if np.any(room <= 0):
        i, o = np.unravel_index(np.argmin(room / limits), room.shape)
        raise ValueError(f"load_bound={load_bound:g} pu takes the whole of area {i}'s "
                         f"{('frequency', 'ROCOF')[o]} limit ({load_bound * load[i, o]:.3g} "
                         f"of {limits[o]:.3g}); lower load_bound")
    # ROCOF, each share the smaller of the box's bound at the widest box (``reach``)
    # and the rate's; it settles to 0 (``settled[1::2]`` is rounding).  A rate of
    # 2 reach / T crosses any box in one period: no faster rate is a constraint.
    rate = _largest_of_smaller(np.zeros_like(rocof_box_gain), rocof_box_gain * reach,
                               moving[1::2], np.zeros_like(rocof_box_gain),
                               room[:, 1] - settled[1::2].sum(axis=1) * reach,
                               2.0 * reach / control_period)
    half = _largest_of_smaller(box_gain, np.zeros_like(box_gain), settled[0::2],
                               moving[0::2] * rate, room[:, 0], reach)
    bound = np.column_stack([
        frequency_bound(box_gain, settled[0::2], moving[0::2], half, rate),
        rocof_bound(rocof_box_gain, settled[1::2], moving[1::2], half, rate)]) \
        + load_bound * load
    arrays = (half, rate, box_gain, settled[0::2], moving[0::2], moving[1::2],
              rocof_box_gain, load, limits, bound)
    for a in arrays:
        a.setflags(write=False)   # shared by every caller (built_once)
    return Contract(*arrays, float(load_bound), float(control_period), float(reach))


@dataclass(frozen=True)
class ContractOptions(Options):
    """Options of the contract filter (``method="contract"``)."""

    half_width: float | None = option(
        None, "pu", "None or > 0",
        "the box [-a, a] on the command; None: contract_design of the area alone (a grid's "
        "area gets its share from lfc.filters.build)")
    rate: float | None = option(
        None, "pu/s", "None or > 0 (with half_width)",
        "the most the command moves per second (r T per control period); None: with "
        "half_width None, contract_design's")
    load_bound: float = option(0.06, "pu", ">= 0",
                               "total variation of the loads over a run the design covers")
    mismatch_budget: bool = option(True, "", "True or False",
                                   "add a fitted design model's load_mismatch to load_bound")
    margin: float = option(0.0, "", "[0, 1)", "extra fractional tightening of both limits")
    control_period: float = option(0.01, "s", "(0, 1]", "period of the calls")

    COLUMNS: ClassVar[tuple[str, ...]] = ("half_width", "rate")

    def __post_init__(self) -> None:
        super().__post_init__()
        if (self.half_width is None) != (self.rate is None):
            raise ValueError(f"half_width and rate go together (both a contract's share, or "
                             f"both None for the area alone), got half_width="
                             f"{self.half_width!r}, rate={self.rate!r}")
        for name in ("half_width", "rate"):
            if getattr(self, name) is not None:
                check_positive(name, getattr(self, name))
                object.__setattr__(self, name, float(getattr(self, name)))
        check_nonnegative("load_bound", self.load_bound)
        check_flag("mismatch_budget", self.mismatch_budget)
        if not 0.0 <= self.margin < 1.0:
            raise ValueError(f"margin must be in [0, 1), got {self.margin!r}")
        check_positive("control_period", self.control_period)
        if self.control_period > 1.0:
            raise ValueError(f"control_period must lie in (0, 1] s, got {self.control_period!r}")
        for name in ("load_bound", "margin", "control_period"):
            object.__setattr__(self, name, float(getattr(self, name)))

    @classmethod
    def from_columns(cls, row: dict) -> dict:
        """The row's ``half_width`` (pu) and ``rate`` (pu/s), if given."""
        return {c: float(row[c]) for c in cls.COLUMNS if given(row.get(c))}


class ContractFilter(Backend):
    """The contract filter (method ``"contract"``, options
    :class:`ContractOptions`): clip the command to ``[-a, a]`` and to within
    ``r T`` of the last one."""

    name, Options = "contract", ContractOptions

    @classmethod
    def grid_options(cls, grid, area: int, relays: RelaySettings,
                     control_period: float) -> dict:
        """In a grid: area ``area``'s box of the grid's :func:`contract_design` with
        its defaults (the decentralized certificate, proven when every area has it)."""
        share = contract_design(grid, relays, control_period=control_period)
        return {"half_width": float(share.half_width[area]), "rate": float(share.rate[area])}

    def __init__(self, params: LFCParams, relays: RelaySettings,
                 options: ContractOptions) -> None:
        super().__init__(params, relays, options)
        half, rate = options.half_width, options.rate
        if half is None:
            own = contract_design(params, relays, control_period=options.control_period,
                                  load_bound=options.load_bound, margin=options.margin,
                                  mismatch_budget=options.mismatch_budget)
            half, rate = float(own.half_width[0]), float(own.rate[0])
        self.box, self.step = half, rate * options.control_period
        self.data = np.array([half, self.step, relays.F, relays.rocof_limit])

    def reason(self, flags: int) -> str:
        if flags & INVALID:
            return ("invalid input (non-finite or beyond 1e6: a corrupted message); last "
                    "command held (inside the contract)")
        return (f"command clipped to its contract (within ±{self.box:.4g} pu, moving at most "
                f"{self.step:.3g} pu per period)" if flags & ACTIVE else "")

    def details(self, d0: float, d1: float, flags: int) -> dict:
        return {"interval": (d0, d1)}


@inline
def decide(fd: np.ndarray, x: np.ndarray, u_ref: float, p: float, mem: np.ndarray) -> tuple:
    """One call of the contract filter: ``u_ref`` clipped to ``[-a, a]`` and to
    within ``r T`` of the last command ``mem[0]`` (``a = fd[HALF]``, ``r T =
    fd[STEP]``; never empty, ``mem[0]`` lying in the box); an invalid input holds
    ``mem[0]``.  Returns ``(u, flags, h_freq, h_rocof, margin, margin, y_freq,
    y_rocof, lo, hi)`` with ``margin`` the distance from ``u`` to the interval's
    nearer end."""
    if not valid_input(x, u_ref, p):
        return hold_invalid(mem, u_ref)
    lo, hi = max(-fd[HALF], mem[0] - fd[STEP]), min(fd[HALF], mem[0] + fd[STEP])
    u = min(max(u_ref, lo), hi)
    mem[0] = u
    flags = ACTIVE | BIND_CERT if u != u_ref else 0
    m = min(u - lo, hi - u)
    return (u, flags, fd[F_LIM] ** 2 - x[3] ** 2, fd[R_LIM] ** 2 - x[4] ** 2, m, m, x[3], x[4],
            lo, hi)
