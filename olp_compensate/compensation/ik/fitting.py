"""Which closed-form family a robot given only by its forward kinematics belongs to.

:func:`fit_family` reads the joint axes at q = 0 from finite rotations, fits the OPW or UR
geometry to them (lengths in m, offsets in rad) and accepts a fit only when the family's
forward kinematics matches the robot's to 1e-9 m and 1e-9 rad.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from ...errors import ModelError
from ...kinematics.model import spread_joints
from ...kinematics.conventions import (invert_pose, pose_from_rotation_translation, rot_y, rot_z,
                                       rotvec_from_rotation)
from .families import OPWParameters, URParameters
from .inputs import as_poses, wrap
from .opw import opw_forward
from .residuals import pose_error
from .ur import ur_forward


_FIT_ANGLE = 0.7          # rad, the finite rotation used to read each joint axis
_STRUCTURE_TOL = 1e-7     # m or rad: how far from the family's geometry a fit may start
_FOLD_TOL = 1e-9          # flange frame folded into c4 / d6 and the axis-6 offset below this
_VERIFY_TOL = 1e-9        # m and rad: acceptance of a fitted family


def _read_axes(flange_pose, n):
    """Joint axes at q = 0 in the base frame: directions (n, 3), points (n, 3), and M (4, 4)."""
    q = np.zeros((n + 1, n))
    q[1:] = np.eye(n) * _FIT_ANGLE
    poses = as_poses(flange_pose(q), "flange_pose(q)")
    if len(poses) != n + 1:
        raise ModelError(f"flange_pose returned {len(poses)} poses for {n + 1} joint vectors")
    M = poses[0]
    G = poses[1:] @ invert_pose(M)
    w = rotvec_from_rotation(G[:, :3, :3])
    if np.any(np.abs(np.linalg.norm(w, axis=1) - _FIT_ANGLE) > _STRUCTURE_TOL):
        return None                                              # not a unit-gain revolute
    directions = w / _FIT_ANGLE
    points = np.empty((n, 3))
    for i in range(n):
        A = np.eye(3) - G[i, :3, :3]
        points[i] = np.linalg.lstsq(A, G[i, :3, 3], rcond=1e-9)[0]
        if np.linalg.norm(A @ points[i] - G[i, :3, 3]) > _STRUCTURE_TOL:
            return None                                          # a screw, not a rotation
    return directions, points, M


def _closest_point(points, directions):
    """Point nearest to all lines (least squares) and the largest distance to them."""
    P = np.eye(3) - directions[:, :, None] * directions[:, None, :]
    A, rhs = P.sum(0), np.einsum("kij,kj->i", P, points)
    if np.linalg.svd(A, compute_uv=False)[-1] < 1e-6:
        return None, np.inf
    x = np.linalg.solve(A, rhs)
    dist = np.linalg.norm(np.einsum("kij,kj->ki", P, x - points), axis=1)
    return x, dist.max()


def _root_frame(direction1, point1):
    """Root frame: z along axis 1, origin on it nearest the base origin, x from base x."""
    z = direction1
    x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    if np.linalg.norm(x) < 1e-6:
        x = np.array([0.0, 1.0, 0.0]) - z[1] * z
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z], 1)
    return pose_from_rotation_translation(R, point1)


def _tidy_length(value):
    """Round fitted lengths to 1e-12 m: fit noise of ~1e-16 m would only clutter a repr."""
    return float(np.round(value, 12)) + 0.0


def _tidy_angles(angles):
    """Wrap to (-pi, pi] and snap to multiples of pi/2 within 1e-12 rad."""
    angles = wrap(np.asarray(angles, dtype=float))
    snapped = np.round(angles / (np.pi / 2)) * (np.pi / 2)
    return tuple(float(v) + 0.0 for v in np.where(np.abs(angles - snapped) < 1e-12,
                                                   wrap(snapped), angles))


def _is_identity(T):
    """Whether the (4, 4) pose ``T`` is the identity to 1e-14."""
    return np.allclose(T, np.eye(4), rtol=0.0, atol=1e-14)


def _fold_tip(tip_T_flange):
    """(along-z offset, rotation about z) if the flange lies on the tip z axis, else None."""
    R, t = tip_T_flange[:3, :3], tip_T_flange[:3, 3]
    if abs(R[2, 2] - 1.0) < _FOLD_TOL and np.hypot(t[0], t[1]) < _FOLD_TOL:
        return t[2], np.arctan2(R[1, 0], R[0, 0])
    return None


class _RootAxes(NamedTuple):
    """Joint axes at q = 0 in the root frame (:func:`_root_frame` in the base frame):
    ``root (4, 4)``, directions ``w (6, 3)``, points ``p (6, 3)`` m, ``flange (4, 4)``."""

    root: np.ndarray
    w: np.ndarray
    p: np.ndarray
    flange: np.ndarray


def _in_root_frame(directions, points, M):
    """:class:`_RootAxes` of the axes read at q = 0 (base frame) and the flange pose M."""
    root = _root_frame(directions[0], points[0])
    root_inv = invert_pose(root)
    return _RootAxes(root=root, w=directions @ root_inv[:3, :3].T,
                     p=points @ root_inv[:3, :3].T + root_inv[:3, 3], flange=root_inv @ M)


def _axis6_signs(flange_z, axis6):
    """Signs of axis 6 to try: the one along the flange z when they are parallel."""
    if abs(abs(flange_z @ axis6) - 1.0) < _FOLD_TOL:
        return (1 if flange_z @ axis6 > 0 else -1,)
    return (1, -1)


def _in_plane(point, origin1, x1, y1):
    """Coordinates (2,) m of ``point`` in the arm plane (origin and axes x1, y1 of frame 1)."""
    rel = point - origin1
    return np.array([rel @ x1, rel @ y1])


def _length_and_angle(vec, previous):
    """Signed DH length and joint angle (rad, relative to ``previous``) of a link vector in
    the arm plane: the sign that gives the smaller angle."""
    best = None
    for sign in (-1.0, 1.0):
        length = sign * np.linalg.norm(vec)
        angle = wrap(np.arctan2(vec[1] / length, vec[0] / length) - previous)
        if best is None or abs(angle) < abs(best[1]) - 1e-12:
            best = (length, angle)
    return best


def _fit_opw(directions, points, M):
    """OPW parameters from joint axes at q = 0 (base frame) and the flange pose M, or None.

    Frame choices: root z along axis 1 (sign1 = +1); arm x towards the front (a1 > 0);
    sign4 so that c3 > 0; sign5 so that |offset4| <= pi/2; sign6 so that the flange z is
    the tip z when it lies along axis 6 (then folded into c4 and offset6)."""
    root, w, p, flange = _in_root_frame(directions, points, M)
    centre, spread = _closest_point(p[3:], w[3:])
    if centre is None or spread > _STRUCTURE_TOL:
        return None                                              # no spherical wrist
    if (abs(w[0] @ w[1]) > _STRUCTURE_TOL or np.linalg.norm(np.cross(w[1], w[2])) > _STRUCTURE_TOL
            or abs(w[2] @ w[3]) > _STRUCTURE_TOL):
        return None
    z = np.array([0.0, 0.0, 1.0])
    # arm frame: y along axis 2, x towards the front (a1 > 0, else the wrist centre at q = 0)
    choice = None
    for sign2 in (1, -1):
        y_arm = sign2 * w[1]
        x_arm = np.cross(y_arm, z)
        a1 = p[1] @ x_arm
        key = (a1 > _STRUCTURE_TOL, abs(a1) <= _STRUCTURE_TOL and centre @ x_arm > _STRUCTURE_TOL)
        if choice is None or key > choice[0]:
            choice = (key, sign2, x_arm, y_arm, a1)
    _, sign2, x_arm, y_arm, a1 = choice
    theta1 = np.arctan2(x_arm[1], x_arm[0])
    c1 = p[1] @ z
    sign3 = 1 if w[2] @ y_arm > 0 else -1
    x3, z3 = p[2] @ x_arm, p[2] @ z
    c2 = np.hypot(x3 - a1, z3 - c1)
    theta2 = np.arctan2(x3 - a1, z3 - c1)
    b = centre @ y_arm
    dx, dz = centre @ x_arm - x3, centre @ z - z3
    best = None
    for sign4 in (1, -1):
        d4 = sign4 * w[3]
        t23 = np.arctan2(d4 @ x_arm, d4 @ z)
        a2 = dx * np.cos(t23) - dz * np.sin(t23)
        c3 = dx * np.sin(t23) + dz * np.cos(t23)
        if best is None or c3 > best[3]:
            best = (sign4, t23, a2, c3)
    sign4, t23, a2, c3 = best
    arm = np.stack([x_arm, y_arm, z], 1)
    R0c = arm @ rot_y(t23)
    best = None
    for sign5 in (1, -1):
        v = R0c.T @ (sign5 * w[4])
        t4 = np.arctan2(-v[0], v[1])
        if best is None or abs(t4) < abs(best[1]):
            best = (sign5, t4)
    sign5, t4 = best
    R04 = R0c @ rot_z(t4)
    flange_z = flange[:3, 2]
    candidates = _axis6_signs(flange_z, w[5])
    best = None
    for sign6 in candidates:
        u = R04.T @ (sign6 * w[5])
        t5 = np.arctan2(u[0], u[2])
        if best is None or abs(t5) < abs(best[1]):
            best = (sign6, t5)
    sign6, t5 = best
    tip0 = pose_from_rotation_translation(R04 @ rot_y(t5), centre)
    tip_T_flange = invert_pose(tip0) @ flange
    folded = _fold_tip(tip_T_flange)
    if folded is not None:
        c4, t6 = folded
        tip_T_flange = None
    else:
        c4, t6 = 0.0, 0.0
    theta0 = np.array([theta1, theta2, t23 - theta2, t4, t5, t6])
    a1, a2, b, c1, c2, c3, c4 = map(_tidy_length, (a1, a2, b, c1, c2, c3, c4))
    return OPWParameters(
        a1=a1, a2=a2, b=b, c1=c1, c2=c2, c3=c3, c4=c4, offsets=_tidy_angles(-theta0),
        signs=(1, sign2, sign3, sign4, sign5, sign6),
        base_T_root=None if _is_identity(root) else root, tip_T_flange=tip_T_flange)


def _line_intersection(p_a, d_a, p_b, d_b):
    """Parameter along line a of its closest point to line b, and the lines' distance."""
    n = np.cross(d_a, d_b)
    if np.linalg.norm(n) < 1e-6:
        return None, np.inf
    n /= np.linalg.norm(n)
    distance = abs((p_b - p_a) @ n)
    # solve p_a + s d_a = p_b + t d_b in least squares
    A = np.stack([d_a, -d_b], 1)
    s, _ = np.linalg.lstsq(A, p_b - p_a, rcond=1e-12)[0]
    return s, distance


