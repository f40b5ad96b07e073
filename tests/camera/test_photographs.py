"""Issue 33 item 4: what real photographs bring, checked without the photographs. Views of
a chessboard and of a ChArUco board are made by warping a drawing of the board with a known
pinhole camera's homography, then spoiled as photographs are (uneven light, sensor noise,
JPEG compression, colour, a board partly out of view, 16-bit files, EXIF orientation,
large sensors). Truth: the known camera's projection of the corners, and its intrinsics."""

from __future__ import annotations

import json
import struct
import sys
from pathlib import Path

import numpy as np
import pytest

from olp_compensate.camera.board import board_from_dict, board_to_dict
from olp_compensate.camera.calibrate import View, calibrate
from olp_compensate.camera.detect_opencv import MIN_CORNERS
from olp_compensate.camera.drawing import board_svg
from olp_compensate.camera.find_board import find_board
from olp_compensate.camera.model import CameraIntrinsics, project_points
from olp_compensate.camera.render import random_views
from olp_compensate.cli.cal import main
from olp_compensate.errors import DataError
from olp_compensate.io.camera_file import read_camera
from olp_compensate.io.images import read_grey

cv2 = pytest.importorskip("cv2")

PINHOLE = CameraIntrinsics(fx=900.0, mu=1.0, cx=323.0, cy=238.0, width=640, height=480)
CHESS = {"kind": "chessboard", "rows": 7, "cols": 9, "pitch_mm": 25.0}
CHARUCO = {"kind": "charuco", "rows": 5, "cols": 7, "pitch_mm": 30.0, "marker_mm": 22.0,
           "dictionary": "DICT_4X4_50"}


def _chess_page(board, px_per_square=120, margin=120):
    """A chessboard drawing (grey, 230 paper, 30 ink) and its board-to-page matrix S."""
    rows, cols = board.rows, board.cols
    page = np.full((rows * px_per_square + 2 * margin, cols * px_per_square + 2 * margin),
                   230, np.uint8)
    for r in range(rows):
        for c in range(cols):
            if (r + c) % 2 == 0:
                y, x = margin + r * px_per_square, margin + c * px_per_square
                page[y:y + px_per_square, x:x + px_per_square] = 30
    scale = px_per_square / board.pitch_m
    S = np.array([[scale, 0, margin - 0.5], [0, scale, margin - 0.5], [0, 0, 1.0]])
    return page, S


def _charuco_page():
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    size, margin = (2800, 2000), 200
    page = cv2.aruco.CharucoBoard((7, 5), 0.03, 0.022, d).generateImage(size, marginSize=margin)
    inner = (size[0] - 2 * margin, size[1] - 2 * margin)
    scale = min(inner[0] / 0.21, inner[1] / 0.15)
    offset = (margin + (inner[0] - 0.21 * scale) / 2, margin + (inner[1] - 0.15 * scale) / 2)
    return page, np.array([[scale, 0, offset[0] - 0.5], [0, scale, offset[1] - 0.5],
                           [0, 0, 1.0]])


def _photograph(page, S, pose, camera=PINHOLE, zoom=1):
    """The page seen by ``camera`` (scaled by ``zoom``) at ``pose``, warped at 4 x the
    resolution and averaged down (no aliasing)."""
    K = np.array([[camera.fx, 0, camera.cx], [0, camera.fy, camera.cy], [0, 0, 1.0]])
    K = np.array([[zoom, 0, (zoom - 1) / 2], [0, zoom, (zoom - 1) / 2], [0, 0, 1]]) @ K
    up = np.array([[4.0, 0, 1.5], [0, 4.0, 1.5], [0, 0, 1]])
    size = (camera.width * zoom, camera.height * zoom)
    fine = cv2.warpPerspective(page, up @ K @ pose[:3, [0, 1, 3]] @ np.linalg.inv(S),
                               (4 * size[0], 4 * size[1]), flags=cv2.INTER_LINEAR,
                               borderValue=150)
    return cv2.resize(fine, size, interpolation=cv2.INTER_AREA)


def _spoil(grey, seed, light=0.5, noise=3.0, quality=75):
    """As a phone or webcam delivers it: the light falling by ``light`` across the image,
    Gaussian noise (grey levels), a colour cast, JPEG at ``quality``: the encoded bytes."""
    rng = np.random.default_rng(seed)
    h, w = grey.shape
    fall = 1.0 - light * (np.arange(w)[None, :] / w + np.arange(h)[:, None] / h) / 2
    lit = grey * fall + rng.normal(0.0, noise, grey.shape)
    bgr = np.clip(np.stack([lit * 0.8, lit, lit * 1.1], -1), 0, 255).astype(np.uint8)
    ok, data = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, quality])
    assert ok
    return data.tobytes()


