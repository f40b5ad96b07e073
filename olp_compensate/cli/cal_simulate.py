"""``olp-cal simulate``: measurements of a virtual robot with known errors, and its truth."""

from __future__ import annotations

import numpy as np

from ..io.atomic import write_text_atomic
from ..io.measurements import write_measurements
from ..robot import load_robot
from ..simulate import make_virtual_robot, random_joints

HELP = "write measurements of a virtual robot (random geometric errors) and its truth file"


def add_arguments(p) -> None:
    p.add_argument("--robot", required=True, help="bundled robot name or path to a URDF")
    p.add_argument("--poses", type=int, required=True, help="number of measured poses")
    p.add_argument("--noise-mm", type=float, default=0.05, help="measurement noise per axis, mm")
    p.add_argument("--seed", type=int, default=0, help="random seed (errors and poses)")
    p.add_argument("--points", type=int, default=1, help="measured points on the tool per pose")
    p.add_argument("--length-error-mm", type=float, default=1.0, help="link error size, mm")
    p.add_argument("--angle-error-deg", type=float, default=0.1, help="axis/zero error size, deg")
    p.add_argument("--device-distance-m", type=float, default=2.0, help="device distance, m")
    p.add_argument("-o", "--output", required=True, help="measurement CSV to write")
    p.add_argument("--truth", help="truth JSON to write (true errors, device pose, tools)")


def run(args) -> int:
    from ..errors import DataError

    if args.poses < 1 or args.noise_mm < 0 or args.points < 1:
        raise DataError("--poses and --points must be positive and --noise-mm not negative")
    robot = load_robot(args.robot)
    virtual = make_virtual_robot(robot, args.seed, args.length_error_mm * 1e-3,
                                 np.radians(args.angle_error_deg), args.points,
                                 args.device_distance_m)
    rng = np.random.default_rng(args.seed + 1_000_003)
    meas = virtual.measure(random_joints(robot, args.poses, rng), args.noise_mm * 1e-3, rng)
    units = [j.unit for j in robot.joints]
    write_measurements(args.output, meas, units,
                       [f"# robot: {robot.name}", f"# virtual robot seed {args.seed}, "
                        f"noise {args.noise_mm} mm per axis"])
    if args.truth:
        write_text_atomic(args.truth, virtual.to_json())
    print(f"wrote {meas.n_rows} measured points ({args.poses} poses, {args.points} per pose) "
          f"to {args.output}" + (f", truth to {args.truth}" if args.truth else ""))
    return 0
