import control as ct
import numpy as np
import pytest

from lfc.model import LFCParams, block_propagator, discretize, lfc_matrices, lfc_model, zoh


def test_named_signals():
    sys = lfc_model(LFCParams())
    assert sys.state_labels == ["dPg", "dPm", "dw", "dw_meas", "rocof_meas"]
    assert sys.input_labels == ["dPc", "dPL"]
    assert sys.output_labels == ["dw_meas", "rocof_meas"]


def test_corrected_droop_is_stable_printed_is_not():
    """Erratum E1: the printed +1/(R tau_G) gives an eigenvalue > 0."""
    p = LFCParams()
    A, _ = lfc_matrices(p)
    A_printed, _ = lfc_matrices(p, printed_droop_sign=True)
    assert np.all(np.linalg.eigvals(A).real < 0)
    assert np.max(np.linalg.eigvals(A_printed).real) > 0.5
    assert A[0, 2] == pytest.approx(-1 / (p.droop * p.tau_g))


def test_dc_gains_match_hand_derivation():
    """Steady state: dw = (dPc - dPL) / (D + 1/R), ROCOF = 0."""
    p = LFCParams()
    g = ct.dcgain(lfc_model(p))
    beta = p.D + 1 / p.droop
    assert g[0, 0] == pytest.approx(1 / beta, rel=1e-9)
    assert g[0, 1] == pytest.approx(-1 / beta, rel=1e-9)
    assert abs(g[1, 0]) < 1e-12 and abs(g[1, 1]) < 1e-12


def test_observable_from_frequency_and_rocof():
    sys = lfc_model(LFCParams())
    assert np.linalg.matrix_rank(ct.obsv(sys.A, sys.C)) == 5


def test_discretization_matches_matrix_exponential():
    from scipy.linalg import expm
    p = LFCParams()
    A, B = lfc_matrices(p)
    Ad, Bd = discretize(p, 0.25)
    M = expm(np.block([[A, B], [np.zeros((2, 7))]]) * 0.25)
    np.testing.assert_allclose(Ad, M[:5, :5], atol=1e-12)
    np.testing.assert_allclose(Bd, M[:5, 5:], atol=1e-12)


def test_discretization_works_for_singular_A():
    """E4: the paper's B_d = A^-1 (A_d - I) B needs an invertible A; ZOH does not.
    A chain of integrators (A singular: rank 2 of 3) against the exact answer."""
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    B = np.array([[0.0], [0.0], [1.0]])
    assert np.linalg.matrix_rank(A) == 2
    Ad, Bd = zoh(A, B, 0.5)
    np.testing.assert_allclose(Ad, [[1, 0.5, 0.125], [0, 1, 0.5], [0, 0, 1]], atol=1e-14)
    np.testing.assert_allclose(Bd.ravel(), [0.5**3 / 6, 0.5**2 / 2, 0.5], atol=1e-14)


def test_block_propagator_equals_stepping():
    Ad, Bd = discretize(LFCParams(), 1e-3)
    Phi, Gu, Gl = block_propagator(Ad, Bd, 7)
    rng = np.random.default_rng(1)
    x, pl, u = rng.normal(size=5), rng.normal(size=7), 0.3
    X = (Phi @ x + Gu * u + Gl @ pl).reshape(7, 5)
    for i in range(7):
        x = Ad @ x + Bd[:, 0] * u + Bd[:, 1] * pl[i]
        np.testing.assert_allclose(X[i], x, atol=1e-14)


@pytest.mark.parametrize("name", ["tau_g", "tau_t", "M", "droop", "tau_w", "tau_rocof",
                                  "f_nominal", "s_base_mva"])
@pytest.mark.parametrize("value", [0.0, -1.0, float("nan"), float("inf")])
def test_positive_parameters_rejected(name, value):
    with pytest.raises(ValueError, match=name):
        LFCParams(**{name: value})


@pytest.mark.parametrize("name", ["D", "k_i"])
def test_nonnegative_parameters_rejected(name):
    with pytest.raises(ValueError, match=name):
        LFCParams(**{name: -0.1})
    LFCParams(**{name: 0.0})


def test_discretize_rejects_bad_period():
    with pytest.raises(ValueError, match="period"):
        discretize(LFCParams(), 0.0)
