"""``olp-cal simulate --camera camera.json --board board.json --robot R --poses N -o DIR``:
a virtual camera campaign (:mod:`olp_compensate.camera.campaign`): a camera with the
intrinsics of camera.json on the flange of a virtual robot (random geometric errors of
``--seed``), the board in its workspace, N poses at which the camera sees the whole board,
rendered into ``DIR/images``, with ``DIR/joints.csv`` (for ``olp-cal camera measure
--joints``) and ``DIR/truth.json``.

Hooked into ``olp-cal simulate`` (cal_simulate.py): :func:`add_camera_arguments` adds the
options, and ``run`` hands over to :func:`run_camera` when ``--camera`` is given.
"""

from __future__ import annotations

import math
import sys

CANDIDATES = 1
"""Default of --candidates-per-pose (the library's CANDIDATES_PER_POSE, without importing
numpy at parser build time)."""


def add_camera_arguments(p) -> None:
    """The camera campaign's options (besides simulate's --robot, --poses, --seed,
    --length-error-mm, --angle-error-deg and -o, read by :func:`run_camera`)."""
    g = p.add_argument_group("camera campaign (with --camera: -o is a folder)")
    g.add_argument("--camera", metavar="camera.json",
                   help="simulate a camera on the flange with these intrinsics looking at the "
                        "board: write DIR/images, DIR/joints.csv and DIR/truth.json")
    g.add_argument("--board", metavar="board.json", help="the board (with --camera)")
    g.add_argument("--distance-mm", default="350:800", metavar="LO:HI",
                   help="camera distance from the board, mm (default 350:800)")
    g.add_argument("--tilt-deg", default="20:50", metavar="LO:HI",
                   help="optical axis from the board normal, deg (default 20:50)")
    g.add_argument("--candidates-per-pose", type=int, default=CANDIDATES,
                   help="good views drawn per pose, of which the pose planner keeps the best "
                        f"for identification (default {CANDIDATES}: keep the first drawn)")
    g.add_argument("--image-noise", type=float, default=2.0,
                   help="image noise, grey levels (default 2)")
    g.add_argument("--blur-px", type=float, default=0.8,
                   help="Gaussian blur, px (default 0.8)")
    g.add_argument("--uneven-light", type=float, default=0.3,
                   help="light falls by this fraction across the image (default 0.3)")


def _range(text: str, option: str) -> tuple[float, float]:
    from ..errors import DataError

    try:
        lo, hi = (float(v) for v in text.split(":"))
    except ValueError:
        raise DataError(f"{option}: expected LO:HI, got '{text}'") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise DataError(f"{option}: expected LO:HI with LO <= HI, got '{text}'")
    return lo, hi


def _progress(done: int, total: int) -> None:
    """One stderr line per tenth of the views (and the last): rendering is the long part."""
    step = max(1, total // 10)
    if done % step == 0 or done == total:
        print(f"rendered {done} of {total} views", file=sys.stderr, flush=True)


def run_camera(args) -> int:
    """Write the campaign of ``args`` (see the module docstring)."""
    from pathlib import Path

    import numpy as np

    from ..camera.board import read_board
    from ..camera.campaign import ViewLimits, make_camera_robot, plan_campaign, write_campaign
    from ..camera.render import RenderOptions
    from ..errors import DataError
    from ..io.camera_file import read_camera
    from ..kinematics.robot import load_robot

    if not args.board:
        raise DataError("--camera needs --board board.json")
    if args.poses is None or args.poses < 1:
        raise DataError("--camera needs --poses N (N >= 1)")
    if getattr(args, "joints", None):
        raise DataError("--camera chooses its own poses (the camera must see the board); "
                        "leave out --joints")
    intrinsics = read_camera(args.camera).intrinsics
    board = read_board(args.board)
    robot = load_robot(args.robot)
    distance = _range(args.distance_mm, "--distance-mm")
    limits = ViewLimits(distance_m=(distance[0] * 1e-3, distance[1] * 1e-3),
                        tilt_deg=_range(args.tilt_deg, "--tilt-deg"))
    options = RenderOptions(noise_sigma=args.image_noise, blur_sigma_px=args.blur_px,
                            gradient=args.uneven_light, vignetting=0.5 * args.uneven_light,
                            seed=args.seed)
    virtual = make_camera_robot(robot, board, args.seed, args.length_error_mm * 1e-3,
                                math.radians(args.angle_error_deg))
    print(f"planning {args.poses} poses at which the camera sees the board ...",
          file=sys.stderr, flush=True)
    campaign = plan_campaign(virtual, board, intrinsics, args.poses,
                             np.random.default_rng(args.seed + 3_000_017), limits,
                             candidates_per_pose=args.candidates_per_pose)
    folder = Path(args.output)
    if folder.exists() and not folder.is_dir():
        raise DataError(f"{folder}: with --camera, -o names a folder, and this is a file")
    images = write_campaign(campaign, folder, options, progress=_progress)
    print(f"wrote {args.poses} views of the board ({intrinsics.width} x {intrinsics.height} "
          f"px) to {images}, the joints to {folder / 'joints.csv'}, the truth (robot errors, "
          f"hand-eye, board pose) to {folder / 'truth.json'}")
    return 0
