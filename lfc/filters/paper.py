"""The paper's safety-critical controller (SCC): a control-barrier-function QP.

Reading of the paper (reproduction notes E2, E5, E6, E9, E10):

* Prediction ``y(t+Ts) = C (Ad x + Bd [u; p_load])`` with a command held over
  the look-ahead ``Ts`` (zero-order hold).
* Barriers ``h_w = F^2 - y_w^2`` and ``h_v = rocof_limit^2 - y_v^2`` (E2: the
  bounds squared), gradients ``dh/dx = -2 y C Ad`` as printed, and the barrier
  derivative along ``x' = A x + B [u; p_load]``: affine in the decision ``u``.
* The paper's constraint ``dB/dt - alpha/B <= 0`` with the log barrier
  ``B = -log(h/(1+h))`` is, for ``h > 0``, the same as
  ``dh/dt(u) + gamma(h) >= 0`` with ``gamma(h) = alpha h (1+h) / B(h)``
  (multiply by ``h (1+h) > 0``); that is the form solved here.
* E9, outside the safe set (a prediction with ``h <= 0``): ``B`` does not
  exist and the paper does not say what the SCC does.  Two readings
  (``outside_rule``), both continuous at ``h = 0``: ``"hold"`` continues the
  paper's own condition, whose limit as ``h -> 0+`` is ``dh/dt >= 0`` ("do
  not get worse"): ``gamma(h) = 0``; ``"push"`` extends ``gamma`` as an
  extended class-K function, ``gamma(h) = alpha h``, demanding
  ``dh/dt >= alpha |h|`` (push back toward the set).  Flagged ``outside``.
* E5, what the prediction holds (``prediction``): ``"incoming"`` (the
  command that arrives, ``u_ref``: "whether the current governor-droop
  control signal can force the system to exit the safety set") or
  ``"applied"`` (the command the governor currently follows, the filter's
  previous output; 0 after a reset).
* E10, the QP is one-dimensional: each constraint is ``u >= bound`` or
  ``u <= bound`` and the exact answer is ``u_ref`` clipped to an interval.
  When the constraints (with the actuator limits) admit no ``u``
  (``conflict``): ``"slack"`` solves the slack-relaxed QP
  ``min 1/2 (u-u_ref)^2 + rho/2 sum s_i^2`` with each slack ``s_i`` the
  violation of constraint ``i`` in pu of command, subject to the actuator
  limits (hard); with a large ``rho`` this splits a conflict between the two
  relays evenly and, against an actuator limit, pushes as hard as the
  actuator allows.  ``"frequency"`` or ``"rocof"`` meets that constraint
  (within the actuator limits) and comes as close to the other as it allows.
  Flagged ``infeasible``.
* A command within ``BOUND_ULPS`` (8) units in the last place of a bound
  satisfies it: not clipped, not flagged ``active``.  The bounds' last bits
  depend on the machine's BLAS kernel, and a steady state exactly on a bound
  (the hold rule's ``dh/dt = 0``) must get the same decision everywhere.
* A constraint whose coefficient on ``u`` vanishes (``|g| <= 1e-12``) cannot
  be influenced by the command: it is dropped, and flagged ``infeasible`` if
  it is violated.
* Non-finite ``x``, ``u_ref`` or ``p_load`` (a lost measurement): no barrier
  can be evaluated; the command is ``u_ref`` (``0`` if ``u_ref`` itself is not
  finite) clipped to the actuator limits, flagged ``invalid_input``.
* ``solver="cvxpy"``: :class:`lfc.filters.cvxpy_paper.PaperQP`, the QP written
  in cvxpy from the paper's definitions (a DPP problem built once, solved by
  Clarabel); the flags come from the closed form.  If it raises or does not
  return an optimal status the exact answer is used, flagged ``solver_error``.

The readings' defaults (``DEFAULT_READING``) are, of the 12, the one that stops
the most tripping attacks of the default attack-surface maps at alpha = 3 and 20
(notebooks/06_attack_surface.ipynb, "The paper's SCC at its strongest").
``details`` of a :class:`~lfc.filters.base.FilterInfo`: ``kind`` (+1: the
constraint reads ``u >= bound``, -1: ``u <= bound``, 0: no influence) and
``bound`` (pu) of the frequency and ROCOF constraints.  No call raises for
numeric trouble; every call returns a finite command.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from lfc._jit import inline
from lfc._validate import check_positive
from lfc.filters.base import (ACTIVE, BIND_FREQ, BIND_ROCOF, BIND_UMAX, BIND_UMIN, INFEASIBLE,
                              INVALID, KIND_FREQ_HI, KIND_FREQ_LO, KIND_ROCOF_HI,
                              KIND_ROCOF_LO, OUTSIDE, SOLVER_ERROR, Backend, Layout,
                              Options, check_choice, check_limits, given, option,
                              valid_input)
from lfc.model import LFCParams, discretize, lfc_matrices, output_matrix
from lfc.relays import RelaySettings

SOLVERS = ("exact", "cvxpy")
OUTSIDE_RULES = ("hold", "push")                  # E9 readings
CONFLICT_RULES = ("slack", "rocof", "frequency")  # E10 readings
PREDICTIONS = ("incoming", "applied")             # E5 readings
DEFAULT_READING = {"outside_rule": "hold", "conflict": "frequency", "prediction": "incoming"}
READING_NAMES = tuple(DEFAULT_READING)
G_EPS = 1e-12      # |coefficient on u| below which a constraint cannot be influenced
BIND_TOL = 1e-7    # relative tolerance to report a bound as binding
# A command within BOUND_ULPS units in the last place of a bound satisfies it: the
# bounds come out of matrix exponentials and BLAS, whose last bits depend on the
# machine (OpenBLAS's core type), so a steady state exactly on a bound (the hold
# rule's dh/dt = 0) must not be clipped and flagged on one machine and not another.
BOUND_ULPS = 8.0
EPS = 2.220446049250313e-16

#: the data array decide() reads: the options, then the look-ahead's outputs
#: ``y = x P + u q + p r`` (P: 5 x 2) and their rates ``C Ad x' = x W + u kg + p wl``,
#: and the squared relay limits
LAYOUT = Layout("alpha", "u_min", "u_max", "rho", "push", "conflict", "applied", ("P", 10),
                ("q", 2), ("r", 2), ("W", 10), ("kg", 2), ("wl", 2), ("limits2", 2))
ALPHA, U_MIN, U_MAX, RHO, PUSH, CONFLICT, APPLIED, P_, Q_, R_, W_, KG_, WL_, LIM2_ = \
    LAYOUT.offsets()
SIZE = LAYOUT.size
_CONFLICT_CODE = {"slack": 0, "frequency": 1, "rocof": 2}


@dataclass(frozen=True)
class PaperOptions(Options):
    """Options of the paper's SCC (``method="paper"``); the readings are E5, E9, E10."""

    alpha: float = option(20.0, "1/s", "> 0", "barrier gain (paper: 3 and 20)")
    Ts: float = option(0.25, "s", "> 0", "look-ahead of the prediction (paper: 0.25)")
    solver: str = option("exact", "", f"one of {SOLVERS}",
                         "closed form, or the cvxpy/Clarabel reference QP")
    u_min: float = option(-math.inf, "pu", "< u_max", "actuator limit on the applied command")
    u_max: float = option(math.inf, "pu", "> u_min", "actuator limit on the applied command")
    slack_weight: float = option(1e4, "pu^-2", "> 0",
                                 "penalty on squared violations of conflict='slack'")
    outside_rule: str = option(DEFAULT_READING["outside_rule"], "", f"one of {OUTSIDE_RULES}",
                               "E9: what to do when the prediction is outside the safe set")
    conflict: str = option(DEFAULT_READING["conflict"], "", f"one of {CONFLICT_RULES}",
                           "E10: which constraint wins when they conflict")
    prediction: str = option(DEFAULT_READING["prediction"], "", f"one of {PREDICTIONS}",
                             "E5: the command the prediction holds")

    COLUMNS: ClassVar[tuple[str, ...]] = ("alpha", "Ts", *READING_NAMES)

    def __post_init__(self) -> None:
        super().__post_init__()
        check_positive("alpha", self.alpha)
        check_positive("Ts", self.Ts)
        check_positive("slack_weight", self.slack_weight)
        check_choice("solver", self.solver, SOLVERS)
        check_choice("outside_rule", self.outside_rule, OUTSIDE_RULES)
        check_choice("conflict", self.conflict, CONFLICT_RULES)
        check_choice("prediction", self.prediction, PREDICTIONS)
        check_limits(self.u_min, self.u_max)
        for name in ("alpha", "Ts", "slack_weight", "u_min", "u_max"):
            object.__setattr__(self, name, float(getattr(self, name)))

    @classmethod
    def from_columns(cls, row: dict) -> dict:
        """``alpha``, ``Ts`` and any reading the row sets."""
        return {"alpha": float(row["alpha"]), "Ts": float(row["Ts"]),
                **{c: row[c] for c in READING_NAMES if given(row.get(c))}}


