"""The robot a V+/AS program was taught on, seen in its precision points: joints outside the
calibration robot's axis ranges mean another robot."""

from __future__ import annotations

import math

import numpy as np

from ...compensation.report import CompensationReport
from ...errors import ModelError


JOINT_SLACK_DEG = 1.0
"""A taught joint value this far outside a controller axis range (deg, or mm) is out."""


def check_taught_joints(report: CompensationReport, robot) -> None:
    """:class:`ModelError` when a precision point of the program (joints as taught, a
    ``joint_target`` row) cannot be of the calibration's robot: fewer values than its axes
    (a 6-axis program against a 7-axis arm; more are external axes, see
    :func:`..object_model.task._external_axes_in_notes`), or a value outside a controller axis range
    (a PUMA's ``#ready`` on an IRB 2400): the program is for another robot."""
    ranges = robot.controller_ranges
    scale = np.array([1e3 if j.kind == "prismatic" else math.degrees(1.0)
                      for j in robot.joints])
    low, high = ranges[:, 0] * scale - JOINT_SLACK_DEG, ranges[:, 1] * scale + JOINT_SLACK_DEG
    for row in report.rows:
        if row.status != "joint_target" or not row.joints:
            continue
        where = f"{row.file}:{row.line}:{row.column}: {row.target}"
        if len(row.joints) < robot.n_joints:
            raise ModelError(f"{where}: {len(row.joints)} joint values, but the calibration's "
                             f"robot {robot.name} has {robot.n_joints} axes: the program is "
                             f"for another robot")
        q = np.asarray(row.joints, float)
        out = np.flatnonzero((q < low) | (q > high))
        if len(out):
            k = int(out[0])
            raise ModelError(f"{where}: axis {k + 1} at {q[k]:g} is outside {robot.name}'s "
                             f"range {low[k] + JOINT_SLACK_DEG:g}..{high[k] - JOINT_SLACK_DEG:g}"
                             f": the program was taught on another robot (its header may "
                             f"say so: '; olp-robot: NAME')")
