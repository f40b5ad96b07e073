"""Measurement CSV, version 1 (DESIGN.md "Formats at the edges").

Lines starting with ``#`` are metadata or comments; then one header row and one row per
measured point. Required: ``q1_deg`` .. ``qN_deg`` (``qK_mm`` for a prismatic joint) and
``x_mm, y_mm, z_mm`` (device frame). Optional: ``pose``, ``point`` (default ``tcp``),
``qw, qx, qy, qz`` (measured orientation, full-pose devices), ``payload_kg``,
``temperature_c``, ``time_s``, ``direction_K`` (approach direction of joint K, +1/-1).
Other columns are kept and reported, never fatal.

Full-pose rows: ``qw, qx, qy, qz`` is the orientation, in the device frame, of the measured
point's own frame (a laser tracker's 6-DoF probe, a camera's marker), as a quaternion, w
first, normalized on input. That frame is the flange frame (``tool0``) turned by a constant
rotation of the tool, the same for every row of one ``point`` and unknown (the probe may be
mounted any way round): identification finds it with the geometry
(:mod:`olp_compensate.calibration.identify`). A file has all four columns or none; in a file that has
them, a row whose four cells are all empty is a position-only row (NaN in
``Measurements.orientation``); three cells filled and one empty, a zero-length or non-finite
quaternion are errors naming file, line and column.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..calibration.measurements import Measurements
from ..errors import DataError
from .atomic import write_text_atomic

FORMAT_LINE = "# olp-compensate measurements v1"
ORIENTATION_COLUMNS = ("qw", "qx", "qy", "qz")
KNOWN_OPTIONAL = ("pose", "point", "qw", "qx", "qy", "qz", "payload_kg", "temperature_c",
                  "time_s")


def joint_columns(joint_units: list[str]) -> list[str]:
    """CSV names of the joint columns, e.g. ``['q1_deg', ..., 'q6_deg']``."""
    return [f"q{k + 1}_{unit}" for k, unit in enumerate(joint_units)]


def data_records(reader, start: int, n_fields: int, source: str):
    """(1-based line, fields) of the data rows of a CSV ``reader`` positioned after the
    header at 0-based line ``start``: blank and ``#`` rows skipped; a row of another field
    count than the header's ``n_fields`` is a DataError naming file and line."""
    for offset, record in enumerate(reader):
        line = start + 2 + offset
        if not record or all(not c.strip() for c in record) or record[0].startswith("#"):
            continue
        if len(record) != n_fields:
            raise DataError(f"{source}:{line}: {len(record)} fields, the header has {n_fields}")
        yield line, record


PLAUSIBLE_LIMITS = {"_mm": 1e6, "_deg": 1e5}
"""Largest magnitude a cell may hold, by the unit at the end of its column name (1 km,
about 280 turns); beyond it the number is a typo or a corrupt file, not a measurement."""
OTHER_LIMIT = 1e12
"""Largest magnitude of any other number (Unix times are about 1.7e9 s)."""


def plausible_limit(column: str) -> float:
    """The largest magnitude accepted in ``column`` (see :data:`PLAUSIBLE_LIMITS`)."""
    for suffix, limit in PLAUSIBLE_LIMITS.items():
        if column.endswith(suffix):
            return limit
    return OTHER_LIMIT


def short(text: str, width: int = 24) -> str:
    """``text`` cut to ``width`` characters for a message (a 309-digit number is not read)."""
    return text if len(text) <= width else text[:width - 3] + "..."


