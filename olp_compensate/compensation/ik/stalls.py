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
within the margin of it, runs exactly as before. Where another start of its target has
reached it (converged), a start behind by the margin also stops once it crawls (its squared
error fell by less than :data:`CRAWL_RELATIVE` over the window): it could matter only by
converging within its steps left, and no start that converged in the benchmark's
all-failing module ever fell by less than 18 % over a window before it did; such crawls
(a start at some 4 mm that runs out its 60 steps) made the tail of each search's Newton.

Given the search's step budget, a start that crawls so (its squared error fell by less
than :data:`CRAWL_RELATIVE` over the window) behind the best start of its target that has
taken a step by the margin, and by more than :data:`OVERTAKE_FACTOR` times its own fall
over the window for every window left, stops too: on the 100,000-target realistic module
720 starts that ran out their 60 steps 0.1 to 2 mm behind (a quarter of the search's
Newton); every start it stopped there ended its 60 steps at least 1.3e-4 behind the best.
Its fall is not bounded (a crawl near the stretched arm once sped up 100-fold within 48
steps: a 1e-7 margin changed a row), hence the margin.

A start may also be set aside before its first step (:class:`FarOutside`): one whose first
Newton step is short and which lies outside an axis range (modulo whole turns) by far more
than that step, so that it ends outside the ranges, near its first step's end; the search
refines it only if the rule reports its joints (issue 32 item 3).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from .normal_equations import DAMPING, gauss_newton_steps

STALL_WINDOW = 5
"""Newton steps over which a stalled start's error has not fallen by :data:`STALL_RELATIVE`."""
STALL_RELATIVE = 1e-6
"""Relative fall of the squared error (m^2 + rad^2) over :data:`STALL_WINDOW` steps below
which a start has stalled (the solver's own stall test uses the same share per step)."""
BEHIND_MARGIN = 1e-4
"""How much worse (m + 0.1 rad) than the best start of its target a stalled start must be
to stop."""
CRAWL_RELATIVE = 0.01
"""Relative fall of the squared error over :data:`STALL_WINDOW` steps below which a start
behind one that reached its target stops."""
REACHED_SCORE = 1.1e-9
"""Score (m + 0.1 rad) at or below which a start has reached its target (1e-9 m, 1e-9 rad)."""


