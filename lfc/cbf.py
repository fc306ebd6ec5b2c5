"""The paper's safety-critical controller (SCC): a control-barrier-function QP.

Reading of the paper (reproduction notes E2, E5, E6, E9, E10):

* Prediction ``y(t+Ts) = C (Ad x + Bd [u_ref; p_load])`` with the incoming
  command ``u_ref`` held over the look-ahead ``Ts`` (zero-order hold).
* Barriers ``h_w = F^2 - y_w^2`` and ``h_v = rocof_limit^2 - y_v^2`` (E2: the
  bounds squared), gradients ``dh/dx = -2 y C Ad`` as printed, and the barrier
  derivative along ``x' = A x + B [u; p_load]``: affine in the decision ``u``.
* The paper's constraint ``dB/dt - alpha/B <= 0`` with the log barrier
  ``B = -log(h/(1+h))`` is, for ``h > 0``, the same as
  ``dh/dt(u) + gamma(h) >= 0`` with ``gamma(h) = alpha h (1+h) / B(h)``
  (multiply by ``h (1+h) > 0``); that form is what both solvers use.
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
  previous output; 0 after :meth:`SafetyFilter.reset`).
* E10, the QP is one-dimensional: each constraint is ``u >= bound`` or
  ``u <= bound`` and the exact answer is ``u_ref`` clipped to an interval.
  When the constraints (with the actuator limits) admit no ``u``
  (``conflict``): ``"slack"`` solves the slack-relaxed QP
  ``min 1/2 (u-u_ref)^2 + rho/2 sum s_i^2`` with each slack ``s_i`` the
  violation of constraint ``i`` in pu of command, subject to the actuator
  limits (hard); with a large ``rho`` this splits a conflict between the two
  relays evenly and, against an actuator limit, pushes as hard as the
  actuator allows.  ``"rocof"`` or ``"frequency"`` meets that constraint
  (within the actuator limits) and comes as close to the other as it allows.
  Flagged ``infeasible``.
* A constraint whose coefficient on ``u`` vanishes (``|g| <= 1e-12``) cannot
  be influenced by the command: it is dropped, and flagged ``infeasible`` if
  it is violated.
* Non-finite ``x``, ``u_ref`` or ``p_load`` (a lost measurement): no barrier
  can be evaluated; the command is ``u_ref`` (``0`` if ``u_ref`` itself is not
  finite) clipped to the actuator limits, flagged ``invalid_input``.
* ``solver="cvxpy"``: :class:`lfc.cvxpy_reference.PaperQP`, the QP written
  in cvxpy from the paper's definitions (a DPP problem built once, solved by
  Clarabel).  If it raises or does not return an optimal status the exact
  answer is used, flagged ``solver_error``.

``filter`` never raises for numeric trouble and always returns a finite command.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from operator import mul

import numpy as np

from lfc._validate import check_positive
from lfc.model import STATES, LFCParams, discretize, lfc_matrices, output_matrix
from lfc.relays import RelaySettings

SOLVERS = ("exact", "cvxpy")
METHODS = ("paper", "certified")
CONSTRAINTS = ("frequency", "rocof")
OUTSIDE_RULES = ("hold", "push")               # E9 readings
CONFLICT_RULES = ("slack", "rocof", "frequency")  # E10 readings
PREDICTIONS = ("incoming", "applied")          # E5 readings
# The reading that stops the most tripping attacks of the default attack-surface maps at
# alpha = 3 and 20 (notebooks/06_attack_surface.ipynb, "The paper's SCC at its strongest").
DEFAULT_READING = {"outside_rule": "hold", "conflict": "frequency", "prediction": "incoming"}
ALARM_FLAGS = ("active", "infeasible", "outside", "invalid_input", "solver_error")
_G_EPS = 1e-12      # |coefficient on u| below which a constraint cannot be influenced
_BIND_TOL = 1e-7    # relative tolerance to report a bound as binding


@dataclass(frozen=True)
class FilterInfo:
    """What the safety filter did at one call.

    Attributes
    ----------
    u_ref, u : float
        Incoming and applied governor command (pu).
    active : bool
        The command was changed (the SCC intervened; an alarm).
    infeasible : bool
        The constraints could not all be met; ``u`` is the slack-relaxed
        compromise (E10) or a constraint could not be influenced.
    outside : bool
        A predicted output is already outside its relay bound (``h <= 0``, E9).
    invalid_input : bool
        ``x``, ``u_ref`` or ``p_load`` was not finite; no barrier was evaluated.
    solver_error : bool
        The cvxpy solve failed; the exact solution was used.
    h_freq, h_rocof : float
        Barrier values ``F^2 - y_w^2`` (pu^2) and ``limit^2 - y_v^2`` ((pu/s)^2).
    margin_freq, margin_rocof : float
        Constraint values ``dh/dt(u) + gamma(h)`` at the applied ``u`` (>= 0: met).
    y_freq, y_rocof : float
        Predicted ``dw_meas`` (pu) and ``rocof_meas`` (pu/s) at ``t + Ts``.
    binding : tuple of str
        Bounds the solution sits on: ``"frequency"``, ``"rocof"``,
        ``"u_min"``, ``"u_max"`` (empty when not active).
    reason : str
        Human-readable explanation ("" when nothing happened).
    """

    u_ref: float
    u: float
    active: bool
    infeasible: bool
    outside: bool
    invalid_input: bool
    solver_error: bool
    h_freq: float
    h_rocof: float
    margin_freq: float
    margin_rocof: float
    y_freq: float
    y_rocof: float
    binding: tuple[str, ...]
    reason: str

    @property
    def alarm(self) -> bool:
        """True when the operator should be told (anything but a pass-through)."""
        return any(getattr(self, flag) for flag in ALARM_FLAGS)


def alarm_mask(flags: dict[str, np.ndarray]) -> np.ndarray:
    """:attr:`FilterInfo.alarm` for the flags of :meth:`SafetyFilter.filter_batch`."""
    return np.logical_or.reduce([flags[f] for f in ALARM_FLAGS if f in flags])


def barrier_gamma(h: np.ndarray, alpha: float, outside_rule: str = "push") -> np.ndarray:
    """``gamma(h) = alpha h (1+h) / -log(h/(1+h))`` for h > 0; for h <= 0
    ``0`` (``outside_rule="hold"``) or ``alpha h`` (``"push"``).

    The paper's condition ``dB/dt <= alpha / B`` equals ``dh/dt >= -gamma(h)``.
    """
    h = np.asarray(h, float)
    hp = np.where(h > 0, h, 1.0)
    paper = alpha * hp * (1 + hp) / np.log1p(1 / hp)
    return np.where(h > 0, paper, alpha * h if outside_rule == "push" else 0.0)


@dataclass(frozen=True)
class _Rows:
    """Constraint data for N states: arrays of shape (N, 2) (frequency, rocof)."""

    y: np.ndarray       # predicted outputs at t + Ts
    h: np.ndarray       # barrier values
    g: np.ndarray       # coefficient of u in dh/dt
    c: np.ndarray       # dh/dt at u = 0, plus gamma(h)
    kind: np.ndarray    # +1: u >= bound, -1: u <= bound, 0: u has no influence
    bound: np.ndarray   # the bound on u (pu); 0 where kind == 0


class SafetyFilter:
    """The paper's SCC: minimally modify the governor command to keep relays safe.

    Parameters
    ----------
    params : LFCParams
        Design model.
    relays : RelaySettings, optional
        Relay settings defining the safe set (default IEEE 1547 Cat. III).
    alpha : float
        Barrier gain alpha (1/s), > 0. Paper: 3 and 20. Default 20.
    Ts : float
        Look-ahead (s), > 0. Paper: 0.25.
    solver : {"exact", "cvxpy"}
        Closed-form solution (default) or the cvxpy/Clarabel reference.
    u_min, u_max : float
        Optional actuator limits on the applied command (pu), ``u_min < u_max``.
    slack_weight : float
        Penalty ``rho`` on squared constraint violations (pu^-2) in the
        relaxed QP used when the constraints conflict, > 0. Default 1e4.
    outside_rule : {"hold", "push"}
        E9, a prediction already outside (``h <= 0``): demand ``dh/dt >= 0``
        or ``dh/dt >= alpha |h|`` (module docstring). Default "hold".
    conflict : {"slack", "rocof", "frequency"}
        E10, conflicting constraints: the slack-relaxed QP, or meet that
        constraint first (module docstring). Default "frequency".
    prediction : {"incoming", "applied"}
        E5, the command held in the look-ahead prediction (module docstring).
        Default "incoming".  The defaults are ``DEFAULT_READING``: of the 12
        readings, the one that stops the most attacks of the default
        attack-surface maps (notebook 06).
    method : {"paper", "certified"}
        The paper's CBF-QP (default), or the filter with a guarantee of
        :mod:`lfc.certified` (``alpha``, ``Ts`` and ``slack_weight`` unused;
        ``solver`` must be ``"exact"``; ``cvxpy_certified`` is its cvxpy check).
    period, horizon, load_bound, margin : float
        Options of ``method="certified"`` (see :class:`lfc.certified.CertifiedSet`):
        time between calls (s, default 0.01), look-ahead before the terminal
        set (s, default 4), load deviation covered (pu, default 0) and extra
        fractional tightening of the limits (default 0).
    """

    def __init__(self, params: LFCParams, relays: RelaySettings | None = None, *,
                 alpha: float = 20.0, Ts: float = 0.25, solver: str = "exact",
                 u_min: float = -math.inf, u_max: float = math.inf,
                 slack_weight: float = 1e4, outside_rule: str = "hold",
                 conflict: str = "frequency", prediction: str = "incoming", method: str = "paper",
                 period: float = 0.01, horizon: float = 4.0, load_bound: float = 0.0,
                 margin: float = 0.0) -> None:
        check_positive("alpha", alpha)
        for name, value, allowed in (("outside_rule", outside_rule, OUTSIDE_RULES),
                                     ("conflict", conflict, CONFLICT_RULES),
                                     ("prediction", prediction, PREDICTIONS)):
            if value not in allowed:
                raise ValueError(f"{name} must be one of {allowed}, got {value!r}")
        self.outside_rule, self.conflict, self.prediction = outside_rule, conflict, prediction
        check_positive("Ts", Ts)
        check_positive("slack_weight", slack_weight)
        if solver not in SOLVERS:
            raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
        if not (u_min < u_max) or math.isnan(u_min) or math.isnan(u_max):
            raise ValueError(f"u_min must be < u_max, got u_min={u_min!r}, u_max={u_max!r}")
        self.params = params
        self.relays = relays if relays is not None else RelaySettings()
        self.alpha, self.Ts, self.solver = float(alpha), float(Ts), solver
        self.u_min, self.u_max, self.slack_weight = float(u_min), float(u_max), float(slack_weight)
        self.limits = np.array([self.relays.F, self.relays.rocof_limit])
        self._build_prediction()
        self._cvx = None
        if solver == "cvxpy":
            from lfc.cvxpy_reference import PaperQP
            self._cvx = PaperQP(params, self.relays, alpha=self.alpha, Ts=self.Ts,
                                outside_rule=outside_rule, conflict=conflict,
                                slack_weight=self.slack_weight, u_min=self.u_min,
                                u_max=self.u_max)
        self._u_applied, self._u_applied_batch = 0.0, None
        self.method, self._certified = self._make_method(method, period, horizon, load_bound,
                                                         margin)

    def _make_method(self, method: str, period: float, horizon: float, load_bound: float,
                     margin: float):
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {method!r}")
        if method == "paper":
            return method, None
        if self.solver != "exact":
            raise ValueError("solver must be 'exact' with method='certified' "
                             "(lfc.certified.cvxpy_certified is its cvxpy reference)")
        from lfc.certified import CertifiedFilter, CertifiedSet
        return method, CertifiedFilter(CertifiedSet(
            self.params, self.relays, period=period, horizon=horizon, load_bound=load_bound,
            margin=margin, u_min=self.u_min, u_max=self.u_max))

    def reset(self) -> None:
        """Forget any state between runs (the certified filter's held command,
        the applied command of ``prediction="applied"``)."""
        self._u_applied, self._u_applied_batch = 0.0, None
        if self._certified is not None:
            self._certified.reset()

    def __repr__(self) -> str:
        if self._certified is not None:
            c = self._certified.cert
            return (f"SafetyFilter(method='certified', load_bound={c.load_bound}, "
                    f"u_min={self.u_min}, u_max={self.u_max})")
        return (f"SafetyFilter(alpha={self.alpha}, Ts={self.Ts}, solver={self.solver!r}, "
                f"outside_rule={self.outside_rule!r}, conflict={self.conflict!r}, "
                f"prediction={self.prediction!r}, u_min={self.u_min}, u_max={self.u_max})")

    def _build_prediction(self) -> None:
        A, B = lfc_matrices(self.params)
        Ad, Bd = discretize(self.params, self.Ts)
        CAd = output_matrix() @ Ad
        self._P = CAd.T.copy()                          # y = x P + u_ref q + pL r
        self._q, self._r = output_matrix() @ Bd[:, 0], output_matrix() @ Bd[:, 1]
        self._W = (CAd @ A).T.copy()                    # C Ad x' = x W + u kg + pL wl
        self._kg, self._wl = CAd @ B[:, 0], CAd @ B[:, 1]
        self._scalar = tuple(  # Python floats: the scalar path avoids numpy overhead
            (tuple(map(float, self._P[:, i])), float(self._q[i]), float(self._r[i]),
             tuple(map(float, self._W[:, i])), float(self._kg[i]), float(self._wl[i]),
             float(self.limits[i] ** 2)) for i in range(2))

    # -- the constraints -------------------------------------------------------
    def rows(self, x: np.ndarray, u_pred: np.ndarray, p_load: np.ndarray) -> _Rows:
        """Barrier constraints for states ``x`` (N, 5), the commands held in the
        prediction and the loads (N,)."""
        y = x @ self._P + u_pred[:, None] * self._q + p_load[:, None] * self._r
        h = self.limits**2 - y**2
        g = -2 * y * self._kg
        c = (-2 * y * (x @ self._W + p_load[:, None] * self._wl)
             + barrier_gamma(h, self.alpha, self.outside_rule))
        kind = np.where(g > _G_EPS, 1, np.where(g < -_G_EPS, -1, 0))
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = np.where(kind != 0, -c / np.where(kind != 0, g, 1.0), 0.0)
        return _Rows(y=y, h=h, g=g, c=c, kind=kind, bound=bound)

    # -- batch interface (exact solver) ------------------------------------------
    def filter_batch(self, x: np.ndarray, u_ref: np.ndarray, p_load: np.ndarray | None = None
                     ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Exact filter for N states at once.

        Parameters
        ----------
        x : ndarray, shape (N, 5)
            States (pu, pu/s).
        u_ref : ndarray, shape (N,)
            Incoming commands (pu).
        p_load : ndarray, shape (N,), optional
            Load change the SCC assumes (pu); default 0 (unmeasured, E7).

        Returns
        -------
        u : ndarray, shape (N,)
            Applied commands (pu), always finite.
        flags : dict of ndarray
            ``active``, ``infeasible``, ``outside``, ``invalid_input``,
            ``h`` (N, 2), ``y`` (N, 2), ``margin`` (N, 2), and the constraint
            rows ``kind`` and ``bound`` (N, 2) as in :func:`solve_interval_qp`.
        """
        if self._certified is not None:
            return self._certified.filter_batch(x, u_ref, p_load)
        x = np.asarray(x, float).reshape(-1, 5)
        u_ref = np.asarray(u_ref, float).reshape(-1)
        p_load = np.zeros_like(u_ref) if p_load is None else np.asarray(p_load, float).reshape(-1)
        valid = np.isfinite(x).all(axis=1) & np.isfinite(u_ref) & np.isfinite(p_load)
        xs, rs, ps = (np.where(valid[:, None], x, 0.0), np.where(valid, u_ref, 0.0),
                      np.where(valid, p_load, 0.0))
        if self.prediction == "applied":
            if self._u_applied_batch is None or len(self._u_applied_batch) != len(u_ref):
                self._u_applied_batch = np.zeros(len(u_ref))
            pred = self._u_applied_batch
        else:
            pred = rs
        rows = self.rows(xs, pred, ps)
        valid &= np.isfinite(rows.c).all(axis=1) & np.isfinite(rows.g).all(axis=1)
        u, feasible = solve_interval_qp(rs, rows.kind, rows.bound, self.u_min, self.u_max,
                                        self.slack_weight, self.conflict)
        fallback = np.clip(np.where(np.isfinite(u_ref), u_ref, 0.0), self.u_min, self.u_max)
        fallback = np.where(np.isfinite(fallback), fallback, 0.0)
        u = np.where(valid, u, fallback)
        if self.prediction == "applied":
            self._u_applied_batch = u.copy()
        return u, self._flags(rows, u_ref, u, feasible, valid)

    def _flags(self, rows: _Rows, u_ref: np.ndarray, u: np.ndarray, feasible: np.ndarray,
               valid: np.ndarray) -> dict[str, np.ndarray]:
        unsat = (rows.kind == 0) & (rows.c < 0)
        admissible = _admissible(u_ref, rows.kind, rows.bound, self.u_min, self.u_max)
        return {
            "active": np.where(valid, ~admissible, u != u_ref),
            "infeasible": valid & (~feasible | unsat.any(axis=1)),
            "outside": valid & (rows.h <= 0).any(axis=1),
            "invalid_input": ~valid,
            "h": np.where(valid[:, None], rows.h, np.nan),
            "y": np.where(valid[:, None], rows.y, np.nan),
            "margin": np.where(valid[:, None], rows.g * u[:, None] + rows.c, np.nan),
            "kind": rows.kind,
            "bound": rows.bound,
        }

    # -- scalar interface ---------------------------------------------------------
    def filter(self, x: np.ndarray, u_ref: float, p_load: float = 0.0
               ) -> tuple[float, FilterInfo]:
        """Filter one governor command.

        Same mathematics as :meth:`filter_batch`, on Python floats (a 1-row numpy
        call costs ~10x more in overhead); the tests check the two agree.

        Parameters
        ----------
        x : array_like, shape (5,)
            State ``[dPg, dPm, dw, dw_meas, rocof_meas]`` (pu, pu/s): true or estimated.
        u_ref : float
            Incoming governor command dPc (pu).
        p_load : float
            Load change the SCC assumes (pu); 0 when unmeasured (E7).

        Returns
        -------
        u : float
            Command to apply (pu), always finite.
        info : FilterInfo
            What the filter did and why.

        Raises
        ------
        ValueError
            If ``x`` does not have 5 entries (a programming error, not numeric trouble).
        """
        xs = np.asarray(x, float).ravel().tolist()
        if len(xs) != 5:
            raise ValueError(f"x must have 5 entries {STATES}, got {len(xs)}")
        if self._certified is not None:
            return self._certified.filter(xs, u_ref, p_load)
        u_ref, p_load = float(u_ref), float(p_load)
        rows = None
        u_pred = self._u_applied if self.prediction == "applied" else u_ref
        if all(map(math.isfinite, xs)) and math.isfinite(u_ref) and math.isfinite(p_load):
            rows = [self._scalar_row(coef, xs, u_pred, p_load) for coef in self._scalar]
            if not all(map(math.isfinite, (v for row in rows for v in row))):
                rows = None
        if rows is None:
            u, info = self._invalid(u_ref)
            self._u_applied = u
            return u, info
        kind = [row[4] for row in rows]
        bound = [row[5] for row in rows]
        u, feasible = self._solve_scalar(u_ref, kind, bound)
        solver_error, note = False, ""
        if self._cvx is not None:
            from cvxpy.error import SolverError
            try:
                u = self._cvx.solve(np.array(xs), u_ref, p_load, u_pred)
            except (SolverError, RuntimeError) as err:
                solver_error, note = True, f"cvxpy failed ({err}); exact solution used"
        self._u_applied = u
        return u, self._info(u_ref, u, rows, feasible, solver_error, note)

    def _scalar_row(self, coef: tuple, x: list[float], u_pred: float, p_load: float
                    ) -> tuple[float, float, float, float, int, float]:
        """(y, h, g, c, kind, bound) of one barrier constraint."""
        P, q, r, W, kg, wl, lim2 = coef
        y = sum(map(mul, P, x)) + q * u_pred + r * p_load
        h = lim2 - y * y
        g = -2.0 * y * kg
        if h > 0:
            gamma = self.alpha * h * (1 + h) / math.log1p(1 / h)
        else:
            gamma = self.alpha * h if self.outside_rule == "push" else 0.0
        c = -2.0 * y * (sum(map(mul, W, x)) + wl * p_load) + gamma
        kind = 1 if g > _G_EPS else (-1 if g < -_G_EPS else 0)
        return y, h, g, c, kind, (-c / g if kind else 0.0)

    def _solve_scalar(self, u_ref: float, kind: list[int], bound: list[float]
                      ) -> tuple[float, bool]:
        lo = max([b for k, b in zip(kind, bound) if k == 1] + [self.u_min])
        hi = min([b for k, b in zip(kind, bound) if k == -1] + [self.u_max])
        if lo <= hi:
            return min(max(u_ref, lo), hi), True
        if self.conflict != "slack":
            u = solve_interval_qp(np.array([u_ref]), np.array([kind]), np.array([bound]),
                                  self.u_min, self.u_max, self.slack_weight, self.conflict)[0]
            return float(u[0]), False
        rows = [(k, b) for k, b in zip(kind, bound) if k]
        rho = self.slack_weight

        def objective(u: float) -> float:
            return 0.5 * (u - u_ref) ** 2 + 0.5 * rho * sum(
                max(k * (b - u), 0.0) ** 2 for k, b in rows)

        candidates = [(u_ref + rho * sum(b for _, b in sub)) / (1 + rho * len(sub))
                      for sub in ([], rows[:1], rows[1:], rows)]  # violated-set guesses
        u = min(candidates, key=objective)
        return min(max(u, self.u_min), self.u_max), False

    def _invalid(self, u_ref: float) -> tuple[float, FilterInfo]:
        u = min(max(u_ref if math.isfinite(u_ref) else 0.0, self.u_min), self.u_max)
        u = u if math.isfinite(u) else 0.0
        nan = math.nan
        return u, FilterInfo(
            u_ref=u_ref, u=u, active=u != u_ref, infeasible=False, outside=False,
            invalid_input=True, solver_error=False, h_freq=nan, h_rocof=nan,
            margin_freq=nan, margin_rocof=nan, y_freq=nan, y_rocof=nan, binding=(),
            reason=_reason(False, False, False, True, (), ""))

    def _info(self, u_ref: float, u: float, rows: list[tuple], feasible: bool,
              solver_error: bool, note: str) -> FilterInfo:
        (yw, hw, gw, cw, kw, bw), (yv, hv, gv, cv, kv, bv) = rows
        admissible = self.u_min <= u_ref <= self.u_max and all(
            (k != 1 or u_ref >= b) and (k != -1 or u_ref <= b) for k, b in ((kw, bw), (kv, bv)))
        active = not admissible
        infeasible = not feasible or (kw == 0 and cw < 0) or (kv == 0 and cv < 0)
        outside = hw <= 0 or hv <= 0
        binding = self._binding(u, (kw, kv), (bw, bv)) if active else ()
        return FilterInfo(
            u_ref=u_ref, u=u, active=active, infeasible=infeasible, outside=outside,
            invalid_input=False, solver_error=solver_error, h_freq=hw, h_rocof=hv,
            margin_freq=gw * u + cw, margin_rocof=gv * u + cv, y_freq=yw, y_rocof=yv,
            binding=binding,
            reason=_reason(active, infeasible, outside, False, binding, note,
                           self.outside_rule, self.conflict))

    def _binding(self, u: float, kind: np.ndarray, bound: np.ndarray) -> tuple[str, ...]:
        names = [name for name, k, b in zip(CONSTRAINTS, kind, bound)
                 if k != 0 and abs(u - b) <= _BIND_TOL * (1 + abs(b))]
        names += [name for name, lim in (("u_min", self.u_min), ("u_max", self.u_max))
                  if math.isfinite(lim) and abs(u - lim) <= _BIND_TOL * (1 + abs(lim))]
        return tuple(names)


