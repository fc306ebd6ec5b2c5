"""AGC and a filter at every area of an interconnected grid on ANDES:
:func:`simulate_andes_grid`, the testbed's :func:`lfc.simulate` (a grid).

The grid (:mod:`lfc.testbed.grid`: Kundur's two-area system or the IEEE
39-bus system) is an :class:`~lfc.testbed.loop.AndesPlant` (:class:`GridPlant`)
run by the one ANDES adapter, :class:`lfc.testbed.loop.AndesLoop`, with each
area's generator side (noise, estimator, filter and AGC on the area's ACE).
Each area's state in design-model coordinates (pu on the area base):

==============  ==========================================================
``dPg``         sum of the area's governor lags ``LAG_y`` (of the case's
                ``TGOV1`` or ``TGOV1N``) minus their initial values
``dPm``         sum of the area's turbine outputs ``pout`` minus theirs
``dw``          inertia-weighted mean rotor speed ``GENROU.omega − 1``
``dw_meas``     frequency of the area's meter bus ``BusFreq.f − 1``
``rocof_meas``  its ROCOF ``BusROCOF.Wf_y`` (pu/s)
``p_tie``       the area's tie-line export (power into the tie-lines at its
                end of them, computed from the bus voltage phasors) minus its
                initial value
``p_net``       the electrical output of the area's machines ``GENROU.Pe``
                minus its initial value: the area's net disturbance, given to
                its filter (``feedforward``)
==============  ==========================================================

Why ``p_net`` is metered at the machines and not summed as load plus tie-line
export (as the linear model defines it): the cases' loads are constant
impedance, so every voltage change moves them.  In the Kundur fit's load step
the generators' output differed from the stepped load plus export by half of
it (0.011 of 0.020 pu), and the model fitted on load plus export came out
with twice the true inertia; on the machines' output it finds the case's
inertia (:mod:`lfc.testbed.grid_fit`).

The area's command ``u`` is shared by its governors in proportion to their
machines' ratings ``Sn`` (equally in Kundur's system): machine ``k`` is to add
``u · Sn_k / Σ Sn`` pu of the area base to its power reference.  A ``TGOV1``
adds its ``paux0`` before the droop gain ``1/R``, so it gets ``R · u · scale ·
Sn_k / Σ Sn``; a ``TGOV1N`` adds it after the gain, so it gets ``u · scale ·
Sn_k / Σ Sn``.  The relays of each area read its meter bus.
"""

from __future__ import annotations

import inspect
import pickle
import struct
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from lfc._validate import check_count, check_flag, check_multiple, check_positive
from lfc.engine import (GeneratorSide, check_area_keys, check_attacks, check_coupled,
                        sample_signal)
from lfc.multiarea import MultiAreaParams
from lfc.relays import RelaySettings, relays_or_default
from lfc.simulate_multiarea import (MultiAreaResult, area_filter, estimate_noise,
                                    multiarea_result)
from lfc.testbed.grid import GridCase, build_grid
import lfc.testbed.stored_runs as stored_runs
from lfc.testbed.loop import AndesLoop, AndesPlant, GeneratorSides, TestbedError


