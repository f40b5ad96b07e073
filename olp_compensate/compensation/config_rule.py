"""The configuration rule: the one status decision every compensation path makes.

A target the calibrated arm does not reach as asked (on the configuration the program
asks for, inside every controller axis range and URDF joint limit) gets exactly one of:

- ``ok``: a search from every configuration finds the asked configuration after all,
  inside every range (the solver had stopped short): compensated with those joints;
- ``branch_changed``: another configuration reaches the target inside every range; the
  joints reported are that configuration's (inside the ranges), and it is the one the
  note names (of those inside, the one of the asked branch nearest the asked joints where
  there is one: only a turn or a quadrant differs);
- ``joint_limit``: some configuration reaches the target, but only outside a range; the
  joints reported are those of the asked configuration where it reaches the target (else
  the ones nearest the ranges), each axis turned by whole turns as near its range as it
  goes;
- ``unreachable`` (the search stalls short of the pose from every start, or the reach
  bound proves it) or ``not_converged`` (a start was still closing in when its steps ran
  out): the joints of the closest approach.

:func:`decide` applies the rule to the failed rows of an :class:`~.ik.IKSolution`;
:func:`search` (:mod:`.rule_search`) is the shared work: damped Newton of the calibrated
arm from the nominal closed form of every branch (stretched where out of reach) and from
the solver's own last iterate, at most :data:`SEARCH_STEPS` steps each, the starts of
:data:`SEARCH_SPAN` rows iterating :data:`SEARCH_POOL` at a time (a start stalled behind
another of its row stops, a start far outside the ranges by its first step's bound is
refined only if the rule reports it: :mod:`.ik.stalls`). What
"the configuration asked for" means is a predicate (:data:`Asked`): ABB confdata here
(:func:`confdata_asked`), a dialect's written configuration in
:mod:`.dialect_program`. Joints: URDF axes in IK solutions, controller axes (rad/m) in the
search results.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np

from .ik import IKSolution
from .rule_search import (SEARCH_BLOCK, SEARCH_POOL, SEARCH_STEPS, Candidates, refined_rough,
                          rows_of, search, searched_blocks, turn_toward_ranges)

if TYPE_CHECKING:
    from .pose import Compensator

__all__ = ["Candidates", "search", "decide", "confdata_asked", "turn_toward_ranges",
           "QUADRANT_TOLERANCE", "SEARCH_STEPS", "SEARCH_BLOCK", "SEARCH_POOL"]

SEARCH_SPAN = 2048
"""Failed targets decided together: their starts' Newton runs in one pool (about 5 KB a
target held at once, the pool aside: 4,096 took 10 MB more at the peak of the benchmark's
realistic module, for 0.96x the retry's CPU)."""
QUADRANT_TOLERANCE = np.pi / 4
"""An axis 1, 4 or 6 this far (rad) outside the asked quadrant is still on the asked
configuration (as the solver's ``quadrant_tolerance``); the quadrant written is then the
one it is in (:mod:`.confdata`)."""

Asked = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
"""``asked(rows (k,) int, q (k, b, n) controller rad, usable (k, b) bool) -> (k, n)``: for
each of ``rows`` (indices into the batch solved), the joints among its usable candidates
that are on the configuration the program asks for (turned as the controller turns them),
NaN where none is."""


def confdata_asked(comp: Compensator, confdata: np.ndarray | None) -> Asked:
    """The :data:`Asked` predicate of ABB confdata ``(m, 4)`` of the batch (None: any
    configuration is the one asked for): same cfx, and axes 1, 4 and 6 each turned (inside its range)
    to within :data:`QUADRANT_TOLERANCE` of its asked quadrant. The first such candidate
    nearest zero is taken."""
    robot = comp.robot

    def asked(rows: np.ndarray, q: np.ndarray, usable: np.ndarray) -> np.ndarray:
        k, b, n = q.shape
        out = np.full((k, n), np.nan)
        flat = q.reshape(-1, n)
        match = usable.reshape(-1).copy()
        turned = flat.copy()
        if confdata is not None and np.any(match):
            want = np.repeat(np.asarray(confdata, dtype=int)[rows], b, axis=0)
            some = np.flatnonzero(match)
            turned[some], on = _on_quadrants(robot, flat[some], want[some, :3])
            cfx = comp.confdata(robot.joints_from_controller(turned[some]))[:, 3]
            match[some] = on & (cfx == want[some, 3])
        norm = np.where(match, np.nansum(turned ** 2, axis=1), np.inf).reshape(k, b)
        pick = np.argmin(norm, axis=1)
        found = np.isfinite(norm[np.arange(k), pick])
        out[found] = turned.reshape(k, b, n)[np.flatnonzero(found), pick[found]]
        return out

    return asked


