"""The compiled positive definite solves (hystid.spd) and their fallback in the re-solve."""

import numpy as np
import pytest

from hystid.identify.horizon import covariance, solve_information
from hystid.spd import spd_inverse, spd_solve


def information(n, seed, scale_spread=6.0):
    # J'J + a prior, columns scaled over `scale_spread` decades: the shape of the identifiers'
    # information matrices (condition ~1e4..1e12)
    rng = np.random.default_rng(seed)
    J = rng.standard_normal((4 * n, n)) * np.logspace(0, scale_spread / 2, n)
    return J.T @ J + np.eye(n) * 1e-3


@pytest.mark.parametrize("n, seed", [(1, 0), (5, 1), (25, 2), (40, 3)])
def test_solve_and_inverse_agree_with_lapack(n, seed):
    A = information(n, seed)
    b = np.random.default_rng(seed + 10).standard_normal(n)
    x = spd_solve(A, b)
    np.testing.assert_allclose(A @ x, b, rtol=0, atol=1e-8 * np.abs(A).max() * np.abs(x).max())
    np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-6)
    P = spd_inverse(A)
    np.testing.assert_array_equal(P, P.T)
    np.testing.assert_allclose(P, np.linalg.inv(A), rtol=1e-6, atol=1e-12 * np.abs(P).max())


@pytest.mark.parametrize("bad", ["indefinite", "singular", "nan"])
def test_a_matrix_that_is_not_positive_definite_is_said_not_solved(bad):
    A = information(6, 4)
    if bad == "indefinite":
        A[2, 2] = -1.0
    elif bad == "singular":
        A[:, 3] = A[3, :] = 0.0
    else:
        A[1, 1] = np.nan
    assert spd_solve(A, np.ones(6)) is None
    assert spd_inverse(A) is None


def test_the_re_solve_falls_back_to_numpy_where_cholesky_refuses():
    # symmetric, invertible, not positive definite: the fallback gives LAPACK's answer
    A = np.array([[2.0, 0.0], [0.0, -1.0]])
    b = np.array([1.0, 1.0])
    np.testing.assert_allclose(solve_information(A, b), [0.5, -1.0])
    np.testing.assert_allclose(covariance(A), np.diag([0.5, -1.0]))
    # positive definite: the compiled one, the same to rounding
    B = information(25, 5)
    np.testing.assert_allclose(covariance(B), np.linalg.inv(B), rtol=1e-6,
                               atol=1e-12 * np.abs(np.linalg.inv(B)).max())
