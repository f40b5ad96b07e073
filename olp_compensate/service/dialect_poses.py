"""The configuration numbers of the pose dialects in ``compensate_poses``: which branch
the dialect's controller takes for a target as the request writes it, by the same rules
olp-fix applies to a program (:mod:`olp_compensate.compensation.dialect_rules`).

``config`` per dialect, as the program would write it:

- ``krl``: ``[S]`` or ``[S, T]`` (KUKA status and turn, integers);
- ``fanuc``: ``["N"|"F", "U"|"D", "T"|"B", turn4, turn5, turn6]`` (letters, then up to three
  turn numbers);
- ``val3``: configuration words (``["righty", "epositive", "wpositive"]``, any of them);
- ``urscript``: the joints the controller starts from (``qnear``, rad); absent: those of
  the previous pose of the request (zero for the first);
- ``vplus``: none (the controller's own configuration).

A pose without ``config`` takes the branch the rules choose without one (the nearest the
previous pose's joints). The answer's ``config`` is then the dialect's configuration of the
joints the real arm takes, in the same form.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..compensation.dialect_rules import ArmGeometry
from ..compensation.ik import closed_form_inverse
from ..kinematics.conventions import invert_pose
from ..programs.fanuc.rules import FANUC_TP
from ..programs.krl.rules import KRL
from ..programs.pose_dialects import PoseTarget
from ..programs.targets import Number
from ..programs.urscript.rules import URSCRIPT
from ..programs.val3.rules import VAL3
from .requests import INVALID_PARAMS, ServiceError

RULES = {"krl": KRL, "fanuc": FANUC_TP, "val3": VAL3, "urscript": URSCRIPT}
_GEOMETRY: dict[int, ArmGeometry] = {}


@dataclass(frozen=True)
class Chosen:
    """The nominal branch of each dialect pose: ``confdata`` (k, 4) ABB confdata of it;
    ``failed`` row -> (status, note) where the rules found none; ``notes`` row -> the
    rules' note; ``targets`` row -> the PoseTarget the rules read."""

    confdata: np.ndarray
    failed: dict
    notes: dict
    targets: dict


def geometry_of(comp) -> ArmGeometry:
    key = id(comp.robot)
    if key not in _GEOMETRY:
        _GEOMETRY[key] = ArmGeometry(comp.robot)
    return _GEOMETRY[key]


def pose_target(dialect: str, config, where: str) -> PoseTarget:
    """The request's ``config`` as a target's configuration numbers (checked)."""
    values = [] if config is None else config
    if not isinstance(values, list) or not all(
            isinstance(v, (int, float, str)) and not isinstance(v, bool) for v in values):
        raise ServiceError(INVALID_PARAMS, f"{where}: expected a list of the dialect's "
                                           f"configuration numbers (see the README)")
    if dialect == "vplus" and values:
        raise ServiceError(INVALID_PARAMS, f"{where}: V+ targets carry no configuration "
                                           f"numbers; leave config out")
    fine = {"krl": len(values) <= 2 and all(type(v) is int and 0 <= v < 65536 for v in values),
            "fanuc": (len(values) in (0, 3, 4, 5, 6)
                      and [str(v).upper() in pair for v, pair in
                           zip(values[:3], ("NF", "UD", "TB"))] == [True] * min(3, len(values))
                      and all(type(v) is int for v in values[3:])),
            "val3": all(type(v) is str for v in values),
            "urscript": len(values) in (0, 6) and all(type(v) in (int, float) for v in values)}
    if dialect in fine and not fine[dialect]:
        forms = {"krl": "[S] or [S, T], integers",
                 "fanuc": '["N"|"F", "U"|"D", "T"|"B", turn, turn, turn]',
                 "val3": 'words such as ["righty", "epositive", "wpositive"]',
                 "urscript": "the 6 joints (rad) the controller starts from"}
        raise ServiceError(INVALID_PARAMS, f"{where}: expected {forms[dialect]}")
    numbers = tuple(Number(0, 0, str(v).upper() if dialect == "fanuc" and k < 3 else str(v))
                    for k, v in enumerate(values))
    return PoseTarget(name=None, source=("<request>", 0, 0), kind="pose", numbers=(),
                      config=numbers)