def parse_cell_number(text: str, source: str, line: int, column: str,
                      decimal_comma: bool = False) -> float:
    """A finite number of plausible size from a CSV cell; :class:`DataError` naming file,
    line and column. ``decimal_comma``: the file separates fields with ``;`` (German or
    French Excel), so ``1,5`` is 1.5; a cell with both ``.`` and ``,`` is refused (a
    thousands separator would be misread)."""
    number = text.strip()
    if decimal_comma and "," in number:
        if "." in number or number.count(",") > 1:
            raise DataError(f"{source}:{line}: column '{column}': '{short(text)}' has a "
                            f"thousands separator; save the numbers without one")
        number = number.replace(",", ".")
    try:
        value = float(number)
    except ValueError:
        raise DataError(f"{source}:{line}: column '{column}': '{short(text)}' is not a "
                        f"number") from None
    if not math.isfinite(value):
        raise DataError(f"{source}:{line}: column '{column}': {short(text)} is not a finite "
                        f"number")
    limit = plausible_limit(column)
    if abs(value) > limit:
        raise DataError(f"{source}:{line}: column '{column}': {short(text)} is beyond any "
                        f"plausible value (at most {limit:g} in size)")
    return value


@dataclass
class Table:
    """A CSV file's parts: ``metadata`` (``#`` lines before the header), ``header``
    (stripped names), ``header_line`` (1-based), ``records`` (an iterator of (1-based line,
    fields) from :func:`data_records`) and ``decimal_comma`` (fields separated by ``;``)."""

    metadata: list[str]
    header: list[str]
    header_line: int
    records: object
    decimal_comma: bool

    def require(self, columns, source: str) -> dict[str, int]:
        """Column index by name; :class:`DataError` naming the first missing column."""
        for name in columns:
            if name not in self.header:
                raise DataError(f"{source}:{self.header_line}: missing column '{name}' "
                                f"(header has: {', '.join(self.header)})")
        return {h: k for k, h in enumerate(self.header)}


def open_table(text: str, source: str, expected: str) -> Table:
    """Split CSV text into metadata, header and data records. A byte-order mark (Excel's
    "CSV UTF-8") is dropped; a header separated by ``;`` (Excel in German or French) selects
    ``;`` fields with decimal commas. ``expected`` names the header's columns for the
    message when there is none."""
    text = text.lstrip("\ufeff")
    lines = text.splitlines()
    metadata, start = [], 0
    while start < len(lines) and (lines[start].startswith("#") or not lines[start].strip()):
        if lines[start].startswith("#"):
            metadata.append(lines[start])
        start += 1
    if start == len(lines):
        raise DataError(f"{source}: no header row (expected {expected})")
    first = lines[start]
    delimiter = ";" if first.count(";") > first.count(",") else ","
    reader = csv.reader(io.StringIO("\n".join(lines[start:])), delimiter=delimiter)
    header = [h.strip().lstrip("\ufeff") for h in next(reader)]
    return Table(metadata=metadata, header=header, header_line=start + 1,
                 records=data_records(reader, start, len(header), source),
                 decimal_comma=delimiter == ";")


def _joint_number(column: str) -> int:
    """K of a joint column ``qK_unit`` (0 when K is not a number, e.g. ``q1x_deg``)."""
    digits = column[1:].split("_")[0]
    return int(digits) if digits.isdigit() else 0


def _parse_quaternion(cell: dict[str, str], source: str, line: int,
                      decimal_comma: bool = False) -> list[float]:
    """The unit quaternion (w, x, y, z) of one row, or four NaN when its cells are empty."""
    empty = [c for c in ORIENTATION_COLUMNS if not cell[c]]
    if len(empty) == len(ORIENTATION_COLUMNS):
        return [math.nan] * 4
    if empty:
        raise DataError(f"{source}:{line}: column '{empty[0]}': empty, but the row has other "
                        f"orientation cells (give all of qw, qx, qy, qz, or none)")
    quat = [parse_cell_number(cell[c], source, line, c, decimal_comma)
            for c in ORIENTATION_COLUMNS]
    norm = math.sqrt(sum(v * v for v in quat))
    if norm < 1e-9:
        raise DataError(f"{source}:{line}: columns 'qw', 'qx', 'qy', 'qz': quaternion of zero "
                        f"length (not an orientation)")
    return [v / norm for v in quat]


