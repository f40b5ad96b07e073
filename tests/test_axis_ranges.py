"""The controller's axis ranges (data sheet) are checked on controller axes after solving.

The regression: an IRB 2400 target that needs axis 3 at 100 degrees (range -60..65) was
reported 'ok', because the limits were checked on the URDF's serial joint_3 only.
"""

from __future__ import annotations

import itertools
import json
import math
import re

import numpy as np
import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.calibration.simulate import random_joints
from olp_compensate.compensation.ik import closed_form_inverse
from olp_compensate.compensation.pose import Compensator, compensate_pose
from olp_compensate.io.calibration_file import calibration_from_dict, calibration_to_dict
from olp_compensate.kinematics.robot import bundled_robot_names, load_robot, robot_from_urdf_text
from olp_compensate.programs.object_model.task import compensate_program

ISSUE_TARGET = """MODULE T
  PROC main()
    MoveJ [[500.373,0,322.975],[-0.34202,0,0.939693,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v100,fine,tool0;
  ENDPROC
ENDMODULE
"""


def _narrow_enough(robot):
    """(robot, axis): an arm axis (2 or 3) whose range is narrower than a turn, so that no
    other turn of it reaches the same pose; robots whose arm axes span a whole turn or more
    (UR: +-360 deg) get a copy with axis 3 narrowed to +-150 deg."""
    ranges = robot.controller_ranges
    for axis in (2, 1):
        lo, hi = ranges[axis]
        if np.isfinite(lo) and np.isfinite(hi) and hi - lo < 2 * np.pi - 0.2:
            return robot, axis
    narrowed = ranges.copy()
    narrowed[2] = np.radians([-150.0, 150.0])
    return robot_from_urdf_text(robot.urdf_text, name=robot.name,
                                urdf_from_controller=robot.urdf_from_controller,
                                axis_ranges=narrowed), 2


def _compensator(robot):
    cal = nominal_calibration(robot)
    if robot.axis_ranges is not None:       # the narrowed copy: keep its ranges
        cal = cal.__class__(**{**cal.__dict__, "robot": robot})
    return Compensator(cal)


def _pose_at(comp, q_ctrl):
    joints = comp.robot.joints_from_controller(q_ctrl[None])
    return comp.nominal_flange(joints)[0], tuple(int(c) for c in comp.confdata(joints)[0])


def in_range_solutions(comp, flange) -> list[np.ndarray]:
    """Every controller joint vector (rad) inside every range and URDF limit that puts the
    (nominal) arm's flange on ``flange``: each closed-form branch with every combination of
    whole turns (-1, 0, +1) of the revolute axes, checked by forward kinematics."""
    robot = comp.robot
    branches = closed_form_inverse(comp.family, flange[None])[0]
    revolute = [a for a, j in enumerate(robot.joints) if j.kind == "revolute"]
    found = []
    for branch in branches[np.all(np.isfinite(branches), axis=1)]:
        base = robot.controller_from_joints(branch[None])[0]
        for turns in itertools.product((-1, 0, 1), repeat=len(revolute)):
            q = base.copy()
            q[revolute] += 2 * np.pi * np.array(turns)
            if robot.outside_ranges(q[None]).any():
                continue
            pose = comp.nominal_flange(robot.joints_from_controller(q[None]))[0]
            if np.allclose(pose, flange, atol=1e-9):
                found.append(q)
    return found


