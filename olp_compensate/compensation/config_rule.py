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
:func:`search` is the shared work: damped Newton of the calibrated arm from the nominal
closed form of every branch (stretched where out of reach) and from the solver's own last
iterate, at most :data:`SEARCH_STEPS` steps each, the starts of :data:`SEARCH_SPAN` rows
iterating :data:`SEARCH_POOL` at a time (a start stalled behind another of its row stops:
:mod:`.ik.stalls`). What
"the configuration asked for" means is a predicate (:data:`Asked`): ABB confdata here
(:func:`confdata_asked`), a dialect's written configuration in
:mod:`.dialect_program`. Joints: URDF axes in IK solutions, controller axes (rad/m) in the
search results.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Iterator

import numpy as np

from .ik import IKSolution, closed_form_inverse, refine
from .ik.stalls import BehindAndStalled, FarOutside

if TYPE_CHECKING:
    from .pose import Compensator

__all__ = ["Candidates", "search", "decide", "confdata_asked", "turn_toward_ranges",
           "QUADRANT_TOLERANCE", "SEARCH_STEPS"]

SEARCH_STEPS = 60
"""Newton steps of each start of the search (a start that stalls stops after 20, or
after 5 where another start of its target is already closer: :mod:`.ik.stalls`)."""
SEARCH_BLOCK = 512
"""Failed targets whose starts and candidates are made together (nine starts each)."""
SEARCH_SPAN = 4096
"""Failed targets decided together: their starts' Newton runs in one pool (about 1.5 KB a
target held at once, the pool aside)."""
SEARCH_POOL = 4608
"""Starts of the search's Newton iterating at once, a finished start's place taken by the
next (:func:`~.ik.newton.pooled_newton`): bounds the Newton's memory as 512 targets of nine
starts did in one batch (13 MB; 2,048 targets held 45 MB), with far fewer passes: the
benchmark's 20,000 all-failing targets took 2,400 passes of about 0.6 ms each beyond their
rows' cost in blocks of 512 targets."""
QUADRANT_TOLERANCE = np.pi / 4
"""An axis 1, 4 or 6 this far (rad) outside the asked quadrant is still on the asked
configuration (as the solver's ``quadrant_tolerance``); the quadrant written is then the
one it is in (:mod:`.confdata`)."""

Asked = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
"""``asked(rows (k,) int, q (k, b, n) controller rad, usable (k, b) bool) -> (k, n)``: for
each of ``rows`` (indices into the batch solved), the joints among its usable candidates
that are on the configuration the program asks for (turned as the controller turns them),
NaN where none is."""


@dataclass(frozen=True)
class Candidates:
    """The calibrated arm's solutions of k poses from b starts each.

    q : (k, b, n) controller axes, rad/m, each revolute axis turned by whole turns as near
        its range as it goes (see :func:`turn_toward_ranges`); NaN where the start is none.
    reached : (k, b) bool, the pose reached (1e-9 m, 1e-9 rad).
    inside : (k, b) bool, reached and inside every controller range and URDF limit.
    reason : (k, b) str, the Newton's verdict ('ok', 'singular', 'unreachable',
        'not_converged').
    position_error_m, rotation_error_rad : (k, b) where each start stopped.
    excess : (k, b) how far past the ranges and limits (rad/m, summed over axes).
    cfx : (k, b) int, the configuration number (branch) of ``q``, -1 where not reached.
    cfx_of : controller joints (n,) -> their configuration number.
    own : whether the last start is the solver's own iterate.
    """

    q: np.ndarray
    reached: np.ndarray
    inside: np.ndarray
    reason: np.ndarray
    position_error_m: np.ndarray
    rotation_error_rad: np.ndarray
    excess: np.ndarray
    cfx: np.ndarray
    cfx_of: Callable[[np.ndarray], int]
    own: bool = False


