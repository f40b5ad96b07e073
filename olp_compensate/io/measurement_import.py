"""Measurement tables as instruments and other tools write them, turned into the
measurement CSV (version 1, :mod:`.measurements`).

A source is a delimited text table: ``,``, ``;`` (then decimal commas), tab or spaces; a
first row that is not all numbers is a header. What each column holds comes from a named
format (:data:`FORMATS`) or a column map ``--columns "q1=0,...,x=6,y=7,z=8"`` whose values
are 0-based column numbers or header names. Map keys:

==============================  ==========================================================
``q1`` .. ``qN``                joints (``joints_unit``: deg or rad; a prismatic axis mm)
``x, y, z``                     measured position (``length_unit``: mm or m)
``rx, ry, rz``                  measured orientation: Euler angles of ``euler`` (scipy's
                                convention: upper case intrinsic, ``XYZ`` = rotate about
                                x, then the new y, then the new z; lower case extrinsic,
                                about the fixed axes), or a rotation vector (``euler`` =
                                ``rotvec``); ``angles_unit`` deg or rad
``qw, qx, qy, qz``              measured orientation as a quaternion, w first
``cmd_x .. cmd_rz``             the commanded pose beside the measured one: kept as extra
                                columns ``cmd_x_mm`` .. (reported, not fitted)
``dx, dy, dz``                  instead of ``x, y, z``: the measured position as the
                                commanded one plus this deviation (``x = cmd_x + dx``;
                                tables that give the error, not the position)
``sx, sy, sz``                  per-axis standard deviations (length unit): the row's
                                ``sigma_mm`` = their RMS, a weight in identification
``temperature, time``           deg C, s
``pose, point``                 pose id, measured point name
==============================  ==========================================================
"""

from __future__ import annotations

import csv
import io
import math
import re
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import DataError
from .measurements import FORMAT_LINE, joint_columns, parse_cell_number, short


@dataclass(frozen=True)
class ImportSpec:
    """How to read a source: column ``map`` (key -> column number or header name) and the
    units and conventions of its numbers."""

    map: dict[str, str]
    joints_unit: str = "deg"
    length_unit: str = "mm"
    angles_unit: str = "deg"
    euler: str = "XYZ"
    name: str = "columns"
    conventions: list[str] = field(default_factory=list)


FORMATS = {
    "robodk": ImportSpec(
        map={**{f"q{k + 1}": str(k) for k in range(6)},
             **dict(zip(("x", "y", "z", "rx", "ry", "rz"), map(str, range(6, 12))))},
        euler="xyz", name="robodk",
        conventions=["RoboDK calibration table: columns 0-5 joints (deg), 6-11 measured x, y, "
                     "z (mm) and w, p, r (deg, rotations about the fixed x, y, z axes in that "
                     "order: R = Rz(r) Ry(p) Rx(w)); a table of 9 columns has positions only"]),
    "astl": ImportSpec(
        map={"pose": "pose", **{f"q{k}": f"j{k}" for k in range(1, 7)}, "x": "X", "y": "Y",
             "z": "Z", "sx": "sx", "sy": "sy", "sz": "sz", "temperature": "T",
             "time": "time"},
        name="astl",
        conventions=["laser-tracker table by header names: pose; j1..j6 (deg); X; Y; Z (mm, "
                     "tracker frame); sx; sy; sz (the tracker's per-axis uncertainty, mm); T "
                     "(deg C); time (s); ';' separated with decimal commas (the layout of "
                     "the HUST_NC_Robot / ASTL tracker data, doi:10.17632/srxktn4752.1, "
                     "with theta.xlsx's joints beside Leica.csv's columns)"]),
}
"""Named formats."""

SESSION_GAP_S = 3600.0
"""Rows more than this apart in time (s) belong to different sessions: the device may
have moved between them (each session has its own device frame)."""

KEYS = ({f"q{k}" for k in range(1, 13)} | {"x", "y", "z", "rx", "ry", "rz", "qw", "qx", "qy",
        "qz", "sx", "sy", "sz", "temperature", "time", "pose", "point", "dx", "dy", "dz"}
        | {f"cmd_{a}" for a in ("x", "y", "z", "rx", "ry", "rz")})


def parse_column_map(text: str) -> dict[str, str]:
    """``key=column,...`` -> dict; DataError naming a bad or unknown key."""
    out = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        key, sep, value = item.partition("=")
        key = key.strip().lower()
        if not sep or not value.strip():
            raise DataError(f"--columns: '{item}' is not KEY=COLUMN")
        if key not in KEYS:
            raise DataError(f"--columns: unknown key '{key}' (known: q1..qN, x, y, z, rx, ry, "
                            f"rz, qw..qz, cmd_x..cmd_rz, dx, dy, dz, sx, sy, sz, temperature, "
                            f"time, pose, point)")
        out[key] = value.strip()
    return out


