"""Conventions shared by the whole package, and the conversions between them.

- A *pose* is a homogeneous transform, a float array of shape ``(..., 4, 4)``, translation
  in metres. Names carry the frames: ``base_T_flange`` maps flange coordinates to base
  coordinates.
- Rotations are ``(..., 3, 3)`` arrays. Quaternions are **w first**: ``(w, x, y, z)``, as in
  ABB RAPID; they are normalized on the way in, so RAPID's unnormalized or integer
  quaternions are accepted.
- V+ (Adept/Staubli) orientations are Euler Z-Y-Z angles ``(yaw, pitch, roll)``:
  ``R = Rz(yaw) Ry(pitch) Rz(roll)`` (rotations about the moving axes), given in degrees in
  the files and handled in radians here.
- Inside the package: SI units (m, rad), 0-based joints. At the edges each format keeps its
  own units (RAPID and CSV in mm and degrees) and users count joints from 1.
"""

from __future__ import annotations

import numpy as np

from ..errors import DataError

MM = 1e-3
"""One millimetre in metres."""


def rot_x(angle):
    """Rotation matrices about x, shape ``(..., 3, 3)``, for angles in radians."""
    c, s = np.cos(angle), np.sin(angle)
    o, z = np.ones_like(c), np.zeros_like(c)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1),
                     np.stack([z, s, c], -1)], -2)


def rot_y(angle):
    """Rotation matrices about y, shape ``(..., 3, 3)``, for angles in radians."""
    c, s = np.cos(angle), np.sin(angle)
    o, z = np.ones_like(c), np.zeros_like(c)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1),
                     np.stack([-s, z, c], -1)], -2)


def rot_z(angle):
    """Rotation matrices about z, shape ``(..., 3, 3)``, for angles in radians."""
    c, s = np.cos(angle), np.sin(angle)
    o, z = np.ones_like(c), np.zeros_like(c)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1),
                     np.stack([z, z, o], -1)], -2)


def pose_from_rotation_translation(rotation, translation):
    """Poses ``(..., 4, 4)`` from rotations ``(..., 3, 3)`` and translations ``(..., 3)`` (m)."""
    rotation = np.asarray(rotation, dtype=float)
    translation = np.asarray(translation, dtype=float)
    shape = np.broadcast_shapes(rotation.shape[:-2], translation.shape[:-1])
    pose = np.zeros(shape + (4, 4))
    pose[..., :3, :3] = rotation
    pose[..., :3, 3] = translation
    pose[..., 3, 3] = 1.0
    return pose


def invert_pose(pose):
    """Inverse of rigid transforms ``(..., 4, 4)``, without a general matrix inverse."""
    pose = np.asarray(pose, dtype=float)
    rotation_t = np.swapaxes(pose[..., :3, :3], -1, -2)
    return pose_from_rotation_translation(
        rotation_t, -np.einsum("...ij,...j->...i", rotation_t, pose[..., :3, 3]))


