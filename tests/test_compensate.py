"""The whole loop: measure a virtual robot, identify it, compensate a program, run the
compensated program on a simulated nominal controller and on the virtual real arm.

The nominal controller here is the closed form of the data-sheet arm (fitted on
pinocchio's forward kinematics of the nominal URDF) choosing the branch the written
confdata asks for; the real arm is the virtual robot (pinocchio on the perturbed URDF).
Both are independent of the calibrated model that olp-fix solves on. Targets are compared
in the measuring device's frame, where both the calibration and the truth place the robot.
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.calibration.identify import IdentificationOptions, identify
from olp_compensate.calibration.registration import kabsch
from olp_compensate.calibration.simulate import VirtualRobot, make_virtual_robot, random_joints
from olp_compensate.compensation.ik import branch_of, closed_form_inverse, fit_family, select_branch
from olp_compensate.compensation.pose import (Compensator, compensate_pose, compensate_poses,
                                              explain_failures)
from olp_compensate.kinematics.conventions import (MM, invert_pose, matrix_from_euler_zyz,
                                                   matrix_from_quat_wxyz,
                                                   pose_from_rotation_translation,
                                                   quat_wxyz_from_matrix, rotation_angle_between,
                                                   rotation_from_rotvec)
from olp_compensate.kinematics.model import build_model, forward, joint_frames
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs import loads, resolve
from olp_compensate.programs.object_model.task import compensate_program

NOISE_M = 0.01e-3
TOLERANCE_M = 0.05e-3


class World:
    """A virtual robot, its identified calibration, and a nominal controller."""

    def __init__(self, robot_name: str, seed: int):
        self.robot = load_robot(robot_name)
        self.virtual = make_virtual_robot(self.robot, seed=seed, n_points=3)
        rng = np.random.default_rng(seed)
        meas = self.virtual.measure(random_joints(self.robot, 60, rng), NOISE_M, rng)
        self.calibration = as_program_tool(
            identify(self.robot, meas, IdentificationOptions(folds=0)).calibration)
        n = self.robot.n_joints
        self.nominal = VirtualRobot(self.robot, np.zeros((n, 6)), np.zeros(n), np.eye(4), {})
        self.family = fit_family(lambda q: self.nominal.flange_poses(
            self.robot.controller_from_joints(q)))
        assert self.family is not None
        self.limits = np.stack([self.robot.lower_limits, self.robot.upper_limits], 1)

    def controller(self, base_T_flange, confdata=None):
        """Controller axes (m, n) rad the nominal controller takes for flange poses."""
        solutions = closed_form_inverse(self.family, base_T_flange)
        if confdata is None:  # V+: the branch the arm is in, here the one nearest zero
            norm = np.where(np.all(np.isfinite(solutions), 2), np.sum(solutions ** 2, 2), np.inf)
            q = solutions[np.arange(len(solutions)), np.argmin(norm, 1)]
        else:
            q, found = select_branch(solutions, confdata, self.limits)
            assert np.all(found)
        return self.robot.controller_from_joints(q)

    def real_tool(self, tool_rotation):
        """The real tool (true flange frame) of the measured point 'tcp' whose orientation
        is ``tool_rotation`` in the calibrated flange frame. The calibrated flange frame is
        defined by the measured points; it is placed in the true one by the three points."""
        names = sorted(self.virtual.tools)
        true_T_cal = kabsch(np.array([self.calibration.tools[n].xyz_m for n in names]),
                            np.array([self.virtual.tools[n] for n in names]))
        return true_T_cal @ pose_from_rotation_translation(
            tool_rotation, self.calibration.tools["tcp"].xyz_m)

    def real_tcp_in_device(self, q_ctrl, flange_T_tool):
        return self.virtual.device_T_base @ self.virtual.flange_poses(q_ctrl) @ flange_T_tool

    def desired_in_device(self, base_T_tcp):
        return self.calibration.device_T_base @ base_T_tcp

    def program_joints(self, m: int, seed: int) -> np.ndarray:
        """URDF joints of m poses the program was written for: inside the limits, wrist
        away from its singularity."""
        rng = np.random.default_rng(seed)
        q = self.robot.joints_from_controller(random_joints(self.robot, 4 * m, rng, margin=0.3))
        q = q[np.abs(np.sin(q[:, 4])) > math.sin(math.radians(15))]
        # away from the stretched or folded elbow too (a program's targets are not at the
        # edge of the workspace, where the real arm may reach a target the nominal cannot)
        model = build_model(self.robot)
        chain = forward(model, model.nominal, q, jacobian=True)
        jac = np.concatenate([chain.dpoint_dq, chain.drot_dq], axis=1)
        smallest = np.linalg.svd(jac, compute_uv=False)[:, -1]
        return q[smallest > 0.02][:m]


def as_program_tool(calibration, name: str = "tcp"):
    """``calibration`` with its measured point ``name`` also calibrated for programs (as
    olp-cal tool would mark it): the programs' tooldata 'tcp' then gets it as its real TCP
    (a measured point alone never replaces a program's tool)."""
    tools = dict(calibration.tools)
    tools[name] = dataclasses.replace(tools[name], for_programs=True)
    return dataclasses.replace(calibration, tools=tools)


def rapid_module(targets, tool_xyz_mm, tool_quat, wobj_xyz_mm, wobj_quat) -> str:
    """A RAPID module with one tooldata 'tcp', one wobjdata, and robtargets p1..pm moved to
    with MoveL (odd: tool tcp in wobj, even: tool tcp in wobj0)."""
    def nums(v, d):
        return ",".join(f"{x:.{d}f}" for x in v)
    lines = ["MODULE Loop",
             f"  PERS tooldata tcp:=[TRUE,[[{nums(tool_xyz_mm, 3)}],[{nums(tool_quat, 6)}]],"
             f"[1,[0,0,50],[1,0,0,0],0,0,0]];",
             f"  PERS wobjdata wTable:=[FALSE,TRUE,\"\",[[{nums(wobj_xyz_mm, 3)}],"
             f"[{nums(wobj_quat, 6)}]],[[0,0,0],[1,0,0,0]]];"]
    for k, (pos, quat, conf) in enumerate(targets, 1):
        lines.append(f"  CONST robtarget p{k}:=[[{nums(pos, 3)}],[{nums(quat, 6)}],"
                     f"[{','.join(str(int(c)) for c in conf)}],[9E9,9E9,9E9,9E9,9E9,9E9]];")
    lines.append("  PROC main()")
    for k in range(1, len(targets) + 1):
        wobj = "\\WObj:=wTable" if k % 2 else ""
        lines.append(f"    MoveL p{k},v100,fine,tcp{wobj};")
    lines += ["  ENDPROC", "ENDMODULE", ""]
    return "\r\n".join(lines)


def written_targets(world: World, q_urdf, flange_T_tool, base_T_wobj, odd_in_wobj=True):
    """Robtarget numbers (position mm, quaternion, confdata) of the nominal TCP at q."""
    tcp = world.nominal.flange_poses(world.robot.controller_from_joints(q_urdf)) @ flange_T_tool
    out = []
    for k, pose in enumerate(tcp, 1):
        wobj = base_T_wobj if (odd_in_wobj and k % 2) else np.eye(4)
        local = invert_pose(wobj) @ pose
        conf = np.concatenate([np.floor(q_urdf[k - 1, [0, 3, 5]] / (np.pi / 2)),
                               branch_of(world.family, q_urdf[k - 1:k])])
        out.append((local[:3, 3] / MM, quat_wxyz_from_matrix(local[:3, :3]), conf))
    return out


def read_rapid_targets(text):
    """name -> (pose (4, 4) m, confdata) or (joints deg,) from RAPID text."""
    program = loads(text, "rapid")
    cart = {t.name: (t.pose(), np.array(t.config_values())) for t in program.targets}
    joints = {t.name: t.joints_deg() for t in program.joint_targets}
    return program, cart, joints


def _frames(world: World, seed: int):
    rng = np.random.default_rng(seed + 100)
    true_tool = world.virtual.tools["tcp"]
    # the program's tooldata: the data-sheet tool, off by about a millimetre from the truth
    program_xyz = true_tool + rng.normal(0, 1e-3, 3)
    tool_rot = rotation_from_rotvec(np.radians([0, 30, 0]))
    program_tool = pose_from_rotation_translation(tool_rot, np.round(program_xyz / MM, 3) * MM)
    wobj = pose_from_rotation_translation(rotation_from_rotvec(np.radians([0, 0, 20])),
                                          np.array([0.6, -0.2, 0.3]))
    return program_tool, wobj, tool_rot, true_tool


_WORLDS: dict = {}


def _world(name: str) -> World:
    if name not in _WORLDS:
        _WORLDS[name] = World(name, seed=3)
    return _WORLDS[name]


@pytest.fixture(scope="module", params=["abb_irb2400", "ur5e"])
def rapid_world(request):
    return _world(request.param)


@pytest.fixture(scope="module")
def irb2400_world():
    return _world("abb_irb2400")


@pytest.mark.parametrize("emit", ["pose", "joints"])
def test_compensated_rapid_program_reaches_the_targets(rapid_world, emit):
    world = rapid_world
    program_tool, wobj, tool_rot, true_tool = _frames(world, 3)
    q = world.program_joints(12, seed=21)
    numbers = written_targets(world, q, program_tool, wobj)
    text = rapid_module(numbers, program_tool[:3, 3] / MM, quat_wxyz_from_matrix(tool_rot),
                        wobj[:3, 3] / MM, quat_wxyz_from_matrix(wobj[:3, :3]))
    out, report = compensate_program(text, "rapid", world.calibration, emit=emit)
    assert report.exit_code == 0, [(r.target, r.status, r.note) for r in report.rows]
    assert all("real TCP of tcp" in r.note for r in report.rows)
    program, cart, joints = read_rapid_targets(out)
    _, original, _ = read_rapid_targets(text)
    real_tool = world.real_tool(tool_rot)
    errors, before = [], []
    for k in range(1, len(numbers) + 1):
        name = f"p{k}"
        frame = wobj if k % 2 else np.eye(4)
        intended = world.desired_in_device(frame @ original[name][0])
        if emit == "joints":
            q_ctrl = np.radians(joints[name])[None]
        else:
            pose, conf = cart[name]
            q_ctrl = world.controller((frame @ pose @ invert_pose(program_tool))[None], conf[None])
        reached = world.real_tcp_in_device(q_ctrl, real_tool)[0]
        errors.append(np.linalg.norm(reached[:3, 3] - intended[:3, 3]))
        assert rotation_angle_between(reached[:3, :3], intended[:3, :3]) < math.radians(0.005)
        pose, conf = original[name]
        q0 = world.controller((frame @ pose @ invert_pose(program_tool))[None], conf[None])
        before.append(np.linalg.norm(world.real_tcp_in_device(q0, real_tool)[0, :3, 3]
                                     - intended[:3, 3]))
    assert max(errors) < TOLERANCE_M, np.array(errors) / MM
    assert min(before) > 0.5e-3, np.array(before) / MM   # uncompensated: millimetres off
    if emit == "joints":
        assert len(program.joint_targets) == len(numbers)
        assert out.count("MoveAbsJ") == len(numbers)


def vplus_file(names, poses) -> str:
    lines = [".PROGRAM loop()"] + [f"    MOVES {n}" for n in names] + [".END", ".LOCATIONS", ""]
    for name, pose in zip(names, poses):
        lines.append(f"{name:<8}" + " ".join(f"{v:10.3f}" for v in pose))
    lines += [".END", ""]
    return "\n".join(lines)


@pytest.fixture(scope="module")
def puma_world():
    return World("unimation_puma560", seed=5)


@pytest.mark.parametrize("emit", ["pose", "joints"])
def test_compensated_vplus_locations_reach_the_targets(puma_world, emit):
    from olp_compensate.kinematics.conventions import euler_zyz_from_matrix

    world = puma_world
    q = world.program_joints(10, seed=8)
    # the branch nearest zero is what the test controller assumes for V+
    flange = world.nominal.flange_poses(world.robot.controller_from_joints(q))
    q_ctrl = world.controller(flange)
    flange = world.nominal.flange_poses(q_ctrl)
    names = [f"loc{k}" for k in range(len(flange))]
    poses = [np.concatenate([f[:3, 3] / MM, np.degrees(euler_zyz_from_matrix(f[:3, :3]))])
             for f in flange]
    text = vplus_file(names, poses)
    out, report = compensate_program(text, "vplus", world.calibration, emit=emit)
    assert report.exit_code == 0, [(r.target, r.status) for r in report.rows]
    program = loads(out, "vplus")
    original = {t.name: t.pose() for t in loads(text, "vplus").targets}
    for name in names:
        intended = world.desired_in_device(original[name])
        if emit == "joints":
            (point,) = [j for j in program.joint_targets if j.name.lstrip("#").lower() == name]
            qc = np.radians(point.joints_deg())[None]
        else:
            (target,) = [t for t in program.targets if t.name == name]
            qc = world.controller(target.pose()[None])
        reached = world.real_tcp_in_device(qc, world.real_tool(np.eye(3)) @ invert_pose(
            pose_from_rotation_translation(np.eye(3), world.calibration.tools['tcp'].xyz_m)))[0]
        assert np.linalg.norm(reached[:3, 3] - intended[:3, 3]) < TOLERANCE_M
        assert rotation_angle_between(reached[:3, :3], intended[:3, :3]) < math.radians(0.005)
    if emit == "joints":
        assert re.search(r"MOVES #loc0", out)


def test_nominal_calibration_changes_no_byte():
    robot = load_robot("abb_irb2400")
    world_nominal = nominal_calibration(robot)
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "samples" / "cell_a.mod"
    data = path.read_bytes()
    out, report = compensate_program(data, "rapid", world_nominal, file=str(path))
    assert out.encode("latin-1") == data
    assert report.edits == 0
    assert any(r.status == "ok" for r in report.rows)


def test_compensate_pose_library_call_matches_program_path(rapid_world):
    world = rapid_world
    program_tool, wobj, tool_rot, _ = _frames(world, 3)
    q = world.program_joints(1, seed=4)
    (pos, quat, conf), = written_targets(world, q, program_tool, wobj)
    pose = pose_from_rotation_translation(matrix_from_quat_wxyz(quat), pos * MM)
    result = compensate_pose(world.calibration, pose, program_tool, wobj, conf)
    assert result.success
    # run it: the nominal controller takes exactly the joints reported
    q_ctrl = world.controller((wobj @ result.pose @ invert_pose(program_tool))[None],
                              np.array(result.config)[None])
    np.testing.assert_allclose(q_ctrl[0], result.joints, atol=1e-8)
    assert 0.05 < np.linalg.norm(result.correction_mm) < 20


def test_unreachable_target_is_a_status_not_an_exception():
    cal = nominal_calibration(load_robot("abb_irb2400"))
    far = pose_from_rotation_translation(np.eye(3), [5.0, 0.0, 0.5])
    result = compensate_pose(cal, far)
    assert not result.success and result.status == "unreachable"
    np.testing.assert_array_equal(result.pose, far)


def test_euler_reader_is_the_one_vplus_uses():
    # guards the V+ test above: the location numbers round-trip through the parser
    R = matrix_from_euler_zyz(*np.radians([30.0, 100.0, -45.0]))
    text = vplus_file(["a"], [np.concatenate([[1, 2, 3], [30.0, 100.0, -45.0]])])
    assert rotation_angle_between(loads(text, "vplus").targets[0].rotation(), R) < 1e-12


UNNORMALIZED = ("MODULE Q\n  CONST robtarget p1:=[[950,0,1100],[0,0,2,0],[0,0,0,0],"
                "[9E9,9E9,9E9,9E9,9E9,9E9]];\n  PROC main()\n    MoveJ p1,v100,fine,tool0;\n"
                "  ENDPROC\nENDMODULE\n")


def test_unnormalized_quaternion_survives_nominal_and_is_rewritten_whole(irb2400_world):
    nominal = nominal_calibration(load_robot("abb_irb2400"))
    out, report = compensate_program(UNNORMALIZED, "rapid", nominal)
    assert out == UNNORMALIZED and report.exit_code == 0
    out, report = compensate_program(UNNORMALIZED, "rapid", irb2400_world.calibration)
    assert report.exit_code == 0
    quat = loads(out, "rapid").targets[0].orientation_values()
    assert abs(np.linalg.norm(quat) - 1.0) < 1e-5     # no mix of old scale and new values
    assert report.rows[0].correction_deg > 0.001


TWO_TOOLS = ("MODULE T\n  PERS tooldata tA:=[TRUE,[[0,0,150],[1,0,0,0]],[1,[0,0,50],[1,0,0,0],0,0,0]];\n"
             "  CONST robtarget p1:=[[950,0,900],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
             "  PROC main()\n    MoveJ p1,v100,fine,tool0;\n    MoveL p1,v100,fine,tA;\n"
             "  ENDPROC\nENDMODULE\n")


def test_target_used_with_two_tools_is_left_as_written_and_reported(irb2400_world):
    out, report = compensate_program(TWO_TOOLS, "rapid", irb2400_world.calibration)
    assert out == TWO_TOOLS and report.exit_code == 2
    assert [r.status for r in report.rows] == ["ambiguous", "ambiguous"]
    assert {r.tool for r in report.rows} == {"tool0", "tA"}
    assert any("p1 is used with 2 tool/work-object pairs" in w for w in report.warnings)


STATIONARY = ("MODULE S\n"
              "  PERS tooldata tFix:=[FALSE,[[1200,300,800],[0,0,1,0]],[1,[0,0,0],[1,0,0,0],0,0,0]];\n"
              "  PERS wobjdata wHeld:=[TRUE,TRUE,\"\",[[0,0,120],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];\n"
              "  CONST robtarget p1:=[[20,-10,5],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
              "  PROC main()\n    MoveL p1,v100,fine,tFix\\WObj:=wHeld;\n  ENDPROC\nENDMODULE\n")


def test_stationary_tool_target_reaches_the_fixed_tool(irb2400_world):
    """Robot-held work object at a stationary tool: the real flange must put the work
    object's target point on the fixed TCP."""
    world = irb2400_world
    out, report = compensate_program(STATIONARY, "rapid", world.calibration)
    assert report.exit_code == 0, report.rows
    program = loads(out, "rapid")
    (rt,) = [r for r in resolve(program).targets if r.target.name == "p1"]
    # controller: base_T_flange = base_T_tool inv(wobj_T_target) inv(flange_T_wobj)
    q_ctrl = world.controller(rt.base_T_flange[None], np.array(rt.target.config_values())[None])
    original = loads(STATIONARY, "rapid").targets[0].pose()
    fixed_tcp = world.desired_in_device(rt.flange_T_tool)          # the fixed tool, device frame
    flange_T_point = world.real_tool(np.eye(3)) @ invert_pose(pose_from_rotation_translation(
        np.eye(3), world.calibration.tools["tcp"].xyz_m)) @ rt.base_T_wobj @ original
    reached = world.real_tcp_in_device(q_ctrl, flange_T_point)[0]
    assert np.linalg.norm(reached[:3, 3] - fixed_tcp[:3, 3]) < TOLERANCE_M


def test_compliance_found_by_diagnose_is_compensated_too():
    """A virtual IRB 2400 whose axis 2 bends under gravity: the extended calibration that
    diagnose finds brings the program within tolerance, the geometric one does not."""
    from dataclasses import replace

    from olp_compensate.calibration.diagnose import DiagnoseOptions, diagnose
    from olp_compensate.calibration.simulate import HiddenEffect

    world = World.__new__(World)
    world.robot = load_robot("abb_irb2400")
    virtual = make_virtual_robot(world.robot, seed=12, n_points=3)
    world.virtual = replace(virtual, effects=(HiddenEffect("joint_compliance", 1, 2e-6),))
    rng = np.random.default_rng(12)
    meas = world.virtual.measure(random_joints(world.robot, 80, rng), NOISE_M, rng)
    found = diagnose(world.robot, meas, DiagnoseOptions(noise_m=NOISE_M))
    assert [(k.effect.kind, k.effect.joint) for k in found.effects][:1] == [("joint_compliance", 1)]
    n = world.robot.n_joints
    world.nominal = VirtualRobot(world.robot, np.zeros((n, 6)), np.zeros(n), np.eye(4), {})
    world.family = fit_family(lambda q: world.nominal.flange_poses(
        world.robot.controller_from_joints(q)))
    world.limits = np.stack([world.robot.lower_limits, world.robot.upper_limits], 1)
    program_tool, wobj, tool_rot, _ = _frames(world, 12)
    q = World.program_joints(world, 10, seed=5)
    errors = {}
    for label, result in (("extended", found.extended), ("geometric", found.geometric)):
        world.calibration = as_program_tool(result.calibration)
        numbers = written_targets(world, q, program_tool, wobj)
        text = rapid_module(numbers, program_tool[:3, 3] / MM, quat_wxyz_from_matrix(tool_rot),
                            wobj[:3, 3] / MM, quat_wxyz_from_matrix(wobj[:3, :3]))
        out, report = compensate_program(text, "rapid", world.calibration)
        assert report.exit_code == 0
        _, cart, _ = read_rapid_targets(out)
        _, original, _ = read_rapid_targets(text)
        worst = 0.0
        for k in range(1, len(numbers) + 1):
            frame = wobj if k % 2 else np.eye(4)
            intended = world.desired_in_device(frame @ original[f"p{k}"][0])
            pose, conf = cart[f"p{k}"]
            qc = world.controller((frame @ pose @ invert_pose(program_tool))[None], conf[None])
            reached = world.real_tcp_in_device(qc, world.real_tool(tool_rot))[0]
            worst = max(worst, np.linalg.norm(reached[:3, 3] - intended[:3, 3]))
        errors[label] = worst
    assert errors["extended"] < TOLERANCE_M, errors
    assert errors["geometric"] > 2 * TOLERANCE_M, errors


def test_bad_pose_input_is_a_data_error():
    from olp_compensate.errors import DataError

    cal = nominal_calibration(load_robot("abb_irb2400"))
    with pytest.raises(DataError, match="tool: poses must be finite"):
        compensate_pose(cal, np.eye(4), tool=np.full((4, 4), np.nan))
    with pytest.raises(DataError, match="wobj: expected shape"):
        compensate_pose(cal, np.eye(4), wobj=np.eye(3))


def test_report_csv_reads_back_field_for_field():
    """The report's CSV (hand-assembled for speed) is what csv.reader reads back: quoted
    names and notes, empty cells for missing numbers, every number in its unit."""
    import csv
    import io
    import math

    from olp_compensate.compensation.report import CompensationReport, TargetReport

    rows = (TargetReport("p1", "a,b.mod", 3, 5, "ok", "tool \"x\"", "wobj0",
                         (1.0, -2.5, 0.00004), 0.25, 1.5, "[0,0,0,0]", "[0,-1,0,0]",
                         (10.0, 20.0, 30.0, 40.0, 50.0, 60.0), "line1\nline2"),
            TargetReport("p2", "f.mod", 4, 1, "unreachable", correction_mm=(math.nan,) * 3,
                         joints=(1.0, math.nan, 3.0, 4.0, 5.0, 6.0)),
            TargetReport("Offs(p1,0,0,10)", "f.mod", 9, 2, "runtime", note="built at run time"))
    table = list(csv.reader(io.StringIO(CompensationReport("f.mod", rows).to_csv())))
    assert table[0][:8] == ["target", "file", "line", "column", "status", "tool", "wobj", "dx_mm"]
    assert table[1] == ["p1", "a,b.mod", "3", "5", "ok", "tool \"x\"", "wobj0", "1.0000",
                        "-2.5000", "0.0000", "0.25000", "1.50000", "[0,0,0,0]", "[0,-1,0,0]",
                        "10.000000", "20.000000", "30.000000", "40.000000", "50.000000",
                        "60.000000", "line1\nline2"]
    assert table[2][7:12] == [""] * 5 and table[2][14:20] == ["1.000000", "", "3.000000",
                                                              "4.000000", "5.000000", "6.000000"]
    assert table[3][14:20] == [""] * 6 and table[3][-1] == "built at run time"
    assert all(len(row) == len(table[0]) for row in table)


@pytest.mark.parametrize("turn_deg, used", [(2.0, True), (90.0, False)])
def test_calibrated_tool_orientation_used_only_near_the_tooldata(turn_deg, used):
    """A calibrated tool of the tooldata's name gives the real TCP; its orientation is
    taken when it is a few degrees from the tooldata's (the tool's axes, measured), kept
    from the tooldata when far (the frame of a measuring probe, not the tool's axes)."""
    import dataclasses

    from olp_compensate.calibration.calibration import ToolPoint

    robot = load_robot("abb_irb2400")
    program_rotation = matrix_from_quat_wxyz([0.92388, 0, 0.382683, 0])
    tool_xyz = np.array([120.5, 0, 210]) * MM
    measured = program_rotation @ rotation_from_rotvec(np.radians([turn_deg, 0, 0]))
    cal = dataclasses.replace(nominal_calibration(robot), tools={
        "tGun": ToolPoint(xyz_m=tool_xyz, quat_wxyz=quat_wxyz_from_matrix(measured),
                          for_programs=True)})
    text = ("MODULE M\n  PERS tooldata tGun:=[TRUE,[[120.5,0,210],[0.92388,0,0.382683,0]],"
            "[2.5,[0,0,80],[1,0,0,0],0,0,0]];\n"
            "  CONST robtarget p1:=[[1200,100,900],[0,0,1,0],[0,0,0,0],"
            "[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
            "  PROC main()\n    MoveL p1,v100,fine,tGun;\n  ENDPROC\nENDMODULE\n")
    out, report = compensate_program(text, "rapid", cal)
    row = report.rows[0]
    assert row.status == "ok"
    if used:  # the TCP turned by 2 deg about its own x: the target turns with it
        assert out != text and row.correction_deg == pytest.approx(turn_deg, abs=1e-3)
        assert "kept" not in row.note
    else:
        assert out == text and "tooldata's orientation kept" in row.note


def test_confdata_texts_of_many_rows_match_row_by_row():
    """The report's confdata column (distinct rows written once, via a 64-bit key) is the
    row-by-row text, also for values beyond the key's 16 bits and rows without confdata."""
    from olp_compensate.compensation.report import config_texts as _config_texts

    rng = np.random.default_rng(0)
    for extreme in (None, 70000, -40000):
        conf = rng.integers(-3, 4, (500, 4))
        if extreme is not None:
            conf[5, 2] = extreme
        has = rng.random(500) > 0.1
        expected = ["[" + ",".join(str(v) for v in row) + "]" if h else ""
                    for row, h in zip(conf.tolist(), has)]
        assert _config_texts(conf, has) == expected


def test_stretched_targets_inside_and_beyond_the_real_arm(irb2400_world):
    """Targets the real arm (the virtual robot) reaches with its elbow 20 to 50 mrad from
    stretched, 0.2 to 1.4 mm inside its reach, are compensated and reached within the
    tolerance. Targets 10 mm beyond its stretched arm (its links are off by about a
    millimetre, its wrist axes miss each other by about as much: no configuration gains
    10 mm) are 'unreachable', and after the first Newton steps only (the calibrated arm's
    reach bound, no restarts)."""
    world = irb2400_world
    cal = world.calibration
    comp = Compensator(cal)
    program_tool, _, tool_rot, _ = _frames(world, 3)
    real_true = world.real_tool(tool_rot)
    real_cal = pose_from_rotation_translation(tool_rot, cal.tools["tcp"].xyz_m)
    theta = np.zeros((1, 6))
    theta[0, 2] = -np.arctan2(comp.family.a2, comp.family.c3)   # the nominal elbow straight
    straight = comp.family.joint_angles(theta)[0, 2]
    rng = np.random.default_rng(11)
    n = 20
    q = world.robot.joints_from_controller(random_joints(world.robot, 20 * n, rng, margin=0.3))
    q[:, 2] = straight
    q[:, 4] = np.where(q[:, 4] < 0, -1.0, 1.0) * np.maximum(np.abs(q[:, 4]), 0.3)
    wrist = np.array([joint_frames(cal.model, cal.model.nominal, x)[4][:3, 3] for x in q])
    # the arm reaching forward, its wrist at least 0.6 m from axis 1
    q = q[(comp.confdata(q)[:, 3] < 4) & (np.hypot(wrist[:, 0], wrist[:, 1]) > 0.6)][:2 * n]
    assert len(q) == 2 * n
    q[:n, 2] += rng.choice([-1.0, 1.0], n) * rng.uniform(0.02, 0.05, n)
    base_T_tcp = invert_pose(cal.device_T_base) @ world.real_tcp_in_device(
        world.robot.controller_from_joints(q), real_true)
    for i in range(n, 2 * n):
        frames = joint_frames(cal.model, cal.model.nominal, q[i])
        outward = frames[4][:3, 3] - frames[1][:3, 3]
        base_T_tcp[i, :3, 3] += 0.010 * outward / np.linalg.norm(outward)
    conf = comp.confdata(q)
    batch = compensate_poses(comp, base_T_tcp, tool=program_tool, confdata=conf,
                             real_tool=real_cal)
    assert batch.status.tolist() == ["ok"] * n + ["unreachable"] * n
    for i in range(n):
        q_ctrl = world.controller((batch.poses[i] @ invert_pose(program_tool))[None],
                                  batch.config[i][None])
        reached = world.real_tcp_in_device(q_ctrl, real_true)[0]
        intended = world.desired_in_device(base_T_tcp[i])
        assert np.linalg.norm(reached[:3, 3] - intended[:3, 3]) < TOLERANCE_M
    beyond = comp.solve_real(base_T_tcp[n:] @ invert_pose(real_cal), conf[n:])
    assert set(beyond.reason) == {"unreachable"} and beyond.iterations.max() <= 8


def test_asked_on_an_unreachable_configuration_names_the_one_that_reaches(irb2400_world):
    """Poses the calibrated arm reaches in front with its elbow 30 mrad from stretched,
    asked for on the configurations reaching over behind axis 1 (cfx 4 to 7: the shoulder
    offset puts them 10 mm and more out of reach). The configuration rule: another
    configuration reaches them (by construction, the one the joints are on), so none is
    'unreachable'; each is 'branch_changed' naming a configuration on which the arm reaches
    the pose inside every range (checked by an independent solve on it and the model's
    forward kinematics), with those joints reported, or 'joint_limit' when the in-front
    joints leave a range."""
    comp = Compensator(irb2400_world.calibration)
    robot = comp.robot
    theta = np.zeros((1, 6))
    theta[0, 2] = -np.arctan2(comp.family.a2, comp.family.c3)   # the nominal elbow straight
    straight = comp.family.joint_angles(theta)[0, 2]
    rng = np.random.default_rng(5)
    n = 12
    q = np.column_stack([rng.uniform(-1, 1, 3 * n), rng.uniform(-0.3, 0.6, 3 * n),
                         np.full(3 * n, straight + 0.03), rng.uniform(-2, 2, 3 * n),
                         rng.choice([-1.0, 1.0], 3 * n) * rng.uniform(0.4, 1.4, 3 * n),
                         rng.uniform(-2, 2, 3 * n)])
    q = q[comp.confdata(q)[:, 3] < 4][:n]                          # in front
    assert len(q) == n
    flange, _ = comp.real_flange_and_jacobian(q)
    nominal = closed_form_inverse(comp.family, flange, clip=True)   # (n, 8, 6)
    poses, asked, truth = [], [], []
    for i in range(n):
        starts = nominal[i][np.all(np.isfinite(nominal[i]), axis=1)]
        behind = comp.confdata(starts)
        behind = behind[behind[:, 3] >= 4]
        poses += [flange[i]] * len(behind)
        asked += list(behind)
        truth += [q[i]] * len(behind)
    poses, asked, truth = np.array(poses), np.array(asked), np.array(truth)
    _, _, solution, _ = comp.compensate_flanges(poses, None, asked)
    failures = explain_failures(comp, solution, poses, asked)
    assert not np.any(solution.success) and "unreachable" not in set(solution.reason)
    note = re.compile(r"asked for configuration \[([-0-9,]+)\], the calibrated arm reaches the "
                      r"target inside every axis range only on another configuration: "
                      r"\[([-0-9,]+)\]")
    changed = 0
    for row in range(len(poses)):
        failure = failures[row]
        in_range_truth = not robot.outside_ranges(
            robot.controller_from_joints(truth[row][None])).any()
        if solution.reason[row] == "joint_limit":
            assert not in_range_truth, failure.note
            continue
        assert solution.reason[row] == "branch_changed"
        found = note.fullmatch(failure.note)
        assert found, failure.note
        assert [int(c) for c in found.group(1).split(",")] == asked[row].tolist()
        named = np.array([[int(c) for c in found.group(2).split(",")]])
        assert named[0, 3] < 4 and tuple(named[0]) == failure.config
        # the reported joints are inside every range and put the real arm on the pose
        assert not robot.outside_ranges(failure.joints[None]).any()
        reached, _ = comp.real_flange_and_jacobian(robot.joints_from_controller(
            failure.joints[None]))
        assert np.allclose(reached[0], poses[row], atol=1e-8)
        again = comp.solve_real(poses[row][None], named)
        assert again.success[0] and again.position_error_m[0] < 1e-9
        changed += 1
    assert changed >= len(poses) // 2


def test_a_target_the_solver_stopped_short_of_is_decided_by_the_search(irb2400_world):
    """A solve that ran out of steps 2 um from a pose the arm reaches on the configuration
    asked for: the rule's search from every configuration reaches it there, inside every
    range, so it is 'ok' with the joints that reach it (not a failure)."""
    from olp_compensate.compensation.config_rule import decide
    from olp_compensate.compensation.ik import IKSolution

    comp = Compensator(irb2400_world.calibration)
    q = np.array([[0.3, 0.2, 0.1, 0.5, 0.8, -0.4]])
    flange, _ = comp.real_flange_and_jacobian(q)
    stopped = IKSolution(q=q + 1e-6, success=np.array([False]),
                         reason=np.array(["not_converged"], dtype="<U14"),
                         iterations=np.array([50]), position_error_m=np.array([2e-6]),
                         rotation_error_rad=np.array([0.0]))
    (failure,) = explain_failures(comp, stopped, flange, comp.confdata(q))
    assert failure is None
    decided = decide(comp, stopped, flange, comp.confdata(q))
    assert decided.reason[0] == "ok" and decided.success[0] and decided.on_asked[0]
    np.testing.assert_allclose(decided.q, q, atol=1e-7)


def test_real_arm_kinematics_are_the_calibrated_models(irb2400_world):
    """The compensator's own pass over the calibrated chain (poses and joint Jacobian) is
    the model's, to rounding, for the calibrated and the data-sheet parameters."""
    cal = irb2400_world.calibration
    comp = Compensator(cal)
    q = np.random.default_rng(1).uniform(-np.pi, np.pi, (300, 6))
    pose, jac = comp.real_flange_and_jacobian(q)
    chain = forward(cal.model, cal.values, q, jacobian=True)
    np.testing.assert_allclose(pose, chain.flange, rtol=0, atol=1e-12)
    np.testing.assert_allclose(jac, np.concatenate([chain.dpoint_dq, chain.drot_dq], axis=1),
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(comp.nominal_flange(q),
                               forward(cal.model, cal.model.nominal, q).flange, rtol=0,
                               atol=1e-12)


def test_nominal_joints_of_the_same_poses_are_the_closed_forms(irb2400_world):
    """compensate_flanges gives the nominal controller's joints of the requested poses;
    when they are the desired ones too, from the closed form the solve starts from: the
    same as solve_nominal, NaN where the nominal arm cannot reach."""
    comp = Compensator(irb2400_world.calibration)
    q = irb2400_world.program_joints(30, seed=2)
    flange = comp.nominal_flange(q)
    flange[0, :3, 3] = [3.0, 0.0, 1.0]                       # beyond the nominal arm
    conf = comp.confdata(q)
    _, _, _, nominal = comp.compensate_flanges(flange, flange.copy(), conf)
    expected = comp.solve_nominal(flange, conf)
    assert np.all(np.isnan(nominal[0])) and np.all(np.isnan(expected[0]))
    np.testing.assert_array_equal(nominal[1:], expected[1:])
    np.testing.assert_allclose(nominal[1:], q[1:], atol=1e-9)


def test_report_rows_pickle_field_for_field():
    """-j N workers send their rows back pickled: every field survives, whatever fields
    the row has."""
    import dataclasses
    import pickle

    from olp_compensate.compensation.report import TargetReport

    row = TargetReport(**{f.name: f"value of {f.name}" for f in dataclasses.fields(TargetReport)})
    back = pickle.loads(pickle.dumps(row, pickle.HIGHEST_PROTOCOL))
    assert back == row and type(back) is TargetReport
