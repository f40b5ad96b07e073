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
