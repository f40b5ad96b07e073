"""``olp-cal camera assess IMAGES --camera camera.json --board board.json --moves moves.csv``:
the accuracy of the camera as a measuring device from views taken at known displacements
(seed section 9; :mod:`olp_compensate.camera.assess`).

moves.csv: ``image, dx_mm, dy_mm, dz_mm``, the known position of the stage (CMM, linear
stage) at each image, stage frame; the first row is the reference. ``--moved board`` when
the board rode the stage and the camera stood still.
Exit codes: 0 success; 1 bad input (one line on stderr).
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

HELP = "accuracy of the camera from views at known displacements (seed section 9)"


def add_arguments(p) -> None:
    p.add_argument("images", nargs="+", metavar="IMAGES",
                   help="folders of .png/.jpg/.jpeg images, or image files")
    p.add_argument("--camera", required=True, help="camera.json from 'camera calibrate'")
    p.add_argument("--board", required=True, help="board.json")
    p.add_argument("--moves", required=True,
                   help="moves CSV: image, dx_mm, dy_mm, dz_mm (known stage positions; the "
                        "first row is the reference)")
    p.add_argument("--moved", choices=("camera", "board"), default="camera",
                   help="what rode the stage (default camera)")
    p.add_argument("-o", "--output", help="also write the per-view figures as CSV")
    p.add_argument("--no-circle-correction", action="store_true",
                   help="use the detected dot centroids as they are")
    from .camera_scale import add_scale_arguments
    add_scale_arguments(p, inherit=True)


def run(args) -> int:
    from ..camera.assess import assess_moves, assessment_table, read_moves
    from ..camera.board import read_board
    from ..camera.campaign import board_centre
    from ..camera.find_board import centre_bias_of, find_board
    from ..camera.measure import measure_pose
    from ..errors import DataError
    from ..io.atomic import write_text_atomic
    from ..io.camera_file import read_camera
    from ..io.images import image_paths, read_grey

    from ..camera.detect_opencv import check_measurable
    from ..camera.scale import scaled_board
    from .camera_scale import board_scale, print_scale

    board = read_board(args.board)
    check_measurable(board)
    camera = read_camera(args.camera)
    intrinsics = camera.intrinsics
    scale = board_scale(args, board, camera.scale)
    nominal_board, board = board, scaled_board(board, scale)
    names, moves = read_moves(args.moves)
    paths = {}
    for item in args.images:
        for path in image_paths(item):
            paths[path.name] = path
    inputs = list(paths.values()) + [Path(args.board), Path(args.camera), Path(args.moves)]
    if args.output and any(Path(args.output).resolve() == p.resolve() for p in inputs):
        raise DataError(f"{args.output}: is an input; choose another output file")
    missing = [n for n in names if n not in paths]
    if missing:
        raise DataError(f"{args.moves}: image '{missing[0]}' is not among the images given")
    bias = centre_bias_of(board, not args.no_circle_correction)
    kept, poses, known = [], [], []
    for name, move in zip(names, moves):
        grey = read_grey(paths[name])
        if (grey.shape[1], grey.shape[0]) != (intrinsics.width, intrinsics.height):
            raise DataError(f"{name}: image is {grey.shape[1]} x {grey.shape[0]} px, the camera "
                            f"was calibrated at {intrinsics.width} x {intrinsics.height}")
        found = find_board(grey, nominal_board, name)
        if not found.ok:
            if not kept:
                raise DataError(f"{name}: board not found ({found.reason}); the reference "
                                f"(first) view must be measured")
            print(f"{name}: board not found ({found.reason}); left out")
            continue
        m = measure_pose(found.pixels, found.points(board), intrinsics, name=name,
                         centre_bias=bias)
        kept.append(name)
        poses.append(m.board_T_camera)
        known.append(move)
    result = assess_moves(np.array(poses), np.array(known), board_centre(board), kept,
                          args.moved)
    print(f"{len(kept)} views, the {args.moved} moved by known translations; errors in mm, "
          f"ratios 1:N of the distance from the camera to the board centre")
    print(assessment_table(result))
    print_scale(scale, result.distance_mm)
    print(implied_scale(result, scale, nominal_board))
    if args.output:
        write_text_atomic(args.output, _csv(result))
        print(f"wrote {args.output}")
    return 0


def implied_scale(result, scale, board) -> str:
    """What the known moves say about the board's scale: the measured travel over the known
    one (least squares) is nominal / printed size of the board as used here."""
    known, measured = result.known_mm[1:], result.measured_mm[1:]
    ratio = float(known @ measured / (known @ known))
    printed = scale.factor / ratio
    bar = board.scale_bar_m * 1e3 * printed
    return (f"the known moves give the printed board {printed:.6f} x board.json's size "
            f"(measured travel / known {ratio:.6f}): as if the scale bar measured "
            f"{bar:.3f} mm (--scale-bar-mm)")


def _csv(result) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["image", "distance_mm", "known_mm", "measured_mm", "travel_error_mm",
                     "spread_error_mm", "registered_error_mm", "rotation_spread_deg"])
    for i, name in enumerate(result.names):
        writer.writerow([name] + [f"{v:.5f}" for v in (
            result.distance_mm[i], result.known_mm[i], result.measured_mm[i],
            result.travel_error_mm[i], result.spread_error_mm[i],
            result.registered_error_mm[i], result.spread_deg[i])])
    return buffer.getvalue()
