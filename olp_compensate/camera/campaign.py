"""Virtual camera campaigns: a camera on the flange of a virtual robot looking at the board.

The scene (all poses are 4x4 homogeneous transforms, metres):

- the robot base frame; the board lies in the workspace at ``base_T_board`` and is the
  measuring device: the virtual robot's ``device_T_base`` is ``board_T_base``;
- the camera is a tool of the virtual robot named :data:`CAMERA_TOOL`: its frame (optical
  centre, z along the optical axis, see :mod:`.model`) sits at ``flange_T_camera`` in the
  true flange frame (the hand-eye transform the identification must find);
- a pose of the campaign is a vector of controller joints, inside the controller's axis
  ranges, at which the true camera sees the whole board from ``distance_m`` away, its
  optical axis ``tilt_deg`` from the board normal, every dot at least ``margin_px`` inside
  the image.

Poses are chosen by drawing views of the board (:func:`.render.random_views`), solving the
*nominal* arm's inverse kinematics for them (damped least squares from several starts,
:func:`nominal_inverse`), and keeping the joints at which the *true* arm's camera still sees
the board as asked (the real arm is millimetres off the nominal one); of several times the
poses wanted, the pose planner keeps those that identify the arm best
(:data:`CANDIDATES_PER_POSE`).

On disk (:func:`write_campaign`): ``images/viewNNN.png``, ``joints.csv`` (``image,
q1_deg..qN_deg``, mm for a prismatic axis) and ``truth.json``: the virtual robot's truth
file (:meth:`VirtualRobot.to_json`, readable by :meth:`VirtualRobot.from_json`) with a
``camera`` entry: intrinsics, hand-eye ``flange_T_camera``, ``base_T_board``, the board,
the render options and every view's true ``board_T_camera`` (mm, w-first quaternions).
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from ..calibration.pose_planning import planning_space, plan_poses
from ..calibration.simulate import VirtualRobot, make_virtual_robot, random_joints
from ..errors import DataError
from ..io.atomic import write_text_atomic
from ..io.images import write_png
from ..kinematics.conventions import (invert_pose, pose_from_rotation_translation,
                                      quat_wxyz_from_matrix, rot_x, rot_z,
                                      rotation_from_rotvec, rotvec_from_rotation)
from ..kinematics.model import build_model, forward
from ..kinematics.robot import Robot
from .board import Board, board_to_dict
from .model import CameraIntrinsics
from .render import RenderOptions, board_in_view, random_views, render_board

CAMERA_TOOL = "camera"
"""Name of the camera as a tool of the virtual robot (and the measured point's name)."""

CAMPAIGN_FORMAT = "olp-compensate camera campaign"

CANDIDATES_PER_POSE = 1
"""Good views drawn per wanted pose, for the planner to choose from (1: no planning). The
planner helps against random noise and not against the camera's own errors: on virtual
IRB 2400s (40 poses), the camera centre predicted at 1,000 new poses went from 0.056-0.071
to 0.031-0.043 mm RMS with simulated Gaussian measurements (0.02 mm, 0.0035 deg; 3 robots,
40 planned among 200), but from 0.022 and 0.070 to 0.069 and 0.104 mm with rendered and
measured views (seeds 1, 2 of benchmarks/camera.py): the planner picks extreme views, where
the camera measures worst."""


@dataclass(frozen=True)
class ViewLimits:
    """What a good view is: camera ``distance_m`` (lo, hi) from the point it looks at on the
    board, optical axis ``tilt_deg`` (lo, hi) from the board normal, every dot at least
    ``margin_px`` inside the image."""

    distance_m: tuple[float, float] = (0.35, 0.8)
    tilt_deg: tuple[float, float] = (20.0, 50.0)
    margin_px: float = 20.0

    def __post_init__(self):
        lo, hi = self.distance_m
        if not 0 < lo <= hi:
            raise DataError(f"campaign: distance range must be 0 < lo <= hi m, got {lo}, {hi}")
        lo, hi = self.tilt_deg
        if not 0 <= lo <= hi < 85:
            raise DataError(f"campaign: tilt range must be 0 <= lo <= hi < 85 deg, got "
                            f"{lo}, {hi}")


@dataclass(frozen=True)
class CameraCampaign:
    """A virtual campaign.

    virtual : the virtual robot; its device is the board (``device_T_base`` =
    board_T_base) and its tool :data:`CAMERA_TOOL` the camera (position and rotation =
    flange_T_camera). board, intrinsics : the board and the camera's true intrinsics.
    joints : (N, n) controller axes, rad or m. camera_T_board : (N, 4, 4) true poses of the
    board in the camera frame at those joints, m. names : (N,) image file names.
    """

    virtual: VirtualRobot
    board: Board
    intrinsics: CameraIntrinsics
    joints: np.ndarray
    camera_T_board: np.ndarray
    names: tuple[str, ...]

    @property
    def flange_T_camera(self) -> np.ndarray:
        """The true hand-eye transform (4, 4), m."""
        return pose_from_rotation_translation(self.virtual.tool_rotation(CAMERA_TOOL),
                                              self.virtual.tools[CAMERA_TOOL])

    @property
    def base_T_board(self) -> np.ndarray:
        """The board in the robot's base frame (4, 4), m."""
        return invert_pose(self.virtual.device_T_base)


def camera_mount(rng: np.random.Generator, distance_m: tuple[float, float] = (0.05, 0.15),
                 offset_m: float = 0.02, tilt_deg: float = 3.0) -> np.ndarray:
    """A plausible flange_T_camera (4, 4), m: the optical axis along the flange z within
    ``tilt_deg`` (N(0, tilt) about x and y), turned by a random angle about it, its centre
    ``distance_m`` out along z and up to ``offset_m`` aside."""
    turn = rot_z(rng.uniform(0, 2 * math.pi)) @ rotation_from_rotvec(
        np.append(rng.normal(0.0, math.radians(tilt_deg), 2), 0.0))
    where = np.array([rng.uniform(-offset_m, offset_m), rng.uniform(-offset_m, offset_m),
                      rng.uniform(*distance_m)])
    return pose_from_rotation_translation(turn, where)


def board_centre(board: Board) -> np.ndarray:
    """The centre of the dot grid in the board frame (3,), m."""
    return board.centre()


def default_board_pose(robot: Robot, board: Board, seed: int = 0) -> np.ndarray:
    """base_T_board (4, 4), m: the board lying face up in front of the robot (base +x), its
    centre at half the flange's reach and half a metre below the flange's median height;
    board x along base x, so its z (away from the printed face) points down."""
    rng = np.random.default_rng(seed)
    model = build_model(robot)
    q = robot.joints_from_controller(random_joints(robot, 500, rng))
    flange = forward(model, model.nominal, q).flange[:, :3, 3]
    reach = float(np.percentile(np.hypot(flange[:, 0], flange[:, 1]), 95))
    height = float(np.median(flange[:, 2])) - 0.5
    base_T_board = pose_from_rotation_translation(rot_x(math.pi), np.zeros(3))
    centre = np.array([0.5 * reach, 0.0, height])
    base_T_board[:3, 3] = centre - base_T_board[:3, :3] @ board_centre(board)
    return base_T_board


def make_camera_robot(robot: Robot, board: Board, seed: int = 0,
                      length_error_m: float = 1e-3, angle_error_rad: float = math.radians(0.1),
                      base_T_board: np.ndarray | None = None,
                      flange_T_camera: np.ndarray | None = None) -> VirtualRobot:
    """A virtual robot (:func:`make_virtual_robot`, same errors for a seed) whose device is
    the board at ``base_T_board`` (default :func:`default_board_pose`) and whose only tool
    is the camera at ``flange_T_camera`` (default :func:`camera_mount` drawn from seed)."""
    virtual = make_virtual_robot(robot, seed, length_error_m, angle_error_rad)
    if base_T_board is None:
        base_T_board = default_board_pose(robot, board, seed)
    if flange_T_camera is None:
        flange_T_camera = camera_mount(np.random.default_rng(seed + 7_000_001))
    return replace(virtual, device_T_base=invert_pose(np.asarray(base_T_board, dtype=float)),
                   tools={CAMERA_TOOL: np.array(flange_T_camera[:3, 3], dtype=float)},
                   tool_rotations={CAMERA_TOOL: np.array(flange_T_camera[:3, :3], dtype=float)})


def nominal_inverse(robot: Robot, base_T_flange: np.ndarray, rng: np.random.Generator,
                    starts: int = 12, iterations: int = 60, tolerance_m: float = 1e-7
                    ) -> np.ndarray | None:
    """Controller axes (n,) rad/m at which the *nominal* arm puts its flange at
    ``base_T_flange`` (4, 4), inside the controller's axis ranges, or None.

    Damped least squares on the analytic Jacobian from ``starts`` random joint vectors at
    once; the first start that converges (position within ``tolerance_m``, rotation within
    ``tolerance_m`` rad per metre) inside the ranges wins. Revolute joints are wrapped by
    whole turns towards zero before the range check.
    """
    model = build_model(robot)
    q = robot.joints_from_controller(random_joints(robot, starts, rng, margin=0.05))
    target_p, target_R = base_T_flange[:3, 3], base_T_flange[:3, :3]
    revolute = np.array([j.kind == "revolute" for j in robot.joints])
    damping = 1e-4
    for _ in range(iterations):
        chain = forward(model, model.nominal, q, jacobian=True)
        R = chain.flange[:, :3, :3]
        err = np.concatenate([target_p - chain.flange[:, :3, 3],
                              rotvec_from_rotation(target_R @ np.swapaxes(R, 1, 2))], axis=1)
        if np.all(np.linalg.norm(err, axis=1) < tolerance_m):
            break
        jac = np.concatenate([chain.dpoint_dq, chain.drot_dq], axis=1)
        jt = np.swapaxes(jac, 1, 2)
        step = np.linalg.solve(jt @ jac + damping * np.eye(robot.n_joints),
                               np.einsum("mij,mj->mi", jt, err)[..., None])[..., 0]
        q = q + np.clip(step, -0.5, 0.5)
    chain = forward(model, model.nominal, q)
    R = chain.flange[:, :3, :3]
    err = np.concatenate([target_p - chain.flange[:, :3, 3],
                          rotvec_from_rotation(target_R @ np.swapaxes(R, 1, 2))], axis=1)
    converged = np.linalg.norm(err, axis=1) < 10 * tolerance_m
    q = np.where(revolute, np.mod(q + math.pi, 2 * math.pi) - math.pi, q)
    q_ctrl = robot.controller_from_joints(q)
    inside = ~np.any(robot.outside_ranges(q_ctrl), axis=1)
    good = np.nonzero(converged & inside)[0]
    return None if good.size == 0 else q_ctrl[good[0]]


def _view_ok(board, intrinsics, camera_T_board, limits: ViewLimits) -> bool:
    """The true view is as asked: whole board inside the margin, tilt and distance in range
    (distance from the optical centre to where the optical axis meets the board plane)."""
    if not board_in_view(board, intrinsics, camera_T_board, limits.margin_px):
        return False
    tilt = math.degrees(math.acos(min(1.0, abs(camera_T_board[2, 2]))))
    board_T_camera = invert_pose(camera_T_board)
    axis, centre = board_T_camera[:3, 2], board_T_camera[:3, 3]
    if abs(axis[2]) < 1e-9:
        return False
    distance = -centre[2] / axis[2]
    lo, hi = limits.tilt_deg
    dlo, dhi = limits.distance_m
    return (lo - 0.5 <= tilt <= hi + 0.5) and (dlo - 0.01 <= distance <= dhi + 0.01)


def plan_campaign(virtual: VirtualRobot, board: Board, intrinsics: CameraIntrinsics,
                  count: int, rng: np.random.Generator, limits: ViewLimits = ViewLimits(),
                  candidates_per_pose: int = CANDIDATES_PER_POSE,
                  max_tries: int | None = None, prefix: str = "view") -> CameraCampaign:
    """``count`` robot poses at which the camera of ``virtual`` sees the whole board well.

    ``candidates_per_pose`` x ``count`` such poses are drawn, and ``count`` of them chosen by
    the I-optimal pose planner (:mod:`olp_compensate.calibration.pose_planning`, at the
    nominal arm, the camera centre as the measured point): the smallest predicted error of
    the identified arm over the workspace. With 1, or fewer poses than an identification
    needs, the first ones drawn are kept. Raises DataError when fewer than wanted are found
    in ``max_tries`` drawn views (default 40 per pose): the board is then out of reach or
    the limits too narrow.
    """
    if candidates_per_pose < 1:
        raise DataError(f"campaign: candidates_per_pose must be at least 1, got "
                        f"{candidates_per_pose}")
    if count < 1:
        raise DataError(f"campaign: the number of poses must be positive, got {count}")
    if CAMERA_TOOL not in virtual.tools:
        raise DataError(f"campaign: the virtual robot has no tool '{CAMERA_TOOL}' (make it "
                        f"with make_camera_robot)")
    robot = virtual.robot
    base_T_board = invert_pose(virtual.device_T_base)
    camera_T_flange = invert_pose(pose_from_rotation_translation(
        virtual.tool_rotation(CAMERA_TOOL), virtual.tools[CAMERA_TOOL]))
    wanted_count = count * candidates_per_pose
    tries = max_tries if max_tries is not None else 40 * wanted_count
    joints, poses = [], []
    for _ in range(tries):
        if len(joints) == wanted_count:
            break
        (wanted,) = random_views(board, intrinsics, 1, rng, limits.distance_m, limits.tilt_deg,
                                 limits.margin_px)
        base_T_flange = base_T_board @ invert_pose(wanted) @ camera_T_flange
        q = nominal_inverse(robot, base_T_flange, rng)
        if q is None:
            continue
        (true_frame,) = virtual.true_frames(q[None], [CAMERA_TOOL])
        camera_T_board = invert_pose(true_frame)
        if _view_ok(board, intrinsics, camera_T_board, limits):
            joints.append(q)
            poses.append(camera_T_board)
    if len(joints) < wanted_count:
        raise DataError(f"campaign: found {len(joints)} of {wanted_count} poses in {tries} "
                        f"tries at which the camera sees the whole board "
                        f"{limits.distance_m[0]:g}-{limits.distance_m[1]:g} m away, tilted "
                        f"{limits.tilt_deg[0]:g}-{limits.tilt_deg[1]:g} deg, inside the axis "
                        f"ranges; move the board within reach, widen the limits or draw fewer "
                        f"candidates per pose")
    chosen = choose_poses(virtual, np.array(joints), count)
    joints, poses = np.array(joints)[chosen], np.array(poses)[chosen]
    width = max(3, len(str(count)))
    names = tuple(f"{prefix}{k + 1:0{width}d}.png" for k in range(count))
    return CameraCampaign(virtual=virtual, board=board, intrinsics=intrinsics,
                          joints=joints, camera_T_board=poses, names=names)


def choose_poses(virtual: VirtualRobot, candidates: np.ndarray, count: int) -> np.ndarray:
    """Indices of the ``count`` candidates (controller joints) the I-optimal planner picks,
    in the order drawn; the first ``count`` when there is nothing to plan."""
    if len(candidates) == count:
        return np.arange(count)
    space = planning_space(virtual.robot, candidates=candidates,
                           tools={CAMERA_TOOL: virtual.tools[CAMERA_TOOL]})
    if count < space.min_poses:
        return np.arange(count)
    return np.sort(plan_poses(space, count, "i").indices)


def render_view(campaign: CameraCampaign, index: int,
                options: RenderOptions = RenderOptions()) -> np.ndarray:
    """The 8-bit image of view ``index`` (its noise seeded by ``options.seed + index``)."""
    return render_board(campaign.board, campaign.intrinsics, campaign.camera_T_board[index],
                        replace(options, seed=options.seed + index))


def _pose_dict(pose: np.ndarray) -> dict:
    return {"xyz_mm": (pose[:3, 3] * 1e3).tolist(),
            "quat_wxyz": quat_wxyz_from_matrix(pose[:3, :3]).tolist()}


def intrinsics_dict(k: CameraIntrinsics) -> dict:
    """The intrinsics as camera.json names them (px; k1, k2 dimensionless)."""
    return {"fx_px": k.fx, "mu": k.mu, "cx_px": k.cx, "cy_px": k.cy, "k1": k.k1, "k2": k.k2,
            "width": int(k.width), "height": int(k.height)}


def truth_json(campaign: CameraCampaign, options: RenderOptions | None = None) -> str:
    """The truth file: the virtual robot's (mm, deg) plus a ``camera`` entry (module
    docstring)."""
    camera = {
        "format": CAMPAIGN_FORMAT, "version": 1,
        "intrinsics": intrinsics_dict(campaign.intrinsics),
        "flange_T_camera": _pose_dict(campaign.flange_T_camera),
        "base_T_board": _pose_dict(campaign.base_T_board),
        "board": board_to_dict(campaign.board),
        "render": None if options is None else asdict(options),
        "views": [{"image": name, "board_T_camera": _pose_dict(invert_pose(T))}
                  for name, T in zip(campaign.names, campaign.camera_T_board)],
    }
    return replace(campaign.virtual, notes={**campaign.virtual.notes, "camera": camera}).to_json()


def joints_csv(campaign: CameraCampaign) -> str:
    """``image, q1_deg..qN_deg`` (mm for a prismatic axis), one row per view."""
    robot = campaign.virtual.robot
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["image"] + [f"q{k + 1}_{j.unit}" for k, j in enumerate(robot.joints)])
    for name, q in zip(campaign.names, robot.to_degrees_or_mm(campaign.joints)):
        writer.writerow([name] + [f"{v:.6f}" for v in q])
    return buffer.getvalue()


