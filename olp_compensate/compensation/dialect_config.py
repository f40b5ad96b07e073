"""The configuration a six-number-target program asks, on every path: the branch each
language's nominal controller takes for the written configuration
(:attr:`~.dialect_rules.DialectRules.choose`), the configuration rule's predicate built from
it, the words a report gives a configuration, and the rule on poses no branch was chosen for
(:func:`decide_unchosen`, also the service's)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..programs.pose_dialects import PoseTarget
from .config_rule import decide
from .dialect_rules import ArmGeometry, DialectRules
from .failures import explain_failures
from .ik import IKSolution, closed_form_inverse
from .pose import Compensator

_GEOMETRY: dict[int, ArmGeometry] = {}


def geometry_of(comp: Compensator) -> ArmGeometry:
    """The :class:`ArmGeometry` of the compensator's robot (one per robot, kept)."""
    key = id(comp.robot)
    if key not in _GEOMETRY:
        _GEOMETRY[key] = ArmGeometry(comp.robot)
    return _GEOMETRY[key]


def choose_all(comp: Compensator, geometry: ArmGeometry, rules: DialectRules,
                jobs: list, requested: np.ndarray) -> tuple[np.ndarray, list]:
    """The controller joints (m, n) the dialect's nominal controller takes for each job
    (NaN where no branch has the written configuration), in program order, and the joints
    before each (None for the first)."""
    robot = geometry.robot
    branches = closed_form_inverse(comp.family, requested)                  # (m, 8, n) URDF
    m, k, n = branches.shape
    branches_ctrl = robot.controller_from_joints(branches.reshape(-1, n)).reshape(m, k, n)
    geometry.prepare(branches_ctrl)          # the configuration words of every branch at once
    chosen = np.full((m, n), np.nan)
    previous_of: list = [None] * m
    previous = None
    for i, job in enumerate(jobs):
        previous_of[i] = previous
        q, _, *note = rules.choose(geometry, job.target, branches_ctrl[i], previous)
        if note and note[0]:
            job.note = "; ".join(x for x in (note[0], job.note) if x)
        if q is not None:
            chosen[i] = q
            previous = q
    return chosen, previous_of


@dataclass(frozen=True)
class _Asked:
    """What the rule's predicates read of a pose that is no program's target."""

    target: PoseTarget


def decide_unchosen(comp: Compensator, rules: DialectRules, targets: list[PoseTarget],
                    previous_of: list, desired: np.ndarray):
    """The configuration rule on dialect poses for which no nominal branch has the written
    configuration (``targets``: their configuration numbers; ``previous_of``: the
    controller joints of the pose before each, or None; ``desired`` (k, 4, 4): the real
    flange poses, base frame, m), as olp-fix decides them in a program:
    ``(solution, failures)``; where ``solution.success`` the calibrated arm reaches the pose
    on the asked configuration inside the ranges (its joints stand in for the nominal
    ones), else ``failures[r]`` holds the status and note."""
    geometry = geometry_of(comp)
    asked_of = [_Asked(t) for t in targets]
    rows = np.arange(len(targets))
    asked = dialect_asked(rules, geometry, asked_of, previous_of)
    found = rule_alone(comp, desired, on_rows(asked, rows))
    words = config_namer(rules, geometry, asked_of)
    return found, explain_failures(comp, found, desired, None, on_rows(words, rows))


def on_rows(function, rows: np.ndarray):
    """``function`` of rows of a sub-batch, called with the rows of the whole batch."""
    def on(sub, *args):
        return function(rows[sub], *args)
    return on


def rule_alone(comp: Compensator, desired: np.ndarray, asked) -> IKSolution:
    """The configuration rule on poses no nominal branch was chosen for (no solve on a
    branch first: the search is the whole answer)."""
    k, n = len(desired), comp.robot.n_joints
    blank = IKSolution(q=np.full((k, n), np.nan), success=np.zeros(k, bool),
                       reason=np.full(k, "unreachable", dtype="<U14"),
                       iterations=np.zeros(k, int), position_error_m=np.full(k, np.nan),
                       rotation_error_rad=np.full(k, np.nan))
    return decide(comp, blank, desired, None, asked)


def dialect_asked(rules: DialectRules, geometry: ArmGeometry, jobs: list,
                   previous_of: list):
    """The configuration rule's predicate of the written configuration: among a row's
    candidate joints, the ones the dialect's controller takes (its ``choose``)."""
    def asked(rows: np.ndarray, q: np.ndarray, usable: np.ndarray) -> np.ndarray:
        k, b, n = q.shape
        out = np.full((k, n), np.nan)
        if np.any(usable):
            geometry.prepare(q[usable])
        for i, row in enumerate(rows.tolist()):
            candidates = q[i][usable[i]]
            if len(candidates):
                picked, *_ = rules.choose(geometry, jobs[row].target, candidates,
                                          previous_of[row])
                if picked is not None:
                    out[i] = picked
        return out
    return asked


def config_namer(rules: DialectRules, geometry: ArmGeometry, jobs: list):
    """``words(row, q_ctrl)``: the configuration of joints ``q_ctrl`` in the dialect's
    words (as many values as the target writes, all where it writes none); with None,
    the written one ('' where none is written)."""
    def words(row: int, q_ctrl) -> str:
        target = jobs[row].target
        if q_ctrl is None:
            return rules.config_words(rules.written(target))
        if rules.joints_are_config:
            return rules.config_words(tuple(q_ctrl))
        return (rules.config_words(rules.config(geometry, q_ctrl, target))
                or _full_words(rules, geometry, q_ctrl))
    return words


def _full_words(rules: DialectRules, geometry: ArmGeometry, q_ctrl: np.ndarray) -> str:
    """The whole configuration of ``q_ctrl`` in a dialect's words, for a target that writes
    none (KRL S and T, FANUC's letters, VAL3's words), else the joints in degrees."""
    if rules.full_words is not None:
        return rules.full_words(geometry, q_ctrl)
    return "joints [" + ", ".join(f"{v:.1f}" for v in np.degrees(q_ctrl)) + "] deg"
