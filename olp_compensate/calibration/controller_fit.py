"""The controller's own model, fitted to the poses the controller reports.

A robot controller turns targets into joints with its own model: the data sheet, the maker's
factory calibration (every UR), or an absolute-accuracy option's hidden model (ABB, KUKA...).
What it computes can be read back: joints and the pose it reports for them (pendant, a RAPID
``CRobT``/``CJointT`` log, KUKA ``$POS_ACT``/``$AXIS_ACT``, UR waypoints). :func:`fit_controller`
fits the robot's calibration model to such rows with the identification core
(:class:`~.problem.IdentificationProblem`, :func:`~.lm.levenberg_marquardt`) *without* a device
registration: the rows are in the controller's base frame, so ``device_T_base`` is the
identity and joint 1's zero and height (``j1.theta``, ``j1.d``) are free. The reported frame
(the flange, or a named tool) is a tool of the fit, position and rotation: for the flange it
is :data:`CONTROLLER_FLANGE`, the part of the controller's flange the model's fixed flange
transform cannot hold (UR's ``d6`` delta...), applied by :func:`controller_chain`.

Its statistics are those of identification: per-parameter standard deviations from
sigma^2 (J^T J)^-1 at the solution, the condition number of the column-scaled Jacobian, and
the residuals, which :attr:`ControllerFit.reproduces` compares with the rows' written
precision.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import DataError, ModelError
from ..kinematics.conventions import (matrix_from_quat_wxyz,
                                      pose_from_rotation_translation, quat_wxyz_from_matrix)
from ..kinematics.fixed_chain import FixedChain
from ..kinematics.model import build_model, fixed_chain, forward
from ..kinematics.robot import Robot
from .calibration import Calibration, ToolPoint, Validation
from .identifiability import RANK_TOLERANCE
from .lm import levenberg_marquardt
from .measurements import Measurements
from .problem import IdentificationProblem, tool_rotation_start
from .statistics import unit_scaled_svd

CONTROLLER_FLANGE = "controller_flange"
"""The tool of a controller model that holds its flange in the model's flange frame."""
METHOD_PREFIX = "controller model"
"""How a controller model's validation method starts (its origin follows)."""


@dataclass(frozen=True)
class ControllerFit:
    """A fitted controller model and how well it reproduces the rows.

    ``calibration``: the model (device frame = controller base; tool ``tool``);
    ``position_rms_m``/``position_max_m``: 3-D distance between reported and modelled
    positions; ``rotation_rms_rad``/``rotation_max_rad``: angle between the frames;
    ``precision_m``/``precision_rad``: what the rows' written decimals resolve (half a unit
    of the last digit, over the three axes)."""

    calibration: Calibration
    tool: str
    rows: int
    position_rms_m: float
    position_max_m: float
    rotation_rms_rad: float
    rotation_max_rad: float
    precision_m: float
    precision_rad: float

    @property
    def reproduces(self) -> bool:
        """Whether every row is reproduced to its written precision (twice the rounding
        of the last digit over three axes, as rounding alone reaches ``sqrt(3)/2`` units)."""
        return (self.position_max_m <= 2 * self.precision_m
                and self.rotation_max_rad <= 2 * self.precision_rad)


def _rows(robot: Robot, q_ctrl: np.ndarray, base_T_tool: np.ndarray, tool: str,
          source: str) -> Measurements:
    m = len(q_ctrl)
    names = np.full(m, tool, dtype=object)
    return Measurements(joints=robot.joints_from_controller(q_ctrl),
                        points=base_T_tool[:, :3, 3].copy(),
                        pose_ids=np.array([str(k) for k in range(m)], dtype=object),
                        point_names=names,
                        orientation=quat_wxyz_from_matrix(base_T_tool[:, :3, :3]),
                        source=source)


