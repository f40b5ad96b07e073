"""``olp-cal nominal``: a calibration file that is exactly the nominal robot."""

from __future__ import annotations

from ..calibration.calibration import nominal_calibration
from ..io.calibration_file import write_calibration
from ..kinematics.robot import load_robot
from .common import refuse_clashes

HELP = "write a calibration that is exactly the nominal robot (device frame = base frame)"


def add_arguments(p) -> None:
    p.add_argument("--robot", required=True, help="bundled robot name or path to a URDF")
    p.add_argument("-o", "--output", required=True, help="calib.json to write")


def run(args) -> int:
    refuse_clashes([("--robot", args.robot)], [("-o", args.output)])
    robot = load_robot(args.robot)
    write_calibration(args.output, nominal_calibration(robot))
    print(f"wrote the nominal calibration of {robot.name} to {args.output}")
    return 0
