"""Scenarios in SIMD lanes: the same numbers as one at a time, bit for bit."""

import numpy as np
import pandas as pd
import pytest
import tiers
from hypothesis import given, settings
from hypothesis import strategies as st

import lfc
from lfc import lanes as lane_kernel
from lfc import scenarios
from lfc.lanes import LANES, lane_blocks
from lfc.scenarios import Scenarios
from lfc.relays import RelaySettings
from lfc.signals import Sinusoid, Square, Step
from test_batch import random_scenarios

P = lfc.LFCParams()


def both(table: pd.DataFrame, duration: float = 6.0,
         min_fill: int = 1) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The table in lanes (every block, however few it holds: ``min_fill`` 1) and one
    at a time."""
    kw = dict(duration=duration, progress=False, executor=None, chunk_size=len(table) + 1)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(scenarios, "LANE_MIN_FILL", min_fill)
        lanes = lfc.simulate_many(P, table, lanes=True, **kw)
    return lanes, lfc.simulate_many(P, table, lanes=False, **kw)


def mixed(n: int, seed: int) -> pd.DataFrame:
    """Every kind of row: waveforms on every channel, no filter, the paper filter's
    readings, the certified filter, other plants, measurement noise with its Kalman
    filter, relay noise (one at a time), anti-windup."""
    rng = np.random.default_rng(seed)
    table = random_scenarios(n, seed)
    table["method"] = np.where(rng.random(n) < 0.3, "certified", "paper")
    table["M"] = rng.choice([P.M, 0.8 * P.M, 1.2 * P.M], n)
    noisy = rng.random(n) < 0.3
    table["noise_w"] = np.where(noisy, 2e-4, 0.0)
    table["noise_rocof"] = np.where(noisy, 1e-3, 0.0)
    table["seed"] = rng.integers(0, 1000, n)
    table["relay_noise"] = noisy & (rng.random(n) < 0.5)
    table["anti_windup"] = ~np.isnan(table["alpha"]) & (rng.random(n) < 0.3)
    table["outside_rule"] = np.where((table["method"] == "paper") & (rng.random(n) < 0.5)
                                     & ~np.isnan(table["alpha"]), "hold", None)
    return table


def test_lanes_equal_one_at_a_time_on_every_kind_of_row():
    table = mixed(90, seed=3)
    lanes, scalar = both(table)
    pd.testing.assert_frame_equal(lanes, scalar, check_exact=True)
    assert lanes["tripped"].any() and not lanes["tripped"].all()
    assert (lanes["alarms"] > 0).any()


@settings(max_examples=tiers.examples(15))
@given(st.integers(1, 2 * LANES + 3), st.integers(0, 10_000))
def test_lanes_equal_one_at_a_time_on_any_table(n, seed):
    """Any number of rows (empty lanes in the last block), any mix."""
    lanes, scalar = both(mixed(n, seed), duration=3.0)
    pd.testing.assert_frame_equal(lanes, scalar, check_exact=True)


@pytest.mark.parametrize("duration, period", [(8.0, 0.01), (8.003, 0.005)])
@pytest.mark.parametrize("stop", [False, True])
def test_lanes_stop_at_a_trip_where_one_at_a_time_stops(stop, duration, period):
    """A lane that trips stops there (its state and metrics frozen) while the
    others in its block go on; with an odd number of plant steps per control
    period and a last period of three (the lanes step two at a time, between two
    buffers: ``lfc.lanes._lane_steps``), too."""
    relays = RelaySettings()
    runs = []
    for lanes in (True, False):
        sc = Scenarios(P, duration=duration, dt=1e-3, control_period=period, relays=relays)
        for amp in np.linspace(0.05, 1.5, 2 * LANES - 5):
            sc.add(attacks={0: {"pc": Sinusoid(amp, 0.5, start=1.0)}},
                   loads={0: Step(-0.05, start=2.0)},
                   filters={0: lfc.SafetyFilter(P, alpha=3.0)} if amp > 1.0 else None)
        sc.add(attacks={0: {"wref": Square(0.02, 0.3, start=0.5)}})
        runs.append(sc.run(stop_on_trip=stop, lanes=lanes))
    a, b = runs
    assert np.array_equal(a.metrics, b.metrics, equal_nan=True)
    assert np.array_equal(a.ends, b.ends)
    tripped = ~np.isnan(a.metrics[:, 0, 0])
    assert tripped.any() and (~tripped).any()
    assert (a.ends[tripped] < round(duration / 1e-3)).all() == stop


def test_lane_blocks_group_by_plant_and_pad():
    plant_of = np.array([0, 1, 0, 0, 1])
    blocks, left = lane_blocks(plant_of, np.array([0, 1, 2, 4]))
    assert blocks.shape == (2, LANES) and len(left) == 0
    assert blocks[0, :3].tolist() == [0, 2, -1] and blocks[1, :3].tolist() == [1, 4, -1]
    assert sorted(blocks[blocks >= 0].tolist()) == [0, 1, 2, 4]
    for row in blocks:
        used = row[row >= 0]
        assert len(set(plant_of[used])) == 1 and (row[len(used):] == -1).all()
    blocks, left = lane_blocks(plant_of, np.array([], np.int64))
    assert blocks.shape == (0, LANES) and len(left) == 0


def test_a_plants_last_few_scenarios_run_one_at_a_time():
    """A block pays for all its lanes: a plant's last block runs in lanes only with
    at least ``min_fill`` scenarios, the rest one at a time (the same numbers)."""
    plant_of = np.repeat([0, 1, 2, 3, 4], [LANES + 3, 9, 1, 8, 7])   # 8 and 7: the corner
    blocks, left = lane_blocks(plant_of, np.arange(len(plant_of)), min_fill=8)
    assert sorted(left.tolist()) == [LANES, LANES + 1, LANES + 2, LANES + 12] + list(
        range(LANES + 21, LANES + 28))
    assert blocks.shape == (3, LANES) and [(b >= 0).sum() for b in blocks] == [LANES, 9, 8]
    assert sorted(np.concatenate([blocks[blocks >= 0], left]).tolist()) == list(
        range(len(plant_of)))


def test_one_plant_per_row_runs_one_at_a_time_with_the_same_numbers():
    """A search over a plant box gives every row its own plant: at the default
    ``LANE_MIN_FILL`` such rows run one at a time (in lanes they took twice as
    long: ``bench/bench_batch.py --fill``), a plant with a full block in lanes."""
    table = mixed(40, seed=5)
    table["M"] = np.where(np.arange(40) < 20, P.M, np.linspace(3.0, 5.0, 40))
    lanes, scalar = both(table, duration=3.0, min_fill=lane_kernel.LANE_MIN_FILL)
    pd.testing.assert_frame_equal(lanes, scalar, check_exact=True)
