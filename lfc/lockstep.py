"""A linear grid stepped one control period at a time, for a caller that sets
each period's commands itself: the generator sides of :mod:`lfc.engine`
(:class:`lfc.testbed.loop.GeneratorSides`, the engine's own compiled code) in
lockstep with the plant.

Two callers: :mod:`lfc.wire` (each period's commands travel over a network) and
:mod:`lfc.experiments.adaptive` (an attacker that reads the filters before it
chooses).  The plant is :func:`lfc.multiarea.discretize_grid`'s, stepped at
``dt`` with every command held for a control period, the relays sampled at
every step, as in :func:`lfc.simulate`; a single area is a grid of one.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from lfc.engine import sample_signal
from lfc.multiarea import N_AREA_STATES, MultiAreaParams, discretize_grid
from lfc.relays import RELAY_NAMES, RelaySettings, relay_sample


class LinearGrid:
    """The grid's state, its loads and relays, advanced one control period at a time.

    Parameters
    ----------
    grid : MultiAreaParams
    loads : dict
        ``{area: signal}``: each area's load change (pu).
    following : dict, optional
        ``{area: FollowingLoad}``: a botnet's load that follows the area's frequency
        meter (:class:`lfc.load_attacks.FollowingLoad`), added to its load, switched at
        every plant step from the meter then and held over the step, as the engine
        does; the plant then steps one ``dt`` at a time.
    n_steps, ratio : int
        Plant steps of the run and per control period.
    dt : float
        Plant step (s).
    relays : RelaySettings

    Attributes
    ----------
    x : ndarray
        The state now (areas' five states each, then the tie lines).
    xs : ndarray
        The state at every plant step (n_steps + 1, states).
    trips : ndarray
        The relays that tripped at every step, as bits per area (n_steps + 1, n_areas).
    """

    def __init__(self, grid: MultiAreaParams, loads: dict, n_steps: int, ratio: int,
                 dt: float, relays: RelaySettings, following: dict | None = None) -> None:
        self.grid, self.n_steps, self.ratio, self.dt = grid, n_steps, ratio, dt
        self.following = dict(following or {})
        self.n_a = grid.n_areas
        self.t = np.arange(n_steps + 1) * dt
        self.p = np.column_stack([sample_signal(loads.get(a), self.t, f"load[{a}]")
                                  for a in range(self.n_a)])
        self.A, self.Bu, self.Bl = discretize_grid(grid, dt)
        # one control period at once: x_(k0+i) = A^i x + sum_(l<i) A^(i-1-l) (Bu u + Bl p_(k0+l))
        n = self.A.shape[0]
        powers = [np.eye(n)]
        for _ in range(ratio):
            powers.append(self.A @ powers[-1])
        self._free = np.vstack(powers[1:])                                  # (ratio n, n)
        self._held = np.vstack([sum(powers[:i]) @ self.Bu for i in range(1, ratio + 1)])
        self._loads = np.zeros((ratio * n, ratio * self.n_a))
        for i in range(1, ratio + 1):
            for k in range(i):
                self._loads[(i - 1) * n:i * n, k * self.n_a:(k + 1) * self.n_a] = \
                    powers[i - 1 - k] @ self.Bl
        self.inc = grid.incidence()
        self.limits, self.delays = relays.arrays()
        self.start, self.due = np.full((self.n_a, 3), np.nan), np.zeros((self.n_a, 3))
        for a in range(self.n_a):
            relay_sample(0.0, 0.0, 0.0, self.limits, self.delays, self.start[a], self.due[a])
        self.x = np.zeros(self.A.shape[0])
        self.xs = np.zeros((n_steps + 1, self.A.shape[0]))
        self.trips = np.zeros((n_steps + 1, self.n_a), np.int64)

    def ties(self, x: np.ndarray | None = None) -> np.ndarray:
        """Each area's tie-line export (pu) at the state ``x`` (default now)."""
        x = self.x if x is None else x
        return self.inc @ x[N_AREA_STATES * self.n_a:]

    def measured(self, j: int) -> np.ndarray:
        """What the generator sides read at control sample ``j`` (the state now):
        (n_areas, 8) in the order of :data:`lfc.testbed.loop.MEASURED` — the five
        states, the load, the tie-line export and their sum."""
        m = N_AREA_STATES
        tie = self.ties()
        load = self.p[j * self.ratio]
        if self.following:
            load = load + self._followed(j * self.ratio, self.x)
        return np.column_stack([self.x[:m * self.n_a].reshape(self.n_a, m), load, tie,
                                load + tie])

    def advance(self, j: int, u: np.ndarray, watch: bool = True) -> np.ndarray:
        """Hold the commands ``u`` (n_areas,; pu) for control period ``j``: the
        state and its record advance, and the relays unless ``watch`` is False;
        returns the relays that tripped in the period, as bits per area."""
        m, n = N_AREA_STATES, len(self.x)
        k0 = j * self.ratio
        steps = min(self.ratio, self.n_steps - k0)
        bits = np.zeros(self.n_a, np.int64)
        if steps <= 0:
            return bits
        with np.errstate(over="ignore", invalid="ignore"):   # non-finite: the caller refuses
            if self.following:                     # the load follows the state: step by step
                xs = np.zeros((steps, n))
                x = self.x
                for i in range(steps):
                    p = self.p[k0 + i] + self._followed(k0 + i, x)
                    x = xs[i] = self.A @ x + self.Bu @ u + self.Bl @ p
            else:
                loads = np.zeros(self.ratio * self.n_a)
                loads[:steps * self.n_a] = self.p[k0:k0 + steps].ravel()
                xs = (self._free @ self.x + self._held @ u + self._loads @ loads).reshape(-1, n)
        self.xs[k0 + 1:k0 + steps + 1] = xs[:steps]
        if watch:
            for k in range(k0 + 1, k0 + steps + 1):
                x = self.xs[k]
                for a in range(self.n_a):
                    self.trips[k, a] = relay_sample(k * self.dt, x[m * a + 3], x[m * a + 4],
                                                    self.limits, self.delays, self.start[a],
                                                    self.due[a])
                    bits[a] |= self.trips[k, a]
        self.x = xs[steps - 1].copy()
        return bits

    def _followed(self, k: int, x: np.ndarray) -> np.ndarray:
        """Each area's following load (pu) over plant step ``k`` from the state ``x``."""
        p = np.zeros(self.n_a)
        for a, botnet in self.following.items():
            p[a] = botnet.load(np.array([k * self.dt]), np.array([x[N_AREA_STATES * a + 3]]))[0]
        return p

    def loads(self) -> np.ndarray:
        """Each area's load at every step (n_steps + 1, n_areas; pu): its signal and its
        following load."""
        p = self.p.copy()
        states = self.states()
        for a, botnet in self.following.items():
            p[:, a] += botnet.load(self.t, states[:, a, 3])
        return p

    def trip_rows(self) -> list[pd.DataFrame]:
        """Each area's trips: one row per relay and instant (``relay``, ``t``)."""
        return [pd.DataFrame([(RELAY_NAMES[r], float(self.t[k]))
                              for k in np.flatnonzero(self.trips[:, a])
                              for r in range(3) if self.trips[k, a] >> r & 1],
                             columns=["relay", "t"]) for a in range(self.n_a)]

    def states(self) -> np.ndarray:
        """The areas' states at every step: (n_steps + 1, n_areas, 5)."""
        m = N_AREA_STATES
        return self.xs[:, :m * self.n_a].reshape(self.n_steps + 1, self.n_a, m)

    def exports(self) -> np.ndarray:
        """Each area's tie-line export at every step: (n_steps + 1, n_areas)."""
        return self.xs[:, N_AREA_STATES * self.n_a:] @ self.inc.T

    def result(self, single: bool, tc: np.ndarray, ctrl: list[np.ndarray], filters: dict,
               settings: dict):
        """The run as :func:`lfc.simulate` reports it (a :class:`~lfc.Result`, of one
        area if ``single``); ``tc`` the control samples, ``ctrl``
        each area's generator-side rows, ``filters`` each area's filter."""
        from lfc.model import STATES
        from lfc.result import area_result, grid_result
        states, trips = self.states(), self.trip_rows()
        if single:
            trace = pd.DataFrame({"t": self.t})
            for i, name in enumerate(STATES):
                trace[name] = states[:, 0, i]
            trace["p_load"] = self.loads()[:, 0]
            return area_result(trace, tc, ctrl[0], trips[0], filters.get(0), settings)
        return grid_result(self.grid, self.t, states, self.loads(), self.exports(), trips, tc,
                           ctrl, filters, settings)
