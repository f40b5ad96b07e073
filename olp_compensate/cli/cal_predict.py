"""``olp-cal predict``: where the calibrated robot puts its measured points."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from ..calibration.effects import Conditions, ThermalExpansion
from ..calibration.validity import map_correction, range_notes
from ..errors import DataError
from ..io.atomic import write_text_atomic
from ..io.calibration_file import read_calibration
from ..io.measurements import joint_columns, open_table, parse_cell_number, read_csv_text
from .common import refuse_clashes

HELP = ("predict measured-point positions (device frame, mm) for joint rows of a CSV; "
        "optional payload_kg, temperature_c and direction_K columns feed the model's effects")


def add_arguments(p) -> None:
    p.add_argument("--model", required=True, help="calib.json")
    p.add_argument("joints", help="CSV with q1_deg..qN_deg (optional: point, payload_kg, "
                                  "temperature_c, direction_K)")
    p.add_argument("-o", "--output", required=True, help="CSV to write (x_mm, y_mm, z_mm added)")
    p.add_argument("--no-residual-map", action="store_true",
                   help="ignore the model's residual map (olp-cal diagnose --residual-map)")


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


def _direction_columns(header: list[str], n: int, where: str) -> dict[str, int]:
    """``direction_K`` columns and their 0-based joint."""
    found = {}
    for h in header:
        if h.startswith("direction_"):
            try:
                joint = int(h.split("_", 1)[1]) - 1
            except ValueError:
                raise DataError(f"{where}: column '{h}': expected direction_K, K a joint "
                                f"number") from None
            if not 0 <= joint < n:
                raise DataError(f"{where}: column '{h}': the robot has joints 1..{n}")
            found[h] = joint
    return found


def _check_limits(cal, q: np.ndarray, lines: list[int], source: str) -> None:
    """:class:`DataError` naming the first row whose joints lie outside the robot's
    limits (as olp-cal identify refuses them)."""
    urdf = cal.robot.joints_from_controller(q)
    outside = (urdf < cal.robot.lower_limits - 1e-6) | (urdf > cal.robot.upper_limits + 1e-6)
    if np.any(outside):
        row, joint = np.argwhere(outside)[0]
        value = cal.robot.to_degrees_or_mm(q[row])[joint]
        raise DataError(f"{source}:{lines[row]}: q{joint + 1} = {value:.6g} puts joint "
                        f"{joint + 1} outside the limits of {cal.robot.name}")


def _range_report(cal, q: np.ndarray, lines: list[int], no_map: bool) -> np.ndarray:
    """Print where the model's fitted-in-a-range parts apply (cyclic errors, the residual
    map); the map's correction (m, 3), device frame."""
    use_map = cal.residual_map is not None and not no_map
    notes = range_notes(cal, q, residual_map=use_map)
    correction = map_correction(cal, q) if use_map else np.zeros((len(q), 3))
    if use_map:
        inside = int(np.sum(cal.residual_map.inside(q)))
        figures = cal.residual_map.validation
        print(f"residual map ({figures.get('method', 'cross-validated')}: held-out "
              f"{figures.get('heldout_rms_mm_without', float('nan')):.4f} -> "
              f"{figures.get('heldout_rms_mm_with', float('nan')):.4f} mm) applied to "
              f"{inside} of {len(q)} rows (the others lie outside its joint region)")
    fallback = int(np.sum(cal.outside_fitted(q)))
    if fallback:
        print(f"{fallback} of {len(q)} rows lie outside the joint ranges the named effects "
              f"were fitted on: predicted by the geometric model of the same measurements")
    for line, note in zip(lines, notes):
        if note:
            print(f"note: line {line}: {note}")
    return correction


def run(args) -> int:
    refuse_clashes([("--model", args.model), ("joints", args.joints)], [("-o", args.output)])
    cal = read_calibration(args.model)
    source = str(Path(args.joints))
    columns = joint_columns([j.unit for j in cal.robot.joints])
    table = open_table(read_csv_text(args.joints, "a CSV of joint values"), source,
                       ", ".join(columns))
    header = table.header
    index = table.require(columns, source)
    optional = [c for c in ("payload_kg", "temperature_c") if c in index]
    n = cal.robot.n_joints
    direction_cols = _direction_columns(header, n, f"{source}:{table.header_line}")
    comma = table.decimal_comma

    def number(row, line, column):
        return parse_cell_number(row[index[column]], source, line, column, comma)
    readings, names, records, lines = [], [], [], []
    extra = {c: [] for c in optional}
    direction_rows = []
    default_point = "tcp" if "tcp" in cal.tools or not cal.tools else sorted(cal.tools)[0]
    for line_no, row in table.records:
        records.append(row)
        lines.append(line_no)
        readings.append([number(row, line_no, c) for c in columns])
        names.append(row[index["point"]].strip() if "point" in index and row[index["point"]].strip()
                     else default_point)
        for c in optional:
            extra[c].append(number(row, line_no, c) if row[index[c]].strip() else np.nan)
        direction_rows.append([np.sign(number(row, line_no, h)) if row[index[h]].strip() else 0.0
                               for h in direction_cols])
    if not records:
        raise DataError(f"{source}: no data rows after the header")
    directions = np.zeros((len(records), n))
    for k, joint in enumerate(direction_cols.values()):
        directions[:, joint] = [r[k] for r in direction_rows]
    q = cal.robot.to_radians_or_metres(np.array(readings).reshape(-1, len(columns)))
    _check_limits(cal, q, lines, source)
    conditions = _conditions(cal, extra, directions if direction_cols else None)
    if not cal.tools:
        points = (cal.flange_poses(q, conditions)[:, :3, 3] @ cal.device_T_base[:3, :3].T
                  + cal.device_T_base[:3, 3])
    else:
        points = cal.predict_points(q, names, conditions)
    points = points + _range_report(cal, q, lines, args.no_residual_map)
    bad = ~np.all(np.isfinite(points), axis=1)
    if np.any(bad):
        raise DataError(f"{source}:{lines[int(np.argmax(bad))]}: the model predicts a "
                        f"non-finite point here; nothing written")
    out_header = [h for h in header if h not in ("x_mm", "y_mm", "z_mm")] + ["x_mm", "y_mm", "z_mm"]
    out = io.StringIO()
    # a spreadsheet's ';' file comes back in its own form: ';' and decimal commas
    writer = csv.writer(out, lineterminator="\n", delimiter=";" if comma else ",")
    writer.writerow(out_header)
    for row, p in zip(records, points * 1e3):
        kept = [row[index[h]] for h in out_header[:-3]]
        numbers = [f"{v:.6f}" for v in p]
        writer.writerow(kept + ([v.replace(".", ",") for v in numbers] if comma else numbers))
    write_text_atomic(args.output, out.getvalue())
    print(f"wrote {len(points)} predicted points (device frame, mm) to {args.output}")
    return 0