def simulate_andes_grid(params: MultiAreaParams, *, duration: float,
                        attacks: dict | None = None, loads: dict | None = None,
                        filters: dict | None = None, relays: RelaySettings | None = None,
                        estimator=None, noise_std: tuple[float, float] = (0.0, 0.0),
                        seed: int = 0, control_period: float = 0.01, step: float = 0.005,
                        stop_on_trip: bool = False, feedforward: bool = True,
                        anti_windup: bool = False, case: GridCase | None = None,
                        plant: AndesPlant | None = None, network=None
                        ) -> MultiAreaResult:
    """Simulate an interconnected grid on ANDES with AGC and filters; the
    arguments and result of :func:`lfc.simulate` (a grid), plus the ones below.

    Parameters
    ----------
    params : MultiAreaParams
        The design model: each area's AGC gains and bias, the estimators'
        models and the filters named by kind (use
        :func:`lfc.testbed.grid_design` of ``case``, the model fitted to it).
    loads : dict, optional
        ``{area: signal}``: load change (pu of the area's base at nominal
        voltage), a constant-impedance load at the area's ``load_buses`` bus,
        updated every ANDES step.
    step : float
        ANDES time step (s); ``control_period`` must be a multiple of it.
    case : GridCase
        The grid; default ``GridCase.kundur()``.
    plant : AndesPlant, optional
        Instead of ``case``: any ANDES plant (:class:`lfc.testbed.loop.AndesPlant`)
        of ``params.n_areas`` areas; ``loads`` go to its ``set_load``.
    network : lfc.wire.link.Link, optional
        Every area's command channels arrive over a network
        (:func:`lfc.wire.run_wire`; no ``attacks``: the man in the middle attacks).

    Returns
    -------
    MultiAreaResult
        One trace row per accepted ANDES step.  Read back without ANDES from a
        run stored by an earlier call with the same arguments but ``filters``
        whose generator sides returned the same commands at every control
        sample (:mod:`lfc.testbed.stored_runs`: equal bit for bit; not with a
        ``network``, or ``LFC_ANDES_RUNS=off``).

    Raises
    ------
    ValueError
        Before anything runs, for a scenario the testbed cannot represent.
    TestbedError
        If ANDES does not converge (with the time and ANDES' reason).
    """
    call = locals()                         # the arguments, with their defaults
    return _run_stored(lambda: _setup(**call), *stored_runs.scenario_keys(call))[0]


@dataclass
class _Setup:
    """One scenario of :func:`simulate_andes_grid`, checked and ready to run: the
    plant, every area's generator side, and what its result records."""

    params: MultiAreaParams
    plant: AndesPlant
    loads: dict
    gens: list[GeneratorSide]
    relays: RelaySettings
    stop_on_trip: bool
    network: object
    duration: float
    step: float
    tc: np.ndarray
    built: dict
    settings: dict

    @property
    def shareable(self) -> bool:
        """Its run is a function of its commands and its plant-side inputs alone
        (:attr:`lfc.testbed.loop.AndesLoop.samples`): no network (whose link has
        a state of its own)."""
        return self.network is None


@dataclass
class _Shared:
    """What a finished run leaves for a run that differs from it only in its
    filters: its logged trace, its trips and its control samples (the row of the
    trace each read, the commands its generator sides returned)."""

    t: np.ndarray
    per_area: np.ndarray        # (rows, n_areas, 8): MEASURED
    trips: list
    read: np.ndarray            # (control samples run,): the row each sample read
    commands: np.ndarray        # (control samples run, n_areas), pu


def _setup(params: MultiAreaParams, *, duration: float, attacks, loads, filters, relays,
           estimator, noise_std, seed, control_period, step, stop_on_trip, feedforward,
           anti_windup, case, plant, network) -> _Setup:
    """:func:`simulate_andes_grid`'s checks, then its plant and generator sides."""
    if plant is not None and case is not None:
        raise ValueError("give case (a GridCase) or plant (an AndesPlant), not both")
    plant = plant if plant is not None else GridPlant(case or GridCase.kundur())
    if not isinstance(params, MultiAreaParams) or params.n_areas != plant.n_areas:
        raise ValueError(f"params must be a MultiAreaParams of {plant.n_areas} areas (the "
                         f"plant's), got {params!r}")
    if isinstance(plant, GridPlant):
        bases = {a.s_base_mva for a in params.areas}
        if bases != {plant.case.area_mva}:
            raise ValueError(f"params' areas are on {sorted(bases)} MVA, the case's on "
                             f"{plant.case.area_mva} MVA (area_mva): the commands and "
                             f"measurements would be scaled wrongly; give a design model on "
                             f"the case's base")
    check_positive("duration", duration)
    check_multiple("control_period", control_period, "step", step)
    relays = relays_or_default(relays)
    n_a = plant.n_areas
    attacks = check_attacks(attacks, n_a)
    loads = check_area_keys(loads, n_a, "loads")
    filters = check_area_keys(filters, n_a, "filters")
    for a, load in loads.items():
        sample_signal(load, np.arange(0.0, duration + step, step), f"loads[{a}]")
    estimate = estimate_noise(estimator, noise_std)
    built = {a: area_filter(params, a, f, relays, control_period, estimate)
             for a, f in filters.items()}
    check_coupled(built, params, estimator, noise_std)
    n_ctrl = int(np.ceil(duration / control_period - 1e-9))
    tc = np.arange(n_ctrl) * control_period
    k_freq, k_tie = params.agc_gains()
    gens = [GeneratorSide(area, built.get(a), estimator, noise_std, seed if a == 0 else (seed, a),
                          tc, attacks.get(a, {}).get("pc"), attacks.get(a, {}).get("wref"),
                          feedforward, control_period, ace_attack=attacks.get(a, {}).get("ace"),
                          k_agc=(float(k_freq[a]), float(k_tie[a])), anti_windup=anti_windup,
                          network=network is not None)
            for a, area in enumerate(params.areas)]
    settings = {"plant": "testbed", "case": repr(getattr(plant, "case", plant)),
                "params": repr(params),
                "relays": vars(relays), "duration": duration, "step": step,
                "control_period": control_period, "seed": seed, "noise_std": list(noise_std),
                "estimator": repr(estimator), "attacks": repr(attacks), "loads": repr(loads),
                "filters": {a: repr(f) for a, f in built.items()},
                "stop_on_trip": stop_on_trip, "feedforward": feedforward,
                "anti_windup": anti_windup}
    return _Setup(params, plant, loads, gens, relays, stop_on_trip, network, duration, step,
                  tc, built, settings)


