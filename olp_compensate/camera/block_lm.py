"""Levenberg-Marquardt for problems with a few shared unknowns and one small block of
unknowns per view (a camera's intrinsics and each view's pose; a bundle adjustment).

The Jacobian ``J = [A | B]`` has dense columns ``A`` for the ``p`` shared unknowns and, for
the rows of view ``v``, nonzero pose columns ``B_v`` (``q`` wide) only in that view's block.
The normal equations are kept as their blocks (:class:`BlockNormal`):
``U = sum A_v^T A_v`` (p, p), ``W_v = A_v^T B_v`` (p, q), ``V_v = B_v^T B_v`` (q, q) and the
gradients ``A^T r``, ``B_v^T r_v``, never as the dense ``(p + q V)^2`` matrix nor the dense
``m x (p + q V)`` Jacobian. A step solves the damped system by the Schur complement on the
pose blocks (Triggs et al. 2000, "Bundle adjustment - a modern synthesis", section 6.1):
``(U - sum W_v V_v^-1 W_v^T) da = -g_a + sum W_v V_v^-1 g_v``, then
``db_v = -V_v^-1 (g_v + W_v^T da)``: V small solves of q x q and one p x p, linear in
the number of views.

The damping and stopping rules are those of :mod:`olp_compensate.calibration.lm` (Marquardt's
schedule on unit-norm columns, the stops on the predicted and actual decrease, the step and
the gradient), so a problem gives the same minimum by either.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.linalg.lapack import dpotrf, dpotrs


@dataclass(frozen=True)
class BlockNormal:
    """Blocks of ``J^T J`` and ``J^T r``: shared (p, p), cross (V, p, q), blocks (V, q, q),
    g_shared (p,), g_blocks (V, q). Unknowns ordered shared first, then view by view."""

    shared: np.ndarray
    cross: np.ndarray
    blocks: np.ndarray
    g_shared: np.ndarray
    g_blocks: np.ndarray

    @property
    def size(self) -> int:
        return len(self.shared) + self.g_blocks.size

    def diagonal(self) -> np.ndarray:
        """Diagonal of ``J^T J`` (n,)."""
        return np.concatenate([np.diag(self.shared),
                               np.diagonal(self.blocks, axis1=1, axis2=2).ravel()])

    def gradient(self) -> np.ndarray:
        """``J^T r`` (n,)."""
        return np.concatenate([self.g_shared, self.g_blocks.ravel()])

    def solve(self, damping: np.ndarray) -> np.ndarray | None:
        """``-(J^T J + diag(damping))^-1 J^T r`` (n,) by the Schur complement on the view
        blocks; None when the damped matrix is not positive definite to working precision."""
        p = len(self.shared)
        n_views, q = self.g_blocks.shape
        blocks = self.blocks + damping[p:].reshape(n_views, q)[:, :, None] * np.eye(q)
        rhs = np.concatenate([np.swapaxes(self.cross, 1, 2), self.g_blocks[:, :, None]], 2)
        try:
            np.linalg.cholesky(blocks)
            solved = np.linalg.solve(blocks, rhs)         # V^-1 W^T and V^-1 g, (V, q, p + 1)
        except np.linalg.LinAlgError:
            return None
        schur = (self.shared + np.diag(damping[:p])
                 - np.einsum("vpq,vqk->pk", self.cross, solved[:, :, :p]))
        rhs_shared = -self.g_shared + np.einsum("vpq,vq->p", self.cross, solved[:, :, p])
        factor, info = dpotrf(schur)
        if info != 0:
            return None
        step_shared = dpotrs(factor, rhs_shared)[0]
        step_blocks = -(solved[:, :, p] + solved[:, :, :p] @ step_shared)
        return np.concatenate([step_shared, step_blocks.ravel()])

    def dense(self) -> np.ndarray:
        """``J^T J`` as one (n, n) matrix."""
        p = len(self.shared)
        n_views, q = self.g_blocks.shape
        out = np.zeros((self.size, self.size))
        out[:p, :p] = self.shared
        out[:p, p:] = np.swapaxes(self.cross, 0, 1).reshape(p, n_views * q)
        out[p:, :p] = out[:p, p:].T
        for v in range(n_views):
            out[p + q * v:p + q * (v + 1), p + q * v:p + q * (v + 1)] = self.blocks[v]
        return out

    def inverse(self) -> np.ndarray:
        """``(J^T J)^-1`` (n, n) from the blocks: with ``S`` the Schur complement and
        ``E = [I; -V^-1 W^T]`` (n, p), it is ``E S^-1 E^T`` plus ``V_v^-1`` on the view
        blocks (O(n^2), not O(n^3)). All inf when the matrix is singular (unidentifiable
        unknowns)."""
        p = len(self.shared)
        n_views, q = self.g_blocks.shape
        try:
            np.linalg.cholesky(self.blocks)
            v_inv = np.linalg.inv(self.blocks)
        except np.linalg.LinAlgError:
            return np.full((self.size, self.size), np.inf)
        v_inv_wt = v_inv @ np.swapaxes(self.cross, 1, 2)                # (V, q, p)
        schur = self.shared - np.einsum("vpq,vqk->pk", self.cross, v_inv_wt)
        factor, info = dpotrf(schur)
        if info != 0:
            return np.full((self.size, self.size), np.inf)
        e = np.concatenate([np.eye(p), -v_inv_wt.reshape(n_views * q, p)])
        out = e @ dpotrs(factor, e.T)[0]
        for v in range(n_views):
            out[p + q * v:p + q * (v + 1), p + q * v:p + q * (v + 1)] += v_inv[v]
        return out


@dataclass(frozen=True)
class BlockLMResult:
    """Outcome of :func:`block_levenberg_marquardt`: ``cost`` half the sum of squares,
    ``residuals`` and ``normal`` at ``x``; ``iterations`` steps taken, ``evaluations`` calls of
    ``evaluate`` and ``residuals``."""

    x: np.ndarray
    cost: float
    residuals: np.ndarray
    normal: BlockNormal
    iterations: int
    evaluations: int
    success: bool
    message: str


Evaluate = Callable[[np.ndarray], tuple[np.ndarray, BlockNormal]]


def block_levenberg_marquardt(evaluate: Evaluate,
                              residuals: Callable[[np.ndarray], np.ndarray], x0: np.ndarray,
                              *, mu0: float = 1e-3, growth: float = 10.0,
                              max_iterations: int = 100, ftol: float = 1e-12,
                              xtol: float = 1e-12, gtol: float = 1e-12) -> BlockLMResult:
    """Minimize ``0.5 |r(x)|^2``. ``evaluate(x)`` gives ``(r, BlockNormal)``, ``residuals(x)``
    r alone (for trials after the first at one Jacobian). Tolerances as in
    :func:`olp_compensate.calibration.lm.levenberg_marquardt`."""
    x = np.array(x0, dtype=float)
    r, normal = evaluate(x)
    evaluations, steps = 1, 0
    cost = 0.5 * float(r @ r)
    scale = np.sqrt(normal.diagonal())
    scale[scale == 0] = 1.0
    mu = mu0
    message, success = "maximum number of iterations reached", False
    for _ in range(max_iterations):
        g = normal.gradient()
        if np.max(np.abs(g / scale), initial=0.0) <= gtol * max(1.0, np.sqrt(2 * cost)):
            message, success = "gradient below tolerance", True
            break
        newton = normal.solve(np.zeros_like(scale))
        if newton is not None and -0.5 * float(g @ newton) <= ftol * cost:
            message, success = "predicted decrease of the cost below tolerance", True
            break
        failed = 0
        while True:
            step = normal.solve(mu * scale * scale)
            if step is not None:
                if failed == 0:              # usually accepted: its Jacobian will be needed
                    r_new, normal_new = evaluate(x + step)
                else:
                    r_new, normal_new = residuals(x + step), None
                evaluations += 1
                cost_new = 0.5 * float(r_new @ r_new)
                if np.isfinite(cost_new) and cost_new < cost:
                    break
                failed += 1
            mu *= growth
            if mu > 1e16:
                return BlockLMResult(x, cost, r, normal, steps, evaluations, True,
                                     "no further decrease possible (at a minimum to machine "
                                     "precision)")
        x, step_scaled = x + step, step * scale
        if normal_new is None:
            r_new, normal_new = evaluate(x)
            evaluations += 1
        steps += 1
        decrease, cost_old = cost - cost_new, cost
        r, normal, cost = r_new, normal_new, cost_new
        scale = np.maximum(scale, np.sqrt(normal.diagonal()))
        mu = max(mu / growth, 1e-12)
        if decrease <= ftol * cost_old:
            message, success = "relative decrease of the cost below tolerance", True
            break
        if np.linalg.norm(step_scaled) <= xtol * (xtol + np.linalg.norm(x * scale)):
            message, success = "relative step below tolerance", True
            break
    return BlockLMResult(x, cost, r, normal, steps, evaluations, success, message)
