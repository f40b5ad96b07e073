"""``olp-cal plan``: which poses to measure, chosen for the identification, as a joint CSV."""

from __future__ import annotations

import numpy as np

from ..errors import DataError
from ..io.poses import check_within_limits, read_poses, write_poses
from ..calibration.pose_planning import (CRITERIA, DEFAULT_CANDIDATES, DEFAULT_CRITERION, DEFAULT_TOOL_M,
                             RANDOM_DRAWS, plan_poses, planning_space)
from ..kinematics.robot import load_robot
from .common import refuse_clashes

HELP = ("plan the poses to measure (I- or D-optimal for the identification, among random or "
        "given candidate poses) and write them as a joint CSV")
CRITERION_NAMES = {"d": "D-optimal (largest log det of the information)",
                   "i": "I-optimal (smallest predicted error at random poses)"}


def add_arguments(p) -> None:
    p.add_argument("--robot", required=True, help="bundled robot name or path to a URDF")
    p.add_argument("--poses", type=int, help="number of poses to plan (not with --volume)")
    p.add_argument("--volume", choices=("cube",),
                   help="plan the seed's pose set of a calibration volume instead: points on "
                        "the faces of a cube or a 3x3x3 grid, each reached with the "
                        "orientation the criterion prefers among those inside the axis ranges")
    p.add_argument("--centre", metavar="X,Y,Z", help="--volume: the cube's centre, mm, base frame")
    p.add_argument("--size", type=float, metavar="MM", help="--volume: the cube's edge, mm")
    p.add_argument("--layout", choices=("faces", "grid"), default="faces",
                   help="--volume: 12 points on the faces (default) or a 3x3x3 grid of 27")
    p.add_argument("--program", metavar="PROGRAM",
                   help="--volume: also write a program that visits the poses: .mod (RAPID "
                        "MoveAbsJ) or .pg (V+ precision points)")
    p.add_argument("--candidates", type=int, default=DEFAULT_CANDIDATES,
                   help="number of random candidate poses inside the joint limits")
    p.add_argument("--from", dest="candidates_file", metavar="CSV",
                   help="choose among these poses instead (pose, q1_deg..qN_deg; e.g. poses "
                        "known to be reachable in the cell)")
    p.add_argument("--seed", type=int, default=0, help="random seed (candidates, test poses)")
    p.add_argument("--criterion", choices=CRITERIA, default=DEFAULT_CRITERION,
                   help="i: smallest predicted error of the model at random poses (default); "
                        "d: largest determinant of the information matrix")
    p.add_argument("--tool", action="append", default=[], metavar="X,Y,Z",
                   help="a measured point in the flange frame, mm (repeatable: one per point "
                        "measured at every pose, named tcp, p2, ... as olp-cal simulate names "
                        "them; default "
                        + ",".join(f"{v * 1e3:g}" for v in DEFAULT_TOOL_M)
                        + "; write --tool=-50,0,150 when X is negative)")
    p.add_argument("--min-distance-deg", type=float, default=0.0,
                   help="two planned poses differ by at least this much in some joint, deg")
    p.add_argument("--freeze", action="append", default=[], metavar="PARAM",
                   help="a parameter you will hold at nominal in identify (repeatable)")
    p.add_argument("-o", "--output", required=True, help="pose CSV to write")


