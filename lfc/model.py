"""The single-area load-frequency-control (LFC) model of the paper, eq. (1).

States ``x = [dPg, dPm, dw, dw_meas, rocof_meas]``: governor output, mechanical
power (pu on the generator's MVA base), frequency deviation (pu of nominal
frequency), its measurement (pu) and the ROCOF measurement (pu/s).
Inputs ``u = [dPc, dPL]``: governor-droop control signal and load change (pu).

The governor row uses the standard droop sign (Kundur 1994, ch. 11; Saadat
1999, ch. 12): ``dPg' = (dPc - dw/R - dPg)/tau_G``.  The paper prints
``+1/(R tau_G)`` (erratum E1), which makes the open loop unstable.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import TYPE_CHECKING

import numpy as np

from lfc._validate import (ParameterTypeError, check_flag, check_nonnegative, check_positive,
                           check_range)

if TYPE_CHECKING:
    import control

STATES = ("dPg", "dPm", "dw", "dw_meas", "rocof_meas")
INPUTS = ("dPc", "dPL")
OUTPUTS = ("dw_meas", "rocof_meas")


# Every positive parameter (s, pu, Hz, MVA) lies in this range, D and k_i in
# [0, 1e9]: far beyond any generator, and narrow enough that a product or a
# reciprocal of two parameters neither underflows to 0 nor overflows.
PHYSICAL = (1e-9, 1e9)


@dataclass(frozen=True)
class LFCParams:
    """Parameters of the single-area LFC model (all per unit on ``s_base_mva``).

    Each positive parameter must lie in ``PHYSICAL`` (1e-9 to 1e9), ``D`` and
    ``k_i`` in [0, 1e9]; anything else is a ``ValueError`` naming it.

    The paper gives no LFC data for its 2.5 MVA machine; the defaults are a
    small fast unit (reproduction notes section 4): typical governor and
    turbine time constants for a small reciprocating/steam unit (Kundur 1994,
    Table 11.x ranges), H = 2 s, D = 1, 5 % droop, and fast measurement lags.

    Parameters
    ----------
    tau_g : float
        Governor time constant (s). Default 0.1.
    tau_t : float
        Turbine/engine time constant (s). Default 0.3.
    M : float
        Inertia constant M = 2H (s). Default 4.0 (H = 2 s).
    D : float
        Load damping (pu power / pu frequency), >= 0. Default 1.0.
    droop : float
        Governor droop R (pu frequency / pu power). Default 0.05 (5 %).
    tau_w : float
        Frequency-measurement lag (s). Default 0.02.
    tau_rocof : float
        ROCOF-measurement lag (s). Default 0.05.
    k_i : float
        Local integral gain in ``d dPc/dt = k_i (dw_ref - dw_meas)``
        (pu power per pu frequency per s), >= 0. Default 2.0.
    f_nominal : float
        Nominal frequency (Hz) used to convert pu to Hz. Default 60.0 (Ontario).
    s_base_mva : float
        Generator MVA base of the per-unit system. Default 2.5.
    """

    tau_g: float = 0.1
    tau_t: float = 0.3
    M: float = 4.0
    D: float = 1.0
    droop: float = 0.05
    tau_w: float = 0.02
    tau_rocof: float = 0.05
    k_i: float = 2.0
    f_nominal: float = 60.0
    s_base_mva: float = 2.5

    def __post_init__(self) -> None:
        low, high = PHYSICAL
        for name in ("tau_g", "tau_t", "M", "droop", "tau_w", "tau_rocof",
                     "f_nominal", "s_base_mva"):
            check_range(name, getattr(self, name), low, high, closed=True)
        for name in ("D", "k_i"):
            value = getattr(self, name)
            check_nonnegative(name, value)
            check_range(name, value, 0.0, high, closed=True)
        for f in fields(self):        # every parameter a float (a Fraction broke numpy)
            object.__setattr__(self, f.name, float(getattr(self, f.name)))


def check_params(params: object, name: str = "params") -> "LFCParams":
    """``params``; raise a :class:`~lfc._validate.ParameterTypeError` unless it is an
    :class:`LFCParams` (a grid is a ``MultiAreaParams``, which takes its own calls)."""
    if not isinstance(params, LFCParams):
        raise ParameterTypeError(f"{name} must be an LFCParams (one area), got "
                                 f"{type(params).__name__}")
    return params


def lfc_matrices(params: LFCParams, *, printed_droop_sign: bool = False
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Return the continuous-time ``(A, B)`` of eq. (1).

    Parameters
    ----------
    params : LFCParams
        Model parameters.
    printed_droop_sign : bool
        If True, use the paper's printed ``A[0, 2] = +1/(R tau_G)`` (erratum
        E1, unstable); only for demonstrating the erratum.

    Returns
    -------
    A : ndarray, shape (5, 5)
    B : ndarray, shape (5, 2)
        Columns: ``dPc``, ``dPL``.
    """
    p = check_params(params)
    sign = 1.0 if check_flag("printed_droop_sign", printed_droop_sign) else -1.0
    A = np.array([
        [-1 / p.tau_g, 0, sign / (p.droop * p.tau_g), 0, 0],
        [1 / p.tau_t, -1 / p.tau_t, 0, 0, 0],
        [0, 1 / p.M, -p.D / p.M, 0, 0],
        [0, 0, 1 / p.tau_w, -1 / p.tau_w, 0],
        [0, 1 / (p.M * p.tau_rocof), -p.D / (p.M * p.tau_rocof), 0, -1 / p.tau_rocof],
    ])
    B = np.array([
        [1 / p.tau_g, 0],
        [0, 0],
        [0, -1 / p.M],
        [0, 0],
        [0, -1 / (p.M * p.tau_rocof)],
    ])
    return A, B


