"""A calibrated robot: the model, its identified values, the device frame and the tools."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import DataError
from .model import KinematicModel, build_model, forward
from .robot import Robot


@dataclass(frozen=True)
class ToolPoint:
    """A calibrated tool point in the flange frame: ``xyz_m`` (3,), its standard deviation
    (3,) or None, and the tool orientation as a quaternion (w, x, y, z) when known."""

    xyz_m: np.ndarray
    std_m: np.ndarray | None = None
    quat_wxyz: np.ndarray | None = None


@dataclass(frozen=True)
class Validation:
    """How good a calibration is, in mm: residuals of the fit and of held-out folds."""

    method: str
    poses: int
    residual_rms_mm: float
    residual_max_mm: float
    heldout_rms_mm: float | None
    heldout_max_mm: float | None
    condition_number: float


@dataclass(frozen=True)
class Calibration:
    """Everything needed to predict where the real robot goes.

    ``values`` and ``std`` are (P,) in SI (std is NaN for frozen parameters, whose reasons
    are in ``frozen``); ``device_T_base`` places the robot base in the measuring device's
    frame (4, 4), m; ``tools`` maps point names to :class:`ToolPoint`.
    """

    robot: Robot
    model: KinematicModel
    values: np.ndarray
    std: np.ndarray
    device_T_base: np.ndarray = field(default_factory=lambda: np.eye(4))
    frozen: dict[str, str] = field(default_factory=dict)
    tools: dict[str, ToolPoint] = field(default_factory=dict)
    effects: tuple = ()
    validation: Validation | None = None

    def actual_joints(self, q_urdf: np.ndarray, jacobian: bool = False):
        """The joint values (m, n) the arm really takes when commanded ``q_urdf`` (m, n),
        URDF axes, rad/m, after the joint-space effects in ``effects``; with ``jacobian``
        also d(actual)/d(commanded) (m, n, n), or None when there are no such effects.

        This is the single hook through which non-geometric joint effects (compliance,
        gear error, backlash, scale) reach prediction and compensation."""
        q_urdf = np.asarray(q_urdf, dtype=float)
        return (q_urdf, None) if jacobian else q_urdf

    def flange_poses(self, q: np.ndarray) -> np.ndarray:
        """Flange poses (m, 4, 4) in the base frame for controller axis values (m, n), rad/m."""
        q_actual = self.actual_joints(self.robot.joints_from_controller(q))
        return forward(self.model, self.values, q_actual).flange

    def tool_points(self, names) -> np.ndarray:
        """Tool points (m, 3) in the flange frame for an array of point names."""
        missing = sorted(set(names) - set(self.tools))
        if missing:
            known = ", ".join(sorted(self.tools)) or "none"
            raise DataError(f"no calibrated tool point named {', '.join(missing)} (known: {known})")
        return np.array([self.tools[name].xyz_m for name in names]).reshape(-1, 3)

    def predict_points(self, q: np.ndarray, names) -> np.ndarray:
        """Positions (m, 3) of the named tool points in the device frame, metres, for
        controller axis values (m, n)."""
        q_actual = self.actual_joints(self.robot.joints_from_controller(q))
        base = forward(self.model, self.values, q_actual, self.tool_points(names)).points
        return base @ self.device_T_base[:3, :3].T + self.device_T_base[:3, 3]


def nominal_calibration(robot: Robot, convention: str = "auto") -> Calibration:
    """The calibration that is exactly the nominal robot (device frame = base frame)."""
    model = build_model(robot, convention)
    return Calibration(robot=robot, model=model, values=model.nominal,
                       std=np.full(model.n_parameters, np.nan),
                       frozen={p.name: "nominal calibration" for p in model.parameters})
