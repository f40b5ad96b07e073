"""The camera pipeline on photographs: views detected, reprojection error, and (when the set
gives known motions) the accuracy as 1:N of the distance.

Run: python benchmarks/camera_real.py PATH... --board board.json [--moves moves.csv]

PATH: folders of .png/.jpg/.jpeg photographs (or files) of one camera at one resolution;
board.json names the board (``"kind"``: olp-dots, opencv-circles, opencv-acircles). Public
calibration photo sets are fetched by the user and never committed. Per view: found or the
reason; then the calibration (RAC or homography start, refinement, circle-centre
correction): reprojection RMS and max (px) per view and overall, the intrinsics with their
standard deviations. With ``--moves`` (``image, dx_mm, dy_mm, dz_mm``, a stage's known
positions): ``olp-cal camera assess``'s three figures on those views.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from olp_compensate.camera.board import read_board  # noqa: E402
from olp_compensate.camera.calibrate import View, calibrate  # noqa: E402
from olp_compensate.camera.detect import circle_centre_bias, detect_dots  # noqa: E402
from olp_compensate.io.images import image_paths, read_grey  # noqa: E402


def detect_all(paths, board):
    """(name -> pixels of the found views, name -> reason of the others, image size)."""
    found, failed, sizes = {}, {}, set()
    for path in paths:
        grey = read_grey(path)
        sizes.add((grey.shape[1], grey.shape[0]))
        result = detect_dots(grey, board, path.name)
        if result.ok:
            found[path.name] = result.pixels
        else:
            failed[path.name] = result.reason
    return found, failed, sizes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="+", metavar="PATH")
    parser.add_argument("--board", required=True, help="board.json")
    parser.add_argument("--moves", help="moves CSV of a stage set (image, dx_mm, dy_mm, dz_mm)")
    args = parser.parse_args()
    board = read_board(args.board)
    paths = [p for item in args.paths for p in image_paths(item)]
    start = time.perf_counter()
    found, failed, sizes = detect_all(paths, board)
    seconds = time.perf_counter() - start
    print(f"{len(found)} of {len(paths)} views detected ({board.kind} {board.rows} x "
          f"{board.cols}) in {seconds:.1f} s")
    for name, reason in failed.items():
        print(f"  not found: {name}: {reason}")
    if len(sizes) != 1:
        raise SystemExit(f"images of {len(sizes)} sizes: one camera, one resolution")
    if len(found) < 3:
        raise SystemExit("fewer than 3 views detected: nothing to calibrate")
    width, height = sizes.pop()
    points = board.dot_positions()
    views = [View(name, pixels, points) for name, pixels in found.items()]
    cal = calibrate(views, width, height,
                    centre_bias=lambda k, T: circle_centre_bias(k, T, board))
    print(f"calibrated {width} x {height} px from {len(cal.views)} views (start {cal.start}): "
          f"reprojection RMS {cal.rms_px:.3f} px, max {cal.max_px:.3f} px")
    for v in cal.views:
        print(f"  {v.name}: RMS {v.rms_px:.3f} px, max {v.max_px:.3f} px, tilt "
              f"{v.tilt_deg:.0f} deg, {v.stage}")
    k = cal.intrinsics
    print("  " + ", ".join(f"{name} {getattr(k, name):.5g} +/- {cal.std[name]:.2g}"
                           for name in ("fx", "mu", "cx", "cy", "k1", "k2")))
    if args.moves:
        from olp_compensate.camera.assess import assess_moves, assessment_table, read_moves
        from olp_compensate.camera.measure import measure_pose

        names, moves = read_moves(args.moves)
        kept = [n for n in names if n in found]
        poses = [measure_pose(found[n], points, k, name=n,
                              centre_bias=lambda i, T: circle_centre_bias(i, T, board)
                              ).board_T_camera for n in kept]
        known = np.array([moves[names.index(n)] for n in kept])
        print(assessment_table(assess_moves(np.array(poses), known, board.centre(), kept)))


if __name__ == "__main__":
    main()