def _admissible(u: np.ndarray, kind: np.ndarray, bound: np.ndarray, u_min: float,
                u_max: float) -> np.ndarray:
    """True where command ``u`` meets every influenceable constraint and the limits."""
    ok = np.where(kind == 1, u[:, None] >= bound, np.where(kind == -1, u[:, None] <= bound, True))
    return ok.all(axis=1) & (u >= u_min) & (u <= u_max)


def solve_interval_qp(u_ref: np.ndarray, kind: np.ndarray, bound: np.ndarray,
                      u_min: float, u_max: float, rho: float, conflict: str = "slack"
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Exact solution of the one-dimensional CBF-QP, vectorized over N problems.

    Parameters
    ----------
    u_ref : ndarray, shape (N,)
        Reference commands (pu).
    kind, bound : ndarray, shape (N, k)
        Constraint ``i`` is ``u >= bound`` (kind +1), ``u <= bound`` (kind -1)
        or absent (kind 0).
    u_min, u_max : float
        Actuator limits (pu), hard.
    rho : float
        Slack penalty of the relaxed QP used where the hard QP is infeasible.
    conflict : {"slack", "frequency", "rocof"}
        Where it is infeasible: the relaxed QP, or (k = 2 constraints,
        frequency then ROCOF) meet the named constraint within the actuator
        limits and come as close to the other as that allows.

    Returns
    -------
    u : ndarray, shape (N,)
        ``u_ref`` clipped to the admissible interval where it is non-empty;
        otherwise the minimizer of ``1/2 (u - u_ref)^2 + rho/2 sum viol_i(u)^2``
        over ``[u_min, u_max]`` (``conflict="slack"``) or the priority answer.
    feasible : ndarray of bool, shape (N,)
        Whether the hard QP was feasible.
    """
    lo = np.max(np.where(kind == 1, bound, -np.inf), axis=1, initial=-np.inf)
    hi = np.min(np.where(kind == -1, bound, np.inf), axis=1, initial=np.inf)
    lo, hi = np.maximum(lo, u_min), np.minimum(hi, u_max)
    feasible = lo <= hi
    u_hard = np.clip(u_ref, np.where(feasible, lo, -np.inf), np.where(feasible, hi, np.inf))
    if feasible.all():
        return u_hard, feasible
    if conflict == "slack":
        u_soft = np.clip(_relaxed_minimizer(u_ref, kind, bound, rho), u_min, u_max)
    else:
        u_soft = _priority_answer(u_ref, kind, bound, u_min, u_max,
                                  CONSTRAINTS.index(conflict))
    return np.where(feasible, u_hard, u_soft), feasible


def _priority_answer(u_ref: np.ndarray, kind: np.ndarray, bound: np.ndarray, u_min: float,
                     u_max: float, first: int) -> np.ndarray:
    """Meet constraint ``first`` within the actuator limits, then come as close
    to the other constraint as that allows (used where the QP is infeasible)."""
    kp, bp = kind[:, first], bound[:, first]
    ko, bo = kind[:, 1 - first], bound[:, 1 - first]
    lo = np.where(kp == 1, np.maximum(bp, u_min), u_min)
    hi = np.where(kp == -1, np.minimum(bp, u_max), u_max)
    target = np.where(ko != 0, bo, u_ref)
    inside = np.clip(target, lo, np.maximum(lo, hi))
    return np.where(lo <= hi, inside, np.clip(bp, u_min, u_max))


def _relaxed_minimizer(u_ref: np.ndarray, kind: np.ndarray, bound: np.ndarray, rho: float
                       ) -> np.ndarray:
    """Unconstrained minimizer of the convex piecewise-quadratic relaxed objective.

    The minimizer has some set S of violated constraints and then equals
    ``(u_ref + rho sum_S bound) / (1 + rho |S|)``; the objective is evaluated
    at every candidate S and the smallest wins (exact, no iteration).
    """
    n, k = kind.shape
    best_u, best_f = u_ref.copy(), _relaxed_objective(u_ref, u_ref, kind, bound, rho)
    for mask in range(1, 2**k):
        sel = np.array([(mask >> i) & 1 for i in range(k)], bool)[None, :] & (kind != 0)
        cand = (u_ref + rho * np.where(sel, bound, 0).sum(axis=1)) / (1 + rho * sel.sum(axis=1))
        f = _relaxed_objective(cand, u_ref, kind, bound, rho)
        better = f < best_f
        best_u, best_f = np.where(better, cand, best_u), np.where(better, f, best_f)
    return best_u


def _relaxed_objective(u: np.ndarray, u_ref: np.ndarray, kind: np.ndarray, bound: np.ndarray,
                       rho: float) -> np.ndarray:
    viol = np.maximum(kind * (bound - u[:, None]), 0.0)
    return 0.5 * (u - u_ref) ** 2 + 0.5 * rho * (viol**2).sum(axis=1)


def _reason(active: bool, infeasible: bool, outside: bool, invalid: bool,
            binding: tuple[str, ...], note: str, outside_rule: str = "push",
            conflict: str = "slack") -> str:
    parts = []
    if invalid:
        parts.append("non-finite input: barrier not evaluated, command passed through "
                     "(0 if not finite) within the actuator limits")
    if outside:
        parts.append("prediction outside the safe set (h <= 0): " + (
            "pushing back" if outside_rule == "push" else "not letting it get worse"))
    if infeasible:
        parts.append("constraints conflict: " + ("relaxed (slack) compromise"
                                                 if conflict == "slack" else
                                                 f"{conflict} constraint met first"))
    if active and binding:
        parts.append("command limited by " + ", ".join(binding))
    if note:
        parts.append(note)
    return "; ".join(parts)
