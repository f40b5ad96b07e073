"""k-fold cross-validation by pose: the model refitted without each fold, errors on it.

Every row of one pose goes to the same fold (repeated measurements of a pose never sit on
both sides); the poses are shared out at random with a fixed seed, so a data set always
gets the same folds. Rows that carry their acquisition time can also be split into
contiguous blocks of time (:func:`time_blocked_folds`): along a path, random folds put a
row's neighbours in time in the training set, so slow drift looks predictable.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .problem import IdentificationProblem
from .seeded_permutation import permutation

FOLD_SEED = 0
"""Seed of the random assignment of poses to folds."""


def pose_codes(pose_ids: np.ndarray) -> tuple[np.ndarray, int]:
    """(codes (m,), number of poses): each row's pose as an integer, the position of its
    id among the sorted distinct ids (one sort, then integer work only)."""
    unique, codes = np.unique(np.asarray(pose_ids), return_inverse=True)
    return codes.reshape(-1), len(unique)


def pose_folds(pose_ids: np.ndarray, k: int) -> list[np.ndarray]:
    """k boolean row masks (the held-out rows of each fold) that split the poses at random
    (seed ``FOLD_SEED``), every row of one pose in the same fold. Fold f holds the f-th of
    k near-equal consecutive parts of a random permutation of the sorted distinct ids."""
    codes, n_poses = pose_codes(pose_ids)
    order = permutation(FOLD_SEED, n_poses)  # numpy's default_rng's, without numpy.random
    fold_of_pose = np.empty(n_poses, dtype=int)
    for fold, part in enumerate(np.array_split(order, k)):
        fold_of_pose[part] = fold
    fold_of_row = fold_of_pose[codes]
    return [fold_of_row == fold for fold in range(k)]


def time_blocked_folds(time_s: np.ndarray | None, pose_ids: np.ndarray, k: int
                       ) -> list[np.ndarray] | None:
    """k boolean row masks, each a contiguous block of acquisition time: the poses sorted
    by their first row's ``time_s`` (s; ties by the row order) and cut into k near-equal
    consecutive parts, every row of one pose in the same fold. None without times, with
    times that do not vary, or with fewer than k poses."""
    if time_s is None:
        return None
    time_s = np.asarray(time_s, float)
    codes, n_poses = pose_codes(pose_ids)
    if n_poses < max(k, 2) or not np.all(np.isfinite(time_s)) or np.ptp(time_s) <= 0:
        return None
    first = np.full(n_poses, np.inf)
    np.minimum.at(first, codes, time_s)
    order = np.lexsort((np.arange(n_poses), first))
    fold_of_pose = np.empty(n_poses, dtype=int)
    for fold, part in enumerate(np.array_split(order, k)):
        fold_of_pose[part] = fold
    fold_of_row = fold_of_pose[codes]
    return [fold_of_row == fold for fold in range(k)]


@dataclass(frozen=True)
class HeldOut:
    """Errors of the refitted models on the rows each fit never saw: ``errors`` (m,) 3-D
    position error per row, m (NaN on rows not in use); ``rms``/``max`` over them, m;
    ``orientation_rms``/``orientation_max``: angle between measured and predicted tool
    frames, rad (None without orientation rows); ``folds``: k."""

    errors: np.ndarray
    rms: float
    max: float
    orientation_rms: float | None
    orientation_max: float | None
    folds: int


def cross_validate(problem: IdentificationProblem, x: np.ndarray, folds: list[np.ndarray],
                   subproblem: Callable[[np.ndarray, np.ndarray], IdentificationProblem],
                   refit: Callable[[IdentificationProblem, np.ndarray], np.ndarray],
                   ) -> HeldOut | None:
    """Cross-validate the fit ``x`` of ``problem`` over ``folds`` (held-out row masks).

    ``subproblem(rows, device_T_base)``: the same problem on the rows of a mask, with that
    reference registration; ``refit(problem, x0)``: the solution from x0. Each fold is
    fitted from the full-data solution. None when some training set has no more equations
    than unknowns (or with fewer than 2 folds)."""
    if len(folds) < 2:
        return None
    values, pose, tools = problem.unpack(x)
    rotations, effect_values = problem.tool_rotations(x), problem.effect_values(x)
    used = problem.row_weight > 0
    oriented = np.zeros(len(used), dtype=bool)
    oriented[problem.oriented_rows] = True
    errors = np.full(len(used), np.nan)
    held, held_angles = [], []
    for test in folds:
        train = ~test & used
        if 3 * train.sum() + 3 * (train & oriented).sum() <= problem.n_unknowns:
            return None
        sub = subproblem(train, pose)
        x_fold = refit(sub, sub.pack(values, pose, tools, effect_values, rotations))
        rows = test & used
        check = subproblem(rows, pose)
        *_, predicted = check.predict(x_fold, jacobian=False)
        held.append(np.linalg.norm(predicted - check.measured, axis=1))
        errors[rows] = held[-1]
        angles = check.orientation_angles(x_fold)
        held_angles.append(angles[np.isfinite(angles)])
    held_all, angles_all = np.concatenate(held), np.concatenate(held_angles)
    return HeldOut(
        errors=errors, rms=float(np.sqrt(np.mean(held_all**2))), max=float(held_all.max()),
        orientation_rms=float(np.sqrt(np.mean(angles_all**2))) if angles_all.size else None,
        orientation_max=float(angles_all.max()) if angles_all.size else None,
        folds=len(folds))
