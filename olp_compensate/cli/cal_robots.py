"""``olp-cal robots``: the robot library (list, one robot's numbers, its generated URDF)."""

from __future__ import annotations

import json

HELP = "list the bundled robots (--json), or show one robot's parameters and ranges (--show)"


def add_arguments(p) -> None:
    p.add_argument("--json", action="store_true",
                   help="print the list as JSON (name, maker, model, axes, axis_ranges_deg...)")
    p.add_argument("--show", metavar="NAME",
                   help="print one robot's geometry, axis ranges, speeds and sources (a bundled "
                        "name or a path to a .robot.json or .urdf)")
    p.add_argument("--urdf", metavar="NAME", help="print the URDF generated for one robot")


def _fmt(value, unit: str = "") -> str:
    if value is None:
        return "-"
    text = f"{value:g}" if isinstance(value, (int, float)) else str(value)
    return f"{text} {unit}".rstrip()


def _summary(record) -> dict:
    """One robot of the list: what ``--json`` prints for it."""
    return {"name": record.name, "maker": record.maker, "model": record.model,
            "axes": len(record.axis_ranges_deg),
            "axis_ranges_deg": record.axis_ranges_deg.tolist(),
            "reach_mm": record.reach_mm, "payload_kg": record.payload_kg,
            "geometry": record.kind, "coupling": record.coupling_name,
            "dialect": record.dialect, "source": record.geometry["source"]}


def _print_list(records) -> None:
    rows = [("name", "maker", "model", "reach", "payload", "axes", "source")]
    for r in records:
        rows.append((r.name, r.maker, r.model, _fmt(r.reach_mm, "mm"), _fmt(r.payload_kg, "kg"),
                     str(len(r.axis_ranges_deg)), r.geometry["source"]))
    widths = [max(len(row[k]) for row in rows) for k in range(6)]
    for row in rows:
        print("  ".join(cell.ljust(w) for cell, w in zip(row[:6], widths)) + "  " + row[6])
    print(f"{len(records)} robots; `olp-cal robots --show NAME` for one robot's numbers")


def _geometry_lines(g: dict) -> list[str]:
    if g["kind"] == "opw":
        lengths = ", ".join(f"{k} {g[k] * 1e3:g}" for k in ("a1", "a2", "b", "c1", "c2", "c3",
                                                            "c4"))
        lines = [f"geometry      OPW: {lengths} mm",
                 f"base frame    {g['base_height'] * 1e3:g} mm above the OPW root (axis 1 foot)"]
        if any(g["flange_rpy_deg"]):
            lines.append(f"flange        rpy {g['flange_rpy_deg']} deg in the OPW tip frame")
    else:
        lines = [f"geometry      standard DH: d {[round(v * 1e3, 6) for v in g['d']]} mm, "
                 f"a {[round(v * 1e3, 6) for v in g['a']]} mm, alpha {list(g['alpha_deg'])} deg"]
    lines.append(f"joint offsets {list(g['offsets_deg'])} deg, signs {list(g['signs'])}")
    lines.append(f"source        {g['source']}")
    return lines


def _show(robot) -> None:
    record = robot.record
    if record is not None:
        print(f"{record.name}: {record.maker} {record.model}")
        print(f"payload {_fmt(record.payload_kg, 'kg')}, reach {_fmt(record.reach_mm, 'mm')}, "
              f"mass {_fmt(record.mass_kg, 'kg')}, program dialect {record.dialect or '-'}")
        for line in _geometry_lines(record.geometry):
            print(line)
        print(f"coupling      {record.coupling_name or 'none'}")
    else:
        print(f"{robot.name}: URDF {robot.source}")
    ranges = robot.to_degrees_or_mm(robot.controller_ranges.T).T
    speeds = None if record is None else record.max_speed_deg_s
    print("axis  range (deg)          max speed (deg/s)")
    for k, (lo, hi) in enumerate(ranges):
        speed = "-" if speeds is None else f"{speeds[k]:g}"
        print(f"{k + 1:>4}  {lo:>8g} .. {hi:<8g}  {speed}")
    if record is not None:
        sheet = record.datasheet
        if sheet.get("wrist_reach_mm") is not None:
            print(f"data sheet    wrist-centre reach {sheet['wrist_reach_mm']:g} mm "
                  f"({sheet.get('source', '')})")
        for source in record.sources:
            print(f"source        {source}")
    print(f"fingerprint   {robot.fingerprint}")


def run(args) -> int:
    from ..kinematics.robot import library_records, load_robot

    if args.urdf:
        print(load_robot(args.urdf).urdf_text, end="")
        return 0
    if args.show:
        _show(load_robot(args.show))
        return 0
    records = library_records()
    if args.json:
        print(json.dumps([_summary(r) for r in records], indent=1, allow_nan=False))
    else:
        _print_list(records)
    return 0
