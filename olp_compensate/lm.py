"""Levenberg-Marquardt for small dense problems, as in Motta 2006 eq. 52.

``x_{j+1} = x_j - (J^T J + mu_j I)^-1 J^T b`` on column-scaled variables, with Marquardt's
damping schedule: mu starts at 1e-3 and is multiplied by ``growth`` after a step that does
not lower the residual and divided by it after one that does (the seed's 2.5 < lambda < 10).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.linalg import cho_factor, cho_solve


@dataclass(frozen=True)
class LMResult:
    """Outcome of :func:`levenberg_marquardt`; ``cost`` is half the sum of squares."""

    x: np.ndarray
    cost: float
    residuals: np.ndarray
    jacobian: np.ndarray
    iterations: int
    evaluations: int
    success: bool
    message: str


def levenberg_marquardt(fun: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                        x0: np.ndarray, *, mu0: float = 1e-3, growth: float = 10.0,
                        max_iterations: int = 100, ftol: float = 1e-12, xtol: float = 1e-12,
                        gtol: float = 1e-12) -> LMResult:
    """Minimize ``0.5 * |r(x)|^2``; ``fun(x)`` returns ``(r, J)`` with J = dr/dx, shape (M, N).

    Columns are scaled to unit norm (the scale only grows, as in MINPACK), so mu is relative
    and the problem's units do not matter. Stops when the relative decrease of the cost, the
    relative step or the scaled gradient falls below its tolerance.
    """
    if not 2.5 <= growth <= 10.0:
        raise ValueError(f"growth must lie in [2.5, 10] (Marquardt), got {growth}")
    x = np.array(x0, dtype=float)
    r, jac = fun(x)
    evaluations = 1
    cost = 0.5 * float(r @ r)
    scale = np.linalg.norm(jac, axis=0)
    scale[scale == 0] = 1.0
    mu = mu0
    message = "maximum number of iterations reached"
    success = False
    iteration = 0
    for iteration in range(1, max_iterations + 1):
        js = jac / scale
        gradient = js.T @ r
        if np.max(np.abs(gradient)) <= gtol * max(1.0, np.sqrt(2 * cost)):
            message, success = "gradient below tolerance", True
            break
        normal = js.T @ js
        while True:
            damped = normal + mu * np.eye(len(x))
            try:
                step_scaled = -cho_solve(cho_factor(damped), gradient)
            except np.linalg.LinAlgError:
                mu *= growth
                continue
            step = step_scaled / scale
            x_new = x + step
            r_new, jac_new = fun(x_new)
            evaluations += 1
            cost_new = 0.5 * float(r_new @ r_new)
            if np.isfinite(cost_new) and cost_new < cost:
                break
            mu *= growth
            if mu > 1e16:
                return LMResult(x, cost, r, jac, iteration, evaluations, True,
                                "no further decrease possible (at a minimum to machine precision)")
        decrease = cost - cost_new
        x, r, jac, cost_old, cost = x_new, r_new, jac_new, cost, cost_new
        scale = np.maximum(scale, np.linalg.norm(jac, axis=0))
        mu = max(mu / growth, 1e-12)
        if decrease <= ftol * cost_old:
            message, success = "relative decrease of the cost below tolerance", True
            break
        if np.linalg.norm(step_scaled) <= xtol * (xtol + np.linalg.norm(x * scale)):
            message, success = "relative step below tolerance", True
            break
    return LMResult(x, cost, r, jac, iteration, evaluations, success, message)
