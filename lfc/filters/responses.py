"""How far a stable linear plant's outputs can move under a class of bounded
inputs: the gains the certificates are built from.

For ``x' = A x + b v`` and outputs ``y = C x`` from equilibrium, with impulse
response ``h(t) = C e^{At} b`` and step response ``S(t) = C A^-1 (e^{At} - I) b``:

* :func:`load_gains` — ``"band"``: ``int |h|``, the most any input within ±1 pu
  moves ``y`` (the L1 norm); ``"steps"``: ``sup |S|``, the most an input of total
  variation 1 pu moves it; ``"swing"``: ``sup S - inf S``;
* :func:`load_tails` — ``int_s^inf |h|``, what a load within ±1 pu from ``s`` on
  can still do;
* :func:`period_step_gain` — ``sup |S|`` within one control period;
* :func:`rate_gains` — the most a held input moving by at most 1 pu/s moves ``y``
  away from where its final value puts it.

Each is an *enclosure*: an upper bound proven for the plant, not an estimate.
With ``h = sum_i r_i e^{w_i t}`` (the eigen-decomposition ``A V = V W``) the
modal envelopes ``sum_i |r_i| e^{Re w_i t}`` and ``sum_i |r_i w_i| e^{Re w_i t}``
bound ``|h|`` and ``|h'|`` from ``t`` on (they decrease).  A gain is evaluated on
a fine time grid (1 ms) up to a horizon (``L1_HORIZON``, 60 s, doubled while what
lies beyond exceeds ``TAIL`` of the gain: tightness, not soundness), and

* between grid points, the linear interpolation's error: ``int |h|`` over a step
  ``dt`` at most that of the interpolation plus ``dt^3 |h''| / 12``, ``sup S`` at
  most the larger end plus ``dt^2 |h'| / 8`` (:func:`_l1`, :func:`_extremes`; the
  envelopes at the step's start);
* beyond the horizon ``T``, the modal bounds ``int_T^inf |h| <= sum_i |r_i|
  e^{Re w_i T} / |Re w_i|`` and ``|S(t) - S(inf)| <= sum_i |r_i / w_i| e^{Re w_i T}``,
  added;
* the floating-point computation (:func:`_decomposition`, :func:`_modes`): what
  the computed eigen-decomposition's residual (``A V - V W``) and rounding in
  evaluating and summing the modal sums can change, added.

``tests/test_proven_load.py`` checks every gain against a 0.1 ms grid reference
(the enclosure contains it, and is within 0.2 % of it).  The grid is evaluated in
pieces of ``L1_HORIZON`` s (memory), each once: a longer horizon reuses the
pieces of the shorter one.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from lfc._validate import check_positive

L1_HORIZON = 60.0      # s: the first horizon of every gain, and the pieces' length
DT = 1e-3              # s: the time grid of load_gains and rate_gains
TAIL = 1e-3            # the horizon grows while what lies beyond exceeds this share of the gain
_EPS = float(np.finfo(float).eps)


def responses(A: np.ndarray, b: np.ndarray, C: np.ndarray,
              t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The outputs' impulse response ``h(t) = C e^{At} b`` and step response
    ``S(t) = C A^-1 (e^{At} - I) b`` at times ``t`` (each (len(C), len(t)))."""
    w, V = np.linalg.eig(A)
    modes = np.linalg.solve(V, b)
    resp = np.real((C @ V) @ (np.exp(np.outer(w, t)) * modes[:, None]))
    step = np.real((C @ V) @ (np.expm1(np.outer(w, t)) * (modes / w)[:, None]))
    return resp, step


