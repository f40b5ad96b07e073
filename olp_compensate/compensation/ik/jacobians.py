"""Analytic geometric Jacobians of the nominal families, and the flange twist of joint steps.

Jacobians ``(m, 6, 6)``: rows flange-origin velocity then angular velocity, columns
controller joints, in the base frame (as ``fk_jacobian`` returns them); lengths in m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .families import OPWParameters
from .ur import ur_frames


def opw_jacobian(params, theta):
    """Geometric Jacobian ``(m, 6, 6)`` (root frame, at the flange origin, per model angle)
    and flange positions ``(m, 3)`` of the OPW arm."""
    arm = opw_axes(params, theta)
    z = np.zeros_like(arm.y_arm)
    z[2] = 1.0
    axes = np.stack([z, arm.y_arm, arm.y_arm, arm.col2, arm.y4, arm.z6])   # (6, 3, m)
    points = np.stack([np.zeros_like(z), arm.axis2, arm.axis3, arm.centre, arm.centre,
                       arm.centre])
    return screw_jacobian(axes, arm.flange - points), arm.flange.T


@dataclass(frozen=True)
class OPWAxes:
    """Joint axes of an OPW arm at m configurations, root frame, each ``(3, m)``: axis 1 is
    the root z through the origin; ``y_arm`` the direction of axes 2 and 3, through the
    points ``axis2`` and ``axis3``; ``col2``, ``y4``, ``z6`` the directions of axes 4, 5
    and 6, through the wrist ``centre``; ``flange`` the flange origin, m."""

    y_arm: np.ndarray
    axis2: np.ndarray
    axis3: np.ndarray
    col2: np.ndarray
    y4: np.ndarray
    z6: np.ndarray
    centre: np.ndarray
    flange: np.ndarray


def opw_axes(params, theta):
    """:class:`OPWAxes` of the OPW arm at model angles ``theta (m, 6)``."""
    t1, t2, t3, t4, t5, t6 = theta.T
    c1, s1 = np.cos(t1), np.sin(t1)
    zero = np.zeros_like(t1)
    x_arm = np.stack([c1, s1, zero])                                  # (3, m)
    y_arm = np.stack([-s1, c1, zero])
    psi3 = np.arctan2(params.a2, params.c3)
    k = np.hypot(params.a2, params.c3)
    s2, c2 = np.sin(t2), np.cos(t2)
    t23 = t2 + t3
    s23, c23 = np.sin(t23), np.cos(t23)
    sk = s23 * np.cos(psi3) + c23 * np.sin(psi3)                      # sin(t23 + psi3)
    ck = c23 * np.cos(psi3) - s23 * np.sin(psi3)
    axis2 = params.a1 * x_arm
    axis2[2] += params.c1
    axis3 = axis2 + params.c2 * s2 * x_arm
    axis3[2] += params.c2 * c2
    centre = (params.c2 * s2 + k * sk + params.a1) * x_arm + params.b * y_arm
    centre[2] += params.c2 * c2 + k * ck + params.c1
    col0 = c23 * x_arm                                                # R0c = Rz(t1) Ry(t23)
    col0[2] -= s23
    col2 = s23 * x_arm
    col2[2] += c23
    s4, c4, s5, c5 = np.sin(t4), np.cos(t4), np.sin(t5), np.cos(t5)
    x4 = c4 * col0 + s4 * y_arm                                       # R04 = R0c Rz(t4)
    y4 = c4 * y_arm - s4 * col0
    z6 = s5 * x4 + c5 * col2                                          # R05 z = R06 z
    flange = centre + params.c4 * z6
    tip = params._tip()
    if tip is not None:
        s6, c6 = np.sin(t6), np.cos(t6)
        x5 = c5 * x4 - s5 * col2
        x6, y6 = c6 * x5 + s6 * y4, c6 * y4 - s6 * x5
        flange = flange + x6 * tip[0, 3] + y6 * tip[1, 3] + z6 * tip[2, 3]
    return OPWAxes(y_arm, axis2, axis3, col2, y4, z6, centre, flange)


def screw_jacobian(axes, r):
    """``(m, 6, n)`` Jacobian with columns ``(w x r, w)`` for axes and lever arms ``(n, 3, m)``."""
    jac = np.empty((axes.shape[2], 6, axes.shape[0]))
    jac[:, 0] = (axes[:, 1] * r[:, 2] - axes[:, 2] * r[:, 1]).T
    jac[:, 1] = (axes[:, 2] * r[:, 0] - axes[:, 0] * r[:, 2]).T
    jac[:, 2] = (axes[:, 0] * r[:, 1] - axes[:, 1] * r[:, 0]).T
    jac[:, 3:] = axes.transpose(2, 1, 0)
    return jac


def ur_jacobian(params, theta):
    """As :func:`opw_jacobian`, for the UR arm (from its DH frames)."""
    frames = ur_frames(params, theta)
    tip, last = params._tip(), frames[-1]
    flange = last[:, :3, 3] if tip is None else last[:, :3, :3] @ tip[:3, 3] + last[:, :3, 3]
    axes = np.concatenate([np.broadcast_to([0.0, 0.0, 1.0], (1, len(theta), 3)),
                           frames[:5, :, :3, 2]])                     # (6, m, 3)
    points = np.concatenate([np.zeros((1, len(theta), 3)), frames[:5, :, :3, 3]])
    return (screw_jacobian(np.swapaxes(axes, 1, 2), np.swapaxes(flange - points, 1, 2)),
            flange)


def nominal_jacobian(params, q):
    """Geometric Jacobian ``(m, 6, 6)`` of the nominal family in the base frame, at the
    flange origin, per controller joint (as ``fk_jacobian`` returns it)."""
    theta = params.model_angles(q)
    jac, _ = (opw_jacobian if isinstance(params, OPWParameters) else ur_jacobian)(params,
                                                                                  theta)
    jac *= np.asarray(params.signs, dtype=float)
    base = params._base()
    if base is not None:
        jac[:, :3] = base[:3, :3] @ jac[:, :3]
        jac[:, 3:] = base[:3, :3] @ jac[:, 3:]
    return jac


def nominal_twist(params, q, dq):
    """``J_nominal(q) dq`` ``(m, 6)``: the flange twist (base frame) of joint steps
    ``dq (m, 6)`` at ``q (m, 6)`` rad, without forming the Jacobian (OPW arms): with the
    wrist's angular velocity w_w = sum of its axes times their steps,
    ``v = dq1 z x f + dq23 y_arm x (...) + w_w x (f - centre)``."""
    if not isinstance(params, OPWParameters):
        return np.einsum("kij,kj->ki", nominal_jacobian(params, q), dq)
    arm = opw_axes(params, params.model_angles(q))
    w0, w1, w2, w3, w4, w5 = (dq * np.asarray(params.signs, dtype=float)).T
    f = arm.flange
    wrist = w3 * arm.col2 + w4 * arm.y4 + w5 * arm.z6
    lever = w1 * (f - arm.axis2) + w2 * (f - arm.axis3)              # about y_arm
    r = f - arm.centre
    y = arm.y_arm
    twist = np.empty((6, len(q)))
    twist[0] = -w0 * f[1] + y[1] * lever[2] - y[2] * lever[1] + wrist[1] * r[2] - wrist[2] * r[1]
    twist[1] = w0 * f[0] + y[2] * lever[0] - y[0] * lever[2] + wrist[2] * r[0] - wrist[0] * r[2]
    twist[2] = y[0] * lever[1] - y[1] * lever[0] + wrist[0] * r[1] - wrist[1] * r[0]
    twist[3:] = (w1 + w2) * y + wrist
    twist[5] += w0
    twist = twist.T
    base = params._base()
    if base is not None:
        twist[:, :3] = twist[:, :3] @ base[:3, :3].T
        twist[:, 3:] = twist[:, 3:] @ base[:3, :3].T
    return twist


def rotation_from_rotvec(rotvec):
    """Rotation matrices ``(m, 3, 3)`` from rotation vectors ``(m, 3)`` (Rodrigues)."""
    angle = np.sqrt(np.einsum("ij,ij->i", rotvec, rotvec))
    small = angle < 1e-8
    safe = np.where(small, 1.0, angle)
    a = np.where(small, 1.0 - angle ** 2 / 6.0, np.sin(angle) / safe)
    b = np.where(small, 0.5 - angle ** 2 / 24.0, (1.0 - np.cos(angle)) / safe ** 2)
    x, y, z = rotvec.T
    R = np.empty((len(rotvec), 3, 3))
    xx, yy, zz, xy, xz, yz = x * x, y * y, z * z, x * y, x * z, y * z
    R[:, 0, 0], R[:, 1, 1], R[:, 2, 2] = 1 - b * (yy + zz), 1 - b * (xx + zz), 1 - b * (xx + yy)
    R[:, 0, 1], R[:, 1, 0] = b * xy - a * z, b * xy + a * z
    R[:, 0, 2], R[:, 2, 0] = b * xz + a * y, b * xz - a * y
    R[:, 1, 2], R[:, 2, 1] = b * yz - a * x, b * yz + a * x
    return R
