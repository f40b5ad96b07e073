"""The camera's pose in the board frame from one view, with the intrinsics fixed.

Start: the RAC on the undistorted rays (:func:`.calibrate.initial_pose`); then a 6-unknown
Levenberg-Marquardt on the reprojection error with the analytic Jacobian of
:mod:`.refine`. The result is board_T_camera, the inverse of camera_T_board: the optical
centre's position in the board frame and the camera axes' orientation there (the board is
the measuring device, the camera the measured tool).

Uncertainty from the 6x6 covariance ``sigma^2 (J^T J)^-1`` of (rotation vector, translation)
of camera_T_board, propagated to the optical centre ``c = -R^T t`` (board frame) and to a
small rotation of the camera about its own axes (``board_R_camera exp([e])``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kinematics.conventions import (invert_pose, quat_wxyz_from_matrix,
                                      rotvec_from_rotation, skew)
from ..errors import DataError
from .calibrate import CentreBias, initial_pose
from .model import CameraIntrinsics
from .refine import left_jacobian, refine_pose

BIAS_ITERATIONS = 2
"""Passes of the circle-centre correction in :func:`measure_pose`."""


@dataclass(frozen=True)
class PoseMeasurement:
    """One view's measurement.

    board_T_camera : (4, 4) m, the camera frame in the board frame. covariance : (6, 6) of
    (optical centre in the board frame, m; small rotation about the camera's axes, rad).
    residuals : (n, 2) projected minus observed px. rms_px, max_px : of the distances.
    """

    name: str
    board_T_camera: np.ndarray
    covariance: np.ndarray
    residuals: np.ndarray
    rms_px: float
    max_px: float

    @property
    def position_mm(self) -> np.ndarray:
        """Optical centre in the board frame, mm (3,)."""
        return self.board_T_camera[:3, 3] * 1e3

    @property
    def quat_wxyz(self) -> np.ndarray:
        """Camera axes in the board frame, unit quaternion (w, x, y, z), w >= 0."""
        return quat_wxyz_from_matrix(self.board_T_camera[:3, :3])

    @property
    def position_std_mm(self) -> np.ndarray:
        """Standard deviation of the position along the board's x, y, z, mm (3,)."""
        return np.sqrt(np.maximum(np.diag(self.covariance)[:3], 0.0)) * 1e3

    @property
    def rotation_std_deg(self) -> np.ndarray:
        """Standard deviation of a small rotation about the camera's x, y, z, deg (3,)."""
        return np.degrees(np.sqrt(np.maximum(np.diag(self.covariance)[3:], 0.0)))

    @property
    def sigma_mm(self) -> float:
        """One number for the position: RMS of the three axis standard deviations, mm."""
        return float(np.sqrt(np.mean(self.position_std_mm ** 2)))

    @property
    def sigma_deg(self) -> float:
        """One number for the rotation: RMS of the three axis standard deviations, deg."""
        return float(np.sqrt(np.mean(self.rotation_std_deg ** 2)))


def pose_covariance(camera_T_board: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """Covariance (6, 6) of (optical centre in the board frame m, rotation about the camera
    axes rad) from that of (rotation vector rad, translation m) of camera_T_board.

    With ``R <- exp([d]) R`` (d = J_l(w) dw, camera frame): ``c = -R^T t`` moves by
    ``-R^T dt - R^T [t]x d``, and ``R^T`` turns by ``exp(-[d])`` on its right, a rotation
    of ``-d`` about the camera's own axes.
    """
    T = np.asarray(camera_T_board, dtype=float)
    rt = T[:3, :3].T
    jl = left_jacobian(rotvec_from_rotation(T[:3, :3]))
    jac = np.zeros((6, 6))
    jac[:3, :3] = -rt @ skew(T[:3, 3]) @ jl
    jac[:3, 3:] = -rt
    jac[3:, :3] = -jl
    return jac @ covariance @ jac.T


def measure_pose(pixels: np.ndarray, points: np.ndarray, intrinsics: CameraIntrinsics, *,
                 name: str = "<view>", centre_bias: CentreBias | None = None,
                 bias_iterations: int = BIAS_ITERATIONS) -> PoseMeasurement:
    """The camera's pose in the board frame from one view.

    pixels : (n, 2) detected dot centres, column, row. points : (n, 3) the dots in the board
    frame, m. centre_bias : as in :func:`.calibrate.calibrate`; subtracted at the current
    pose, then the pose re-fitted, ``bias_iterations`` times.
    """
    pixels = np.asarray(pixels, dtype=float)
    points = np.asarray(points, dtype=float)
    if pixels.ndim != 2 or pixels.shape[1] != 2 or points.shape != (len(pixels), 3):
        raise DataError(f"{name}: expected pixels (n, 2) and points (n, 3), got "
                        f"{pixels.shape} and {points.shape}")
    if len(pixels) < 8 or not np.all(np.isfinite(pixels)):
        raise DataError(f"{name}: a pose needs at least 8 finite dot centres, got "
                        f"{int(np.sum(np.all(np.isfinite(pixels), axis=1)))}")
    fit = refine_pose(pixels, points, intrinsics, initial_pose(pixels, points, intrinsics))
    if centre_bias is not None:
        for _ in range(bias_iterations):
            corrected = pixels - centre_bias(intrinsics, fit.camera_T_board)
            fit = refine_pose(corrected, points, intrinsics, fit.camera_T_board)
    distances = np.hypot(fit.residuals[:, 0], fit.residuals[:, 1])
    return PoseMeasurement(name, invert_pose(fit.camera_T_board),
                           pose_covariance(fit.camera_T_board, fit.covariance),
                           fit.residuals, float(np.sqrt(np.mean(distances ** 2))),
                           float(np.max(distances)))