def _on_quadrants(robot, q: np.ndarray, quadrants: np.ndarray):
    """``q (r, n)`` with axes 1, 4, 6 turned (inside their ranges) into the ``quadrants
    (r, 3)`` asked, give or take :data:`QUADRANT_TOLERANCE`; and (r,) bool where all
    three fit."""
    q = q.copy()
    ok = np.ones(len(q), bool)
    ranges = robot.controller_ranges
    quarter = np.pi / 2
    for j, a in enumerate((0, 3, 5)):
        lo = quadrants[:, j] * quarter - QUADRANT_TOLERANCE
        hi = (quadrants[:, j] + 1) * quarter + QUADRANT_TOLERANCE
        fit = np.zeros(len(q), bool)
        for turn in (0.0, -2 * np.pi, 2 * np.pi):
            value = q[:, a] + turn
            good = (~fit & (value >= lo) & (value <= hi)
                    & (value >= ranges[a, 0] - 1e-9) & (value <= ranges[a, 1] + 1e-9))
            q[good, a] = value[good]
            fit |= good
        ok &= fit
    return q, ok


def decide(comp: Compensator, solution: IKSolution, desired: np.ndarray,
           confdata: np.ndarray | None, asked: Asked | None = None) -> IKSolution:
    """``solution`` (of ``desired (m, 4, 4)`` on ``confdata (m, 4)`` or any) with each
    failed row's reason, joints (URDF) and errors set by the rule of this module, and
    :attr:`~.ik.IKSolution.on_asked` filled in (whether the joints kept are on the asked
    configuration). ``asked``: the predicate of the asked configuration (default
    :func:`confdata_asked` of ``confdata``). Changed in place and returned."""
    m = len(solution.success)
    if solution.on_asked is None:
        solution.on_asked = solution.success.copy()
    failed = np.flatnonzero(~solution.success)
    if not len(failed):
        return solution
    conf = None if confdata is None else np.asarray(confdata, dtype=int).reshape(m, 4)
    predicate = asked if asked is not None else confdata_asked(comp, conf)
    for start in range(0, len(failed), SEARCH_SPAN):
        span = failed[start:start + SEARCH_SPAN]
        own = solution.q[span].copy()
        own[solution.reason[span] == "unreachable"] = np.nan
        blocks = [(span[a:b], found) for a, b, found in searched_blocks(comp, desired[span], own)]
        _decide_span(comp, solution, blocks, desired, predicate)
    return solution


def _decide_span(comp: Compensator, solution: IKSolution,
                 blocks: list[tuple[np.ndarray, Candidates]], desired: np.ndarray,
                 predicate: Asked) -> None:
    """:func:`decide` of the failed rows of ``solution`` in ``blocks`` (rows, their search),
    changed in place: where the rule keeps a rough candidate (set aside by the search), it
    is refined and the rule applied again to its row (each round refines one more start of
    a row)."""
    rows = [failed for failed, _ in blocks]
    found = [f for _, f in blocks]
    kept = [_kept(comp, solution, r, f, predicate) for r, f in zip(rows, found)]
    while True:
        picks = [np.flatnonzero(k.has & f.rough[np.arange(len(r)), k.start])
                 for r, f, k in zip(rows, found, kept)]
        if not any(len(p) for p in picks):
            break
        found = refined_rough(comp, found, [np.stack([p, k.start[p]], 1) for p, k in
                                            zip(picks, kept)],
                              [desired[r[p]] for r, p in zip(rows, picks)])
        for r, f, k, p in zip(rows, found, kept, picks):
            if len(p):
                again = _kept(comp, solution, r[p], rows_of(f, p), predicate)
                for name in ("q", "reason", "start", "as_asked", "has"):
                    getattr(k, name)[p] = getattr(again, name)
    for r, f, k in zip(rows, found, kept):
        _write(comp, solution, r, f, k)


def _kept(comp: Compensator, solution: IKSolution, failed: np.ndarray, found: Candidates,
          predicate: Asked) -> _Kept:
    """What the rule keeps of the rows ``failed`` of ``solution``, searched: ``found``."""
    robot = comp.robot
    on_asked_q = predicate(failed, found.q, found.inside)
    picked = np.all(np.isfinite(on_asked_q), axis=1)
    if np.any(picked):       # a predicate turns axes as its controller does: still inside?
        outside = robot.outside_ranges(on_asked_q[picked]).any(axis=1)
        on_asked_q[np.flatnonzero(picked)[outside]] = np.nan
    # the same predicate, ranges aside: is the out-of-range solution the asked one?
    any_q = predicate(failed, found.q, found.reached)
    return _rule(comp, found, on_asked_q, any_q, solution.reason[failed] == "unreachable")


def _write(comp: Compensator, solution: IKSolution, failed: np.ndarray, found: Candidates,
           kept: _Kept) -> None:
    """The rows ``failed`` of ``solution`` set to what the rule ``kept`` of ``found``."""
    robot = comp.robot
    solution.reason[failed] = kept.reason
    solution.success[failed] = np.isin(kept.reason, ("ok", "singular"))
    solution.on_asked[failed] = kept.as_asked
    has = np.flatnonzero(kept.has)
    if len(has):
        solution.q[failed[has]] = robot.joints_from_controller(kept.q[has])
        solution.position_error_m[failed[has]] = found.position_error_m[has, kept.start[has]]
        solution.rotation_error_rad[failed[has]] = found.rotation_error_rad[has, kept.start[has]]


