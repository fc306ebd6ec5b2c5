"""Scenarios in SIMD lanes: the same numbers as one at a time, bit for bit."""

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lfc
from lfc.engine import LANES, Scenarios, lane_blocks
from lfc.relays import RelaySettings
from lfc.signals import Sinusoid, Square, Step
from test_batch import random_scenarios

P = lfc.LFCParams()


def both(table: pd.DataFrame, duration: float = 6.0) -> tuple[pd.DataFrame, pd.DataFrame]:
    kw = dict(duration=duration, progress=False, executor=None, chunk_size=len(table) + 1)
    return (lfc.simulate_many(P, table, lanes=True, **kw),
            lfc.simulate_many(P, table, lanes=False, **kw))


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


@settings(max_examples=15)
@given(st.integers(1, 2 * LANES + 3), st.integers(0, 10_000))
def test_lanes_equal_one_at_a_time_on_any_table(n, seed):
    """Any number of rows (empty lanes in the last block), any mix."""
    lanes, scalar = both(mixed(n, seed), duration=3.0)
    pd.testing.assert_frame_equal(lanes, scalar, check_exact=True)


@pytest.mark.parametrize("stop", [False, True])
def test_lanes_stop_at_a_trip_where_one_at_a_time_stops(stop):
    """A lane that trips stops there (its state and metrics frozen) while the
    others in its block go on."""
    relays = RelaySettings()
    runs = []
    for lanes in (True, False):
        sc = Scenarios(P, duration=8.0, dt=1e-3, control_period=0.01, relays=relays)
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
    assert (a.ends[tripped] < 8000).all() == stop


def test_lane_blocks_group_by_plant_and_pad():
    plant_of = np.array([0, 1, 0, 0, 1])
    blocks = lane_blocks(plant_of, np.array([0, 1, 2, 4]))
    assert blocks.shape == (2, LANES)
    assert blocks[0, :3].tolist() == [0, 2, -1] and blocks[1, :3].tolist() == [1, 4, -1]
    assert sorted(blocks[blocks >= 0].tolist()) == [0, 1, 2, 4]
    for row in blocks:
        used = row[row >= 0]
        assert len(set(plant_of[used])) == 1 and (row[len(used):] == -1).all()
    assert lane_blocks(plant_of, np.array([], np.int64)).shape == (0, LANES)
