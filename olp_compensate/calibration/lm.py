"""Levenberg-Marquardt for small dense problems, as in Motta 2006 eq. 52.

``x_{j+1} = x_j - (J^T J + mu_j I)^-1 J^T b`` on column-scaled variables, with Marquardt's
damping schedule: mu starts at 1e-3 and is multiplied by ``growth`` after a step that does
not lower the residual and divided by it after one that does (the seed's 2.5 < lambda < 10).

Each Jacobian (M x N, M >> N) is reduced once to the small normal matrix ``J^T J`` and
gradient ``J^T r`` (one BLAS product each); every damping trial is then a Cholesky
factorization of the N x N matrix (the test that it is positive definite) and a solve,
O(N^3), independent of M. The undamped solve gives the decrease the Gauss-Newton model
predicts, so the iteration stops without a confirming evaluation once that is negligible.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, NamedTuple

import numpy as np

from .factorizations import solve_positive_definite


@dataclass(frozen=True)
class LMResult:
    """Outcome of :func:`levenberg_marquardt`; ``cost`` is half the sum of squares,
    ``residuals``, ``jacobian`` and ``normal`` (J^T J) are those at ``x``; ``iterations``
    counts the steps taken, ``evaluations`` the calls of ``fun`` and ``residuals``."""

    x: np.ndarray
    cost: float
    residuals: np.ndarray
    jacobian: np.ndarray
    iterations: int
    evaluations: int
    success: bool
    message: str
    normal: np.ndarray | None = None


def levenberg_marquardt(fun: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                        x0: np.ndarray, *, mu0: float = 1e-3, growth: float = 10.0,
                        max_iterations: int = 100, ftol: float = 1e-12, xtol: float = 1e-12,
                        gtol: float = 1e-12,
                        residuals: Callable[[np.ndarray], np.ndarray] | None = None,
                        initial: tuple[np.ndarray, ...] | None = None) -> LMResult:
    """Minimize ``0.5 * |r(x)|^2``; ``fun(x)`` returns ``(r, J)`` with J = dr/dx, shape (M, N).

    Columns are scaled to unit norm (the scale only grows, as in MINPACK), so mu is relative
    and the problem's units do not matter. Stops when the decrease of the cost that the
    Gauss-Newton model predicts, or the actual decrease of a step, falls below ``ftol`` times
    the cost, when the relative step falls below ``xtol`` or the scaled gradient below
    ``gtol``.

    ``residuals(x)``, optional, returns r alone. A rejected trial needs no Jacobian, but a
    trial that is accepted does, and ``fun`` gives both from one evaluation: the first two
    trials at a Jacobian (the second, with ``growth`` times the damping, usually succeeds) call
    ``fun``; further ones call ``residuals``, and ``fun`` once more at the one accepted.
    ``initial``: ``(r, J)`` or ``(r, J, J^T J)`` at x0 when the caller has them.
    """
    if not 2.5 <= growth <= 10.0:
        raise ValueError(f"growth must lie in [2.5, 10] (Marquardt), got {growth}")
    x = np.array(x0, dtype=float)
    if initial is None:
        r, jac = fun(x)
        evaluations = 1
    else:
        r, jac = initial[:2]
        evaluations = 0
    cost = 0.5 * float(r @ r)
    normal = jac.T @ jac if initial is None or len(initial) < 3 else initial[2]
    jtr = jac.T @ r
    scale = np.sqrt(np.diag(normal))
    scale[scale == 0] = 1.0
    mu = mu0
    message = "maximum number of iterations reached"
    success = False
    steps = 0
    for _ in range(max_iterations):
        gradient = jtr / scale
        if np.max(np.abs(gradient), initial=0.0) <= gtol * max(1.0, np.sqrt(2 * cost)):
            message, success = "gradient below tolerance", True
            break
        scaled = normal / np.outer(scale, scale)
        # Decrease predicted by the Gauss-Newton model, g^T (J^T J)^-1 g / 2 (when regular).
        newton = solve_positive_definite(scaled, gradient)
        if newton is not None and 0.5 * float(gradient @ newton) <= ftol * cost:
            message, success = "predicted decrease of the cost below tolerance", True
            break
        trial = _damped_step(fun, residuals, x, cost, scaled, gradient, scale, mu, growth)
        evaluations += trial.evaluations
        if trial.x is None:
            return LMResult(x=x, cost=cost, residuals=r, jacobian=jac, iterations=steps,
                            evaluations=evaluations, success=True,
                            message="no further decrease possible (at a minimum to machine "
                                    "precision)", normal=normal)
        x_new, r_new, jac_new, cost_new = trial.x, trial.residuals, trial.jacobian, trial.cost
        step_scaled, mu = trial.step_scaled, trial.mu
        steps += 1
        decrease = cost - cost_new
        x, r, jac, cost_old, cost = x_new, r_new, jac_new, cost, cost_new
        normal, jtr = jac.T @ jac, jac.T @ r
        scale = np.maximum(scale, np.sqrt(np.diag(normal)))
        mu = max(mu / growth, 1e-12)
        if decrease <= ftol * cost_old:
            message, success = "relative decrease of the cost below tolerance", True
            break
        if np.linalg.norm(step_scaled) <= xtol * (xtol + np.linalg.norm(x * scale)):
            message, success = "relative step below tolerance", True
            break
    return LMResult(x=x, cost=cost, residuals=r, jacobian=jac, iterations=steps,
                    evaluations=evaluations, success=success, message=message, normal=normal)


class _Trial(NamedTuple):
    """An accepted damped step: the new ``x`` (None when the damping ran out), its
    residuals, Jacobian and cost, the scaled step, the damping ``mu`` that gave it, and the
    evaluations it took."""

    x: np.ndarray | None
    residuals: np.ndarray | None
    jacobian: np.ndarray | None
    cost: float
    step_scaled: np.ndarray | None
    mu: float
    evaluations: int


def _damped_step(fun, residuals, x: np.ndarray, cost: float, scaled: np.ndarray,
                 gradient: np.ndarray, scale: np.ndarray, mu: float, growth: float) -> _Trial:
    """Marquardt's trials at one Jacobian: solve ``(J^T J + mu I) step = -g`` on the scaled
    variables, multiplying mu by ``growth`` until the cost decreases (see
    :func:`levenberg_marquardt` for when ``fun`` or ``residuals`` is called)."""
    identity = np.eye(len(x))
    failed = 0  # trials rejected at this Jacobian
    evaluations = 0
    while True:
        solution = solve_positive_definite(scaled + mu * identity, gradient)
        if solution is not None:  # else not positive definite to working precision: damp more
            step_scaled = -solution
            x_new = x + step_scaled / scale
            if failed < 2 or residuals is None:
                r_new, jac_new = fun(x_new)
            else:
                r_new, jac_new = residuals(x_new), None
            evaluations += 1
            cost_new = 0.5 * float(r_new @ r_new)
            if np.isfinite(cost_new) and cost_new < cost:
                break
            failed += 1
        mu *= growth
        if mu > 1e16:
            return _Trial(x=None, residuals=None, jacobian=None, cost=cost, step_scaled=None,
                          mu=mu, evaluations=evaluations)
    if jac_new is None:
        r_new, jac_new = fun(x_new)
        evaluations += 1
    return _Trial(x=x_new, residuals=r_new, jacobian=jac_new, cost=cost_new,
                  step_scaled=step_scaled, mu=mu, evaluations=evaluations)