@dataclass(frozen=True)
class _Kept:
    """What the rule keeps of each of k rows: controller joints ``q (k, n)`` (written where
    ``has``), ``reason (k,)``, ``start (k,)`` the index of the start they came from, and
    ``as_asked (k,)`` whether they are on the asked configuration."""

    q: np.ndarray
    reason: np.ndarray
    start: np.ndarray
    as_asked: np.ndarray
    has: np.ndarray


def _rule(comp: Compensator, found: Candidates, on_asked: np.ndarray, asked_any: np.ndarray,
          own_unreachable: np.ndarray) -> _Kept:
    """The rule on every row of ``found`` at once; ``on_asked`` / ``asked_any`` (k, n) the
    predicate's joints among the in-range / reached candidates (NaN where none),
    ``own_unreachable (k,)`` where the solver's own verdict was 'unreachable'. In order: the
    asked configuration inside the ranges (its status), another inside
    ('branch_changed', :func:`_nearest_other`), one reaching outside ('joint_limit': the asked
    one where it reaches, else the one least past the ranges), else the closest approach."""
    q, inside, reached = found.q, found.inside, found.reached
    k = len(q)
    rows = np.arange(k)
    asked_in = np.all(np.isfinite(on_asked), axis=1)
    other_in = ~asked_in & np.any(inside, axis=1)
    limit = ~asked_in & ~other_in & np.any(reached, axis=1)
    asked_out = limit & np.all(np.isfinite(asked_any), axis=1)
    start = np.zeros(k, int)
    start[asked_in] = _index_of(q[asked_in], on_asked[asked_in], inside[asked_in])
    start[other_in] = _nearest_other(comp, found, np.flatnonzero(other_in), asked_any[other_in])
    start[asked_out] = _index_of(q[asked_out], asked_any[asked_out], reached[asked_out])
    least = limit & ~asked_out
    start[least] = np.argmin(np.where(reached[least], found.excess[least], np.inf), axis=1)
    rest = ~asked_in & ~other_in & ~limit
    score = found.position_error_m[rest] + 0.1 * found.rotation_error_rad[rest]
    score = np.where(np.isfinite(score), score, np.inf)
    start[rest] = np.argmin(score, axis=1)
    approach = np.zeros(k, bool)
    approach[rest] = np.isfinite(score[np.arange(len(score)), start[rest]])
    start[rest & ~approach] = 0
    reason = found.reason[rows, start].astype(object)
    reason[other_in] = "branch_changed"
    reason[limit] = "joint_limit"
    stopped = approach & (reason == "not_converged")
    reason[rest & (own_unreachable | ~stopped)] = "unreachable"
    kept_q = q[rows, start]
    kept_q[asked_in] = on_asked[asked_in]
    kept_q[asked_out] = asked_any[asked_out]
    return _Kept(q=kept_q, reason=reason, start=start, as_asked=asked_in | asked_out,
                 has=asked_in | other_in | limit | approach)


def _index_of(q: np.ndarray, chosen: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """(r,) for each row of ``q (r, b, n)`` the candidate (usable only) nearest ``chosen
    (r, n)`` modulo whole turns."""
    gap = np.remainder(q - chosen[:, None] + np.pi, 2 * np.pi) - np.pi
    score = np.where(usable, np.nansum(gap ** 2, axis=2), np.inf)
    return np.argmin(score, axis=1)


def _nearest_other(comp: Compensator, found: Candidates, rows: np.ndarray,
                   asked_any: np.ndarray) -> np.ndarray:
    """The in-range candidate to name for each of ``rows`` of ``found``: where the asked
    configuration reaches the pose outside a range (``asked_any (r, n)``), one of its
    branch (same cfx: only a turn or a quadrant differs) nearest those joints, else any
    nearest them; else the one nearest zero. Without ``asked_any``, the solver's own end on
    the asked configuration stands for it where it reached the pose."""
    q, inside, robot = found.q[rows], found.inside[rows], comp.robot
    target = np.array(asked_any, dtype=float, copy=True)
    if found.own:               # where the solver on the asked configuration ended
        ended = ~np.all(np.isfinite(target), axis=1) & found.reached[rows, -1]
        target[ended] = q[ended, -1]
    near = np.all(np.isfinite(target), axis=1)
    pick = np.argmin(np.where(inside, np.nansum(q ** 2, axis=2), np.inf), axis=1)
    if np.any(near):
        t, qn, ins = target[near], q[near], inside[near]
        cfx = comp.confdata(robot.joints_from_controller(t))[:, 3]
        same = ins & (found.cfx[rows[near]] == cfx[:, None])
        usable = np.where(np.any(same, axis=1)[:, None], same, ins)
        pick[near] = np.argmin(np.where(usable, np.nansum((qn - t[:, None]) ** 2, axis=2),
                                        np.inf), axis=1)
    return pick