def _run_stored(make: Callable[[], _Setup], share: bytes | None, key: str | None
                ) -> tuple[MultiAreaResult, _Shared | None, bool]:
    """The result of the setup ``make()`` builds, its run if it is shareable
    (else None), and whether ANDES ran: a run stored under ``key``
    (:mod:`lfc.testbed.stored_runs`; ``share``: the call's pickle) that its
    generator sides replay, or run on ANDES and stored (``key`` None: run, not
    stored)."""
    setup = make()
    if not setup.shareable:
        return _run(setup)[0], None, True
    if key is None:
        return (*_run(setup), True)
    for run in stored_runs.stored(key):
        result = _replay(setup, run)
        if result is not None:
            return result, run, False
        setup = make()                  # its generator sides have moved on: fresh ones
    result, run = _run(setup)
    stored_runs.store(key, run, run.commands.tobytes(), share,
                      {"case": getattr(getattr(setup.plant, "case", None), "name",
                                       type(setup.plant).__name__),
                       "duration": setup.duration})
    return result, run, True


def _run(setup: _Setup) -> tuple[MultiAreaResult, _Shared]:
    """Run ``setup`` on ANDES: its result, and what it leaves to share."""
    loop = AndesLoop(setup.plant, setup.loads, setup.gens, setup.relays, setup.stop_on_trip,
                     setup.network)
    loop.run(setup.duration, setup.step)
    rows = np.array(loop.rows)
    t = rows[:, 0].round(9)              # ANDES accumulates its time in floating point
    n_a = setup.plant.n_areas
    per_area = rows[:, 1:1 + 8 * n_a].reshape(len(rows), n_a, 8)   # then the plant's extra
    shared = _Shared(t, per_area, loop.trips(t),
                     np.array([k for k, _ in loop.samples], dtype=np.int64),
                     np.array([u for _, u in loop.samples]).reshape(-1, n_a))
    return _result(setup, shared), shared


def _result(setup: _Setup, run: _Shared) -> MultiAreaResult:
    """The result of ``setup``'s generator sides on the run ``run``."""
    per_area = run.per_area
    return multiarea_result(setup.params, run.t, per_area[:, :, :5], per_area[:, :, 5],
                            per_area[:, :, 6], run.trips, setup.tc,
                            [g.ctrl for g in setup.gens], setup.built, setup.settings,
                            p_net=per_area[:, :, 7])


def _replay(setup: _Setup, run: _Shared) -> MultiAreaResult | None:
    """``setup``'s result without running ANDES, if it is ``run``: its generator
    sides read ``run``'s control samples and return the same commands, bit for
    bit, at every one (then ANDES would integrate the same run: the plant, its
    loads, relays and times are the same,
    :func:`~lfc.testbed.stored_runs.scenario_keys`); None at the first command
    that differs (a filter that acts), or for a setup that is not shareable."""
    if not setup.shareable or len(run.read) != len(setup.tc) and not setup.stop_on_trip:
        return None
    sides = GeneratorSides(setup.gens)
    for j, (row, commands) in enumerate(zip(run.read, run.commands)):
        u = sides.sample(j, run.per_area[row])
        if not all(map(_same_float, u, commands)):
            return None
    return _result(setup, run)


