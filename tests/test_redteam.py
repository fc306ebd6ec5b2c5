"""The red team's searches, severity, and the README-section writer."""

import numpy as np
import pandas as pd
import pytest

import lfc
from lfc.experiments.redteam import Defender, family_search, freeform_search, severity
from lfc.repro.notebook import update_markdown_section

P, RELAYS = lfc.LFCParams(), lfc.RelaySettings()


def test_severity_is_the_worst_ratio_to_the_settings():
    res = pd.DataFrame({"max_abs_rocof_meas": [0.025, 0.1], "max_abs_dw_meas": [0.03, 0.003]})
    assert list(severity(res, RELAYS)) == pytest.approx([1.0, 2.0])


def test_family_search_beats_the_paper_filter_and_not_the_certified_one():
    paper = family_search(P, Defender("paper α=20"), "square on P_c", relays=RELAYS,
                          duration=6.0, maxiter=3, popsize=4, seed=1)
    cert = family_search(P, Defender("certified", method="certified"), "square on P_c",
                         relays=RELAYS, duration=6.0, maxiter=3, popsize=4, seed=1)
    assert paper["tripped"] and paper["severity"] > 1
    assert not cert["tripped"] and cert["severity"] <= 1


def test_freeform_search_is_seeded_and_bounded():
    kw = dict(relays=RELAYS, amplitude=1.0, attack_duration=0.2, duration=2.0, maxiter=1,
              seed=3)
    a = freeform_search(P, Defender("paper α=20"), **kw)
    b = freeform_search(P, Defender("paper α=20"), **kw)
    assert a == b and "max |value|" in a["attack"]


def test_markdown_section_needs_its_markers(tmp_path):
    path = tmp_path / "doc.md"
    path.write_text("no markers here\n")
    with pytest.raises(ValueError, match="no <!-- table:start -->"):
        update_markdown_section(path, "table", "x")


def test_the_square_on_wref_family_covers_the_audits_attack():
    """The audit beat the red team's worst case against the robust filter (0.808, five
    families) with a plain 0.5 pu, 0.3 Hz square on ω_ref at the weak corner (0.83):
    squares on ω_ref are now a family, and that attack is inside its bounds."""
    from lfc.experiments.redteam import FAMILIES, _family_table
    channel, waveform, bounds = FAMILIES["square on ω_ref"]
    assert (channel, waveform) == ("wref", "square")
    assert bounds[0][0] <= 0.5 <= bounds[0][1] and bounds[1][0] <= 0.3 <= bounds[1][1]
    robust = Defender("robust", method="certified", uncertainty=0.2, declare_noise=True)
    weak = dict(M=3.2, D=0.8, droop=0.04, tau_g=0.12, tau_t=0.36)
    table = _family_table("square on ω_ref", np.array([[0.5], [0.3]]), robust).assign(
        noise_w=1e-4, noise_rocof=1e-3, seed=1, **weak)
    res = lfc.simulate_many(lfc.LFCParams(), table, duration=10.0, progress=False)
    assert 0.808 < severity(res, lfc.RelaySettings())[0] < 1.0 and not res.tripped.iloc[0]