class PaperFilter(Backend):
    """The paper's CBF-QP (method ``"paper"``), options :class:`PaperOptions`.

    Parameters
    ----------
    params : LFCParams
        Design model.
    relays : RelaySettings
        Relay settings defining the safe set.
    options : PaperOptions
    """

    name, Options = "paper", PaperOptions

    def __init__(self, params: LFCParams, relays: RelaySettings, options: PaperOptions) -> None:
        super().__init__(params, relays, options)
        self.limits = np.array([relays.F, relays.rocof_limit])
        self.data = self._pack()
        self.jit = options.solver == "exact"
        self.reference = None
        if options.solver == "cvxpy":
            from lfc.filters.cvxpy_paper import PaperQP
            self.reference = PaperQP(params, relays, alpha=self.alpha, Ts=self.Ts,
                                     outside_rule=self.outside_rule, conflict=self.conflict,
                                     slack_weight=self.slack_weight, u_min=self.u_min,
                                     u_max=self.u_max)

    def _pack(self) -> np.ndarray:
        A, B = lfc_matrices(self.params)
        try:
            Ad, Bd = discretize(self.params, self.Ts)
        except ValueError as err:
            raise ValueError(f"Ts={self.Ts!r} s: the prediction over the look-ahead cannot "
                             f"be computed ({err})") from err
        C = output_matrix()
        CAd = C @ Ad
        d = np.zeros(SIZE)
        d[:APPLIED + 1] = (self.alpha, self.u_min, self.u_max, self.slack_weight,
                           self.outside_rule == "push", _CONFLICT_CODE[self.conflict],
                           self.prediction == "applied")
        d[P_:Q_] = CAd.T.ravel()                 # y = x P + u q + p r   (P: 5 x 2)
        d[Q_:R_], d[R_:W_] = C @ Bd[:, 0], C @ Bd[:, 1]
        d[W_:KG_] = (CAd @ A).T.ravel()          # C Ad x' = x W + u kg + p wl
        d[KG_:WL_], d[WL_:LIM2_] = CAd @ B[:, 0], CAd @ B[:, 1]
        d[LIM2_:SIZE] = self.limits ** 2
        return d

    def reason(self, flags: int) -> str:
        parts = []
        if flags & INVALID:
            parts.append("invalid input (non-finite or beyond 1e6: a corrupted message): "
                         "barrier not evaluated, last applied command held within the "
                         "actuator limits")
        if flags & OUTSIDE:
            parts.append("prediction outside the safe set (h <= 0): " + (
                "pushing back" if self.outside_rule == "push" else "not letting it get worse"))
        if flags & INFEASIBLE:
            parts.append("constraints conflict: " + (
                "relaxed (slack) compromise" if self.conflict == "slack"
                else f"{self.conflict} constraint met first"))
        bound = [n for n, bit in (("frequency", BIND_FREQ), ("rocof", BIND_ROCOF),
                                  ("u_min", BIND_UMIN), ("u_max", BIND_UMAX)) if flags & bit]
        if flags & ACTIVE and bound:
            parts.append("command limited by " + ", ".join(bound))
        if flags & SOLVER_ERROR:
            parts.append("cvxpy failed; exact solution used")
        return "; ".join(parts)

    def details(self, d0: float, d1: float, flags: int) -> dict:
        return {"kind": _kinds_of(flags) if isinstance(flags, int) else _kinds(flags),
                "bound": (d0, d1)}

    def decide_python(self, x: np.ndarray, u_ref: float, p_load: float,
                      memory: np.ndarray) -> tuple:
        """``solver="cvxpy"``: the closed form's flags, the reference QP's command
        (predicting with the command applied last, read before the closed form
        overwrites it)."""
        u_pred = memory[0] if self.prediction == "applied" else u_ref
        out = decide(self.data, x, u_ref, p_load, memory)
        if out[1] & INVALID:
            return out
        from cvxpy.error import SolverError
        try:
            u = self.reference.solve(np.asarray(x, float), u_ref, p_load, u_pred)
        except (SolverError, RuntimeError):
            return (out[0], out[1] | SOLVER_ERROR) + out[2:]
        memory[0] = u
        return (u,) + out[1:]


