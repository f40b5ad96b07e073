"""Accuracy assessment from views at known displacements (seed section 9): exact on exact
poses, the injected error found where it was put, and on rendered views of known moves."""

import argparse
import contextlib
import io
import math

import numpy as np
import pytest

from olp_compensate.camera.assess import ErrorStats, assess_moves, mean_rotation, parse_moves
from olp_compensate.camera.board import Board, write_board
from olp_compensate.camera.calibrate import CameraCalibration, ViewResult
from olp_compensate.camera.campaign import board_centre
from olp_compensate.camera.detect import circle_centre_bias, detect_dots
from olp_compensate.camera.measure import measure_pose
from olp_compensate.camera.model import CameraIntrinsics
from olp_compensate.camera.render import RenderOptions, render_board
from olp_compensate.cli import cal_camera
from olp_compensate.cli.common import run_guarded
from olp_compensate.errors import DataError
from olp_compensate.io.camera_file import write_camera
from olp_compensate.io.images import write_png
from olp_compensate.kinematics.conventions import (invert_pose, pose_from_rotation_translation,
                                                   rotation_from_rotvec)

CAMERA = CameraIntrinsics(fx=820.0, mu=1.0, cx=322.0, cy=243.0, k1=0.06, width=640,
                          height=480)
BOARD = Board(rows=7, cols=7, pitch_m=0.02, dot_diameter_m=0.005, marker_diameter_m=0.008)


def stage_scene(moved="camera"):
    """board_T_camera (k, 4, 4) of a camera on a stage, the stage moves (k, 3) m, and
    board_R_stage: 25 positions, 5 x 5 in the stage's x-y plane plus depth steps."""
    board_R_stage = rotation_from_rotvec(np.radians([10.0, -25.0, 40.0]))
    eye = board_centre(BOARD) + [0.16, -0.12, -0.3]
    z = board_centre(BOARD) - eye
    z /= np.linalg.norm(z)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    start = pose_from_rotation_translation(np.column_stack([x, np.cross(z, x), z]), eye)
    g = np.linspace(-0.012, 0.012, 5)
    moves = np.array([[x, y, 0.008 * (i % 3 - 1)] for i, (x, y) in
                      enumerate((x, y) for x in g for y in g)])
    moves -= moves[0]
    sign = 1.0 if moved == "camera" else -1.0
    poses = np.repeat(start[None], len(moves), axis=0)
    poses[:, :3, 3] += sign * moves @ board_R_stage.T
    return poses, moves, board_R_stage


def test_exact_poses_give_zero_errors_and_find_the_stage_axes():
    for moved in ("camera", "board"):
        poses, moves, board_R_stage = stage_scene(moved)
        result = assess_moves(poses, moves + [0.5, 0.2, 0.1], board_centre(BOARD),
                              moved=moved)
        assert result.travel.max_mm < 1e-9
        assert result.spread.max_mm < 1e-9 and result.registered.max_mm < 1e-9
        np.testing.assert_allclose(result.board_R_stage, board_R_stage, atol=1e-9)
        np.testing.assert_allclose(result.known_mm[1:], result.measured_mm[1:], atol=1e-9)
        assert result.travel.median_ratio > 1e12


