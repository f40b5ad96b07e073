"""From rendered pixels to a compensated program, on a virtual IRB 2400 with a camera on
its flange (the seed's setup, sections 8-10).

Calibration views of the board are rendered with a known camera and the camera calibrated
from them (``olp-cal camera calibrate``); a virtual campaign of 40 robot poses is rendered
and measured with the joints (``olp-cal camera measure --joints``) into a measurement CSV
whose rows are full poses: the camera frame in the board frame. Identification finds the
arm's geometry, the board's place (the device registration) and the camera as a tool (its
position and rotation in the flange frame). A RAPID program written for the nominal arm with
the designed camera mount is compensated, and its joints run on the virtual arm: the real
camera frame reaches the intended poses in the board frame within a tolerance far below the
uncompensated miss. Numbers over the workspace are the benchmark's
(``python benchmarks/camera.py``).
"""

import argparse
import contextlib
import dataclasses
import io
import math

import numpy as np
import pytest

from olp_compensate.calibration.identify import IdentificationOptions, identify
from olp_compensate.calibration.simulate import VirtualRobot, random_joints
from olp_compensate.camera.board import Board, write_board
from olp_compensate.camera.campaign import (CAMERA_TOOL, ViewLimits, make_camera_robot,
                                            plan_campaign, write_campaign)
from olp_compensate.camera.model import CameraIntrinsics
from olp_compensate.camera.render import RenderOptions, random_views, render_board
from olp_compensate.cli import cal_camera
from olp_compensate.cli.common import run_guarded
from olp_compensate.compensation.ik import branch_of, fit_family
from olp_compensate.io.camera_file import read_camera
from olp_compensate.io.images import write_png
from olp_compensate.io.measurements import read_measurements
from olp_compensate.kinematics.conventions import (MM, pose_from_rotation_translation,
                                                   quat_wxyz_from_matrix, rotation_angle_between,
                                                   rotation_from_rotvec)
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs import loads
from olp_compensate.programs.object_model.task import compensate_program

CAMERA = CameraIntrinsics(fx=900.0, mu=1.0, cx=323.0, cy=238.0, k1=0.06, width=640,
                          height=480)
BOARD = Board(rows=7, cols=7, pitch_m=0.025, dot_diameter_m=0.006, marker_diameter_m=0.01)
LIMITS = ViewLimits(distance_m=(0.35, 0.55), tilt_deg=(20.0, 45.0), margin_px=15.0)
RENDER = RenderOptions(supersample=6, noise_sigma=2.0, blur_sigma_px=0.8, gradient=0.3,
                       vignetting=0.15)


def olp_cal_camera(argv):
    from olp_compensate.cli import cal

    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        if "camera" in cal.COMMANDS:
            code = cal.main(["camera"] + list(argv))
        else:
            parser = argparse.ArgumentParser(prog="olp-cal camera")
            cal_camera.add_arguments(parser)
            args = parser.parse_args(argv)
            code = run_guarded(lambda: cal_camera.run(args), 0, "olp-cal")
    assert code == 0, printed.getvalue()
    return printed.getvalue()


@pytest.fixture(scope="module")
def pipeline(tmp_path_factory):
    return run_pipeline(tmp_path_factory.mktemp("end_to_end"))


def run_pipeline(root):
    """Calibrated camera, the measured campaign, the identification, the virtual robot."""
    write_board(BOARD, root / "board.json")
    (root / "cal").mkdir()
    rng = np.random.default_rng(11)
    for k, T in enumerate(random_views(BOARD, CAMERA, 10, rng, distance_m=(0.3, 0.45),
                                       tilt_deg=(25.0, 50.0), margin_px=10.0)):
        image = render_board(BOARD, CAMERA, T, RenderOptions(**{**RENDER.__dict__,
                                                                 "seed": 500 + k}))
        write_png(root / "cal" / f"cal{k:02d}.png", image)
    olp_cal_camera(["calibrate", str(root / "cal"), "--board", str(root / "board.json"),
                    "-o", str(root / "camera.json")])
    robot = load_robot("abb_irb2400")
    virtual = make_camera_robot(robot, BOARD, seed=21)
    campaign = plan_campaign(virtual, BOARD, CAMERA, 40, np.random.default_rng(22), LIMITS)
    images = write_campaign(campaign, root / "campaign", RENDER)
    olp_cal_camera(["measure", str(images), "--camera", str(root / "camera.json"), "--board",
                    str(root / "board.json"), "--joints", str(root / "campaign" / "joints.csv"),
                    "-o", str(root / "meas.csv")])
    meas = read_measurements(root / "meas.csv", robot)
    sigma_mm = float(np.median([float(v) for v in meas.extra["sigma_mm"]]))
    sigma_deg = float(np.median([float(v) for v in meas.extra["sigma_deg"]]))
    result = identify(robot, meas, IdentificationOptions(
        folds=0, position_sigma_mm=sigma_mm, orientation_sigma_deg=sigma_deg))
    return {"robot": robot, "virtual": virtual, "campaign": campaign, "meas": meas,
            "result": result, "camera": read_camera(root / "camera.json")}


@pytest.mark.slow
def test_camera_calibrated_from_rendered_views(pipeline):
    k = pipeline["camera"].intrinsics
    assert abs(k.fx - CAMERA.fx) < 1.5 and abs(k.cx - CAMERA.cx) < 1.5
    assert abs(k.cy - CAMERA.cy) < 1.5 and abs(k.k1 - CAMERA.k1) < 0.01


