"""The RAC's two stages for every view at once, for the centre and mu searches.

:func:`.rac.search_centre` and :func:`.rac.search_mu` evaluate the stages some 30 times (120
with the former Nelder-Mead and bounded scalar searches), each time for every view; one
view at a time that is thousands of small ``lstsq`` and SVD calls (82 % of a 20-view
calibration before this module). Here the views, when they all have the
same number of points (a board detected whole), are stacked on a leading axis and each
view's least squares solved by a batched QR; the arithmetic is that of :func:`.rac.stage1`
and :func:`.rac.stage2` (same equations, same sign rules, same two-pass weighting), so the
costs agree with the one-view code to rounding. Units as there: centred coordinates in
column pixels, board points in m.

No import of :mod:`.rac` (it imports this module).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np


@dataclass(frozen=True)
class Stacked:
    """Views stacked on axis 0: ``X``, ``Y`` (V, n) centred column and row coordinates in
    column pixels (``Y' = (row - cy) / mu``); ``xw``, ``yw`` (V, n) board points, m."""

    X: np.ndarray
    Y: np.ndarray
    xw: np.ndarray
    yw: np.ndarray


@dataclass(frozen=True)
class Stage1Batch:
    """Stage 1 of every view: rotations camera_R_board (V, 3, 3), ``tx``, ``ty`` (V,) m,
    eq. 69 residuals (V, n) column px."""

    rotation: np.ndarray
    tx: np.ndarray
    ty: np.ndarray
    residuals: np.ndarray


def stack(pixels: Sequence[np.ndarray], points: Sequence[np.ndarray], cx: float, cy: float,
          mu: float) -> Stacked | None:
    """The views stacked, or None when their point counts differ (then the one-view code
    runs). pixels : per view (n, 2) column, row; points : per view (n, 2 or 3), m; either
    may already be one (V, n, 2) array (see :func:`stack_arrays`)."""
    if not (isinstance(pixels, np.ndarray) and isinstance(points, np.ndarray)):
        arrays = stack_arrays(pixels, points)
        if arrays is None:
            return None
        pixels, points = arrays
    pix, pts = pixels, points
    return Stacked(pix[..., 0] - cx, (pix[..., 1] - cy) / mu, pts[..., 0], pts[..., 1])


def stack_arrays(pixels: Sequence[np.ndarray], points: Sequence[np.ndarray]
                 ) -> tuple[np.ndarray, np.ndarray] | None:
    """pixels (V, n, 2) and board points (V, n, 2) m as arrays, or None when the views'
    point counts differ; the searches stack once and pass the arrays."""
    sizes = {len(p) for p in pixels} | {len(q) for q in points}
    if len(sizes) != 1:
        return None
    return (np.asarray(pixels, dtype=float),
            np.asarray([np.asarray(q, dtype=float)[:, :2] for q in points]))


def _least_squares(design: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Per view the least-squares solution (V, k) of ``design (V, m, k) @ x = rhs (V, m)``:
    normal equations on unit-norm columns (the RAC's designs are well conditioned once
    scaled), by QR when a view's are not positive definite; NaN for a rank-deficient
    view."""
    norms = np.sqrt(np.einsum("vmk,vmk->vk", design, design))
    norms[norms == 0] = 1.0
    scaled = design / norms[:, None, :]
    normal = np.swapaxes(scaled, 1, 2) @ np.concatenate([scaled, rhs[..., None]], axis=2)
    k = design.shape[2]
    try:
        factor = np.linalg.cholesky(normal[:, :, :k])
    except np.linalg.LinAlgError:
        return _least_squares_qr(design, rhs)
    if np.any(np.diagonal(factor, axis1=1, axis2=2) < 1e-7):
        return _least_squares_qr(design, rhs)
    return np.linalg.solve(normal[:, :, :k], normal[:, :, k:])[..., 0] / norms


def _least_squares_qr(design: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """As :func:`_least_squares`, by QR."""
    q, r = np.linalg.qr(design)
    qtb = np.einsum("vmk,vm->vk", q, rhs)
    diag = np.abs(np.diagonal(r, axis1=1, axis2=2))
    singular = np.any(diag <= 1e-12 * np.max(diag, axis=1, keepdims=True), axis=1)
    r = np.where(singular[:, None, None], np.eye(r.shape[1]), r)
    x = np.linalg.solve(r, qtb[..., None])[..., 0]
    x[singular] = np.nan
    return x


def stage1(s: Stacked) -> Stage1Batch | None:
    """:func:`.rac.stage1` for every view; None when a view is degenerate (the one-view
    code then raises its error)."""
    X, Y = s.X, s.Y
    board = np.stack([s.xw, s.yw], axis=1)                       # (V, 2, n), m
    image = np.stack([X, Y], axis=1)                             # (V, 2, n), column px
    bt = np.swapaxes(board, 1, 2)
    design = np.concatenate([Y[..., None] * bt, Y[..., None], -X[..., None] * bt], axis=2)
    sol = _least_squares(design, X)
    c = sol[:, [0, 1, 3, 4]].reshape(-1, 2, 2)
    frob = np.sum(c * c, axis=(1, 2))
    det = c[:, 0, 0] * c[:, 1, 1] - c[:, 0, 1] * c[:, 1, 0]
    s1 = np.sqrt(0.5 * (frob + np.sqrt(np.maximum(frob * frob - 4.0 * det * det, 0.0))))
    if not np.all(np.isfinite(s1)) or np.any(s1 <= 0):
        return None
    ty = 1.0 / s1
    t = np.stack([sol[:, 2] * ty, ty], axis=1)                   # (tx, ty), (V, 2)
    block = c * ty[:, None, None]
    xy = block @ board + t[:, :, None]
    sign = np.where(np.sum(xy * image, axis=(1, 2)) < 0, -1.0, 1.0)
    t, block = t * sign[:, None], block * sign[:, None, None]
    rows = np.empty((len(block), 3, 3))
    rows[:, :2, :2] = block
    rows[:, :2, 2] = np.sqrt(np.maximum(0.0, 1.0 - np.sum(block * block, axis=2)))
    r1, r2, r4, r5 = block[:, 0, 0], block[:, 0, 1], block[:, 1, 0], block[:, 1, 1]
    rows[:, 1, 2] = np.where(r1 * r4 + r2 * r5 > 0, -rows[:, 1, 2], rows[:, 1, 2])
    a, b = rows[:, 0], rows[:, 1]                               # third row: a x b
    rows[:, 2, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    rows[:, 2, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    rows[:, 2, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    rotation = _orthonormal(rows)
    xy = rotation[:, :2, :2] @ board + t[:, :, None]
    x, y = xy[:, 0], xy[:, 1]
    residuals = (X * y - Y * x) / np.maximum(np.hypot(x, y), 1e-300)
    tx, ty = t[:, 0], t[:, 1]
    return Stage1Batch(rotation, tx, ty, residuals)


def _orthonormal(m: np.ndarray) -> np.ndarray:
    """The rotations nearest to ``m`` (V, 3, 3) (polar decomposition)."""
    u, _, vt = np.linalg.svd(m)
    r = u @ vt
    flip = np.linalg.det(r) < 0
    if np.any(flip):
        u[flip, :, -1] *= -1
        r[flip] = u[flip] @ vt[flip]
    return r


def _weighted(design: np.ndarray, rhs: np.ndarray, depth_w: np.ndarray,
              solve) -> tuple[np.ndarray, np.ndarray]:
    """The two-pass depth weighting of :func:`.rac._solve_stage2`: (solution, weights at it).
    ``solve(design * w, rhs * w) -> (solution, Tz of every row)``."""
    weights = np.ones_like(rhs)
    for _ in range(2):
        sol, tz_rows = solve(design * weights[..., None], rhs * weights)
        depth = depth_w + tz_rows
        weights = 1.0 / np.where(np.abs(depth) > 1e-9, np.abs(depth), 1e-9)
    return sol, weights


@dataclass(frozen=True)
class Stage2Batch:
    """Stage 2 over all views: ``fx`` column px, ``kfx`` (k fx, k per squared column-pixel
    radius), ``tz`` (V,) m, ``flipped`` (V,) whether the view's other completion was taken
    (:func:`.rac.flip_completion`), eq. 66 residuals (V, 2n) column px (X rows, then Y')."""

    fx: float
    kfx: float
    tz: np.ndarray
    flipped: np.ndarray
    residuals: np.ndarray


def stage2(s: Stacked, first: Stage1Batch, with_k: bool = True) -> Stage2Batch:
    """:func:`.rac.stage2` for every view.

    Each view's completion is chosen so that its own fx is positive; flipping the
    completion negates ``w`` (rotation entries r7, r8), so the rows keep ``A`` and negate
    ``b`` and ``w``, and the view's fx changes sign exactly.
    """
    rot = first.rotation
    X, Y, xw, yw = s.X, s.Y, s.xw, s.yw
    x = rot[:, 0, 0, None] * xw + rot[:, 0, 1, None] * yw + first.tx[:, None]
    y = rot[:, 1, 0, None] * xw + rot[:, 1, 1, None] * yw + first.ty[:, None]
    w = rot[:, 2, 0, None] * xw + rot[:, 2, 1, None] * yw
    r2 = X * X + Y * Y
    k = 3 if with_k else 2
    design = np.concatenate([np.stack([-X, x, -x * r2], 2), np.stack([-Y, y, -y * r2], 2)],
                            axis=1)[..., :k]
    rhs = np.concatenate([X * w, Y * w], axis=1)
    depth_w = np.concatenate([w, w], axis=1)

    def per_view(a, b):
        sol = _least_squares(a, b)
        return sol, sol[:, :1]

    own, _ = _weighted(design, rhs, depth_w, per_view)
    sign = np.where(own[:, 1] < 0, -1.0, 1.0)[:, None]
    rhs, depth_w = rhs * sign, depth_w * sign
    n_views = len(design)

    def joint(a, b):
        # normal equations on unit-norm columns, Tz of each view eliminated (its column
        # touches only that view's rows): a 2 x 2 (or 1 x 1) system for fx and k fx
        norms = np.sqrt(np.einsum("vmk,vmk->k", a, a))
        norms[norms == 0] = 1.0
        scaled = a / norms
        normal = np.swapaxes(scaled, 1, 2) @ np.concatenate([scaled, b[..., None]], axis=2)
        n00, n0s, h0 = normal[:, 0, 0], normal[:, 0, 1:k], normal[:, 0, k]
        schur = normal[:, 1:k, 1:k].sum(0) - np.einsum("vi,vj->ij", n0s, n0s / n00[:, None])
        shared = np.linalg.solve(schur, normal[:, 1:k, k].sum(0) - (h0 / n00) @ n0s)
        tz = (h0 - n0s @ shared) / n00
        sol = np.concatenate([tz / norms[0], shared / norms[1:]])
        return sol, sol[:n_views, None]

    sol, weights = _weighted(design, rhs, depth_w, joint)
    shared = sol[n_views:]
    fitted = design[..., 0] * sol[:n_views, None] + design[..., 1:] @ shared
    return Stage2Batch(float(shared[0]), float(shared[1]) if with_k else 0.0, sol[:n_views],
                       sign[:, 0] < 0, (fitted - rhs) * weights)
