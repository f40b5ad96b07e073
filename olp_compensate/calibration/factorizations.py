"""Small dense factorizations for identification, in numpy alone.

The matrices here are the N x N normal matrices J^T J of a fit (N below about 100) and its
tall Jacobians. numpy's LAPACK covers the Cholesky and the plain QR; the two factorizations
it lacks are written here (pivoted Cholesky, N steps of an N x N update) or borrowed from
scipy on the rare path that needs them (column-pivoted QR, only for a rank-deficient fit).
Importing ``scipy.linalg`` costs 0.2-0.4 s, more than a 100-pose ``olp-cal identify`` fits
for; none of the usual path imports it.
"""

from __future__ import annotations

import numpy as np


def cholesky(a: np.ndarray) -> np.ndarray | None:
    """Lower-triangular L with ``a = L L^T`` for symmetric ``a`` (n, n), or None when ``a``
    is not positive definite to working precision (LAPACK ``dpotrf``'s ``info > 0``)."""
    try:
        return np.linalg.cholesky(a)
    except np.linalg.LinAlgError:
        return None


def solve_positive_definite(a: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """x with ``a x = b`` for symmetric ``a`` (n, n), or None when ``a`` is not positive
    definite to working precision (its Cholesky factorization fails, as LAPACK ``dpotrf``).
    The solve is numpy's LU of ``a``: without a triangular solve in numpy, two general
    solves on the Cholesky factor would cost twice as much."""
    if cholesky(a) is None:
        return None
    return np.linalg.solve(a, b)


def pivoted_cholesky_diagonal(a: np.ndarray) -> np.ndarray | None:
    """The diagonal of the pivoted Cholesky factor of a symmetric positive semi-definite
    ``a`` (n, n), in pivot order (largest remaining diagonal first, as LAPACK ``dpstrf``);
    None when a remaining diagonal falls to dpstrf's default tolerance ``n eps max(diag a)``
    or is not a number (``a`` is then rank deficient to working precision: dpstrf's
    ``info = 1``). In exact arithmetic the values are |diag R| of the column-pivoted QR of
    any J with ``J^T J = a``."""
    work = np.array(a, dtype=float)
    n = len(work)
    remaining = np.diag(work).copy()
    tol = n * np.finfo(float).eps * max(float(np.max(remaining, initial=0.0)), 0.0)
    out = np.empty(n)
    for k in range(n):
        j = int(np.argmax(remaining))
        pivot = remaining[j]
        if not pivot > tol:  # also NaN
            return None
        out[k] = np.sqrt(pivot)
        column = work[:, j] / out[k]
        work -= np.outer(column, column)
        remaining -= column * column
        remaining[j] = -np.inf  # done; its row and column of ``work`` are now zero
    return out


def pivoted_qr_r(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R, column permutation) of the column-pivoted QR ``a[:, P] = Q R`` (LAPACK
    ``dgeqp3`` through scipy, imported here: only rank-deficient fits come this way).
    ``a`` (m, n) is overwritten; pass a Fortran-ordered copy."""
    from scipy.linalg import qr

    _, r, pivots = qr(a, mode="raw", pivoting=True, overwrite_a=True, check_finite=False)
    return r, pivots


def qr_r(a: np.ndarray) -> np.ndarray:
    """The R factor (min(m, n), n) of the QR of ``a`` (m, n)."""
    return np.linalg.qr(a, mode="r")
