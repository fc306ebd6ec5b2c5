"""Interconnected grids on ANDES: the case description, its builder, the design
model its data imply, and AGC and a filter at every area (:func:`simulate_andes_grid`,
the testbed's :func:`lfc.simulate` of a grid).

Two cases that ANDES ships are described (:meth:`GridCase.kundur`,
:meth:`GridCase.ieee39`); any case whose machines are ``GENROU`` with
``TGOV1`` or ``TGOV1N`` governors can be described the same way.

**Kundur's two-area system** (Kundur 1994, Example 12.6; Klein, Rogers and
Kundur 1991), ``kundur/kundur_full.xlsx``: four 900 MVA round-rotor machines
(H = 6.5 s in area 1, 6.175 s in area 2) with TGOV1 governors (5 % droop,
T1 = 0.49 s, turbine lead-lag T2 = 2.1 s over T3 = 7 s) and EXDC2 exciters,
two machines per area, 1159 MW of load in area 1 and 1575 MW in area 2, and
three 230 kV tie-lines from bus 7 to bus 8 carrying about 400 MW from area 1
to area 2.  ANDES numbers its buses 1-10 and names them as Kundur's figure
does::

    G1 (1) -- 5 (101) -- 6 (102) -- 7 (3) ===== 8 (13) -- 9 (112) -- 10 (111) -- G4 (4)
                          |                                  |
                        G2 (2)                             G3 (3)

**The IEEE 39-bus system** (New England; Athay, Podmore and Virmani 1979),
``ieee39/ieee39_full.xlsx``: ten GENROU machines with TGOV1N governors
(5 % droop, T1 = 0.05 s, turbine lead-lag T2 = 1 s over T3 = 2.1 s), IEEEX1
exciters and IEEEST stabilizers.  The case defines **two areas** (ANDES'
``Area`` 1 "WEST", 2 "EAST"), not three: machines 1, 2, 3, 8 and 10 (10, at
bus 39, is the equivalent of the external New York system: 1199 MVA, H = 50
s) against 4, 5, 6, 7 and 9, joined by five lines (4-14, 13-14, 16-17, 26-28,
26-29).  This package keeps the case's two areas (the issue asked for three;
the case has two).

What :func:`build_grid` changes in a case, and why:

* the case's own disturbances (``Toggle`` events: Kundur's line trip at 2 s;
  the 39-bus case's, already off) are switched off; scenarios bring their own;
* one ``BusFreq`` and one ``BusROCOF`` per area at its ``meter_buses`` bus:
  the frequency and ROCOF the area's relays, filter and AGC read (lags as in
  the microgrid, :class:`MicrogridCase`);
* one zero ``PQ`` load per area at its ``load_buses`` bus that carries
  load-step scenarios.

The AGC is not in the cases: each area's AGC is the engine's generator side
(:class:`lfc.generator.GeneratorSide`), whose command goes through the area's
filter and is shared by the area's governors in proportion to their ratings
(below).

Per unit.  ANDES keeps the cases' 100 MVA system base (their powers are
stored on it).  Everything this package reads or writes is in pu on the
**area base** ``area_mva``, one for every area (so that tie-line
coefficients are symmetric): 1800 MVA for Kundur (each area's two
machines), 5000 MVA for the 39-bus system (its areas' machines are rated
4889 and 6050 MVA); :attr:`GridCase.scale` converts.

**AGC and a filter at every area.** The grid (Kundur's two-area system or the IEEE
39-bus system) is an :class:`~lfc.testbed.loop.AndesPlant`
(:class:`GridPlant`) run by the one ANDES adapter, :class:`lfc.testbed.loop.AndesLoop`,
with each area's generator side (noise, estimator, filter and AGC on the area's ACE).
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
inertia (:mod:`lfc.testbed.fit`).

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
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import lfc.testbed.stored_runs as stored_runs
from lfc._validate import (ParameterTypeError, check_count, check_flag, check_multiple,
                           check_positive)
from lfc.engine import SENSOR_CHANNELS, check_area_keys, check_attacks, sample_signal
from lfc.filters.coupled import check_coupled
from lfc.generator import GeneratorSide
from lfc.linear_grid import area_filter, estimate_noise
from lfc.load_attacks import FollowingLoad
from lfc.model import LFCParams
from lfc.multiarea import MultiAreaParams
from lfc.relays import RelaySettings, relays_or_default
from lfc.result import Result, grid_result
from lfc.scenarios import check_sensed
from lfc.testbed.loop import AndesLoop, AndesPlant, GeneratorSides, RecordedSides, TestbedError

GOVERNORS = ("TGOV1", "TGOV1N")


@dataclass(frozen=True)
class GridCase:
    """An interconnected grid as the testbed runs it (pu on ``area_mva``, s);
    the defaults are Kundur's two-area system (:meth:`kundur`).

    Parameters
    ----------
    name : str
        Short name, used in file names (``kundur_fit.md``).
    case_file : str
        The ANDES case (``andes.get_case`` path).
    area_mva : float
        Per-unit base of every area's model (MVA).
    system_mva : float
        The case's system base (MVA): ANDES stores its powers on it.
    f_nominal : float
        Nominal frequency (Hz).
    generators : tuple of tuple
        ANDES ``GENROU`` idx of each area's machines (area 0 first).
    governor : str
        The machines' governor model, ``"TGOV1"`` (the command enters before
        the droop gain) or ``"TGOV1N"`` (after it).
    meter_buses : tuple of int
        The bus whose frequency and ROCOF each area reads.
    load_buses : tuple of int
        Where ``loads[i]`` adds its constant-impedance load.
    tie_lines : tuple of str
        The lines between the areas (their power at each area's end is the
        area's tie-line export).
    tau_w, tau_washout, tau_rocof : float
        ``BusFreq`` lag and washout, ``BusROCOF`` lag (s).
    """

    name: str = "kundur"
    case_file: str = "kundur/kundur_full.xlsx"
    area_mva: float = 1800.0
    system_mva: float = 100.0
    f_nominal: float = 60.0
    generators: tuple[tuple[int | str, ...], ...] = ((1, 2), (3, 4))
    governor: str = "TGOV1"
    meter_buses: tuple[int, ...] = (6, 9)
    load_buses: tuple[int, ...] = (7, 8)
    tie_lines: tuple[str, ...] = ("Line_4", "Line_5", "Line_6")
    tau_w: float = 0.02
    tau_washout: float = 0.02
    tau_rocof: float = 0.05

    def __post_init__(self) -> None:
        for name in ("area_mva", "system_mva", "f_nominal", "tau_w", "tau_washout",
                     "tau_rocof"):
            check_positive(name, getattr(self, name))
        n = len(self.generators)
        if n < 2 or len(self.meter_buses) != n or len(self.load_buses) != n:
            raise ValueError("generators, meter_buses and load_buses must name the same "
                             f"number (>= 2) of areas, got {len(self.generators)}, "
                             f"{len(self.meter_buses)}, {len(self.load_buses)}")
        if not all(self.generators):
            raise ValueError(f"generators must name at least one machine per area, got "
                             f"{self.generators!r}")
        seen: dict = {}
        for a, machines in enumerate(self.generators):
            for m in machines:
                if m in seen:
                    raise ValueError(f"generators names machine {m!r} in area {seen[m]} and "
                                     f"area {a}: each machine belongs to one area")
                seen[m] = a
        if self.governor not in GOVERNORS:
            raise ValueError(f"governor must be one of {GOVERNORS}, got {self.governor!r}")
        if not self.tie_lines:
            raise ValueError("tie_lines must name at least one line")

    @classmethod
    def kundur(cls) -> GridCase:
        """Kundur's two-area system (module docstring): meters at buses 6 and 9,
        between each area's machines and the tie; load steps at the tie's ends,
        buses 7 and 8."""
        return cls()

    @classmethod
    def ieee39(cls) -> GridCase:
        """The IEEE 39-bus system in the case's two areas (module docstring):
        area 0 is the case's WEST (machines 1, 2, 3, 8 and the external
        system's 10; M 28.9 s on 5000 MVA), area 1 its EAST (machines 4, 5, 6,
        7, 9; M 7.4 s), the lighter one.  Meters at bus 2 (west, between
        machine 1 and the external system's bus 39) and bus 19 (east, between
        machines 4 and 5 and the tie's bus 16); load steps at buses 4 and 16,
        the ends of tie-lines 4-14 and 16-17."""
        return cls(name="ieee39", case_file="ieee39/ieee39_full.xlsx", area_mva=5000.0,
                   generators=(("GENROU_1", "GENROU_2", "GENROU_3", "GENROU_8", "GENROU_10"),
                               ("GENROU_4", "GENROU_5", "GENROU_6", "GENROU_7", "GENROU_9")),
                   governor="TGOV1N", meter_buses=(2, 19), load_buses=(4, 16),
                   tie_lines=("Line_8", "Line_18", "Line_21", "Line_32", "Line_33"))

    @property
    def n_areas(self) -> int:
        return len(self.generators)

    @property
    def scale(self) -> float:
        """System-base pu per area-base pu (18 for 1800 over 100 MVA)."""
        return self.area_mva / self.system_mva


def case_design(case: GridCase) -> MultiAreaParams:
    """The linear model the case's data imply (the fit's start), on the area
    base: each area's inertia the sum of its machines', its droop their
    parallel droops, its governor lag and turbine lag the governors' mean
    ``T1`` and ``T3``, a small load damping (the loads are constant
    impedance), the meters' lags, and a unit tie-line coefficient (the fit
    finds it).

    Raises
    ------
    ValueError
        As :func:`build_grid`.
    """
    ss = build_grid(case)
    gen, gov = ss.GENROU, getattr(ss, case.governor)
    areas = []
    for machines in case.generators:
        g = [gen.idx2uid(m) for m in machines]
        v = [list(gov.syn.v).index(m) for m in machines]
        areas.append(LFCParams(M=float(gen.M.v[g].sum()) / case.scale,
                               D=0.5, droop=case.scale / float((1 / gov.R.v[v]).sum()),
                               tau_g=float(np.mean(gov.T1.v[v])),
                               tau_t=float(np.mean(gov.T3.v[v])), tau_w=case.tau_w,
                               tau_rocof=case.tau_rocof, k_i=2.0, f_nominal=case.f_nominal,
                               s_base_mva=case.area_mva))
    return MultiAreaParams(areas=tuple(areas), tie=((0, 1, 1.0),))


def build_grid(case: GridCase):
    """Load, modify (module docstring), set up and solve the power flow.

    Returns
    -------
    andes.System
        With ``BusFreq`` ``F{i}``, ``BusROCOF`` ``R{i}`` and zero ``PQ``
        ``LS{i}`` for each area ``i``.

    Raises
    ------
    ValueError
        If a bus, machine, governor or line of ``case`` is not in the ANDES
        case, or a machine has no governor of the case's model.
    RuntimeError
        If the power flow does not converge.
    """
    from lfc.testbed.andes_setup import prepare_andes, quiet_load

    prepare_andes()
    with quiet_load(Path(case.case_file).stem, "loading"):
        return _build(case)


def _build(case: GridCase):
    """:func:`build_grid`'s work, its ANDES warnings collected."""
    import andes

    ss = andes.load(andes.get_case(case.case_file), setup=False, no_output=True,
                    default_config=True)
    buses = set(ss.Bus.idx.v)
    for name, group in (("meter_buses", case.meter_buses), ("load_buses", case.load_buses)):
        for bus in group:
            if bus not in buses:
                raise ValueError(f"{name} names bus {bus!r}, not in {case.case_file} "
                                 f"(buses {sorted(buses)})")
    for i, (meter, load) in enumerate(zip(case.meter_buses, case.load_buses)):
        ss.add("BusFreq", dict(idx=f"F{i}", bus=meter, Tf=case.tau_w, Tw=case.tau_washout,
                               fn=case.f_nominal))
        ss.add("BusROCOF", dict(idx=f"R{i}", bus=meter, Tf=case.tau_w, Tw=case.tau_washout,
                                Tr=case.tau_rocof, fn=case.f_nominal))
        ss.add("PQ", dict(idx=f"LS{i}", bus=load, Vn=float(_bus_kv(ss, load)), p0=0.0, q0=0.0))
    ss.setup()
    machines = set(ss.GENROU.idx.v)
    governed = set(getattr(ss, case.governor).syn.v)
    for gens in case.generators:
        for g in gens:
            if g not in machines:
                raise ValueError(f"generators names machine {g!r}, not in {case.case_file} "
                                 f"(GENROU {sorted(machines, key=str)})")
            if g not in governed:
                raise ValueError(f"generators names machine {g!r}, which has no "
                                 f"{case.governor} governor in {case.case_file} (governor)")
    lines = set(ss.Line.idx.v)
    for name in case.tie_lines:
        if name not in lines:
            raise ValueError(f"tie_lines names {name!r}, not a line of {case.case_file}")
    if ss.Toggle.n:                     # the case's own events: off, and never due
        ss.Toggle.u.v[:] = 0.0          # (ANDES steps onto every event time)
        ss.Toggle.t.v[:] = 1e9
    ss.PFlow.run()
    if not ss.PFlow.converged:
        raise RuntimeError(f"ANDES power flow of {case.case_file} did not converge")
    return ss


