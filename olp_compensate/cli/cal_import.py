"""``olp-cal import``: a measurement table as an instrument or another tool writes it
(``;`` separators and decimal commas, Euler angles or rotation vectors, joints in
radians, a commanded pose, per-axis standard deviations, temperature) turned into the
measurement CSV (see :mod:`olp_compensate.io.measurement_import`)."""

from __future__ import annotations

import dataclasses

from ..errors import DataError
from ..io.atomic import write_text_atomic
from ..io.measurement_import import (FORMATS, SESSION_GAP_S, ImportSpec, convert,
                                     parse_column_map, sessions)
from ..io.measurements import parse_measurements, read_csv_text
from ..kinematics.robot import load_robot
from .common import refuse_clashes

HELP = ("turn a measurement table as instruments and other tools write it into the "
        "measurement CSV")


def add_arguments(p) -> None:
    p.add_argument("source", help="the table to import (text: , ; tab or space separated)")
    how = p.add_mutually_exclusive_group(required=True)
    how.add_argument("--format", choices=sorted(FORMATS),
                     help="a named format (robodk: columns 0-5 joints in deg, 6-11 measured "
                          "x, y, z in mm and w, p, r in deg about the fixed x, y, z axes; "
                          "astl: header names pose, j1..j6, X, Y, Z, sx, sy, sz, T, time)")
    how.add_argument("--columns", metavar="MAP",
                     help="KEY=COLUMN,... with COLUMN a 0-based number or a header name; "
                          "keys q1..qN, x, y, z, rx, ry, rz (or qw, qx, qy, qz), cmd_x.. "
                          "cmd_rz (commanded pose), dx, dy, dz (instead of x, y, z: "
                          "measured = commanded + d), sx, sy, sz (per-axis standard "
                          "deviations), temperature, time, pose, point")
    p.add_argument("-o", "--output", required=True, help="measurement CSV to write")
    p.add_argument("--pose-prefix", metavar="TEXT",
                   help="keep only the rows whose pose id starts with TEXT (one session of a "
                        "table that joins several: each session has its own device frame)")
    p.add_argument("--robot", help="bundled robot name or URDF (joint count and units; "
                                   "default 6 revolute joints)")
    p.add_argument("--joints-unit", choices=("deg", "rad"), help="default deg")
    p.add_argument("--length-unit", choices=("mm", "m"), help="default mm")
    p.add_argument("--angles-unit", choices=("deg", "rad"),
                   help="unit of the orientation angles (default deg)")
    p.add_argument("--euler", help="orientation convention of rx, ry, rz: XYZ, ZYX.. "
                                   "(upper case intrinsic), xyz.. (lower case extrinsic, about "
                                   "the fixed axes) or rotvec (rotation vector); default XYZ")


def run(args) -> int:
    refuse_clashes([("source", args.source)], [("-o", args.output)])
    spec = FORMATS[args.format] if args.format else ImportSpec(map=parse_column_map(args.columns))
    changes = {k: v for k, v in (("joints_unit", args.joints_unit),
                                 ("length_unit", args.length_unit),
                                 ("angles_unit", args.angles_unit), ("euler", args.euler))
               if v is not None}
    spec = dataclasses.replace(spec, **changes)
    units = [j.unit for j in load_robot(args.robot).joints] if args.robot else ["deg"] * 6
    if args.columns:
        n_joints = len([k for k in spec.map if k[:1] == "q" and k[1:].isdigit()])
        if not args.robot:
            units = ["deg"] * n_joints
        elif n_joints != len(units):
            raise DataError(f"--columns maps {n_joints} joints, the robot has {len(units)}")
    text = convert(read_csv_text(args.source, "a measurement table"), spec, units,
                   args.source, pose_prefix=args.pose_prefix)
    meas = parse_measurements(text, units, args.output)  # what we write must read back
    write_text_atomic(args.output, text)
    conventions = [line[2:] for line in text.splitlines()[1:]
                   if line.startswith("# ") and not line.startswith("# imported from")]
    print(f"wrote {meas.n_rows} rows to {args.output}")
    for line in conventions:
        print(f"  {line}")
    runs = sessions(meas.time_s) if meas.time_s is not None else []
    if len(runs) > 1:
        print(f"WARNING: the rows form {len(runs)} sessions (time gaps over "
              f"{SESSION_GAP_S / 3600:g} h; first poses "
              f"{', '.join(str(meas.pose_ids[a]) for a, _ in runs[:6])}): a device moved "
              f"between sessions has a frame of its own, which one fit cannot take; "
              f"diagnose each session alone (--pose-prefix) unless the device stayed put")
    return 0
