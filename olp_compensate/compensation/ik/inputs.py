"""Checks of the arrays the IK takes (poses, joints, limits, confdata), and angle wrapping.

Each check names the argument and says which shape and unit it expected; bad input is a
:class:`~olp_compensate.errors.DataError`.
"""

from __future__ import annotations

import numpy as np

from ...errors import DataError


TWO_PI = 2.0 * np.pi


def as_poses(value, name):
    """``value`` as finite poses ``(m, 4, 4)`` (a single (4, 4) pose gives m = 1)."""
    arr = np.asarray(value, dtype=float)
    if arr.shape == (4, 4):
        arr = arr[None]
    if arr.ndim != 3 or arr.shape[1:] != (4, 4):
        raise DataError(f"{name} must be poses of shape (m, 4, 4), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise DataError(f"{name} contains NaN or infinite values")
    return arr


def as_joints(value, n, name, allow_nan=False):
    """``value`` as joints ``(m, n)`` rad (``n`` None: any); finite unless ``allow_nan``."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 1:
        arr = arr[None]
    if arr.ndim != 2 or (n is not None and arr.shape[1] != n):
        want = f"(m, {n})" if n is not None else "(m, n)"
        raise DataError(f"{name} must be joint values of shape {want} in rad, "
                        f"got shape {arr.shape}")
    if not allow_nan and not np.all(np.isfinite(arr)):
        raise DataError(f"{name} contains NaN or infinite values")
    return arr


def as_limits(limits, n):
    """``limits`` as ``(n, 2)`` rad (lower, upper) per joint, or None."""
    if limits is None:
        return None
    arr = np.asarray(limits, dtype=float)
    if arr.shape != (n, 2):
        raise DataError(f"limits must be (lower, upper) per joint, shape ({n}, 2) in rad, "
                        f"got shape {arr.shape}")
    if np.any(arr[:, 0] > arr[:, 1]):
        raise DataError(f"limits have a lower bound above the upper bound: {arr.tolist()}")
    return arr


def wrap(angle):
    """Angles wrapped to (-pi, pi]."""
    return np.pi - np.mod(np.pi - angle, TWO_PI)


def as_confdata(confdata, m):
    """``confdata`` as ``(m, 4)`` int (cf1, cf4, cf6, cfx) with cfx in 0..7."""
    arr = np.asarray(confdata)
    if arr.ndim == 1:
        arr = arr[None]
    if arr.shape != (m, 4) or not np.all(np.equal(np.mod(arr, 1), 0)):
        raise DataError(f"confdata must be integers (cf1, cf4, cf6, cfx) of shape ({m}, 4), "
                        f"got shape {arr.shape}")
    arr = arr.astype(int)
    if np.any((arr[:, 3] < 0) | (arr[:, 3] > 7)):
        raise DataError(f"cfx must be in 0..7, got {sorted(set(arr[:, 3].tolist()))}")
    return arr
