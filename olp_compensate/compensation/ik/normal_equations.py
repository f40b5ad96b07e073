"""Batched damped Gauss-Newton steps and singularity tests of many small Jacobians at once.

Jacobians ``(k, 6, n)`` (or their columns ``(n, 6, k)``, batch last, the ``_t`` variants);
LAPACK would pay one call per 6 x 6 system, so the elimination is written out over the batch.
"""

from __future__ import annotations

import numpy as np


DAMPING = 1e-10       # Tikhonov term of the Newton step, relative to mean(diag(J^T J))


def joint_major(jac):
    """``jac (k, r, n)`` as a contiguous ``(n, r, k)`` array: the columns, batch last (no
    copy if it is one already, as a Jacobian built that way and handed out transposed)."""
    return np.ascontiguousarray(np.transpose(jac, (2, 1, 0)))


def normal_matrices(jc, rhs=None):
    """``J^T J`` of Jacobians ``jc (n, r, k)`` (columns, batch last) as ``(n, n [+ 1], k)``
    (so that the elimination below works on contiguous rows), with ``J^T rhs`` appended as
    column n for ``rhs (k, r)``. The upper triangle is computed, the lower copied."""
    n, _, k = jc.shape
    A = np.empty((n, n + (rhs is not None), k))
    for i in range(n):
        np.einsum("ak,jak->jk", jc[i], jc[i:], out=A[i, i:n])
        A[i + 1:, i] = A[i, i + 1:n]
    if rhs is not None:
        A[:, n] = np.einsum("iak,ak->ik", jc, np.ascontiguousarray(rhs.T))
    return A


def eliminate(A, n):
    """Gaussian elimination without pivoting, in place, of ``A (n, n + c, k)`` whose
    leading ``(n, n)`` blocks are symmetric positive (semi)definite (where it is stable)."""
    for c in range(n - 1):
        factor = A[c + 1:, c] / A[c, c]
        A[c + 1:, c + 1:] -= factor[:, None] * A[c, None, c + 1:]


def gauss_newton_steps(jac, err, damping):
    """Steps ``(k, n)`` solving ``(J^T J + mu I) dq = J^T err``, ``mu = damping *
    trace(J^T J) / n``, for a batch ``jac (k, 6, n)``; see :func:`gauss_newton_steps_t`."""
    return gauss_newton_steps_t(joint_major(jac), err, damping)


def gauss_newton_steps_t(jc, err, damping):
    """:func:`gauss_newton_steps` of Jacobians ``jc (n, 6, k)``, columns and batch last.
    Batched by hand: LAPACK's solve pays a call per 6 x 6 system. Rows without a finite
    solution get a zero step."""
    n = jc.shape[0]
    A = normal_matrices(jc, err)
    diagonal = np.arange(n)
    A[diagonal, diagonal] += damping * np.einsum("iik->k", A[:, :n]) / n
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        eliminate(A, n)
        step = np.empty((n, A.shape[2]))
        for c in range(n - 1, -1, -1):
            step[c] = (A[c, n] - np.einsum("ik,ik->k", A[c, c + 1:n], step[c + 1:])) / A[c, c]
    step = step.T
    step[~np.all(np.isfinite(step), axis=1)] = 0.0
    return step


def near_singular(jac, tolerance):
    """Rows ``(k,)`` of ``jac (k, 6, n)`` whose smallest singular value is below
    ``tolerance`` times the largest; see :func:`near_singular_t`."""
    return near_singular_t(joint_major(jac), tolerance)


def near_singular_t(jc, tolerance):
    """:func:`near_singular` of Jacobians ``jc (n, 6, k)``, columns and batch last. For square
    ones, |det J| / |J|_F^6 <= s_min / s_max clears most rows without an SVD (det(J)^2 =
    det(J^T J), the product of the pivots of its elimination)."""
    k = jc.shape[2]
    candidates = np.ones(k, bool)
    if jc.shape[0] == 6 and k:
        A = normal_matrices(jc)
        frobenius_2 = np.einsum("iik->k", A)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            eliminate(A, 6)
            det_2 = np.prod(A[np.arange(6), np.arange(6)], axis=0)
            candidates = ~(det_2 >= tolerance ** 2 * frobenius_2 ** 6)
    singular = np.zeros(k, bool)
    if np.any(candidates):
        sv = np.linalg.svd(np.transpose(jc[..., candidates], (2, 1, 0)), compute_uv=False)
        singular[candidates] = sv[:, -1] < tolerance * sv[:, 0]
    return singular
