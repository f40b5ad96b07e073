"""``olp-cal iso9283``: the ISO 9283 pose accuracy and repeatability test.

``plan`` writes the test program (five poses in a cube, visited in the standard's order
for n cycles; RAPID or V+ by the output's extension); ``report`` computes AP and RP per pose
from the measured attained poses next to the commanded ones.
"""

from __future__ import annotations

import csv
import io
import json
import os
from pathlib import Path

import numpy as np

from ..calibration.calibration import nominal_calibration
from ..calibration.iso9283 import (DEFAULT_CYCLES, iso_report_to_dict, iso_results,
                                   iso_summary, plan_iso_test, rapid_program, vplus_program)
from ..errors import DataError
from ..io.atomic import check_finite_json, write_text_atomic
from ..io.calibration_file import read_calibration
from ..io.measurements import data_records, parse_cell_number, read_csv_text
from ..kinematics.conventions import MM
from ..kinematics.robot import load_robot

HELP = "ISO 9283 pose accuracy and repeatability: write the test program, or report AP and RP"
ATTAINED = ("x_mm", "y_mm", "z_mm")
COMMANDED = ("xc_mm", "yc_mm", "zc_mm")
QUAT = ("qw", "qx", "qy", "qz")
QUAT_COMMANDED = ("qcw", "qcx", "qcy", "qcz")


def add_arguments(p) -> None:
    sub = p.add_subparsers(dest="iso_command", required=True, metavar="plan|report")
    plan = sub.add_parser("plan", help="write the test program for a cube")
    plan.add_argument("--cube", required=True, metavar="X,Y,Z,EDGE",
                      help="cube centre and edge length, mm, robot base frame")
    plan.add_argument("--cycles", type=int, default=DEFAULT_CYCLES,
                      help=f"number of cycles (default {DEFAULT_CYCLES}, as the standard asks)")
    who = plan.add_mutually_exclusive_group(required=True)
    who.add_argument("--robot", help="bundled robot name or URDF path (nominal kinematics)")
    who.add_argument("--model", help="calib.json: its robot's nominal kinematics (what the "
                                     "controller uses) and its only tool as the TCP")
    plan.add_argument("-o", "--output", required=True,
                      help="program to write: .mod (RAPID) or .pg (V+)")
    report = sub.add_parser("report", help="AP and RP per pose from measured poses")
    report.add_argument("measurements", help="CSV: pose, cycle, x_mm, y_mm, z_mm (attained), "
                                             "xc_mm, yc_mm, zc_mm (commanded); optional "
                                             "qw..qz and qcw..qcz")
    report.add_argument("--json", dest="json_out", metavar="OUT.json")
    report.add_argument("--html", dest="html_out", metavar="REPORT.html")
    report.add_argument("--load-kg", type=float, help="load on the robot during the test, kg")
    report.add_argument("--speed-mm-s", type=float, help="test speed, mm/s")
    report.add_argument("--temperature-c", type=float, help="ambient temperature, deg C")
    report.add_argument("--instrument", help="the measuring instrument, in words")


