"""Which parameters to freeze for the combinations the data cannot separate, chosen stably.

The null space of the unit-scaled Jacobian (the right singular vectors below
``RANK_TOLERANCE``, an orthonormal basis ``N``, one row per unknown) says how much of each
unknown the data cannot see: the *claim* of unknown k is the norm of row k of ``N``, the
length of the unit vector e_k's projection on the null space (1: invisible, 0: fully
seen). Claims depend on the null space only, not on the basis an SVD happens to return, so
they move with the data by no more than the data's perturbation over the spectral gap.

The choice is the column-pivoted QR of ``N^T`` with one rule for ties: at each step the
largest claim wins, except that every claim within ``TIE_MARGIN`` of it ties, and among tied
unknowns the first in the preference order is frozen (:func:`choose_frozen`); the chosen
direction is then projected out of ``N`` and the claims recomputed. A pivoted QR of the
Jacobian itself decides the same question by the last few pivots' norms, near the rank
threshold, where measurement noise picks the winner: on the ASTL LINE session (a line path,
six inseparable combinations) it froze a different set in most 0.1 % weight perturbations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TIE_MARGIN = 0.1
"""Claims within this fraction of the largest remaining claim tie; the preference order
decides among them."""


@dataclass(frozen=True)
class FreezeChoice:
    """One frozen unknown: ``index`` (into the null basis' rows), its ``claim`` when chosen,
    the other unknowns it ``tied`` with (indices, preference order) and ``direction`` (the
    null-space combination it takes most part in: e_k projected on the null space)."""

    index: int
    claim: float
    tied: tuple[int, ...]
    direction: np.ndarray


def choose_frozen(null: np.ndarray, preference: np.ndarray) -> list[FreezeChoice]:
    """As many unknowns as ``null`` (n, d; orthonormal columns) has columns, whose freezing
    leaves the rest separable (the frozen rows of ``null`` are a regular d x d block), by
    largest claim with ties (within ``TIE_MARGIN``) going to the lowest ``preference`` (n,)
    (then the lowest index)."""
    work = np.array(null, dtype=float)
    order = np.lexsort((np.arange(len(work)), preference))  # preference, then index
    rank_of = np.empty(len(work), dtype=int)
    rank_of[order] = np.arange(len(work))
    out = []
    for _ in range(null.shape[1]):
        claims = np.linalg.norm(work, axis=1)
        best = claims.max()
        tied = np.flatnonzero(claims >= (1.0 - TIE_MARGIN) * best)
        tied = tied[np.argsort(rank_of[tied])]
        k = int(tied[0])
        row = work[k] / claims[k]
        work -= np.outer(work @ row, row)  # the rest of the null space, without e_k's part
        work[k] = 0.0
        out.append(FreezeChoice(index=k, claim=float(claims[k]),
                                tied=tuple(int(t) for t in tied[1:]),
                                direction=null @ null[k]))
    return out
