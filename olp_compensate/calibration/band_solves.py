"""The band scan's linear algebra (:mod:`.cyclic_scan`): symmetric solves of its per-fold
normal equations, factored once per matrix and shared by every fit that uses the same
matrix (the candidates of a round share the training sets, the kept bands' penalties and
the geometry's columns), and the band's problem with the other unknowns profiled out.
Everything is in the band scan's unit-scaled columns (dimensionless Gram matrices)."""

from __future__ import annotations

import numpy as np
from scipy import linalg


class Factored:
    """A symmetric positive (semi-)definite matrix, factored once: Cholesky, or least
    squares (rcond 1e-12) when it is singular."""

    def __init__(self, matrix: np.ndarray):
        self.matrix = None
        try:
            self.factor = linalg.cho_factor(matrix)
        except linalg.LinAlgError:
            self.factor, self.matrix = None, matrix

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """matrix^-1 rhs (rhs a vector or columns)."""
        if self.factor is None:
            return np.linalg.lstsq(self.matrix, rhs, rcond=1e-12)[0]
        return linalg.cho_solve(self.factor, rhs)


class Recent(dict):
    """A dict keeping the ``size`` entries used last (factorizations: a few hundred kB
    each; a round of candidates reuses its base's and its own)."""

    def __init__(self, size: int = 96):
        super().__init__()
        self.size = size

    def get_or_make(self, key, make):
        """The entry of ``key``, made by ``make()`` when absent."""
        if key in self:
            value = self.pop(key)
        else:
            value = make()
            while len(self) >= self.size:
                del self[next(iter(self))]
        self[key] = value
        return value


class ProfiledBand:
    """The band's problem on one training set with the other unknowns profiled out:
    ``c(lam) = -V (V'h / (d + lam))`` and ``u = -(y + X c)``; ``factor``: the
    factorization of the other unknowns' block ``gram[:nu, :nu] + diag(penalty_u)`` plus
    a 1e-12 relative jitter (:func:`other_block`), shared by every band tested beside the
    same unknowns."""

    def __init__(self, gram: np.ndarray, rhs: np.ndarray, nu: int, factor):
        guc = gram[:nu, nu:]
        self.x_uc = linalg.cho_solve(factor, guc)
        self.y = linalg.cho_solve(factor, rhs[:nu])
        schur = gram[nu:, nu:] - guc.T @ self.x_uc
        self.d, self.v = np.linalg.eigh(0.5 * (schur + schur.T))
        self.d = np.clip(self.d, 0.0, None)
        self.hv = self.v.T @ (rhs[nu:] - guc.T @ self.y)

    def solution(self, lam: float) -> np.ndarray:
        c = -self.v @ (self.hv / (self.d + lam))
        return np.concatenate([-(self.y + self.x_uc @ c), c])

    def dof(self, lam: float) -> float:
        return float(np.sum(self.d / (self.d + lam)))


def other_block(gram_uu: np.ndarray, penalty_u: np.ndarray):
    """The Cholesky factor of the other unknowns' block of :class:`ProfiledBand`:
    ``gram_uu + diag(penalty_u)`` with 1e-12 of its mean diagonal added."""
    nu = len(penalty_u)
    guu = gram_uu + np.diag(penalty_u)
    guu[np.diag_indices(nu)] += 1e-12 * np.trace(guu) / max(nu, 1)
    return linalg.cho_factor(guu)