def parse_cube(text: str) -> tuple[np.ndarray, float]:
    """(centre (3,), edge) in m from ``X,Y,Z,EDGE`` in mm."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 4 or not np.all(np.isfinite(values)) or values[3] <= 0:
        raise DataError(f"--cube: expected X,Y,Z,EDGE in mm with EDGE > 0, got '{text}'")
    return np.array(values[:3]) * MM, values[3] * MM


def _is_input(out: Path, sources) -> Path | None:
    for source in sources:
        if source is None:
            continue
        try:
            if out.exists() and os.path.samefile(out, source):
                return Path(source)
        except OSError:
            pass
        if out.resolve() == Path(source).resolve():
            return Path(source)
    return None


def _run_plan(args) -> int:
    out = Path(args.output)
    dialect = {".mod": "rapid", ".pg": "vplus"}.get(out.suffix.lower())
    if dialect is None:
        raise DataError(f"{out}: the program's extension says its language: .mod (RAPID) or "
                        f".pg (V+)")
    source = _is_input(out, [args.model])
    if source is not None:
        raise DataError(f"{out}: is an input ({source}); choose another output file")
    centre, edge = parse_cube(args.cube)
    tool_m = None
    if args.model:
        calibrated = read_calibration(args.model)
        robot = calibrated.robot
        if len(calibrated.tools) == 1:
            tool_m = next(iter(calibrated.tools.values())).xyz_m
    else:
        robot = load_robot(args.robot)
    nominal = nominal_calibration(robot)
    plan = plan_iso_test(nominal, centre, edge, args.cycles, tool_m,
                         same_branch=dialect == "vplus")
    text = rapid_program(plan) if dialect == "rapid" else vplus_program(plan)
    write_text_atomic(out, text)
    tcp = ", ".join(f"{v / MM:.3f}" for v in plan.tool_m)
    print(f"ISO 9283 test for {robot.name}: cube centre ({', '.join(f'{v / MM:.1f}' for v in centre)}) "
          f"mm, edge {edge / MM:.1f} mm, tool ({tcp}) mm {plan.orientation}")
    for name, p, q in zip(("P1", "P2", "P3", "P4", "P5"), plan.positions_m,
                          robot.to_degrees_or_mm(plan.joints)):
        print(f"  {name}: ({', '.join(f'{v / MM:.1f}' for v in p)}) mm; axes "
              f"({', '.join(f'{v:.2f}' for v in q)}) deg")
    print(f"wrote {out}: {args.cycles} cycles of P1, P5, P4, P3, P2 "
          f"({'RAPID' if dialect == 'rapid' else 'V+'})")
    return 0


def read_iso_measurements(path):
    """(poses (m,), attained (m, 3) m, commanded (m, 3) m, attained quats (m, 4) or None,
    commanded quats (m, 4) or None) from the test's CSV."""
    source = str(path)
    lines = read_csv_text(path, "an ISO 9283 measurement CSV").splitlines()
    start = 0
    while start < len(lines) and (lines[start].startswith("#") or not lines[start].strip()):
        start += 1
    if start == len(lines):
        raise DataError(f"{source}: no header row (expected pose, cycle, x_mm, ..., zc_mm)")
    reader = csv.reader(io.StringIO("\n".join(lines[start:])))
    header = [h.strip() for h in next(reader)]
    for column in ("pose", "cycle") + ATTAINED + COMMANDED:
        if column not in header:
            raise DataError(f"{source}:{start + 1}: missing column '{column}' "
                            f"(header has: {', '.join(header)})")
    has = [all(c in header for c in cols) for cols in (QUAT, QUAT_COMMANDED)]
    if has[0] != has[1] or (not has[0] and any(c in header for c in QUAT + QUAT_COMMANDED)):
        raise DataError(f"{source}:{start + 1}: orientation needs all of qw, qx, qy, qz "
                        f"(attained) and qcw, qcx, qcy, qcz (commanded), or none")
    index = {h: k for k, h in enumerate(header)}
    poses, attained, commanded, quat, quat_c = [], [], [], [], []
    for line, record in data_records(reader, start, len(header), source):
        cell = {h: record[k].strip() for h, k in index.items()}
        if not cell["pose"]:
            raise DataError(f"{source}:{line}: column 'pose': empty")
        poses.append(cell["pose"])
        parse_cell_number(cell["cycle"], source, line, "cycle")
        attained.append([parse_cell_number(cell[c], source, line, c) for c in ATTAINED])
        commanded.append([parse_cell_number(cell[c], source, line, c) for c in COMMANDED])
        if has[0]:
            for columns, target in ((QUAT, quat), (QUAT_COMMANDED, quat_c)):
                q = [parse_cell_number(cell[c], source, line, c) for c in columns]
                if np.linalg.norm(q) < 1e-9:
                    raise DataError(f"{source}:{line}: columns {', '.join(columns)}: a "
                                    f"quaternion of zero length")
                target.append(q)
    if not poses:
        raise DataError(f"{source}: no data rows after the header")
    return (np.array(poses, dtype=object), np.array(attained) * MM, np.array(commanded) * MM,
            np.array(quat) if has[0] else None, np.array(quat_c) if has[0] else None)


CONDITION_RANGES = {"load_kg": ("--load-kg", 0.0, 1e4), "speed_mm_s": ("--speed-mm-s", 0.0, 1e5),
                    "temperature_c": ("--temperature-c", -273.15, 1e3)}
"""Accepted test conditions: option, least and largest value (kg; mm/s; deg C)."""


def _conditions(args) -> dict:
    """The test conditions given; :class:`DataError` for a number that is not finite or
    outside :data:`CONDITION_RANGES` (NaN would end in the JSON report)."""
    given = {"load_kg": args.load_kg, "speed_mm_s": args.speed_mm_s,
             "temperature_c": args.temperature_c, "instrument": args.instrument}
    for key, (option, low, high) in CONDITION_RANGES.items():
        value = given[key]
        if value is not None and not (low <= value <= high):
            raise DataError(f"{option}: expected a number from {low:g} to {high:g}, got "
                            f"{value!r}")
    return {k: v for k, v in given.items() if v is not None}


def _run_report(args) -> int:
    for out in (args.json_out, args.html_out):
        source = out and _is_input(Path(out), [args.measurements])
        if source:
            raise DataError(f"{out}: is an input ({source}); choose another output file")
    conditions = _conditions(args)
    poses, attained, commanded, quat, quat_c = read_iso_measurements(args.measurements)
    results = iso_results(poses, attained, commanded, quat, quat_c)
    for line in iso_summary(results, conditions):
        print(line)
    if args.json_out:
        doc = iso_report_to_dict(results, conditions)
        check_finite_json(doc, args.json_out)
        write_text_atomic(args.json_out, json.dumps(doc, indent=2, allow_nan=False) + "\n")
        print(f"wrote {args.json_out}")
    if args.html_out:
        from ..report.validation_html import write_iso_html

        write_iso_html(results, conditions, attained, poses, args.html_out)
        print(f"wrote {args.html_out}")
    return 0


def run(args) -> int:
    return _run_plan(args) if args.iso_command == "plan" else _run_report(args)
