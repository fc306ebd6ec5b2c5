"""The Grid rebuild's regression set: every recorded run gives the recorded values
(``tests/regression_set.py``: 1e-12 relative on the linear model, 1e-9 on ANDES, on
the recording machine; the measured cross-machine tolerances elsewhere)."""

import pytest

import regression_set as rs

RECORDED = rs.load()
LINEAR = {**rs.linear_cases(), **rs.batch_cases(), **rs.multiarea_cases()}


def test_every_case_is_recorded():
    assert set(RECORDED) == set(rs.all_cases())


@pytest.mark.parametrize("name", sorted(LINEAR))
def test_linear_case_matches_record(name):
    same = rs.recorded_machine(name) == rs.machine()
    assert rs.compare(name, LINEAR[name](), RECORDED[name], same) == []


@pytest.mark.parametrize("name", sorted(rs.testbed_cases()))
def test_testbed_case_matches_record(name, monkeypatch):
    """A short live run of each ANDES case (the microgrid, Kundur, the IEEE 39-bus
    system; no stored run read back) against the record."""
    pytest.importorskip("andes")
    monkeypatch.setenv("LFC_ANDES_RUNS", "off")
    same = rs.recorded_machine(name) == rs.machine()
    assert rs.compare(name, rs.testbed_cases()[name](), RECORDED[name], same) == []