def _bus_kv(ss, bus: int) -> float:
    """Nominal voltage (kV) of ``bus`` in a system not yet set up."""
    return float(ss.Bus.Vn.v[list(ss.Bus.idx.v).index(bus)])


def simulate_andes_grid(params: MultiAreaParams, *, duration: float,
                        attacks: dict | None = None, loads: dict | None = None,
                        following_loads: dict | None = None,
                        filters: dict | None = None, relays: RelaySettings | None = None,
                        estimator=None, noise_std: tuple[float, float] = (0.0, 0.0),
                        seed: int = 0, control_period: float = 0.01, step: float = 0.005,
                        stop_on_trip: bool = False, feedforward: bool = True,
                        anti_windup: bool = False, case: GridCase | None = None,
                        plant: AndesPlant | None = None, network=None
                        ) -> Result:
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
    following_loads : dict, optional
        ``{area: FollowingLoad}`` (:mod:`lfc.load_attacks`): a botnet's load at the
        same bus, following the area's frequency meter, held over each ANDES step
        from the meter at its start (:class:`lfc.testbed.loop.AndesLoop`).
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
    Result
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
    following: dict

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
           anti_windup, case, plant, network, following_loads=None) -> _Setup:
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
    check_sensed(attacks, filters, estimator)
    for a, load in loads.items():
        sample_signal(load, np.arange(0.0, duration + step, step), f"loads[{a}]")
    following = check_area_keys(following_loads, n_a, "following_loads")
    for a, botnet in following.items():
        if not isinstance(botnet, FollowingLoad):
            raise ParameterTypeError(f"following_loads[{a}] must be a FollowingLoad "
                                     f"(lfc.load_attacks), got {botnet!r:.80}")
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
                          network=network is not None,
                          sensor_attacks={c: attacks[a][c] for c in SENSOR_CHANNELS
                                          if attacks.get(a, {}).get(c) is not None})
            for a, area in enumerate(params.areas)]
    settings = {"plant": "testbed", "case": repr(getattr(plant, "case", plant)),
                "params": repr(params),
                "relays": vars(relays), "duration": duration, "step": step,
                "control_period": control_period, "seed": seed, "noise_std": list(noise_std),
                "estimator": repr(estimator), "attacks": repr(attacks), "loads": repr(loads),
                "following_loads": repr(following),
                "filters": {a: repr(f) for a, f in built.items()},
                "stop_on_trip": stop_on_trip, "feedforward": feedforward,
                "anti_windup": anti_windup}
    return _Setup(params, plant, loads, gens, relays, stop_on_trip, network, duration, step,
                  tc, built, settings, following)


