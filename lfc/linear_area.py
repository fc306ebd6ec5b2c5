"""Closed-loop simulation of the LFC plant, local controller, safety filter and relays.

Timing: the plant is advanced exactly (zero-order hold) every ``dt``; the
local controller, the network command (with any attack) and the filter run
every ``control_period`` and hold their command in between.  Relays watch the
measured signals at every plant step.  Trips are recorded and the run goes on
(as in the paper, "to show the SCC's continuity") unless ``stop_on_trip``.
:func:`simulate_area` is the engine (:mod:`lfc.engine`) with one scenario and a trace;
:func:`lfc.simulate` runs it for an ``LFCParams`` plant.
"""

from __future__ import annotations


import numpy as np
import pandas as pd

from lfc._validate import (ParameterTypeError, check_flag, check_multiple,
                           check_positive)
from lfc.engine import N_CTRL, sample_signal
from lfc.filters import SafetyFilter
from lfc.load_attacks import FollowingLoad
from lfc.model import STATES, LFCParams
from lfc.relays import RELAY_NAMES, RelaySettings, relays_or_default
from lfc.result import Result, area_result
from lfc.scenarios import Scenarios
from lfc.sensors import Redundant
from lfc.signals import Signal

__all__ = ["check_timing", "simulate_area"]
MAX_STEPS = 10**7   # plant steps in one single-area run (2.8 h at 1 ms)
#: values a run's trace may hold: a single area's at MAX_STEPS (5 states and an
#: area's trip column per step, N_CTRL columns per 10 ms control period): about a
#: gigabyte with the frames built from it.  A grid's longest run is shorter.
MAX_TRACE_VALUES = MAX_STEPS * (5 + 1 + N_CTRL / 10)


def check_timing(duration: float, dt: float, control_period: float, n_areas: int = 1,
                 n_states: int = 5) -> int:
    """Validate a run's timing (s): ``duration`` and ``control_period`` whole
    multiples of ``dt``, and a trace (``n_states`` values and ``n_areas`` trip
    columns per plant step, ``N_CTRL`` columns per area and control period) of at
    most ``MAX_TRACE_VALUES`` values, checked before anything is allocated; return
    plant steps per control period."""
    for name, value in (("duration", duration), ("dt", dt), ("control_period", control_period)):
        check_positive(name, value)
    per_step = n_states + n_areas + n_areas * N_CTRL * dt / max(control_period, dt)
    longest = MAX_TRACE_VALUES / per_step * dt           # s
    if duration > longest:
        raise ValueError(f"duration / dt = {duration / dt:.3g} plant steps is more than one "
                         f"run holds: its trace ({n_areas} area(s), {n_states} states) would "
                         f"take about {duration / dt * per_step * 8 / 1e9:.3g} GB; lower "
                         f"duration (at most {longest:.6g} s at dt = {dt} s) or raise dt")
    if duration < dt * (1 - 1e-9):
        raise ValueError(f"duration must be at least one plant step (dt = {dt} s), "
                         f"got {duration!r}")
    if not dt <= control_period <= max(duration, dt):
        raise ValueError(f"control_period must lie in [dt, duration] = [{dt}, {duration}] s, "
                         f"got {control_period!r}")
    ratio = check_multiple("control_period", control_period, "dt", dt)
    check_multiple("duration", duration, "dt", dt)     # else the run ends off the asked time
    return ratio


