"""Why a pose was not compensated, in words and numbers: the status the configuration rule
gave it (:mod:`.config_rule`), the joints it came closest with and their configuration."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np

from .config_rule import decide, turn_toward_ranges
from .ik import IKSolution

if TYPE_CHECKING:
    from .pose import Compensator


@dataclass(frozen=True)
class FailureReport:
    """Why one target was not compensated, for a user to act on.

    note : the reason in words and numbers (axis, value, limit; configurations asked for
        and found; distance out of reach).
    joints : (n,) controller axes of the joints the rule keeps (see :mod:`.config_rule`),
        each revolute axis turned as near its range as it goes, rad/m (NaN if none).
    config : ABB confdata (cf1, cf4, cf6, cfx) of ``joints`` (None if none).
    status : the rule's status ('branch_changed', 'joint_limit', 'unreachable',
        'not_converged').
    """

    note: str
    joints: np.ndarray
    config: tuple[int, int, int, int] | None
    status: str = ""


def _config_words(conf) -> str:
    return "[" + ",".join(str(int(c)) for c in conf) + "]"


class _ConfigWords(dict):
    """:func:`_config_words` of configurations (tuples of ints), each written once: a
    batch's failed rows share a few dozen."""

    def __missing__(self, conf) -> str:
        words = self[conf] = _config_words(conf)
        return words


@dataclass(frozen=True)
class _Ranges:
    """A robot's controller ranges and URDF limits as the notes write them (deg, mm)."""

    robot: object
    ranges: np.ndarray          # (n, 2) controller ranges, rad/m
    lo: list                    # (n,) controller range ends, deg/mm
    hi: list
    jlo: list                   # (n,) URDF limits, deg/mm
    jhi: list
    unit: list

    @classmethod
    def of(cls, robot) -> "_Ranges":
        ranges = robot.controller_ranges
        lo, hi = (robot.to_degrees_or_mm(ranges[:, k][None])[0] for k in (0, 1))
        jlo = robot.to_degrees_or_mm(robot.lower_limits[None])[0]
        jhi = robot.to_degrees_or_mm(robot.upper_limits[None])[0]
        unit = ["deg" if j.kind == "revolute" else "mm" for j in robot.joints]
        return cls(robot, ranges, list(lo), list(hi), list(jlo), list(jhi), unit)


def _range_words(limits: _Ranges, q_ctrl: np.ndarray) -> list[list[str]]:
    """For each row of ``q_ctrl (k, n)`` (controller axes, rad/m), each axis outside the
    controller's range, and each URDF joint outside its limits, as words with values in deg
    (mm); all rows converted at once, the words written only where an axis is outside."""
    robot, ranges, unit = limits.robot, limits.ranges, limits.unit
    lo, hi = limits.lo, limits.hi
    out: list[list[str]] = [[] for _ in range(len(q_ctrl))]
    if not len(q_ctrl):
        return out
    listed = (q_ctrl < ranges[:, 0] - 1e-9) | (q_ctrl > ranges[:, 1] + 1e-9)
    joints = robot.joints_from_controller(q_ctrl)
    outside = ((joints < robot.lower_limits - 1e-9) | (joints > robot.upper_limits + 1e-9)) \
        & ~listed                          # an axis already named is not named again
    edge = robot.to_degrees_or_mm(q_ctrl)
    joint_edge = robot.to_degrees_or_mm(joints)
    rows, axes = np.nonzero(listed)                # row by row, axes in order
    for k, a, value in zip(rows.tolist(), axes.tolist(), edge[rows, axes].tolist()):
        past = lo[a] - value if value < lo[a] else value - hi[a]
        side = "below" if value < lo[a] else "above"
        out[k].append(f"axis {a + 1} = {value:.2f} {unit[a]} is {past:.2f} {unit[a]} "
                      f"{side} the controller's range {lo[a]:g}..{hi[a]:g} {unit[a]}")
    rows, axes = np.nonzero(outside)               # after a row's axes: its URDF joints
    for k, j, value in zip(rows.tolist(), axes.tolist(), joint_edge[rows, axes].tolist()):
        out[k].append(f"URDF {robot.joints[j].name} = {value:.2f} {unit[j]} is "
                      f"outside its limits {limits.jlo[j]:.2f}..{limits.jhi[j]:.2f} "
                      f"{unit[j]}")
    return out


ConfigWords = Callable[[int, "np.ndarray | None"], str]
"""``words(row, q_ctrl)``: the configuration of controller joints ``q_ctrl`` (rad) of row
``row`` in the program's own words, or, with ``q_ctrl`` None, the one the row asks for."""