@dataclass(frozen=True)
class _Modes:
    """The modal form of ``(A, b, C)``: eigenvalues ``w``, residues' moduli
    ``residue`` (len(C), len(A)), the step response's final value ``final``
    (signed), and what bounds the computed form's error (:func:`_modes`):
    ``|h - h_computed|(t) <= gap t e^{-decay t}`` and ``int |h - h_computed| <=
    gap_int`` (per output); ``rounding``, the relative size of one evaluation's
    rounding."""

    w: np.ndarray
    residue: np.ndarray
    final: np.ndarray
    gap: np.ndarray
    gap_int: np.ndarray
    decay: float
    rounding: float

    def envelope(self, t: np.ndarray, power: int = 0) -> np.ndarray:
        """``sum_i |r_i| |w_i|^power e^{Re w_i t}`` (len(C), len(t)): at least
        ``|h|`` (power 0), ``|h'|`` (1), ``|h''|`` (2) or ``|S - S(inf)|`` (-1) from
        ``t`` on."""
        return (self.residue * np.abs(self.w) ** power) @ np.exp(np.outer(self.w.real, t))

    def beyond(self, horizon: float, power: int = 0) -> np.ndarray:
        """``sum_i |r_i| |w_i|^power e^{Re w_i T} / |Re w_i|`` at ``T = horizon``:
        at least ``int_T^inf |h|`` (power 0)."""
        return (self.residue * np.abs(self.w) ** power) @ (np.exp(self.w.real * horizon)
                                                           / -self.w.real)

    def rounded(self) -> np.ndarray:
        """Per output, at least what rounding moves ``int |h|``, one ``S(t)`` or
        ``S(t) - S(inf)``: ``rounding`` times ``sum_i |r_i| (1 / |Re w_i| + 1 /
        |w_i|) + |S(inf)|``."""
        return self.rounding * (self.residue @ (1.0 / -self.w.real + 1.0 / np.abs(self.w))
                                + np.abs(self.final))

    def error(self) -> np.ndarray:
        """Per output, at least how far ``int |h|`` or ``sup |S|`` computed from the
        modal form can be from the exact value: ``gap_int`` and :meth:`rounded`."""
        return self.gap_int + self.rounded()


