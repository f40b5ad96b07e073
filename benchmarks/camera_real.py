"""The camera pipeline on photographs: views detected, reprojection error, OpenCV's
``calibrateCamera`` on the same detections, and (when the set gives known motions) the
accuracy as 1:N of the distance.

Run: python benchmarks/camera_real.py PATH... --board board.json
         [--moves moves.csv] [--flange-poses poses.csv]

PATH: folders of .png/.jpg/.jpeg photographs (or files) of one camera at one resolution;
board.json names the board (``"kind"``: olp-dots, opencv-circles, opencv-acircles,
charuco, chessboard). Public calibration photo sets are fetched by the user and never
committed. Printed, per view: found (whole, or the corners a charuco board shows) or the
reason; then our calibration (RAC or homography start, refinement, circle-centre
correction for dots): reprojection RMS and max (px) per view and overall, the intrinsics
with their standard deviations; then ``cv2.calibrateCamera`` on the same pixels, once
with our model's distortion (k1, k2 radial only) and once with OpenCV's default five
(k1, k2, p1, p2, k3).

Known motions:

- ``--moves`` (``image, dx_mm, dy_mm, dz_mm``, a stage's known translations):
  ``olp-cal camera assess``'s three figures on those views.
- ``--flange-poses`` (``image, x_mm, y_mm, z_mm, qw, qx, qy, qz``: the robot flange in
  its base frame as the controller reports it, camera on the flange, board fixed): the
  hand-eye transform (:func:`hand_eye`) fitted on all views but one predicts where
  the board is in the robot base from the one left out; the distance between that and
  where the others put it, per view, is the error; reported for our poses and for
  OpenCV's, as mm and as 1:N of the camera-board distance. It includes the robot's own
  positioning error, so it bounds the camera's from above. Also, with no fit at all: the
  angle the flange turned between two views against the angle the camera turned (equal
  whatever the mount), per pair of views.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from olp_compensate.camera.board import Board, read_board  # noqa: E402
from olp_compensate.camera.calibrate import View, calibrate  # noqa: E402
from olp_compensate.camera.find_board import centre_bias_of, find_board  # noqa: E402
from olp_compensate.io.images import image_paths, read_grey  # noqa: E402
from olp_compensate.kinematics.conventions import (  # noqa: E402
    matrix_from_quat_wxyz, pose_from_rotation_translation, rotation_angle_between,
    rotation_from_rotvec, rotvec_from_rotation)


def detect_all(paths, board):
    """(name -> FoundView of the found views, name -> reason of the others, image sizes)."""
    found, failed, sizes = {}, {}, set()
    for path in paths:
        grey = read_grey(path)
        sizes.add((grey.shape[1], grey.shape[0]))
        result = find_board(grey, board, path.name)
        if result.ok:
            found[path.name] = result
        else:
            failed[path.name] = result.reason
    return found, failed, sizes


@dataclass(frozen=True)
class PeerCalibration:
    """``cv2.calibrateCamera`` on our detections: overall reprojection RMS (px), camera
    matrix (3, 3), distortion, camera_T_board (4, 4) per view name."""

    label: str
    rms_px: float
    matrix: np.ndarray
    distortion: np.ndarray
    poses: dict


def opencv_calibration(found: dict, board: Board, size, label: str, flags: int):
    """OpenCV's calibration of the same detections (its model, its start, its solver)."""
    import cv2

    names = list(found)
    objects = [found[n].points(board).astype(np.float32) for n in names]
    images = [found[n].pixels.astype(np.float32).reshape(-1, 1, 2) for n in names]
    rms, matrix, dist, rvecs, tvecs = cv2.calibrateCamera(objects, images, size, None, None,
                                                          flags=flags)
    poses = {n: pose_from_rotation_translation(cv2.Rodrigues(r)[0], t.ravel())
             for n, r, t in zip(names, rvecs, tvecs)}
    return PeerCalibration(label, float(rms), matrix, dist.ravel(), poses)


def read_flange_poses(path: str) -> dict:
    """image -> base_T_flange (4, 4), m, from ``image, x_mm, y_mm, z_mm, qw, qx, qy, qz``."""
    out = {}
    with open(path, newline="", encoding="utf-8") as handle:
        for row in csv.DictReader(line for line in handle if not line.startswith("#")):
            q = np.array([float(row[k]) for k in ("qw", "qx", "qy", "qz")])
            t = np.array([float(row[k]) for k in ("x_mm", "y_mm", "z_mm")]) * 1e-3
            out[row["image"].strip()] = pose_from_rotation_translation(
                matrix_from_quat_wxyz(q / np.linalg.norm(q)), t)
    return out


