"""``olp-cal camera``: make a dot board, calibrate a camera from views of it, measure the
camera's pose in the board frame.

- ``board``: board.json (and optionally the printable SVG / PNG).
- ``calibrate IMAGES... --board board.json -o camera.json``: the seed's RAC followed by the
  full refinement (``--method rac-only`` keeps the RAC estimates); any board kind
  (:mod:`..camera.board`), a charuco board's partial views included
  (:mod:`..camera.find_board`).
- ``measure IMAGES... --camera camera.json --board board.json -o poses.csv``: one row per
  image, the camera frame in the board frame; with ``--joints joints.csv`` a measurement CSV
  for ``olp-cal identify`` (the board is the measuring device, the camera the tool).
- ``assess IMAGES... --camera camera.json --board board.json --moves moves.csv``: accuracy
  from views at known displacements (seed section 9, :mod:`.cal_camera_assess`).

IMAGES: folders (their .png/.jpg/.jpeg files, any case, sorted by name) or files.
Exit codes: 0 success; 1 bad input (one line on stderr).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import re
from pathlib import Path

import numpy as np

from ..camera.board import (CORNER_KINDS, READ_KINDS, Board, board_to_dict, read_board,
                            write_board)
from ..camera.detect_opencv import check_measurable
from ..camera.scale import SCALE_LINE, BoardScale, scaled_board
from ..camera.calibrate import METHODS, View, calibrate
from ..camera.find_board import centre_bias_of, find_board
from ..camera.measure import measure_pose
from ..errors import DataError
from .camera_scale import add_scale_arguments, board_scale, print_scale
from ..io.atomic import write_text_atomic
from ..io.camera_file import read_camera, write_camera
from ..io.images import image_paths, read_grey
from ..kinematics.conventions import MM, invert_pose
from ..io.measurements import FORMAT_LINE, parse_cell_number, read_csv_text

HELP = "camera: make a dot board, calibrate a camera from views of it, measure camera poses"

JOINT_RE = re.compile(r"q(\d+)_(deg|mm)$")


def add_arguments(p) -> None:
    sub = p.add_subparsers(dest="camera_command", required=True, metavar="SUBCOMMAND")
    b = sub.add_parser("board", help="write board.json (and a printable SVG/PNG)",
                       description="Write a dot board's description (board.json, mm) and "
                                   "optionally a drawing to print at scale.")
    b.add_argument("--rows", type=int, default=9, help="dot rows (default 9)")
    b.add_argument("--cols", type=int, default=7, help="dot columns (default 7)")
    b.add_argument("--pitch-mm", type=float, default=22.0,
                   help="centre-to-centre distance of the dots, mm (default 22: the default "
                        "sheet, 184 x 228 mm, prints on A4 and Letter)")
    b.add_argument("--dot-mm", type=float, default=5.0, help="dot diameter, mm (default 5)")
    b.add_argument("--marker-mm", type=float, default=8.0,
                   help="diameter of the marker dot (row 0, column 0), mm (default 8)")
    b.add_argument("--kind", choices=READ_KINDS[:3], default="olp-dots",
                   help="olp-dots (default: ours, with a marker dot); opencv-circles or "
                        "opencv-acircles: OpenCV's symmetric or asymmetric circle grid "
                        "(--cols circles per row; no marker)")
    b.add_argument("-o", "--output", required=True, help="board.json to write")
    b.add_argument("--svg", help="also write the board as SVG (print at 100 %%)")
    b.add_argument("--png", help="also write the board as PNG")
    b.add_argument("--dpi", type=float, default=300.0, help="PNG resolution (default 300)")

    c = sub.add_parser("calibrate", help="calibrate the camera from views of the board",
                       description="Calibrate a camera from images of the dot board: the "
                                   "seed's RAC (Tsai), then a full Levenberg-Marquardt "
                                   "refinement on the reprojection error.")
    c.add_argument("images", nargs="+", metavar="IMAGES",
                   help="folders of .png/.jpg/.jpeg images, or image files")
    c.add_argument("--board", required=True,
                   help="board.json; its \"kind\": olp-dots (default), opencv-circles, "
                        "opencv-acircles, charuco (views showing part of the board are "
                        "used) or chessboard")
    c.add_argument("-o", "--output", required=True, help="camera.json to write")
    c.add_argument("--method", choices=METHODS, default="rac",
                   help="rac: the RAC then the full refinement (default); rac-only: keep the "
                        "RAC estimates, as the seed did")
    c.add_argument("--no-circle-correction", action="store_true",
                   help="use the detected dot centroids as they are (default: correct the "
                        "perspective bias of circle centres)")
    add_scale_arguments(c)
    c.add_argument("--html", metavar="REPORT.html",
                   help="also write an HTML report: parameters, reprojection error per view, "
                        "each view with its dots and magnified residuals")

    m = sub.add_parser("measure", help="the camera's pose in the board frame, per image",
                       description="Measure the camera frame in the board frame in each image "
                                   "with the calibrated intrinsics.")
    m.add_argument("images", nargs="+", metavar="IMAGES",
                   help="folders of .png/.jpg/.jpeg images, or image files")
    m.add_argument("--camera", required=True, help="camera.json from 'camera calibrate'")
    m.add_argument("--board", required=True, help="board.json")
    m.add_argument("-o", "--output", required=True,
                   help="CSV to write: image, x_mm, y_mm, z_mm, qw, qx, qy, qz, rms_px "
                        "(with --joints: a measurement CSV for 'olp-cal identify')")
    m.add_argument("--joints", help="joints CSV: image, q1_deg..qN_deg [, pose, other "
                                    "columns passed through]")
    m.add_argument("--name", default="camera",
                   help="point name in the measurement CSV (default camera)")
    m.add_argument("--no-circle-correction", action="store_true",
                   help="use the detected dot centroids as they are")
    add_scale_arguments(m, inherit=True)

    from . import cal_camera_assess
    cal_camera_assess.add_arguments(sub.add_parser(
        "assess", help=cal_camera_assess.HELP, description=cal_camera_assess.HELP))


def run(args) -> int:
    if args.camera_command == "assess":
        from . import cal_camera_assess
        return cal_camera_assess.run(args)
    return {"board": _run_board, "calibrate": _run_calibrate,
            "measure": _run_measure}[args.camera_command](args)


# -- shared -----------------------------------------------------------------------------------

def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve()
    except OSError:
        return False


def _check_output(out: Path, inputs: list[Path]) -> None:
    for source in inputs:
        if _same_file(out, source):
            raise DataError(f"{out}: is an input ({source}); inputs are never overwritten, "
                            f"choose another output file")


def _expand(images: list[str]) -> list[Path]:
    paths = []
    for item in images:
        paths += image_paths(item)
    names = [p.name for p in paths]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup is not None:
        raise DataError(f"{dup}: two images of this name; rows are named by file name, "
                        f"rename one")
    return paths


def _detect(paths: list[Path], board: Board):
    """(name, :class:`FoundView` or None, reason, (width, height)) per image, in order; an
    unreadable image is a DataError."""
    out = []
    for path in paths:
        if not path.is_file():
            raise DataError(f"{path}: no such image file")
        grey = read_grey(path)
        found = find_board(grey, board, path.name)
        size = (grey.shape[1], grey.shape[0])
        if found.ok:
            out.append((path.name, found, "", size))
        else:
            out.append((path.name, None, found.reason, size))
    return out


# -- board ------------------------------------------------------------------------------------

def _run_board(args) -> int:
    from ..camera.drawing import check_png_size, fits_on, write_board_png, write_board_svg

    marker = args.marker_mm if args.kind == "olp-dots" else args.dot_mm
    board = Board(rows=args.rows, cols=args.cols, pitch_m=args.pitch_mm * 1e-3,
                  dot_diameter_m=args.dot_mm * 1e-3, marker_diameter_m=marker * 1e-3,
                  kind=args.kind)
    outputs = [Path(p) for p in (args.output, args.svg, args.png) if p]
    if len({p.resolve() for p in outputs}) < len(outputs):
        raise DataError("-o, --svg and --png must name different files")
    if args.png:
        check_png_size(board, args.dpi)
    write_board(board, args.output)
    sheet = board.sheet_extent()
    papers = fits_on(board)
    paper = (f"prints on {' and '.join(papers)}" if papers else
             "larger than A4 and Letter: print it at a print shop, at 100 %")
    what = (f"marker {args.marker_mm:g} mm" if args.kind == "olp-dots" else args.kind)
    print(f"wrote {args.output} ({board.rows} x {board.cols} dots, pitch "
          f"{args.pitch_mm:g} mm, dots {args.dot_mm:g} mm, {what}; "
          f"sheet {sheet.width / MM:.0f} x {sheet.height / MM:.0f} mm, {paper})")
    if args.svg:
        write_board_svg(board, args.svg)
        print(f"wrote {args.svg} (print at 100 %, then measure the printed scale bar, "
              f"nominal {board.scale_bar_m / MM:g} mm, with a caliper: --scale-bar-mm)")
    if args.png:
        write_board_png(board, args.png, args.dpi)
        print(f"wrote {args.png} ({args.dpi:g} dpi)")
    return 0


# -- calibrate --------------------------------------------------------------------------------

_UNITS = {"fx": ("px", 3), "mu": ("(fy / fx)", 6), "cx": ("px", 3), "cy": ("px", 3),
          "k1": ("(per normalized radius^2, distorted to undistorted)", 5),
          "k2": ("(per normalized radius^4)", 5)}


def _run_calibrate(args) -> int:
    board = read_board(args.board)
    paths = _expand(args.images)
    out = Path(args.output)
    _check_output(out, paths + [Path(args.board)])
    found = _detect(paths, board)
    sizes = {size for _, _, _, size in found}
    if len(sizes) > 1:
        raise DataError("images of different sizes: " + ", ".join(
            f"{name} {w}x{h}" for name, _, _, (w, h) in found[:len(sizes) + 1]) +
            "; calibrate one camera at one resolution")
    width, height = sizes.pop()
    scale = board_scale(args, board)
    nominal_board, board = board, scaled_board(board, scale)
    views = [View(name, f.pixels, f.points(board)) for name, f, _, _ in found if f is not None]
    partial = {name: f.describe() for name, f, _, _ in found if f is not None and f.partial}
    not_found = [(name, reason) for name, f, reason, _ in found if f is None]
    for name, reason in not_found:
        print(f"skipped {name}: {reason}")
    bias = centre_bias_of(board, not args.no_circle_correction)
    cal = dataclasses.replace(calibrate(views, width, height, method=args.method,
                                        centre_bias=bias), scale=scale)
    what = ("the seed's RAC estimates kept" if args.method == "rac-only" else
            "the seed's RAC, then the full refinement" if cal.start == "rac" else
            "too few views tilted for the RAC: homographies (Zhang), then the full refinement")
    corr = (f"circle-centre correction, {cal.bias_iterations} passes" if cal.bias_iterations
            else "corners as detected" if board.kind in CORNER_KINDS
            else "detected centroids as they are")
    print(f"camera {width} x {height} px from {len(cal.views)} of {len(paths)} images "
          f"(method {args.method}: {what}; {corr})")
    for v in cal.views:
        note = {"rac": "", "rac-pose": "  (not in the RAC: too near face-on; started from the "
                                       "RAC's intrinsics)",
                "homography": "  (started from its homography)"}[v.stage]
        print(f"  {v.name}: rms {v.rms_px:.3f} px, max {v.max_px:.3f} px, board tilted "
              f"{v.tilt_deg:.0f} deg{partial.get(v.name, '')}{note}")
    for s in cal.skipped:
        print(f"skipped {s.name}: {s.reason}")
    n_dots = sum(len(v.pixels) for v in views)
    sigma = "" if not np.isfinite(cal.sigma_px) else f", sigma {cal.sigma_px:.3f} px"
    print(f"overall: rms {cal.rms_px:.3f} px, max {cal.max_px:.3f} px over {n_dots} dots"
          f"{sigma}")
    label = "RAC" if cal.start == "rac" else "start"
    print(f"parameters (value +/- one standard deviation; {label} estimate):")
    for name, (unit, digits) in _UNITS.items():
        value, std = getattr(cal.intrinsics, name), cal.std[name]
        sd = f"+/- {std:.{digits}f}" if np.isfinite(std) else "+/- n/a (RAC)"
        print(f"  {name:3s} {value:.{digits}f} {sd} {unit}".rstrip()
              + f"   ({label} {getattr(cal.rac, name):.{digits}f})")
    centre = board.dot_positions().mean(axis=0)
    print_scale(scale, [np.linalg.norm(invert_pose(v.camera_T_board)[:3, 3] - centre) / MM
                        for v in cal.views])
    write_camera(out, cal, board_to_dict(nominal_board))
    print(f"wrote {out}")
    if args.html:
        from ..report.camera_html import write_calibration_html
        _check_output(Path(args.html), paths + [Path(args.board), out])
        # the report draws whole boards; a partial charuco view is listed, not drawn
        write_calibration_html(args.html, cal, board,
                               {name: f.pixels for name, f, _, _ in found
                                if f is not None and not f.partial},
                               {p.name: p for p in paths})
        print(f"wrote {args.html}")
    return 0


# -- measure ----------------------------------------------------------------------------------

def _read_joints(path: Path) -> tuple[list[str], list[dict[str, str]], list[int]]:
    """Header, rows (column -> text) and 1-based line numbers of a joints CSV."""
    text = read_csv_text(path, "a joints CSV (image, q1_deg..qN_deg)")
    lines = text.splitlines()
    start = 0
    while start < len(lines) and (lines[start].startswith("#") or not lines[start].strip()):
        start += 1
    if start == len(lines):
        raise DataError(f"{path}: no header row (expected image, q1_deg, ..., qN_deg)")
    reader = csv.reader(io.StringIO("\n".join(lines[start:])))
    header = [h.strip() for h in next(reader)]
    if "image" not in header:
        raise DataError(f"{path}:{start + 1}: missing column 'image' (header has: "
                        f"{', '.join(header)})")
    joints = [h for h in header if JOINT_RE.match(h)]
    if not joints:
        raise DataError(f"{path}:{start + 1}: no joint columns (expected q1_deg, ..., "
                        f"qN_deg)")
    numbers = sorted(int(JOINT_RE.match(h).group(1)) for h in joints)
    if numbers != list(range(1, len(numbers) + 1)):
        raise DataError(f"{path}:{start + 1}: joint columns must be q1..q{len(numbers)}, got "
                        f"{', '.join(joints)}")
    rows, where = [], []
    for offset, record in enumerate(reader):
        line = start + 2 + offset
        if not record or all(not c.strip() for c in record) or record[0].startswith("#"):
            continue
        if len(record) != len(header):
            raise DataError(f"{path}:{line}: {len(record)} fields, the header has "
                            f"{len(header)}")
        row = {h: c.strip() for h, c in zip(header, record)}
        for column in joints:              # a finite, plausible number (NaN is refused)
            parse_cell_number(row[column], str(path), line, column)
        rows.append(row)
        where.append(line)
    if not rows:
        raise DataError(f"{path}: no data rows after the header")
    return header, rows, where


def _run_measure(args) -> int:
    board = read_board(args.board)
    check_measurable(board)
    cal = read_camera(args.camera)
    paths = _expand(args.images)
    out = Path(args.output)
    inputs = paths + [Path(args.board), Path(args.camera)]
    joints = None
    if args.joints:
        inputs.append(Path(args.joints))
        joints = _read_joints(Path(args.joints))
        known = {p.name for p in paths}
        header, rows, where = joints
        for row, line in zip(rows, where):
            if row["image"] not in known:
                raise DataError(f"{args.joints}:{line}: image '{row['image']}' is not among "
                                f"the images given")
    _check_output(out, inputs)
    k = cal.intrinsics
    scale = board_scale(args, board, cal.scale)
    nominal_board, board = board, scaled_board(board, scale)
    bias = centre_bias_of(board, not args.no_circle_correction)
    measured = {}
    for name, found, reason, (w, h) in _detect(paths, nominal_board):
        if (w, h) != (k.width, k.height):
            raise DataError(f"{name}: image is {w} x {h} px, the camera was calibrated at "
                            f"{k.width} x {k.height} ({args.camera})")
        if found is None:
            print(f"{name}: board not found ({reason}); left out")
            continue
        measured[name] = measure_pose(found.pixels, found.points(board), k, name=name,
                                      centre_bias=bias)
    if joints is None:
        text = _poses_csv(measured)
        count = len(measured)
    else:
        text, count = _measurements_csv(joints, measured, args.name, args.joints, scale)
        listed = {row["image"] for row in joints[1]}
        for name in measured:
            if name not in listed:
                print(f"{name}: no row in {args.joints}; left out")
    write_text_atomic(out, text)
    for m in measured.values():
        print(f"  {m.name}: x {m.position_mm[0]:.3f} y {m.position_mm[1]:.3f} z "
              f"{m.position_mm[2]:.3f} mm, +/- {m.sigma_mm:.3f} mm, {m.sigma_deg:.4f} deg, "
              f"rms {m.rms_px:.3f} px")
    centre = board.dot_positions().mean(axis=0)
    print_scale(scale, [np.linalg.norm(m.board_T_camera[:3, 3] - centre) / MM
                        for m in measured.values()])
    print(f"wrote {out} ({count} rows: the camera frame in the board frame, mm, quaternion "
          f"w first)")
    return 0


def _pose_cells(m) -> list[str]:
    return [f"{v:.4f}" for v in m.position_mm] + [f"{v:.9f}" for v in m.quat_wxyz]


def _poses_csv(measured: dict) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["image", "x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz", "rms_px"])
    for m in measured.values():
        writer.writerow([m.name] + _pose_cells(m) + [f"{m.rms_px:.4f}"])
    return buf.getvalue()


def _measurements_csv(joints, measured: dict, point: str, source: str,
                      scale: BoardScale) -> tuple[str, int]:
    header, rows, _ = joints
    joint_cols = sorted((h for h in header if JOINT_RE.match(h)),
                        key=lambda h: int(JOINT_RE.match(h).group(1)))
    own = {"image", "pose", "point", "x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz",
           "sigma_mm", "sigma_deg"}
    extra = [h for h in header if h not in own and h not in joint_cols]
    buf = io.StringIO()
    buf.write(f"{FORMAT_LINE}\n# device: the board (frame of its dot (0, 0)); point "
              f"{point}: the camera's optical centre and axes; from {source}\n"
              f"{SCALE_LINE}{scale.summary()}\n")
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["image"] + joint_cols + ["pose", "point", "x_mm", "y_mm", "z_mm", "qw",
                                             "qx", "qy", "qz", "sigma_mm", "sigma_deg"]
                    + extra)
    count = 0
    for number, row in enumerate(rows, start=1):
        m = measured.get(row["image"])
        if m is None:
            continue
        pose = row.get("pose") or str(number)
        writer.writerow([row["image"]] + [row[c] for c in joint_cols] + [pose, point]
                        + _pose_cells(m) + [f"{m.sigma_mm:.4f}", f"{m.sigma_deg:.5f}"]
                        + [row[h] for h in extra])
        count += 1
    return buf.getvalue(), count
