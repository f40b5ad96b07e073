"""``olp-cal record``: the robot's joints at each measured pose, into an MCAP session."""

from __future__ import annotations

from ..errors import DataError, ModelError
from ..io.rtde_source import RtdeJointSource, TypedJointSource, console_ask, console_say
from ..io.session import record_session
from ..kinematics.robot import load_robot
from .common import refuse_clashes

HELP = ("record the joints at each measured pose into an MCAP session (live from a UR "
        "controller with --ur, else typed on stdin)")


def add_arguments(p) -> None:
    source = p.add_mutually_exclusive_group()
    source.add_argument("--ur", metavar="HOST",
                        help="read the joints live from a UR controller over RTDE (read-only); "
                             "press Enter at each pose")
    source.add_argument("--typed", action="store_true",
                        help="type the joints (degrees, as the pendant shows them) at each "
                             "pose (the default without --ur)")
    p.add_argument("-o", "--output", required=True,
                   help="session file to write (.mcap; never overwritten)")
    p.add_argument("--robot", help="robot name stored in the session (bundled name or URDF "
                                   "path; sets the joint count for typed joints)")
    p.add_argument("--joints", type=int, default=None,
                   help="joint count for typed joints without --robot (default 6)")
    p.add_argument("--note", default="", help="free text stored in the session")
    p.add_argument("--connect-timeout-s", type=float, default=5.0,
                   help="--ur: give up connecting after this long, s")
    p.add_argument("--stall-timeout-s", type=float, default=1.0,
                   help="--ur: a reading fails when the controller sends nothing this long, s")


def run(args) -> int:
    refuse_clashes([("--robot", args.robot)], [("-o", args.output)])
    robot = load_robot(args.robot) if args.robot else None
    if robot is not None:
        odd = [j.name for j in robot.joints if j.unit != "deg"]
        if odd:
            raise ModelError(f"sessions hold joints in degrees; robot {robot.name} has "
                             f"prismatic joints ({', '.join(odd)})")
        if args.joints is not None and args.joints != robot.n_joints:
            raise DataError(f"--joints {args.joints}: robot {robot.name} has "
                            f"{robot.n_joints} joints")
    n = robot.n_joints if robot is not None else (args.joints or 6)
    if n < 1:
        raise DataError(f"--joints: expected a positive joint count, got {n}")
    if args.ur:
        if n != 6:
            raise DataError(f"--ur reads 6 joints from a UR controller; the robot has {n}")
        console_say(f"Connecting to the UR controller at {args.ur} (RTDE, read-only)...")
        source = RtdeJointSource(args.ur, connect_timeout_s=args.connect_timeout_s,
                                 stall_timeout_s=args.stall_timeout_s)
        name = robot.name if robot is not None else f"UR robot at {args.ur}"
    else:
        source = TypedJointSource(n)
        name = robot.name if robot is not None else "unspecified"
    try:
        count = record_session(args.output, source, console_ask, console_say,
                               robot_name=name, note=args.note)
    finally:
        source.close()
    if count:
        console_say(f"next: olp-cal merge {args.output} POINTS.csv -o measurements.csv "
                    f"(the measuring device's points, one per pose)")
    return 0
