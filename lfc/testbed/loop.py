"""The one ANDES adapter: the generator sides in the loop of any ANDES case.

ANDES integrates the network (implicit trapezoidal, fixed ``step`` except
around events).  Before every step it calls back into :class:`AndesLoop`,
which logs the last accepted state, runs the case's protection and the
frequency relays, and, when a control sample is due, hands every area's
generator side (:class:`lfc.generator.GeneratorSide`: noise, estimator, AGC or
local integrator, attacks, filter — the engine's own compiled code) the area's
state in design-model coordinates, and applies the command it returns.

A case plugs in as an :class:`AndesPlant`: it builds its ANDES system, meters
each area (:meth:`AndesPlant.measure`), applies commands and load changes, and
may protect its lines.  The microgrid (:mod:`lfc.testbed.microgrid`) and the
interconnected grids (:mod:`lfc.testbed.grids`) are the two today; a new
ANDES case is one such class.
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path
from typing import Protocol

import numpy as np
import pandas as pd

from lfc._validate import check_flag
from lfc.engine import sample_signal
from lfc.filters.coupled import CoupledFilter
from lfc.generator import GeneratorSide, GridReading
from lfc.relays import RelayBank, RelaySettings
from lfc.testbed.andes_setup import quiet_load

# columns of AndesPlant.measure, per area
MEASURED = ("dPg", "dPm", "dw", "dw_meas", "rocof_meas", "p_load", "p_tie", "p_net")
_METER = MEASURED.index("dw_meas")     # what a following load reads

#: An environment variable naming a file to which every ANDES run appends, as one
#: line, the CPU seconds ANDES itself took (its process's, so runs in parallel
#: on shared cores are not counted twice): loading and setting up the case,
#: initializing and stepping it, but not :class:`AndesLoop`'s per-step callback
#: (the meters, relays and generator sides).  ``python -m lfc reproduce`` sets it
#: for each notebook run, to report ANDES' share of the time (the run's floor).
CLOCK_ENV = "LFC_ANDES_CLOCK"


def record_andes_seconds(seconds: float) -> None:
    """Append ``seconds`` (s) to the file :data:`CLOCK_ENV` names, if it names one
    (one short line per write: processes that share the file do not interleave)."""
    path = os.environ.get(CLOCK_ENV)
    if path:
        with open(path, "a", encoding="ascii") as clock:
            clock.write(f"{seconds:.6f}\n")


class TestbedError(RuntimeError):
    """ANDES failed during a run (the message says when and why)."""

    __test__ = False  # not a pytest test class


class Stop(Exception):
    """Raised inside the ANDES callback to end a run early (a relay tripped)."""


class RunComplete(Stop):
    """Raised inside the ANDES callback when all that is left of the run is a
    sliver of a step (below ``SLIVER`` s) that ANDES' accumulated time left
    before the end: the run is complete (see :meth:`AndesLoop._callback`)."""


#: s: a step attempt shorter than this at the end of a run is ANDES' floating-point
#: remainder, not a step: 0.005 s added 320 times falls 2e-16 s short of 1.6 s, and
#: ANDES then integrates those 2e-16 s; with the IEEE 39-bus system's stabilizers
#: (an input filter whose time constants are 0) Newton's method fails on a step that
#: short, and the run was reported as not converged (``tests/test_grids.py``: attacked
#: runs of 1.6 and 1.605 s).
SLIVER = 1e-9


class BreakerOpens(Stop):
    """Raised by a case's protection in a first pass, when its breaker opens."""