def output_matrix() -> np.ndarray:
    """Return ``C`` (2 x 5) selecting ``[dw_meas, rocof_meas]``."""
    C = np.zeros((2, len(STATES)))
    C[0, STATES.index("dw_meas")] = 1.0
    C[1, STATES.index("rocof_meas")] = 1.0
    return C


def lfc_model(params: LFCParams) -> control.StateSpace:
    """Return eq. (1) as a named python-control ``StateSpace``.

    States ``[dPg, dPm, dw, dw_meas, rocof_meas]``, inputs ``[dPc, dPL]``,
    outputs ``[dw_meas, rocof_meas]``; droop sign corrected (E1).
    """
    import control as ct  # here, not at import: python-control loads matplotlib
    A, B = lfc_matrices(params)
    return ct.ss(A, B, output_matrix(), np.zeros((2, 2)), states=list(STATES),
                 inputs=list(INPUTS), outputs=list(OUTPUTS), name="lfc")


def discretize(params: LFCParams, period: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretization of eq. (1) with python-control (E4).

    Valid for any ``A`` (the paper's ``A^-1 (A_d - I) B`` needs A invertible).

    Parameters
    ----------
    params : LFCParams
    period : float
        Sample period (s), > 0.

    Returns
    -------
    Ad : ndarray, shape (5, 5)
    Bd : ndarray, shape (5, 2)

    Raises
    ------
    ValueError
        If the discretization is not finite (a parameter so extreme that the
        plant cannot be simulated), naming the parameter.
    """
    with np.errstate(over="ignore", invalid="ignore"):   # checked just below
        Ad, Bd = zoh(*lfc_matrices(params), period)
    if not (np.all(np.isfinite(Ad)) and np.all(np.isfinite(Bd))):
        with np.errstate(over="ignore", divide="ignore"):
            rates = {("tau_g",): 1 / params.tau_g, ("tau_t",): 1 / params.tau_t,
                     ("M",): 1 / params.M, ("droop", "tau_g"): 1 / (params.droop * params.tau_g),
                     ("tau_w",): 1 / params.tau_w, ("tau_rocof",): 1 / params.tau_rocof,
                     ("D", "M"): params.D / params.M}
        names = max(rates, key=rates.get)
        given = " and ".join(f"{n}={getattr(params, n)!r}" for n in names)
        raise ValueError(f"{given} make{'s' if len(names) == 1 else ''} the plant too fast to "
                         f"simulate at a {period} s step (its discretization is not finite); "
                         f"use a physical value")
    return Ad, Bd


def zoh(A: np.ndarray, B: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretization of ``x' = A x + B u`` with python-control,
    for any ``A`` (singular included).

    Returns ``(Ad, Bd)`` with ``Ad = exp(A period)``, ``Bd = int_0^period exp(A s) ds B``.
    """
    import control as ct  # here, not at import: python-control loads matplotlib
    check_positive("period", period)
    sysd = ct.c2d(ct.ss(A, B, np.zeros((1, A.shape[0])), np.zeros((1, B.shape[1]))), period,
                  method="zoh")
    return np.asarray(sysd.A), np.asarray(sysd.B)


def block_propagator(Ad: np.ndarray, Bd: np.ndarray, steps: int
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact map from a held command and per-step loads to the next ``steps`` states.

    With ``x[k+1] = Ad x[k] + Bd[:, 0] u + Bd[:, 1] pL[k]`` and ``u`` held,
    the stacked states ``X = [x[1]; ...; x[steps]]`` (shape ``(steps*n,)``) are
    ``Phi @ x[0] + Gu * u + Gl @ pL[0:steps]``.

    Returns
    -------
    Phi : ndarray, shape (steps*n, n)
    Gu : ndarray, shape (steps*n,)
    Gl : ndarray, shape (steps*n, steps)
        Block lower-triangular: row block ``i`` depends on ``pL[0..i]`` only.
    """
    n = Ad.shape[0]
    Phi, Gu, Gl = np.zeros((steps * n, n)), np.zeros(steps * n), np.zeros((steps * n, steps))
    power, gu = np.eye(n), np.zeros(n)
    for i in range(steps):
        gu = Ad @ gu + Bd[:, 0]
        power = Ad @ power
        Phi[i * n:(i + 1) * n], Gu[i * n:(i + 1) * n] = power, gu
        for j in range(i + 1):
            Gl[i * n:(i + 1) * n, j] = np.linalg.matrix_power(Ad, i - j) @ Bd[:, 1]
    return Phi, Gu, Gl