def matrix_from_quat_wxyz(quat):
    """Rotation matrices ``(..., 3, 3)`` from quaternions ``(..., 4)`` in (w, x, y, z) order.

    The quaternions are normalized first; a zero quaternion raises :class:`DataError`.
    """
    quat = np.asarray(quat, dtype=float)
    norm = np.linalg.norm(quat, axis=-1, keepdims=True)
    if np.any(norm < 1e-12):
        raise DataError("quaternion of zero length cannot describe an orientation")
    w, x, y, z = np.moveaxis(quat / norm, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def quat_wxyz_from_matrix(rotation):
    """Unit quaternions ``(..., 4)``, (w, x, y, z), w >= 0, from rotations ``(..., 3, 3)``.

    Uses the numerically stable branch (largest diagonal term) for every input.
    """
    r = np.asarray(rotation, dtype=float)
    batch = r.shape[:-2]
    r = r.reshape(-1, 3, 3)
    trace = np.trace(r, axis1=1, axis2=2)
    diag = np.stack([trace, r[:, 0, 0], r[:, 1, 1], r[:, 2, 2]], axis=1)
    choice = np.argmax(diag, axis=1)
    quat = np.empty((len(r), 4))
    for k in range(4):
        sel = choice == k
        if not np.any(sel):
            continue
        m = r[sel]
        if k == 0:
            s = 2.0 * np.sqrt(1.0 + trace[sel])
            q = [0.25 * s, (m[:, 2, 1] - m[:, 1, 2]) / s, (m[:, 0, 2] - m[:, 2, 0]) / s,
                 (m[:, 1, 0] - m[:, 0, 1]) / s]
        elif k == 1:
            s = 2.0 * np.sqrt(1.0 + m[:, 0, 0] - m[:, 1, 1] - m[:, 2, 2])
            q = [(m[:, 2, 1] - m[:, 1, 2]) / s, 0.25 * s, (m[:, 0, 1] + m[:, 1, 0]) / s,
                 (m[:, 0, 2] + m[:, 2, 0]) / s]
        elif k == 2:
            s = 2.0 * np.sqrt(1.0 + m[:, 1, 1] - m[:, 0, 0] - m[:, 2, 2])
            q = [(m[:, 0, 2] - m[:, 2, 0]) / s, (m[:, 0, 1] + m[:, 1, 0]) / s, 0.25 * s,
                 (m[:, 1, 2] + m[:, 2, 1]) / s]
        else:
            s = 2.0 * np.sqrt(1.0 + m[:, 2, 2] - m[:, 0, 0] - m[:, 1, 1])
            q = [(m[:, 1, 0] - m[:, 0, 1]) / s, (m[:, 0, 2] + m[:, 2, 0]) / s,
                 (m[:, 1, 2] + m[:, 2, 1]) / s, 0.25 * s]
        quat[sel] = np.stack(q, axis=1)
    quat *= np.where(quat[:, :1] < 0, -1.0, 1.0)
    return quat.reshape(batch + (4,))


def matrix_from_euler_zyz(yaw, pitch, roll):
    """Rotation matrices for V+ Euler angles (radians): ``Rz(yaw) Ry(pitch) Rz(roll)``."""
    return rot_z(yaw) @ rot_y(pitch) @ rot_z(roll)


def euler_zyz_from_matrix(rotation):
    """V+ Euler angles ``(yaw, pitch, roll)`` in radians, each ``(...)``, from rotations.

    ``pitch`` is in [0, pi]. At pitch = 0 or pi (gimbal lock) only yaw +/- roll is defined;
    roll is then set to 0 and yaw carries the whole rotation about z.
    """
    r = np.asarray(rotation, dtype=float)
    pitch = np.arctan2(np.hypot(r[..., 2, 0], r[..., 2, 1]), r[..., 2, 2])
    yaw = np.arctan2(r[..., 1, 2], r[..., 0, 2])
    roll = np.arctan2(r[..., 2, 1], -r[..., 2, 0])
    locked = np.sin(pitch) < 1e-9
    if np.any(locked):
        yaw_locked = np.where(r[..., 2, 2] > 0, np.arctan2(r[..., 1, 0], r[..., 0, 0]),
                              np.arctan2(-r[..., 1, 0], -r[..., 0, 0]))
        yaw = np.where(locked, yaw_locked, yaw)
        roll = np.where(locked, 0.0, roll)
    return yaw, pitch, roll


def skew(v):
    """Skew-symmetric matrices ``(..., 3, 3)`` with ``skew(v) @ w == cross(v, w)``."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape[:-1] + (3, 3))  # filled in place: four np.stack cost 4x more
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    out[..., 0, 1], out[..., 0, 2] = -w, y
    out[..., 1, 0], out[..., 1, 2] = w, -x
    out[..., 2, 0], out[..., 2, 1] = -y, x
    return out


def rotation_from_rotvec(rotvec):
    """Rotation matrices ``(..., 3, 3)`` from rotation vectors ``(..., 3)`` (axis * angle, rad)."""
    rotvec = np.asarray(rotvec, dtype=float)
    angle = np.linalg.norm(rotvec, axis=-1)[..., None, None]
    k = skew(rotvec)
    small = angle < 1e-8
    safe = np.where(small, 1.0, angle)
    a = np.where(small, 1.0 - angle**2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - angle**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    return np.eye(3) + a * k + b * (k @ k)


def rotvec_from_rotation(rotation):
    """Rotation vectors ``(..., 3)`` (rad) from rotation matrices ``(..., 3, 3)``."""
    quat = quat_wxyz_from_matrix(rotation)
    w = np.clip(quat[..., 0], -1.0, 1.0)
    xyz = quat[..., 1:]
    sin_half = np.linalg.norm(xyz, axis=-1)
    angle = 2.0 * np.arctan2(sin_half, w)
    scale = np.where(sin_half < 1e-12, 2.0, angle / np.where(sin_half < 1e-12, 1.0, sin_half))
    return xyz * scale[..., None]


def rotation_angle_between(rotation_a, rotation_b):
    """Angle (rad) of the rotation taking ``rotation_a`` to ``rotation_b``, shape ``(...)``."""
    rel = np.swapaxes(rotation_a, -1, -2) @ rotation_b
    cos = np.clip((np.trace(rel, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    return np.arccos(cos)


def matrix_from_euler_zyx(a, b, c):
    """Rotation matrices for KUKA ``A, B, C`` (radians): about z by A, then the new y by B,
    then the new x by C: ``Rz(A) Ry(B) Rx(C)``. FANUC's ``W, P, R`` (about the fixed x, y,
    z axes, in that order) give the same matrix as ``(A, B, C) = (R, P, W)``."""
    return rot_z(a) @ rot_y(b) @ rot_x(c)


def euler_zyx_from_matrix(rotation, reference=None):
    """KUKA ``(A, B, C)`` in radians from a rotation ``(3, 3)``, B in [-pi/2, pi/2].

    Two angle triples give each rotation (B and pi - B); with ``reference`` (3,) rad the
    triple nearest to it (each angle taken modulo 2 pi) is returned. At B = +-pi/2
    (gimbal lock) only A -+ C is defined: A is kept at the reference's (or 0)."""
    r = np.asarray(rotation, dtype=float)
    ref = np.zeros(3) if reference is None else np.asarray(reference, dtype=float)
    cb = np.hypot(r[0, 0], r[1, 0])
    if cb < 1e-9:
        a = ref[0]
        if r[2, 0] < 0:          # B = +90 deg: R = Rz(A - C) ... about the same axis
            b = np.pi / 2
            c = a - np.arctan2(-r[0, 1], r[1, 1])
        else:
            b = -np.pi / 2
            c = np.arctan2(-r[0, 1], r[1, 1]) - a
        candidates = [np.array([a, b, c])]
    else:
        a = np.arctan2(r[1, 0], r[0, 0])
        b = np.arctan2(-r[2, 0], cb)
        c = np.arctan2(r[2, 1], r[2, 2])
        candidates = [np.array([a, b, c]), np.array([a + np.pi, np.pi - b, c + np.pi])]
    best = None
    for cand in candidates:
        near = ref + np.remainder(cand - ref + np.pi, 2 * np.pi) - np.pi
        dist = np.sum((near - ref) ** 2)
        if best is None or dist < best[0]:
            best = (dist, near)
    return best[1]


def matrix_from_euler_xyz(rx, ry, rz):
    """Rotation matrices for Staubli VAL3 ``rx, ry, rz`` (radians): about x by rx, then the
    new y by ry, then the new z by rz: ``Rx(rx) Ry(ry) Rz(rz)``."""
    return rot_x(rx) @ rot_y(ry) @ rot_z(rz)


def euler_xyz_from_matrix(rotation, reference=None):
    """VAL3 ``(rx, ry, rz)`` in radians from a rotation ``(3, 3)``; the triple nearest
    ``reference`` (rad) of the two that give it (see :func:`euler_zyx_from_matrix`)."""
    r = np.asarray(rotation, dtype=float)
    # Rx Ry Rz = (Rz^T Ry^T Rx^T)^T: the transpose read as z-y-x angles, negated
    ref = None if reference is None else -np.asarray(reference, dtype=float)[::-1]
    zyx = euler_zyx_from_matrix(r.T, ref)
    return -zyx[::-1]