def _run_stored(make: Callable[[], _Setup], share: bytes | None, key: str | None
                ) -> tuple[Result, _Shared | None, bool]:
    """The result of the setup ``make()`` builds, its run if it is shareable
    (else None), and whether ANDES ran: a run stored under ``key``
    (:mod:`lfc.testbed.stored_runs`; ``share``: the call's pickle) that its
    generator sides replay, or run on ANDES and stored (``key`` None: run, not
    stored)."""
    setup = make()
    if not setup.shareable or key is None:
        run = _run(setup)
        return _result(setup, run), (run if setup.shareable else None), True
    for run in stored_runs.stored(key):
        result = _replay(setup, run)
        if result is not None:
            return result, run, False
        setup = make()                  # its generator sides have moved on: fresh ones
    run = _run(setup)
    stored_runs.store(key, run, run.commands.tobytes(), share,
                      {"case": getattr(getattr(setup.plant, "case", None), "name",
                                       type(setup.plant).__name__),
                       "duration": setup.duration})
    return _result(setup, run), run, True


def _run(setup: _Setup) -> _Shared:
    """Run ``setup`` on ANDES: what it leaves to share (its result: :func:`_result`)."""
    loop = AndesLoop(setup.plant, setup.loads, setup.gens, setup.relays, setup.stop_on_trip,
                     setup.network, setup.following)
    loop.run(setup.duration, setup.step)
    rows = np.array(loop.rows)
    t = rows[:, 0].round(9)              # ANDES accumulates its time in floating point
    n_a = setup.plant.n_areas
    per_area = rows[:, 1:1 + 8 * n_a].reshape(len(rows), n_a, 8)   # then the plant's extra
    return _Shared(t, per_area, loop.trips(t),
                   np.array([k for k, _ in loop.samples], dtype=np.int64),
                   np.array([u for _, u in loop.samples]).reshape(-1, n_a))