@pytest.mark.parametrize("name", bundled_robot_names())
def test_a_target_reachable_only_outside_the_range_is_joint_limit(name):
    """A pose only a configuration outside the ranges reaches (no branch, no turn of an
    axis, puts it inside: checked by enumeration) is 'joint_limit' with the axis, its
    value and the range named, and 'no configuration reaches it inside the axis ranges'."""
    robot, axis = _narrow_enough(load_robot(name))
    comp = _compensator(robot)
    lo, hi = robot.controller_ranges[axis]
    rng = np.random.default_rng(5)
    # 5 deg past the range's end first; arms whose other elbow reaches most such poses
    # inside the ranges (wide axis-3 ranges: Yaskawa GP25, GP88, Kawasaki RS013N) need the
    # pose further past it
    for q, past in itertools.product(random_joints(robot, 400, rng, margin=0.3),
                                     np.radians([5.0, 15.0, 30.0])):
        q_out = q.copy()
        q_out[axis] = hi + past
        q_in = q.copy()
        q_in[axis] = hi - np.radians(5.0)
        joints = robot.joints_from_controller(np.array([q_out, q_in]))
        inside_urdf = np.all((joints >= robot.lower_limits) & (joints <= robot.upper_limits), 1)
        if inside_urdf[1] and not in_range_solutions(comp, comp.nominal_flange(joints)[0]):
            break
    else:    # checked by enumeration: each of the 1,200 poses has an in-range configuration
        pytest.skip(f"{name}: every pose tried past axis {axis + 1}'s range end is reached by "
                    f"another configuration inside the ranges")
    pose_in, conf_in = _pose_at(comp, q_in)
    inside = compensate_pose(comp, pose_in, config=conf_in)
    assert inside.status in ("ok", "singular"), inside.note
    pose_out, conf_out = _pose_at(comp, q_out)
    outside = compensate_pose(comp, pose_out, config=conf_out)
    assert outside.status == "joint_limit"
    # the axis, its value (one turn on is the same pose) and the range are named
    found = re.search(rf"axis {axis + 1} = (-?[0-9.]+) deg is ([0-9.]+) deg (above|below)",
                      outside.note)
    assert found, outside.note
    value = float(found.group(1))
    assert math.remainder(value - np.degrees(q_out[axis]), 360.0) == pytest.approx(0, abs=0.01)
    past = value - np.degrees(hi) if found.group(3) == "above" else np.degrees(lo) - value
    assert float(found.group(2)) == pytest.approx(past, abs=0.01)
    assert f"range {np.degrees(lo):g}..{np.degrees(hi):g} deg" in outside.note, outside.note
    assert "(on the configuration asked for" in outside.note, outside.note
    assert outside.note.endswith("no configuration reaches it inside the axis ranges")
    # the best joints found are reported: where the arm would have to go
    turns = np.remainder(outside.joints - q_out + np.pi, 2 * np.pi) - np.pi
    assert np.allclose(turns, 0, atol=1e-6)


def test_the_issue_target_is_joint_limit_with_axis_3_in_the_note():
    comp = Compensator(nominal_calibration(load_robot("abb_irb2400")))
    _, report = compensate_program(ISSUE_TARGET, "rapid", comp)
    (row,) = report.rows
    assert row.status == "joint_limit"
    assert "axis 3 = 100.00 deg" in row.note and "-60..65 deg" in row.note
    assert row.joints[2] == pytest.approx(100.0, abs=1e-3)
    assert row.config_after == "[0,0,0,0]"
    assert report.exit_code == 2


def test_axis_ranges_come_from_the_controller_file_and_survive_calib_json():
    robot = load_robot("abb_irb2400")
    assert np.allclose(np.degrees(robot.controller_ranges[2]), [-60, 65])
    doc = calibration_to_dict(nominal_calibration(robot))
    assert doc["robot"]["axis_ranges_deg"][2] == pytest.approx([-60, 65])
    again = calibration_from_dict(json.loads(json.dumps(doc)))
    assert np.allclose(again.robot.controller_ranges, robot.controller_ranges)
    # a file written before the ranges were stored takes the bundled robot's
    del doc["robot"]["axis_ranges_deg"]
    older = calibration_from_dict(doc)
    assert np.allclose(older.robot.controller_ranges, robot.controller_ranges)


def test_random_campaign_poses_stay_inside_the_controller_ranges():
    robot = load_robot("abb_irb2400")
    q = random_joints(robot, 500, np.random.default_rng(1))
    assert not robot.outside_ranges(q).any()
    envelope = random_joints(robot, 500, np.random.default_rng(1), within_ranges=False)
    assert robot.outside_ranges(envelope).any()      # what the URDF alone would allow