@functools.cache
def _kinds_of(flags: int) -> tuple[int, int]:
    """:func:`_kinds` of one call's flags, worked out once per value."""
    return _kinds(flags)


def _kinds(flags):
    """+1 (``u >= bound``), -1 (``u <= bound``) or 0 per constraint, from the flag bits
    (an int for one call, an array for a batch)."""
    return tuple(((flags & lo) != 0) * 1 - ((flags & hi) != 0) * 1
                 for lo, hi in ((KIND_FREQ_LO, KIND_FREQ_HI), (KIND_ROCOF_LO, KIND_ROCOF_HI)))


@inline
def gamma(h: float, alpha: float, push: bool) -> float:
    """``gamma(h) = alpha h (1+h) / -log(h/(1+h))`` for h > 0; for h <= 0 ``alpha h``
    (``push``, E9 "push") or 0 (E9 "hold").  The paper's ``dB/dt <= alpha / B``
    equals ``dh/dt >= -gamma(h)``."""
    if h > 0:
        return alpha * h * (1 + h) / math.log1p(1 / h)
    return alpha * h if push else 0.0


@inline
def _row(fd: np.ndarray, i: int, x: np.ndarray, u_pred: float, p: float) -> tuple:
    """Constraint ``i`` (0: frequency, 1: ROCOF): ``(y, h, g, c, kind, bound)`` with
    the constraint ``g u + c >= 0`` read as ``u >= bound`` (kind +1), ``u <= bound``
    (kind -1) or no influence (kind 0)."""
    y, w = 0.0, 0.0
    for k in range(5):
        y += fd[P_ + 2 * k + i] * x[k]
        w += fd[W_ + 2 * k + i] * x[k]
    y = y + fd[Q_ + i] * u_pred + fd[R_ + i] * p
    w = w + fd[WL_ + i] * p
    h = fd[LIM2_ + i] - y * y
    g, c = -2.0 * y * fd[KG_ + i], -2.0 * y * w + gamma(h, fd[ALPHA], fd[PUSH] == 1.0)
    kind = 1 if g > G_EPS else (-1 if g < -G_EPS else 0)
    return y, h, g, c, kind, (-c / g if kind != 0 else 0.0)