def turn_toward_ranges(robot, q_ctrl: np.ndarray) -> np.ndarray:
    """``q_ctrl (..., n)`` rad with each revolute axis turned by whole turns into its
    controller range (the turn nearest zero where several fit), or, where no turn fits and
    for axes without a finite range, wrapped to [-180, 180) deg. A value already inside its
    range and under :data:`_UNTURNED` in size stays (plus 0.0, as the turns add it): any
    other turn is over 2 pi - 3 > 3 from zero, so it is the one nearest zero; only the
    others try the turns."""
    q = np.array(q_ctrl, dtype=float, copy=True)
    ranges = robot.controller_ranges
    turns = 2 * np.pi * np.arange(-3, 4)
    for a, joint in enumerate(robot.joints):
        if joint.kind != "revolute":
            continue
        lo, hi = ranges[a]
        if not (np.isfinite(lo) and np.isfinite(hi)):
            q[..., a] = (q[..., a] + np.pi) % (2 * np.pi) - np.pi
            continue
        value = q[..., a]
        stays = (np.abs(value) < _UNTURNED) & (value >= lo - 1e-9) & (value <= hi + 1e-9)
        out = value + 0.0
        if not np.all(stays):
            other = ~stays
            out[other] = _turned(value[other], turns, lo, hi)
        q[..., a] = out
    return q


_UNTURNED = 3.0
"""rad: an axis value inside its range and smaller than this is its own nearest turn to
zero (every other turn is at least 2 pi - 3 from zero)."""


