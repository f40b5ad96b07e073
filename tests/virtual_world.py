"""A virtual robot and its calibration identified from 60 measured poses, shared by the
dialect tests' whole loops (identify, compensate, run on the virtual arm)."""

from __future__ import annotations

import dataclasses

import numpy as np

from olp_compensate.calibration.calibration import ToolPoint
from olp_compensate.calibration.identify import IdentificationOptions, identify
from olp_compensate.calibration.simulate import make_virtual_robot, random_joints


def identified_world(robot, seed: int, tool_alias: str | None = None):
    """(virtual robot, its calibration from 60 poses at 0.01 mm noise); ``tool_alias``: the
    program's name for the measured point 'tcp', added to the calibration's tools as a tool
    calibrated for programs (as ``olp-cal tool`` would write it) so the program's tool finds
    its real TCP; a measured point alone is never a program's tool."""
    virtual = make_virtual_robot(robot, seed=seed, n_points=3)
    rng = np.random.default_rng(seed)
    meas = virtual.measure(random_joints(robot, 60, rng), 0.01e-3, rng)
    cal = identify(robot, meas, IdentificationOptions(folds=0)).calibration
    if tool_alias is not None:
        tools = dict(cal.tools)
        tools[tool_alias] = ToolPoint(xyz_m=cal.tools["tcp"].xyz_m, for_programs=True)
        cal = dataclasses.replace(cal, tools=tools)
    return virtual, cal


def nominal_arm(robot):
    """(the data-sheet arm as a VirtualRobot, the closed-form family fitted on its forward
    kinematics): what a test's own nominal controller of ``robot`` solves with."""
    from olp_compensate.calibration.simulate import VirtualRobot
    from olp_compensate.compensation.ik import fit_family

    n = robot.n_joints
    nominal = VirtualRobot(robot, np.zeros((n, 6)), np.zeros(n), np.eye(4), {})
    family = fit_family(lambda q: nominal.flange_poses(robot.controller_from_joints(q)))
    return nominal, family


def misses_mm(virtual, meant, before, after) -> tuple[np.ndarray, np.ndarray]:
    """(untouched, compensated) distances, mm, from each target's ``meant`` point (k, 3), m,
    device frame, to where ``virtual``'s true TCP goes at the controller joints the nominal
    controller runs the untouched program at (``before``) and the compensated one at
    (``after``), (k, n) rad."""
    meant = np.asarray(meant, float)
    k = len(meant)
    joints = np.concatenate([np.asarray(before, float), np.asarray(after, float)])
    reached = virtual.true_frames(joints, ["tcp"] * (2 * k))[:, :3, 3]
    distance = np.linalg.norm(reached - np.concatenate([meant, meant]), axis=1) * 1e3
    return distance[:k], distance[k:]


def assert_the_gap_closed(label: str, before_mm, after_mm) -> None:
    """The untouched program misses every target by more than 0.5 mm, the compensated one
    by less than 0.05 mm (printed with ``label``, the robot)."""
    print(f"{label}: untouched program misses by {min(before_mm):.2f}..{max(before_mm):.2f} "
          f"mm, compensated by at most {max(after_mm):.4f} mm")
    assert max(after_mm) < 0.05, after_mm
    assert min(before_mm) > 0.5, before_mm


def axis1_poses(robot, n: int, seed: int) -> np.ndarray:
    """Controller joints (n, 6), rad: axes 1 and 2 random, axis 3 keeps j2 + j3 at 30 deg and
    the wrist is still, so the flange only turns about axis 1: a tool point's component along
    that axis cannot be told from the device frame's (a structural tie)."""
    rng = np.random.default_rng(seed)
    q = np.empty((n, 6))
    q[:, 0] = rng.uniform(-2.5, 2.5, n)
    q[:, 1] = rng.uniform(-1.0, 1.2, n)
    q[:, 2] = np.radians(30.0) - q[:, 1]
    q[:, 3:] = np.radians([10.0, 40.0, 20.0])
    return q