def parse_measurements(text: str, joint_units: list[str], source: str = "<measurements>",
                       ) -> Measurements:
    """Parse measurement CSV text for a robot whose joints read in ``joint_units``
    (``'deg'`` or ``'mm'`` per joint)."""
    table = open_table(text, source, "columns like q1_deg, ..., x_mm")
    metadata, header, start = table.metadata, table.header, table.header_line - 1
    expected_joints = joint_columns(joint_units)
    present_joints = sorted((h for h in header if h.startswith("q") and h[1:2].isdigit()),
                            key=_joint_number)
    if len(present_joints) != len(expected_joints) and present_joints:
        raise DataError(f"{source}:{start + 1}: the file has {len(present_joints)} joint columns "
                        f"({', '.join(present_joints)}) but the robot has {len(expected_joints)} "
                        f"joints ({', '.join(expected_joints)})")
    table.require(expected_joints + ["x_mm", "y_mm", "z_mm"], source)
    index = {h: k for k, h in enumerate(header)}
    has_orientation = all(c in index for c in ORIENTATION_COLUMNS)
    if not has_orientation and any(c in index for c in ORIENTATION_COLUMNS):
        missing = [c for c in ORIENTATION_COLUMNS if c not in index]
        raise DataError(f"{source}:{start + 1}: orientation columns need all of qw, qx, qy, qz; "
                        f"missing {', '.join(missing)}")
    direction_cols = [h for h in header if h.startswith("direction_")]
    known = set(expected_joints) | {"x_mm", "y_mm", "z_mm"} | set(KNOWN_OPTIONAL) | set(direction_cols)
    extra_cols = [h for h in header if h not in known]

    joints, points, poses, names, quats = [], [], [], [], []
    payload, temperature, time_s, directions, rows = [], [], [], [], []
    extra: dict[str, list[str]] = {h: [] for h in extra_cols}
    comma = table.decimal_comma

    def number(cell, line, column):
        return parse_cell_number(cell[column], source, line, column, comma)
    for line, record in table.records:
        cell = {h: record[k].strip() for h, k in index.items()}
        joints.append([number(cell, line, c) for c in expected_joints])
        points.append([number(cell, line, c) for c in ("x_mm", "y_mm", "z_mm")])
        poses.append(cell.get("pose") or str(len(poses)))
        names.append(cell.get("point") or "tcp")
        if has_orientation:
            quats.append(_parse_quaternion(cell, source, line, comma))
        for column, target in (("payload_kg", payload), ("temperature_c", temperature),
                               ("time_s", time_s)):
            if column in index:
                target.append(number(cell, line, column) if cell[column] else 0.0)
        if direction_cols:
            directions.append([number(cell, line, c) if cell[c] else 0.0
                               for c in direction_cols])
        for h in extra_cols:
            extra[h].append(cell[h])
        rows.append(line)
    if not rows:
        raise DataError(f"{source}: no data rows after the header")
    scale = np.array([np.pi / 180.0 if u == "deg" else 1e-3 for u in joint_units])
    quat_array = None
    if has_orientation:
        quat_array = np.array(quats)
    direction_array = None
    if direction_cols:
        direction_array = np.zeros((len(rows), len(joint_units)))
        for k, c in enumerate(direction_cols):
            try:
                j = int(c.split("_")[1]) - 1
            except ValueError:
                raise DataError(f"{source}: column '{c}': expected direction_K with K a joint number") from None
            if not 0 <= j < len(joint_units):
                raise DataError(f"{source}: column '{c}': the robot has no joint {j + 1}")
            direction_array[:, j] = np.sign(np.array(directions)[:, k])
    return Measurements(
        joints=np.array(joints) * scale, points=np.array(points) * 1e-3,
        pose_ids=np.array(poses, dtype=object), point_names=np.array(names, dtype=object),
        orientation=quat_array,
        payload_kg=np.array(payload) if payload else None,
        temperature_c=np.array(temperature) if temperature else None,
        time_s=np.array(time_s) if time_s else None, directions=direction_array,
        extra=extra, metadata=metadata, rows=np.array(rows), source=source)


