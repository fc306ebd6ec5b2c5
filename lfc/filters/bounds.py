"""The certificate mathematics the certified, coupled and contract filters share.

Between two samples of a held input, how far an output can move (:func:`intersample`,
from :func:`curvature_gains`), the sparsest sample times that keep that within a
tightening (:func:`merge_intervals`), the matrix exponential at many times
(:func:`expm_at`), and how far a tie-line export can move in one control period while
every frequency stays in its relay band (:func:`tie_step_bound`: the per-area filters'
load budget in a grid), and how far a load within a certified filter's assumption moves
the state at the horizon in its terminal set's norm (:func:`load_moves_terminal`,
:func:`band_moves_terminal`).  The gains of the plant's responses to bounded inputs are
:mod:`lfc.filters.responses`.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import eigh, expm

from lfc.filters.responses import L1_HORIZON
from lfc.multiarea import MultiAreaParams
from lfc.relays import RelaySettings


def curvature_gains(A: np.ndarray, C: np.ndarray, times: np.ndarray) -> np.ndarray:
    """``K_k`` (per interval of ``times``, the first from 0; shape (n, 2, 5)) with
    ``|y''| <= K_k V`` on the interval whenever ``|x'(0)| <= V`` entrywise.

    Held input: ``y''(t) = C A e^{At} v`` with ``v = x'(0)``, and on
    ``[t_k, t_k + d]``, ``|C A e^{At} v| <= |C A e^{A t_k}| e^{|A| d} |v|``
    entrywise (``|e^{As}| <= e^{|A| s}``)."""
    starts = np.concatenate([[0.0], times[:-1]])
    growth = expm_at(np.abs(A), times - starts)          # e^{|A| d}
    return np.abs(C @ A @ expm_at(A, starts)) @ growth


def merge_intervals(times: np.ndarray, curvature: np.ndarray, tightening: float
                     ) -> np.ndarray:
    """The coarsest subset of ``times`` whose steps ``d`` keep ``D2 d^2 / 8``
    within ``tightening`` (``curvature``: ``D2`` over each interval of ``times``
    divided by the limit, (n, 2)): consecutive intervals are merged greedily,
    ``D2`` over a merged step being the largest of its parts'."""
    keep, start, worst = [], 0.0, 0.0
    for k, t in enumerate(times):
        worst = max(worst, float(np.max(curvature[k])))
        if k + 1 < len(times):
            nxt = max(worst, float(np.max(curvature[k + 1])))
            if nxt * (times[k + 1] - start) ** 2 / 8 <= tightening:
                continue
        keep.append(k)
        start, worst = t, 0.0
    return np.array(keep)


def intersample(gains: np.ndarray, V: np.ndarray, fine: np.ndarray,
                 times: np.ndarray) -> np.ndarray:
    """How far each output can move between two samples (pu, pu/s).

    For the interval ending at sample k (the first starts at the current state),
    of length d: ``D2 d^2 / 8``, ``D2`` the largest of :func:`curvature_gains`
    ``@ V`` over the intervals of the finer grid ``fine`` it spans (``times`` is
    a subset of ``fine``).  Returns, per sample and output (n, 2), the larger
    of its two intervals' bounds (row 0 also bounds the first interval).  If an
    output's extreme between two samples is interior, ``y' = 0`` there and it
    is at most ``d / 2`` from one of them: ``|y| <= max(|y_k|, |y_k+1|) +
    D2 d^2 / 8``."""
    d2_fine = gains @ V                                     # (n_fine, 2)
    ends = np.searchsorted(fine, times - 1e-12) + 1         # fine[ends - 1] == times
    d2 = np.maximum.reduceat(d2_fine, np.concatenate([[0], ends[:-1]]), axis=0)
    steps = np.diff(np.concatenate([[0.0], times]))
    tau = d2 * steps[:, None] ** 2 / 8
    return np.maximum(tau, np.vstack([tau[1:], tau[-1:]]))


def expm_at(A: np.ndarray, times: np.ndarray) -> np.ndarray:
    """``e^{A t}`` for every ``t`` of ``times``: shape (len(times), n, n); by the
    eigendecomposition when ``A``'s eigenvectors are well conditioned, else
    ``expm`` at each distinct time."""
    w, V = np.linalg.eig(A)
    if np.linalg.cond(V) < 1e6:
        return np.real(np.einsum("ij,tj,jk->tik", V, np.exp(np.outer(times, w)),
                                 np.linalg.inv(V)))
    distinct, back = np.unique(times, return_inverse=True)
    return np.array([expm(A * t) for t in distinct])[back]


def pair(v) -> str:
    """Two numbers (frequency pu, ROCOF pu/s) as ``(a, b)`` to 3 digits, for messages."""
    return f"({v[0]:.3g}, {v[1]:.3g})"


def tie_step_bound(params: MultiAreaParams, area: int, relays: RelaySettings,
                   control_period: float) -> float:
    """How far area ``area``'s tie-line export can move in one control period
    (pu) while every area's frequency deviation stays within the relay band
    ``F``: ``control_period * sum_j T_ij * 2 F``."""
    rate = sum(coef for i, j, coef in params.tie if area in (i, j)) * 2 * relays.F
    return float(control_period * rate)


def load_moves_terminal(A: np.ndarray, bl: np.ndarray, E: np.ndarray, P: np.ndarray, *,
                        load_given: bool = False) -> float:
    """How far, in ``P``'s norm, a load of total variation 1 pu moves ``e_T = E (x -
    x_eq)`` between a command's certification and a re-check (a proven bound), the
    re-check given the true load (``load_given``) or the load given at the
    certification.

    A step ``d`` at ``s`` before the re-check leaves ``-e^{As} q_p d`` of the new
    equilibrium's deviation (the load given), or ``(I - e^{As}) q_p d`` of the old
    one's; ``||E e^{As} z||_P`` does not grow with ``s`` (``P`` is a Lyapunov matrix
    of ``A``): at most ``||E q_p||_P``, or twice that."""
    z = E @ np.linalg.solve(A, bl)
    moved = float(np.sqrt(max(z @ P @ z, 0.0)))
    return moved if load_given else 2.0 * moved


def band_moves_terminal(A: np.ndarray, bl: np.ndarray, E: np.ndarray, P: np.ndarray) -> float:
    """How far, in ``P``'s norm, a load within ±1 pu of the one given at a
    command's certification moves ``e_T = E (x - x_eq)`` between the certification
    and a re-check at that load (a proven bound): ``int_0^inf f(s) ds`` with ``f(s) =
    ||e^{As} E b_l||_P`` (``E = e^{AT}``).  ``f`` does not increase (``P`` is a
    Lyapunov matrix of ``A``), so the left sum on 1 ms to ``L1_HORIZON`` bounds it
    there, and after, ``f(s) <= f(H) e^{-lam (s - H) / 2}`` with ``lam`` the least
    ``z' Q z / z' P z``, ``Q = -(A' P + P A)``: ``2 f(H) / lam``."""
    dt = 1e-3
    s = np.arange(0.0, L1_HORIZON + dt / 2, dt)
    z = expm_at(A, s) @ (E @ bl)
    f = np.sqrt(np.maximum(np.einsum("ti,ij,tj->t", z, P, z), 0.0))
    lam = float(np.min(eigh(-(A.T @ P + P @ A), P, eigvals_only=True)))
    return float(dt * np.sum(f[:-1]) + 2.0 * f[-1] / lam)
