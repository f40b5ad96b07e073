"""Poses compensated in a batch, each failure with olp-fix's note: for callers that answer
pose by pose (the service, the RoboDK post) yet solve many at once.

Poses are 4x4 in metres; joints are the controller's axes in degrees (mm for a prismatic
axis), as the report writes them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kinematics.conventions import invert_pose
from .pose import COMPENSATED, Compensator


@dataclass(frozen=True)
class ExplainedBatch:
    """m poses compensated.

    poses : (m, 4, 4) the targets to write (in the frame given, m); where not compensated
        the target as given.
    joints_deg : (m, n) controller axes the real arm takes (deg, mm), where not
        compensated the best found, NaN where none.
    status : (m,) 'ok', 'singular' or why not; notes : m strings, olp-fix's note ('' when
        compensated).
    config : (m, 4) int, ABB confdata of the joints the real arm takes (where compensated).
    model_notes : m strings, where compensated: which fitted-in-a-range parts of the
        calibration did not apply or did (:meth:`~.pose.Compensator.fitted_parts`).
    """

    poses: np.ndarray
    joints_deg: np.ndarray
    status: list[str]
    notes: list[str]
    config: np.ndarray
    model_notes: tuple[str, ...] = ()

    @property
    def ok(self) -> np.ndarray:
        return np.isin(np.asarray(self.status), COMPENSATED)


def confdata_of_joints(comp: Compensator, joints_deg: np.ndarray) -> np.ndarray:
    """ABB confdata (m, 4) of controller joints ``joints_deg`` (m, n) deg (mm): the
    configuration a controller is in at those joints."""
    robot = comp.robot
    scale = np.array([np.pi / 180.0 if j.kind == "revolute" else 1e-3 for j in robot.joints])
    q_urdf = robot.joints_from_controller(np.asarray(joints_deg, dtype=float) * scale)
    return comp.confdata(q_urdf)


def compensate_explained(comp: Compensator, wobj_T_target: np.ndarray, tool: np.ndarray,
                         wobj: np.ndarray, confdata: np.ndarray | None,
                         real_tool: np.ndarray | None = None) -> ExplainedBatch:
    """Compensate ``wobj_T_target`` (m, 4, 4) with ``tool`` flange_T_tool and ``wobj``
    base_T_wobj (m, 4, 4 each), on ``confdata`` (m, 4) or None (any configuration, the
    branch nearest zero); ``real_tool`` the calibrated tool where it differs (m, 4, 4)."""
    from .regions import RegionalCompensator, explain_failures

    real_tool = tool if real_tool is None else real_tool
    requested = wobj @ wobj_T_target @ invert_pose(tool)
    desired = wobj @ wobj_T_target @ invert_pose(real_tool)
    regional = None
    if isinstance(comp, RegionalCompensator):
        q, flange, solution, _, regional = comp.solve_regions(desired, requested, confdata)
    else:
        q, flange, solution, _ = comp.compensate_flanges(desired, requested, confdata)
    parts = comp.fitted_parts(desired, q, flange, solution.success)   # (not with regions)
    q, flange = parts.q, parts.flange
    robot = comp.robot
    ok = np.isin(solution.reason, COMPENSATED)
    poses = invert_pose(wobj) @ flange @ tool
    poses[~ok] = wobj_T_target[~ok]
    joints = robot.to_degrees_or_mm(robot.controller_from_joints(q))
    config = np.zeros((len(q), 4), dtype=int)
    if np.any(ok):
        config[ok] = comp.confdata(q[ok])
    notes = [""] * len(q)
    if not np.all(ok):
        for i, failure in enumerate(explain_failures(comp, solution, desired, confdata,
                                                     regional)):
            if failure is not None and not ok[i]:
                notes[i] = failure.note
                joints[i] = robot.to_degrees_or_mm(failure.joints[None])[0]
    return ExplainedBatch(poses=poses, joints_deg=joints,
                          status=[str(s) for s in solution.reason], notes=notes,
                          config=config, model_notes=tuple(parts.notes))
