"""``olp-cal controller``: the model the robot's controller runs, as a calib.json.

SOURCE is a UR ``calibration.conf`` (deltas), a UR ``.urp`` program (absolute D-H in its
``<kinematics>``), the ``.yaml`` of ROS's UR calibration (segments), or a ``.csv`` of the
poses the controller reports (``q1_deg..qN_deg, x_mm, y_mm, z_mm, qw, qx, qy, qz``). The
model is fitted with the identification core in the controller's base frame; the written
calib.json (same robot, same format) says where it came from in its validation method.
"""

from __future__ import annotations

import math
from pathlib import Path

from ..errors import DataError
from .common import refuse_clashes

HELP = ("write the model the robot controller runs (UR calibration.conf, .urp, ROS "
        "calibration .yaml, or a CSV of the poses it reports) as a calib.json")
SOURCES = (".conf", ".urp", ".yaml", ".yml", ".csv")


def add_arguments(p) -> None:
    p.add_argument("source", metavar="SOURCE",
                   help="calibration.conf, PROGRAM.urp, calibration.yaml or poses.csv")
    p.add_argument("--robot", required=True, help="bundled robot name or path to a URDF")
    p.add_argument("-o", "--output", required=True, help="controller.json to write")
    p.add_argument("--tool", metavar="NAME",
                   help="CSV only: the rows are the pose of this tool, not of the flange "
                        "(the tool is fitted with the model and kept under this name)")


def run(args) -> int:
    from ..calibration.controller_fit import CONTROLLER_FLANGE, fit_chain, fit_controller
    from ..io.calibration_file import write_calibration
    from ..kinematics.robot import load_robot

    refuse_clashes([("SOURCE", args.source), ("--robot", args.robot)], [("-o", args.output)])
    suffix = Path(args.source).suffix.lower()
    if suffix not in SOURCES:
        raise DataError(f"{args.source}: expected one of {', '.join(SOURCES)} (UR "
                        f"calibration.conf, UR program, ROS calibration YAML, reported poses)")
    if args.tool and suffix != ".csv":
        raise DataError("--tool: only a CSV of reported poses names a tool; UR files state "
                        "the flange")
    robot = load_robot(args.robot)
    if suffix == ".csv":
        from ..io.controller_poses import read_reported_poses

        rows = read_reported_poses(args.source, robot)
        origin = (f"{len(rows.lines)} poses reported by the controller ({args.source}"
                  f"{', tool ' + args.tool if args.tool else ', flange'})")
        fit = fit_controller(robot, rows.q_ctrl, rows.base_T_tool, origin=origin,
                             tool=args.tool or CONTROLLER_FLANGE,
                             precision_m=rows.precision_m, precision_rad=rows.precision_rad)
    else:
        from ..io.ur_kinematics import read_ur_kinematics
        from ..kinematics.dh_table import ur_nominal

        kin = read_ur_kinematics(args.source)
        nominal = ur_nominal(robot.name)
        words = {"conf": "UR calibration.conf (D-H deltas added to the data sheet)",
                 "urp": "UR program kinematics (absolute D-H, deltaTheta on zero offsets)",
                 "yaml": "ROS UR calibration YAML (joint origins x y z roll pitch yaw)"}
        fit = fit_chain(robot, kin.chain(nominal), f"{words[kin.form]} {args.source}")
        for note in kin.notes:
            print(f"olp-cal controller: warning: {args.source}: {note}")
    write_calibration(args.output, fit.calibration)
    _print(fit, args)
    return 0


def _print(fit, args) -> None:
    cal = fit.calibration
    print(f"olp-cal controller: {cal.validation.method}")
    print(f"  model of {cal.robot.name} fitted to {fit.rows} poses in the controller's base "
          f"frame: residual {fit.position_rms_m * 1e3:.6f} mm RMS, "
          f"{fit.position_max_m * 1e3:.6f} mm max; {math.degrees(fit.rotation_rms_rad):.6f} "
          f"deg RMS, {math.degrees(fit.rotation_max_rad):.6f} deg max (condition number "
          f"{cal.validation.condition_number:.1f})")
    if args.source.lower().endswith(".csv"):
        if fit.reproduces:
            print(f"  the model reproduces every row to its written precision "
                  f"({fit.precision_m * 1e3:.6f} mm, {math.degrees(fit.precision_rad):.6f} deg)")
        else:
            print(f"  warning: the model does NOT reproduce the rows to their written precision "
                  f"({fit.precision_m * 1e3:.6f} mm, {math.degrees(fit.precision_rad):.6f} deg): "
                  f"the controller runs something this model cannot hold (a load model, a "
                  f"base frame off axis 1, rows of different tools) or the rows are not what "
                  f"the controller computed")
    print(f"  wrote {args.output}")