def write_campaign(campaign: CameraCampaign, folder: str | Path,
                   options: RenderOptions = RenderOptions(), progress=None) -> Path:
    """Render every view into ``folder/images`` and write ``joints.csv`` and
    ``truth.json`` beside it (each file atomically); returns the images folder.
    ``progress(done, total)``, when given, is called after each view is written."""
    folder = Path(folder)
    images = folder / "images"
    try:
        images.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DataError(f"{images}: cannot create the folder ({exc.strerror})") from None
    for k, name in enumerate(campaign.names):
        write_png(images / name, render_view(campaign, k, options))
        if progress is not None:
            progress(k + 1, len(campaign.names))
    write_text_atomic(folder / "joints.csv", joints_csv(campaign))
    write_text_atomic(folder / "truth.json", truth_json(campaign, options))
    return images


def read_campaign_truth(path: str | Path, robot: Robot) -> tuple[VirtualRobot, dict]:
    """The virtual robot of a campaign's truth.json and its ``camera`` entry (mm at the
    edge, as written)."""
    text = Path(path).read_text(encoding="utf-8")
    doc = json.loads(text)
    if doc.get("camera", {}).get("format") != CAMPAIGN_FORMAT:
        raise DataError(f"{path}: not a camera campaign truth file")
    return VirtualRobot.from_json(text, robot), doc["camera"]
