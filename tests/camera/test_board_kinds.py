"""Issue 33 item 4 (part): the boards users own, OpenCV's symmetric and asymmetric circle
grids and ChArUco boards, named in board.json (``"kind"``), found and calibrated from.
Truth: the rendering (or warping) camera's projection of the dot centres or corners."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from olp_compensate.camera.board import Board, board_from_dict, read_board
from olp_compensate.camera.calibrate import View, calibrate
from olp_compensate.camera.detect import detect_dots
from olp_compensate.camera.drawing import board_svg
from olp_compensate.camera.model import CameraIntrinsics, project_points
from olp_compensate.camera.render import RenderOptions, random_views, render_board
from olp_compensate.cli.cal import main
from olp_compensate.errors import DataError

ROOT = Path(__file__).resolve().parents[2]
CAMERA = CameraIntrinsics(fx=900.0, mu=1.0, cx=323.0, cy=238.0, k1=0.06, width=640,
                          height=480)
ACIRCLES = Board(rows=11, cols=4, pitch_m=0.02, dot_diameter_m=0.01,
                 marker_diameter_m=0.01, kind="opencv-acircles")
CIRCLES = Board(rows=6, cols=9, pitch_m=0.02, dot_diameter_m=0.01, marker_diameter_m=0.01,
                kind="opencv-circles")


def test_board_json_names_the_kind_and_the_layout_is_opencvs(tmp_path):
    doc = {"kind": "opencv-acircles", "rows": 11, "cols": 4, "pitch_mm": 20.0,
           "dot_diameter_mm": 10.0}                         # no marker for OpenCV's grids
    board = board_from_dict(doc)
    assert board == ACIRCLES
    # OpenCV's samples: object point (i, j) at ((2 j + i % 2) s, i s)
    expected = [((2 * j + i % 2) * 0.02, i * 0.02) for i in range(11) for j in range(4)]
    assert np.allclose(board.dot_positions()[:, :2], expected)
    assert board_svg(board).count("<circle") == 44
    assert main(["camera", "board", "--kind", "opencv-circles", "--rows", "6", "--cols", "9",
                 "--pitch-mm", "20", "--dot-mm", "10", "-o", str(tmp_path / "b.json")]) == 0
    assert read_board(tmp_path / "b.json") == CIRCLES
    assert json.loads((tmp_path / "b.json").read_text())["kind"] == "opencv-circles"
    with pytest.raises(DataError, match="charuco board needs 'marker_mm'"):
        board_from_dict({**doc, "kind": "charuco"})
    with pytest.raises(DataError, match="unknown kind"):
        board_from_dict({**doc, "kind": "apriltag-grid"})


def _views(board, count, seed):
    poses = random_views(board, CAMERA, count, np.random.default_rng(seed), (0.35, 0.55),
                         (20.0, 45.0), margin_px=15.0)
    out = []
    for k, pose in enumerate(poses):
        image = render_board(board, CAMERA, pose, RenderOptions(supersample=4, noise_sigma=2.0,
                                                               blur_sigma_px=0.8, seed=k))
        out.append((detect_dots(image, board, f"v{k}"), pose))
    return out


@pytest.mark.parametrize("board", [ACIRCLES, CIRCLES], ids=["acircles", "circles"])
def test_opencv_grids_are_found_to_a_tenth_of_a_pixel_and_calibrate(board):
    found = _views(board, 6, 3)
    views = []
    for detection, pose in found:
        assert detection.ok, detection.reason
        truth = project_points(CAMERA, pose, board.dot_positions())
        error = np.linalg.norm(detection.pixels - truth, axis=1)
        if board.kind == "opencv-circles":            # ambiguous by a half turn
            error = np.minimum(error, np.linalg.norm(detection.pixels[::-1] - truth, axis=1))
        assert np.max(error) < 0.15
        views.append(View(detection.name, detection.pixels, board.dot_positions()))
    cal = calibrate(views, 640, 480)
    assert abs(cal.intrinsics.fx - CAMERA.fx) < 1.0 and abs(cal.intrinsics.cx - CAMERA.cx) < 1.0


def test_a_symmetric_grid_does_not_measure_poses(tmp_path, capsys):
    (tmp_path / "b.json").write_text(json.dumps({
        "kind": "opencv-circles", "rows": 6, "cols": 9, "pitch_mm": 20.0,
        "dot_diameter_mm": 10.0}))
    assert main(["camera", "measure", str(tmp_path), "--camera", str(ROOT / "samples" / "camera.json"),
                 "--board", str(tmp_path / "b.json"), "-o", str(tmp_path / "p.csv")]) == 1
    assert "half turn" in capsys.readouterr().err


CHARUCO = {"kind": "charuco", "rows": 5, "cols": 7, "pitch_mm": 30.0, "marker_mm": 22.0,
           "dictionary": "DICT_4X4_50"}
PINHOLE = CameraIntrinsics(fx=900.0, mu=1.0, cx=323.0, cy=238.0, width=640, height=480)


def _charuco_views(board, count, seed):
    """Views of OpenCV's own drawing of the board, warped by a pinhole camera's homography
    (no distortion): (grey image, camera_T_board) pairs."""
    import cv2

    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    opencv_board = cv2.aruco.CharucoBoard((7, 5), 0.03, 0.022, d)
    size, margin = (2800, 2000), 200
    page = opencv_board.generateImage(size, marginSize=margin)
    inner = (size[0] - 2 * margin, size[1] - 2 * margin)
    scale = min(inner[0] / 0.21, inner[1] / 0.15)         # px per m, as generateImage fits
    offset = (margin + (inner[0] - 0.21 * scale) / 2, margin + (inner[1] - 0.15 * scale) / 2)
    S = np.array([[scale, 0, offset[0] - 0.5], [0, scale, offset[1] - 0.5], [0, 0, 1.0]])
    K = np.array([[PINHOLE.fx, 0, PINHOLE.cx], [0, PINHOLE.fy, PINHOLE.cy], [0, 0, 1.0]])
    out = []
    for pose in random_views(board, PINHOLE, count, np.random.default_rng(seed),
                             (0.35, 0.5), (20.0, 40.0), margin_px=20.0):
        # warped at 4 x the resolution, then averaged down: no aliasing of the edges
        up = np.diag([4.0, 4.0, 1.0]) @ np.array([[1, 0, 0.375], [0, 1, 0.375], [0, 0, 1]])
        M = up @ K @ pose[:3, [0, 1, 3]] @ np.linalg.inv(S)
        fine = cv2.warpPerspective(page, M, (2560, 1920), flags=cv2.INTER_LINEAR,
                                   borderValue=200)
        image = cv2.resize(fine, (640, 480), interpolation=cv2.INTER_AREA)
        out.append((image, pose))
    return out


def test_charuco_corners_are_found_and_calibrate():
    board = board_from_dict(CHARUCO)
    assert board.count == 24 and board.grid_shape == (4, 6)
    assert np.allclose(board.dot_positions()[:2, :2], [[0.03, 0.03], [0.06, 0.03]])
    views = []
    for k, (image, pose) in enumerate(_charuco_views(board, 6, 5)):
        found = detect_dots(image, board, f"c{k}")
        assert found.ok, found.reason
        truth = project_points(PINHOLE, pose, board.dot_positions())
        # OpenCV's sub-pixel corners, used as they are: 0.04-0.16 px RMS on these views
        assert np.sqrt(np.mean(np.sum((found.pixels - truth) ** 2, axis=1))) < 0.25
        views.append(View(found.name, found.pixels, board.dot_positions()))
    cal = calibrate(views, 640, 480)
    assert abs(cal.intrinsics.fx - PINHOLE.fx) < 2.0 and abs(cal.intrinsics.cx - PINHOLE.cx) < 2.0
    with pytest.raises(DataError, match="not drawn here"):
        board_svg(board)
    with pytest.raises(DataError, match="dictionary"):
        board_from_dict({**CHARUCO, "dictionary": "4x4"})