@inline
def decide(fd: np.ndarray, x: np.ndarray, u_ref: float, p: float, mem: np.ndarray) -> tuple:
    """One call of the paper's filter (see the module docstring).

    ``fd`` is :class:`PaperFilter`'s data, ``mem[0]`` the command applied last
    (``prediction="applied"``).  Returns ``(u, flags, h_freq, h_rocof,
    margin_freq, margin_rocof, y_freq, y_rocof, bound_freq, bound_rocof)``.
    """
    u_min, u_max = fd[U_MIN], fd[U_MAX]
    nan = math.nan
    valid = valid_input(x, u_ref, p)
    # defined on every path (numba inlines this function into the dispatcher's
    # generated body, which cannot type a variable defined on one branch only)
    y0 = h0 = g0 = c0 = b0 = y1 = h1 = g1 = c1 = b1 = nan
    k0 = k1 = 0
    if valid:
        u_pred = mem[0] if fd[APPLIED] == 1.0 else u_ref
        y0, h0, g0, c0, k0, b0 = _row(fd, 0, x, u_pred, p)
        y1, h1, g1, c1, k1, b1 = _row(fd, 1, x, u_pred, p)
        valid = (math.isfinite(c0) and math.isfinite(g0) and math.isfinite(c1)
                 and math.isfinite(g1))
    if not valid:                  # hold the last command applied (0 at first)
        u = min(max(mem[0], u_min), u_max)
        u = u if math.isfinite(u) else 0.0
        mem[0] = u
        return u, INVALID | (ACTIVE if u != u_ref else 0), nan, nan, nan, nan, nan, nan, nan, nan
    lo, hi = u_min, u_max
    for k, b in ((k0, b0), (k1, b1)):
        if k == 1:
            lo = max(lo, b)
        elif k == -1:
            hi = min(hi, b)
    feasible = lo <= hi
    if feasible:
        u = min(max(u_ref, lo), hi)
        if abs(u - u_ref) <= BOUND_ULPS * EPS * abs(u) and u_min <= u_ref <= u_max:
            u = u_ref                # on the bound within round-off: satisfied
    elif fd[CONFLICT] == 0.0:
        u = min(max(_relaxed(u_ref, k0, b0, k1, b1, fd[RHO]), u_min), u_max)
    elif fd[CONFLICT] == 1.0:        # frequency first
        u = _priority(u_ref, k0, b0, k1, b1, u_min, u_max)
    else:                            # ROCOF first
        u = _priority(u_ref, k1, b1, k0, b0, u_min, u_max)
    mem[0] = u
    flags = 0
    admissible = u_min <= u_ref <= u_max
    for k, b, c, h, lo_bit, hi_bit in ((k0, b0, c0, h0, KIND_FREQ_LO, KIND_FREQ_HI),
                                       (k1, b1, c1, h1, KIND_ROCOF_LO, KIND_ROCOF_HI)):
        slack = BOUND_ULPS * EPS * abs(b)
        admissible = (admissible and (k != 1 or u_ref >= b - slack)
                      and (k != -1 or u_ref <= b + slack))
        if k == 0 and c < 0:
            feasible = False
        if h <= 0:
            flags |= OUTSIDE
        flags |= lo_bit if k == 1 else (hi_bit if k == -1 else 0)
    if not admissible:
        flags |= ACTIVE
        for k, b, bit in ((k0, b0, BIND_FREQ), (k1, b1, BIND_ROCOF)):
            if k != 0 and abs(u - b) <= BIND_TOL * (1 + abs(b)):
                flags |= bit
        for lim, bit in ((u_min, BIND_UMIN), (u_max, BIND_UMAX)):
            if math.isfinite(lim) and abs(u - lim) <= BIND_TOL * (1 + abs(lim)):
                flags |= bit
    if not feasible:
        flags |= INFEASIBLE
    m0 = k0 * (u - b0) if k0 != 0 else nan
    m1 = k1 * (u - b1) if k1 != 0 else nan
    return u, flags, h0, h1, m0, m1, y0, y1, b0, b1