def fit_controller(robot: Robot, q_ctrl: np.ndarray, base_T_tool: np.ndarray, *,
                   origin: str, tool: str = CONTROLLER_FLANGE, precision_m: float = 1e-9,
                   precision_rad: float = 1e-6, max_iterations: int = 200) -> ControllerFit:
    """Fit the model of ``robot`` to what its controller reports.

    q_ctrl : (m, n) controller axes, rad (m for prismatic axes).
    base_T_tool : (m, 4, 4) the pose the controller reports for them, its base frame, m.
    origin : where the rows came from, in words (kept in the calibration's validation).
    tool : the name of the reported frame (:data:`CONTROLLER_FLANGE` for the flange).
    precision_m, precision_rad : half a unit of the rows' last written digit, m and rad;
        they weight orientation against position and judge :attr:`ControllerFit.reproduces`.
    """
    q_ctrl = np.atleast_2d(np.asarray(q_ctrl, dtype=float))
    base_T_tool = np.asarray(base_T_tool, dtype=float).reshape(-1, 4, 4)
    if len(q_ctrl) != len(base_T_tool) or q_ctrl.shape[1] != robot.n_joints:
        raise DataError(f"{origin}: expected one pose per row of {robot.n_joints} joints, got "
                        f"{q_ctrl.shape} joints and {len(base_T_tool)} poses")
    if not (np.all(np.isfinite(q_ctrl)) and np.all(np.isfinite(base_T_tool))):
        raise DataError(f"{origin}: joints and poses must be finite")
    model = build_model(robot)
    meas = _rows(robot, q_ctrl, base_T_tool, tool, origin)
    last = f"j{robot.n_joints}.theta"
    frozen = {last: f"redundant with the reported frame's rotation about axis "
                    f"{robot.n_joints} (held at nominal; the frame is found in the flange "
                    f"frame of the nominal zero)"} if last in model.names else {}
    free = np.array([k for k, name in enumerate(model.names) if name not in frozen], dtype=int)
    equations, unknowns = 6 * len(q_ctrl), len(free) + 6
    if equations <= unknowns:
        raise DataError(f"{origin}: {len(q_ctrl)} poses give {equations} equations for "
                        f"{unknowns} unknowns; report at least {unknowns // 6 + 1} poses")
    nominal = forward(model, model.nominal, meas.joints).flange
    start_point = np.mean(np.einsum("mji,mj->mi", nominal[:, :3, :3],
                                    meas.points - nominal[:, :3, 3]), axis=0)
    rotations = tool_rotation_start(nominal, np.eye(4), meas, [tool])
    problem = IdentificationProblem(model, meas, model.nominal, free, [tool], np.eye(4),
                                    tool_rotations0=rotations,
                                    orientation_weight=precision_m / precision_rad)
    x0 = problem.pack(model.nominal, np.eye(4), start_point[None])
    fixed = problem.layout.registration          # no registration: the base is the controller's

    def residuals_and_jacobian(xs):
        x = np.concatenate([np.zeros(6), xs])
        r, jac = problem.residuals_and_jacobian(x)
        return r, jac[:, fixed.stop:]

    result = levenberg_marquardt(residuals_and_jacobian, x0[fixed.stop:],
                                 max_iterations=max_iterations, ftol=1e-30, xtol=1e-15,
                                 gtol=1e-30)
    x = np.concatenate([np.zeros(6), result.x])
    return _result(robot, model, problem, x, result, frozen, free, origin, tool,
                   precision_m, precision_rad)


