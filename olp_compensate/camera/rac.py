"""Tsai's Radial Alignment Constraint calibration, as in the seed (sections 8.1-8.3).

Every view sees coplanar points (``zw = 0`` in the board frame, metres). With centred pixel
coordinates ``X = col - cx`` and ``Y' = (row - cy) / mu`` (both in column pixels), the RAC
says that ``(X, Y')`` is parallel to ``(x, y)``, the first two camera coordinates of the point
(eq. 68), whatever the radial distortion:

- stage 1 (:func:`stage1`): the linear system of eq. 69 for ``(r1, r2, Tx, r4, r5) / Ty``,
  then ``|Ty|``, its sign, the rotation and ``Tx`` (Tsai 1987);
- stage 2 (:func:`stage2`): the seed's linear system of eq. 66 in both image directions for
  ``Tz`` (per view), ``fx`` and ``k fx`` (shared by the views); ``k`` is per squared column-pixel
  radius ``X^2 + Y'^2``, the model's ``k1 = k fx^2``;
- the image centre (:func:`search_centre`) and the scale ratio mu (:func:`search_mu`) by
  searching residuals averaged over all views, alternately (:func:`rac_calibrate`).

A finding the seed does not state: for coplanar points the eq. 69 residuals do not depend on
mu at all (a scale of ``Y'`` is absorbed exactly by ``r1, r2, Tx``; one plane gives a 2x2
block of ``R / Ty``, which any 2x2 matrix is), so mu is searched on the stage-2 residuals
(eq. 66, in pixels), which do depend on it; the centre is searched on the eq. 69 residuals.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.optimize import minimize_scalar

from ..errors import DataError
from ..kinematics.conventions import pose_from_rotation_translation
from . import rac_batch
from .model import CameraIntrinsics

MU_BOUNDS = (0.8, 1.25)
"""Range searched for mu = fy / fx (square pixels give 1; real sensors within a few %)."""

MIN_POINTS = 8
"""Fewest points a view needs for stage 1 (5 unknowns, some redundancy)."""


@dataclass(frozen=True)
class Stage1:
    """Stage 1 of one view: ``rotation`` camera_R_board (3, 3), ``tx``, ``ty`` (m), and
    the eq. 69 residuals as distances (column pixels) of the centred image points from the
    radial lines the pose predicts, (n,)."""

    rotation: np.ndarray
    tx: float
    ty: float
    residuals: np.ndarray


@dataclass(frozen=True)
class Stage2:
    """Stage 2 over all views: ``fx`` (column px), ``k`` (per squared column-pixel radius),
    ``tz`` (V,) m, the rotations (V, 3, 3) after Tsai's sign rule, and the eq. 66
    residuals in column pixels per view (list of (2n,))."""

    fx: float
    k: float
    tz: np.ndarray
    rotations: np.ndarray
    residuals: list


@dataclass(frozen=True)
class RacResult:
    """The RAC calibration: ``intrinsics`` (k2 = 0), ``camera_T_board`` (V, 4, 4) m,
    ``rac_rms_px`` the eq. 69 residual RMS (column px) and ``stage2_rms_px`` the eq. 66
    residual RMS over all views at the solution."""

    intrinsics: CameraIntrinsics
    camera_T_board: np.ndarray
    rac_rms_px: float
    stage2_rms_px: float


def _centred(pixels: np.ndarray, cx: float, cy: float, mu: float):
    """Centred coordinates in column pixels: ``X = col - cx``, ``Y' = (row - cy) / mu``."""
    return pixels[:, 0] - cx, (pixels[:, 1] - cy) / mu