def _decomposition(A: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
    """``(w, V, kappa ||R||, s)``: the eigen-decomposition ``A V ~ V W`` and what
    bounds its error.

    The computed form is exact for ``A' = V W V^-1 = A - R V^-1`` with ``R = A V
    - V W``.  With ``delta = ||R|| ||V^-1||``, ``kappa = cond(V)``, ``sigma = min |Re
    w|`` and ``s = sigma - kappa delta``, ``||e^{A t}|| <= kappa e^{-s t}`` (Gronwall
    in the eigenvectors' coordinates), and ``e^{At} - e^{A't} = int_0^t e^{A(t-u)} R
    e^{Wu} V^-1 du``: for any ``C_o`` and ``M``, ``||C_o (e^{At} - e^{A't}) M|| <=
    ||C_o|| kappa ||R|| int_0^t e^{-s(t-u)} sum_i ||(V^-1 M)_i|| e^{Re w_i u} du``.
    ``ValueError`` if ``A`` is not asymptotically stable (no gain is finite) or
    ``s <= sigma / 2`` (eigenvectors too ill-conditioned for the bound)."""
    w, V = np.linalg.eig(A)
    if not np.all(w.real < 0):
        raise ValueError(f"the held plant is not asymptotically stable (eigenvalue real part "
                         f"{w.real.max():.3g} 1/s >= 0): no gain is finite")
    sigma = float(-w.real.max())
    kappa = float(np.linalg.cond(V))
    residual = float(np.linalg.norm(A @ V - V * w, 2))
    delta = residual * float(np.linalg.norm(np.linalg.inv(V), 2))
    if sigma - kappa * delta <= 0.5 * sigma:
        raise ValueError(f"the held plant's eigenvectors are too ill-conditioned (condition "
                         f"number {kappa:.3g}) for a proven gain")
    return w, V, kappa * residual, sigma - kappa * delta


def _modes(A: np.ndarray, b: np.ndarray, C: np.ndarray) -> _Modes:
    """The modal form of ``(A, b, C)`` and the bound on its computed error
    (:func:`_decomposition` with ``M = b``, ``m = V^-1 b``): ``gap = ||C_o|| kappa
    ||R|| sum_i |m_i|`` (``e^{-s(t-u)} e^{Re w_i u} <= e^{-s t}``) and, integrated
    over ``t``, ``gap_int = ||C_o|| kappa ||R|| sum_i |m_i| / (s |Re w_i|)``.
    Rounding in one evaluation of a modal sum of ``n`` terms is below ``64 n eps``
    of the sum of its terms' moduli (pairwise summation of a grid adds ``log2`` of
    its length times ``eps``, far less)."""
    w, V, spread, decay = _decomposition(A)
    m = np.linalg.solve(V, b)
    residue = np.abs((C @ V) * m[None, :])
    scale = spread * np.linalg.norm(C, axis=1)
    return _Modes(w, residue, -C @ np.linalg.solve(A, b), scale * np.sum(np.abs(m)),
                  scale * np.sum(np.abs(m) / -w.real) / decay, decay, 64 * len(A) * _EPS)


def _until_negligible(gains: Callable[[float], tuple[tuple[np.ndarray, ...],
                                                      tuple[np.ndarray, ...]]],
                      slowest: float, what: str) -> tuple[np.ndarray, ...]:
    """The enclosures ``gains(horizon)`` returns (with what lies beyond the
    horizon, which it also returns, added) at the first horizon (``L1_HORIZON``,
    doubled up to ``64 L1_HORIZON``) where what lies beyond is at most ``TAIL`` of
    each gain; ``ValueError`` naming ``what`` if none is."""
    horizon = L1_HORIZON
    while True:
        values, tails = gains(horizon)
        if all(np.all(t <= TAIL * v) for t, v in zip(tails, values)):
            return values
        if horizon >= 64 * L1_HORIZON:
            raise ValueError(f"the held plant is too slow for {what} (slowest decay "
                             f"{slowest:.3g} 1/s: more than 0.1 % of its response lies "
                             f"beyond {horizon:.0f} s)")
        horizon *= 2


def _l1_steps(resp: np.ndarray, modes: _Modes, t: np.ndarray) -> np.ndarray:
    """Per output and step of ``t`` (len(C), len(t) - 1), at least ``int |h|`` over
    the step given ``h`` at ``t`` (``resp``): per step ``d``, ``|h| <= |l| + |h -
    l|`` with ``l`` the linear interpolation, ``int |l|`` exact (``d (a^2 + b^2) /
    (2 (a + b))`` where it changes sign, ``a, b`` its ends' moduli) and ``int |h -
    l| <= d^3 / 12 sup |h''|``, the sup bounded by the envelope at the step's
    start."""
    d = np.diff(t)
    a, b = np.abs(resp[:, :-1]), np.abs(resp[:, 1:])
    crossing = resp[:, :-1] * resp[:, 1:] < 0
    line = np.where(crossing, (a ** 2 + b ** 2) / np.where(crossing, a + b, 1.0), a + b)
    return 0.5 * d * line + d ** 3 / 12 * modes.envelope(t[:-1], 2)


def _l1(resp: np.ndarray, modes: _Modes, t: np.ndarray) -> np.ndarray:
    """Per output, at least ``int |h|`` between ``t[0]`` and ``t[-1]`` (:func:`_l1_steps`
    summed)."""
    return np.sum(_l1_steps(resp, modes, t), axis=1)


def _extremes(step: np.ndarray, modes: _Modes, t: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """Per output, at least ``sup S`` and at most ``inf S`` between ``t[0]`` and
    ``t[-1]`` given ``S`` at ``t`` (``step``): per step ``d``, the larger (smaller)
    end plus (less) ``d^2 / 8 sup |S''|`` (at an interior extremum ``S' = 0``, so the
    nearer end, at most ``d / 2`` away, is within that), ``S'' = h'`` bounded by the
    envelope at the step's start."""
    pad = np.diff(t) ** 2 / 8 * modes.envelope(t[:-1], 1)
    return ((np.maximum(step[:, :-1], step[:, 1:]) + pad).max(axis=1),
            (np.minimum(step[:, :-1], step[:, 1:]) - pad).min(axis=1))


def load_gains(A: np.ndarray, bl: np.ndarray, C: np.ndarray) -> dict[str, np.ndarray]:
    """Per output, the largest deviation per pu of load (``load_kind``), each an
    enclosure (module docstring):

    * ``"band"``: ``int_0^inf |h(t)| dt``: the worst over every signal within
      ±1 pu;
    * ``"steps"``: ``sup_t |S(t)|``: a load ``L`` of total variation ``V`` moves
      the output by ``int S(t - s) dL(s)``, at most ``V sup |S|``;
    * ``"swing"``: ``sup S - inf S`` (0 and the final value included), the most
      ``int (S(t - s) - S(t - s + d)) dL(s)`` can be for a load of total variation
      1 pu that stops at a lag ``d`` (what a re-check that takes the load for 0
      has to absorb: :class:`lfc.filters.certified.CertifiedSet`).

    The horizon grows while it matters: on a chain of six areas the L1 norm over
    60 s is 0.6 of the whole (``tests/test_contract.py``).  Raises ``ValueError``
    for a plant too slow for that, or not asymptotically stable.
    """
    modes = _modes(A, bl, C)
    size = int(round(L1_HORIZON / DT))

    @functools.cache
    def piece(start: int, stop: int) -> tuple[np.ndarray, ...]:
        t = np.arange(start, stop) * DT
        resp, step = responses(A, bl, C, t)
        return (_l1(resp, modes, t), *_extremes(step, modes, t))

    def gains(horizon: float) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
        n = len(np.arange(0.0, horizon, DT))
        end = (n - 1) * DT                             # the grid's last point
        after = modes.envelope(np.array([end]), -1)[:, 0]   # |S - S(inf)| from there on
        zero = np.zeros(len(C))
        band, peak = zero, np.abs(modes.final) + after
        high, low = np.maximum(zero, modes.final + after), np.minimum(zero, modes.final - after)
        for start in range(0, n - 1, size):   # the next piece's first point closes each
            b, hi, lo = piece(start, min(start + size + 1, n))
            band, peak = band + b, np.maximum(peak, np.maximum(hi, -lo))
            high, low = np.maximum(high, hi), np.minimum(low, lo)
        tail = modes.beyond(end)
        err = modes.error()
        return ((band + tail + err, peak + err, high - low + 2 * err),
                (tail, after, 2 * after))

    band, steps, swing = _until_negligible(gains, float(-modes.w.real.max()), "a load gain")
    return {"band": band, "steps": steps, "swing": swing}


def load_tails(A: np.ndarray, bl: np.ndarray, C: np.ndarray,
               times: np.ndarray) -> np.ndarray:
    """Per time ``s`` of ``times`` (s, >= 0) and output, an enclosure of ``int_s^inf
    |h(t)| dt`` (shape (len(times), len(C))): how far a load within ±1 pu that
    acts only from ``s`` on can still move the output.  The terms of
    :func:`load_gains`' ``"band"`` (the same 1 ms grid, horizon, tail and error)
    summed from the grid point at or before ``s`` on (at ``s = 0`` that gain, to
    the summation order's rounding)."""
    times = np.asarray(times, float)
    if times.ndim != 1 or not np.all(np.isfinite(times)) or np.any(times < 0):
        raise ValueError("times must be a 1-D array of finite times >= 0 s")
    modes = _modes(A, bl, C)

    def gains(horizon: float) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
        t = np.arange(0.0, horizon, DT)
        end = (len(t) - 1) * DT
        steps = np.concatenate([_l1_steps(responses(A, bl, C, t[i:i + size + 1])[0], modes,
                                          t[i:i + size + 1])
                                for i in range(0, len(t) - 1, size)], axis=1)
        after = np.cumsum(steps[:, ::-1], axis=1)[:, ::-1]   # from each grid point on
        after = np.hstack([after, np.zeros((len(C), 1))])
        tail, err = modes.beyond(end), modes.error()
        first = np.floor(times / DT + 1e-9).astype(int)     # the grid point at or before s
        inside = first < len(t)
        rest = np.empty((len(times), len(C)))
        rest[inside] = after[:, first[inside]].T + tail
        for k in np.flatnonzero(~inside):                   # beyond the grid: the modal tail
            rest[k] = modes.beyond(times[k])
        return (after[:, 0] + tail + err, rest + err), (tail, np.zeros_like(rest))

    size = int(round(L1_HORIZON / DT))
    return _until_negligible(gains, float(-modes.w.real.max()), "a load gain")[1]


def period_step_gain(A: np.ndarray, bl: np.ndarray, C: np.ndarray,
                     period: float) -> np.ndarray:
    """Per output, the most a load of total variation 1 pu moves it within
    ``period`` s of its start: an enclosure of ``sup_{t <= period} |S(t)|`` (module
    docstring) on a grid of at most 10 us."""
    modes = _modes(A, bl, C)
    t = np.linspace(0.0, period, max(2, math.ceil(period / 1e-5)) + 1)
    high, low = _extremes(responses(A, bl, C, t)[1], modes, t)
    return np.maximum(high, -low) + modes.error()


def rate_gains(A: np.ndarray, b: np.ndarray, C: np.ndarray,
               period: float) -> tuple[np.ndarray, np.ndarray]:
    """Per output, how far an input held between samples ``period`` s apart and
    moving by at most 1 pu/s moves it away from its settled part.

    Such an input is a sum of steps ``du_k`` (``|du_k| <= period``) at the
    samples, so ``y(t) = S(inf) u(t) + sum_k (S(t - k period) - S(inf)) du_k`` and
    ``|y(t) - S(inf) u(t)| <= period sup_phi F(phi)``, ``F(phi) = sum_k |S(phi + k
    period) - S(inf)|``.  Returns an enclosure of that gain (pu per pu/s) and
    ``|S(inf)|`` (pu per pu: the settled part of an input within ±1 pu).  For
    ROCOF the final value is 0 and the gain bounds the output itself.

    ``F`` on a grid of about 1 ms (``period / ceil(period / 1 ms)``) for ``phi``;
    between grid points each term ``f_k = S(phi + k period) - S(inf)`` is within
    ``d^2 / 8 sup |h'|`` of its linear interpolation ``l_k`` (the envelope at the
    step's start), and ``sum_k |l_k|`` is convex, so ``F`` is at most the larger end
    plus the terms' sum; beyond the horizon's ``K`` periods, ``sum_i |r_i / w_i|
    e^{Re w_i K period} / (1 - e^{Re w_i period})`` at every ``phi``; the computed
    form's error summed over the periods (``gap (period / s^2 + 2 / s^3)`` for the
    decomposition, :meth:`_Modes.rounded` per term).
    """
    check_positive("period", period)
    modes = _modes(A, b, C)
    m = math.ceil(period / DT - 1e-9)
    dt = period / m
    size = max(1, int(round(L1_HORIZON / period)))

    @functools.cache
    def piece(k0: int, k1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.append((np.arange(k0, k1)[:, None] * period + np.arange(m)[None, :] * dt)
                      .ravel(), k1 * period)
        _, step = responses(A, b, C, t)
        f = step - modes.final[:, None]
        pad = dt ** 2 / 8 * modes.envelope(t[:-1], 1)
        per_phi = (len(C), -1, m)
        return (np.abs(f[:, :-1]).reshape(per_phi).sum(axis=1),
                np.abs(f[:, 1:]).reshape(per_phi).sum(axis=1), pad.reshape(per_phi).sum(axis=1))

    def gains(horizon: float) -> tuple[tuple[np.ndarray], tuple[np.ndarray]]:
        k = int(round(horizon / period))
        left, right, pad = np.zeros((3, len(C), m))
        for k0 in range(0, k, size):
            lo, hi, e = piece(k0, min(k, k0 + size))
            left, right, pad = left + lo, right + hi, pad + e
        geometric = np.exp(modes.w.real * k * period) / -np.expm1(modes.w.real * period)
        tail = (modes.residue / np.abs(modes.w)) @ geometric
        err = (modes.gap * (period / modes.decay ** 2 + 2 / modes.decay ** 3)
               + period * k * modes.rounded())
        return ((period * ((np.maximum(left, right) + pad).max(axis=1) + tail) + err,),
                (period * tail,))

    gain, = _until_negligible(gains, float(-modes.w.real.max()), "a rate gain")
    return gain, np.abs(modes.final)


def peak_norm(A: np.ndarray, C: np.ndarray, M: np.ndarray, offset: np.ndarray,
              times: np.ndarray) -> np.ndarray:
    """Per output ``o``, an enclosure of ``sup_{t >= 0} ||u_o(t)||``, ``u_o(t) = C_o
    e^{At} M + offset_o`` (a row of ``M.shape[1]``; ``offset`` (len(C),
    M.shape[1])), from ``u`` on the grid ``times`` (from 0, increasing).

    With the envelopes ``E_j(t) = sum_i |w_i|^j ||(C_o V)_i (V^-1 M)_i|| e^{Re w_i
    t}`` (at least ``||u^(j)||`` from ``t`` on, ``j >= 1``; ``||u - offset||`` for
    ``j = 0``): between grid points ``d`` apart, ``||u||^2`` (smooth, its second
    derivative at most ``2 (E_1^2 + U E_2)``, ``U`` the larger end's norm plus ``d
    E_1``) is at most the larger end plus ``d^2 / 8`` of that; beyond the last
    point ``T``, ``||offset_o|| + E_0(T)``; plus the computed form's error (the
    decomposition's, ``||C_o|| kappa ||R|| sum_i ||(V^-1 M)_i|| t e^{-s t} <= ... /
    (e s)`` with :func:`_decomposition`'s notation, and rounding's, ``64 n eps`` of
    ``E_0(0) + ||offset_o||``)."""
    w, V, spread, decay = _decomposition(A)
    left, right = C @ V, np.linalg.solve(V, M)                   # (outputs, n), (n, k)
    size = np.abs(left) * np.linalg.norm(right, axis=1)[None, :]  # per output and mode
    u = np.real(np.einsum("oi,ti,ik->tok", left, np.exp(np.outer(times, w)), right)) + offset
    norm = np.linalg.norm(u, axis=2)                              # (t, outputs)
    d = np.diff(times)[:, None]
    decays = np.exp(np.outer(times[:-1], w.real))                 # (t - 1, n)
    e1, e2 = decays @ (size * np.abs(w)).T, decays @ (size * np.abs(w) ** 2).T
    ends = np.maximum(norm[:-1], norm[1:])
    square = ends ** 2 + d ** 2 / 4 * (e1 ** 2 + (ends + d * e1) * e2)
    beyond = np.linalg.norm(offset, axis=1) + size @ np.exp(w.real * times[-1])
    err = (spread * np.linalg.norm(C, axis=1) * np.linalg.norm(right, axis=1).sum()
           / (math.e * decay)
           + 64 * len(A) * _EPS * (size.sum(axis=1) + np.linalg.norm(offset, axis=1)))
    return np.maximum(np.sqrt(square.max(axis=0)), beyond) + err