def rerun(rec: stored_runs.Recording) -> _Shared:
    """A recording's run computed again on ANDES, fed the commands it holds at its
    control samples (no generator side computes them): what checks a recording
    (``tests/test_stored_runs.py``)."""
    setup = _setup(**pickle.loads(rec.call), filters=None)   # the committed call
    loop = AndesLoop(setup.plant, setup.loads, setup.gens, setup.relays, setup.stop_on_trip)
    loop.sides = _Recorded(rec.run.commands)
    loop.run(setup.duration, setup.step)
    rows = np.array(loop.rows)
    n_a = setup.plant.n_areas
    t = rows[:, 0].round(9)
    return _Shared(t, rows[:, 1:1 + 8 * n_a].reshape(len(rows), n_a, 8), loop.trips(t),
                   np.array([k for k, _ in loop.samples], dtype=np.int64),
                   np.array([u for _, u in loop.samples]).reshape(-1, n_a))


class _Recorded:
    """Generator sides that return recorded commands (:func:`rerun`)."""

    def __init__(self, commands: np.ndarray) -> None:
        self.commands = commands

    def sample(self, j: int, state: np.ndarray) -> np.ndarray:
        return self.commands[j].copy()


def _same_float(a: float, b: float) -> bool:
    """``a`` and ``b`` are the same float, bit for bit (0.0 is not -0.0)."""
    return struct.pack("<d", a) == struct.pack("<d", b)


class GridPlant:
    """An interconnected grid as an :class:`~lfc.testbed.loop.AndesPlant`
    (module docstring: what is metered, how a command is shared)."""

    def __init__(self, case: GridCase) -> None:
        self.case, self.n_areas = case, case.n_areas

    def build(self):
        return build_grid(self.case)

    def attach(self, ss) -> None:
        case = self.case
        gen, gov, bus = ss.GENROU, getattr(ss, case.governor), ss.Bus
        self.gov = gov
        self.gen_uid = [[gen.idx2uid(g) for g in gens] for gens in case.generators]
        self.gov_uid = [[list(gov.syn.v).index(g) for g in gens] for gens in case.generators]
        self.weights = [gen.M.v[u] / gen.M.v[u].sum() for u in map(np.array, self.gen_uid)]
        self.a_omega = gen.omega.a
        self.a_lag, self.a_pout = gov.LAG_y.a, gov.pout.a
        self.lag0 = ss.dae.x[self.a_lag].copy()
        self.pout0 = ss.dae.y[self.a_pout].copy()
        self.a_pe = gen.Pe.a
        self.pe0 = ss.dae.y[self.a_pe].copy()
        self.a_f = [ss.BusFreq.f.a[ss.BusFreq.idx2uid(f"F{i}")] for i in range(case.n_areas)]
        self.a_r = [ss.BusROCOF.Wf_y.a[ss.BusROCOF.idx2uid(f"R{i}")]
                    for i in range(case.n_areas)]
        omega = ss.dae.x[self.a_omega]
        if not (np.all(abs(omega - 1) < 1e-6) and np.all(abs(ss.dae.y[self.a_f] - 1) < 1e-6)):
            raise TestbedError("the testbed did not initialize at 1.0 pu frequency")
        # each governor's paux0 = before_droop * u * scale * share (module docstring)
        self.share = [gen.Sn.v[gu] / gen.Sn.v[gu].sum() for gu in self.gen_uid]
        self.before_droop = [gov.R.v[vu] if case.governor == "TGOV1" else np.ones(len(vu))
                             for vu in self.gov_uid]
        self.v_addr, self.ang_addr = bus.v.a, bus.a.a
        self.ls_uid = [ss.PQ.idx2uid(f"LS{i}") for i in range(case.n_areas)]
        self.ls_v0 = [float(bus.v.v[bus.idx2uid(b)]) for b in case.load_buses]
        area_of = dict(zip(bus.idx.v, bus.area.v))
        area_id = [area_of[gen.bus.v[u[0]]] for u in self.gen_uid]
        self.ties = []          # (area, bus uid at its end, other end's uid, 1/z, shunt)
        for name in case.tie_lines:
            k = ss.Line.idx2uid(name)
            ends = (ss.Line.bus1.v[k], ss.Line.bus2.v[k])
            areas = [area_id.index(area_of[b]) if area_of[b] in area_id else -1 for b in ends]
            if -1 in areas or areas[0] == areas[1]:
                raise ValueError(f"tie_lines: {name} does not join two of the case's areas")
            y = 1 / complex(ss.Line.r.v[k], ss.Line.x.v[k])
            sh = complex(ss.Line.g.v[k] / 2, ss.Line.b.v[k] / 2)
            for end in (0, 1):
                self.ties.append((areas[end], bus.idx2uid(ends[end]), bus.idx2uid(ends[1 - end]),
                                  y, sh))
        self.tie0 = self._export(ss)

    def _export(self, ss) -> np.ndarray:
        """Each area's tie-line export (pu of its base)."""
        v, a = ss.dae.y[self.v_addr], ss.dae.y[self.ang_addr]
        p = np.zeros(self.case.n_areas)
        for area, here, there, y, sh in self.ties:
            v1, v2 = v[here] * np.exp(1j * a[here]), v[there] * np.exp(1j * a[there])
            p[area] += (v1 * np.conj((v1 - v2) * y + v1 * sh)).real
        return p / self.case.scale

    def measure(self, ss, p_load: np.ndarray) -> np.ndarray:
        x, y = ss.dae.x, ss.dae.y
        s = self.case.scale
        out = np.zeros((self.case.n_areas, 8))
        for i, (gu, vu) in enumerate(zip(self.gen_uid, self.gov_uid)):
            out[i, 0] = (x[self.a_lag[vu]] - self.lag0[vu]).sum() / s
            out[i, 1] = (y[self.a_pout[vu]] - self.pout0[vu]).sum() / s
            out[i, 2] = self.weights[i] @ (x[self.a_omega[gu]] - 1.0)
            out[i, 3] = y[self.a_f[i]] - 1.0
            out[i, 4] = y[self.a_r[i]]
            out[i, 7] = (y[self.a_pe[gu]] - self.pe0[gu]).sum() / s
        out[:, 6] = self._export(ss) - self.tie0
        out[:, 5] = p_load
        return out

    def extra(self) -> tuple[float, ...]:
        return ()

    def protect(self, t: float) -> None:
        """No line protection in the grid cases."""

    def actuate(self, ss, area: int, u: float) -> None:
        self.gov.paux0.v[self.gov_uid[area]] = (self.before_droop[area] * u * self.case.scale
                                                * self.share[area])

    def set_load(self, ss, p_load: np.ndarray) -> None:
        for i, uid in enumerate(self.ls_uid):
            ss.PQ.Req.v[uid] = p_load[i] * self.case.scale / self.ls_v0[i] ** 2


