"""The written numbers of Cartesian targets as arrays, their poses, and which of them are
no target a controller accepts (zero quaternion, implausible confdata), in batches."""

from __future__ import annotations

import math
from itertools import chain

import numpy as np

from ..kinematics.conventions import (MM, matrix_from_euler_zyz, matrix_from_quat_wxyz,
                                      pose_from_rotation_translation)
from .targets import QUAT_WXYZ, CartesianTarget

CONFDATA_LIMIT = 1 << 15
"""|cf| at or above this is no configuration a controller writes (quarter turns, branch)."""


WRITTEN_COLUMNS = 11


def written_values(targets) -> np.ndarray:
    """The leading numbers of Cartesian targets as written, (n, 11), converted in one batch:
    position in mm (columns 0-2), orientation (3-6: quaternion w, x, y, z, or V+ Z-Y-Z
    degrees then NaN) and RAPID confdata cf1, cf4, cf6, cfx (7-10; NaN for V+)."""
    n = len(targets)
    out = np.full((n, WRITTEN_COLUMNS), np.nan)
    full = [i for i, t in enumerate(targets)
            if t.orientation_kind == QUAT_WXYZ and len(t.texts) >= WRITTEN_COLUMNS]
    if full:
        out[full] = np.fromiter(
            map(float, chain.from_iterable(targets[i].texts[:WRITTEN_COLUMNS] for i in full)),
            float, WRITTEN_COLUMNS * len(full)).reshape(-1, WRITTEN_COLUMNS)
    if len(full) < n:
        done = set(full)
        for i, t in enumerate(targets):
            if i not in done:
                width = 7 if t.orientation_kind == QUAT_WXYZ else 6
                out[i, :width] = [float(x) for x in t.texts[:width]]
                if width == 7 and len(t.texts) > 7:
                    config = [float(x) for x in t.texts[7:WRITTEN_COLUMNS]]
                    out[i, 7:7 + len(config)] = config
    return out


def target_poses(targets, values: np.ndarray | None = None) -> np.ndarray:
    """wobj_T_target of Cartesian targets, (n, 4, 4), metres, computed in one batch.

    values : their :func:`written_values`, when the caller has them already."""
    n = len(targets)
    poses = np.zeros((n, 4, 4))
    if n == 0:
        return poses
    v = written_values(targets) if values is None else values
    euler = np.fromiter((t.orientation_kind != QUAT_WXYZ for t in targets), bool, n)
    if not euler.all():
        quat = ~euler
        poses[quat] = pose_from_rotation_translation(matrix_from_quat_wxyz(v[quat, 3:7]),
                                                     v[quat, :3] * MM)
    if euler.any():
        a = np.deg2rad(v[euler, 3:6])
        poses[euler] = pose_from_rotation_translation(
            matrix_from_euler_zyz(a[:, 0], a[:, 1], a[:, 2]), v[euler, :3] * MM)
    return poses


def bad_values(written: np.ndarray) -> np.ndarray:
    """(m,) rows of :func:`written_values` with a zero quaternion or a confdata that is
    not a finite integer of plausible size (V+ rows: NaN confdata, never bad)."""
    quat = written[:, 3:7]
    zero = np.all(quat == 0, axis=1) & ~np.isnan(quat[:, 3])
    conf = written[:, 7:11]
    with np.errstate(invalid="ignore"):
        odd = ~np.isnan(conf) & (~np.isfinite(conf) | (np.abs(conf) >= CONFDATA_LIMIT)
                                 | (conf != np.round(conf)))
    return zero | np.any(odd, axis=1)


def value_problem(t: CartesianTarget) -> str:
    """Why the written values of robtarget ``t`` are no target (see :func:`_bad_values`)."""
    if not any(float(x) for x in t.texts[3:7]):
        return "zero quaternion [0,0,0,0]: no rotation; left as written"
    for label, written in zip(("cf1", "cf4", "cf6", "cfx"), t.texts[7:11]):
        value = float(written)
        if not math.isfinite(value) or abs(value) >= CONFDATA_LIMIT or value != int(value):
            return (f"confdata {label} = {written} is no integer configuration (|cf| < "
                    f"{CONFDATA_LIMIT}): not solved on any configuration; left as written")
    return "values no controller accepts; left as written"