def stage1(pixels: np.ndarray, points: np.ndarray, cx: float, cy: float,
           mu: float) -> Stage1:
    """Tsai's first stage for one view.

    pixels : (n, 2) column, row. points : (n, 2) or (n, 3) board frame, m (z = 0 used).
    Solves eq. 69 divided by Ty by linear least squares; ``|Ty| = 1 / s1`` with s1 the larger
    singular value of the 2x2 block of R / Ty (the block of a rotation has s1 = 1); the sign
    of Ty makes the points project on the side of the centre where they are seen; the third
    column of R by Tsai's rule (r3 >= 0, r6 of the sign that makes rows 1 and 2 orthogonal),
    the third row as their cross product. Which of the two mirror completions is right shows
    in stage 2 (fx > 0), see :func:`flip_completion`.
    """
    X, Y = _centred(pixels, cx, cy, mu)
    xw, yw = points[:, 0], points[:, 1]
    a = np.stack([Y * xw, Y * yw, Y, -X * xw, -X * yw], axis=1)
    sol = np.linalg.lstsq(a, X, rcond=None)[0]
    c = np.array([[sol[0], sol[1]], [sol[3], sol[4]]])
    s1 = np.linalg.svd(c, compute_uv=False)[0]
    if not np.isfinite(s1) or s1 <= 0:
        raise DataError("RAC stage 1: degenerate view (the points do not constrain the pose)")
    ty = 1.0 / s1
    block, tx = c * ty, sol[2] * ty
    x = block[0, 0] * xw + block[0, 1] * yw + tx
    y = block[1, 0] * xw + block[1, 1] * yw + ty
    if np.sum(x * X + y * Y) < 0:    # the points would be seen through the centre: Ty < 0
        ty, block, tx = -ty, -block, -tx
    r1, r2 = block[0]
    r4, r5 = block[1]
    r3 = np.sqrt(max(0.0, 1.0 - r1 * r1 - r2 * r2))
    r6 = np.sqrt(max(0.0, 1.0 - r4 * r4 - r5 * r5))
    if r1 * r4 + r2 * r5 > 0:
        r6 = -r6
    row1, row2 = np.array([r1, r2, r3]), np.array([r4, r5, r6])
    rotation = _orthonormal(np.stack([row1, row2, np.cross(row1, row2)]))
    return Stage1(rotation, float(tx), float(ty), rac_residuals(pixels, points, cx, cy, mu,
                                                               rotation, tx, ty))


def stage1_all(pixels: Sequence[np.ndarray], points: Sequence[np.ndarray], cx: float,
               cy: float, mu: float) -> list[Stage1]:
    """:func:`stage1` of every view (at once by :mod:`.rac_batch` when the views have equal
    point counts and none is degenerate; else one by one, which raises for a degenerate
    view)."""
    stacked = rac_batch.stack(pixels, points, cx, cy, mu)
    first = None if stacked is None else rac_batch.stage1(stacked)
    if first is None:
        return [stage1(p, q, cx, cy, mu) for p, q in zip(pixels, points)]
    return [Stage1(r, float(tx), float(ty), res)
            for r, tx, ty, res in zip(first.rotation, first.tx, first.ty, first.residuals)]


def _orthonormal(m: np.ndarray) -> np.ndarray:
    """The rotation nearest to ``m`` (polar decomposition)."""
    u, _, vt = np.linalg.svd(m)
    r = u @ vt
    if np.linalg.det(r) < 0:
        u[:, -1] *= -1
        r = u @ vt
    return r


def flip_completion(rotation: np.ndarray) -> np.ndarray:
    """The other completion of stage 1: r3, r6, r7, r8 negated (Tsai's rule for f < 0)."""
    d = np.diag([1.0, 1.0, -1.0])
    return d @ rotation @ d


def rac_residuals(pixels: np.ndarray, points: np.ndarray, cx: float, cy: float, mu: float,
                  rotation: np.ndarray, tx: float, ty: float) -> np.ndarray:
    """Eq. 69 for every point, normalised to a distance in column pixels: the distance of
    ``(X, Y')`` from the line through the centre along ``(x, y)``, (n,)."""
    X, Y = _centred(pixels, cx, cy, mu)
    xw, yw = points[:, 0], points[:, 1]
    x = rotation[0, 0] * xw + rotation[0, 1] * yw + tx
    y = rotation[1, 0] * xw + rotation[1, 1] * yw + ty
    return (X * y - Y * x) / np.maximum(np.hypot(x, y), 1e-300)


def _stage2_rows(pixels, points, cx, cy, mu, rotation, tx, ty):
    """Eq. 66 rows of one view: ``A @ (Tz, fx, k fx) = b`` (X rows then Y' rows)."""
    X, Y = _centred(pixels, cx, cy, mu)
    xw, yw = points[:, 0], points[:, 1]
    x = rotation[0, 0] * xw + rotation[0, 1] * yw + tx
    y = rotation[1, 0] * xw + rotation[1, 1] * yw + ty
    w = rotation[2, 0] * xw + rotation[2, 1] * yw
    r2 = X * X + Y * Y
    a = np.concatenate([np.stack([-X, x, -x * r2], 1), np.stack([-Y, y, -y * r2], 1)])
    return a, np.concatenate([X * w, Y * w]), np.concatenate([w, w])


