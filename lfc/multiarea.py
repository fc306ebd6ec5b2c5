"""Interconnected areas: tie-lines, the area control error (ACE) and AGC.

Each area is the single-area model of :mod:`lfc.model` (its own
:class:`~lfc.model.LFCParams`, all on one common MVA base and nominal
frequency).  Tie-line ``l`` between areas ``i`` and ``j`` carries the export
deviation ``dP_l`` (pu) from ``i`` to ``j``:

    dP_l' = T_ij (dw_i - dw_j)

with ``T_ij`` the synchronizing coefficient in pu power per pu frequency per
second, the convention of Saadat (1999), *Power System Analysis*, sec. 12.7,
whose block diagram feeds ``P_s / s`` with the per-unit frequency difference.
Area ``i`` exports ``dP_tie,i = sum_l (+dP_l if it starts the line, -dP_l if
it ends it)``; the export enters its swing equation exactly as a load does,
``M dw_i' = dPm_i - D dw_i - dP_L,i - dP_tie,i``, so ``w_i = dP_L,i +
dP_tie,i`` is the area's **net disturbance**.

AGC integrates the area control error ``ACE_i = dP_tie,i + B_i dw_i`` (the
frequency bias ``B_i`` defaults to ``D_i + 1/R_i``, the area's natural
response): ``d dPc_i/dt = -k_agc,i (ACE_i - B_i dw_ref,i)``.  Its default gain
``k_agc,i = k_i / B_i`` makes one area exactly the single-area model's local
integral controller, ``d dPc/dt = k_i (dw_ref - dw_meas)``.

States: the areas' ``[dPg, dPm, dw, dw_meas, rocof_meas]`` one after another,
then one export deviation per tie-line.  Inputs: every area's command
``dPc_i``, then every area's load ``dP_L,i``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from lfc._validate import ParameterTypeError, check_index, check_number, is_sequence
from lfc.model import PHYSICAL, STATES, LFCParams, discretize, lfc_matrices, zoh

N_AREA_STATES = len(STATES)
SAADAT_T = 2.0   # pu: Saadat (1999), Examples 12.5-12.7, "synchronizing power coefficient"


@dataclass(frozen=True)
class MultiAreaParams:
    """An interconnected grid of LFC areas (module docstring).

    Parameters
    ----------
    areas : tuple of LFCParams
        One per area, on one common MVA base and nominal frequency.
    tie : tuple of (i, j, T_ij)
        Tie-lines: area indices ``i != j`` and the synchronizing coefficient
        ``T_ij > 0`` (pu power per pu frequency per s).  At most one line per
        pair of areas.
    bias : tuple of float, optional
        Frequency bias ``B_i`` of each area's ACE (pu power per pu frequency),
        in ``PHYSICAL`` (1e-9 to 1e9).  Default ``D_i + 1/R_i``.
    k_agc : tuple of float, optional
        AGC integral gain on ACE of each area (1/s), in [0, 1e9].  Default
        ``k_i / B_i``: one area is then exactly :func:`lfc.simulate`'s loop.
    command_range : float, optional
        Each area's command magnitude (pu) within which this model describes the
        plant it stands for, > 0.  Default ∞: the model is the plant (the
        presets, any grid simulated on this model).  A model fitted to ANDES
        carries the range it was validated on there
        (:func:`lfc.testbed.fit.validated_range`: beyond it ANDES' tie-lines
        are far from linear).  The coupled certificate keeps every area's command
        within ``±command_range`` (its ``u_min``, ``u_max``,
        :class:`lfc.filters.coupled.CoupledOptions`).
    load_mismatch : float, optional
        How far this model is from the plant it stands for, as load (pu, summed
        over the areas), >= 0 and finite.  Default 0: the model is the plant.  A
        model fitted to ANDES carries its fit's (:func:`lfc.testbed.fit.mismatch`:
        the largest swing of the load that makes the model reproduce ANDES' rotor
        speeds, over the records of the fit and of its command range).  The grid-wide
        certificates add it to their ``load_bound`` (``mismatch_budget``,
        :class:`lfc.filters.coupled.CoupledOptions`).
    """

    areas: tuple[LFCParams, ...]
    tie: tuple[tuple[int, int, float], ...] = ()
    bias: tuple[float, ...] | None = None
    k_agc: tuple[float, ...] | None = None
    command_range: float = math.inf
    load_mismatch: float = 0.0

    def __post_init__(self) -> None:
        areas = tuple(self.areas) if isinstance(self.areas, (list, tuple)) else ()
        if not areas or not all(isinstance(a, LFCParams) for a in areas):
            error = ParameterTypeError if areas else ValueError
            raise error(f"areas must be a non-empty sequence of LFCParams, got "
                        f"{self.areas!r}")
        for name in ("f_nominal", "s_base_mva"):
            values = {getattr(a, name) for a in areas}
            if len(values) > 1:
                raise ValueError(f"every area must share one {name} (a common per-unit base), "
                                 f"got {sorted(values)}")
        n = len(areas)
        ties, pairs = [], set()
        if not is_sequence(self.tie):
            raise ParameterTypeError(f"tie must be a sequence of (i, j, T_ij) lines, got "
                                     f"{self.tie!r}")
        for k, line in enumerate(self.tie):
            try:
                i, j, coef = line
            except (TypeError, ValueError):
                raise ValueError(f"tie[{k}] must be (i, j, T_ij), got {line!r}") from None
            i, j = check_index(f"tie[{k}]'s i", i, n), check_index(f"tie[{k}]'s j", j, n)
            check_number(f"tie[{k}]'s T_ij", coef)
            coef = float(coef)
            if i == j:
                raise ValueError(f"tie[{k}] must join two different areas in [0, {n - 1}], "
                                 f"got {line!r}")
            if not (math.isfinite(coef) and coef > 0):
                raise ValueError(f"tie[{k}]'s T_ij must be a finite number > 0 (pu), got "
                                 f"{coef!r}")
            if frozenset((i, j)) in pairs:
                raise ValueError(f"tie[{k}] repeats the line between areas {i} and {j}")
            pairs.add(frozenset((i, j)))
            ties.append((i, j, coef))
        object.__setattr__(self, "areas", areas)
        object.__setattr__(self, "tie", tuple(ties))
        check_number("command_range", self.command_range)
        if not self.command_range > 0:
            raise ValueError(f"command_range must be > 0 pu (math.inf: no range), got "
                             f"{self.command_range!r}")
        object.__setattr__(self, "command_range", float(self.command_range))
        check_number("load_mismatch", self.load_mismatch)
        if not (math.isfinite(self.load_mismatch) and self.load_mismatch >= 0):
            raise ValueError(f"load_mismatch must be a finite number >= 0 pu, got "
                             f"{self.load_mismatch!r}")
        object.__setattr__(self, "load_mismatch", float(self.load_mismatch))
        for name, low, strict in (("bias", 0.0, True), ("k_agc", 0.0, False)):
            value = getattr(self, name)
            if value is None:
                continue
            if not is_sequence(value):
                raise ParameterTypeError(f"{name} must be a sequence of {n} numbers (one per "
                                         f"area), got {value!r}")
            for k, v in enumerate(value):
                check_number(f"{name}[{k}]", v)
            value = tuple(float(v) for v in value)
            if len(value) != n or not all((PHYSICAL[0] <= v if strict else 0 <= v)
                                          and v <= PHYSICAL[1] for v in value):
                raise ValueError(f"{name} must be {n} numbers in "
                                 f"{'[' + str(PHYSICAL[0]) if strict else '[0'}, {PHYSICAL[1]}]"
                                 f" (one per area), got {getattr(self, name)!r}")
            object.__setattr__(self, name, value)

    @property
    def n_areas(self) -> int:
        return len(self.areas)

    @property
    def n_states(self) -> int:
        return N_AREA_STATES * self.n_areas + len(self.tie)

    def biases(self) -> np.ndarray:
        """Each area's frequency bias ``B_i`` (pu power per pu frequency)."""
        if self.bias is not None:
            return np.array(self.bias)
        return np.array([a.D + 1 / a.droop for a in self.areas])

    def agc_gains(self) -> tuple[np.ndarray, np.ndarray]:
        """``(k_freq, k_tie)`` (1/s): AGC is ``d dPc_i/dt = k_freq_i (dw_ref_i -
        dw_meas_i) - k_tie_i (dP_tie,i + ACE attack)``, that is ``k_freq = k_agc B``
        and ``k_tie = k_agc``; by default ``k_freq = k_i`` exactly."""
        if self.k_agc is None:
            k_freq = np.array([a.k_i for a in self.areas])
            return k_freq, k_freq / self.biases()
        k = np.array(self.k_agc)
        return k * self.biases(), k

    def incidence(self) -> np.ndarray:
        """``(n_areas, n_lines)``: area ``i``'s export is ``incidence[i] @ dP_lines``."""
        E = np.zeros((self.n_areas, len(self.tie)))
        for line, (i, j, _) in enumerate(self.tie):
            E[i, line], E[j, line] = 1.0, -1.0
        return E

    @classmethod
    def two_area(cls, area: LFCParams | None = None, T: float = SAADAT_T) -> MultiAreaParams:
        """Two equal areas (default :class:`LFCParams` on a 1000 MVA base, as in
        Saadat's two-area examples) joined by one tie-line with ``T`` = 2.0 pu,
        Saadat (1999), Examples 12.5-12.7."""
        area = area or LFCParams(s_base_mva=1000.0)
        return cls(areas=(area, area), tie=((0, 1, T),))

    @classmethod
    def three_area(cls, T: float = SAADAT_T) -> MultiAreaParams:
        """Three unequal areas in a ring, each line ``T`` = 2.0 pu: area 0 the
        default area on 1000 MVA, area 1 heavier (M 6 s, D 1.5), area 2 lighter
        with a slower turbine (M 3 s, tau_T 0.4 s, D 0.8; its least damped mode
        has damping ratio 0.15).  Illustrative values in the default area's
        ranges, not from a published case."""
        base = LFCParams(s_base_mva=1000.0)
        heavy = LFCParams(M=6.0, D=1.5, s_base_mva=1000.0)
        light = LFCParams(M=3.0, tau_t=0.4, D=0.8, s_base_mva=1000.0)
        return cls(areas=(base, heavy, light), tie=((0, 1, T), (1, 2, T), (0, 2, T)))


