"""How far a stable linear plant's outputs can move under a class of bounded
inputs: the gains the certificates are built from.

For ``x' = A x + b v`` and outputs ``y = C x`` from equilibrium, with impulse
response ``h(t) = C e^{At} b`` and step response ``S(t) = C A^-1 (e^{At} - I) b``:

* :func:`load_gains` — ``"band"``: ``int |h|``, the most any input within ±1 pu
  moves ``y`` (the L1 norm); ``"steps"``: ``sup |S|``, the most an input of total
  variation 1 pu moves it; ``"swing"``: ``sup S - inf S``;
* :func:`period_step_gain` — ``sup |S|`` within one control period;
* :func:`rate_gains` — the most a held input moving by at most 1 pu/s moves ``y``
  away from where its final value puts it.

Each is evaluated on a fine time grid (1 ms) up to a horizon of ``L1_HORIZON``
(60 s), doubled while a modal bound on what lies beyond exceeds 0.1 % of the
gain, plus 1 % (which covers that rest and the grid).  With ``h = sum_i r_i
e^{w_i t}`` the modal bounds are ``int_T^inf |h| <= sum_i |r_i| e^{Re w_i T} /
|Re w_i|`` and ``|S(t) - S(inf)| <= sum_i |r_i / w_i| e^{Re w_i T}`` for ``t >= T``.
The grid is evaluated in pieces of ``L1_HORIZON`` s (memory), each once: a
longer horizon reuses the pieces of the shorter one.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np

from lfc._validate import check_positive

L1_HORIZON = 60.0      # s: the first horizon of every gain, and the pieces' length
DT = 1e-3              # s: the time grid of load_gains and rate_gains
TAIL = 1e-3            # the modal bound on what lies beyond the horizon, relative to the gain
COVER = 1.01           # the gains' factor: covers TAIL and the grid


def responses(A: np.ndarray, b: np.ndarray, C: np.ndarray,
              t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The outputs' impulse response ``h(t) = C e^{At} b`` and step response
    ``S(t) = C A^-1 (e^{At} - I) b`` at times ``t`` (each (len(C), len(t)))."""
    w, V = np.linalg.eig(A)
    modes = np.linalg.solve(V, b)
    resp = np.real((C @ V) @ (np.exp(np.outer(w, t)) * modes[:, None]))
    step = np.real((C @ V) @ (np.expm1(np.outer(w, t)) * (modes / w)[:, None]))
    return resp, step