def read_csv_text(path: str | Path, expected: str) -> str:
    """The text of a CSV file; DataError naming the file when it cannot be read or is
    binary (``expected`` says what it should have been, for the message)."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror})") from None
    if b"\x00" in raw[:4096]:
        raise DataError(f"{path}: binary file, expected {expected}")
    return raw.decode("utf-8-sig", errors="replace")


def read_measurements(path: str | Path, robot_or_units) -> Measurements:
    """Read a measurement CSV file (see :func:`parse_measurements`) for a robot (a
    :class:`~olp_compensate.kinematics.robot.Robot`, whose joints give the columns' units) or
    for a list of joint units ('deg' or 'mm' per joint). Joints in SI, controller axes."""
    joints = getattr(robot_or_units, "joints", None)
    units = [j.unit for j in joints] if joints is not None else list(robot_or_units)
    return parse_measurements(read_csv_text(path, "a measurement CSV"), units, str(path))


def format_measurements(meas: Measurements, joint_units: list[str],
                        metadata: list[str] | None = None) -> str:
    """CSV text of measurements (mm and degrees, 6 decimals), the inverse of the parser.
    :class:`DataError` when a number to write is not finite (nothing non-finite is written)."""
    check_finite_measurements(meas)
    out = io.StringIO()
    for line in [FORMAT_LINE] + list(metadata or []):
        out.write(line if line.startswith("#") else f"# {line}")
        out.write("\n")
    header = ["pose", "point"] + joint_columns(joint_units) + ["x_mm", "y_mm", "z_mm"]
    optional = [("payload_kg", meas.payload_kg), ("temperature_c", meas.temperature_c),
                ("time_s", meas.time_s)]
    header += [name for name, values in optional if values is not None]
    direction_joints = ([] if meas.directions is None
                        else [j for j in range(meas.directions.shape[1]) if np.any(meas.directions[:, j])])
    header += [f"direction_{j + 1}" for j in direction_joints]
    if meas.orientation is not None:
        header += ["qw", "qx", "qy", "qz"]
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(header)
    scale = np.array([180.0 / np.pi if u == "deg" else 1e3 for u in joint_units])
    for k in range(meas.n_rows):
        row = [meas.pose_ids[k], meas.point_names[k]]
        row += [f"{v:.6f}" for v in meas.joints[k] * scale]
        row += [f"{v:.6f}" for v in meas.points[k] * 1e3]
        row += [f"{values[k]:.6g}" for _, values in optional if values is not None]
        row += [f"{meas.directions[k, j]:.0f}" for j in direction_joints]
        if meas.orientation is not None:
            row += [f"{v:.9f}" if np.isfinite(v) else "" for v in meas.orientation[k]]
        writer.writerow(row)
    return out.getvalue()


def check_finite_measurements(meas: Measurements) -> None:
    """:class:`DataError` naming the first non-finite number of ``meas`` (orientations may
    be NaN: position-only rows)."""
    arrays = [("joints", meas.joints), ("points", meas.points), ("payload_kg", meas.payload_kg),
              ("temperature_c", meas.temperature_c), ("time_s", meas.time_s),
              ("directions", meas.directions)]
    for name, values in arrays:
        if values is not None and not np.all(np.isfinite(values)):
            row = int(np.argwhere(~np.isfinite(np.asarray(values)))[0][0])
            raise DataError(f"{meas.source}: refusing to write a non-finite number "
                            f"({name}, row {row + 1})")


def write_measurements(path: str | Path, meas: Measurements, joint_units: list[str],
                       metadata: list[str] | None = None) -> None:
    """Write measurements atomically (see :func:`format_measurements`)."""
    write_text_atomic(path, format_measurements(meas, joint_units, metadata))