def parse_tool(text: str, flag: str = "--tool") -> np.ndarray:
    """(3,) metres from ``X,Y,Z`` in mm (``flag`` names the option in the message)."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 3 or not np.all(np.isfinite(values)):
        raise DataError(f"{flag}: expected X,Y,Z in mm, got '{text}'")
    return np.array(values) * 1e-3


def run(args) -> int:
    refuse_clashes([("--from", args.candidates_file), ("--robot", args.robot)],
                   [("-o", args.output), ("--program", args.program)])
    if args.volume:
        return _run_volume(args)
    if args.poses is None:
        raise DataError("give --poses N (or --volume cube with --centre and --size)")
    if args.poses < 1 or args.candidates < 1 or not args.min_distance_deg >= 0:
        raise DataError("--poses and --candidates must be positive, --min-distance-deg not "
                        "negative")
    robot = load_robot(args.robot)
    units = [j.unit for j in robot.joints]
    tools = None
    if args.tool:
        tools = {("tcp" if k == 0 else f"p{k + 1}"): parse_tool(t) for k, t in enumerate(args.tool)}
    candidates = None
    if args.candidates_file:
        given = read_poses(args.candidates_file, units)
        check_within_limits(given, robot)
        candidates = given.joints
    space = planning_space(robot, candidates, args.candidates, args.seed, tools,
                           tuple(args.freeze))
    plan = plan_poses(space, args.poses, args.criterion, args.min_distance_deg,
                      compare_seed=args.seed)
    n_tool = sum(n.startswith("tool.") for n in plan.unknown_names)
    source = args.candidates_file or f"{plan.n_candidates} random candidates"
    write_poses(args.output, plan.joints, units, metadata=[
        f"# robot: {robot.name}",
        f"# {args.poses} poses planned from {source} (seed {args.seed}), "
        f"criterion {args.criterion}",
        "# tool points (flange frame, mm): " + "; ".join(
            f"{n} {','.join(f'{v * 1e3:g}' for v in xyz)}"
            for n, xyz in zip(space.tool_names, space.tools_m))])
    q, r = plan.quality, plan.random
    print(f"robot {robot.name}: {args.poses} poses planned from {source}, "
          f"{CRITERION_NAMES[args.criterion]}; {plan.n_unknowns} unknowns (6 device "
          f"registration + {plan.n_unknowns - 6 - n_tool} geometric + {n_tool} tool), "
          f"{plan.swaps} exchanges after the greedy start")
    print(f"log det of the information (unit-scaled columns): {q.log_det:.2f} "
          f"(random poses: {r.log_det:.2f}, median of {RANDOM_DRAWS} sets)")
    print(f"expected model error at random poses: {q.expected_error:.2f}x the per-axis noise "
          f"(random poses: {r.expected_error:.2f}x); RMS of the measured point's error, "
          f"linearized at the nominal model")
    unseen = [n for n, why in plan.frozen.items() if "candidate" in why]
    frozen = [n for n in plan.frozen if n not in unseen]
    if frozen:
        print("frozen, as olp-cal identify freezes them: " + ", ".join(frozen))
    if unseen:
        print("not planned for, inseparable at every candidate pose with this tool: "
              + ", ".join(unseen))
    print(f"wrote {args.poses} poses to {args.output} (pose, "
          f"{', '.join([f'q1_{units[0]}', '...', f'q{len(units)}_{units[-1]}'])}; "
          f"controller axes)")
    return 0


def _run_volume(args) -> int:
    """``--volume cube``: the seed's pose set of one calibration volume (section 6.1)."""
    from ..calibration.volumes import cube_pose_set, joint_program, pose_set_metadata
    from ..io.atomic import write_text_atomic
    from ..programs import dialect_for

    if args.centre is None or args.size is None or not args.size > 0:
        raise DataError("--volume cube needs --centre X,Y,Z (mm) and a positive --size (mm)")
    if args.poses is not None or args.candidates_file:
        raise DataError("--volume plans its own points: leave out --poses and --from")
    robot = load_robot(args.robot)
    units = [j.unit for j in robot.joints]
    centre = parse_tool(args.centre, "--centre")
    tool = parse_tool(args.tool[0]) if args.tool else np.array(DEFAULT_TOOL_M)
    dialect = dialect_for(args.program) if args.program else None
    pose_set = cube_pose_set(robot, centre, args.size * 1e-3, args.layout, tool_m=tool,
                             criterion=args.criterion, seed=args.seed)
    write_poses(args.output, pose_set.joints, units, pose_ids=pose_set.names,
                metadata=[f"# robot: {robot.name}"] + pose_set_metadata(pose_set))
    if args.program:
        write_text_atomic(args.program, joint_program(pose_set, robot, dialect))
    degrees = robot.to_degrees_or_mm(pose_set.joints)
    print(f"robot {robot.name}: {len(pose_set.names)} poses of a {args.size:g} mm cube at "
          f"({args.centre}) mm, layout {args.layout}, {CRITERION_NAMES[args.criterion]}")
    for name, point, q in zip(pose_set.names, pose_set.points_m, degrees):
        print(f"  {name}: point ({', '.join(f'{v * 1e3:.1f}' for v in point)}) mm, joints "
              f"({', '.join(f'{v:.2f}' for v in q)}) deg")
    print(f"wrote {args.output}" + (f" and {args.program}" if args.program else ""))
    return 0
