"""The configuration rule's search (:mod:`.config_rule`): the calibrated arm's solutions of
failed targets from the nominal closed form of every branch and from the solver's own
last iterate (:func:`search`, :func:`searched_blocks`), as :class:`Candidates` the rule
judges. A start that ends far outside the ranges by its first step's bound is not refined
(:class:`~.ik.stalls.FarOutside`) unless the rule reports it (:func:`refined_rough`).
Joints: URDF axes in IK solutions, controller axes (rad/m) in the candidates.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Iterator

import numpy as np

from .ik import closed_form_inverse, refine
from .ik.stalls import BehindAndStalled, CrawlingSettled, FarOutside

if TYPE_CHECKING:
    from .pose import Compensator

__all__ = ["Candidates", "search", "searched_blocks", "refined_rough", "rows_of",
           "turn_toward_ranges",
           "SEARCH_STEPS", "SEARCH_BLOCK", "SEARCH_POOL"]

SEARCH_STEPS = 60
"""Newton steps of each start of the search (a start that stalls stops after 20, or
after 5 where another start of its target is already closer: :mod:`.ik.stalls`)."""
SEARCH_BLOCK = 512
"""Failed targets whose starts and candidates are made together (nine starts each)."""
SEARCH_POOL = 4608
"""Starts of the search's Newton iterating at once, a finished start's place taken by the
next (:func:`~.ik.newton.pooled_newton`): bounds the Newton's memory as 512 targets of nine
starts did in one batch (13 MB; 2,048 targets held 45 MB), with far fewer passes: the
benchmark's 20,000 all-failing targets took 2,400 passes of about 0.6 ms each beyond their
rows' cost in blocks of 512 targets."""


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
    rough : (k, b) bool, a start set aside (:class:`~.ik.stalls.FarOutside`): reached
        outside the ranges by its first step's bound, ``q`` its first step's end (within
        the step of its end), errors NaN; :func:`refined_rough` refines it.
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
    rough: np.ndarray | None = None


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
    return Candidates(**{f: np.concatenate([getattr(p, f) for p in parts]) for f in _FIELDS},
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
    judged = _judged(comp, ends.q[part], reason, given)

    def cfx_of(q_ctrl: np.ndarray) -> int:
        return int(comp.confdata(robot.joints_from_controller(q_ctrl[None]))[0, 3])
    position = np.where(given, ends.position_error_m[part], np.inf)
    rotation = np.where(given, ends.rotation_error_rad[part], np.inf)
    return Candidates(q=judged.q.reshape(k, b, n), reached=judged.reached.reshape(k, b),
                      inside=judged.inside.reshape(k, b), reason=reason.reshape(k, b),
                      position_error_m=position.reshape(k, b),
                      rotation_error_rad=rotation.reshape(k, b),
                      excess=judged.excess.reshape(k, b), cfx=judged.cfx.reshape(k, b),
                      cfx_of=cfx_of, own=own, rough=ends.rough[part].reshape(k, b))


@dataclass(frozen=True)
class _Judged:
    """Ends as the rule sees them: ``q (r, n)`` controller axes turned toward the ranges,
    ``reached``, ``inside (r,)`` bool, ``excess (r,)`` and ``cfx (r,)`` (see
    :class:`Candidates`)."""

    q: np.ndarray
    reached: np.ndarray
    inside: np.ndarray
    excess: np.ndarray
    cfx: np.ndarray


def _judged(comp: Compensator, end_q: np.ndarray, reason: np.ndarray,
            given: np.ndarray) -> _Judged:
    """:class:`_Judged` of the ends ``end_q (r, n)`` (URDF rad) with the Newton's
    ``reason (r,)``, ``given (r,)`` where the start is some (NaN joints elsewhere)."""
    robot = comp.robot
    r, n = end_q.shape
    reached = np.isin(reason, ("ok", "singular"))
    q = np.full((r, n), np.nan)
    some = reached | given                # in one batch (each row's arithmetic its own)
    if np.any(some):
        q[some] = turn_toward_ranges(robot, robot.controller_from_joints(end_q[some]))
    inside = reached.copy()
    excess = np.full(r, np.inf)
    cfx = np.full(r, -1)
    if np.any(reached):
        inside[reached] = ~robot.outside_ranges(q[reached]).any(axis=1)
        excess[reached] = _excess(robot, q[reached])
        cfx[reached] = comp.confdata(robot.joints_from_controller(q[reached]))[:, 3]
    return _Judged(q=q, reached=reached, inside=inside, excess=excess, cfx=cfx)


@dataclass(frozen=True)
class _Ends:
    """Where the search's Newton ended from each start: ``q (r, n)`` URDF rad, ``reason
    (r,)``, ``position_error_m``, ``rotation_error_rad (r,)``, ``rough (r,)`` set aside
    (:class:`~.ik.stalls.FarOutside`)."""

    q: np.ndarray
    reason: np.ndarray
    position_error_m: np.ndarray
    rotation_error_rad: np.ndarray
    rough: np.ndarray


def _first_copies(starts: np.ndarray) -> np.ndarray:
    """(k * b,) for each start of ``starts (k, b, n)`` the flat index of the first start of
    its row with the same bits (itself where none before it): two branches of the closed
    form often stretch to the same joints for a pose out of reach."""
    k, b, n = starts.shape
    bits = np.ascontiguousarray(starts, dtype=float).view(np.int64)
    same = bits[:, :, None, 0] == bits[:, None, :, 0]                             # (k, b, b)
    for a in range(1, n):        # axis by axis: no (k, b, b, n) array, no reduction over n
        same &= bits[:, :, None, a] == bits[:, None, :, a]
    first = np.argmax(same, axis=2)          # (a start's bits equal its own: never none)
    return (first + b * np.arange(k)[:, None]).reshape(-1)


def _newton_once(comp: Compensator, flat: np.ndarray, desired: np.ndarray,
                 given: np.ndarray, first: np.ndarray, target: np.ndarray) -> _Ends:
    """Damped Newton of the calibrated arm from each given start of ``flat (r, n)`` (URDF
    rad) to ``desired[target] ((r,) indices into desired (k, 4, 4), non-decreasing)``,
    run once per ``first`` copy (:func:`_first_copies`; a copy's iterates are its first's)
    and not at all where not given ('unreachable'); :data:`SEARCH_POOL` starts iterate at
    once, and a start that has stalled behind another of its target stops early
    (:class:`~.ik.stalls.BehindAndStalled`: it cannot be the one kept). A start that ends
    outside the ranges by its first step's bound is set aside
    (:class:`~.ik.stalls.FarOutside`): 'ok', rough, at its first step's end."""
    r, n = flat.shape
    solve = np.flatnonzero(given & (first == np.arange(r)))
    ends = _Ends(q=np.full((r, n), np.nan), reason=np.full(r, "unreachable", dtype="<U14"),
                 position_error_m=np.full(r, np.inf), rotation_error_rad=np.full(r, np.inf),
                 rough=np.zeros(r, bool))
    if len(solve):
        robot = comp.robot
        park = FarOutside(robot.controller_from_joints, robot.controller_ranges,
                          np.array([joint.kind == "revolute" for joint in robot.joints]))
        result = refine(comp.real_flange_and_jacobian, flat[solve], desired[target[solve]],
                        None, 1e-9, 1e-9, SEARCH_STEPS, pool=SEARCH_POOL,
                        drop=BehindAndStalled(target[solve], steps=SEARCH_STEPS),
                        park=park)
        ends.q[solve], ends.reason[solve] = result.q, result.reason
        ends.position_error_m[solve] = result.position_error_m
        ends.rotation_error_rad[solve] = result.rotation_error_rad
        parked = solve[park.rows]
        ends.q[parked], ends.reason[parked], ends.rough[parked] = park.ends, "ok", True
        ends.position_error_m[parked] = ends.rotation_error_rad[parked] = np.nan
    return _Ends(q=ends.q[first], reason=ends.reason[first],
                 position_error_m=ends.position_error_m[first],
                 rotation_error_rad=ends.rotation_error_rad[first], rough=ends.rough[first])


def refined_rough(comp: Compensator, found: list[Candidates], picks: list[np.ndarray],
                  desired: list[np.ndarray]) -> list[Candidates]:
    """``found`` (blocks of candidates) with the rough candidates ``picks[i] (p, 2)``
    (target, start) of block i refined toward ``desired[i] (p, 4, 4)``, all in one Newton
    (from the rough joints: the same end, within the search's tolerance, as from the
    start; one that crawls where its target has another candidate that reached it stops:
    :class:`~.ik.stalls.CrawlingSettled`), and judged again (:class:`Candidates`: no
    longer rough)."""
    robot = comp.robot
    q = np.concatenate([f.q[p[:, 0], p[:, 1]] for f, p in zip(found, picks)])
    settled = np.concatenate([_settled(f, p) for f, p in zip(found, picks)])
    result = refine(comp.real_flange_and_jacobian, robot.joints_from_controller(q),
                    np.concatenate(desired), None, 1e-9, 1e-9, SEARCH_STEPS,
                    pool=SEARCH_POOL, drop=CrawlingSettled(settled))
    judged = _judged(comp, result.q, result.reason, np.ones(len(q), bool))
    out, at = [], 0
    for f, p in zip(found, picks):
        part = slice(at, at + len(p))
        at += len(p)
        if not len(p):
            out.append(f)
            continue
        fields = {name: getattr(f, name).copy() for name in _FIELDS}
        where = (p[:, 0], p[:, 1])
        for name in ("q", "reached", "inside", "excess", "cfx"):
            fields[name][where] = getattr(judged, name)[part]
        fields["reason"][where] = result.reason[part]
        fields["position_error_m"][where] = result.position_error_m[part]
        fields["rotation_error_rad"][where] = result.rotation_error_rad[part]
        fields["rough"][where] = False
        out.append(Candidates(**fields, cfx_of=f.cfx_of, own=f.own))
    return out


def _settled(found: Candidates, picks: np.ndarray) -> np.ndarray:
    """(p,) whether the target of each of ``picks (p, 2)`` (target, start) has another
    candidate than the one picked that reached it (refined, or rough: then refined in
    turn, should the rule pick it)."""
    other = found.reached.copy()
    other[picks[:, 0], picks[:, 1]] = False
    return np.any(other[picks[:, 0]], axis=1)


def rows_of(found: Candidates, rows: np.ndarray) -> Candidates:
    """The :class:`Candidates` of ``rows`` of ``found``."""
    return Candidates(**{name: getattr(found, name)[rows] for name in _FIELDS},
                      cfx_of=found.cfx_of, own=found.own)


_FIELDS = ("q", "reached", "inside", "reason", "position_error_m", "rotation_error_rad",
           "excess", "cfx", "rough")


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