class AndesPlant(Protocol):
    """What an ANDES case gives :class:`AndesLoop`.

    ``n_areas`` areas, each with a generator side; every quantity in pu of the
    area's base (design-model coordinates).
    """

    n_areas: int

    def build(self):
        """A fresh ANDES system of the case (set up, not initialized)."""

    def attach(self, ss) -> None:
        """Find the addresses of what :meth:`measure` reads in the initialized
        ``ss``; raise :class:`TestbedError` if it did not start at 1 pu frequency."""

    def measure(self, ss, p_load: np.ndarray) -> np.ndarray:
        """Each area's state now, (n_areas, 8) in the order of ``MEASURED``:
        the design-model state, the load ``p_load`` applied (pu), the tie-line
        export and the net disturbance the filter is given (pu)."""

    def extra(self) -> tuple[float, ...]:
        """The case's own trace columns at the last :meth:`measure` (may be empty)."""

    def protect(self, t: float) -> None:
        """The case's line protection after a measurement at ``t`` (s); may
        raise :class:`BreakerOpens`."""

    def actuate(self, ss, area: int, u: float) -> None:
        """Hold the command ``u`` (pu) at ``area``'s governors."""

    def set_load(self, ss, p_load: np.ndarray) -> None:
        """Apply each area's load change ``p_load`` (pu, at nominal voltage)."""


def init_tds(ss, duration: float, step: float) -> None:
    """Configure ANDES' time-domain run of ``ss`` (to ``duration`` at ``step``,
    s; quiet, no line search, no stored history: the callback logs) and
    initialize it."""
    cfg = ss.TDS.config
    cfg.tf, cfg.tstep, cfg.no_tqdm, cfg.criteria = duration, step, 1, 0
    cfg.linesearch, cfg.save_every = 0, 0
    case = Path(ss.files.case).stem if ss.files.case else "the microgrid"
    with quiet_load(case, "time-domain initialization"):
        ss.TDS.init()


def run_tds(ss, duration: float, callback) -> float:
    """Run the initialized ``ss`` with ``callback(t, system)`` before every step
    attempt; return the end time (s), or raise :class:`TestbedError` with ANDES'
    reason if it stopped before ``duration``."""
    ss.TDS.callpert = callback
    ss.TDS.run(no_summary=True)
    t_end = float(ss.dae.t)
    if ss.TDS.busted or t_end < duration - 1e-9:
        raise TestbedError(f"ANDES did not converge at t = {t_end:.4f} s: "
                           f"{ss.TDS.err_msg or 'the run ended early'}")
    return t_end