def hand_eye(flange: list, camera_T_board: list, corners: np.ndarray) -> np.ndarray:
    """flange_T_camera (4, 4) of a camera on the flange viewing a fixed board:
    ``base_T_flange_i @ X @ camera_T_board_i`` the same for every view. Start: Park and
    Martin's rotation (Kabsch on the relative motions' rotation vectors) and the linear
    translation; then X and the board's pose in the base fitted together to the board
    ``corners`` (k, 3) in the base frame (least squares, m)."""
    from scipy.optimize import least_squares

    pairs = list(zip(range(len(flange)), range(1, len(flange))))
    A = [np.linalg.inv(flange[j]) @ flange[i] for i, j in pairs]
    B = [camera_T_board[j] @ np.linalg.inv(camera_T_board[i])
         for i, j in pairs]
    a = np.array([rotvec_from_rotation(m[:3, :3]) for m in A])
    b = np.array([rotvec_from_rotation(m[:3, :3]) for m in B])
    u, _, vt = np.linalg.svd(b.T @ a)
    R = (u @ np.diag([1, 1, np.linalg.det(u @ vt)]) @ vt).T
    lhs = np.vstack([m[:3, :3] - np.eye(3) for m in A])
    rhs = np.concatenate([R @ n[:3, 3] - m[:3, 3] for m, n in zip(A, B)])
    X = pose_from_rotation_translation(R, np.linalg.lstsq(lhs, rhs, rcond=None)[0])
    W = flange[0] @ X @ camera_T_board[0]

    def pose(v):
        return pose_from_rotation_translation(rotation_from_rotvec(v[:3]), v[3:])

    def residuals(v):
        x, w = pose(v[:6]), pose(v[6:])
        ends = [(f @ x @ c @ np.c_[corners, np.ones(len(corners))].T)[:3].T
                for f, c in zip(flange, camera_T_board)]
        board = (w @ np.c_[corners, np.ones(len(corners))].T)[:3].T
        return np.concatenate([(e - board).ravel() for e in ends])

    v0 = np.concatenate([rotvec_from_rotation(X[:3, :3]), X[:3, 3],
                         rotvec_from_rotation(W[:3, :3]), W[:3, 3]])
    return pose(least_squares(residuals, v0).x[:6])


def hand_eye_errors(flange: dict, camera_T_board: dict, board: Board):
    """Leave-one-out board-centre errors (m) and camera-board distances (m) per view: the
    hand-eye transform fitted on the other views (:func:`hand_eye`) places the board centre
    in the robot base from the view left out; the others' median is the reference."""
    names = [n for n in camera_T_board if n in flange]
    centre = np.append(board.centre(), 1.0)
    p = board.dot_positions()
    corners = p[[0, board.grid_shape[1] - 1, -board.grid_shape[1], -1]]
    errors, distances = [], []
    for left_out in names:
        rest = [n for n in names if n != left_out]
        X = hand_eye([flange[n] for n in rest], [camera_T_board[n] for n in rest], corners)

        def board_centre_in_base(n):
            return (flange[n] @ X @ camera_T_board[n] @ centre)[:3]

        reference = np.median([board_centre_in_base(n) for n in rest], axis=0)
        errors.append(np.linalg.norm(board_centre_in_base(left_out) - reference))
        distances.append(np.linalg.norm((camera_T_board[left_out] @ centre)[:3]))
    return np.array(errors), np.array(distances)


def turn_errors_deg(flange: dict, camera_T_board: dict) -> np.ndarray:
    """Per pair of views, |the flange's turn - the camera's turn| (deg): both turn by the
    same angle whatever the mount (the motions are conjugate), so this needs no hand-eye
    fit."""
    names = [n for n in camera_T_board if n in flange]
    out = []
    for k, a in enumerate(names):
        for b in names[k + 1:]:
            robot = rotation_angle_between(flange[a][:3, :3], flange[b][:3, :3])
            camera = rotation_angle_between(camera_T_board[a][:3, :3],
                                            camera_T_board[b][:3, :3])
            out.append(abs(np.degrees(robot - camera)))
    return np.array(out)