class BehindAndStalled:
    """The ``drop`` of :func:`~.newton.pooled_newton` for r starts of a search:
    ``groups (r,) int`` the target of each start, non-decreasing (a target's starts side by
    side). Called as they join (steps 0) and after each step with the starts iterating
    ``act (k,)``, the steps each has taken ``steps (k,)``, their squared errors ``cost
    (k,)`` and errors ``err (k, 6)``; returns (k,) bool, the starts to stop (see the
    module)."""

    def __init__(self, groups: np.ndarray, window: int = STALL_WINDOW,
                 relative: float = STALL_RELATIVE, margin: float = BEHIND_MARGIN,
                 steps: int | None = None):
        groups = np.asarray(groups, dtype=int)
        self.window, self.relative, self.margin = int(window), float(relative), float(margin)
        self.steps = steps                       # the starts' step budget, if hopeless ones stop
        r = len(groups)
        new = np.r_[True, groups[1:] != groups[:-1]] if r else np.zeros(0, bool)
        self.first = np.flatnonzero(new)         # the first start of each target
        self.target = np.cumsum(new) - 1         # each start's target, 0..g-1
        self.score = np.full(r, np.inf)          # each start's latest score (m + 0.1 rad)
        # its last squared errors and scores (a start's slot 1 is set once it has stepped)
        self.history = np.full((r, self.window, 2), np.inf)
        self.end = np.r_[self.first[1:], r]      # past the last start of each target
        self.width = int(np.max(self.end - self.first, initial=0))

    def __call__(self, steps: np.ndarray, act: np.ndarray, cost: np.ndarray,
                 err: np.ndarray) -> np.ndarray:
        position = np.sqrt(np.einsum("ij,ij->i", err[:, :3], err[:, :3]))
        rotation = np.sqrt(np.einsum("ij,ij->i", err[:, 3:], err[:, 3:]))
        score = position + 0.1 * rotation
        self.score[act] = score
        best = self._best(self.target[act])
        past = self._swap_history(act, steps, cost, score)
        before = past[:, 0]
        stalled = cost > (1.0 - self.relative) * before          # inf before: never
        slow = cost > (1.0 - CRAWL_RELATIVE) * before
        crawling = (best <= REACHED_SCORE) & slow
        behind = score - best
        stop = (stalled | crawling) & (behind > self.margin)
        some = np.flatnonzero(slow & ~stop & (behind > self.margin))
        if self.steps is not None and len(some):
            stop[some] = self._cannot_catch_up(act[some], steps[some], cost[some], past[some])
        return stop

    def _swap_history(self, act: np.ndarray, steps: np.ndarray, cost: np.ndarray,
                      score: np.ndarray) -> np.ndarray:
        """(k, 2) the squared errors and scores of starts ``act`` :attr:`window` steps
        ago, replaced in the history by ``cost`` and ``score`` (k,) of ``steps`` now."""
        at = act * self.window + steps % self.window      # (start, slot) in the history
        history = self.history.reshape(-1, 2)             # (a view)
        past = history[at]
        history[at, 0], history[at, 1] = cost, score
        return past

    def _best(self, target: np.ndarray) -> np.ndarray:
        """(k,) the least latest score of the starts of each of ``target (k,)``: only the
        targets from the least to the greatest of them are reduced (a pool holds a few
        hundred of a search's thousands)."""
        if not len(target):
            return np.zeros(0)
        lo, hi = target.min(), target.max()
        a = self.first[lo]
        return np.minimum.reduceat(self.score[a:self.end[hi]],
                                   self.first[lo:hi + 1] - a)[target - lo]

    def _cannot_catch_up(self, rows: np.ndarray, steps: np.ndarray, cost: np.ndarray,
                         past: np.ndarray) -> np.ndarray:
        """(c,) which crawling starts ``rows`` (``steps`` taken, squared errors ``cost``,
        ``past (c, 2)`` squared error and score a window ago) cannot catch up with the
        best start of their target that has taken a step (not one set aside as it
        joined, whose score is its start's) by :data:`BEHIND_MARGIN`
        (:func:`_hopeless`: their fall over the window the larger of their score's and
        their error norm's)."""
        target = self.target[rows]
        starts = self.first[target][:, None] + np.arange(self.width)
        mine = starts < self.end[target][:, None]
        starts = np.where(mine, starts, 0)
        stepped = mine & np.isfinite(self.history[starts, 1, 0])
        best = np.min(np.where(stepped, self.score[starts], np.inf), axis=1)
        score = self.score[rows]
        behind = score - best
        with np.errstate(invalid="ignore"):      # (inf - inf before a window: no stop)
            fall = np.fmax(past[:, 1] - score, np.sqrt(past[:, 0]) - np.sqrt(cost))
        return (behind > self.margin) & _hopeless(behind, fall, self.steps - steps,
                                                  self.window)


OVERTAKE_FACTOR = 100.0
"""How many times faster than over its last window a crawling start behind another of its
target would have to close in, for all its steps left, to catch it up, for it to stop
(:func:`_hopeless`)."""


def _hopeless(behind: np.ndarray, fall: np.ndarray, left: np.ndarray,
              window: int) -> np.ndarray:
    """(k,) starts ``behind (k,)`` (m + 0.1 rad) the best of their target that could not
    catch it up in their ``left (k,)`` steps at :data:`OVERTAKE_FACTOR` times the
    ``fall (k,)`` of their own score over the last ``window`` steps (inf before a whole
    window: never)."""
    return behind > OVERTAKE_FACTOR * np.maximum(fall, 0.0) * left / window


class CrawlingSettled:
    """The ``drop`` of :func:`~.newton.pooled_newton` for r starts refined one per target:
    stops a start whose squared error fell by less than :data:`CRAWL_RELATIVE` over
    :data:`STALL_WINDOW` steps where ``settled (r,)`` (its target has another candidate
    that reached it: the start matters only if it converges, see the module)."""

    def __init__(self, settled: np.ndarray):
        self.settled = np.asarray(settled, dtype=bool)
        self.history = np.full((len(self.settled), STALL_WINDOW), np.inf)

    def __call__(self, steps: np.ndarray, act: np.ndarray, cost: np.ndarray,
                 err: np.ndarray) -> np.ndarray:
        slot = steps % STALL_WINDOW
        before = self.history[act, slot]
        self.history[act, slot] = cost
        return self.settled[act] & (cost > (1.0 - CRAWL_RELATIVE) * before)


