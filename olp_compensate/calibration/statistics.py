"""Statistics of a fitted identification: noise, standard deviations, residuals, outliers.

sigma^2 = RSS / (m - n) over the m equations of the rows in use (3 per position, 3 per
orientation) and n unknowns; the covariance of the unknowns is sigma^2 (J^T J)^-1, from the
SVD of the unit-column-scaled Jacobian (a pseudo-inverse guards near-rank loss). Residuals
are reported per row: the 3-D position error (m) and the angle between measured and
predicted tool frames (rad).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .factorizations import qr_r
from .identifiability import (RANK_TOLERANCE, WEAK_TOLERANCE, describe_combination,
                              unit_columns)
from .problem import IdentificationProblem

NORMAL_EQUATIONS_CONDITION = 1e5
"""Up to this condition number of the unit-scaled Jacobian, the final statistics use the
eigendecomposition of J^T J that the solver formed; beyond it, a QR of the Jacobian."""
OUTLIER_QUANTILE_SIGMA = 4.03
"""99.9 % quantile of the norm of a 3-D Gaussian error, in units of the per-axis sigma."""


@dataclass(frozen=True)
class FitStatistics:
    """The statistics of a fit at its solution x.

    ``n_equations``: equations of the rows in use; ``std``: (n,) standard deviation of each
    unknown, NaN for a held one (units of the unknown: m, rad, or the effect's);
    ``singular_values`` of the unit-scaled Jacobian of the fitted unknowns (descending),
    ``weak``: descriptions of combinations below ``WEAK_TOLERANCE``;
    ``residual_rms``/``residual_max``: 3-D position error over the rows in use, m;
    ``orientation_rms``/``orientation_max``: rad, None without orientation rows;
    ``n_orientation_rows``: orientation rows in use."""

    n_equations: int
    std: np.ndarray
    singular_values: np.ndarray
    weak: list[str]
    residual_rms: float
    residual_max: float
    orientation_rms: float | None
    orientation_max: float | None
    n_orientation_rows: int

    @property
    def condition_number(self) -> float:
        """Of the unit-column-scaled Jacobian."""
        s = self.singular_values
        return float(s[0] / s[-1])


def unit_scaled_svd(jac: np.ndarray, normal: np.ndarray | None = None):
    """(column norms (n,), singular values s (descending), V^T) of the Jacobian with its
    columns scaled to unit norm.

    With ``normal`` = J^T J at hand (the solver's), from its eigendecomposition when the
    scaled Jacobian's condition number is below ``NORMAL_EQUATIONS_CONDITION`` (J^T J squares
    it: the relative error of s and of the covariance stays below cond^2 * eps = 1e-6);
    otherwise, or without ``normal``, from a QR of the scaled Jacobian and the SVD of R."""
    if normal is not None:
        norms = np.sqrt(np.diag(normal))
        norms[norms == 0] = 1.0
        lam, vec = np.linalg.eigh(normal / np.outer(norms, norms))
        if lam[0] > lam[-1] / NORMAL_EQUATIONS_CONDITION**2:
            return norms, np.sqrt(lam[::-1]), vec[:, ::-1].T
    norms = np.sqrt(np.einsum("ij,ij->j", jac, jac))
    norms[norms == 0] = 1.0
    r_factor = qr_r(unit_columns(jac, np.arange(jac.shape[1]), norms))
    _, s, vt = np.linalg.svd(r_factor)
    return norms, s, vt


def fit_statistics(problem: IdentificationProblem, x: np.ndarray,
                   evaluation: tuple[np.ndarray, np.ndarray, np.ndarray | None]
                   ) -> FitStatistics:
    """Statistics at the solution ``x``; ``evaluation``: (residuals, Jacobian, J^T J or
    None) at x, as the solver left them."""
    residual, jac, normal = evaluation
    fitted = np.flatnonzero(~problem.held)  # held unknowns: std NaN, not in the spectrum
    if jac.shape[1] != len(fitted):  # a whole-vector evaluation (trf's): cut it
        jac, normal = jac[:, fitted], None if normal is None else normal[np.ix_(fitted, fitted)]
    used = problem.row_weight > 0
    n_oriented = int(used[problem.oriented_rows].sum())
    m_eq = 3 * int(used.sum()) + 3 * n_oriented
    dof = m_eq - problem.n_unknowns
    sigma2 = float(residual @ residual) / max(dof, 1)
    norms, s, vt = unit_scaled_svd(jac, normal)
    # (J^T J)^-1 = V S^-2 V^T on the scaled columns; pseudo-inverse guards near-rank loss.
    inv_s2 = np.where(s > RANK_TOLERANCE * s[0], 1.0 / np.maximum(s, 1e-300) ** 2, 0.0)
    cov_scaled = (vt.T * inv_s2) @ vt
    std = np.full(problem.layout.size, np.nan)
    std[fitted] = np.sqrt(np.clip(np.diag(cov_scaled), 0, None) * sigma2) / norms
    names = [problem.names()[k] for k in fitted]
    weak = [f"{describe_combination(vt[k], names)} (relative singular value {s[k] / s[0]:.1e})"
            for k in range(len(s)) if s[k] < WEAK_TOLERANCE * s[0]]
    m_rows = len(problem.measured)
    if np.all(problem.position_weight[used] == 1.0):  # the position rows of the residual
        errors = np.linalg.norm(residual[:3 * m_rows].reshape(m_rows, 3), axis=1)[used]
    else:
        errors = row_errors(problem, x)[used]
    angles = problem.orientation_angles(x)[used]
    angles = angles[np.isfinite(angles)]
    return FitStatistics(
        n_equations=m_eq, std=std, singular_values=s, weak=weak,
        residual_rms=float(np.sqrt(np.mean(errors**2))), residual_max=float(errors.max()),
        orientation_rms=float(np.sqrt(np.mean(angles**2))) if angles.size else None,
        orientation_max=float(angles.max()) if angles.size else None,
        n_orientation_rows=n_oriented)


def row_errors(problem: IdentificationProblem, x: np.ndarray) -> np.ndarray:
    """(m,) 3-D distance between predicted and measured point of each row, m (unweighted)."""
    *_, predicted = problem.predict(x, jacobian=False)
    return np.linalg.norm(predicted - problem.measured, axis=1)


def inlier_weight(problem: IdentificationProblem, x: np.ndarray) -> np.ndarray:
    """Row weights (m,) for the robust fit: 0 for a row whose position error, or whose
    orientation error, exceeds the 99.9 % quantile of its kind. Each kind's per-axis sigma
    is the smaller of a robust one (median) and RSS / (3 rows) scaled by M / (M - n), M all
    equations (the degrees of freedom shared out between the kinds)."""
    inliers = problem.row_weight > 0
    errors = row_errors(problem, x)
    angles = problem.orientation_angles(x)
    with_angle = inliers & np.isfinite(angles)
    m_eq = 3 * inliers.sum() + 3 * with_angle.sum()
    inflate = m_eq / max(m_eq - problem.n_unknowns, 1)
    reject = np.zeros(len(errors), dtype=bool)
    for err, rows in ((errors, inliers), (angles, with_angle)):
        if not rows.any():
            continue
        sigma = np.sqrt(np.sum(err[rows] ** 2) / (3 * rows.sum()) * inflate)
        med_sigma = np.median(err[rows]) / 1.5382
        reject |= np.nan_to_num(err, nan=0.0) > OUTLIER_QUANTILE_SIGMA * min(sigma, med_sigma)
    return (~reject).astype(float)
