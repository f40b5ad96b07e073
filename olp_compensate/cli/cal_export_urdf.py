"""``olp-cal export-urdf``: the calibrated robot as a URDF."""

from __future__ import annotations

import re

from ..errors import DataError

from ..io.atomic import write_text_atomic
from ..io.calibration_file import read_calibration
from ..io.urdf_export import calibrated_urdf
from .common import refuse_clashes

NON_FINITE = re.compile(r'(?:xyz|rpy)="[^"]*(?:nan|inf)', re.IGNORECASE)
HELP = "write a URDF whose joint origins carry the identified geometry"


def add_arguments(p) -> None:
    p.add_argument("--model", required=True, help="calib.json")
    p.add_argument("-o", "--output", required=True, help="URDF file to write")


def run(args) -> int:
    refuse_clashes([("--model", args.model)], [("-o", args.output)])
    cal = read_calibration(args.model)
    text = calibrated_urdf(cal)
    if NON_FINITE.search(text):
        raise DataError(f"{args.model}: the calibrated URDF would hold a non-finite joint "
                        f"origin; nothing written")
    write_text_atomic(args.output, text)
    print(f"wrote the calibrated URDF of {cal.robot.name} to {args.output}")
    return 0