class AndesLoop:
    """One ANDES run of ``plant`` with every area's generator side in its
    per-step callback.

    Parameters
    ----------
    plant : AndesPlant
    loads : dict
        ``{area: signal}``: each area's load change (pu), updated every ANDES step.
    gens : list of GeneratorSide
        One per area, sharing the control sample times.
    relays : RelaySettings
        Every area's frequency and ROCOF relays.
    stop_on_trip : bool
        End the run at the first trip (:attr:`stopped`); else the relays are
        applied to the logged trace afterwards (:meth:`trips`).
    network : lfc.wire.link.Link, optional
        The commands arrive over a network (:mod:`lfc.wire`): at each control
        sample the control centre writes them, each generator side (built with
        ``network=True``) receives what arrived, and the reports go back (their
        trip bits 0: on ANDES the relays are applied to the logged trace).
    following : dict, optional
        ``{area: FollowingLoad}`` (:mod:`lfc.load_attacks`): a botnet's load added to
        the area's, from its frequency meter (``dw_meas``) at the last accepted
        step, held over the next (as the linear engine holds it over a plant step).

    Attributes
    ----------
    rows : list of list
        One per accepted ANDES step: ``t``, each area's ``MEASURED`` values,
        then the plant's :meth:`~AndesPlant.extra` columns.
    stopped : tuple or None
        ``(found, t)`` when the relays ended the run: :meth:`RelayBank.update`'s
        trips and the time (s, rounded to 1 ns as the trace).
    samples : list of (int, ndarray)
        One per control sample run: the index in :attr:`rows` of the state the
        generator sides read, and the commands they returned (n_areas,; pu).
        The run is a function of these commands and of its plant, loads, relays
        and times alone: a run whose generator sides return the same commands
        at every sample is this run
        (:func:`lfc.testbed.grids.simulate_andes_grid_table` shares it, and
        :mod:`lfc.testbed.stored_runs` keeps it on disk).
    """

    def __init__(self, plant: AndesPlant, loads: dict, gens: list[GeneratorSide],
                 relays: RelaySettings, stop_on_trip: bool, network=None,
                 following: dict | None = None) -> None:
        self.plant, self.loads, self.gens, self.relays = plant, loads, gens, relays
        self.following = following or {}
        self.bank = (RelayBank(relays, plant.n_areas)
                     if check_flag("stop_on_trip", stop_on_trip) else None)
        t0 = time.process_time()
        self.ss = plant.build()
        self._andes_seconds = time.process_time() - t0    # ANDES' own, reported by run
        self._callback_seconds = 0.0
        self.rows: list[list[float]] = []
        self.stopped: tuple | None = None
        self.samples: list[tuple[int, np.ndarray]] = []
        self.next_j = 0
        self.sides = GeneratorSides(gens, network)
        self._load_at = (math.nan, np.zeros(plant.n_areas))

    def run(self, duration: float, step: float) -> bool:
        """Integrate to ``duration``; return True if the plant's protection
        ended a first pass (:class:`BreakerOpens`)."""
        t0 = time.process_time()
        try:
            try:
                init_tds(self.ss, duration, step)
                self.plant.attach(self.ss)
                t_end = run_tds(self.ss, duration, self._callback)
            finally:                # to the end, or to where a trip or breaker stopped it
                self._andes_seconds += time.process_time() - t0 - self._callback_seconds
                record_andes_seconds(self._andes_seconds)
            self._log(t_end)        # the final accepted state
        except BreakerOpens:
            return True
        except Stop:
            pass
        return False

    def trips(self, t: np.ndarray) -> list[pd.DataFrame]:
        """Each area's relay trips (``relay``, ``t`` in s, in time order): those
        that ended the run, or, without ``stop_on_trip``, the relays applied to
        the logged measurements at the rows' times ``t`` (s, rounded)."""
        n = self.plant.n_areas
        if self.stopped is not None:
            found, t_stop = self.stopped
            return _by_area(found, np.array([t_stop]), n)
        if self.bank is not None:
            return _by_area([], t, n)
        per_area = np.array(self.rows)[:, 1:1 + 8 * n].reshape(len(self.rows), n, 8)
        found = RelayBank(self.relays, n).update(t, per_area[:, :, 3], per_area[:, :, 4])
        return _by_area(found, t, n)

    def _p_load(self, t: float) -> np.ndarray:
        """Each area's dP_L at ``t`` (pu); the callback asks for each step's end
        time, and the log for the same time one call later, so the last value
        is kept."""
        if t != self._load_at[0]:
            p = np.zeros(self.plant.n_areas)
            for a, load in self.loads.items():
                p[a] = float(sample_signal(load, np.array([t]), f"loads[{a}]")[0])
            for a, botnet in self.following.items():     # its meter at the last step
                meter = self.rows[-1][1 + len(MEASURED) * a + _METER] if self.rows else 0.0
                p[a] += float(botnet.load(t, meter))
            self._load_at = (t, p)
        return self._load_at[1]

    def _callback(self, t_attempt, system) -> None:
        t0 = time.process_time()
        try:
            t_next, h = float(t_attempt), float(self.ss.TDS.h)
            self._log(max(t_next - h, 0.0))
            if h < SLIVER and t_next >= self.ss.TDS.config.tf - SLIVER:
                raise RunComplete       # the end is logged: the sliver would change nothing
            self.plant.set_load(self.ss, self._p_load(t_next))
        finally:
            self._callback_seconds += time.process_time() - t0

    def _log(self, t: float) -> None:
        """Record the accepted state at ``t`` (once), protect, check the relays,
        and control if due."""
        if self.rows and t <= self.rows[-1][0] + 1e-9:
            return
        state = self.plant.measure(self.ss, self._p_load(t))
        self.rows.append([t, *state.ravel(), *self.plant.extra()])
        self.plant.protect(t)
        if self.bank is not None:
            found = self.bank.update(np.array([t]), state[None, :, 3], state[None, :, 4])
            if found:
                self.stopped = (found, round(t, 9))
                raise Stop
        tc = self.gens[0].tc
        while self.next_j < len(tc) and tc[self.next_j] <= t + 1e-7:
            u = self.sides.sample(self.next_j, state)
            for a in range(self.plant.n_areas):
                self.plant.actuate(self.ss, a, u[a])
            self.samples.append((len(self.rows) - 1, u))
            self.next_j += 1