def _fit_ur(directions, points, M):
    """UR (DH) parameters from joint axes at q = 0 (base frame) and the flange pose M, or
    None. Signs of a2, a3 and of axes 5, 6 are chosen for the smallest zero offsets."""
    root, w, p, flange = _in_root_frame(directions, points, M)
    z = np.array([0.0, 0.0, 1.0])
    if abs(w[0] @ w[1]) > _STRUCTURE_TOL:
        return None
    if any(np.linalg.norm(np.cross(w[1], w[i])) > _STRUCTURE_TOL for i in (2, 3)):
        return None
    z1 = w[1]                                     # sign2 = +1 by choice of theta1
    theta1 = np.arctan2(z1[0], -z1[1])
    x1 = np.array([np.cos(theta1), np.sin(theta1), 0.0])
    y1 = np.cross(z1, x1)
    d1 = p[1] @ z
    origin1 = d1 * z
    if abs((p[1] - origin1) @ x1) > _STRUCTURE_TOL:
        return None                                              # axis 2 misses axis 1
    P3, P4 = _in_plane(p[2], origin1, x1, y1), _in_plane(p[3], origin1, x1, y1)
    a2, theta2 = _length_and_angle(P3, 0.0)
    a3, theta3 = _length_and_angle(P4 - P3, theta2)
    sign3 = 1 if w[2] @ z1 > 0 else -1
    sign4 = 1 if w[3] @ z1 > 0 else -1
    t23 = theta2 + theta3
    x3 = np.cos(t23) * x1 + np.sin(t23) * y1
    y3 = np.cross(z1, x3)
    origin3 = origin1 + a2 * (np.cos(theta2) * x1 + np.sin(theta2) * y1) + a3 * x3
    d4, gap = _line_intersection(origin3, z1, p[4], w[4])
    if d4 is None or gap > _STRUCTURE_TOL:
        return None
    origin4 = origin3 + d4 * z1
    best = None
    for sign5 in (1, -1):
        z4 = sign5 * w[4]
        t4 = np.arctan2(z4 @ x3, -(z4 @ y3))
        if best is None or abs(t4) < abs(best[1]):
            best = (sign5, t4, z4)
    sign5, theta4, z4 = best
    x4 = np.cos(theta4) * x3 + np.sin(theta4) * y3
    y4 = np.cross(z4, x4)
    d5, gap = _line_intersection(origin4, z4, p[5], w[5])
    if d5 is None or gap > _STRUCTURE_TOL:
        return None
    origin5 = origin4 + d5 * z4
    flange_z = flange[:3, 2]
    candidates = _axis6_signs(flange_z, w[5])
    best = None
    for sign6 in candidates:
        z5 = sign6 * w[5]
        t5 = np.arctan2(-(z5 @ x4), z5 @ y4)
        if best is None or abs(t5) < abs(best[1]):
            best = (sign6, t5, z5)
    sign6, theta5, z5 = best
    x5 = np.cos(theta5) * x4 + np.sin(theta5) * y4
    R5 = np.stack([x5, np.cross(z5, x5), z5], 1)
    reach = (flange[:3, 3] - origin5) @ z5
    d6 = reach if abs(reach) > 1e-3 else 0.1                 # d6 must not vanish
    tip0 = pose_from_rotation_translation(R5, origin5 + d6 * z5)
    tip_T_flange = invert_pose(tip0) @ flange
    folded = _fold_tip(tip_T_flange)
    if folded is not None:
        d6, theta6 = d6 + folded[0], folded[1]
        tip_T_flange = None
    else:
        theta6 = 0.0
    theta0 = np.array([theta1, theta2, theta3, theta4, theta5, theta6])
    d1, a2, a3, d4, d5, d6 = map(_tidy_length, (d1, a2, a3, d4, d5, d6))
    return URParameters(
        d1=d1, a2=a2, a3=a3, d4=d4, d5=d5, d6=d6, offsets=_tidy_angles(-theta0),
        signs=(1, 1, sign3, sign4, sign5, sign6),
        base_T_root=None if _is_identity(root) else root, tip_T_flange=tip_T_flange)


