import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from lfc.signals import Chirp, Ramp, Samples, Sinusoid, Square, Step

t = np.linspace(-1, 20, 2101)


def test_zero_before_start_and_float_in_float_out():
    for sig in (Sinusoid(1, 1, start=2), Square(1, 1, start=2), Step(1, start=2),
                Ramp(1, start=2), Chirp(1, 0.1, 2, start=2, stop=5),
                Samples([2, 3], [1, 2])):
        assert np.all(sig(t[t < 2]) == 0)
        assert isinstance(sig(3.3), float)


def test_values():
    assert Sinusoid(2, 1, start=1)(1.25) == pytest.approx(2.0)
    assert Sinusoid(2, 1, start=1, stop=2)(2.25) == 0.0
    assert Sinusoid(1, 1, phase=math.pi / 2)(0.0) == pytest.approx(1.0)
    assert Square(0.3, 0.5)(0.5) == 0.3 and Square(0.3, 0.5)(1.5) == -0.3
    assert Step(0.04, start=1)(1.0) == 0.04
    assert Ramp(0.1, start=1, stop=3)(2.0) == pytest.approx(0.1)
    assert Ramp(0.1, start=1, stop=3)(10.0) == pytest.approx(0.2)
    assert Samples([0, 1, 2], [0, 1, 0])(0.5) == 0.5
    assert Samples([0, 1, 2], [0, 1, 5])(9.0) == 5.0


def test_chirp_sweeps_linearly():
    c = Chirp(1.0, 1.0, 3.0, start=0.0, stop=10.0)
    # instantaneous frequency f0 + (f1 - f0) t / T: zero crossings get denser
    tt = np.linspace(0, 10, 100001)
    crossings = tt[1:][np.diff(np.sign(c(tt))) != 0]
    assert len(crossings[crossings < 1]) in (2, 3)
    assert len(crossings[crossings > 9]) in (5, 6, 7)
    assert c(10.5) == 0.0


@given(st.floats(0.01, 5), st.floats(0.05, 3), st.floats(0, 5))
def test_sinusoid_and_square_bounded(a, f, start):
    for sig in (Sinusoid(a, f, start=start), Square(a, f, start=start)):
        assert np.max(np.abs(sig(t))) <= a + 1e-12


@pytest.mark.parametrize("factory, name", [
    (lambda: Sinusoid(1, 0), "freq_hz"), (lambda: Sinusoid(float("nan"), 1), "amplitude"),
    (lambda: Square(1, -1), "freq_hz"), (lambda: Sinusoid(1, 1, start=2, stop=1), "stop"),
    (lambda: Step(float("inf")), "value"), (lambda: Ramp(1, start=3, stop=3), "stop"),
    (lambda: Chirp(1, 0, 1), "f0_hz"), (lambda: Chirp(1, 1, 2, stop=math.inf), "stop"),
    (lambda: Samples([0, 0], [1, 2]), "increasing"), (lambda: Samples([0, 1], [1]), "length"),
    (lambda: Samples([0, 1], [1, np.nan]), "finite")])
def test_bad_arguments(factory, name):
    with pytest.raises(ValueError, match=name):
        factory()
