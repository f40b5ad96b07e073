"""Pose errors between batches of poses: position (m) and rotation vector (rad), base frame."""

from __future__ import annotations

import numpy as np

from ...kinematics.conventions import rotvec_from_rotation


def pose_error(target, poses):
    """Errors ``(m, 6)``: position (m) and rotation vector (rad), both in the base frame,
    taking ``poses`` to ``target``."""
    err = np.empty((len(poses), 6))
    np.subtract(target[:, :3, 3], poses[:, :3, 3], out=err[:, :3])
    # R = Rt Rp^T = sum_k t_k p_k^T over the columns k: sin(angle) * axis = (R - R^T)^v / 2
    # = sum_k p_k x t_k / 2 and cos(angle) = (trace(R) - 1) / 2 = (sum Rt * Rp - 1) / 2.
    # Exact, and cheaper than via a quaternion, up to 90 deg (beyond: the quaternion).
    t = np.ascontiguousarray(np.moveaxis(target[:, :3, :3], 0, -1))      # (3, 3, m)
    p = np.ascontiguousarray(np.moveaxis(poses[:, :3, :3], 0, -1))
    dr = np.empty((3, len(poses)))
    np.sum(p[1] * t[2] - p[2] * t[1], axis=0, out=dr[0])
    np.sum(p[2] * t[0] - p[0] * t[2], axis=0, out=dr[1])
    np.sum(p[0] * t[1] - p[1] * t[0], axis=0, out=dr[2])
    dr *= 0.5
    cos = 0.5 * (np.sum(t * p, axis=(0, 1)) - 1.0)
    sin = np.sqrt(np.sum(dr * dr, axis=0))
    tiny = sin < 1e-12
    dr *= np.where(tiny, 1.0, np.arctan2(sin, cos) / np.where(tiny, 1.0, sin))
    err[:, 3:] = dr.T
    wide = np.flatnonzero(cos < 0.0)
    if len(wide):
        err[wide, 3:] = rotvec_from_rotation(
            target[wide, :3, :3] @ np.swapaxes(poses[wide, :3, :3], -1, -2))
    return err


def error_norms(err):
    """Position and rotation error norms ``(m,)`` of errors ``(m, 6)``."""
    return (np.sqrt(np.einsum("ij,ij->i", err[:, :3], err[:, :3])),
            np.sqrt(np.einsum("ij,ij->i", err[:, 3:], err[:, 3:])))