def fit_family(flange_pose: Callable[[np.ndarray], np.ndarray], n_joints: int = 6,
               seed: int = 0) -> OPWParameters | URParameters | None:
    """Closed-form family and parameters of a robot given only its forward kinematics.

    ``flange_pose(q (m, n_joints) rad) -> base_T_flange (m, 4, 4)`` (m). The joint axes are
    read at q = 0 from finite rotations of each joint, the OPW or UR geometry is fitted to
    them, and the fit is accepted only if the family's forward kinematics matches
    ``flange_pose`` at 50 configurations spread over [-pi, pi] on every axis
    (:func:`spread_joints`, ``seed``) within 1e-9 m and 1e-9 rad. Returns None for any
    other robot.
    """
    if n_joints != 6:
        return None
    axes = _read_axes(flange_pose, n_joints)
    if axes is None:
        return None
    q = spread_joints(50, 6, seed)
    expected = as_poses(flange_pose(q), "flange_pose(q)")
    for fit, forward in ((_fit_opw, opw_forward), (_fit_ur, ur_forward)):
        try:
            params = fit(*axes)
        except (ModelError, np.linalg.LinAlgError):
            params = None
        if params is None:
            continue
        err = pose_error(expected, forward(params, q))
        if (np.max(np.linalg.norm(err[:, :3], axis=1)) <= _VERIFY_TOL
                and np.max(np.linalg.norm(err[:, 3:], axis=1)) <= _VERIFY_TOL):
            return params
    return None