def print_hand_eye(label: str, errors: np.ndarray, distances: np.ndarray,
                   turns: np.ndarray) -> None:
    ratio = distances / np.maximum(errors, 1e-12)
    print(f"  {label}: board centre from the view left out, median {np.median(errors) * 1e3:.3f}"
          f" mm, max {np.max(errors) * 1e3:.3f} mm; median 1:{np.median(ratio):,.0f} of the "
          f"{np.median(distances) * 1e3:.0f} mm distance; turn between views, robot vs "
          f"camera, median {np.median(turns):.3f} deg, max {np.max(turns):.3f} deg "
          f"({len(turns)} pairs)")


def print_ours(cal, found: dict) -> None:
    print(f"ours: {cal.intrinsics.width} x {cal.intrinsics.height} px from {len(cal.views)} "
          f"views (start {cal.start}): reprojection RMS {cal.rms_px:.3f} px, max "
          f"{cal.max_px:.3f} px")
    for v in cal.views:
        print(f"  {v.name}: RMS {v.rms_px:.3f} px, max {v.max_px:.3f} px, tilt "
              f"{v.tilt_deg:.0f} deg, {v.stage}{found[v.name].describe()}")
    k = cal.intrinsics
    print("  " + ", ".join(f"{name} {getattr(k, name):.5g} +/- {cal.std[name]:.2g}"
                           for name in ("fx", "mu", "cx", "cy", "k1", "k2")))


def print_peer(peer: PeerCalibration) -> None:
    m = peer.matrix
    print(f"OpenCV calibrateCamera, {peer.label}: reprojection RMS {peer.rms_px:.3f} px; fx "
          f"{m[0, 0]:.5g}, fy/fx {m[1, 1] / m[0, 0]:.6f}, cx {m[0, 2]:.5g}, cy {m[1, 2]:.5g}, "
          f"distortion {np.array2string(peer.distortion, precision=4)}")


def assess(args, found, board, cal) -> None:
    from olp_compensate.camera.assess import assess_moves, assessment_table, read_moves
    from olp_compensate.camera.measure import measure_pose

    names, moves = read_moves(args.moves)
    kept = [n for n in names if n in found]
    poses = [measure_pose(found[n].pixels, found[n].points(board), cal.intrinsics, name=n,
                          centre_bias=centre_bias_of(board)).board_T_camera for n in kept]
    known = np.array([moves[names.index(n)] for n in kept])
    print(assessment_table(assess_moves(np.array(poses), known, board.centre(), kept)))


def main() -> None:
    import cv2

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="+", metavar="PATH")
    parser.add_argument("--board", required=True, help="board.json")
    parser.add_argument("--moves", help="moves CSV of a stage set (image, dx_mm, dy_mm, dz_mm)")
    parser.add_argument("--flange-poses", help="CSV: image, x_mm, y_mm, z_mm, qw, qx, qy, qz")
    args = parser.parse_args()
    board = read_board(args.board)
    paths = [p for item in args.paths for p in image_paths(item)]
    start = time.perf_counter()
    found, failed, sizes = detect_all(paths, board)
    seconds = time.perf_counter() - start
    partial = sum(f.partial for f in found.values())
    print(f"{len(found)} of {len(paths)} views detected ({partial} partly), {board.kind} "
          f"{board.rows} x {board.cols}, in {seconds:.1f} s")
    for name, reason in failed.items():
        print(f"  not found: {name}: {reason}")
    if len(sizes) != 1:
        raise SystemExit(f"images of {len(sizes)} sizes: one camera, one resolution")
    if len(found) < 3:
        raise SystemExit("fewer than 3 views detected: nothing to calibrate")
    width, height = sizes.pop()
    views = [View(name, f.pixels, f.points(board)) for name, f in found.items()]
    cal = calibrate(views, width, height, centre_bias=centre_bias_of(board))
    print_ours(cal, found)
    peers = [opencv_calibration(found, board, (width, height), "k1, k2 (our model's count)",
                                cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K3),
             opencv_calibration(found, board, (width, height), "k1, k2, p1, p2, k3", 0)]
    for peer in peers:
        print_peer(peer)
    if args.moves:
        assess(args, found, board, cal)
    if args.flange_poses:
        flange = read_flange_poses(args.flange_poses)
        ours = {v.name: v.camera_T_board for v in cal.views}
        print(f"hand-eye, {sum(n in flange for n in ours)} views with flange poses "
              f"(leave one out):")
        print_hand_eye("ours", *hand_eye_errors(flange, ours, board),
                       turn_errors_deg(flange, ours))
        for peer in peers:
            print_hand_eye(f"OpenCV {peer.label}", *hand_eye_errors(flange, peer.poses, board),
                           turn_errors_deg(flange, peer.poses))


if __name__ == "__main__":
    main()