def _turned(value: np.ndarray, turns: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """``value (r,)`` rad turned by one of ``turns`` into [lo, hi] (the one nearest zero),
    else wrapped to [-pi, pi)."""
    values = value[:, None] + turns                                   # (r, 7)
    inside = (values >= lo - 1e-9) & (values <= hi + 1e-9)
    pick = np.argmin(np.where(inside, np.abs(values), np.inf), axis=-1)
    turned = np.take_along_axis(values, pick[:, None], axis=-1)[:, 0]
    wrapped = (value + np.pi) % (2 * np.pi) - np.pi
    return np.where(np.any(inside, axis=-1), turned, wrapped)


def search(comp: Compensator, desired: np.ndarray, own: np.ndarray | None = None
           ) -> Candidates:
    """The calibrated arm's solutions of ``desired (k, 4, 4)`` (flange, base frame, m):
    damped Newton from the nominal closed form of every branch (stretched where the
    nominal arm falls short) and from ``own (k, n)`` (URDF rad: the solver's last iterate,
    NaN where none), at most :data:`SEARCH_STEPS` steps each, all in one batch
    (:func:`searched_blocks`, joined)."""
    parts = [found for _, _, found in searched_blocks(comp, desired, own)]
    if len(parts) == 1:
        return parts[0]
    fields = ("q", "reached", "inside", "reason", "position_error_m", "rotation_error_rad",
              "excess", "cfx")
    return Candidates(**{f: np.concatenate([getattr(p, f) for p in parts]) for f in fields},
                      cfx_of=parts[0].cfx_of, own=parts[0].own)


def searched_blocks(comp: Compensator, desired: np.ndarray, own: np.ndarray | None = None
                    ) -> Iterator[tuple[int, int, Candidates]]:
    """:func:`search` of ``desired (k, 4, 4)`` (and ``own``) as ``(a, b, candidates of
    rows a:b)`` for blocks of :data:`SEARCH_BLOCK` rows: the starts and candidates are
    made block by block (arrays that stay in the processor's cache), the Newton of every
    start of every block runs :data:`SEARCH_POOL` at a time (a finished start's place
    taken by the next, a start stalled behind another of its target stopped); a block's
    candidates are made when the caller asks for them."""
    k = len(desired)
    blocks = [(a, min(a + SEARCH_BLOCK, k)) for a in range(0, k, SEARCH_BLOCK)]
    starts = []
    for a, b in blocks:
        block = closed_form_inverse(comp.family, desired[a:b], clip=True)      # (r, 8, n)
        if own is not None:
            block = np.concatenate([block, np.asarray(own[a:b], dtype=float)[:, None]], 1)
        starts.append(block)
    if not blocks:
        return
    width, n = starts[0].shape[1], starts[0].shape[2]
    flat = np.concatenate([block.reshape(-1, n) for block in starts])
    first = np.concatenate([_first_copies(block) + a * width
                            for block, (a, _) in zip(starts, blocks)])
    given = np.all(np.isfinite(flat), axis=1)
    target = np.repeat(np.arange(k), width)
    ends = _newton_once(comp, flat, desired, given, first, target)
    for a, b in blocks:
        yield a, b, _candidates(comp, ends, given, slice(a * width, b * width), b - a, width,
                                own is not None)


def _candidates(comp: Compensator, ends: _Ends, given: np.ndarray, part: slice, k: int,
                b: int, own: bool) -> Candidates:
    """The :class:`Candidates` of the k targets (b starts each) whose starts are the flat
    rows ``part`` of the search's Newton ``ends`` (``given``: the starts that are some)."""
    robot = comp.robot
    given = given[part]
    n = ends.q.shape[1]
    reason = np.where(given, ends.reason[part], "unreachable")
    reached = np.isin(reason, ("ok", "singular"))
    end_q = ends.q[part]
    q = np.full((k * b, n), np.nan)
    if np.any(reached):
        q[reached] = turn_toward_ranges(robot, robot.controller_from_joints(end_q[reached]))
    q[~reached & given] = turn_toward_ranges(
        robot, robot.controller_from_joints(end_q[~reached & given]))
    inside = reached.copy()
    excess = np.full(k * b, np.inf)
    cfx = np.full(k * b, -1)
    if np.any(reached):
        inside[reached] = ~robot.outside_ranges(q[reached]).any(axis=1)
        excess[reached] = _excess(robot, q[reached])
        cfx[reached] = comp.confdata(robot.joints_from_controller(q[reached]))[:, 3]

    def cfx_of(q_ctrl: np.ndarray) -> int:
        return int(comp.confdata(robot.joints_from_controller(q_ctrl[None]))[0, 3])
    position = np.where(given, ends.position_error_m[part], np.inf)
    rotation = np.where(given, ends.rotation_error_rad[part], np.inf)
    return Candidates(q=q.reshape(k, b, n), reached=reached.reshape(k, b),
                      inside=inside.reshape(k, b), reason=reason.reshape(k, b),
                      position_error_m=position.reshape(k, b),
                      rotation_error_rad=rotation.reshape(k, b), excess=excess.reshape(k, b),
                      cfx=cfx.reshape(k, b), cfx_of=cfx_of, own=own)


@dataclass(frozen=True)
class _Ends:
    """Where the search's Newton ended from each start: ``q (r, n)`` URDF rad, ``reason
    (r,)``, ``position_error_m``, ``rotation_error_rad (r,)``."""

    q: np.ndarray
    reason: np.ndarray
    position_error_m: np.ndarray
    rotation_error_rad: np.ndarray


def _first_copies(starts: np.ndarray) -> np.ndarray:
    """(k * b,) for each start of ``starts (k, b, n)`` the flat index of the first start of
    its row with the same bits (itself where none before it): two branches of the closed
    form often stretch to the same joints for a pose out of reach."""
    k, b, n = starts.shape
    bits = np.ascontiguousarray(starts, dtype=float).view(np.int64)
    same = np.all(bits[:, :, None, :] == bits[:, None, :, :], axis=-1)          # (k, b, b)
    first = np.where(np.any(same, axis=2), np.argmax(same, axis=2), np.arange(b))
    return (first + b * np.arange(k)[:, None]).reshape(-1)


def _newton_once(comp: Compensator, flat: np.ndarray, desired: np.ndarray,
                 given: np.ndarray, first: np.ndarray, target: np.ndarray) -> _Ends:
    """Damped Newton of the calibrated arm from each given start of ``flat (r, n)`` (URDF
    rad) to ``desired[target] ((r,) indices into desired (k, 4, 4), non-decreasing)``,
    run once per ``first`` copy (:func:`_first_copies`; a copy's iterates are its first's)
    and not at all where not given ('unreachable'); :data:`SEARCH_POOL` starts iterate at
    once, and a start that has stalled behind another of its target stops early
    (:class:`~.ik.stalls.BehindAndStalled`: it cannot be the one kept). A start that ends
    outside the ranges by its first step's bound (:class:`~.ik.stalls.FarOutside`) is set
    aside and run only where no end of its target is inside the ranges; elsewhere it can
    be neither reported nor change the status, and it ends 'ok' at its start plus its
    first step (errors NaN: not refined)."""
    r, n = flat.shape
    solve = np.flatnonzero(given & (first == np.arange(r)))
    ends = _Ends(q=np.full((r, n), np.nan), reason=np.full(r, "unreachable", dtype="<U14"),
                 position_error_m=np.full(r, np.inf), rotation_error_rad=np.full(r, np.inf))
    if len(solve):
        robot = comp.robot
        revolute = np.array([joint.kind == "revolute" for joint in robot.joints])
        park = FarOutside(robot.controller_from_joints, robot.controller_ranges, revolute,
                          target[solve])
        _refined(comp, ends, solve, flat, desired, target, park)
        parked = solve[park.rows]
        decided = _inside_somewhere(comp, ends, target, parked)
        ends.q[parked[decided]] = park.ends[decided]
        ends.reason[parked[decided]] = "ok"
        ends.position_error_m[parked[decided]] = np.nan
        ends.rotation_error_rad[parked[decided]] = np.nan
        if not np.all(decided):
            _refined(comp, ends, parked[~decided], flat, desired, target, None)
    return _Ends(q=ends.q[first], reason=ends.reason[first],
                 position_error_m=ends.position_error_m[first],
                 rotation_error_rad=ends.rotation_error_rad[first])


def _refined(comp: Compensator, ends: _Ends, rows: np.ndarray, flat: np.ndarray,
             desired: np.ndarray, target: np.ndarray, park: FarOutside | None) -> None:
    """The search's Newton of the starts ``flat[rows]`` toward ``desired[target[rows]]``,
    written into ``ends`` at ``rows``."""
    result = refine(comp.real_flange_and_jacobian, flat[rows], desired[target[rows]], None,
                    1e-9, 1e-9, SEARCH_STEPS, pool=SEARCH_POOL,
                    drop=BehindAndStalled(target[rows]), park=park)
    ends.q[rows], ends.reason[rows] = result.q, result.reason
    ends.position_error_m[rows] = result.position_error_m
    ends.rotation_error_rad[rows] = result.rotation_error_rad


def _inside_somewhere(comp: Compensator, ends: _Ends, target: np.ndarray,
                      rows: np.ndarray) -> np.ndarray:
    """(len(rows),) bool: whether the target of each of ``rows`` has an end that reached
    it inside every range and limit (as :func:`_candidates` judges it)."""
    robot = comp.robot
    reached = np.flatnonzero(np.isin(ends.reason, ("ok", "singular")))
    if not len(rows) or not len(reached):
        return np.zeros(len(rows), bool)
    q = turn_toward_ranges(robot, robot.controller_from_joints(ends.q[reached]))
    inside = reached[~robot.outside_ranges(q).any(axis=1)]
    return np.isin(target[rows], target[inside])


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
        for a, b, found in searched_blocks(comp, desired[span], own):
            _decide_rows(comp, solution, span[a:b], found, predicate)
    return solution


def _decide_rows(comp: Compensator, solution: IKSolution, failed: np.ndarray,
                 found: Candidates, predicate: Asked) -> None:
    """:func:`decide` of the rows ``failed`` of ``solution`` (changed in place), searched:
    ``found``."""
    robot = comp.robot
    on_asked_q = predicate(failed, found.q, found.inside)
    picked = np.all(np.isfinite(on_asked_q), axis=1)
    if np.any(picked):       # a predicate turns axes as its controller does: still inside?
        outside = robot.outside_ranges(on_asked_q[picked]).any(axis=1)
        on_asked_q[np.flatnonzero(picked)[outside]] = np.nan
    # the same predicate, ranges aside: is the out-of-range solution the asked one?
    any_q = predicate(failed, found.q, found.reached)
    kept = _rule(comp, found, on_asked_q, any_q, solution.reason[failed] == "unreachable")
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


def _excess(robot, q_ctrl: np.ndarray) -> np.ndarray:
    """(r,) how far (rad/m, summed over axes) ``q_ctrl (r, n)`` lies past the controller's
    ranges and the URDF limits."""
    ranges = robot.controller_ranges
    past = np.maximum(np.maximum(ranges[:, 0] - q_ctrl, q_ctrl - ranges[:, 1]), 0.0)
    joints = robot.joints_from_controller(q_ctrl)
    past_urdf = np.maximum(np.maximum(robot.lower_limits - joints,
                                      joints - robot.upper_limits), 0.0)
    return np.nansum(np.nan_to_num(past, posinf=0.0) + np.nan_to_num(past_urdf, posinf=0.0),
                     axis=1)
