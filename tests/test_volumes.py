"""Cube volumes: the layouts by hand, the pose sets checked with pinocchio's forward
kinematics and against a naive choice of orientations, and the programs that visit them."""

from __future__ import annotations

import numpy as np
import pytest

from olp_compensate.calibration.pose_planning import design_quality, planning_space
from olp_compensate.calibration.simulate import VirtualRobot
from olp_compensate.calibration.volumes import (CubeVolume, cube_points, cube_pose_set,
                                                rapid_joint_program, vplus_joint_program)
from olp_compensate.errors import DataError
from olp_compensate.kinematics.robot import load_robot

TOOL_M = np.array([0.05, 0.0, 0.15])


def test_layouts_by_hand():
    points, names = cube_points(np.array([1.0, 0.0, 0.5]), 0.4, "faces")
    assert len(points) == 12 and len(set(names)) == 12
    offsets = np.round((points - [1.0, 0.0, 0.5]) / 0.2).astype(int)
    corners = {tuple(o) for o in offsets[:8]}
    assert corners == {(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)}
    assert {tuple(o) for o in offsets[8:]} == {(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)}
    # every point lies on a face: one coordinate at the half edge
    assert np.all(np.max(np.abs(points - [1.0, 0.0, 0.5]), axis=1) == pytest.approx(0.2))
    grid, _ = cube_points(np.zeros(3), 0.2, "grid")
    assert len(grid) == 27 and len({tuple(np.round(p, 9)) for p in grid}) == 27
    assert np.allclose(grid.mean(axis=0), 0.0) and np.allclose(np.sort(np.unique(grid)),
                                                                [-0.1, 0.0, 0.1])
    with pytest.raises(DataError, match="layout"):
        cube_points(np.zeros(3), 0.2, "sphere")


def test_contains():
    cube = CubeVolume("v1", np.array([1.0, 0.0, 0.5]), 0.4)
    inside = cube.contains(np.array([[1.2, 0.2, 0.3], [1.21, 0.0, 0.5], [1.0, 0.0, 0.5]]))
    assert inside.tolist() == [True, False, True]


@pytest.mark.parametrize("robot_name, centre, size, layout", [
    ("abb_irb2400", (0.95, 0.0, 0.8), 0.4, "faces"),
    ("unimation_puma560", (0.45, 0.15, 0.1), 0.2, "grid"),
])
def test_pose_sets_reach_the_points_inside_the_ranges(robot_name, centre, size, layout):
    robot = load_robot(robot_name)
    pose_set = cube_pose_set(robot, np.array(centre), size, layout, tool_m=TOOL_M)
    n = 12 if layout == "faces" else 27
    assert pose_set.joints.shape == (n, 6)
    assert not robot.outside_ranges(pose_set.joints).any()
    truth = VirtualRobot(robot=robot, origin_errors=np.zeros((6, 6)), joint_offsets=np.zeros(6),
                         device_T_base=np.eye(4), tools={"tcp": TOOL_M})
    reached = truth.true_points(pose_set.joints, ["tcp"] * n)
    assert np.allclose(reached, pose_set.points_m, atol=1e-7)
    flange = truth.flange_poses(pose_set.joints)
    assert np.allclose(flange[:, :3, :3], pose_set.rotations, atol=1e-7)
    # the orientations are not all alike: the criterion spread them
    assert len({tuple(np.round(r[:, 2], 3)) for r in pose_set.rotations}) > 3


def test_chosen_orientations_beat_a_single_orientation():
    robot = load_robot("abb_irb2400")
    pose_set = cube_pose_set(robot, np.array([0.95, 0.0, 0.8]), 0.4, "grid", tool_m=TOOL_M)
    # the same points all reached pointing straight down (the usual hand-taught choice)
    from olp_compensate.calibration.volumes import _reachable, candidate_orientations

    down = candidate_orientations()[:1]
    joints, _ = _reachable(robot, pose_set.points_m, down, TOOL_M)
    assert np.all(np.isfinite(joints))
    both = np.vstack([pose_set.joints, joints[:, 0]])
    space = planning_space(robot, candidates=both, tools={"tcp": TOOL_M})
    chosen = design_quality(space, np.arange(27))
    naive = design_quality(space, np.arange(27, 54))
    assert chosen.log_det > naive.log_det + 5.0


def test_unreachable_cube_names_the_point():
    robot = load_robot("abb_irb2400")
    with pytest.raises(DataError, match=r"cube point C\d at \(.*\) mm"):
        cube_pose_set(robot, np.array([1.6, 0.0, 0.8]), 0.4, "faces")


def test_programs_visit_every_pose_in_degrees():
    robot = load_robot("unimation_puma560")
    pose_set = cube_pose_set(robot, np.array([0.45, 0.15, 0.1]), 0.2, "faces")
    rapid = rapid_joint_program(pose_set, robot)
    assert rapid.count("MoveAbsJ jCube") == 12
    first = rapid.split("jCube1:=[[")[1].split("]")[0]
    assert np.allclose([float(v) for v in first.split(",")], np.degrees(pose_set.joints[0]),
                       atol=1e-4)
    vplus = vplus_joint_program(pose_set, robot)
    assert vplus.count("MOVE #cube") == 12
    row = [ln for ln in vplus.splitlines() if ln.startswith("#cube12")][0].split()
    assert np.allclose([float(v) for v in row[1:]], np.degrees(pose_set.joints[11]), atol=1e-3)
    try:
        from olp_compensate import programs
    except ImportError:         # the programs package is being edited elsewhere
        return
    for text, dialect in ((rapid, "rapid"), (vplus, "vplus")):
        program = programs.loads(text, dialect)
        assert len(program.joint_targets) == 12 and len(program.motions) == 12


def test_plan_volume_command_writes_joints_and_a_program(tmp_path, capsys):
    """olp-cal plan --volume cube: the joints file holds the pose set's points (each reached
    by the nominal arm, checked here through its own forward kinematics) and the program
    visits them."""
    from olp_compensate.calibration.calibration import nominal_calibration
    from olp_compensate.cli.cal import main
    from olp_compensate.io.poses import read_poses
    from olp_compensate.kinematics.robot import load_robot

    out, program = tmp_path / "cube.csv", tmp_path / "cube.mod"
    assert main(["plan", "--robot", "abb_irb2400", "--volume", "cube", "--centre",
                 "1200,0,800", "--size", "400", "--layout", "grid", "-o", str(out),
                 "--program", str(program)]) == 0
    robot = load_robot("abb_irb2400")
    poses = read_poses(out, [j.unit for j in robot.joints])
    assert len(poses.joints) == 27 and not robot.outside_ranges(poses.joints).any()
    flange = nominal_calibration(robot).flange_poses(poses.joints)
    reached = flange[:, :3, :3] @ np.array([0.05, 0.0, 0.15]) + flange[:, :3, 3]
    grid = np.array([[x, y, z] for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1)])
    expected = np.array([1.2, 0.0, 0.8]) + 0.2 * grid
    assert np.allclose(np.sort(reached, axis=0), np.sort(expected, axis=0), atol=1e-6)
    assert program.read_text().count("MoveAbsJ") == 27
    with pytest.raises(SystemExit):
        main(["plan", "--robot", "abb_irb2400", "--volume", "sphere", "-o", str(out)])
    assert main(["plan", "--robot", "abb_irb2400", "--volume", "cube", "-o", str(out)]) == 1
    assert "--centre" in capsys.readouterr().err