def _result(robot, model, problem, x, lm, frozen, free, origin, tool, precision_m,
            precision_rad) -> ControllerFit:
    """The :class:`ControllerFit` at the solution: statistics and the calibration."""
    residual, jac = lm.residuals, lm.jacobian
    dof = max(len(residual) - jac.shape[1], 1)
    sigma2 = float(residual @ residual) / dof
    norms, s, vt = unit_scaled_svd(jac)
    inv_s2 = np.where(s > RANK_TOLERANCE * s[0], 1.0 / np.maximum(s, 1e-300) ** 2, 0.0)
    std_sub = np.sqrt(np.clip(np.diag((vt.T * inv_s2) @ vt), 0, None) * sigma2) / norms
    std_all = np.concatenate([np.zeros(6), std_sub])
    layout = problem.layout
    values, _, tools = problem.unpack(x)
    std = np.full(model.n_parameters, np.nan)
    std[free] = std_all[layout.geometry]
    m = len(problem.measured)
    distances = np.linalg.norm(residual[:3 * m].reshape(m, 3), axis=1)
    angles = problem.orientation_angles(x)
    rotation = problem.tool_rotations(x)[0]
    point = ToolPoint(xyz_m=tools[0], std_m=std_all[layout.tool_point(0)],
                      quat_wxyz=quat_wxyz_from_matrix(rotation),
                      rot_std_rad=std_all[layout.tool_rotations][:3])
    validation = Validation(
        method=f"{METHOD_PREFIX}: {origin}", poses=m,
        residual_rms_mm=float(np.sqrt(np.mean(distances ** 2))) * 1e3,
        residual_max_mm=float(distances.max()) * 1e3, heldout_rms_mm=None,
        heldout_max_mm=None, condition_number=float(s[0] / s[-1]),
        orientation_rms_deg=float(np.degrees(np.sqrt(np.mean(angles ** 2)))),
        orientation_max_deg=float(np.degrees(angles.max())))
    calibration = Calibration(robot=robot, model=model, values=values, std=std,
                              frozen=dict(frozen), tools={tool: point}, validation=validation)
    return ControllerFit(calibration=calibration, tool=tool, rows=m,
                         position_rms_m=validation.residual_rms_mm * 1e-3,
                         position_max_m=validation.residual_max_mm * 1e-3,
                         rotation_rms_rad=float(np.sqrt(np.mean(angles ** 2))),
                         rotation_max_rad=float(angles.max()),
                         precision_m=precision_m, precision_rad=precision_rad)


def fit_chain(robot: Robot, chain: FixedChain, origin: str, poses: int = 120) -> ControllerFit:
    """The controller model of a chain a maker's file states (UR D-H, ROS segments):
    fitted, noise-free, to its flange at ``poses`` joint sets spread over +-180 deg."""
    from ..kinematics.model import spread_joints

    q_urdf = spread_joints(poses, robot.n_joints, seed=7)
    q_ctrl = robot.controller_from_joints(q_urdf)
    return fit_controller(robot, q_ctrl, chain.flange(q_urdf), origin=origin,
                          precision_m=1e-12, precision_rad=1e-12)


def is_controller_model(calibration: Calibration) -> bool:
    """Whether the calibration was written by ``olp-cal controller``."""
    v = calibration.validation
    return v is not None and v.method.startswith(METHOD_PREFIX)


def controller_chain(calibration: Calibration) -> FixedChain:
    """The chain the controller computes with: the calibration's model at its values, its
    flange moved by the tool :data:`CONTROLLER_FLANGE` where it has one. Geometry only: a
    controller's model holds no load or gear effects."""
    chain = fixed_chain(calibration.model, calibration.values)
    if chain is None:
        raise ModelError(f"{calibration.robot.name}: a controller model needs a 6R arm")
    tool = calibration.tools.get(CONTROLLER_FLANGE)
    if tool is None:
        return chain
    rotation = np.eye(3) if tool.quat_wxyz is None else matrix_from_quat_wxyz(tool.quat_wxyz)
    flange = pose_from_rotation_translation(rotation, tool.xyz_m)
    links = chain.links.copy()
    links[-1] = links[-1] @ flange
    return FixedChain(first=chain.first, links=links)


def controller_poses(calibration: Calibration, q_ctrl: np.ndarray) -> np.ndarray:
    """(m, 4, 4) the flange poses the controller of ``calibration`` computes for controller
    axes ``q_ctrl`` (m, n), rad, its base frame, m."""
    robot = calibration.robot
    return controller_chain(calibration).flange(robot.joints_from_controller(
        np.atleast_2d(np.asarray(q_ctrl, dtype=float))))


__all__ = ["ControllerFit", "fit_controller", "fit_chain", "controller_chain",
           "controller_poses", "is_controller_model", "CONTROLLER_FLANGE"]
