"""Rigid registration of the measuring device's frame (the device may stand anywhere).

Horn/Kabsch fits ``device_T_base`` to point pairs; :func:`register_device` alternates it with
a linear solve of the tool points, so the fit starts right even when the measured point sits
far from the flange and the device is rotated by any angle.
"""

from __future__ import annotations

import numpy as np


def kabsch(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The rigid transform (4, 4) minimizing |T source - target|, points (m, 3)."""
    cs, ct = source.mean(axis=0), target.mean(axis=0)
    h = (source - cs).T @ (target - ct)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
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
    rot, origin = flange[:, :3, :3], flange[:, :3, 3]
    tools = np.zeros((n_points, 3))
    linear = _linear_start(rot, origin, measured, point_index, n_points)
    if linear is not None:
        tools = linear
    device_T_base = np.eye(4)
    for _ in range(iterations):
        predicted = origin + np.einsum("mij,mj->mi", rot, tools[point_index])
        device_T_base = kabsch(predicted, measured)
        in_base = (measured - device_T_base[:3, 3]) @ device_T_base[:3, :3]
        local = np.einsum("mji,mj->mi", rot, in_base - origin)
        new_tools = np.array([local[point_index == k].mean(axis=0) for k in range(n_points)])
        if np.max(np.abs(new_tools - tools)) < 1e-9:
            tools = new_tools
            break
        tools = new_tools
    return device_T_base, tools


def _linear_start(rot, origin, measured, point_index, n_points):
    """Tool points from the linear model ``p = M o + sum_k (t_k M) r_k + c`` (M, t_k M and c
    free: 12 + 27 per point unknowns), global, no initial guess needed; None when the poses
    are too few or too alike for it."""
    m = len(measured)
    n_unknowns = 12 + 27 * n_points
    if 3 * m < 2 * n_unknowns:
        return None
    a = np.zeros((m, 3, n_unknowns))
    for i in range(3):  # row i of p depends on row i of M and of each t_k M
        a[:, i, 3 * i:3 * i + 3] = origin
        a[:, i, 9 + i] = 1.0
        for k in range(3):
            for p in range(n_points):
                col = 12 + 27 * p + 9 * k + 3 * i
                sel = point_index == p
                a[sel, i, col:col + 3] = rot[sel, :, k]
    solution, *_ = np.linalg.lstsq(a.reshape(3 * m, -1), measured.ravel(), rcond=None)
    m_est = solution[:9].reshape(3, 3)
    u, s, vt = np.linalg.svd(m_est)
    if s[-1] < 0.5 * s[0]:
        return None
    tools = np.zeros((n_points, 3))
    for p in range(n_points):
        for k in range(3):
            n_k = solution[12 + 27 * p + 9 * k:12 + 27 * p + 9 * k + 9].reshape(3, 3)
            tools[p, k] = np.trace(m_est.T @ n_k) / np.trace(m_est.T @ m_est)
    return tools
