"""Virtual camera campaigns: the poses see the board as asked on the *true* arm, inside the
controller's ranges; the files on disk carry the truth; the ``olp-cal simulate --camera``
entry point."""

import argparse
import contextlib
import csv
import io
import math

import numpy as np
import pytest
from test_assess import write_true_camera

from olp_compensate.calibration.pose_planning import design_quality, planning_space
from olp_compensate.calibration.simulate import VirtualRobot
from olp_compensate.camera.board import Board, write_board
from olp_compensate.camera.campaign import (CAMERA_TOOL, ViewLimits, board_centre, choose_poses,
                                            make_camera_robot, nominal_inverse, plan_campaign,
                                            read_campaign_truth, write_campaign)
from olp_compensate.camera.detect import detect_dots
from olp_compensate.camera.model import CameraIntrinsics, project_points
from olp_compensate.camera.render import RenderOptions
from olp_compensate.cli import cal_simulate
from olp_compensate.cli.cal_simulate_camera import add_camera_arguments, run_camera
from olp_compensate.cli.common import run_guarded
from olp_compensate.errors import DataError
from olp_compensate.io.images import read_grey
from olp_compensate.kinematics.conventions import (invert_pose, pose_from_rotation_translation,
                                                   rotation_angle_between)
from olp_compensate.kinematics.robot import load_robot

CAMERA = CameraIntrinsics(fx=800.0, mu=1.0, cx=322.0, cy=241.0, k1=0.05, width=640,
                          height=480)
BOARD = Board(rows=7, cols=7, pitch_m=0.025, dot_diameter_m=0.006, marker_diameter_m=0.01)
LIMITS = ViewLimits(distance_m=(0.35, 0.6), tilt_deg=(20.0, 45.0), margin_px=15.0)


@pytest.fixture(scope="module")
def irb2400():
    return load_robot("abb_irb2400")


@pytest.fixture(scope="module")
def campaign(irb2400):
    virtual = make_camera_robot(irb2400, BOARD, seed=3)
    return plan_campaign(virtual, BOARD, CAMERA, 8, np.random.default_rng(4), LIMITS,
                         candidates_per_pose=1)


def nominal_arm(robot):
    n = robot.n_joints
    return VirtualRobot(robot, np.zeros((n, 6)), np.zeros(n), np.eye(4), {})


def test_camera_mount_and_board_are_plausible(campaign):
    flange_T_camera = campaign.flange_T_camera
    assert 0.05 <= flange_T_camera[2, 3] <= 0.15
    # optical axis roughly along the flange z
    assert math.degrees(math.acos(flange_T_camera[2, 2])) < 15
    np.testing.assert_allclose(campaign.virtual.device_T_base,
                               invert_pose(campaign.base_T_board), atol=1e-12)
    assert set(campaign.virtual.tools) == {CAMERA_TOOL}
    # the printed face looks up: board z (away from the print) points down in the base
    assert campaign.base_T_board[2, 2] < -0.99


def test_every_pose_sees_the_whole_board_on_the_true_arm(campaign, irb2400):
    q = campaign.joints
    assert q.shape == (8, 6) and not np.any(irb2400.outside_ranges(q))
    # independent: the virtual arm's true flange (pinocchio), the board and the hand-eye
    base_T_flange = campaign.virtual.flange_poses(q)
    points = BOARD.dot_positions()
    for k, flange in enumerate(base_T_flange):
        board_T_camera = invert_pose(campaign.base_T_board) @ flange @ campaign.flange_T_camera
        camera_T_board = invert_pose(board_T_camera)
        np.testing.assert_allclose(campaign.camera_T_board[k], camera_T_board, atol=1e-12)
        pixels = project_points(CAMERA, camera_T_board, points)
        assert np.all((pixels >= 15) & (pixels <= [640 - 16, 480 - 16]))
        tilt = math.degrees(math.acos(abs(camera_T_board[2, 2])))
        assert 19.5 <= tilt <= 45.5
        centre = camera_T_board[:3, :3] @ board_centre(BOARD) + camera_T_board[:3, 3]
        assert 0.3 < np.linalg.norm(centre) < 0.7
    # different views, not one repeated
    assert len({tuple(np.round(T[:3, 3], 3)) for T in campaign.camera_T_board}) == 8


def test_nominal_inverse_reaches_the_flange_pose_on_the_nominal_arm(irb2400):
    rng = np.random.default_rng(7)
    nominal = nominal_arm(irb2400)
    q_true = np.radians([[20.0, 10.0, 15.0, 30.0, 60.0, -40.0]])
    target = nominal.flange_poses(q_true)[0]
    q = nominal_inverse(irb2400, target, rng)
    assert q is not None and not np.any(irb2400.outside_ranges(q[None]))
    reached = nominal.flange_poses(q[None])[0]
    assert np.linalg.norm(reached[:3, 3] - target[:3, 3]) < 1e-6
    assert rotation_angle_between(reached[:3, :3], target[:3, :3]) < 1e-6
    far = pose_from_rotation_translation(np.eye(3), [5.0, 0.0, 0.5])
    assert nominal_inverse(irb2400, far, rng) is None