def multiarea_matrices(params: MultiAreaParams) -> tuple[np.ndarray, np.ndarray]:
    """Continuous-time ``(A, B)`` of the interconnection (module docstring).

    Returns
    -------
    A : ndarray, shape (n_states, n_states)
    B : ndarray, shape (n_states, 2 n_areas)
        Columns: every area's ``dPc``, then every area's ``dP_L``.
    """
    if not isinstance(params, MultiAreaParams):
        raise ParameterTypeError(f"params must be a MultiAreaParams (a grid; one area: "
                                 f"lfc_matrices), got {type(params).__name__}")
    n, m = params.n_areas, N_AREA_STATES
    A, B = np.zeros((params.n_states, params.n_states)), np.zeros((params.n_states, 2 * n))
    for a, area in enumerate(params.areas):
        Aa, Ba = lfc_matrices(area)
        rows = slice(m * a, m * (a + 1))
        A[rows, rows], B[rows, a], B[rows, n + a] = Aa, Ba[:, 0], Ba[:, 1]
    E = params.incidence()
    dw = STATES.index("dw")
    for line, (i, j, coef) in enumerate(params.tie):
        s = m * n + line
        A[s, m * i + dw], A[s, m * j + dw] = coef, -coef
        for a in (i, j):     # the export acts on its area as a load does
            A[m * a:m * (a + 1), s] = E[a, line] * B[m * a:m * (a + 1), n + a]
    return A, B


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
        ``z = R x`` from the full state ``x`` of :func:`multiarea_matrices`.
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