def _error_px(found, truth, board):
    """RMS distance (px) of the found corners to the truth, allowing the half turn of a
    chessboard (its corners reversed)."""
    def rms(p):
        return float(np.sqrt(np.mean(np.sum((p - truth[found.indices]) ** 2, axis=1))))
    return rms(found.pixels) if board.kind != "chessboard" else \
        min(rms(found.pixels), rms(found.pixels[::-1]))


def test_chessboard_photographs_in_poor_light_calibrate_the_known_camera(tmp_path, capsys):
    board = board_from_dict(CHESS)
    assert board.count == 48 and board.grid_shape == (6, 8)
    page, S = _chess_page(board)
    poses = random_views(board, PINHOLE, 8, np.random.default_rng(11), (0.45, 0.6),
                         (15.0, 40.0), margin_px=20.0)
    truth = {}
    for k, pose in enumerate(poses):
        (tmp_path / f"v{k}.jpg").write_bytes(_spoil(_photograph(page, S, pose), k))
        truth[f"v{k}.jpg"] = project_points(PINHOLE, pose, board.dot_positions())
    for name, expected in truth.items():
        found = find_board(read_grey(tmp_path / name), board, name)
        assert found.ok and not found.partial, getattr(found, "reason", "")
        assert _error_px(found, expected, board) < 0.2
    (tmp_path / "board.json").write_text(json.dumps(CHESS))
    out = tmp_path / "out"
    out.mkdir()
    assert main(["camera", "calibrate", str(tmp_path), "--board", str(tmp_path / "board.json"),
                 "-o", str(out / "camera.json")]) == 0
    assert "corners as detected" in capsys.readouterr().out
    k = read_camera(out / "camera.json").intrinsics
    assert abs(k.fx / PINHOLE.fx - 1) < 0.005
    assert abs(k.cx - PINHOLE.cx) < 2.0 and abs(k.cy - PINHOLE.cy) < 2.0
    # a chessboard is ambiguous by a half turn: it calibrates, it does not measure
    assert main(["camera", "measure", str(tmp_path), "--camera", str(out / "camera.json"),
                 "--board", str(tmp_path / "board.json"), "-o", str(out / "p.csv")]) == 1
    assert "half turn" in capsys.readouterr().err


def test_a_large_sensor_is_searched_shrunk_and_refined_at_full_resolution():
    board = board_from_dict(CHESS)
    page, S = _chess_page(board, px_per_square=300, margin=300)
    pose = random_views(board, PINHOLE, 1, np.random.default_rng(4), (0.45, 0.6),
                        (25.0, 35.0), margin_px=20.0)[0]
    image = _photograph(page, S, pose, zoom=4)               # 2560 x 1920 px
    big = CameraIntrinsics(fx=4 * PINHOLE.fx, mu=1.0, cx=4 * PINHOLE.cx + 1.5,
                           cy=4 * PINHOLE.cy + 1.5, width=2560, height=1920)
    found = find_board(image, board, "big")
    assert found.ok, found.reason
    assert _error_px(found, project_points(big, pose, board.dot_positions()), board) < 0.3


def test_a_charuco_board_partly_hidden_gives_the_corners_it_shows_and_calibrates():
    board = board_from_dict(CHARUCO)
    page, S = _charuco_page()
    poses = random_views(board, PINHOLE, 7, np.random.default_rng(5), (0.35, 0.5),
                         (20.0, 40.0), margin_px=20.0)
    views, partial = [], 0
    for k, pose in enumerate(poses):
        image = _photograph(page, S, pose)
        if k % 2:                               # a hand over the right third of the view
            image[:, 430:] = 90
        grey = cv2.imdecode(np.frombuffer(_spoil(image, k, light=0.3, noise=2.0, quality=85),
                                          np.uint8), cv2.IMREAD_GRAYSCALE)
        found = find_board(grey, board, f"c{k}")
        assert found.ok, found.reason
        truth = project_points(PINHOLE, pose, board.dot_positions())
        assert _error_px(found, truth, board) < 0.3
        if k % 2:                               # no corner under the hand is reported
            hidden = np.flatnonzero(truth[:, 0] > 425)
            assert len(hidden) and not np.any(np.isin(hidden, found.indices))
        partial += found.partial
        views.append(View(found.name, found.pixels, found.points(board)))
    assert partial >= 2
    cal = calibrate(views, 640, 480)
    assert abs(cal.intrinsics.fx - PINHOLE.fx) < 3.0 and abs(cal.intrinsics.cx - PINHOLE.cx) < 3.0
    # too little of the board: refused with the reason, not guessed
    image = _photograph(page, S, poses[0])
    image[:, 200:] = 90
    found = find_board(image, board, "corner")
    assert not found.ok and (f"need at least {MIN_CORNERS}" in found.reason
                             or "one row or column" in found.reason)