@inline
def _relaxed(u_ref: float, k0: int, b0: float, k1: int, b1: float, rho: float) -> float:
    """Minimizer of ``1/2 (u - u_ref)^2 + rho/2 sum violation_i(u)^2``: with a set S
    of violated constraints it is ``(u_ref + rho sum_S bound) / (1 + rho |S|)``;
    every candidate S is tried and the smallest objective wins (exact)."""
    best_u, best_f = u_ref, _relaxed_objective(u_ref, u_ref, k0, b0, k1, b1, rho)
    for mask in range(1, 4):
        total, count = 0.0, 0
        if mask & 1 and k0 != 0:
            total, count = total + b0, count + 1
        if mask & 2 and k1 != 0:
            total, count = total + b1, count + 1
        cand = (u_ref + rho * total) / (1 + rho * count)
        f = _relaxed_objective(cand, u_ref, k0, b0, k1, b1, rho)
        if f < best_f:
            best_u, best_f = cand, f
    return best_u


@inline
def _relaxed_objective(u: float, u_ref: float, k0: int, b0: float, k1: int, b1: float,
                       rho: float) -> float:
    v0, v1 = max(k0 * (b0 - u), 0.0), max(k1 * (b1 - u), 0.0)
    return 0.5 * (u - u_ref) ** 2 + 0.5 * rho * (v0 * v0 + v1 * v1)


@inline
def _priority(u_ref: float, kp: int, bp: float, ko: int, bo: float, u_min: float,
              u_max: float) -> float:
    """Meet the priority constraint ``(kp, bp)`` within the actuator limits, then
    come as close to the other ``(ko, bo)`` as that allows (where the QP is
    infeasible)."""
    lo = max(bp, u_min) if kp == 1 else u_min
    hi = min(bp, u_max) if kp == -1 else u_max
    if lo > hi:
        return min(max(bp, u_min), u_max)
    target = bo if ko != 0 else u_ref
    return min(max(target, lo), max(lo, hi))
