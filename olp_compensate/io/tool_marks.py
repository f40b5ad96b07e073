"""Files of tool recalibration: the marks CSV (``olp-cal tool --marks``) and the tool entry
to merge into calib.json (``tools.NAME``), mm and degrees at this edge."""

from __future__ import annotations

import csv
import io
import json
import re
from pathlib import Path

import numpy as np

from ..calibration.tool import ToolCalibration, ToolRequest
from ..errors import DataError
from ..kinematics.conventions import MM
from .atomic import check_finite_json, write_text_atomic
from .measurements import open_table, parse_cell_number


def tool_to_dict(result: ToolCalibration) -> dict:
    """The tool as a calib.json ``tools.NAME`` entry (mm, flange frame)."""
    entry = {
        "xyz_mm": [round(v / MM, 6) for v in result.xyz_m],
        "xyz_std_mm": [round(v / MM, 6) for v in result.xyz_std_m],
        "method": result.method,
        "condition_number": round(result.condition_number, 4),
        "rms_residual_mm": round(result.rms_m / MM, 6),
        "residuals_mm": {n: round(r / MM, 6) for n, r in zip(result.mark_names,
                                                             result.residuals_m)},
    }
    if result.quat_wxyz is not None:
        entry["quat_wxyz"] = [float(v) for v in result.quat_wxyz]
    if result.point_m is not None:
        entry["fixed_point_base_mm"] = [round(v / MM, 6) for v in result.point_m]
    return entry


def write_tool_json(result: ToolCalibration, path) -> None:
    """Write ``{"tools": {name: entry}}`` atomically (an entry to merge into calib.json)."""
    document = {"tools": {result.name: tool_to_dict(result)}}
    check_finite_json(document, str(path))
    text = json.dumps(document, indent=2, allow_nan=False)
    write_text_atomic(path, text + "\n")


def format_marks_csv(request: ToolRequest) -> str:
    """The request as a marks CSV (the inverse of :func:`read_marks_csv`)."""
    out = io.StringIO()
    out.write(f"# olp-compensate tool marks v1\n# tool: {request.name}\n")
    n = request.joints.shape[1]
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(["mark"] + [f"q{k + 1}_deg" for k in range(n)]
                    + ["x_mm", "y_mm", "z_mm", "frame"])
    for k, label in enumerate(request.labels()):
        xyz = [""] * 3 if request.marks is None else [f"{v / MM:.4f}" for v in request.marks[k]]
        writer.writerow([label] + [f"{v:.6f}" for v in np.degrees(request.joints[k])] + xyz
                        + [request.frame])
    return out.getvalue()



def read_marks_csv(path, n_joints: int, frame: str | None = None) -> ToolRequest:
    """Read a marks CSV: ``mark, q1_deg..qN_deg, x_mm, y_mm, z_mm[, frame]``.

    Lines starting with ``#`` are metadata (``# tool: NAME`` names the tool, else the file
    stem). Empty coordinates on every row select the fixed-point method; on every row filled,
    known marks. ``frame`` is 'base' (default) or 'world' for all rows; the argument
    ``frame`` sets it for rows whose ``frame`` cell is empty or absent, and a row saying
    otherwise is an error.
    """
    if frame not in (None, "base", "world"):
        raise DataError(f"frame: expected 'base' or 'world', got {frame!r}")
    source = str(path)
    try:
        text = Path(path).read_bytes().decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{source}: cannot read ({getattr(exc, 'strerror', None) or exc})") \
            from None
    joint_cols = [f"q{k + 1}_deg" for k in range(n_joints)]
    table = open_table(text, source, "mark, q1_deg, ..., x_mm, y_mm, z_mm")
    name = Path(path).stem
    for line in table.metadata:
        found = re.match(r"#\s*tool\s*:\s*(\S+)", line.lstrip("\ufeff"))
        name = found.group(1) if found else name
    index = table.require(["mark"] + joint_cols + ["x_mm", "y_mm", "z_mm"], source)

    def number(cell, line, column):
        return parse_cell_number(cell[column], source, line, column, table.decimal_comma)
    labels, joints, marks, frames, filled = [], [], [], [], []
    for line, record in table.records:
        cell = {h: record[k].strip() for h, k in index.items()}
        labels.append(cell["mark"] or f"M{len(labels) + 1}")
        joints.append([number(cell, line, c) for c in joint_cols])
        xyz = [cell[c] for c in ("x_mm", "y_mm", "z_mm")]
        filled.append((line, sum(bool(v) for v in xyz)))
        if all(xyz):
            marks.append([number(cell, line, c) for c in ("x_mm", "y_mm", "z_mm")])
        row_frame = (cell.get("frame") or frame or "base").lower()
        if row_frame not in ("base", "world"):
            raise DataError(f"{source}:{line}: column 'frame': expected 'base' or 'world', "
                            f"got '{cell.get('frame')}'")
        if frame is not None and row_frame != frame:
            raise DataError(f"{source}:{line}: column 'frame' says '{row_frame}' but the "
                            f"{frame} frame was asked for")
        frames.append(row_frame)
    if not joints:
        raise DataError(f"{source}: no data rows after the header")
    expected = 3 if filled[0][1] == 3 else 0
    odd = [line for line, count in filled if count != expected]
    if odd:
        raise DataError(f"{source}:{odd[0]}: coordinates x_mm, y_mm, z_mm must be given on "
                        f"every row (known marks) or left empty on every row (fixed point)")
    if len(set(frames)) > 1:
        raise DataError(f"{source}: column 'frame' mixes {sorted(set(frames))}; use one frame")
    known = expected == 3
    return ToolRequest(name=name, method="known_marks" if known else "fixed_point",
                       joints=np.radians(np.array(joints)),
                       marks=np.array(marks) * MM if known else None,
                       frame=frames[0] if known else "base", mark_names=tuple(labels))