def test_board_json_for_a_chessboard_and_what_is_refused():
    board = board_from_dict(CHESS)
    assert board_to_dict(board) == CHESS
    assert np.allclose(board.dot_positions()[[0, 1, 8], :2],
                       [[0.025, 0.025], [0.05, 0.025], [0.025, 0.05]])
    with pytest.raises(DataError, match="chessboard needs 'pitch_mm'"):
        board_from_dict({"kind": "chessboard", "rows": 7, "cols": 9})
    with pytest.raises(DataError, match="not drawn here"):
        board_svg(board)


def _jpeg_with_orientation(image: np.ndarray, orientation: int) -> bytes:
    """A JPEG of ``image`` with an EXIF orientation tag (TIFF little-endian, one entry)."""
    ok, jpg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 95])
    assert ok
    tiff = (b"II*\x00" + struct.pack("<I", 8) + struct.pack("<H", 1)
            + struct.pack("<HHIHH", 0x0112, 3, 1, orientation, 0) + struct.pack("<I", 0))
    app1 = b"Exif\x00\x00" + tiff
    jpg = jpg.tobytes()
    return jpg[:2] + b"\xff\xe1" + struct.pack(">H", len(app1) + 2) + app1 + jpg[2:]


def test_image_files_are_read_as_the_sensor_wrote_them(tmp_path):
    image = np.full((40, 60), 40, np.uint8)
    image[:10, :20] = 220                                    # bright block, top left
    (tmp_path / "turned.jpg").write_bytes(_jpeg_with_orientation(image, 6))
    grey = read_grey(tmp_path / "turned.jpg")
    assert grey.shape == (40, 60)                            # not turned to 60 x 40
    assert grey[:10, :20].mean() > 200 and grey[20:, 30:].mean() < 60
    # 12-bit data in a 16-bit PNG: scaled to the brightest pixel, not cut to its top byte
    twelve = (np.arange(40 * 60).reshape(40, 60) % 4096).astype(np.uint16)
    ok, png = cv2.imencode(".png", twelve)
    (tmp_path / "deep.png").write_bytes(png.tobytes())
    grey = read_grey(tmp_path / "deep.png")
    assert grey.dtype == np.uint8 and grey.max() == 255
    assert np.array_equal(grey, np.round(twelve * (255.0 / twelve.max())).astype(np.uint8))
    # colour: the luma
    bgr = np.zeros((4, 4, 3), np.uint8)
    bgr[..., 1] = 200
    ok, png = cv2.imencode(".png", bgr)
    (tmp_path / "green.png").write_bytes(png.tobytes())
    assert abs(int(read_grey(tmp_path / "green.png")[0, 0]) - round(0.587 * 200)) <= 1


def test_the_benchmarks_hand_eye_check_recovers_a_known_camera_mount(tmp_path, monkeypatch):
    """benchmarks/camera_real.py --flange-poses: a camera 120 mm off a flange (known
    mount X), a fixed board (known pose W); the views' camera_T_board follow from both. The
    fit recovers X; the leave-one-out error is zero on exact poses and of the size of the
    pose noise otherwise."""
    import importlib.util

    from olp_compensate.camera.board import Board
    from olp_compensate.kinematics.conventions import (
        invert_pose, pose_from_rotation_translation, quat_wxyz_from_matrix,
        rotation_angle_between, rotation_from_rotvec)

    spec = importlib.util.spec_from_file_location(
        "camera_real", Path(__file__).resolve().parents[2] / "benchmarks" / "camera_real.py")
    real = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "camera_real", real)      # its dataclasses need it
    spec.loader.exec_module(real)
    rng = np.random.default_rng(8)

    def pose(angle_scale, centre, spread):
        return pose_from_rotation_translation(rotation_from_rotvec(rng.normal(0, angle_scale, 3)),
                                              centre + rng.normal(0, spread, 3))
    X = pose(0.6, np.array([0.02, -0.05, 0.12]), 0.0)
    W = pose(0.2, np.array([0.6, 0.1, 0.0]), 0.0)
    board = Board(rows=7, cols=9, pitch_m=0.025, dot_diameter_m=0.025,
                  marker_diameter_m=0.025, kind="chessboard")
    flange, seen, noisy = {}, {}, {}
    for k in range(7):
        A = pose(0.35, np.array([0.6, 0.1, 0.5]), 0.08)
        flange[f"v{k}"], seen[f"v{k}"] = A, invert_pose(A @ X) @ W
        noisy[f"v{k}"] = pose(2e-4, np.zeros(3), 5e-5) @ seen[f"v{k}"]
    lines = ["image,x_mm,y_mm,z_mm,qw,qx,qy,qz"] + [
        ",".join([n] + [f"{v * 1e3:.6f}" for v in A[:3, 3]]
                 + [f"{v:.12f}" for v in quat_wxyz_from_matrix(A[:3, :3])])
        for n, A in flange.items()]
    (tmp_path / "flange.csv").write_text("\n".join(lines) + "\n")
    flange = real.read_flange_poses(str(tmp_path / "flange.csv"))
    p = board.dot_positions()
    found = real.hand_eye(list(flange.values()), list(noisy.values()), p[[0, 7, -8, -1]])
    assert np.linalg.norm(found[:3, 3] - X[:3, 3]) < 1e-3
    assert np.degrees(rotation_angle_between(found[:3, :3], X[:3, :3])) < 0.1
    exact, distances = real.hand_eye_errors(flange, seen, board)
    assert np.max(exact) < 1e-6 and np.all((distances > 0.2) & (distances < 1.5))
    errors, _ = real.hand_eye_errors(flange, noisy, board)
    assert 1e-5 < np.median(errors) < 1e-3
    # the turn between two views is the flange's and the camera's alike, with no fit
    assert len(real.turn_errors_deg(flange, seen)) == 21
    assert np.max(real.turn_errors_deg(flange, seen)) < 1e-4
    assert 1e-4 < np.median(real.turn_errors_deg(flange, noisy)) < 0.1