def test_a_board_out_of_reach_is_reported(irb2400):
    far = pose_from_rotation_translation(np.diag([1.0, -1.0, -1.0]), [6.0, 0.0, 0.0])
    virtual = make_camera_robot(irb2400, BOARD, seed=1, base_T_board=far)
    with pytest.raises(DataError, match="found 0 of 3 poses in 20 tries"):
        plan_campaign(virtual, BOARD, CAMERA, 3, np.random.default_rng(0), LIMITS,
                      candidates_per_pose=1, max_tries=20)


def test_planner_keeps_the_poses_that_identify_the_arm_best(irb2400):
    virtual = make_camera_robot(irb2400, BOARD, seed=5)
    drawn = plan_campaign(virtual, BOARD, CAMERA, 36, np.random.default_rng(6), LIMITS,
                          candidates_per_pose=1)
    chosen = choose_poses(virtual, drawn.joints, 12)
    assert len(set(chosen)) == 12 and np.all(np.diff(chosen) > 0)
    space = planning_space(irb2400, candidates=drawn.joints,
                           tools={CAMERA_TOOL: virtual.tools[CAMERA_TOOL]})
    planned = design_quality(space, chosen).expected_error
    first = design_quality(space, np.arange(12)).expected_error
    assert planned < 0.8 * first
    np.testing.assert_array_equal(choose_poses(virtual, drawn.joints, 5), np.arange(5))  # too few


def test_written_campaign_carries_images_joints_and_truth(campaign, irb2400, tmp_path):
    few = type(campaign)(virtual=campaign.virtual, board=BOARD, intrinsics=CAMERA,
                         joints=campaign.joints[:3], camera_T_board=campaign.camera_T_board[:3],
                         names=campaign.names[:3])
    images = write_campaign(few, tmp_path, RenderOptions(supersample=4, noise_sigma=2.0,
                                                         blur_sigma_px=0.8, gradient=0.3))
    for k, name in enumerate(few.names):
        found = detect_dots(read_grey(images / name), BOARD, name)
        assert found.ok, found.reason
        truth = project_points(CAMERA, few.camera_T_board[k], BOARD.dot_positions())
        assert np.median(np.hypot(*(found.pixels - truth).T)) < 0.3
    with open(tmp_path / "joints.csv") as handle:
        rows = list(csv.DictReader(handle))
    assert [r["image"] for r in rows] == list(few.names)
    np.testing.assert_allclose([[float(r[f"q{j}_deg"]) for j in range(1, 7)] for r in rows],
                               np.degrees(few.joints), atol=1e-5)
    virtual, camera = read_campaign_truth(tmp_path / "truth.json", irb2400)
    np.testing.assert_allclose(virtual.origin_errors, campaign.virtual.origin_errors,
                               atol=1e-12)
    np.testing.assert_allclose(virtual.true_frames(few.joints, [CAMERA_TOOL] * 3),
                               invert_pose(few.camera_T_board), atol=1e-9)
    assert camera["intrinsics"]["fx_px"] == 800.0 and camera["board"]["rows"] == 7
    assert len(camera["views"]) == 3 and camera["render"]["noise_sigma"] == 2.0


def olp_cal_simulate(argv):
    """``olp-cal simulate ARGV`` (through olp-cal once the lead hooks --camera in)."""
    parser = argparse.ArgumentParser(prog="olp-cal simulate")
    cal_simulate.add_arguments(parser)
    if not any(a.dest == "camera" for a in parser._actions):
        add_camera_arguments(parser)
    args = parser.parse_args(argv)
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = run_guarded(lambda: run_camera(args), 0, "olp-cal")
    return code, printed.getvalue()


def test_cli_writes_a_campaign_folder(tmp_path, capsys):
    write_true_camera(tmp_path / "camera.json", CAMERA)
    write_board(BOARD, tmp_path / "board.json")
    out = tmp_path / "campaign"
    code, text = olp_cal_simulate(["--camera", str(tmp_path / "camera.json"), "--board",
                                   str(tmp_path / "board.json"), "--robot", "abb_irb2400",
                                   "--poses", "2", "--seed", "5", "--distance-mm", "350:600",
                                   "--candidates-per-pose", "2",
                                   "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 0, err
    # progress on stderr (issue 25: 64 s of silence before)
    assert "planning 2 poses" in err and "rendered 1 of 2 views" in err
    assert "rendered 2 of 2 views" in err
    assert sorted(p.name for p in (out / "images").iterdir()) == ["view001.png", "view002.png"]
    assert (out / "joints.csv").read_text().startswith("image,q1_deg,")
    assert "truth" in text
    code, _ = olp_cal_simulate(["--camera", str(tmp_path / "camera.json"), "--robot",
                                "abb_irb2400", "--poses", "2", "-o", str(out)])
    assert code == 1 and "--camera needs --board" in capsys.readouterr().err
