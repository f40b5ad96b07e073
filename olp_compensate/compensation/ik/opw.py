"""Closed-form forward and inverse kinematics of OPW arms (ortho-parallel base, spherical
wrist: ABB, KUKA, FANUC, Staubli, PUMA...), after M. Brandstoetter, A. Angerer, M. Hofbaur,
"An analytical solution of the inverse kinematics problem of industrial serial manipulators
with an ortho-parallel basis and a spherical wrist", Austrian Robotics Workshop 2014.

Poses ``(m, 4, 4)`` in m, base frame; joints ``(m, 6)`` rad, controller convention.
"""

from __future__ import annotations

import numpy as np

from ...kinematics.conventions import pose_from_rotation_translation, rot_y, rot_z
from .families import WRIST_EPS, OPWParameters, all_branches, clipped_acos
from .inputs import as_joints, as_poses


def _opw_tip(params, theta):
    """Tip frames ``(m, 4, 4)`` in the root frame for model angles ``theta (m, 6)``."""
    t1, t2, t3, t4, t5, t6 = np.moveaxis(theta, -1, 0)
    psi3 = np.arctan2(params.a2, params.c3)
    k = np.hypot(params.a2, params.c3)
    cx1 = params.c2 * np.sin(t2) + k * np.sin(t2 + t3 + psi3) + params.a1
    cz1 = params.c2 * np.cos(t2) + k * np.cos(t2 + t3 + psi3)
    c1, s1 = np.cos(t1), np.sin(t1)
    centre = np.stack([cx1 * c1 - params.b * s1, cx1 * s1 + params.b * c1, cz1 + params.c1], -1)
    rotation = rot_z(t1) @ rot_y(t2 + t3) @ rot_z(t4) @ rot_y(t5) @ rot_z(t6)
    position = centre + params.c4 * rotation[..., :, 2]
    return pose_from_rotation_translation(rotation, position)


def opw_forward(params: OPWParameters, q) -> np.ndarray:
    """Flange poses ``base_T_flange (m, 4, 4)`` (m) for joints ``q (m, 6)`` (rad)."""
    q = as_joints(q, 6, "q")
    return params._to_base(_opw_tip(params, params.model_angles(q)))


def opw_branch(params, root_T_tip, branch, clip):
    """Model angles ``(k, 6)`` of one branch per row (``branch (k,)`` in 0..7) for tip poses
    in the root frame; NaN where unreachable. ``clip``: out-of-reach targets get the
    stretched arm instead of NaN."""
    behind, elbow, negative = branch >= 4, (branch // 2) % 2 == 1, branch % 2 == 1
    M = np.ascontiguousarray(root_T_tip[:, :3, :].transpose(1, 2, 0))    # (3, 4, k)
    R = M[:, :3]                                                        # R[i, j]: (k,)
    cx, cy, cz = M[:, 3] - params.c4 * R[:, 2]
    a1, a2, b, c1, c2, c3 = params.a1, params.a2, params.b, params.c1, params.c2, params.c3
    kappa_2 = a2 * a2 + c3 * c3
    psi3 = np.arctan2(a2, c3)
    with np.errstate(invalid="ignore", divide="ignore"):
        radial2 = cx * cx + cy * cy - b * b
        nx1 = np.sqrt(np.maximum(radial2, 0.0) if clip else radial2) - a1
        tmp1, tmp2 = np.arctan2(cy, cx), np.arctan2(b, nx1 + a1)
        theta1 = np.where(behind, tmp1 + tmp2 - np.pi, tmp1 - tmp2)
        # wrist centre in the arm plane, relative to axis 2 (behind: the arm turned round)
        forward = np.where(behind, nx1 + 2 * a1, nx1)
        dz = cz - c1
        s_2 = forward * forward + dz * dz
        phi = np.where(behind, -1.0, 1.0) * np.arctan2(forward, dz)
        g2 = clipped_acos((s_2 + c2 * c2 - kappa_2) / (2 * np.sqrt(s_2) * c2), clip)
        g3 = clipped_acos((s_2 - c2 * c2 - kappa_2) / (2 * c2 * np.sqrt(kappa_2)), clip)
    side = np.where(elbow, -1.0, 1.0)          # +1: wrist centre in front of the lower arm
    theta2 = phi - side * g2
    theta3 = side * g3 - psi3
    # rows of r = (Rz(theta1) Ry(theta2 + theta3))^T rotation, entry by entry
    s1, c1_ = np.sin(theta1), np.cos(theta1)
    t23 = theta2 + theta3
    s23, c23 = np.sin(t23), np.cos(t23)
    along = c1_ * R[0] + s1 * R[1]                                      # (3, k)
    across = c1_ * R[1] - s1 * R[0]
    r2 = s23 * along + c23 * R[2]
    theta4, theta5, theta6 = _spherical_wrist(
        c23 * along - s23 * R[2], across, r2, -params.offsets[3], params.signs[4], negative)
    theta = np.stack([theta1, theta2, theta3, theta4, theta5, theta6], 1)
    theta[np.any(np.isnan(theta), axis=1)] = np.nan
    return theta


def _spherical_wrist(r0, r1, r2, free4, sign5, negative):
    """Wrist angles (theta4, theta5, theta6), each ``(k,)``, of ``r = Rz(t4) Ry(t5) Rz(t6)``
    given by its rows ``r0, r1, r2 (3, k)`` (entry j of all k rows in ``r0[j]``): with
    ``sign5 * sin(t5) >= 0`` (positive wrist), or the flipped wrist where ``negative``. At a
    singular wrist t4 = ``free4``."""
    horizontal = np.hypot(r0[2], r1[2])
    t5 = np.arctan2(horizontal, r2[2])
    t4 = np.arctan2(r1[2], r0[2])
    t6 = np.arctan2(r2[1], -r2[0])
    singular = horizontal < WRIST_EPS
    if np.any(singular):
        upright = r2[2] > 0
        t6_up = np.arctan2(r1[0], r0[0]) - free4
        t6_down = free4 - np.arctan2(-r1[0], -r0[0])
        t4 = np.where(singular, free4, t4)
        t6 = np.where(singular, np.where(upright, t6_up, t6_down), t6)
    flip = negative if sign5 > 0 else ~negative
    return (np.where(flip, t4 + np.pi, t4), np.where(flip, -t5, t5),
            np.where(flip, t6 + np.pi, t6))


def opw_inverse(params: OPWParameters, base_T_flange) -> np.ndarray:
    """All 8 joint solutions ``(m, 8, 6)`` (rad, in (-pi, pi]) for flange poses ``(m, 4, 4)``.

    Branch ``k`` has configuration number ``k`` (ABB cfx, see :func:`configuration_bits`);
    unreachable branches are NaN. At a singular wrist, axis 4 is set to 0.
    """
    return all_branches(opw_branch, params, as_poses(base_T_flange, "base_T_flange"), False)
