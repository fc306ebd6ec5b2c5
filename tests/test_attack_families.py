"""Where the paper's SCC fails (reproduction notes E13, and what this package found).

These are findings, not bugs to hide: each test pins an attack that the
paper's SCC (our reading, documented defaults) does NOT stop, so that a change
which silently alters that behaviour is noticed.  The certified filter of a
later issue is meant to stop them.
"""

import pytest

from lfc import Chirp, LFCParams, Ramp, SafetyFilter, Sinusoid, Square, Step, simulate

P = LFCParams()

BEATEN = {  # attack -> (channel, duration s)
    "sinusoid 0.2 Hz, 1 pu on P_c": (Sinusoid(1.0, 0.2, start=1), "pc_attack", 30),
    "sinusoid 0.5 Hz, 0.5 pu on P_c": (Sinusoid(0.5, 0.5, start=1), "pc_attack", 30),
    "square 0.4 Hz, 0.3 pu on P_c": (Square(0.3, 0.4, start=1), "pc_attack", 30),
    "chirp 0.1-3 Hz, 0.5 pu on P_c": (Chirp(0.5, 0.1, 3.0, start=1, stop=25), "pc_attack", 30),
    "ramp 0.1 pu/s on P_c": (Ramp(0.1, start=1), "pc_attack", 30),
    "sinusoid 1.2 Hz, 0.66 pu (2x trip amplitude) on P_c":
        (Sinusoid(0.66, 1.2, start=1), "pc_attack", 15),
    "bias 0.06 pu on w_ref (integrator wind-up)": (Step(0.06, start=1), "wref_attack", 30),
}


@pytest.mark.parametrize("name", list(BEATEN))
@pytest.mark.parametrize("alpha", [3.0, 20.0])
def test_paper_scc_is_beaten(name, alpha):
    signal, channel, duration = BEATEN[name]
    without = simulate(P, duration=duration, **{channel: signal})
    with_scc = simulate(P, duration=duration, scc=SafetyFilter(P, alpha=alpha),
                        **{channel: signal})
    assert without.metrics()["tripped"]
    assert with_scc.metrics()["tripped"], f"{name} no longer trips with alpha={alpha}"


def test_wind_up_defeats_the_scc_on_a_long_fig5_attack():
    """Fig. 5's bias is stopped for 30 s but not forever: the local integrator winds
    up behind the SCC, the held command in the prediction grows, and the barrier's
    push-back eventually trips ROCOF."""
    r = simulate(P, duration=45, wref_attack=Step(0.04, start=1), scc=SafetyFilter(P))
    trip = r.metrics()["first_trip"]
    assert trip["relay"] == "ROCOF" and trip["t"] > 30
    assert r.controls.pc_ref.iloc[-1] > 2.0   # the wound-up incoming command (pu)


def test_scc_causes_a_trip_that_would_not_happen_without_it():
    """A -0.06 pu bias on w_ref stays above UF2 (-0.058 pu) without SCC.  The SCC
    uses the symmetric bound F = min(OF2-1, 1-UF2) = 0.03 pu, holds the frequency
    at -0.03 pu, the integrator winds up, and the push-back trips ROCOF."""
    attack = Step(-0.06, start=1)
    assert not simulate(P, duration=30, wref_attack=attack).metrics()["tripped"]
    for alpha in (3.0, 20.0):
        r = simulate(P, duration=30, wref_attack=attack, scc=SafetyFilter(P, alpha=alpha))
        assert r.metrics()["first_trip"]["relay"] == "ROCOF"
