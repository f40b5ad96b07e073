"""Frame assignment on the nominal axes (Motta 2006, sections 3-4, after Schroer).

Walking the nominal chain at its zero position, each joint axis gets a frame (z along the
axis), and the link from one frame to the next axis gets its parameter values: D-H
(theta, d, a, alpha; eq. 16) when the axes are far from parallel, Hayati (theta, a, alpha,
beta; eq. 17) when they are nearly parallel. Frames are (4, 4) homogeneous transforms in the
robot's base frame, m; axes are (point, unit direction) in the same frame; angles rad.
:func:`olp_compensate.kinematics.model.build_model` chooses between the two per link.
"""

from __future__ import annotations

import math

import numpy as np


def unit(v: np.ndarray) -> np.ndarray:
    """``v`` scaled to length 1."""
    return v / np.linalg.norm(v)


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of two 3-vectors (np.cross costs ten times more on single vectors)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def signed_angle(a: np.ndarray, b: np.ndarray, axis: np.ndarray) -> float:
    """Angle (rad) rotating direction ``a`` onto ``b`` about ``axis`` (all perpendicular)."""
    return math.atan2(float(np.dot(cross(a, b), axis)), float(np.dot(a, b)))


def dh_link(frame: np.ndarray, point: np.ndarray, direction: np.ndarray):
    """D-H values (theta, d, a, alpha) from ``frame`` (z on axis i) to the axis
    (point, direction), and the new frame on that axis."""
    origin, x0, z0 = frame[:3, 3], frame[:3, 0], frame[:3, 2]
    b = float(np.dot(z0, direction))
    w = origin - point
    denom = 1.0 - b * b
    if denom < 1e-12:  # parallel: D-H is singular here; take the foot at the current origin
        s = 0.0
    else:
        s = (b * np.dot(direction, w) - np.dot(z0, w)) / denom
    foot0 = origin + s * z0
    foot1 = point + np.dot(foot0 - point, direction) * direction
    normal = foot1 - foot0
    a = float(np.linalg.norm(normal))
    if a < 1e-9:
        common = cross(z0, direction)  # the common normal of intersecting axes
        x_new = unit(common) if np.linalg.norm(common) > 1e-9 else x0
        a = 0.0
    else:
        x_new = normal / a
    theta = signed_angle(x0, x_new, z0)
    alpha = signed_angle(z0, direction, x_new)
    new = np.eye(4)
    new[:3, 0], new[:3, 2] = x_new, direction
    new[:3, 1] = cross(direction, x_new)
    new[:3, 3] = foot1
    return (theta, float(s), a, alpha), new


def hayati_link(frame: np.ndarray, point: np.ndarray, direction: np.ndarray):
    """Hayati values (theta, a, alpha, beta) from ``frame`` to a nearly parallel axis, and the
    new frame where the plane z = 0 of ``frame`` meets that axis."""
    origin, x0, z0 = frame[:3, 3], frame[:3, 0], frame[:3, 2]
    t = np.dot(origin - point, z0) / np.dot(direction, z0)
    foot = point + t * direction
    v = foot - origin
    a = float(np.linalg.norm(v))
    x_new = v / a if a > 1e-9 else x0  # collinear axes: Hayati is singular, the SVD will say
    theta = signed_angle(x0, x_new, z0)
    y_new = cross(z0, x_new)
    u, w_, h = np.dot(direction, x_new), np.dot(direction, y_new), np.dot(direction, z0)
    beta = float(np.arcsin(np.clip(u, -1.0, 1.0)))
    alpha = float(np.arctan2(-w_, h))
    rot = np.column_stack([x_new, y_new, z0])
    ca, sa, cb, sb = np.cos(alpha), np.sin(alpha), np.cos(beta), np.sin(beta)
    rot = rot @ np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]]) @ np.array(
        [[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    new = np.eye(4)
    new[:3, :3] = rot
    new[:3, 3] = foot
    return (theta, a, alpha, beta), new


def first_frame(point: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """The first joint's frame, fixed to the base: z along axis 1 (``point``, unit
    ``direction``), origin where the axis is closest to the base origin, x from the base x
    (from the base y when axis 1 is along x)."""
    frame = np.eye(4)
    z = direction
    frame[:3, 3] = point - np.dot(point, z) * z
    x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    if np.linalg.norm(x) < 1e-6:
        x = np.array([0.0, 1.0, 0.0]) - z[1] * z
    x = unit(x)
    frame[:3, 0], frame[:3, 1], frame[:3, 2] = x, cross(z, x), z
    return frame