def test_injected_errors_show_where_they_were_put():
    poses, moves, _ = stage_scene()
    wrong = poses.copy()
    # view 7 measured 0.1 mm too far along its displacement: travel error +0.1 mm there
    direction = wrong[7, :3, 3] - wrong[0, :3, 3]
    wrong[7, :3, 3] += 1e-4 * direction / np.linalg.norm(direction)
    # view 12: camera axes turned by 0.01 deg about an axis normal to T -> spread error
    camera_T_board = invert_pose(wrong[12])
    axis = np.cross(camera_T_board[:3, 3], [0.0, 0.0, 1.0])
    turn = rotation_from_rotvec(math.radians(0.01) * axis / np.linalg.norm(axis))
    camera_T_board[:3, :3] = turn @ camera_T_board[:3, :3]
    wrong[12] = invert_pose(camera_T_board)     # same T: the position moves with R^T
    result = assess_moves(wrong, moves, board_centre(BOARD))
    assert abs(result.travel_error_mm[7] - 0.1) < 1e-3
    others = np.delete(np.abs(result.travel_error_mm), [7, 12])
    assert others.max() < 1e-9
    # spread: view 12's rotation is off by 0.01 deg (the others by 0.01/25 from the mean)
    assert abs(result.spread_deg[12] - 0.01 * 24 / 25) < 1e-4
    lever = np.linalg.norm(camera_T_board[:3, 3]) * 1e3
    assert result.spread_error_mm[12] == pytest.approx(
        lever * math.radians(0.01) * 24 / 25, rel=0.05)
    assert np.argmax(result.registered_error_mm) in (7, 12)
    assert result.travel.max_mm == pytest.approx(np.max(np.abs(result.travel_error_mm)))


def test_error_statistics_and_ratios():
    s = ErrorStats.of(np.array([0.1, -0.2, 0.3]), np.array([500.0, 500.0, 600.0]))
    assert s.mean_mm == pytest.approx(0.2) and s.median_mm == pytest.approx(0.2)
    assert s.max_mm == pytest.approx(0.3) and s.std_mm == pytest.approx(0.1)
    assert s.median_ratio == pytest.approx(2500.0)     # median of 1/5000, 1/2500, 1/2000
    assert s.worst_ratio == pytest.approx(2000.0)


def test_mean_rotation_of_symmetric_spread_is_the_centre():
    centre = rotation_from_rotvec([0.3, -0.2, 1.0])
    spread = [centre @ rotation_from_rotvec(s * np.array(a)) for a in np.eye(3)
              for s in (-0.01, 0.01)]
    np.testing.assert_allclose(mean_rotation(np.array(spread)), centre, atol=1e-9)


def test_bad_moves_files_are_refused_with_the_line():
    with pytest.raises(DataError, match=r"moves.csv:1: missing column\(s\) dz_mm"):
        parse_moves("image,dx_mm,dy_mm\na,0,0\n", "moves.csv")
    with pytest.raises(DataError, match=r"moves.csv:3: dy_mm is not a number: 'x'"):
        parse_moves("image,dx_mm,dy_mm,dz_mm\na,0,0,0\nb,1,x,0\nc,0,0,0\n", "moves.csv")
    with pytest.raises(DataError, match="listed twice"):
        parse_moves("image,dx_mm,dy_mm,dz_mm\na,0,0,0\na,1,0,0\nc,0,0,0\n", "moves.csv")
    names, moves = parse_moves("# stage\nimage,dz_mm,dx_mm,dy_mm,note\na,0,0,0,x\n"
                               "b,3,1,2,y\nc,0,5,0,z\n")
    assert names == ["a", "b", "c"]
    np.testing.assert_allclose(moves[1], [1e-3, 2e-3, 3e-3])
    with pytest.raises(DataError, match="all the same"):
        assess_moves(np.repeat(np.eye(4)[None], 3, 0), np.zeros((3, 3)), np.zeros(3))