def explain_failures(comp: Compensator, solution: IKSolution, desired_flange: np.ndarray,
                     confdata: np.ndarray | None, words: ConfigWords | None = None
                     ) -> list[FailureReport | None]:
    """A :class:`FailureReport` for each row of ``solution`` that failed (None for the
    others): ``desired_flange (m, 4, 4)`` the real flange poses solved for, ``confdata
    (m, 4)`` the configurations asked for (None: any); ``words`` names configurations
    (default: ABB confdata ``[cf1,cf4,cf6,cfx]``). A solution the configuration rule has
    not decided yet (:attr:`~.ik.IKSolution.on_asked` None) is decided on a copy first.
    The notes, by the rule's status (:mod:`.config_rule`):

    - 'joint_limit': each axis outside its range, its value (turned as near the range as
      it goes) and the range; whether those joints are on the configuration asked for
      (else which they are on); and that no configuration reaches it inside the ranges;
    - 'branch_changed': the configuration asked for and the one that reaches the target
      inside every range (the joints reported are that one's);
    - 'unreachable' / 'not_converged': how close the calibrated arm comes over every
      configuration (out of reach) or where the search stopped (not converged), in mm and
      degrees.
    """
    robot = comp.robot
    if solution.on_asked is None:
        solution = decide(comp, _copy(solution), desired_flange, confdata)
    failed = np.flatnonzero(~solution.success)
    out: list[FailureReport | None] = [None] * len(solution.success)
    q_ctrl_of, config_of = _turned_and_configs(comp, solution.q[failed])
    reasons = solution.reason[failed].astype(str).tolist()
    limited = np.flatnonzero((solution.reason[failed] == "joint_limit")
                             & np.all(np.isfinite(q_ctrl_of), axis=1))
    range_words: list[list[str]] = [[] for _ in reasons]
    for k, words_k in zip(limited.tolist(), _range_words(_Ranges.of(robot),
                                                          q_ctrl_of[limited])):
        range_words[k] = words_k
    on_asked = solution.on_asked[failed].tolist()
    dist_m = solution.position_error_m[failed].tolist()
    dist_rad = solution.rotation_error_rad[failed].tolist()
    written = _ConfigWords()
    asked_words = [None] * len(reasons) if words is not None or confdata is None else \
        [written[c] for c in map(tuple, np.asarray(confdata)[failed].tolist())]
    changed: dict = {}      # 'branch_changed' notes by (asked, found): a batch has a few dozen
    for row, reason, q_ctrl, config, asked, range_words_k, on_asked_k, dist_m_k, dist_rad_k \
            in zip(failed.tolist(), reasons, q_ctrl_of, config_of, asked_words, range_words,
                   on_asked, dist_m, dist_rad):
        has_q = config is not None
        if words is not None:
            asked = words(row, None) or None
            found = words(row, q_ctrl) if has_q else "none"
        else:
            found = written[config] if has_q else "none"
        note = changed.get((asked, found)) if reason == "branch_changed" else None
        if note is None:
            note = _note(reason, range_words_k, has_q, on_asked_k, asked, found, dist_m_k,
                         dist_rad_k)
            if reason == "branch_changed":
                changed[asked, found] = note
        out[row] = FailureReport(note=note, joints=q_ctrl, config=config, status=reason)
    return out


def _turned_and_configs(comp: Compensator, q_urdf: np.ndarray):
    """For joints ``q_urdf (k, n)`` (URDF axes; a row with NaN: none found) the controller
    joints turned toward the ranges (k, n), NaN rows where none, and each row's confdata
    as a tuple (None where none), in one batch."""
    robot = comp.robot
    has = np.all(np.isfinite(q_urdf), axis=1)
    q_ctrl = np.full((len(q_urdf), robot.n_joints), np.nan)
    configs: list = [None] * len(q_urdf)
    if np.any(has):
        q_ctrl[has] = turn_toward_ranges(robot, robot.controller_from_joints(q_urdf[has]))
        found = comp.confdata(robot.joints_from_controller(q_ctrl[has])).tolist()
        for k, conf in zip(np.flatnonzero(has).tolist(), found):
            configs[k] = tuple(conf)
    return q_ctrl, configs


def _note(reason: str, range_words: list[str], has_q: bool, on_asked: bool,
          asked: str | None, found: str, dist_m: float, dist_rad: float) -> str:
    """The report note of one failed row (see :func:`explain_failures`); ``range_words``
    the axes of its joints outside their ranges (:func:`_range_words`)."""
    if reason == "joint_limit":
        note = "; ".join(range_words if has_q else []) or "outside the joint limits"
        if on_asked:
            note += f" (on the configuration asked for, {asked})" if asked else ""
        else:
            note += f" (on configuration {found}" + (f", not the one asked for, {asked})"
                                                     if asked else ")")
        return note + "; no configuration reaches it inside the axis ranges"
    if reason == "branch_changed":
        where = f"asked for configuration {asked}, t" if asked else "T"
        return (f"{where}he calibrated arm reaches the target inside every axis range only "
                f"on another configuration: {found}")
    if not np.isfinite(dist_m):
        return "out of reach: no start of the search reaches near it on any configuration"
    if reason == "unreachable":
        return (f"out of reach on every configuration: the calibrated arm comes no closer "
                f"than {dist_m * 1e3:.2f} mm and {np.degrees(dist_rad):.3f} deg")
    return (f"not solved on any configuration: the search stopped short by "
            f"{dist_m * 1e3:.2f} mm and {np.degrees(dist_rad):.3f} deg (on configuration "
            f"{found})")


def _copy(solution: IKSolution) -> IKSolution:
    return IKSolution(q=solution.q.copy(), success=solution.success.copy(),
                      reason=solution.reason.copy(), iterations=solution.iterations.copy(),
                      position_error_m=solution.position_error_m.copy(),
                      rotation_error_rad=solution.rotation_error_rad.copy())
