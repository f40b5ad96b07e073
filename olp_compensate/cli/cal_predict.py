"""``olp-cal predict``: where the calibrated robot puts its measured points."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from ..calibration.effects import Conditions, ThermalExpansion
from ..errors import DataError
from ..io.atomic import write_text_atomic
from ..io.calibration_file import read_calibration
from ..io.measurements import joint_columns, parse_cell_number

HELP = ("predict measured-point positions (device frame, mm) for joint rows of a CSV; "
        "optional payload_kg, temperature_c and direction_K columns feed the model's effects")


def add_arguments(p) -> None:
    p.add_argument("--model", required=True, help="calib.json")
    p.add_argument("joints", help="CSV with q1_deg..qN_deg (optional: point, payload_kg, "
                                  "temperature_c, direction_K)")
    p.add_argument("-o", "--output", required=True, help="CSV to write (x_mm, y_mm, z_mm added)")


def _conditions(cal, columns: dict[str, list[float]], directions) -> Conditions | None:
    """Operating conditions from the optional columns (payload_kg, temperature_c,
    direction_K); empty cells mean no payload / the reference temperature."""
    if not columns and directions is None:
        return None
    payload = temperature = None
    if "payload_kg" in columns:
        payload = np.nan_to_num(np.array(columns["payload_kg"]), nan=0.0)
    if "temperature_c" in columns:
        reference = next((e.reference_temperature_c for e in cal.effects
                          if isinstance(e, ThermalExpansion)), 20.0)
        temperature = np.array(columns["temperature_c"])
        temperature = np.where(np.isnan(temperature), reference, temperature)
    return Conditions(payload_kg=payload, temperature_c=temperature, directions=directions)


def run(args) -> int:
    cal = read_calibration(args.model)
    path = Path(args.joints)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: cannot read ({exc})") from None
    lines = [ln for ln in text.splitlines() if not ln.startswith("#")]
    rows = list(csv.reader(lines))
    if not rows:
        raise DataError(f"{path}: empty file, expected a header with {', '.join(joint_columns(['deg'] * 2))}...")
    header = [h.strip() for h in rows[0]]
    columns = joint_columns([j.unit for j in cal.robot.joints])
    for c in columns:
        if c not in header:
            raise DataError(f"{path}:1: missing column '{c}'")
    index = {h: k for k, h in enumerate(header)}
    optional = [c for c in ("payload_kg", "temperature_c") if c in index]
    n = cal.robot.n_joints
    direction_cols = {}
    for h in header:
        if h.startswith("direction_"):
            try:
                joint = int(h.split("_", 1)[1]) - 1
            except ValueError:
                raise DataError(f"{path}:1: column '{h}': expected direction_K, K a joint "
                                f"number") from None
            if not 0 <= joint < n:
                raise DataError(f"{path}:1: column '{h}': the robot has joints 1..{n}")
            direction_cols[h] = joint
    readings, names = [], []
    extra = {c: [] for c in optional}
    directions = np.zeros((len(rows) - 1, n))
    for line_no, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise DataError(f"{path}:{line_no}: {len(row)} fields, the header has {len(header)}")
        readings.append([parse_cell_number(row[index[c]], str(path), line_no, c) for c in columns])
        names.append(row[index["point"]].strip() if "point" in index and row[index["point"]].strip()
                     else ("tcp" if "tcp" in cal.tools or not cal.tools else sorted(cal.tools)[0]))
        for c in optional:
            cell = row[index[c]].strip()
            extra[c].append(parse_cell_number(cell, str(path), line_no, c) if cell else np.nan)
        for h, joint in direction_cols.items():
            cell = row[index[h]].strip()
            if cell:
                directions[line_no - 2, joint] = np.sign(parse_cell_number(cell, str(path), line_no, h))
    q = cal.robot.to_radians_or_metres(np.array(readings).reshape(-1, len(columns)))
    conditions = _conditions(cal, extra, directions if direction_cols else None)
    if not cal.tools:
        points = (cal.flange_poses(q, conditions)[:, :3, 3] @ cal.device_T_base[:3, :3].T
                  + cal.device_T_base[:3, 3])
    else:
        points = cal.predict_points(q, names, conditions)
    out_header = [h for h in header if h not in ("x_mm", "y_mm", "z_mm")] + ["x_mm", "y_mm", "z_mm"]
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(out_header)
    for row, p in zip(rows[1:], points * 1e3):
        kept = [row[index[h]] for h in out_header[:-3]]
        writer.writerow(kept + [f"{v:.6f}" for v in p])
    write_text_atomic(args.output, out.getvalue())
    print(f"wrote {len(points)} predicted points (device frame, mm) to {args.output}")
    return 0