def _solve_stage2(rows: list, with_k: bool = True):
    """Joint weighted least squares of eq. 66 over views: per-view Tz, shared fx and k fx.
    Rows are divided by the depth ``w + Tz`` of a first unweighted solution, so that the
    residuals are in column pixels. Returns (tz (V,), fx, kfx, residuals list).

    Each view's rows are first reduced by a QR to as many rows as unknowns it touches, so
    the joint least squares is (k V) x (V + k - 1), not (2 n V) x (V + k - 1)."""
    n_views = len(rows)
    k = 3 if with_k else 2
    designs = [a[:, :k] for a, _, _ in rows]
    weights = [np.ones(len(b)) for _, b, _ in rows]
    for _ in range(2):
        big = np.zeros((n_views, k, n_views + k - 1))
        qtb = np.empty((n_views, k))
        for v, ((_, b, _), a, w) in enumerate(zip(rows, designs, weights)):
            q, r = np.linalg.qr(a * w[:, None])
            qtb[v] = q.T @ (b * w)
            big[v, :, v] = r[:, 0]
            big[v, :, n_views:] = r[:, 1:]
        sol = np.linalg.lstsq(big.reshape(-1, n_views + k - 1), qtb.ravel(), rcond=None)[0]
        weights = [1.0 / np.where(np.abs(w + tz) > 1e-9, np.abs(w + tz), 1e-9)
                   for (_, _, w), tz in zip(rows, sol[:n_views])]
    split = [(a[:, 0] * tz + a[:, 1:] @ sol[n_views:] - b) * w
             for (_, b, _), a, w, tz in zip(rows, designs, weights, sol[:n_views])]
    kfx = sol[n_views + 1] if with_k else 0.0
    return sol[:n_views], float(sol[n_views]), float(kfx), split


def stage2(stage1s: Sequence[Stage1], pixels: Sequence[np.ndarray],
           points: Sequence[np.ndarray], cx: float, cy: float, mu: float,
           with_k: bool = True) -> Stage2:
    """The seed's second stage (eq. 66, X and Y' rows) over all views.

    Each view's completion is first chosen so that its own fx is positive (Tsai: if f < 0,
    negate r3, r6, r7, r8), then fx and k fx are solved jointly with one Tz per view.
    ``with_k=False`` fixes k = 0 (pinhole). Views of equal point counts are solved at once
    by :func:`.rac_batch.stage2`.
    """
    stacked = rac_batch.stack(pixels, points, cx, cy, mu)
    if stacked is not None:
        first = rac_batch.Stage1Batch(np.array([s.rotation for s in stage1s]),
                                      np.array([s.tx for s in stage1s]),
                                      np.array([s.ty for s in stage1s]), None)
        second = rac_batch.stage2(stacked, first, with_k)
        fx, kfx, tz, residuals = second.fx, second.kfx, second.tz, list(second.residuals)
        rotations = [flip_completion(r) if flip else r
                     for r, flip in zip(first.rotation, second.flipped)]
    else:
        rotations, rows = [], []
        for s, pix, pts in zip(stage1s, pixels, points):
            rot = s.rotation
            one = _stage2_rows(pix, pts, cx, cy, mu, rot, s.tx, s.ty)
            if _solve_stage2([one], with_k)[1] < 0:
                rot = flip_completion(rot)
                one = _stage2_rows(pix, pts, cx, cy, mu, rot, s.tx, s.ty)
            rotations.append(rot)
            rows.append(one)
        tz, fx, kfx, residuals = _solve_stage2(rows, with_k)
    if not fx > 0:
        raise DataError(f"RAC stage 2: focal length {fx:.1f} px is not positive (views too "
                        f"close to parallel to the board, or the centre is far off)")
    return Stage2(fx, kfx / fx, tz, np.array(rotations), residuals)


def rac_cost(pixels: Sequence[np.ndarray], points: Sequence[np.ndarray], cx: float, cy: float,
             mu: float) -> float:
    """RMS over all views of the eq. 69 residuals (column px) for a trial centre and mu
    (the views at once by :mod:`.rac_batch` when they have equal point counts)."""
    stacked = rac_batch.stack(pixels, points, cx, cy, mu)
    first = None if stacked is None else rac_batch.stage1(stacked)
    if first is not None:
        return float(np.sqrt(np.mean(first.residuals ** 2)))
    total, count = 0.0, 0
    for pix, pts in zip(pixels, points):
        r = stage1(pix, pts, cx, cy, mu).residuals
        total += float(r @ r)
        count += len(r)
    return np.sqrt(total / count)