def write_true_camera(path, intrinsics):
    """camera.json holding the true intrinsics (and one placeholder view)."""
    view = ViewResult("truth", np.eye(4), 0.0, 0.0, 0.0, True)
    write_camera(path, CameraCalibration(intrinsics=intrinsics, std={}, rac=intrinsics,
                                         method="rac", views=(view,)))


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """25 rendered views of a camera moved by known translations, board.json, camera.json."""
    root = tmp_path_factory.mktemp("assess")
    poses, moves, _ = stage_scene()
    options = RenderOptions(supersample=4, noise_sigma=2.0, blur_sigma_px=0.7, gradient=0.3,
                            vignetting=0.15)
    names = []
    (root / "views").mkdir()
    for k, board_T_camera in enumerate(poses):
        image = render_board(BOARD, CAMERA, invert_pose(board_T_camera),
                             RenderOptions(**{**options.__dict__, "seed": k}))
        names.append(f"pos{k:02d}.png")
        write_png(root / "views" / names[-1], image)
    write_board(BOARD, root / "board.json")
    write_true_camera(root / "camera.json", CAMERA)
    lines = ["image,dx_mm,dy_mm,dz_mm"] + [f"{n},{x * 1e3:.4f},{y * 1e3:.4f},{z * 1e3:.4f}"
                                           for n, (x, y, z) in zip(names, moves)]
    (root / "moves.csv").write_text("\n".join(lines) + "\n")
    return root, names, poses, moves


def _measure(root, names, intrinsics):
    bias = lambda k, T: circle_centre_bias(k, T, BOARD)  # noqa: E731
    from olp_compensate.io.images import read_grey

    out = []
    for name in names:
        found = detect_dots(read_grey(root / "views" / name), BOARD, name)
        assert found.ok, found.reason
        out.append(measure_pose(found.pixels, BOARD.dot_positions(), intrinsics,
                                centre_bias=bias).board_T_camera)
    return np.array(out)


def test_rendered_moves_with_the_true_camera_are_accurate(rendered):
    root, names, poses, moves = rendered
    measured = _measure(root, names, CAMERA)
    result = assess_moves(measured, moves, board_centre(BOARD), names)
    truth = np.linalg.norm(measured[:, :3, 3] - poses[:, :3, 3], axis=1) * 1e3
    # the figures stay within the true errors' size (they are blind to a common offset)
    assert result.registered.max_mm < 2 * truth.max() + 0.01
    assert result.travel.median_ratio > 20_000 and result.travel.worst_ratio > 3_000
    assert result.spread.median_ratio > 3_000
    # a focal length 0.5 % off scales every depth: the travelled distances show it
    wrong = CameraIntrinsics(**{**CAMERA.__dict__, "fx": CAMERA.fx * 1.005})
    worse = assess_moves(_measure(root, names, wrong), moves, board_centre(BOARD), names)
    assert worse.travel.max_mm > 3 * result.travel.max_mm
    assert worse.registered.median_mm > 2 * result.registered.median_mm


def run_assess(argv):
    parser = argparse.ArgumentParser(prog="olp-cal camera")
    cal_camera.add_arguments(parser)
    args = parser.parse_args(["assess"] + list(argv))
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = run_guarded(lambda: cal_camera.run(args), 0, "olp-cal")
    return code, printed.getvalue()


def test_cli_assess_prints_the_three_figures_and_writes_the_csv(rendered, tmp_path):
    root, names, _, _ = rendered
    out = tmp_path / "assess.csv"
    code, text = run_assess([str(root / "views"), "--camera", str(root / "camera.json"),
                             "--board", str(root / "board.json"), "--moves",
                             str(root / "moves.csv"), "-o", str(out)])
    assert code == 0, text
    assert "travelled distance (seed method 1)" in text and "1:" in text
    assert "rotation spread (seed method 2)" in text
    rows = out.read_text().splitlines()
    assert rows[0].startswith("image,distance_mm") and len(rows) == len(names) + 1


def test_cli_assess_names_a_missing_image(rendered, tmp_path, capsys):
    root, _, _, _ = rendered
    moves = tmp_path / "moves.csv"
    moves.write_text("image,dx_mm,dy_mm,dz_mm\npos00.png,0,0,0\nnone.png,1,0,0\n"
                     "pos01.png,0,1,0\n")
    code, _ = run_assess([str(root / "views"), "--camera", str(root / "camera.json"),
                          "--board", str(root / "board.json"), "--moves", str(moves)])
    assert code == 1
    assert "image 'none.png' is not among the images given" in capsys.readouterr().err
