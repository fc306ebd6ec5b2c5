"""The filters' commands on a fixed set of states, pinned before the filters move.

``tests/data/filter_regression.npz`` was recorded by :func:`record`: the paper's
filter (with the "push" reading of E9) at commit bbe860e, before the Baseline and
Engine issues, and again in the Reliability issue, which changed only its answer
to invalid input (the first 20 states: it now holds the last applied command
instead of passing the incoming one through; every other state unchanged, checked
before re-recording); the certified filter's entries again in the Robust issue, which
changed its definition on purpose (a continuous-time certificate over 8 s, the
parameter box and the estimation bound; issue note); and in the Rigor issue, whose
enclosures replaced the gains' 1 % pad (the two certified entries: 174 and 1,237
commands moved, by at most 0.095 and 0.0036 pu; ``outside`` 3,840 -> 3,797 and
``active`` one fewer each, the certificates' tightenings being smaller); and again in
the Rigor issue when ``load_kind="band"``'s held check moved from a re-certification
at the load given now to the load given at the certification with room for what the
band did since (commands unchanged; ``outside`` 3,797 -> 2,846 with ``load_bound=0.05``,
and 2,065 -> 2,066 at ``load_bound=0``: a load given that moved from the one
certified: a breach of a zero band).  Every later version of the filters must give the
same commands and flags on these states.  A change of
behaviour on purpose needs a new recording of the entries it changes
(``record(names=...)``) and a note in the issue.
"""

from pathlib import Path

import numpy as np
import pytest

import lfc

DATA = Path(__file__).parent / "data" / "filter_regression.npz"
P, RELAYS = lfc.LFCParams(), lfc.RelaySettings()
N = 4000


def cases() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Seeded states (N, 5), commands and assumed loads (N,): near equilibrium,
    at the limits and well outside them, so every regime of each filter occurs."""
    rng = np.random.default_rng(20261122)
    scale = np.array([0.5, 0.5, 0.04, 0.04, 0.08]) * rng.choice([0.05, 0.3, 1.0, 3.0], (N, 1))
    x = rng.normal(size=(N, 5)) * scale
    u_ref = rng.normal(scale=0.6, size=N)
    p_load = np.where(rng.random(N) < 0.5, 0.0, rng.normal(scale=0.05, size=N))
    x[:10, 2], u_ref[10:20] = np.nan, np.inf   # lost measurements, a broken command
    return x, u_ref, p_load


PUSH = {"outside_rule": "push", "conflict": "slack", "prediction": "incoming"}
FILTERS = {  # name -> SafetyFilter keyword arguments (paper filter: the "push" reading)
    "paper_a3": {"alpha": 3.0, **PUSH},
    "paper_a20": {"alpha": 20.0, **PUSH},
    "paper_a20_limits": {"alpha": 20.0, "u_min": -0.5, "u_max": 0.8, **PUSH},
    "paper_a1_ts01": {"alpha": 1.0, "Ts": 0.1, **PUSH},
    "certified": {"method": "certified"},
    "certified_load_margin": {"method": "certified", "load_bound": 0.05, "margin": 0.1},
    "certified_box_noise": {"method": "certified", "uncertainty": 0.2,
                            "noise_std": (1e-4, 1e-3)},
}
FLAGS = ("active", "infeasible", "outside", "invalid_input")


def record(path: Path = DATA, names: list[str] | None = None) -> None:
    """Write the current filters' outputs on :func:`cases` to ``path``: all of
    ``FILTERS``, or only ``names`` (the other entries are kept)."""
    x, u_ref, p_load = cases()
    out = dict(np.load(path)) if names is not None and path.exists() else {}
    for name, kw in FILTERS.items():
        if names is not None and name not in names:
            continue
        u, flags = lfc.SafetyFilter(P, RELAYS, **kw).filter_batch(x, u_ref, p_load)
        out[f"{name}/u"] = u
        for f in FLAGS:
            out[f"{name}/{f}"] = flags[f]
    np.savez_compressed(path, **out)


@pytest.mark.parametrize("name", list(FILTERS))
def test_commands_and_flags_are_unchanged(name):
    expected = np.load(DATA)
    x, u_ref, p_load = cases()
    u, flags = lfc.SafetyFilter(P, RELAYS, **FILTERS[name]).filter_batch(x, u_ref, p_load)
    np.testing.assert_allclose(u, expected[f"{name}/u"], rtol=1e-9, atol=1e-12)
    for f in FLAGS:
        np.testing.assert_array_equal(flags[f], expected[f"{name}/{f}"], err_msg=f)


@pytest.mark.parametrize("name", [n for n in FILTERS if not n.startswith("certified")])
def test_one_state_at_a_time_gives_the_same_commands(name):
    expected = np.load(DATA)
    x, u_ref, p_load = cases()
    filt = lfc.SafetyFilter(P, RELAYS, **FILTERS[name])
    u = np.array([filt.filter(x[i], u_ref[i], p_load[i])[0] for i in range(0, N, 7)])
    np.testing.assert_allclose(u, expected[f"{name}/u"][::7], rtol=1e-9, atol=1e-12)
