"""When a start of a multi-start search may stop early: :class:`BehindAndStalled`.

A search runs damped Newton (:func:`~.newton.pooled_newton`) from several starts per target
and keeps, per target, the start that reaches it or else the one that comes closest
(score: position error, m, plus 0.1 times the rotation error, rad). A start that has
stalled (its squared error fell by less than :data:`STALL_RELATIVE` of itself over the last
:data:`STALL_WINDOW` steps) while another start of its target is already
:data:`BEHIND_MARGIN` closer cannot become the one kept: in the last steps of a stall the
error falls by about 1e-6 m in all (measured on 2,000 stalled starts of the benchmark's
all-failing module), 100 times less than the margin. It leaves the batch, reason
'unreachable' (stalled), where the solver would have given it up only after 20 steps in a
row without progress (:data:`~.newton._STALL_STEPS`). The start kept, and every start
within the margin of it, runs exactly as before.
"""

from __future__ import annotations

import numpy as np

STALL_WINDOW = 5
"""Newton steps over which a stalled start's error has not fallen by :data:`STALL_RELATIVE`."""
STALL_RELATIVE = 1e-6
"""Relative fall of the squared error (m^2 + rad^2) over :data:`STALL_WINDOW` steps below
which a start has stalled (the solver's own stall test uses the same share per step)."""
BEHIND_MARGIN = 1e-4
"""How much worse (m + 0.1 rad) than the best start of its target a stalled start must be
to stop."""


class BehindAndStalled:
    """The ``drop`` of :func:`~.newton.pooled_newton` for r starts of a search:
    ``groups (r,) int`` the target of each start, non-decreasing (a target's starts side by
    side). Called after each step with the starts iterating ``act (k,)``, the steps each
    has taken ``steps (k,)``, their squared errors ``cost (k,)`` and errors ``err (k, 6)``;
    returns (k,) bool, the starts to stop (see the module)."""

    def __init__(self, groups: np.ndarray, window: int = STALL_WINDOW,
                 relative: float = STALL_RELATIVE, margin: float = BEHIND_MARGIN):
        groups = np.asarray(groups, dtype=int)
        self.window, self.relative, self.margin = int(window), float(relative), float(margin)
        r = len(groups)
        new = np.r_[True, groups[1:] != groups[:-1]] if r else np.zeros(0, bool)
        self.first = np.flatnonzero(new)         # the first start of each target
        self.target = np.cumsum(new) - 1         # each start's target, 0..g-1
        self.score = np.full(r, np.inf)          # each start's latest score (m + 0.1 rad)
        self.history = np.full((r, self.window), np.inf)   # its last squared errors

    def __call__(self, steps: np.ndarray, act: np.ndarray, cost: np.ndarray,
                 err: np.ndarray) -> np.ndarray:
        position = np.sqrt(np.einsum("ij,ij->i", err[:, :3], err[:, :3]))
        rotation = np.sqrt(np.einsum("ij,ij->i", err[:, 3:], err[:, 3:]))
        self.score[act] = position + 0.1 * rotation
        best = np.minimum.reduceat(self.score, self.first)[self.target[act]]
        slot = steps % self.window
        before = self.history[act, slot]          # the squared error `window` steps ago
        self.history[act, slot] = cost
        stalled = cost > (1.0 - self.relative) * before          # inf before: never
        return stalled & (self.score[act] > best + self.margin)