def choose_branches(comp, rows: np.ndarray, dialects: list[str], configs: list,
                    requested: np.ndarray) -> Chosen:
    """The nominal branch of each pose ``rows`` of a dialect other than RAPID, in the
    request's order (each after the previous pose's joints): ``requested`` (k, 4, 4) the
    flange poses (base frame, m) the controller's model is asked for."""
    robot = comp.robot
    geometry = geometry_of(comp)
    branches = closed_form_inverse(comp.family, requested)                  # (k, 8, n) URDF
    k, b, n = branches.shape
    branches_ctrl = robot.controller_from_joints(branches.reshape(-1, n)).reshape(k, b, n)
    geometry.prepare(branches_ctrl)
    confdata = np.zeros((k, 4), dtype=int)
    failed, notes, targets = {}, {}, {}
    unchosen: list[tuple[int, int, object]] = []     # (j, row, previous joints)
    previous = None
    for j, row in enumerate(rows.tolist()):
        dialect = dialects[row]
        target = pose_target(dialect, configs[row], f"poses[{row}].config")
        targets[row] = target
        if dialect == "vplus":
            q, reason, note = _nearest(branches_ctrl[j], previous)
        else:
            q, reason, *rest = RULES[dialect].choose(geometry, target, branches_ctrl[j],
                                                     previous)
            note = rest[0] if rest else ""
        if note:
            notes[row] = note
        if q is None:
            if dialect == "vplus":
                failed[row] = ("unreachable", reason)
            else:
                unchosen.append((j, row, previous))
            continue
        confdata[j] = comp.confdata(robot.joints_from_controller(q[None]))[0]
        previous = q
    _decide(comp, dialects, requested, unchosen, targets, confdata, failed)
    return Chosen(confdata=confdata, failed=failed, notes=notes, targets=targets)


def _decide(comp, dialects, requested, unchosen, targets, confdata, failed) -> None:
    """Poses no nominal branch has the written configuration of: the configuration rule
    olp-fix applies in a program (:func:`~olp_compensate.compensation.dialect_program.
    decide_unchosen`), per dialect: the calibrated arm's joints where it reaches them as
    asked, else the rule's status and note."""
    from ..compensation.dialect_config import decide_unchosen

    for dialect in sorted({dialects[row] for _, row, _ in unchosen}):
        mine = [(j, row, prev) for j, row, prev in unchosen if dialects[row] == dialect]
        found, failures = decide_unchosen(
            comp, RULES[dialect], [targets[row] for _, row, _ in mine],
            [prev for _, _, prev in mine], requested[[j for j, _, _ in mine]])
        for r, (j, row, _) in enumerate(mine):
            if found.success[r]:
                confdata[j] = comp.confdata(found.q[r][None])[0]
            else:
                failed[row] = (failures[r].status, failures[r].note)


def _nearest(branches: np.ndarray, previous):
    """The branch nearest the previous joints (zero for the first), as the V+ rules of a
    program without configuration take it."""
    finite = [q for q in branches if np.all(np.isfinite(q))]
    if not finite:
        return None, "the nominal arm does not reach the target", ""
    reference = np.zeros(len(finite[0])) if previous is None else previous
    return min(finite, key=lambda q: float(np.sum((q - reference) ** 2))), None, ""


FULL = {"krl": [0, 0], "fanuc": ["N", "U", "T", 0, 0, 0],
        "val3": ["righty", "epositive", "wpositive"]}
"""The configuration a pose without ``config`` is answered in (every number of it)."""


def answer_config(comp, dialect: str, target: PoseTarget, joints_deg) -> list | None:
    """The dialect's configuration of the real joints ``joints_deg`` (deg), in the
    request's form (all of it where the request gave none; [] for V+ and URScript, whose
    targets carry none of their own); None where there are no joints."""
    if joints_deg is None:
        return None
    if dialect in ("vplus", "urscript"):
        return []
    if not target.config:
        target = pose_target(dialect, FULL[dialect], "config")
    q = np.radians(np.asarray(joints_deg, dtype=float))
    return list(RULES[dialect].config(geometry_of(comp), q, target))


def requested_flanges(targets, tools, wobjs) -> np.ndarray:
    """Flange poses (k, 4, 4) base frame, m, the controller's model is asked for."""
    return wobjs @ targets @ invert_pose(tools)