def as_grid(params: LFCParams | MultiAreaParams) -> MultiAreaParams:
    """``params`` as a grid: a single area (:class:`LFCParams`) is a grid of one
    area with no tie-line, whose AGC is exactly its local integral controller."""
    if isinstance(params, MultiAreaParams):
        return params
    if isinstance(params, LFCParams):
        return _one_area(params)
    raise ValueError(f"params must be an LFCParams or a MultiAreaParams, got "
                     f"{type(params).__name__}")


@functools.lru_cache(maxsize=64)
def _one_area(params: LFCParams) -> MultiAreaParams:
    """The grid of one area (both frozen: built once per area, not once per scenario)."""
    return MultiAreaParams(areas=(params,))


def discretize_grid(params: MultiAreaParams, dt: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Zero-order hold of :func:`multiarea_matrices` at ``dt`` (s): ``(Ad, Bu, Bl)``
    with ``Bu`` the commands' and ``Bl`` the loads' columns (one per area).

    Raises ``ValueError`` naming the parameter if the discretization is not
    finite (:func:`lfc.model.discretize`)."""
    A, B = multiarea_matrices(params)
    with np.errstate(over="ignore", invalid="ignore"):   # checked just below
        Ad, Bd = zoh(A, B, dt)
    if not (np.all(np.isfinite(Ad)) and np.all(np.isfinite(Bd))):
        for area in params.areas:
            discretize(area, dt)           # raises, naming the parameter
        raise ValueError(f"the grid is too fast to simulate at a {dt} s step (its "
                         f"discretization is not finite); use physical tie-line coefficients")
    n = params.n_areas
    return Ad, np.ascontiguousarray(Bd[:, :n]), np.ascontiguousarray(Bd[:, n:])