@pytest.mark.slow
def test_identified_robot_finds_the_camera_mount_and_predicts_new_poses(pipeline):
    robot, virtual, result = pipeline["robot"], pipeline["virtual"], pipeline["result"]
    assert pipeline["meas"].n_rows == 40 and pipeline["meas"].orientation is not None
    calibration = result.calibration
    tool = calibration.tools[CAMERA_TOOL]
    assert tool.quat_wxyz is not None
    # new poses anywhere in the workspace (the camera need not see the board there)
    q = random_joints(robot, 300, np.random.default_rng(23))
    truth = virtual.true_frames(q, [CAMERA_TOOL] * len(q))
    predicted = calibration.predict_points(q, [CAMERA_TOOL] * len(q))
    error = np.linalg.norm(predicted - truth[:, :3, 3], axis=1)
    nominal = identify(robot, pipeline["meas"], IdentificationOptions(
        folds=0, freeze=tuple(result.calibration.model.names))).calibration
    nominal_error = np.linalg.norm(nominal.predict_points(q, [CAMERA_TOOL] * len(q))
                                   - truth[:, :3, 3], axis=1)
    assert np.sqrt(np.mean(error ** 2)) < 0.15 * MM, np.sqrt(np.mean(error ** 2)) / MM
    assert np.sqrt(np.mean(nominal_error ** 2)) > 10 * np.sqrt(np.mean(error ** 2))
    rotation = rotation_angle_between(
        calibration.predict_rotations(q, [CAMERA_TOOL] * len(q)), truth[:, :3, :3])
    assert np.max(rotation) < math.radians(0.02)


def rapid_module(targets, tool: np.ndarray) -> str:
    """RAPID: tooldata 'camera' = ``tool`` (4, 4), robtargets p1..pm moved to with MoveL."""
    def nums(v, digits):
        return ",".join(f"{x:.{digits}f}" for x in v)

    lines = ["MODULE Look",
             f"  PERS tooldata camera:=[TRUE,[[{nums(tool[:3, 3] / MM, 3)}],"
             f"[{nums(quat_wxyz_from_matrix(tool[:3, :3]), 6)}]],"
             f"[1,[0,0,50],[1,0,0,0],0,0,0]];"]
    for k, (pose, conf) in enumerate(targets, 1):
        lines.append(f"  CONST robtarget p{k}:=[[{nums(pose[:3, 3] / MM, 3)}],"
                     f"[{nums(quat_wxyz_from_matrix(pose[:3, :3]), 6)}],"
                     f"[{','.join(str(int(c)) for c in conf)}],[9E9,9E9,9E9,9E9,9E9,9E9]];")
    lines += ["  PROC main()"] + [f"    MoveL p{k},v100,fine,camera;"
                                  for k in range(1, len(targets) + 1)]
    lines += ["  ENDPROC", "ENDMODULE", ""]
    return "\n".join(lines)


@pytest.mark.slow
def test_compensated_program_brings_the_real_camera_to_its_targets(pipeline):
    robot, virtual = pipeline["robot"], pipeline["virtual"]
    calibration = pipeline["result"].calibration
    # the camera point, calibrated for programs too (as olp-cal tool marks a tool): only
    # such a tool replaces the program's tooldata 'camera'
    tools = dict(calibration.tools)
    tools[CAMERA_TOOL] = dataclasses.replace(tools[CAMERA_TOOL], for_programs=True)
    calibration = dataclasses.replace(calibration, tools=tools)
    n = robot.n_joints
    nominal = VirtualRobot(robot, np.zeros((n, 6)), np.zeros(n), np.eye(4), {})
    family = fit_family(lambda q: nominal.flange_poses(robot.controller_from_joints(q)))
    # the camera mount as designed: the true one off by about a millimetre and half a degree
    true_mount = pose_from_rotation_translation(virtual.tool_rotation(CAMERA_TOOL),
                                                virtual.tools[CAMERA_TOOL])
    design = pose_from_rotation_translation(
        true_mount[:3, :3] @ rotation_from_rotvec(np.radians([0.4, -0.3, 0.5])),
        np.round((true_mount[:3, 3] + [0.8e-3, -0.6e-3, 1.0e-3]) / MM, 1) * MM)
    rng = np.random.default_rng(24)
    q = robot.joints_from_controller(random_joints(robot, 40, rng, margin=0.3))
    q = q[np.abs(np.sin(q[:, 4])) > math.sin(math.radians(20))][:8]
    targets = []
    for qk, flange in zip(q, nominal.flange_poses(robot.controller_from_joints(q))):
        conf = np.concatenate([np.floor(qk[[0, 3, 5]] / (np.pi / 2)),
                               branch_of(family, qk[None])])
        targets.append((flange @ design, conf))
    text = rapid_module(targets, design)
    out, report = compensate_program(text, "rapid", calibration, emit="joints")
    assert report.exit_code == 0, [(r.target, r.status, r.note) for r in report.rows]
    assert all("real TCP of camera" in r.note for r in report.rows)
    joints = {t.name: np.radians(t.joints_deg()) for t in loads(out, "rapid").joint_targets}
    after, before = [], []
    for k, (target, _) in enumerate(targets, 1):
        intended = calibration.device_T_base @ target          # in the board frame
        reached = virtual.true_frames(joints[f"p{k}"][None], [CAMERA_TOOL])[0]
        after.append(np.linalg.norm(reached[:3, 3] - intended[:3, 3]))
        assert rotation_angle_between(reached[:3, :3], intended[:3, :3]) < math.radians(0.02)
        # uncompensated: the nominal controller goes to the written joints
        missed = virtual.true_frames(robot.controller_from_joints(q[k - 1:k]),
                                     [CAMERA_TOOL])[0]
        before.append(np.linalg.norm(missed[:3, 3] - intended[:3, 3]))
    assert min(before) > 1.0 * MM, np.array(before) / MM
    assert max(after) < 0.2 * MM, np.array(after) / MM
    assert max(after) < min(before) / 10