PARK_FACTOR = 4.0
"""How many times its first Newton step (controller axes, rad/m, largest axis) a start must
lie outside an axis range to be set aside: while the steps contract by at least half each,
the whole travel from the start is at most twice the first step."""
PARK_EXPLAINED = 1e-3
"""Share of a start's pose error its first step may leave unexplained (``|e - J d| /
|e|``): a start the Newton can take to its target solves ``J d = e`` (up to the damping);
one out of reach, at a stretched arm's singularity, takes a short step that leaves most of
its error (it is not in Newton's regime however short the step)."""
PARK_STEP = 0.05
"""rad/m: the largest first step (URDF and controller axes) of a start set aside: a start
this near its end is in Newton's quadratic regime (the search's converging starts move by
under 0.02 rad from the nominal closed form to the calibrated arm)."""


def past_ranges(q_ctrl: np.ndarray, ranges: np.ndarray, revolute: np.ndarray) -> np.ndarray:
    """(k,) how far (rad or m) ``q_ctrl (k, n)`` lies past the controller's ``ranges (n,
    2)``, the largest over axes, each ``revolute (n,)`` axis at its whole turn nearest the
    range: positive outside, else minus the room left to the nearest edge (an axis without
    a finite range, or a revolute one of a full turn or more, holds every value: -inf)."""
    q = np.asarray(q_ctrl, dtype=float)
    lo, hi = ranges[:, 0], ranges[:, 1]
    finite = np.isfinite(lo) & np.isfinite(hi)
    centre = np.where(finite, (lo + hi) / 2, 0.0)
    half = np.where(finite, (hi - lo) / 2, np.inf)
    plain = np.abs(q - centre) - half
    turned = np.abs(np.remainder(q - centre + np.pi, 2 * np.pi) - np.pi) - half
    past = np.where(revolute, np.where(half < np.pi, turned, -np.inf), plain)
    return np.max(np.where(finite, past, -np.inf), axis=-1, initial=-np.inf)


class FarOutside:
    """The ``park`` of :func:`~.newton.pooled_newton` for a search's starts: sets aside a
    start, as it joins, whose first Newton step ``d`` (Gauss-Newton, as
    :func:`~.newton.newton_step` takes it) is at most :data:`PARK_STEP`, explains its
    pose error (:data:`PARK_EXPLAINED`), and which lies outside an axis range (modulo
    whole turns) by more than :data:`PARK_FACTOR` times ``|d|`` (controller axes,
    largest): it ends outside the ranges, within ``|d|`` of its start plus ``d``.
    ``controller(q_urdf (k, n)) -> (k, n)`` the controller axes (linear), ``ranges (n,
    2)`` and ``revolute (n,)`` as :func:`past_ranges`. After the Newton, :attr:`rows` are
    the starts set aside (rows of the Newton) and :attr:`ends`
    (len(rows), n) URDF rad, each one's start plus its first step."""

    def __init__(self, controller: Callable[[np.ndarray], np.ndarray], ranges: np.ndarray,
                 revolute: np.ndarray, factor: float = PARK_FACTOR, step: float = PARK_STEP):
        self.controller, self.ranges = controller, np.asarray(ranges, dtype=float)
        self.revolute = np.asarray(revolute, dtype=bool)
        self.factor, self.step = float(factor), float(step)
        self._rows: list[np.ndarray] = []
        self._ends: list[np.ndarray] = []

    def __call__(self, rows: np.ndarray, q: np.ndarray, jac: np.ndarray,
                 err: np.ndarray) -> np.ndarray:
        """(k,) bool: which of the joining ``rows (k,)`` (at ``q (k, n)`` URDF rad, with
        Jacobians ``jac (k, 6, n)`` and pose errors ``err (k, 6)``) are set aside."""
        park = np.zeros(len(rows), bool)
        past = past_ranges(self.controller(q), self.ranges, self.revolute)
        some = np.flatnonzero(past > 0.0)
        if not len(some):
            return park
        d = gauss_newton_steps(jac[some], err[some], DAMPING)
        travel = np.max(np.abs(self.controller(d)), axis=1)
        left = err[some] - np.einsum("kij,kj->ki", jac[some], d)     # what d leaves
        far = ((np.max(np.abs(d), axis=1) <= self.step) & (travel <= self.step)
               & (np.linalg.norm(left, axis=1) <= PARK_EXPLAINED * np.linalg.norm(
                   err[some], axis=1))
               & (past[some] > self.factor * travel + 1e-9))
        park[some[far]] = True
        self._rows.append(rows[some[far]])
        self._ends.append(q[some[far]] + d[far])
        return park

    @property
    def rows(self) -> np.ndarray:
        return np.concatenate(self._rows) if self._rows else np.zeros(0, int)

    @property
    def ends(self) -> np.ndarray:
        n = len(self.ranges)
        return np.concatenate(self._ends) if self._ends else np.zeros((0, n))