def _rows(text: str, source: str) -> tuple[list[str] | None, list[tuple[int, list[str]]], bool]:
    """(header or None, [(1-based line, fields)], decimal comma)."""
    lines = [(k + 1, line) for k, line in enumerate(text.lstrip("\ufeff").splitlines())
             if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise DataError(f"{source}: no rows")
    first = lines[0][1]
    # ';' first: a ';'-separated file writes decimal commas (more commas than fields)
    delimiter = next((d for d in (";", "\t", ",") if d in first), None)
    if delimiter is None:
        records = [(n, line.split()) for n, line in lines]
    else:
        reader = csv.reader(io.StringIO("\n".join(line for _, line in lines)),
                            delimiter=delimiter)
        records = [(n, [c.strip() for c in rec]) for (n, _), rec in zip(lines, reader)]
    comma = delimiter == ";"
    header = None

    def numeric(cell: str) -> bool:
        return re.fullmatch(r"[-+]?(\d+([.,]\d*)?|[.,]\d+)([eE][-+]?\d+)?", cell) is not None
    if not all(numeric(c) for c in records[0][1] if c):
        header, records = records[0][1], records[1:]
    return header, records, comma


def _column(value: str, header: list[str] | None, n_fields: int, source: str) -> int:
    if value.isdigit():
        index = int(value)
    elif header is not None and value in header:
        index = header.index(value)
    else:
        raise DataError(f"{source}: no column '{value}'"
                        + (f" (header has: {', '.join(header)})" if header else
                           " (the file has no header: give column numbers, 0-based)"))
    if index >= n_fields:
        raise DataError(f"{source}: column {index} is beyond the {n_fields} columns of the file")
    return index


def _rotation(values: dict[str, float], spec: ImportSpec, prefix: str = "") -> np.ndarray | None:
    """Quaternion (w, x, y, z) of a row's orientation, or None."""
    keys = [prefix + k for k in ("rx", "ry", "rz")]
    if all(k in values for k in keys):
        angles = np.array([values[k] for k in keys])
        if spec.angles_unit == "deg":
            angles = np.radians(angles)
        rot = (Rotation.from_rotvec(angles) if spec.euler == "rotvec"
               else Rotation.from_euler(spec.euler, angles))
        x, y, z, w = rot.as_quat()
        return np.array([w, x, y, z])
    if all(prefix + k in values for k in ("qw", "qx", "qy", "qz")):
        return np.array([values[prefix + k] for k in ("qw", "qx", "qy", "qz")])
    return None


def check_spec(spec: ImportSpec, n_joints: int) -> None:
    """DataError for an incomplete map or an unknown unit or sequence."""
    deviation = [k for k in ("dx", "dy", "dz") if k in spec.map]
    if deviation and any(k in spec.map for k in ("x", "y", "z")):
        raise DataError("--columns: give the measured position (x, y, z) or its deviation "
                        "from the commanded one (dx, dy, dz with cmd_x, cmd_y, cmd_z), not both")
    position = (["dx", "dy", "dz", "cmd_x", "cmd_y", "cmd_z"] if deviation else ["x", "y", "z"])
    needed = [f"q{k + 1}" for k in range(n_joints)] + position
    missing = [k for k in needed if k not in spec.map]
    if missing:
        raise DataError(f"--columns: missing {', '.join(missing)}")
    for name, value, allowed in (("joints unit", spec.joints_unit, ("deg", "rad")),
                                 ("length unit", spec.length_unit, ("mm", "m")),
                                 ("angles unit", spec.angles_unit, ("deg", "rad"))):
        if value not in allowed:
            raise DataError(f"{name} must be {' or '.join(allowed)}, got '{value}'")
    if spec.euler != "rotvec" and not re.fullmatch(r"[XYZ]{3}|[xyz]{3}", spec.euler):
        raise DataError(f"--euler must be three of XYZ (intrinsic) or xyz (extrinsic), or "
                        f"rotvec; got '{spec.euler}'")


def convert(text: str, spec: ImportSpec, joint_units: list[str], source: str,
            pose_prefix: str | None = None) -> str:
    """The measurement CSV text of a source table (see the module docstring); with
    ``pose_prefix`` only the rows whose pose id starts with it."""
    spec_map = dict(spec.map)
    header, records, comma = _rows(text, source)
    if pose_prefix is not None:
        if "pose" not in spec_map:
            raise DataError("--pose-prefix needs a pose column (map pose=COLUMN)")
        at = _column(spec_map["pose"], header, max(len(r) for _, r in records), source)
        records = [(n, r) for n, r in records if len(r) > at and r[at].startswith(pose_prefix)]
        if not records:
            raise DataError(f"{source}: no row's pose starts with '{pose_prefix}'")
    n_fields = max(len(r) for _, r in records) if records else 0
    if spec.name == "robodk" and n_fields < 12:  # positions only
        spec_map = {k: v for k, v in spec_map.items() if k not in ("rx", "ry", "rz")}
    check_spec(ImportSpec(map=spec_map, joints_unit=spec.joints_unit,
                          length_unit=spec.length_unit, angles_unit=spec.angles_unit,
                          euler=spec.euler), len(joint_units))
    index = {k: _column(v, header, n_fields, source) for k, v in spec_map.items()}
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    has_rot = {"rx", "ry", "rz"} <= set(index) or {"qw", "qx", "qy", "qz"} <= set(index)
    has_cmd = [a for a in ("x", "y", "z", "rx", "ry", "rz") if f"cmd_{a}" in index]
    has_sigma = {"sx", "sy", "sz"} <= set(index)
    optional = [c for c, k in (("temperature_c", "temperature"), ("time_s", "time"))
                if k in index]
    columns = (["pose", "point"] + joint_columns(joint_units) + ["x_mm", "y_mm", "z_mm"]
               + optional + (["sigma_mm"] if has_sigma else [])
               + [f"cmd_{a}_{'mm' if a in 'xyz' else spec.angles_unit}" for a in has_cmd]
               + (["qw", "qx", "qy", "qz"] if has_rot else []))
    for line in [FORMAT_LINE, f"# imported from {source} ({spec.name})"] + [
            f"# {c}" for c in spec.conventions + _conventions(spec, has_rot)]:
        out.write(line + "\n")
    writer.writerow(columns)
    length = 1.0 if spec.length_unit == "mm" else 1e3
    joint = [1.0 if u == "mm" or spec.joints_unit == "deg" else 180.0 / math.pi
             for u in joint_units]
    zero_sigma = 0
    for number, (line, fields) in enumerate(records):
        if any(i >= len(fields) for i in index.values()):
            raise DataError(f"{source}:{line}: {len(fields)} fields, expected {n_fields}")
        values = {k: parse_cell_number(fields[i], source, line, k, comma)
                  for k, i in index.items() if k not in ("pose", "point")}
        row = [fields[index["pose"]] if "pose" in index else str(number + 1),
               fields[index["point"]] if "point" in index else "tcp"]
        row += [f"{values[f'q{k + 1}'] * joint[k]:.9g}" for k in range(len(joint_units))]
        row += [f"{_measured(values, a) * length:.9g}" for a in ("x", "y", "z")]
        row += [f"{values[k]:.15g}" for k in ("temperature", "time") if k in index]
        if has_sigma:
            sigma = math.sqrt(sum(values[k] ** 2 for k in ("sx", "sy", "sz")) / 3) * length
            if sigma < 0 or not math.isfinite(sigma):
                raise DataError(f"{source}:{line}: standard deviations must not be negative")
            zero_sigma += sigma == 0
            row.append(f"{sigma:.6g}" if sigma > 0 else "")  # below resolution: the default
        row += [f"{values['cmd_' + a] * (length if a in 'xyz' else 1.0):.9g}" for a in has_cmd]
        if has_rot:
            quat = _rotation(values, spec)
            norm = float(np.linalg.norm(quat))
            if not norm > 1e-9:
                raise DataError(f"{source}:{line}: orientation of zero length")
            row += [f"{v:.12f}" for v in quat / norm]
        writer.writerow(row)
    if not records:
        raise DataError(f"{source}: no data rows")
    text = out.getvalue()
    if zero_sigma:
        text = text.replace("\n", f"\n# {zero_sigma} rows give zero standard deviations "
                            f"(below the device's resolution): their sigma_mm is left empty "
                            f"(the fit's default)\n", 1)
    return text


def sessions(time_s, gap_s: float = SESSION_GAP_S) -> list[tuple[int, int]]:
    """(first, last) row indexes of the runs of rows whose times lie within ``gap_s`` of
    the previous row's (time order as written)."""
    t = np.asarray(time_s, dtype=float)
    if len(t) == 0:
        return []
    cuts = np.flatnonzero(np.abs(np.diff(t)) > gap_s) + 1
    starts, ends = np.r_[0, cuts], np.r_[cuts, len(t)] - 1
    return [(int(a), int(b)) for a, b in zip(starts, ends)]


def _measured(values: dict[str, float], axis: str) -> float:
    """The measured coordinate ``axis`` (x, y or z): its column, or commanded + deviation."""
    return values[axis] if axis in values else values[f"cmd_{axis}"] + values[f"d{axis}"]


def _conventions(spec: ImportSpec, has_rot: bool) -> list[str]:
    words = [f"joints read in {spec.joints_unit}, lengths in {spec.length_unit}"]
    if "dx" in spec.map:
        words.append("measured position = commanded (cmd_x, cmd_y, cmd_z) + deviation (dx, "
                     "dy, dz)")
    if has_rot:
        kind = "intrinsic" if spec.euler.isupper() else "extrinsic"
        how = ("a rotation vector" if spec.euler == "rotvec" else
               f"Euler angles {spec.euler} ({kind})")
        words.append(f"orientation from {how} in {spec.angles_unit}, written as the quaternion "
                     f"qw, qx, qy, qz (w first) of the measured frame in the device frame")
    return words