def _stage2_residual_vector(pixels, points, cx: float, cy: float, mu: float):
    """The eq. 66 residuals of every view (column px) after both stages as one vector, or
    None when a view is degenerate or the focal length is not positive."""
    stacked = rac_batch.stack(pixels, points, cx, cy, mu)
    first = None if stacked is None else rac_batch.stage1(stacked)
    if first is not None:
        second = rac_batch.stage2(stacked, first)
        return second.residuals.ravel() if second.fx > 0 else None
    try:
        s1 = [stage1(pix, pts, cx, cy, mu) for pix, pts in zip(pixels, points)]
        return np.concatenate(stage2(s1, pixels, points, cx, cy, mu).residuals)
    except DataError:
        return None


def stage2_cost(pixels: Sequence[np.ndarray], points: Sequence[np.ndarray], cx: float,
                cy: float, mu: float) -> float:
    """RMS over all views of the eq. 66 residuals (column px) after both stages (the views
    at once by :mod:`.rac_batch` when they have equal point counts); inf where the stages
    fail."""
    res = _stage2_residual_vector(pixels, points, cx, cy, mu)
    return np.inf if res is None else float(np.sqrt(np.mean(res * res)))


MU_TOL = 2e-7
""":func:`search_mu` stops when its step is smaller than this."""

CENTRE_TOL_PX = 5e-3
""":func:`search_centre` stops when its step is shorter than this (px)."""


def _rac_residual_vector(pixels, points, cx: float, cy: float, mu: float):
    """The eq. 69 residuals of every view (column px) as one vector for a trial centre and
    mu, or None when a view is degenerate there."""
    stacked = rac_batch.stack(pixels, points, cx, cy, mu)
    if stacked is not None:
        first = rac_batch.stage1(stacked)
        return None if first is None else first.residuals.ravel()
    try:
        return np.concatenate([stage1(p, q, cx, cy, mu).residuals
                               for p, q in zip(pixels, points)])
    except DataError:
        return None


def _small_lm(fun, x0: np.ndarray, h: float, max_step: float, tol: float,
              bounds: tuple[float, float] = (-np.inf, np.inf)
              ) -> tuple[np.ndarray | None, bool]:
    """Levenberg-Marquardt on a residual vector ``fun(x)`` (None where undefined) of one or
    two unknowns ``x0``, the Jacobian by forward differences of ``h``, steps at most
    ``max_step`` long and kept inside ``bounds``, until a step is shorter than ``tol`` or
    none lowers the cost. Returns (the last point, None when ``fun(x0)`` is undefined;
    whether it converged: False when the derivatives were undefined or the steps ran out)."""
    x = np.array(x0, dtype=float)
    res = fun(x)
    if res is None:
        return None, False
    cost, damping, eye = float(res @ res), 0.0, np.eye(len(x))
    for _ in range(40):
        jac = np.empty((len(res), len(x)))
        for i in range(len(x)):
            other = fun(x + h * eye[i])
            jac[:, i] = np.inf if other is None else (other - res) / h
        normal, gradient = jac.T @ jac, jac.T @ res
        if not np.all(np.isfinite(normal)) or not np.all(np.diag(normal) > 0):
            return x, False
        for _ in range(20):
            step = -np.linalg.solve(normal + damping * np.diag(np.diag(normal)), gradient)
            length = float(np.linalg.norm(step))
            if length > max_step:
                step *= max_step / length
            step = np.clip(x + step, *bounds) - x
            length = float(np.linalg.norm(step))
            if length < tol and damping == 0.0:
                return x + step, True   # the Gauss-Newton step: converged, no trial needed
            trial = fun(x + step)
            if trial is not None and float(trial @ trial) <= cost:
                break
            damping = max(10.0 * damping, 1e-3)
        else:
            return x, True      # no step lowers the cost: a minimum to rounding
        x, res, cost = x + step, trial, float(trial @ trial)
        damping = damping / 10.0 if damping > 1e-6 else 0.0
        if length < tol:
            return x, True
    return x, False


def search_mu(pixels, points, cx: float, cy: float,
              bounds: tuple[float, float] = MU_BOUNDS, start: float = 1.0) -> float:
    """mu minimizing :func:`stage2_cost` averaged over all views: Levenberg-Marquardt on
    the residual vector from ``start`` (steps of at most 0.05, until one is below
    :data:`MU_TOL`: some 6 evaluations of both stages where the bounded scalar search
    took 14); the bounded scalar search over ``bounds`` when that fails or ends on a
    bound."""
    found, converged = _small_lm(
        lambda x: _stage2_residual_vector(pixels, points, cx, cy, x[0]),
        np.array([float(np.clip(start, *bounds))]), 1e-6, 0.05, MU_TOL, bounds)
    if converged and bounds[0] < found[0] < bounds[1]:
        return float(found[0])
    res = minimize_scalar(lambda mu: stage2_cost(pixels, points, cx, cy, mu), bounds=bounds,
                          method="bounded", options={"xatol": 2e-6})
    return float(res.x)