def _result(setup: _Setup, run: _Shared) -> Result:
    """The result of ``setup``'s generator sides on the run ``run``."""
    per_area = run.per_area
    return grid_result(setup.params, run.t, per_area[:, :, :5], per_area[:, :, 5],
                            per_area[:, :, 6], run.trips, setup.tc,
                            [g.ctrl for g in setup.gens], setup.built, setup.settings,
                            p_net=per_area[:, :, 7])


def _replay(setup: _Setup, run: _Shared) -> Result | None:
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
        if not all(map(stored_runs.same_float, u, commands)):
            return None
    return _result(setup, run)


def rerun(rec: stored_runs.Recording) -> _Shared:
    """A recording's run computed again on ANDES, fed the commands it holds at its
    control samples (no generator side computes them): what checks a recording
    (``tests/test_stored_runs.py``)."""
    setup = _setup(**pickle.loads(rec.call), filters=None)   # the committed call
    loop = AndesLoop(setup.plant, setup.loads, setup.gens, setup.relays, setup.stop_on_trip,
                     following=setup.following)
    loop.sides = RecordedSides(rec.run.commands)
    loop.run(setup.duration, setup.step)
    rows = np.array(loop.rows)
    n_a = setup.plant.n_areas
    t = rows[:, 0].round(9)
    return _Shared(t, rows[:, 1:1 + 8 * n_a].reshape(len(rows), n_a, 8), loop.trips(t),
                   np.array([k for k, _ in loop.samples], dtype=np.int64),
                   np.array([u for _, u in loop.samples]).reshape(-1, n_a))


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
                              **common) -> list[Result]:
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
    out: list[Result | None] = [None] * len(calls)
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

    def finished(i: int, result: Result, run: _Shared | None, andes: bool) -> None:
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
              keep: bool) -> tuple[Result, _Shared | None, bool]:
    """Run a table's scenario (in a worker process), reading back a run stored
    under ``key`` (``share``: its call's pickle); what it leaves to share if
    ``keep`` and it is shareable; whether ANDES ran."""
    result, run, andes = _run_stored(lambda: _setup_call(params, call), share, key)
    return result, (run if keep else None), andes
