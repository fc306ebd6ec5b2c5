import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from lfc.relays import RelayBank, RelaySettings


def test_defaults_are_ieee1547_cat3():
    r = RelaySettings()
    assert (r.of2, r.uf2, r.of2_delay, r.uf2_delay, r.rocof_limit, r.rocof_delay) == \
        (1.03, 0.942, 0.16, 0.16, 0.05, 0.0)
    assert r.F == pytest.approx(0.03)


@pytest.mark.parametrize("kwargs, name", [
    ({"of2": 1.0}, "of2"), ({"of2": 0.9}, "of2"), ({"uf2": 1.0}, "uf2"), ({"uf2": 0.0}, "uf2"),
    ({"rocof_limit": 0.0}, "rocof_limit"), ({"of2_delay": -0.1}, "of2_delay"),
    ({"uf2_delay": float("nan")}, "uf2_delay"), ({"rocof_delay": -1}, "rocof_delay")])
def test_bad_settings_rejected(kwargs, name):
    with pytest.raises(ValueError, match=name):
        RelaySettings(**kwargs)


def _run(signal_dw, signal_rocof=None, dt=1e-3, block=None, settings=RelaySettings()):
    n = len(signal_dw)
    t = np.arange(n) * dt
    rc = np.zeros(n) if signal_rocof is None else np.asarray(signal_rocof)
    bank = RelayBank(settings)
    block = block or n
    trips = []
    for k in range(0, n, block):
        for relay, i, _ in bank.update(t[k:k + block], signal_dw[k:k + block], rc[k:k + block]):
            trips.append((relay, round(t[k + i], 9)))
    return sorted(trips, key=lambda r: r[1])


def test_of2_trips_after_160ms_and_not_before():
    dw = np.zeros(1000)
    dw[100:259] = 0.031  # 159 samples = 0.158 s beyond
    assert _run(dw) == []
    dw[100:261] = 0.031  # 0.16 s beyond: trips at t = 0.1 + 0.16
    assert _run(dw) == [("OF2", 0.26)]


def test_timer_resets_when_signal_returns():
    dw = np.zeros(1000)
    dw[100:200] = -0.06
    dw[201:300] = -0.06
    assert _run(dw) == []


def test_rocof_trips_immediately_and_every_excursion():
    rc = np.zeros(100)
    rc[10:15] = 0.051
    rc[50] = -0.06
    assert _run(np.zeros(100), rc) == [("ROCOF", 0.01), ("ROCOF", 0.05)]


@given(st.lists(st.sampled_from([0.0, 0.031, -0.06]), min_size=1, max_size=60),
       st.integers(1, 40))
def test_blocks_give_same_trips_as_whole_trace(levels, block):
    dw = np.repeat(levels, 37)
    assert _run(dw, block=block) == _run(dw)


def test_vectorized_over_scenarios():
    t = np.arange(400) * 1e-3
    dw = np.zeros((400, 3))
    dw[:, 1] = 0.05
    bank = RelayBank(RelaySettings(), n=3)
    trips = bank.update(t, dw, np.zeros((400, 3)))
    assert trips == [("OF2", 160, 1)]


def test_safe_set():
    r = RelaySettings()
    assert r.in_safe_set(0.0, 0.0) and not r.in_safe_set(0.031, 0.0)
    assert not r.in_safe_set(0.0, -0.051) and r.in_safe_set(-0.058, 0.05)


@pytest.mark.parametrize("category, hz_per_s", [("I", 0.5), ("II", 2.0), ("III", 3.0)])
def test_ieee1547_categories_set_the_rocof_ride_through_and_keep_table_1(category, hz_per_s):
    """IEEE 1547-2018: ROCOF ride-through 0.5 / 2.0 / 3.0 Hz/s for categories I / II /
    III; the frequency thresholds are the paper's Table 1 in every category, and
    category III is the default (the paper's)."""
    r = RelaySettings.ieee1547(category)
    assert r.rocof_limit * 60.0 == pytest.approx(hz_per_s, rel=1e-15)
    assert (r.of2, r.uf2, r.of2_delay, r.uf2_delay) == (1.03, 0.942, 0.16, 0.16)
    assert RelaySettings.ieee1547(category, nominal_hz=50.0).rocof_limit == hz_per_s / 50.0
    assert RelaySettings.ieee1547() == RelaySettings()


@pytest.mark.parametrize("kwargs, name", [({"category": "IV"}, "category"),
                                          ({"category": 3}, "category"),
                                          ({"category": ["III"]}, "category"),
                                          ({"nominal_hz": 0.0}, "nominal_hz"),
                                          ({"nominal_hz": 1e-3}, "nominal_hz")])
def test_ieee1547_refuses_an_unknown_category_or_frequency(kwargs, name):
    with pytest.raises(ValueError, match=name):
        RelaySettings.ieee1547(**kwargs)


def test_a_notebooks_physical_knobs_reach_its_model_and_relays():
    """``lfc.repro.notebook.setup``: M, the relay category and the ROCOF setting."""
    from lfc.repro.notebook import setup
    params, relays = setup("linear", M=2.0, relay_category="I")
    assert params.M == 2.0 and relays == RelaySettings.ieee1547("I")
    assert setup("linear", rocof_limit=0.02)[1].rocof_limit == 0.02
    assert setup("linear", M=4.0) == setup("linear")         # the defaults are the paper's
    for kwargs, name in (({"M": 0.0}, "M"), ({"M": 101.0}, "M"),
                         ({"relay_category": "IV"}, "category"),
                         ({"rocof_limit": -0.1}, "rocof_limit")):
        with pytest.raises(ValueError, match=name):
            setup("linear", **kwargs)
    with pytest.raises(ValueError, match="fitted"):
        setup("testbed", M=4.0)
    with pytest.raises(TypeError, match="M must be a number"):
        setup("linear", M=True)                 # refused, not read as M = 1 s