def simulate_andes_grid_table(params: MultiAreaParams, scenarios: list[dict], *,
                              jobs: int = 2, progress: bool = True,
                              **common) -> list[MultiAreaResult]:
    """Many :func:`simulate_andes_grid` runs in ``jobs`` processes (ANDES holds the
    GIL), each scenario a dict of its keyword arguments, ``common`` the ones
    they share; the results in the scenarios' order.

    Scenarios that differ only in their ``filters`` share ANDES' work (and each
    reads back a run stored by an earlier call, as :func:`simulate_andes_grid`
    does): one of them runs (the one without filters, if there is one), and each
    other one's generator sides read that run's control samples; where they return the same
    commands at every sample (filters that never act: a legitimate load step),
    its result is that run with its own generator sides' records, equal bit for
    bit to running it, and ANDES is not run again.  Where a command differs,
    the scenario runs.  While a shared run is under way, a process that would
    otherwise wait runs one of the scenarios that wait on it, one per shared run
    (more would spend the CPU time sharing saves: measured on chapter 09's
    Kundur load step, where a second one ran the filter that would have shared).
    The progress bar counts the scenarios ANDES ran and those read back."""
    from concurrent.futures import ProcessPoolExecutor

    from tqdm.auto import tqdm

    check_count("jobs", jobs)
    check_flag("progress", progress)
    if not isinstance(scenarios, (list, tuple)) or not all(isinstance(s, dict)
                                                           for s in scenarios):
        raise ValueError(f"scenarios must be a list of dicts, got {scenarios!r}")
    calls = [{**common, **s} for s in scenarios]
    # each scenario's key to share a run in this table, and to read one back from disk
    keys, store_keys = map(list, zip(*(stored_runs.scenario_keys(_bound(params, kw))
                                       for kw in calls)))
    shares = list(keys)                  # the calls' pickles (keys[i] is cleared once used)
    leader = {}                          # a group's key -> the scenario that runs for it
    for i in sorted(range(len(calls)), key=lambda i: (bool(calls[i].get("filters")), i)):
        if keys[i] is not None:
            leader.setdefault(keys[i], i)
    out: list[MultiAreaResult | None] = [None] * len(calls)
    shared: dict[bytes, _Shared] = {}    # a finished leader's run
    speculated: set[bytes] = set()       # groups one of whose others started early
    todo = list(range(len(calls)))
    bar = tqdm(total=len(calls), unit="run", desc="simulate", disable=not progress)
    ran = [0, 0]                         # scenarios ANDES ran, scenarios read back

    def count(andes: bool) -> None:
        ran[0 if andes else 1] += 1
        bar.set_postfix_str(f"ANDES ran {ran[0]}, read back {ran[1]}", refresh=False)
        bar.update()

    def replay_ready() -> None:
        """Every waiting scenario whose leader has finished: its result from the
        leader's run, or it runs."""
        for i in [i for i in todo if keys[i] in shared and leader[keys[i]] != i]:
            result = _replay(_setup_call(params, calls[i]), shared[keys[i]])
            keys[i] = None               # it runs, or it is done
            if result is not None:
                out[i] = result
                todo.remove(i)
                count(andes=False)

    def next_run() -> int | None:
        """The next scenario to run: one that waits on no run, else (rather than
        a process idle) the first that waits on a run none of whose others has
        started; None: wait."""
        free = [i for i in todo if keys[i] is None or leader[keys[i]] == i]
        if free:
            i = free[0]
        else:
            i = next((i for i in todo if keys[i] not in speculated), None)
            if i is None:
                return None
            speculated.add(keys[i])
            keys[i] = None
        todo.remove(i)
        return i

    def finished(i: int, result: MultiAreaResult, run: _Shared | None, andes: bool) -> None:
        out[i] = result
        if keys[i] is not None and run is not None:
            shared[keys[i]] = run
        elif keys[i] is not None:        # nothing to share: the others of its group run
            for k in [k for k in todo if keys[k] == keys[i]]:
                keys[k] = None
        count(andes)

    if jobs == 1 or len(calls) <= 1:
        while todo:
            replay_ready()
            if todo:
                i = next_run()
                finished(i, *_run_call(params, calls[i], shares[i], store_keys[i],
                                       keys[i] is not None))
    else:
        from concurrent.futures import FIRST_COMPLETED, wait

        from lfc._pool import POLL
        with ProcessPoolExecutor(max_workers=min(jobs, len(calls))) as pool:
            running = {}
            while todo or running:
                replay_ready()
                while todo and len(running) < min(jobs, len(calls)):
                    i = next_run()
                    if i is None:
                        break
                    running[pool.submit(_run_call, params, calls[i], shares[i],
                                        store_keys[i], keys[i] is not None)] = i
                done, _ = wait(running, timeout=POLL, return_when=FIRST_COMPLETED)
                for future in done:
                    finished(running.pop(future), *future.result())
    bar.close()
    return out


def _setup_call(params: MultiAreaParams, call: dict) -> _Setup:
    """:func:`_setup` of a table's scenario: its keywords with the defaults of
    :func:`simulate_andes_grid`."""
    return _setup(**_bound(params, call))


def _bound(params: MultiAreaParams, call: dict) -> dict:
    """A table's scenario as the arguments of :func:`simulate_andes_grid`, with
    its defaults."""
    bound = inspect.signature(simulate_andes_grid).bind(params, **call)
    bound.apply_defaults()
    return bound.arguments


def _run_call(params: MultiAreaParams, call: dict, share: bytes | None, key: str | None,
              keep: bool) -> tuple[MultiAreaResult, _Shared | None, bool]:
    """Run a table's scenario (in a worker process), reading back a run stored
    under ``key`` (``share``: its call's pickle); what it leaves to share if
    ``keep`` and it is shareable; whether ANDES ran."""
    result, run, andes = _run_stored(lambda: _setup_call(params, call), share, key)
    return result, (run if keep else None), andes