def simulate_area(params: LFCParams, *, duration: float, pc_attack: Signal | None = None,
             wref_attack: Signal | None = None, load: Signal | None = None,
             scc: SafetyFilter | None = None, relays: RelaySettings | None = None,
             estimator=None, noise_std: tuple[float, float] = (0.0, 0.0), seed: int = 0,
             dt: float = 1e-3, control_period: float = 0.01, stop_on_trip: bool = False,
             load_feedforward: bool = False, relay_noise: bool = False,
             anti_windup: bool = False, dw_meas_attack: Signal | None = None,
             rocof_meas_attack: Signal | None = None,
             following_load: FollowingLoad | None = None,
             sensors: Redundant | None = None) -> Result:
    """Simulate the closed loop from equilibrium.

    Parameters
    ----------
    params : LFCParams
        Plant (and local controller) parameters.
    duration : float
        Simulated time (s), > 0.
    pc_attack : callable, optional
        Added to the governor command dPc that arrives from the network (pu);
        a :class:`~lfc.signals.Signal` or any callable of time.
    wref_attack : callable, optional
        Corrupts the frequency reference dw_ref of the local integral
        controller ``d dPc/dt = k_i (dw_ref - dw_meas)`` (pu).
    load : callable, optional
        Load change dPL (pu).
    scc : SafetyFilter, optional
        The safety filter; None runs without one.
    relays : RelaySettings, optional
        Default IEEE 1547 Cat. III.
    estimator : None, "kalman" or KalmanFilter
        None gives the filter the true state; "kalman" a Kalman filter's estimate
        (its measurement-noise model taken from ``noise_std`` where > 0).
    noise_std : (float, float)
        Std of white noise on the controller's ``dw_meas`` (pu) and
        ``rocof_meas`` (pu/s) readings.
    seed : int
        Seed of the noise generators, in [0, 2**32) (the relays' noise keeps 32 bits).
    dt : float
        Plant step (s). Default 1 ms.
    control_period : float
        Controller/filter period (s), an integer multiple of ``dt``. Default 10 ms.
    stop_on_trip : bool
        End the run at the first relay trip.
    load_feedforward : bool
        Give the filter the true dPL (an idealized load measurement) instead of 0
        (E7: dPL is not measured at the generator); needs ``scc`` and
        ``estimator=None`` (else ``ValueError``: it would have no effect).
    relay_noise : bool
        The relays read ``dw_meas`` and ``rocof_meas`` through white noise of
        std ``noise_std`` too, drawn independently at every plant step (seeded
        by ``seed``); default False: the relays see the noise-free signals.
        ``trace`` and the metrics keep the noise-free signals.
    anti_windup : bool
        While the filter's command differs from the incoming one, the local
        integrator does not integrate in the direction that widens the
        difference (conditional integration), so it cannot wind up behind a
        held command.  Default False: the paper's loop, where it winds up.
    dw_meas_attack, rocof_meas_attack : callable, optional
        Added to what the generator side's frequency (pu) and ROCOF (pu/s) sensors
        read: the local integrator, the Kalman filter (``estimator``) and, with the
        exact state, the filter's ``dw_meas`` and ``rocof_meas`` states all read the
        spoofed value; the relays, the trace and the metrics the plant's.
    following_load : FollowingLoad, optional
        A dynamic load-altering attack (:class:`lfc.load_attacks.FollowingLoad`): a
        botnet's load that follows the frequency meter, added to ``load`` (the
        trace's ``p_load`` holds both).
    sensors : Redundant, optional
        Redundant frequency and ROCOF sensors, some of which may lie
        (:class:`lfc.sensors.Redundant`): the local integrator, the Kalman filter and
        the filter read their median; the alarm log names each reading found a lie
        (``reason`` ``"spoofed: ..."``) and each sample beyond the array's statement
        (``"beyond: ..."``).  Not with ``dw_meas_attack``, ``rocof_meas_attack`` or
        ``noise_std``.

    Returns
    -------
    Result
    """
    check_timing(duration, dt, control_period)
    if scc is not None and not isinstance(scc, SafetyFilter):
        raise ParameterTypeError(f"scc must be a SafetyFilter or None, got {scc!r}")
    relays = relays_or_default(relays)
    check_flag("load_feedforward", load_feedforward)   # the engine calls it feedforward
    if load_feedforward and (scc is None or estimator is not None):
        raise ValueError("load_feedforward=True gives the filter the true load in place of "
                         "an estimate: it needs scc and estimator=None (it would have no "
                         "effect here)")
    sc = Scenarios(params, duration=duration, dt=dt, control_period=control_period,
                   relays=relays)
    sc.add(attacks={0: {"pc": pc_attack, "wref": wref_attack, "dw_meas": dw_meas_attack,
                        "rocof_meas": rocof_meas_attack}}, loads={0: load},
           filters={0: scc}, estimator=estimator, noise_std=noise_std, seed=seed,
           feedforward=load_feedforward, relay_noise=relay_noise, anti_windup=anti_windup,
           following_loads={0: following_load}, sensors={0: sensors})
    run = sc.run(trace=True, stop_on_trip=stop_on_trip)
    end = int(run.ends[0])
    t = sc.t[:end + 1]
    trace = pd.DataFrame({"t": t})
    for i, name in enumerate(STATES):
        trace[name] = run.x[:end + 1, i]
    trace["p_load"] = sample_signal(load, t, "load")
    if following_load is not None:
        trace["p_load"] += following_load.load(t, trace["dw_meas"].to_numpy())
    bits = run.trips[:end + 1, 0]
    trips = pd.DataFrame([(RELAY_NAMES[r], float(t[k])) for k in np.flatnonzero(bits)
                          for r in range(3) if bits[k] >> r & 1], columns=["relay", "t"])
    settings = {"params": vars(params), "relays": vars(relays), "duration": duration,
                "dt": dt, "control_period": control_period, "seed": seed,
                "noise_std": list(noise_std), "scc": repr(scc), "estimator": repr(estimator),
                "pc_attack": repr(pc_attack), "wref_attack": repr(wref_attack),
                "load": repr(load), "stop_on_trip": stop_on_trip,
                "load_feedforward": load_feedforward, "anti_windup": anti_windup,
                **{name: repr(v) for name, v in (("dw_meas_attack", dw_meas_attack),
                                                 ("rocof_meas_attack", rocof_meas_attack),
                                                 ("following_load", following_load),
                                                 ("sensors", sensors))
                   if v is not None}}
    return area_result(trace, sc.tc, run.ctrl[:, 0], trips, scc,
                       settings).with_alarms(sc.sensor_alarms[0])
