"""A start for views the RAC cannot use: Zhang's homography method (Zhang 2000, sections
3.1-3.2), as OpenCV's ``initIntrinsicParams2D`` does it for a board.

The RAC stages need views tilted 20 degrees or more (:mod:`.calibrate`); a set of views all
nearer to face-on still calibrates once the refinement has a start. Each view's homography
``H`` (board x, y in m -> pixels, no distortion) gives two constraints on ``w = K^-T K^-1``:
``h1' w h2 = 0`` and ``h1' w h1 = h2' w h2``. With the principal point at the image's middle
and square pixels (mu = 1), ``w`` has one unknown ``1 / f^2``, found by linear least squares
over every view (near-frontal views determine it weakly, each a little; the refinement
then frees the centre, mu and the distortion). Each view's pose follows from its
homography with the start's ``K``: ``r1 = l K^-1 h1``, ``r2 = l K^-1 h2``, ``t = l K^-1 h3``,
the rotation made orthonormal by SVD. Near face-on the lens distortion can spoil that focal
length, so a few more trial starts are refined a little and the best kept
(:func:`zhang_start`).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ..errors import DataError
from .detect import fit_homography
from .model import CameraIntrinsics
from .refine import refine


def homography(pixels: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(3, 3) board plane (x, y, m) -> pixels (column, row) of one view."""
    return fit_homography(np.asarray(points, dtype=float)[:, :2],
                          np.asarray(pixels, dtype=float))


def focal_from_homographies(homographies: Sequence[np.ndarray], cx: float,
                            cy: float) -> float:
    """The focal length (px, mu = 1) from Zhang's constraints with the principal point
    ``(cx, cy)``; :class:`DataError` when the views do not determine a positive one."""
    shift = np.array([[1.0, 0.0, -cx], [0.0, 1.0, -cy], [0.0, 0.0, 1.0]])
    rows, rhs = [], []
    for H in homographies:
        G = shift @ H
        G = G / np.linalg.norm(G[:, :2])
        h1, h2 = G[:, 0], G[:, 1]
        # a = 1 / f^2:  a (h1x h2x + h1y h2y) + h1z h2z = 0
        rows.append(h1[0] * h2[0] + h1[1] * h2[1])
        rhs.append(-h1[2] * h2[2])
        # a (|h1xy|^2 - |h2xy|^2) + h1z^2 - h2z^2 = 0
        rows.append(h1[0] ** 2 + h1[1] ** 2 - h2[0] ** 2 - h2[1] ** 2)
        rhs.append(-(h1[2] ** 2 - h2[2] ** 2))
    a_col, b = np.array(rows), np.array(rhs)
    denominator = float(a_col @ a_col)
    a = float(a_col @ b) / denominator if denominator > 0 else math.nan
    if not (math.isfinite(a) and a > 0):
        raise DataError("calibrate: the views' homographies do not determine a focal length "
                        "(all exactly face-on?); tilt some views 20-50 degrees")
    return 1.0 / math.sqrt(a)


def pose_from_homography(H: np.ndarray, intrinsics: CameraIntrinsics) -> np.ndarray:
    """camera_T_board (4, 4) of a view from its homography with the intrinsics' K (no
    distortion), the board in front of the camera (z > 0)."""
    K = np.array([[intrinsics.fx, 0.0, intrinsics.cx], [0.0, intrinsics.fy, intrinsics.cy],
                  [0.0, 0.0, 1.0]])
    M = np.linalg.solve(K, H)
    scale = 2.0 / (np.linalg.norm(M[:, 0]) + np.linalg.norm(M[:, 1]))
    if M[2, 2] * scale < 0:                  # the board's origin must lie in front
        scale = -scale
    r1, r2, t = M[:, 0] * scale, M[:, 1] * scale, M[:, 2] * scale
    u, _, vt = np.linalg.svd(np.stack([r1, r2, np.cross(r1, r2)], axis=1))
    R = u @ vt
    if np.linalg.det(R) < 0:
        R = u @ np.diag([1.0, 1.0, -1.0]) @ vt
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = R, t
    return pose


FOCAL_SCAN = (0.5, 0.7, 1.0, 1.4, 2.0, 2.8, 4.0)
"""Focal lengths tried besides Zhang's, times the image width (fields of view from 90 to
14 degrees): near face-on, the lens distortion can spoil the homographies' estimate."""
SCAN_ITERATIONS = 25
"""Refinement steps per trial start; the best start is then refined to the end."""


def zhang_start(pixels: Sequence[np.ndarray], points: Sequence[np.ndarray], width: int,
                height: int) -> tuple[CameraIntrinsics, np.ndarray]:
    """(intrinsics, camera_T_board (V, 4, 4)) to start the full refinement from.

    Trial starts: the focal length of :func:`focal_from_homographies` (when the views give
    one) and :data:`FOCAL_SCAN`, each at the image's middle, mu = 1, no distortion, every
    view's pose from its homography; each is refined :data:`SCAN_ITERATIONS` steps and the
    one with the smallest reprojection error is returned. :class:`DataError` when no trial
    converges."""
    homographies = [homography(p, q) for p, q in zip(pixels, points)]
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    focals = [width * f for f in FOCAL_SCAN]
    try:
        focals.insert(0, focal_from_homographies(homographies, cx, cy))
    except DataError:
        pass
    best, best_cost = None, math.inf
    for f in focals:
        start = CameraIntrinsics(fx=f, mu=1.0, cx=cx, cy=cy, width=width, height=height)
        poses = np.array([pose_from_homography(H, start) for H in homographies])
        try:
            trial = refine(pixels, points, start, poses, max_iterations=SCAN_ITERATIONS)
        except (DataError, np.linalg.LinAlgError, FloatingPointError):
            continue
        cost = float(sum(np.sum(r ** 2) for r in trial.residuals))
        if math.isfinite(cost) and cost < best_cost and trial.intrinsics.fx > 0:
            best, best_cost = trial, cost
    if best is None:
        raise DataError("calibrate: no start from the views' homographies converged; tilt "
                        "some views 20-50 degrees")
    return best.intrinsics, best.camera_T_board
