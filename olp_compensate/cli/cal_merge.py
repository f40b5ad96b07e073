"""``olp-cal merge``: join a recorded session's joints with the device's points."""

from __future__ import annotations

from ..io.session import merge_session
from .common import refuse_clashes

HELP = "join an MCAP session (joints) with the measuring device's points into a measurement CSV"


def add_arguments(p) -> None:
    p.add_argument("session", help="MCAP session written by olp-cal record")
    p.add_argument("points", help="device CSV: x_mm, y_mm, z_mm [, time_s, point, pose]")
    p.add_argument("-o", "--output", required=True, help="measurement CSV (version 1) to write")
    p.add_argument("--by", choices=("order", "time"), default="order",
                   help="order: k-th point with k-th pose (or by the device's 'pose' column); "
                        "time: each point with the pose read nearest in time (default order)")
    p.add_argument("--tolerance-s", type=float, default=0.5,
                   help="--by time: largest gap between a point and its pose, s")
    p.add_argument("--time-offset-s", type=float, default=0.0,
                   help="--by time: added to the device's time_s to get Unix time, s")


def run(args) -> int:
    refuse_clashes([("session", args.session), ("points", args.points)], [("-o", args.output)])
    count = merge_session(args.session, args.points, args.output, by=args.by,
                          tolerance_s=args.tolerance_s, time_offset_s=args.time_offset_s)
    print(f"wrote {count} measured points ({args.session} joints + {args.points} points, "
          f"by {args.by}) to {args.output}")
    return 0
