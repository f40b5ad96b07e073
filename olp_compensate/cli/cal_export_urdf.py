"""``olp-cal export-urdf``: the calibrated robot as a URDF."""

from __future__ import annotations

from ..io.atomic import write_text_atomic
from ..io.calibration_file import read_calibration
from ..io.urdf_export import calibrated_urdf

HELP = "write a URDF whose joint origins carry the identified geometry"


def add_arguments(p) -> None:
    p.add_argument("--model", required=True, help="calib.json")
    p.add_argument("-o", "--output", required=True, help="URDF file to write")


def run(args) -> int:
    cal = read_calibration(args.model)
    write_text_atomic(args.output, calibrated_urdf(cal))
    print(f"wrote the calibrated URDF of {cal.robot.name} to {args.output}")
    return 0