def _modes(A: np.ndarray, b: np.ndarray, C: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The eigenvalues ``w``, the residues' moduli ``|r_i|`` per output (len(C),
    len(A)) and the step response's final value ``-C A^-1 b`` (signed).
    ``ValueError`` if ``A`` is not asymptotically stable (no gain is finite)."""
    w, V = np.linalg.eig(A)
    if not np.all(w.real < 0):
        raise ValueError(f"the held plant is not asymptotically stable (eigenvalue real part "
                         f"{w.real.max():.3g} 1/s >= 0): no gain is finite")
    residue = np.abs((C @ V) * np.linalg.solve(V, b)[None, :])
    return w, residue, -C @ np.linalg.solve(A, b)


def _until_negligible(gains: Callable[[float], tuple[np.ndarray, ...]],
                      tails: Callable[[float], tuple[np.ndarray, ...]],
                      slowest: float, what: str) -> tuple[np.ndarray, ...]:
    """``COVER`` times ``gains(horizon)`` at the first horizon (``L1_HORIZON``,
    doubled up to ``64 L1_HORIZON``) where every ``tails(horizon)`` is at most
    ``TAIL`` of its gain; ``ValueError`` naming ``what`` if none is."""
    horizon = L1_HORIZON
    while True:
        values = gains(horizon)
        if all(np.all(t <= TAIL * v) for t, v in zip(tails(horizon), values)):
            return tuple(COVER * v for v in values)
        if horizon >= 64 * L1_HORIZON:
            raise ValueError(f"the held plant is too slow for {what} (slowest decay "
                             f"{slowest:.3g} 1/s: more than 0.1 % of its response lies "
                             f"beyond {horizon:.0f} s)")
        horizon *= 2


def load_gains(A: np.ndarray, bl: np.ndarray, C: np.ndarray) -> dict[str, np.ndarray]:
    """Per output, the largest deviation per pu of load (``load_kind``):

    * ``"band"``: ``int_0^inf |h(t)| dt``: the worst over every signal within
      ±1 pu (trapezoidal on the 1 ms grid, plus 1 %);
    * ``"steps"``: ``sup_t |S(t)|``: a load ``L`` of total variation ``V`` moves
      the output by ``int S(t - s) dL(s)``, at most ``V sup |S|``; on the same
      grid, plus the most ``S`` can move within half a step (``|h| dt / 2``) and
      1 %, and the final value;
    * ``"swing"``: ``sup S - inf S`` (0 and the final value included), the most
      ``int (S(t - s) - S(t - s + d)) dL(s)`` can be for a load of total variation
      1 pu that stops at a lag ``d`` (what a re-check that takes the load for 0
      has to absorb: :class:`lfc.filters.certified.CertifiedSet`); same grid and
      allowances.

    The horizon grows while it matters (module docstring): on a chain of six
    areas the L1 norm over 60 s is 0.6 of the whole (``tests/test_contract.py``).
    Raises ``ValueError`` for a plant too slow for that, or not asymptotically
    stable.
    """
    w, residue, final = _modes(A, bl, C)
    size = int(round(L1_HORIZON / DT))

    @functools.cache
    def piece(start: int, stop: int) -> tuple[np.ndarray, ...]:
        t = np.arange(start, stop) * DT
        resp, step = responses(A, bl, C, t)
        slack = 0.5 * DT * np.abs(resp).max(axis=1)
        return (np.trapezoid(np.abs(resp), t, axis=1), np.abs(step).max(axis=1) + slack,
                step.max(axis=1) + slack, step.min(axis=1) - slack)

    def gains(horizon: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = len(np.arange(0.0, horizon, DT))
        zero = np.zeros(len(C))
        band, peak, high, low = zero, zero, np.maximum(zero, final), np.minimum(zero, final)
        for start in range(0, n, size):       # the next piece's first point closes each
            b, p, hi, lo = piece(start, min(start + size + 1, n))
            band, peak = band + b, np.maximum(peak, p)
            high, low = np.maximum(high, hi), np.minimum(low, lo)
        return band, np.maximum(peak, np.abs(final)), high - low

    def tails(horizon: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        decay = np.exp(w.real * horizon)
        beyond = residue @ (decay / np.abs(w))
        return residue @ (decay / -w.real), beyond, 2 * beyond

    band, steps, swing = _until_negligible(gains, tails, -w.real.max(), "a load gain")
    return {"band": band, "steps": steps, "swing": swing}


def period_step_gain(A: np.ndarray, bl: np.ndarray, C: np.ndarray,
                     period: float) -> np.ndarray:
    """Per output, the most a load of total variation 1 pu moves it within
    ``period`` s of its start: ``sup_{t <= period} |S(t)|`` on a 0.1 ms grid plus
    the most ``S`` moves in half a grid step (``|h| dt / 2``) and 1 %."""
    dt = 1e-4
    resp, step = responses(A, bl, C, np.append(np.arange(0.0, period, dt), period))
    return COVER * (np.abs(step).max(axis=1) + 0.5 * dt * np.abs(resp).max(axis=1))


def rate_gains(A: np.ndarray, b: np.ndarray, C: np.ndarray,
               period: float) -> tuple[np.ndarray, np.ndarray]:
    """Per output, how far an input held between samples ``period`` s apart and
    moving by at most 1 pu/s moves it away from its settled part.

    Such an input is a sum of steps ``du_k`` (``|du_k| <= period``) at the
    samples, so ``y(t) = S(inf) u(t) + sum_k (S(t - k period) - S(inf)) du_k`` and
    ``|y(t) - S(inf) u(t)| <= period sup_phi sum_k |S(phi + k period) - S(inf)|``.
    Returns that gain (pu per pu/s) and ``|S(inf)|`` (pu per pu: the settled part
    of an input within ±1 pu).  For ROCOF the final value is 0 and the gain
    bounds the output itself.

    On a grid of about 1 ms (``period / ceil(period / 1 ms)``) for ``phi``, plus
    the most ``S`` moves within half a grid step (``|h| dt / 2`` per term) and
    1 %; beyond the horizon the modal bound on ``|S - S(inf)|``, summed as a
    geometric series.
    """
    check_positive("period", period)
    w, residue, final = _modes(A, b, C)
    m = math.ceil(period / DT - 1e-9)
    dt = period / m
    size = max(1, int(round(L1_HORIZON / period)))

    @functools.cache
    def piece(k0: int, k1: int) -> tuple[np.ndarray, np.ndarray]:
        t = (np.arange(k0, k1)[:, None] * period + np.arange(m)[None, :] * dt).ravel()
        resp, step = responses(A, b, C, t)
        moved = np.abs(step - final[:, None]).reshape(len(C), -1, m).sum(axis=1)
        return moved, 0.5 * dt * np.abs(resp).reshape(len(C), -1, m).max(axis=2).sum(axis=1)

    def gains(horizon: float) -> tuple[np.ndarray]:
        k = int(round(horizon / period))
        sums, slack = np.zeros((len(C), m)), np.zeros(len(C))
        for k0 in range(0, k, size):
            s, e = piece(k0, min(k, k0 + size))
            sums, slack = sums + s, slack + e
        return (period * (sums.max(axis=1) + slack),)

    def tails(horizon: float) -> tuple[np.ndarray]:
        decay = np.exp(w.real * horizon)
        return (period * residue @ (decay / np.abs(w) / -np.expm1(w.real * period)),)

    gain, = _until_negligible(gains, tails, -w.real.max(), "a rate gain")
    return gain, np.abs(final)
