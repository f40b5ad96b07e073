"""A calibrated arm as a D-H table, for controllers and tools that take only D-H.

The geometry converts exactly (:func:`~olp_compensate.kinematics.dh_table.dh_from_chain`:
each row from the identified joint axes). What a D-H table cannot hold is everything else
the calibration knows: joint effects (compliance, gear error, scale...) and a flange off the
plane D-H allows. :func:`export_dh` therefore fits the table's 24 values to the calibrated
arm (effects included, no payload) over the joint ranges, starting from the exact geometry,
and states what is left: the distance between the table's flange and the calibrated arm's
at random poses the fit never saw, mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..errors import ModelError
from ..kinematics.conventions import rotvec_from_rotation
from ..kinematics.dh_table import DHFit, DHTable, dh_from_chain
from ..kinematics.model import fixed_chain
from .calibration import Calibration
from .effects import geometry_effects, joint_effects
from .simulate import random_joints

ROTATION_WEIGHT_M = 0.1
"""m per rad: an orientation error counts as the position error it makes 100 mm out."""


@dataclass(frozen=True)
class DHExport:
    """``table`` to write; ``exact`` the geometry's exact table (and what its flange row
    cannot hold); ``rms_mm``/``max_mm``/``max_deg``: the table's flange against the
    calibrated arm's at ``poses`` random poses within the axis ranges; ``fitted``: whether
    the table was fitted to the arm's effects (it has some)."""

    table: DHTable
    exact: DHFit
    rms_mm: float
    max_mm: float
    max_deg: float
    poses: int
    fitted: bool


def _residuals(table: DHTable, q_urdf: np.ndarray, target: np.ndarray) -> np.ndarray:
    flange = table.chain().flange(q_urdf)
    turn = rotvec_from_rotation(np.swapaxes(target[:, :3, :3], 1, 2) @ flange[:, :3, :3])
    return np.concatenate([(flange[:, :3, 3] - target[:, :3, 3]).ravel(),
                           ROTATION_WEIGHT_M * turn.ravel()])


def _table(x: np.ndarray) -> DHTable:
    return DHTable(x[0:6], x[6:12], x[12:18], x[18:24])


def export_dh(calibration: Calibration, reference: DHTable | None = None, poses: int = 1000,
              seed: int = 0) -> DHExport:
    """The D-H table of the calibrated arm (module docstring); ``reference`` chooses the
    signs as in :func:`~olp_compensate.kinematics.dh_table.dh_from_chain`."""
    robot = calibration.robot
    chain = fixed_chain(calibration.model, calibration.values)
    if chain is None:
        raise ModelError(f"{robot.name}: a D-H table needs a 6R arm")
    exact = dh_from_chain(chain, reference)
    rng = np.random.default_rng(seed)
    table, fitted = exact.table, False
    if joint_effects(calibration.effects) or geometry_effects(calibration.effects):
        q_fit = random_joints(robot, 250, rng)
        target = calibration.flange_poses(q_fit)
        q_urdf = robot.joints_from_controller(q_fit)
        x0 = np.concatenate([exact.table.theta, exact.table.d, exact.table.a,
                             exact.table.alpha])
        result = least_squares(lambda x: _residuals(_table(x), q_urdf, target), x0,
                               x_scale="jac", xtol=1e-14, ftol=1e-14, gtol=1e-14)
        table, fitted = _table(result.x), True
    q_check = random_joints(robot, poses, rng)
    truth = calibration.flange_poses(q_check)
    flange = table.chain().flange(robot.joints_from_controller(q_check))
    distance = np.linalg.norm(flange[:, :3, 3] - truth[:, :3, 3], axis=1) * 1e3
    turn = np.linalg.norm(rotvec_from_rotation(
        np.swapaxes(truth[:, :3, :3], 1, 2) @ flange[:, :3, :3]), axis=1)
    return DHExport(table=table, exact=exact, rms_mm=float(np.sqrt(np.mean(distance ** 2))),
                    max_mm=float(distance.max()), max_deg=float(np.degrees(turn.max())),
                    poses=poses, fitted=fitted)
