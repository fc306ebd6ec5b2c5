"""The generator side of one scenario, driven one control period at a time by a plant
that keeps its own time (the ANDES testbed, :mod:`lfc.testbed`; a network,
:mod:`lfc.wire`): :class:`GeneratorSide` runs :func:`lfc.engine.generator_period`, the
engine's own code, at every control sample it is given."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from lfc._validate import check_flag
from lfc.engine import (ACE, DW_MEAS, N_CTRL, N_KF, PC, ROCOF_MEAS, SENSOR_CHANNELS, WREF,
                        Controller, Estimate, GridView, Memory, check_attacks,
                        generator_period, make_estimator, make_noise, scenario_signals,
                        sensor_reading, signal_value)
from lfc.filters import SafetyFilter
from lfc.filters.base import MEMORY
from lfc.filters.dispatch import is_grid_wide, scratch_size
from lfc.model import LFCParams

#: what a generator side without sensor attacks keeps of its reports: nothing
_NO_READINGS = np.zeros((0, 2))


class GridReading(NamedTuple):
    """What a coupled filter's generator side reads of the grid at a sample
    (:meth:`GeneratorSide.step`): this ``area``'s index, the grid's ``state``
    (design-model coordinates), every area's latest ``commands`` and ``loads`` (pu);
    on the filter's grid Kalman estimate also the ``measurements`` (3 n_areas
    values, then as many of scratch: each area's ``dw_meas`` and ``rocof_meas`` with
    its noise, then each area's metered export), the ``estimate`` of the grid's
    state (n_states) and the ``estimator``'s state (2, its states), shared by every
    area (area 0's call steps them)."""

    area: int
    state: np.ndarray
    commands: np.ndarray
    loads: np.ndarray
    measurements: np.ndarray | None = None
    estimate: np.ndarray | None = None
    estimator: np.ndarray | None = None


class GeneratorSide:
    """The generator side of one scenario, for a plant that drives time itself
    (the ANDES testbed): call :meth:`step` at every control sample; it runs
    :func:`generator_period`, the engine's own code.

    Parameters
    ----------
    design : LFCParams
        Design model (local controller gain, ``"kalman"`` model).
    scc : SafetyFilter or None
    estimator, noise_std, seed, pc_attack, wref_attack, load_feedforward, anti_windup
        As in :func:`lfc.simulate`.
    tc : ndarray
        Control sample times (s), uniform with step ``period``.
    period : float
        Controller period (s).
    ace_attack : signal, optional
        Added to the measured tie-line export the AGC integrates (pu; an
        interconnected area, :mod:`lfc.multiarea`).
    k_agc : (float, float), optional
        The AGC's gains on frequency and on tie-line export (1/s,
        :meth:`lfc.MultiAreaParams.agc_gains`); default ``(design.k_i, 0)``, the
        local integral controller of one area; ``(0, 0)`` where the integrator
        runs elsewhere (a control centre across a network).
    network : bool
        The command channels arrive by :meth:`receive` each period (:mod:`lfc.wire`).
    sensor_attacks : dict, optional
        ``{"dw_meas" | "rocof_meas": signal}``: what an attacker makes of what the
        generator side's frequency and ROCOF sensors read (a waveform added, or a
        reading transform of :mod:`lfc.sensor_attacks`), as in :func:`lfc.simulate`.
    """

    def __init__(self, design: LFCParams, scc: SafetyFilter | None, estimator,
                 noise_std: tuple[float, float], seed: int, tc: np.ndarray, pc_attack,
                 wref_attack, load_feedforward: bool, period: float, *, ace_attack=None,
                 k_agc: tuple[float, float] | None = None, anti_windup: bool = False,
                 network: bool = False, sensor_attacks: dict | None = None) -> None:
        if scc is not None:
            scc.check_period(period)
        self.tc, self.scc = tc, scc
        self.noise = make_noise(noise_std, len(tc), seed)
        self.grid_wide = is_grid_wide(scc)
        if self.grid_wide:   # its grid Kalman filter, if any, is shared: its state
            scc.check_estimator(estimator, noise_std)   # and measurements come with
            kf = scc.kalman                             # step's grid (area 0's)
        else:
            kf = make_estimator(estimator, design, period, noise_std)
        self.est = -1 if kf is None else 0
        self.ka, self.kb, self.kc, self.kg = (
            np.ascontiguousarray(m, float) for m in ((kf.A, kf.B, kf.C, kf.gain) if kf else
                                                     (np.zeros((0, 0)),) * 4))
        if network and (pc_attack is not None or wref_attack is not None
                        or ace_attack is not None):
            raise ValueError("network=True: the command channels arrive by receive(); give "
                             "no pc_attack, wref_attack or ace_attack")
        zero = (lambda t: np.zeros_like(t)) if network else None
        self.network = network
        sensors = check_attacks({0: sensor_attacks or {}}, 1)[0]
        if set(sensors) - set(SENSOR_CHANNELS):
            raise ValueError(f"sensor_attacks must be a dict with keys among "
                             f"{SENSOR_CHANNELS}, got {sorted(sensors)}")
        self.signals = scenario_signals(pc_attack or zero, wref_attack or zero, None, tc, tc,
                                        ace_attack or zero, sensors.get("dw_meas"),
                                        sensors.get("rocof_meas"))
        self.seen = np.zeros((len(tc), 2)) if sensors else _NO_READINGS
        k_freq, k_tie = (design.k_i, 0.0) if k_agc is None else k_agc
        self.k_i_period, self.k_tie_period = k_freq * period, k_tie * period
        self.feedforward = load_feedforward
        self.anti_windup = check_flag("anti_windup", anti_windup)
        self.method = scc.method_id if scc is not None else -1
        self.data = scc.data if scc is not None else np.zeros(0)
        self.sums = np.zeros(scratch_size(scc) if scc is not None else 0)
        self.kstate, self.gstate = np.zeros((2, N_KF)), np.zeros(1)
        self.memory = np.zeros(MEMORY)
        self.x_hat = np.zeros(5)
        self.ctrl = np.full((len(tc), N_CTRL), np.nan)
        self.n_done = 0

    def receive(self, j: int, pc: float, wref: float = 0.0, ace: float = 0.0) -> None:
        """Control sample ``j``'s command channels as they arrived over a network
        (:mod:`lfc.wire`; built with ``network=True``): the command ``pc`` added to
        the integrator's output, the reference ``wref`` and the ACE term ``ace``
        (pu), in place of ``pc_attack``, ``wref_attack`` and ``ace_attack``."""
        if not self.network:
            raise ValueError("receive() needs a generator side built with network=True")
        _, _, offsets, _, sv = self.signals
        for channel, value in ((PC, pc), (WREF, wref), (ACE, ace)):
            sv[offsets[channel, 0] + j] = value

    def reports(self, j: int, x: np.ndarray) -> tuple[float, float]:
        """What the frequency and ROCOF sensors report at control sample ``j`` when
        the meters' state is ``x`` (``dw_meas``, ``rocof_meas``: pu, pu/s): the
        reading with this side's noise and the attack on it
        (:func:`lfc.engine.sensor_reading`; called before :meth:`step` of ``j``)."""
        t = float(self.tc[j])
        return tuple(sensor_reading(c, float(x[c - DW_MEAS]) + float(self.noise[j, c - DW_MEAS]),
                                    self.signals, self.seen, t, j)[0]
                     for c in (DW_MEAS, ROCOF_MEAS))

    def step(self, j: int, x: np.ndarray, p_load: float, tie: float = 0.0,
             grid: GridReading | None = None) -> float:
        """Control sample ``j``: read the plant state ``x`` (design-model
        coordinates, pu), the true load — in an interconnected area the net
        disturbance, load plus tie-line export — and the measured tie-line
        export ``tie`` (pu); return the command to hold (pu).  A coupled filter
        (:mod:`lfc.filters.coupled`) also reads ``grid`` (:class:`GridReading`;
        its estimator's fields exactly when it runs on its grid Kalman estimate)."""
        estimates = self.est >= 0
        if self.grid_wide and (
                grid is None or (grid.measurements is not None) != estimates):
            raise ValueError("the coupled filter needs grid=GridReading(area, state, commands, "
                             "loads), and on its estimate also (measurements, estimate, "
                             "estimator); without it, none of them")
        kinds, params, offsets, st, sv = self.signals
        t = float(self.tc[j])
        tie += signal_value(ACE, kinds, params, offsets, st, sv, t, j)
        empty = self.memory[:0]
        if grid is None:
            view = GridView(0, self.x_hat, empty, empty, empty, empty, self.kstate, empty)
        else:
            shared = ((grid.measurements, grid.estimate, grid.estimator)
                      if grid.measurements is not None else (empty, empty, self.kstate))
            view = GridView(int(grid.area), *(np.ascontiguousarray(v, float) for v in
                                              (grid.state, grid.commands, grid.loads)),
                            *shared, self.sums)
        u, _, _ = generator_period(
            j, t, np.asarray(x, float), float(p_load),
            (float(self.noise[j, 0]), float(self.noise[j, 1])), tie, self.signals,
            Estimate(self.est, self.ka, self.kb, self.kc, self.kg, self.kstate),
            Controller(self.k_i_period, self.k_tie_period, self.feedforward, self.anti_windup,
                       self.method, self.data),
            Memory(self.memory, self.gstate, self.x_hat, self.ctrl, self.seen), view)
        self.n_done = j + 1
        return u