class GeneratorSides:
    """Every area's generator side at the control samples of a run: on ANDES
    (:class:`AndesLoop`), or replaying a logged run's samples without it
    (:func:`lfc.testbed.grids.simulate_andes_grid_table`, the stored runs).

    Parameters
    ----------
    gens : list of GeneratorSide
        One per area, sharing the control sample times.
    network : lfc.wire.link.Link, optional
        The commands travel over it (:class:`AndesLoop`).
    """

    def __init__(self, gens: list[GeneratorSide], network=None) -> None:
        self.gens, self.network = gens, network
        self.commands = np.zeros(len(gens))   # each area's latest command (pu)
        scc = gens[0].scc
        self.coupled = scc if isinstance(scc, CoupledFilter) else None
        self._kalman: tuple | None = None   # a coupled filter's estimator: measurements,
                                            # scratch, state (:meth:`_estimate`)

    def sample(self, j: int, state: np.ndarray) -> np.ndarray:
        """Run control sample ``j`` on the areas' ``state`` ((n_areas, 8) in the
        order of ``MEASURED``); return every area's command (pu, a new array).
        A coupled filter reads the grid's state as its design model sees it and
        the commands of the areas before it at this sample, of the others at the
        last one."""
        grid = None
        coupled = self.coupled
        if coupled is not None:
            grid = GridReading(0, coupled.grid_state(state[:, :5], state[:, 6]), self.commands,
                               state[:, 5], *self._estimate(coupled, state, j))
        net = self.network
        if net is not None:
            net.send(j)
            links = net.deliver(j, self.gens)
        for a, gen in enumerate(self.gens):
            self.commands[a] = gen.step(j, state[a, :5], state[a, 7], state[a, 6],
                                        None if grid is None else grid._replace(area=a))
        if net is not None:
            for a, gen in enumerate(self.gens):
                net.publish(j, a, gen, state[a, :5], links[a], 0)
            net.read(j)
        return self.commands.copy()

    def _estimate(self, coupled: CoupledFilter, state: np.ndarray, j: int) -> tuple:
        """What a coupled filter on its grid Kalman estimate reads at control sample
        ``j`` besides the grid (:meth:`lfc.generator.GeneratorSide.step`): each area's
        ``dw_meas`` and ``rocof_meas`` as its sensors report them (its generator side's
        noise and any attack on them: :meth:`~lfc.generator.GeneratorSide.reports`),
        each area's metered export, the scratch, and the estimator's state, kept
        across samples; nothing without the estimate."""
        if coupled.kalman is None:
            return ()
        n_a = len(self.gens)
        if self._kalman is None:
            self._kalman = (np.zeros(6 * n_a), np.zeros(coupled.params.n_states),
                            np.zeros((2, coupled.kalman.n)))
        ym = self._kalman[0]
        for a, gen in enumerate(self.gens):
            ym[2 * a:2 * a + 2] = gen.reports(j, state[a, 3:5])
            ym[2 * n_a + a] = state[a, 6]
        return self._kalman


class RecordedSides:
    """Generator sides that return recorded commands, one row of ``commands`` (one
    command per area, pu) per control sample: a recording computed again on ANDES
    (:func:`lfc.testbed.grids.rerun`, :func:`lfc.testbed.microgrid.rerun`)."""

    def __init__(self, commands: np.ndarray) -> None:
        self.commands = commands

    def sample(self, j: int, state: np.ndarray) -> np.ndarray:
        """Control sample ``j``'s recorded commands (a new array); ``state`` is unread."""
        return self.commands[j].copy()


def _by_area(found: list[tuple[str, int, int]], t: np.ndarray, n_areas: int
             ) -> list[pd.DataFrame]:
    """:meth:`RelayBank.update`'s trips (relay, sample, area) as one table of
    ``relay``, ``t`` per area, in time order."""
    return [pd.DataFrame([(r, float(t[k])) for r, k, j in found if j == a],
                         columns=["relay", "t"]) for a in range(n_areas)]