@pytest.mark.parametrize("kind", ["opencv-acircles", "opencv-circles", "olp-dots"])
def test_circle_boards_under_uneven_light_and_jpeg_are_found_to_a_tenth_of_a_pixel(kind):
    """Rendered views (camera/render.py) with 70 % of the light lost across the image, 30 %
    vignetting, noise and JPEG at 75 %: every dot found, within 0.1 px RMS of the truth."""
    from olp_compensate.camera.board import Board
    from olp_compensate.camera.render import RenderOptions, render_board

    camera = CameraIntrinsics(fx=900.0, mu=1.0, cx=323.0, cy=238.0, k1=0.06, width=640,
                              height=480)
    rows, cols = (11, 4) if kind == "opencv-acircles" else (6, 9)
    board = Board(rows=rows, cols=cols, pitch_m=0.02, dot_diameter_m=0.01,
                  marker_diameter_m=0.016 if kind == "olp-dots" else 0.01, kind=kind)
    poses = random_views(board, camera, 4, np.random.default_rng(3), (0.35, 0.55),
                         (20.0, 45.0), margin_px=15.0)
    for k, pose in enumerate(poses):
        image = render_board(board, camera, pose, RenderOptions(
            supersample=4, noise_sigma=3.0, blur_sigma_px=0.8, gradient=0.7,
            vignetting=0.3, seed=k))
        ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 75])
        found = find_board(cv2.imdecode(data, cv2.IMREAD_GRAYSCALE), board, f"v{k}")
        assert found.ok, found.reason
        truth = project_points(camera, pose, board.dot_positions())
        error = np.linalg.norm(found.pixels - truth, axis=1)
        if kind == "opencv-circles":                          # ambiguous by a half turn
            error = np.minimum(error, np.linalg.norm(found.pixels[::-1] - truth, axis=1))
        assert np.sqrt(np.mean(error ** 2)) < 0.1


def test_a_circle_grid_on_a_large_sensor_is_ordered_on_a_shrunk_copy():
    """cv2.findCirclesGrid lost this asymmetric grid at 1920 x 1440 px (it found the dots and
    could not order them): the view, enlarged 3 times, is found, every dot within 0.3 px of
    the enlarged truth."""
    from olp_compensate.camera.board import Board
    from olp_compensate.camera.render import RenderOptions, render_board

    camera = CameraIntrinsics(fx=900.0, mu=1.0, cx=323.0, cy=238.0, k1=0.06, width=640,
                              height=480)
    board = Board(rows=11, cols=4, pitch_m=0.02, dot_diameter_m=0.01,
                  marker_diameter_m=0.01, kind="opencv-acircles")
    pose = random_views(board, camera, 1, np.random.default_rng(3), (0.35, 0.55),
                        (20.0, 45.0), margin_px=15.0)[0]
    image = render_board(board, camera, pose, RenderOptions(supersample=4, noise_sigma=2.0,
                                                            blur_sigma_px=0.8, seed=1))
    big = cv2.resize(image, None, fx=3, fy=3, interpolation=cv2.INTER_CUBIC)
    found = find_board(big, board, "big")
    assert found.ok, found.reason
    truth = (project_points(camera, pose, board.dot_positions()) + 0.5) * 3 - 0.5
    assert np.max(np.linalg.norm(found.pixels - truth, axis=1)) < 0.3
