"""The numpy factorizations of identification against scipy's LAPACK (an independent peer)."""

import numpy as np
import pytest
from scipy.linalg import cho_solve, qr
from scipy.linalg.lapack import dpotrf, dpstrf

from olp_compensate.calibration.factorizations import (cholesky, pivoted_cholesky_diagonal,
                                                       qr_r, solve_positive_definite)


def _graded(rng, m, n, spread):
    """A tall matrix whose columns span ``spread`` decades of scale."""
    return rng.normal(size=(m, n)) * np.logspace(0, -spread, n)


@pytest.mark.parametrize("seed", range(5))
def test_cholesky_and_solve_agree_with_lapack(seed):
    rng = np.random.default_rng(seed)
    jac = _graded(rng, 90, 27, 3)
    a = jac.T @ jac
    b = rng.normal(size=27)
    lower = cholesky(a)
    upper, info = dpotrf(a)
    assert info == 0
    np.testing.assert_allclose(lower.T, np.triu(upper), rtol=1e-10, atol=1e-14)
    expected = cho_solve((upper, False), b)
    np.testing.assert_allclose(solve_positive_definite(a, b), expected, rtol=1e-8)
    np.testing.assert_allclose(a @ solve_positive_definite(a, b), b, rtol=1e-6, atol=1e-9)


def test_cholesky_refuses_what_lapack_refuses():
    a = np.diag([1.0, -1e-3, 2.0])
    assert dpotrf(a)[1] > 0
    assert cholesky(a) is None
    assert solve_positive_definite(a, np.ones(3)) is None


@pytest.mark.parametrize("seed", range(5))
def test_pivoted_cholesky_diagonal_agrees_with_dpstrf_and_pivoted_qr(seed):
    rng = np.random.default_rng(10 + seed)
    jac = _graded(rng, 120, 30, 4)
    a = jac.T @ jac
    factor, _, rank, info = dpstrf(a)
    assert info == 0 and rank == 30
    ours = pivoted_cholesky_diagonal(a)
    np.testing.assert_allclose(ours, np.abs(np.diag(factor)), rtol=1e-8)
    r = qr(jac, mode="r", pivoting=True)[0]
    np.testing.assert_allclose(ours, np.abs(np.diag(r)), rtol=1e-6)


def test_pivoted_cholesky_reports_rank_deficiency_as_dpstrf():
    rng = np.random.default_rng(3)
    jac = rng.normal(size=(60, 8))
    jac[:, 5] = jac[:, 1] - 2 * jac[:, 2]  # an exact combination: rank 7
    a = jac.T @ jac
    assert dpstrf(a)[3] == 1
    assert pivoted_cholesky_diagonal(a) is None
    nan = a.copy()
    nan[2, 2] = np.nan
    assert pivoted_cholesky_diagonal(nan) is None


def test_qr_r_gives_the_singular_values_of_the_matrix():
    rng = np.random.default_rng(4)
    jac = _graded(rng, 200, 20, 5)
    r = qr_r(np.asfortranarray(jac))
    assert r.shape == (20, 20)
    np.testing.assert_allclose(np.linalg.svd(r, compute_uv=False),
                               np.linalg.svd(jac, compute_uv=False), rtol=1e-9)