def search_centre(pixels, points, mu: float, start: tuple[float, float],
                  step_px: float = 20.0) -> tuple[float, float]:
    """Image centre (cx, cy), px, minimizing :func:`rac_cost` averaged over all views.

    Levenberg-Marquardt on the residual vector from ``start``, its 2 columns of derivatives
    by forward differences of 1e-3 px, each step at most ``step_px`` long, until a step is
    shorter than :data:`CENTRE_TOL_PX`, as Nelder-Mead's tolerance was: 18 evaluations of
    stage 1 for every view from 7 px away, then 3 per later round, where Nelder-Mead took
    48 and about 30 (benchmarks/camera_speed.py). Where the derivatives are undefined the
    last point is returned (the refinement starts from it).
    """
    found, _ = _small_lm(lambda c: _rac_residual_vector(pixels, points, c[0], c[1], mu),
                         np.asarray(start, dtype=float), 1e-3, step_px, CENTRE_TOL_PX)
    if found is None:
        raise DataError("RAC stage 1: degenerate view (the points do not constrain the pose)")
    return float(found[0]), float(found[1])


def rac_poses(pixels, points, intrinsics: CameraIntrinsics, stages: Stage2 | None = None,
              stage1s: Sequence[Stage1] | None = None) -> np.ndarray:
    """camera_T_board (V, 4, 4) from the two stages at ``intrinsics``' centre and mu."""
    if stage1s is None:
        stage1s = stage1_all(pixels, points, intrinsics.cx, intrinsics.cy, intrinsics.mu)
    if stages is None:
        stages = stage2(stage1s, pixels, points, intrinsics.cx, intrinsics.cy, intrinsics.mu)
    t = np.array([[s.tx, s.ty, tz] for s, tz in zip(stage1s, stages.tz)])
    return pose_from_rotation_translation(stages.rotations, t)


def rac_calibrate(pixels: Sequence[np.ndarray], points: Sequence[np.ndarray], width: int,
                  height: int, *, rounds: int = 3, mu: float = 1.0,
                  centre: tuple[float, float] | None = None) -> RacResult:
    """The seed's calibration: centre and mu searched alternately over all views
    (``rounds`` times, from ``mu`` and ``centre``, default the middle of the image), then the
    two stages at the result.

    pixels : per view (n_v, 2) column, row. points : per view (n_v, 2 or 3) board frame, m.
    width, height : image size, px.
    """
    if len(pixels) != len(points) or not pixels:
        raise DataError("RAC: give as many point sets as pixel sets, at least one")
    for pix, pts in zip(pixels, points):
        if len(pix) < MIN_POINTS or len(pix) != len(pts):
            raise DataError(f"RAC: a view needs at least {MIN_POINTS} points with pixels, "
                            f"got {len(pix)} pixels for {len(pts)} points")
    cx, cy = centre if centre is not None else ((width - 1) / 2.0, (height - 1) / 2.0)
    arrays = rac_batch.stack_arrays(pixels, points)
    if arrays is not None:                  # stacked once for the ~120 evaluations
        pixels, points = arrays
    for k in range(rounds):   # later rounds start at the last centre: a small simplex
        step = 20.0 if k == 0 and centre is None else 1.0
        cx_new, cy_new = search_centre(pixels, points, mu, (cx, cy), step)
        mu_new = search_mu(pixels, points, cx_new, cy_new, start=mu)
        moved = abs(cx_new - cx) + abs(cy_new - cy) + abs(mu_new - mu) * 1e3
        cx, cy, mu = cx_new, cy_new, mu_new
        if moved < 1e-3:
            break
    s1 = stage1_all(pixels, points, cx, cy, mu)
    s2 = stage2(s1, pixels, points, cx, cy, mu)
    intrinsics = CameraIntrinsics(fx=s2.fx, mu=mu, cx=cx, cy=cy, k1=s2.k * s2.fx ** 2,
                                  width=int(width), height=int(height))
    rac = np.concatenate([s.residuals for s in s1])
    res2 = np.concatenate(s2.residuals)
    return RacResult(intrinsics, rac_poses(pixels, points, intrinsics, s2, s1),
                     float(np.sqrt(np.mean(rac ** 2))), float(np.sqrt(np.mean(res2 ** 2))))
