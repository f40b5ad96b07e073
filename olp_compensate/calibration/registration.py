"""Rigid registration of the measuring device's frame (the device may stand anywhere).

Horn/Kabsch fits ``device_T_base`` to point pairs; :func:`register_device` alternates it with
a linear solve of the tool points, so the fit starts right even when the measured point sits
far from the flange and the device is rotated by any angle.

The linear start needs the flange orientation to vary: when it barely changes over the poses
the columns of the flange rotation are nearly constant, the tool's regressors nearly
collinear with the constant one, and a least-squares solution splits the measured points'
offset between the two arbitrarily (a tool 24.5 m from the flange on the ASTL SURFACE
session, whose orientation is fixed up to the rounding of the joint values). The start is
then refused (:data:`LINEAR_SEPARATION`) and the tools start at zero, as for too few poses.
"""

from __future__ import annotations

import numpy as np

LINEAR_SEPARATION = 1e-3
"""The linear start is refused when the tool's regressors (the flange rotation's entries),
each scaled to unit length, keep less than this outside the span of the others (the flange
position and the constant): the smallest singular value of their part outside that span,
in [0, 1] and free of units (scaling a length scales a whole column, which the unit
scaling and the span undo). Measured: 0.058 on the ASTL POINTS session (300 poses, the
orientation varied, the wrist centre less), 0.28-0.72 on random poses of each bundled
robot (30 and 100 poses); below 3e-16 on the ASTL LINE, CURVE and SURFACE sessions
(orientation fixed). For an orientation spread of d rad it is about d, or d^2 where the
mean rotation has an entry of +-1 (a tool held straight down): 1e-3 refuses spreads below
about 0.06-2 deg, where the offset along the fixed orientation cannot be told from the
device frame's translation anyway."""


def _det3(a: np.ndarray) -> float:
    return float(a[0, 0] * (a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1])
                 - a[0, 1] * (a[1, 0] * a[2, 2] - a[1, 2] * a[2, 0])
                 + a[0, 2] * (a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]))


def kabsch(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The rigid transform (4, 4) minimizing |T source - target|, points (m, 3)."""
    cs = np.add.reduce(source, axis=0) / len(source)
    ct = np.add.reduce(target, axis=0) / len(target)
    h = (source - cs).T @ (target - ct)
    u, _, vt = np.linalg.svd(h)
    rotation = vt.T @ u.T
    if _det3(rotation) < 0:  # a reflection: turn the axis of the smallest singular value
        rotation = (vt.T * [1.0, 1.0, -1.0]) @ u.T
    pose = np.eye(4)
    pose[:3, :3] = rotation
    pose[:3, 3] = ct - rotation @ cs
    return pose


def register_device(flange: np.ndarray, measured: np.ndarray, point_index: np.ndarray,
                    n_points: int, iterations: int = 30) -> tuple[np.ndarray, np.ndarray]:
    """Initial ``device_T_base`` (4, 4) and tool points (n_points, 3), flange frame, m.

    ``flange``: (m, 4, 4) base frame poses of the flange; ``measured``: (m, 3) device frame;
    ``point_index``: (m,) which tool point each row measured.
    """
    rot, origin = np.ascontiguousarray(flange[:, :3, :3]), flange[:, :3, 3]
    tools = np.zeros((n_points, 3))
    linear = _linear_start(rot, origin, measured, point_index, n_points)
    if linear is not None:
        tools = linear
    device_T_base = np.eye(4)
    # the mean over each point's rows, as one product: (n_points, m) @ (m, 3)
    member = np.arange(n_points)[:, None] == point_index[None, :]
    average = member / member.sum(axis=1, keepdims=True)
    stacked = rot.reshape(-1, 3)  # (3m, 3): one point's rows as one matrix-vector product
    for _ in range(iterations):
        if n_points == 1:
            predicted = origin + (stacked @ tools[0]).reshape(-1, 3)
        else:
            predicted = origin + np.matmul(rot, tools[point_index][:, :, None])[:, :, 0]
        device_T_base = kabsch(predicted, measured)
        offset = (measured - device_T_base[:3, 3]) @ device_T_base[:3, :3] - origin
        if n_points == 1:  # the mean of rot^T offset over the rows
            new_tools = (offset.reshape(-1) @ stacked)[None, :] / len(offset)
        else:
            new_tools = average @ np.matmul(offset[:, None, :], rot)[:, 0]
        if np.max(np.abs(new_tools - tools)) < 1e-9:
            tools = new_tools
            break
        tools = new_tools
    return device_T_base, tools


def _linear_start(rot, origin, measured, point_index, n_points):
    """Tool points from the linear model ``p = M o + sum_k (t_k M) r_k + c`` (M, t_k M and c
    free: 12 + 27 per point unknowns), global, no initial guess needed; None when the poses
    are too few or too alike for it, or their orientations (:data:`LINEAR_SEPARATION`).

    Row i of p involves only row i of M, of c and of each t_k M, with the same regressors
    (o, 1 and the columns r_k of the flange rotation) for every i: one least-squares problem
    with m rows, 4 + 9 per point unknowns and the three coordinates as right-hand sides."""
    m = len(measured)
    n_unknowns = 12 + 27 * n_points
    if 3 * m < 2 * n_unknowns:
        return None
    a = np.zeros((m, 4 + 9 * n_points))
    a[:, :3] = origin
    a[:, 3] = 1.0
    for p in range(n_points):
        sel = point_index == p
        a[sel, 4 + 9 * p:13 + 9 * p] = rot[sel].transpose(0, 2, 1).reshape(-1, 9)  # r_0 r_1 r_2
    if _tool_separation(a) < LINEAR_SEPARATION:
        return None
    solution, *_ = np.linalg.lstsq(a, measured, rcond=None)  # (4 + 9P, 3): column i for row i
    m_est = solution[:3].T
    u, s, vt = np.linalg.svd(m_est)
    if s[-1] < 0.5 * s[0]:
        return None
    tools = np.zeros((n_points, 3))
    norm2 = np.sum(m_est * m_est)
    for p in range(n_points):
        for k in range(3):
            n_k = solution[4 + 9 * p + 3 * k:7 + 9 * p + 3 * k].T  # t_k M
            tools[p, k] = np.sum(m_est * n_k) / norm2  # trace(M^T N_k) / trace(M^T M)
    return tools


def _tool_separation(a: np.ndarray) -> float:
    """How far the tool's regressors, columns 4.. of ``a`` (m, 4 + 9P), stand out of the
    span of the first four (flange position, m, and the constant): the smallest singular
    value of their unit-length columns' part outside that span, in [0, 1]; 0 when a tool
    column is zero or a combination of the others (a rotation entry that never changes)."""
    norms = np.sqrt(np.einsum("ij,ij->j", a, a))
    if np.any(norms[4:] == 0.0):
        return 0.0
    scaled = a / np.where(norms > 0.0, norms, 1.0)
    u, s, _ = np.linalg.svd(scaled[:, :4], full_matrices=False)
    basis = u[:, s > s[0] * max(a.shape) * np.finfo(float).eps]
    rest = scaled[:, 4:] - basis @ (basis.T @ scaled[:, 4:])
    return float(np.linalg.svd(rest, compute_uv=False)[-1])
