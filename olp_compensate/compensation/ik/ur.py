"""Closed-form forward and inverse kinematics of arms with axes 2, 3, 4 parallel (Universal
Robots), after K. P. Hawkins, "Analytic inverse kinematics for the Universal Robots
UR-5/UR-10 arms", Georgia Tech, 2013.

Poses ``(m, 4, 4)`` in m, base frame; joints ``(m, 6)`` rad, controller convention.
"""

from __future__ import annotations

import numpy as np

from ...kinematics.conventions import invert_pose
from .families import WRIST_EPS, URParameters, all_branches, clipped_acos
from .inputs import as_joints, as_poses


def _dh(theta, d, a, cos_alpha, sin_alpha):
    """Standard DH transforms ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``, shape ``(..., 4, 4)``."""
    c, s = np.cos(theta), np.sin(theta)
    out = np.zeros(np.shape(theta) + (4, 4))
    out[..., 0, 0], out[..., 0, 1], out[..., 0, 2], out[..., 0, 3] = (
        c, -s * cos_alpha, s * sin_alpha, a * c)
    out[..., 1, 0], out[..., 1, 1], out[..., 1, 2], out[..., 1, 3] = (
        s, c * cos_alpha, -c * sin_alpha, a * s)
    out[..., 2, 1], out[..., 2, 2], out[..., 2, 3] = sin_alpha, cos_alpha, d
    out[..., 3, 3] = 1.0
    return out


_UR_ALPHA = ((0.0, 1.0), (1.0, 0.0), (1.0, 0.0), (0.0, 1.0), (0.0, -1.0), (1.0, 0.0))


def ur_link(params, i, theta):
    """DH transform ``(..., 4, 4)`` of link ``i`` (0-based) at model angles ``theta`` rad."""
    d = (params.d1, 0.0, 0.0, params.d4, params.d5, params.d6)[i]
    a = (0.0, params.a2, params.a3, 0.0, 0.0, 0.0)[i]
    return _dh(theta, d, a, *_UR_ALPHA[i])


def ur_frames(params, theta):
    """DH frames 1..6 in the root frame, shape ``(6, m, 4, 4)``."""
    frames = []
    T = None
    for i in range(6):
        link = ur_link(params, i, theta[..., i])
        T = link if T is None else T @ link
        frames.append(T)
    return np.stack(frames)


def ur_forward(params: URParameters, q) -> np.ndarray:
    """Flange poses ``base_T_flange (m, 4, 4)`` (m) for joints ``q (m, 6)`` (rad)."""
    q = as_joints(q, 6, "q")
    return params._to_base(ur_frames(params, params.model_angles(q))[-1])


def ur_branch(params, root_T_tip, branch, clip):
    """Model angles ``(k, 6)`` of one branch per row, as :func:`opw_branch` (Hawkins)."""
    behind, elbow, negative = branch >= 4, (branch // 2) % 2 == 1, branch % 2 == 1
    T = root_T_tip
    x_axis, y_axis, z_axis, p06 = T[:, :3, 0], T[:, :3, 1], T[:, :3, 2], T[:, :3, 3]
    p05 = p06 - params.d6 * z_axis
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.hypot(p05[:, 0], p05[:, 1])
        phi = clipped_acos(params.d4 / r, clip)
        # "+phi" puts the wrist point at p05 . x1 <= 0: in front when a2 < 0
        plus = behind if params.a2 >= 0 else ~behind
        t1 = np.arctan2(p05[:, 1], p05[:, 0]) + np.where(plus, phi, -phi) + np.pi / 2
        s1, c1 = np.sin(t1), np.cos(t1)
        t5 = clipped_acos((p06[:, 0] * s1 - p06[:, 1] * c1 - params.d4) / params.d6, clip)
        t5 = params.signs[4] * np.where(negative, -t5, t5)
        s5 = np.sin(t5)
        singular = np.abs(s5) < WRIST_EPS
        safe = np.where(singular, 1.0, s5)
        t6 = np.where(singular, -params.offsets[5],
                      np.arctan2((-y_axis[:, 0] * s1 + y_axis[:, 1] * c1) / safe,
                                 (x_axis[:, 0] * s1 - x_axis[:, 1] * c1) / safe))
        T14 = (invert_pose(ur_link(params, 0, t1)) @ T
               @ invert_pose(ur_link(params, 4, t5) @ ur_link(params, 5, t6)))
        px, py = T14[:, 0, 3], T14[:, 1, 3]
        g3 = clipped_acos((px * px + py * py - params.a2 ** 2 - params.a3 ** 2)
                   / (2 * params.a2 * params.a3), clip)
    t3 = np.where(elbow, -g3, g3)
    t2 = np.arctan2(py, px) - np.arctan2(params.a3 * np.sin(t3),
                                         params.a2 + params.a3 * np.cos(t3))
    t4 = np.arctan2(T14[:, 1, 0], T14[:, 0, 0]) - t2 - t3
    theta = np.stack([t1, t2, t3, t4, t5, t6], 1)
    theta[np.any(np.isnan(theta), axis=1)] = np.nan
    return theta


def ur_inverse(params: URParameters, base_T_flange) -> np.ndarray:
    """All 8 joint solutions ``(m, 8, 6)`` (rad, in (-pi, pi]) for flange poses ``(m, 4, 4)``.

    Branch ``k`` has configuration number ``k`` (:func:`configuration_bits`); unreachable
    branches are NaN. At a singular wrist (sin(theta5) = 0), axis 6 is set to 0.
    """
    return all_branches(ur_branch, params, as_poses(base_T_flange, "base_T_flange"), False)
