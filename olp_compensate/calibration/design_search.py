"""The search of :mod:`olp_compensate.calibration.pose_planning`: greedy D-optimal selection,
then Fedorov exchange passes, on rank-r updates of the design's information.

A design is a set of candidate poses, each a Jacobian block ``J_k`` (r rows, u unknowns,
unit-scaled columns); its information is ``M = sum_k J_k^T J_k``. See the planning module's
docstring for the criteria and their sources.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import DataError

REGULARIZATION = 1e-6
"""``eps`` of the greedy start ``M = eps I`` (unit-scaled columns: one pose adds ~1 per
unknown on the diagonal)."""
PASS_TOLERANCE = 1e-3
"""Exchange passes stop when one improves log det M by less than this (D), or trace(M^-1 A)
by less than this fraction (I): later passes gain well under 0.1 % of the error."""
def _inverse_and_log_det(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse (r, r, K) and log |det| (K,) of a batch of small matrices stored
    component-major (r, r, K); closed form for r = 3 (one measured point per pose)."""
    if s.shape[0] != 3:
        batch = s.transpose(2, 0, 1)
        return np.linalg.inv(batch).transpose(1, 2, 0), np.linalg.slogdet(batch)[1]
    (a, b, c), (d, e, f), (g, h, i) = s
    co = np.empty_like(s)
    co[0, 0], co[0, 1], co[0, 2] = e * i - f * h, c * h - b * i, b * f - c * e
    co[1, 0], co[1, 1], co[1, 2] = f * g - d * i, a * i - c * g, c * d - a * f
    co[2, 0], co[2, 1], co[2, 2] = d * h - e * g, b * g - a * h, a * e - b * d
    det = a * co[0, 0] + b * co[1, 0] + c * co[2, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        return co / det, np.log(np.abs(det))


def _times_transposed(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """x_k @ y_k^T for a batch of small matrices stored component-major, (a, b, K) and
    (c, b, K) -> (a, c, K): one vectorized multiply-add per inner index."""
    out = x[:, None, 0] * y[None, :, 0]
    for b in range(1, x.shape[1]):
        out += x[:, None, b] * y[None, :, b]
    return out


def _right(x: np.ndarray, m: np.ndarray) -> np.ndarray:
    """x_k @ m for a batch x (a, b, K) (component-major) and one matrix m (b, c)."""
    return np.matmul(m.T[None], x)


class Design:
    """State of a design over all K candidates: ``M^-1``, ``log det M`` and per candidate
    ``D_k = J_k M^-1 J_k^T``; with a test information ``A`` also ``phi = trace(M^-1 A)``,
    ``Q_k = J_k M^-1 A`` and ``E_k = J_k M^-1 A M^-1 J_k^T``. Updated by rank-r steps.
    Per-candidate arrays are component-major, candidates last: J and Q (r, u, K), D and E
    (r, r, K), so every batched product runs over contiguous vectors of length K."""

    def __init__(self, blocks: np.ndarray, chosen, information: np.ndarray | None):
        self.blocks = blocks
        self.r, self.u = blocks.shape[1:]
        self.jt = np.ascontiguousarray(blocks.transpose(1, 2, 0))
        self.information = information
        self.reset(chosen)

    def reset(self, chosen) -> None:
        """Recompute the state for ``chosen`` from scratch."""
        rows = self.blocks[list(chosen)].reshape(-1, self.u)
        info = REGULARIZATION * np.eye(self.u) + rows.T @ rows
        self.minv = np.linalg.inv(info)
        self.minv = 0.5 * (self.minv + self.minv.T)
        self.log_det = float(np.linalg.slogdet(info)[1])
        p = np.matmul(self.minv[None], self.jt)
        self.d = np.einsum("auk,buk->abk", p, self.jt)
        if self.information is not None:
            self.q = np.matmul(self.information[None], p)
            self.e = np.einsum("auk,buk->abk", self.q, p)
            self.phi = float(np.trace(self.minv @ self.information))

    def _step(self, k: int, sign: float):
        """The pieces of M += sign J_k^T J_k: (w, s, s_inv, c s_inv, c) with w = M^-1 J_k^T
        (u, r), s = I + sign J_k w (r, r), c = J w per candidate (r, r, K)."""
        b = self.blocks[k]
        w = self.minv @ b.T
        s = np.eye(self.r) + sign * (b @ w)
        s_inv = np.linalg.inv(s)
        c = np.matmul(w.T[None], self.jt)
        return w, s, s_inv, _right(c, s_inv), c

    def _moved(self, sign, w, s_inv, cs, c):
        """(D, E, phi) after the step, without touching the state (E, phi None without A)."""
        d = self.d - sign * _times_transposed(cs, c)
        if self.information is None:
            return d, None, None
        waw = w.T @ self.information @ w
        u = -sign * cs
        ut = _times_transposed(u, np.matmul(w.T[None], self.q))
        e = self.e + ut + ut.transpose(1, 0, 2) + _times_transposed(_right(u, waw), u)
        return d, e, self.phi - sign * float(np.trace(s_inv @ waw))

    def update(self, k: int, sign: float) -> None:
        """Add (sign +1) or remove (-1) candidate k: M += sign J_k^T J_k."""
        w, s, s_inv, cs, c = self._step(k, sign)
        self.d, e, phi = self._moved(sign, w, s_inv, cs, c)
        if self.information is not None:
            self.q += _right(-sign * cs, w.T @ self.information)
            self.e, self.phi = e, phi
        self.minv -= sign * (w @ s_inv @ w.T)
        self.log_det += float(np.linalg.slogdet(s)[1])

    def value(self, criterion: str) -> float:
        """The criterion to maximize: log det M, or -trace(M^-1 A)."""
        return self.log_det if criterion == "d" else -self.phi

    def values_after_adding(self, criterion: str) -> np.ndarray:
        """(K,) the criterion after adding each candidate."""
        if criterion == "d":
            return self._scores(criterion, self.log_det, self.d, None, None)
        return self._scores(criterion, self.log_det, self.d, self.e, self.phi)

    def values_after_swapping(self, j: int, criterion: str) -> np.ndarray:
        """(K,) the criterion after removing candidate j and adding each candidate."""
        w, s, s_inv, cs, c = self._step(j, -1.0)
        if criterion == "d":
            d, e, phi = self.d + _times_transposed(cs, c), None, None
        else:
            d, e, phi = self._moved(-1.0, w, s_inv, cs, c)
        return self._scores(criterion, self.log_det + float(np.linalg.slogdet(s)[1]), d, e, phi)

    def _scores(self, criterion, log_det, d, e, phi) -> np.ndarray:
        inverse, log_dets = _inverse_and_log_det(np.eye(self.r)[:, :, None] + d)
        if criterion == "d":
            return log_det + log_dets
        return -(phi - np.sum(inverse * e.transpose(1, 0, 2), axis=(0, 1)))


def too_close(candidates_deg: np.ndarray, pose: np.ndarray, min_distance: float) -> np.ndarray:
    """(K,) candidates whose every joint is within ``min_distance`` of ``pose``."""
    return np.max(np.abs(candidates_deg - pose), axis=1) < min_distance


@dataclass
class Selection:
    """The poses chosen so far: ``chosen`` candidate indices by position, ``taken`` (K,)
    flags, and with a minimum distance the (n, K) candidates too close to each position's
    pose (``in_units``: the candidates in degrees or mm)."""

    chosen: list[int]
    taken: np.ndarray
    near: np.ndarray
    in_units: np.ndarray
    min_distance_deg: float

    def blocked(self, skip: int | None = None) -> np.ndarray:
        """(K,) candidates too close to a chosen pose (but the one at position ``skip``)."""
        rows = self.near if skip is None else np.delete(self.near, skip, axis=0)
        return rows.any(axis=0)

    def place(self, pos: int, k: int) -> None:
        """Candidate ``k`` at position ``pos`` (appended when ``pos`` is the next one)."""
        if pos == len(self.chosen):
            self.chosen.append(k)
        else:
            self.taken[self.chosen[pos]] = False
            self.chosen[pos] = k
        self.taken[k] = True
        if self.min_distance_deg > 0:
            self.near[pos] = too_close(self.in_units, self.in_units[k], self.min_distance_deg)


def greedy_selection(blocks: np.ndarray, selection: Selection, n_poses: int) -> None:
    """Add ``n_poses`` of the candidates (``blocks``: their Jacobian blocks) one by one,
    each the best by the D criterion."""
    greedy = Design(blocks, [], None)
    for step in range(n_poses):
        scores = greedy.values_after_adding("d")
        scores[selection.taken | selection.blocked()] = -np.inf
        k = int(np.argmax(scores))
        if not np.isfinite(scores[k]):
            raise DataError(f"only {step} candidate poses are {selection.min_distance_deg:g} "
                            f"deg apart; lower the minimum distance or give more candidates")
        greedy.update(k, +1.0)
        selection.place(step, k)


def exchange_passes(blocks: np.ndarray, information: np.ndarray, selection: Selection,
                    stage: str, max_passes: int) -> int:
    """Passes of single-pose exchanges by criterion ``stage`` ('d', or 'i' with the test
    ``information``) until a pass changes nothing or gains less than ``PASS_TOLERANCE``;
    returns the swaps made."""
    design = Design(blocks, selection.chosen, information if stage == "i" else None)
    value = design.value(stage)
    swaps = 0
    for _ in range(max_passes):
        changed = False
        for pos, j in enumerate(selection.chosen):
            current = design.value(stage)
            scores = design.values_after_swapping(j, stage)
            mask = selection.taken.copy()
            mask[j] = False
            if selection.min_distance_deg > 0:
                mask |= selection.blocked(pos)
            scores[mask] = -np.inf
            k = int(np.argmax(scores))
            if k == j or scores[k] <= current + 1e-9 * max(1.0, abs(current)):
                continue
            design.update(j, -1.0)
            design.update(k, +1.0)
            selection.place(pos, k)
            swaps += 1
            changed = True
        before = value
        design.reset(selection.chosen)  # no drift from the rank-r updates
        value = design.value(stage)
        if not changed or value - before < PASS_TOLERANCE * (1.0 if stage == "d" else -before):
            break
    return swaps
