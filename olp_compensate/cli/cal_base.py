"""``olp-cal base``: re-fit only the robot's base frame from marks touched with a known tool.

The marks CSV has ``mark, q1_deg..qN_deg, x_mm, y_mm, z_mm``: the controller's axes at each
touch and the mark's coordinates in the new (world or device) frame. The output is the input
calibration with the new ``device_T_base``: ``olp-cal predict --model OUT`` then predicts in
the marks' frame. Seed section 6: the base is recalibrated whenever the robot moves to
another part of the workspace (or to another cell).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import os
from pathlib import Path

import numpy as np

from ..calibration.base import base_report, recalibrate_base
from ..calibration.fit_check import MAX_RMS_M, forced_warning, judge_residual
from ..errors import DataError
from ..io.calibration_file import read_calibration, write_calibration
from ..io.measurements import data_records, joint_columns, parse_cell_number, read_csv_text
from ..kinematics.conventions import MM

HELP = ("re-fit only the base frame (where the robot stands) from marks of known "
        "coordinates touched with a calibrated tool")
FLAG_MM = 0.3
"""A mark whose residual exceeds this is flagged in the printout (a bad touch?), mm."""


def add_arguments(p) -> None:
    p.add_argument("--model", required=True, help="calib.json whose arm and tool to keep")
    p.add_argument("--marks", required=True,
                   help="marks CSV: mark, q1_deg..qN_deg, x_mm, y_mm, z_mm (coordinates in "
                        "the new world or device frame)")
    p.add_argument("--tool", help="the calibrated tool that touched the marks (default: the "
                                  "calibration's only tool)")
    p.add_argument("--keep-tilt", action="store_true",
                   help="keep the tilt of the model's device_T_base; fit only the rotation "
                        "about z and the translation (4 DoF)")
    p.add_argument("--force", action="store_true",
                   help="write the base even when its RMS residual is above the "
                        f"{MAX_RMS_M / MM:g} mm limit (the file then carries the warning)")
    p.add_argument("-o", "--output", required=True, help="calib.json to write (never an input)")


def read_base_marks(path, robot) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """(mark names, joints (m, n) controller axes rad/m, marks (m, 3) m) from a marks CSV."""
    source = str(path)
    lines = read_csv_text(path, "a marks CSV").splitlines()
    start = 0
    while start < len(lines) and (lines[start].startswith("#") or not lines[start].strip()):
        start += 1
    if start == len(lines):
        raise DataError(f"{source}: no header row (expected mark, q1_deg, ..., x_mm, y_mm, z_mm)")
    reader = csv.reader(io.StringIO("\n".join(lines[start:])))
    header = [h.strip() for h in next(reader)]
    joint_cols = joint_columns([j.unit for j in robot.joints])
    for column in joint_cols + ["x_mm", "y_mm", "z_mm"]:
        if column not in header:
            raise DataError(f"{source}:{start + 1}: missing column '{column}' "
                            f"(header has: {', '.join(header)})")
    index = {h: k for k, h in enumerate(header)}
    names, joints, marks = [], [], []
    for line, record in data_records(reader, start, len(header), source):
        cell = {h: record[k].strip() for h, k in index.items()}
        names.append(cell.get("mark") or f"M{len(names) + 1}")
        joints.append([parse_cell_number(cell[c], source, line, c) for c in joint_cols])
        marks.append([parse_cell_number(cell[c], source, line, c)
                      for c in ("x_mm", "y_mm", "z_mm")])
    if not joints:
        raise DataError(f"{source}: no data rows after the header")
    return (tuple(names), robot.to_radians_or_metres(np.array(joints)),
            np.array(marks) * MM)


def _same_file(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def run(args) -> int:
    out = Path(args.output)
    for source in (args.model, args.marks):
        if _same_file(out, Path(source)):
            raise DataError(f"{out}: is an input ({source}); inputs are never overwritten, "
                            f"choose another output file")
    cal = read_calibration(args.model)
    names, joints, marks = read_base_marks(args.marks, cal.robot)
    result = recalibrate_base(cal, joints, marks, tool=args.tool, keep_tilt=args.keep_tilt,
                              mark_names=names)
    for line in base_report(result, flag_above_m=FLAG_MM * MM):
        print(line)
    verdict = judge_residual("base frame: the marks do not fit one rigid frame",
                             result.residuals_m, result.mark_names)
    calibration = result.calibration
    if verdict.rejected:
        if not args.force:
            raise DataError(f"{args.marks}: {verdict.message} Nothing written (--force "
                            f"writes it with this warning in the file)")
        calibration = dataclasses.replace(
            calibration, warnings=calibration.warnings + (forced_warning(verdict),))
        print(f"WARNING: {verdict.message} Written anyway (--force), flagged in {out}")
    write_calibration(out, calibration)
    print(f"wrote {out}: the calibration of {args.model} with the new base frame "
          f"(olp-cal predict --model {out} predicts in the marks' frame)")
    return 0
