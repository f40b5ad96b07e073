"""Subpixel centres of dots already found and matched (:mod:`.detect`), and the
perspective bias that separates them from the images of the dots' centres.

Two estimates, each inside an ellipse around the dot (the blob's covariance axes) against a
background plane fitted on a ring around it:

- :func:`refine_centres` - the darkness-weighted centroid, darkness ``1 - I / paper``. It is
  the centroid of the dot's image whatever its shape (blur keeps first moments), but every
  pixel of the window adds its noise, the dark interior and the paper around the dot alike,
  with a lever arm of up to the window's radius.
- :func:`robust_centres` - from there, the centroid of the darkness mapped through a
  smooth step between :data:`EDGE_RAMP` of the dot's own contrast: the interior (all 1)
  and the paper (all 0) add no noise, only the edge does, weighted most at mid-edge
  where its gradient, hence its information on the position, is largest; a window
  :data:`WIDEN` times further out (short of the neighbouring dots) keeps the ring clear of
  a blurred edge. A symmetric dot image (the ellipse a circle projects to, blurred by any
  symmetric kernel) has the same centre under any such map, so the estimate is still the
  centre of the dot's ellipse. On rendered views with 6 grey levels of noise its error is
  1.4-1.7 times smaller, within 1.2 times the Cramer-Rao bound (README, "camera").

:func:`circle_centre_bias` gives the centre of the dot's ellipse (the centroid of its
area) minus the image of the printed circle's centre. Pixel coordinates: integer values at
pixel centres, X = column, Y = row.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .blobs import Blobs
from .board import Board
from ..errors import DataError
from .model import CameraIntrinsics, project_points

BORDER_MARGIN_PX = 2
"""A dot whose window comes closer than this to the image border is not measured."""

EDGE_RAMP = (0.1, 0.9)
"""The smooth step of :func:`robust_centres` rises from 0 to 1 between these fractions of
the dot's contrast (its mean darkness above half its peak)."""

WIDEN = 2.0
""":func:`robust_centres` widens the band between the dot and its window, and the ring,
by this factor where the neighbouring dots leave room."""

PRESMOOTH_PX = 1.0
""":func:`robust_centres` works on the image smoothed by a Gaussian of this sigma (px): a
non-linear map of pixels whose edge is sharper than a pixel aliases (0.023 px RMS on
noise-free unblurred views; after it 0.0043 px, the darkness centroid's 0.0042 px), and a
symmetric kernel keeps the dot's image symmetric. 0.8 px aliased a little more (0.005 px),
1.2 px spent 4 % more noise."""


@dataclass(frozen=True, eq=False)
class CentreEstimate:
    """Dot centres from :func:`robust_centres`: centres (n, 2) px; widened (n,) bool, the
    band around the dot was widened by :data:`WIDEN`; inside (n,) bool, the window stayed
    inside the image (where not, the centre is the last one that did)."""

    centres: np.ndarray
    widened: np.ndarray
    inside: np.ndarray


@dataclass(frozen=True, eq=False)
class _Windows:
    """Per dot: axes (n, 2, 2) of the blob's covariance, semi-axes (n, 2) px of the
    centroid's ellipse (``window``) and of the ring's outer ellipse (``outer``), and the
    half-size (n,) int of the square window cut around the dot."""

    axes: np.ndarray
    window: np.ndarray
    outer: np.ndarray
    half: np.ndarray


def _windows(covariances: np.ndarray, widen: float | np.ndarray = 1.0) -> _Windows:
    """Ellipses around each dot: semi-axes ``semi + grow`` and ``semi + 2 grow`` with
    ``semi`` 2 sigma of the blob and ``grow = widen * max(2.5 px, 0.35 semi)``."""
    axes_var, axes = np.linalg.eigh(covariances)  # (n, 2), (n, 2, 2)
    semi = 2 * np.sqrt(np.maximum(axes_var, 0.25))
    grow = (np.maximum(2.5, 0.35 * semi.min(axis=1)) * widen)[:, None]
    window = semi + grow
    outer = window + grow
    return _Windows(axes, window, outer, np.ceil(outer.max(axis=1)).astype(int) + 2)


def refine_centres(grey: np.ndarray, blobs: Blobs, indices: np.ndarray,
                   iterations: int = 2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Darkness-weighted centroids (n, 2) px of the blobs ``indices``, with a background
    plane fitted on a ring around each; also (n,) peak contrast and (n,) bool "window fits
    inside the image".

    Per dot, with the blob's covariance axes: the centroid is taken inside an ellipse of
    semi-axes ``semi + grow`` (semi = 2 sigma of the blob), the plane on the ring out to
    ``semi + 2 grow``, both around the previous centre; a window of half-size ``half``
    around it must keep :data:`BORDER_MARGIN_PX` from the image border. All dots are done
    at once, in groups of equal window size.
    """
    windows = _windows(blobs.covariances[indices])
    return _iterate(grey, blobs.centres[indices], windows, iterations, None)


def robust_centres(grey: np.ndarray, blobs: Blobs, indices: np.ndarray, start: np.ndarray,
                   iterations: int = 1) -> CentreEstimate:
    """Edge-weighted centroids of the blobs ``indices`` from ``start`` (n, 2) px, the
    centroids of :func:`refine_centres` (see the module's text), on the image smoothed by
    :data:`PRESMOOTH_PX`.

    The band around each dot is widened by :data:`WIDEN` where the ring then keeps 2 px
    clear of the nearest other blob (its 2-sigma ellipse) and within half the distance to
    it, and where the window stays inside the image; elsewhere it keeps the width of
    :func:`refine_centres`. One pass around ``start`` is enough: neither the paper (weight
    0) nor the interior (weight 1, inside the window) pulls towards the window's centre
    (three passes: the same errors to 0.0001 px on the views of benchmarks/camera.py).
    """
    from scipy.spatial import cKDTree

    height, width = grey.shape
    covariances = blobs.covariances[indices]
    wide = _windows(covariances, WIDEN)
    if len(blobs.centres) > 1:
        distance, nearest = cKDTree(blobs.centres).query(start, k=2)
        own = nearest[:, 0] == indices  # else the dot's own blob is not its nearest
        gap = np.where(own, distance[:, 1], distance[:, 0])
        other = np.where(own, nearest[:, 1], nearest[:, 0])
        other_semi = 2 * np.sqrt(np.maximum(np.linalg.eigvalsh(blobs.covariances[other]),
                                            0.25)).max(axis=1)
        room = np.minimum(gap - other_semi - 2.0, 0.5 * gap)
    else:
        room = np.full(len(indices), np.inf)
    m = BORDER_MARGIN_PX
    lo = np.rint(start).astype(int) - wide.half[:, None]
    hi = np.rint(start).astype(int) + wide.half[:, None] + 1
    fits = (lo[:, 0] >= m) & (lo[:, 1] >= m) & (hi[:, 0] <= width - m) \
        & (hi[:, 1] <= height - m)
    use = (wide.outer.max(axis=1) <= room) & fits
    windows = _windows(covariances, np.where(use, WIDEN, 1.0))
    reach = windows.half + 2  # a window may move by up to 2 px, then windows.half around
    corner_lo = np.rint(start).astype(int) - reach[:, None]
    corner_hi = np.rint(start).astype(int) + reach[:, None] + 1
    smooth = _smoothed(grey, corner_lo.min(axis=0), corner_hi.max(axis=0))
    centres, _, inside = _iterate(smooth, start, windows, iterations, EDGE_RAMP)
    return CentreEstimate(centres, use, inside)


def _smoothed(grey: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """float32 image of ``grey``'s shape, smoothed by :data:`PRESMOOTH_PX` between the
    corners ``lo`` (x, y) and ``hi`` (exclusive); undefined outside (never read there).
    The box is cut with a margin of the kernel's reach, so it equals the whole image
    smoothed with reflected borders."""
    import cv2

    height, width = grey.shape
    margin = int(np.ceil(4 * PRESMOOTH_PX)) + 1
    x0, y0 = max(int(lo[0]) - margin, 0), max(int(lo[1]) - margin, 0)
    x1, y1 = min(int(hi[0]) + margin, width), min(int(hi[1]) + margin, height)
    out = np.empty(grey.shape, np.float32)
    if x1 > x0 and y1 > y0:
        out[y0:y1, x0:x1] = cv2.GaussianBlur(grey[y0:y1, x0:x1].astype(np.float32), (0, 0),
                                             PRESMOOTH_PX, borderType=cv2.BORDER_REFLECT)
    return out


def _iterate(grey, start, windows: _Windows, iterations, ramp):
    """Centroids of every dot from ``start`` (n, 2) px, ``iterations`` times around the
    previous centre: (n, 2) centres, (n,) peak contrast, (n,) inside."""
    height, width = grey.shape
    n = len(start)
    centres = np.array(start, dtype=float)
    half = windows.half
    contrast = np.zeros(n)
    inside = np.ones(n, bool)
    active = np.ones(n, bool)
    m = BORDER_MARGIN_PX
    for _ in range(iterations):
        origin = np.rint(centres).astype(int)  # half to even, as round()
        lo, hi = origin - half[:, None], origin + half[:, None] + 1
        fits = (lo[:, 0] >= m) & (lo[:, 1] >= m) & (hi[:, 0] <= width - m) \
            & (hi[:, 1] <= height - m)
        inside &= fits | ~active
        active &= fits
        for size in np.unique(half[active]):
            k = np.nonzero(active & (half == size))[0]
            update, new_centres, peak = _centroids(
                grey, origin[k], centres[k], windows.axes[k], windows.window[k],
                windows.outer[k], int(size), ramp)
            active[k[~update]] = False
            centres[k[update]] = new_centres[update]
            contrast[k[update]] = peak[update]
    return centres, contrast, inside


def _centroids(grey, origin, centre, axes, window, outer, half, ramp=None):
    """One step of :func:`_iterate` for k dots, each in the (2 half + 1)^2 window around
    ``origin`` (k, 2) int, inside the image: (k,) bool "weights positive", (k, 2)
    centroids, (k,) peak contrasts. ``ramp`` None weighs by the darkness, (lo, hi) by its
    smooth step (:func:`_edge_weights`)."""
    from numpy.lib.stride_tricks import sliding_window_view

    size = 2 * half + 1
    x0, y0 = origin[:, 0] - half, origin[:, 1] - half
    patch = sliding_window_view(grey, (size, size))[y0, x0].astype(np.float64)  # (k, s, s)
    steps = np.arange(size)
    xs, ys = x0[:, None] + steps, y0[:, None] + steps  # (k, s) pixel columns and rows
    dx, dy = xs - centre[:, :1], ys - centre[:, 1:]
    # u = axes^T (dx, dy); inside an ellipse of semi-axes e where (u1/e1)^2 + (u2/e2)^2 <= 1,
    # a quadratic form q_xx dx^2 + 2 q_xy dx dy + q_yy dy^2
    a00, a10, a01, a11 = axes[:, 0, 0], axes[:, 1, 0], axes[:, 0, 1], axes[:, 1, 1]

    def quadratic(semi_axes):
        w1, w2 = semi_axes[:, 0] ** -2, semi_axes[:, 1] ** -2
        qxx = a00 * a00 * w1 + a01 * a01 * w2
        qxy = a00 * a10 * w1 + a01 * a11 * w2
        qyy = a10 * a10 * w1 + a11 * a11 * w2
        return ((qxx[:, None] * dx * dx)[:, None, :] + (qyy[:, None] * dy * dy)[:, :, None]
                + (2 * qxy[:, None] * dy)[:, :, None] * dx[:, None, :])

    inner = quadratic(window) <= 1
    ring = (quadratic(outer) <= 1) & ~inner
    # background plane p + q dx + r dy fitted on the ring: normal equations
    ring = ring.astype(np.float64)
    by_row, by_col = ring.sum(axis=2), ring.sum(axis=1)  # (k, s): over x, over y
    cross = np.einsum("kij,ki,kj->k", ring, dy, dx)
    ring *= patch
    grey_row, grey_col = ring.sum(axis=2), ring.sum(axis=1)
    sx, sy = (by_col * dx).sum(1), (by_row * dy).sum(1)
    normal = np.stack([np.stack([by_row.sum(1), sx, sy], -1),
                       np.stack([sx, (by_col * dx * dx).sum(1), cross], -1),
                       np.stack([sy, cross, (by_row * dy * dy).sum(1)], -1)], -2)
    rhs = np.stack([grey_row.sum(1), (grey_col * dx).sum(1), (grey_row * dy).sum(1)], -1)
    p, q, r = np.linalg.solve(normal, rhs[:, :, None])[:, :, 0].T
    paper = (p[:, None] + q[:, None] * dx)[:, None, :] + (r[:, None] * dy)[:, :, None]
    weight = paper - patch
    weight /= np.maximum(paper, 1.0)
    if ramp is None:
        weight *= inner
        peak = weight.max(axis=(1, 2))  # the inner maximum wherever the total is positive
    else:
        weight, peak = _edge_weights(weight, inner, ramp)
    w_row, w_col = weight.sum(axis=2), weight.sum(axis=1)
    total = w_row.sum(1)
    ok = total > 0
    safe = np.where(ok, total, 1.0)
    centroid = np.stack([(w_col * xs).sum(1), (w_row * ys).sum(1)], -1) / safe[:, None]
    return ok, centroid, peak


def _edge_weights(darkness, inner, ramp):
    """Weights (k, s, s) of :func:`robust_centres` from the darkness (k, s, s) against
    the plane inside the centroid's ellipse ``inner`` (bool): the smooth step
    ``3 t^2 - 2 t^3`` of ``t = (darkness / level - lo) / (hi - lo)`` clipped to 0..1, level
    the mean darkness above half the peak; also (k,) the inner peak darkness."""
    lo, hi = ramp
    dark = darkness * inner
    peak = dark.max(axis=(1, 2))
    core = dark > 0.5 * peak[:, None, None]
    level = (dark * core).sum(axis=(1, 2)) / np.maximum(core.sum(axis=(1, 2)), 1)
    span = (hi - lo) * np.where(level > 0, level, np.inf)
    t = np.clip((darkness - (lo * level)[:, None, None]) / span[:, None, None], 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t) * inner, peak


def ellipse_centres(blobs: Blobs, indices: np.ndarray) -> np.ndarray:
    """Centres (n, 2) px of ellipses fitted to the blobs' outer contours (cv2.fitEllipse);
    the alternative to :func:`refine_centres`, kept for comparison."""
    import cv2

    out = np.empty((len(indices), 2))
    for k, b in enumerate(indices):
        x, y, w, h = blobs.boxes[b]
        mask = (blobs.labels[y:y + h, x:x + w] == blobs.label_ids[b]).astype(np.uint8)
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        contour = max(contours, key=len)
        if len(contour) >= 5:
            (ex, ey), _, _ = cv2.fitEllipse(contour)
        else:
            ex, ey = contour.reshape(-1, 2).mean(axis=0)
        out[k] = (ex + x, ey + y)
    return out


BIAS_NODES = 24
"""Nodes of :func:`circle_centre_bias`'s quadrature around each dot's boundary (8 already
agree with 256 to 5e-10 px on the views of benchmarks/camera_speed.py, 12 to 6e-14 px)."""


def circle_centre_bias(intrinsics: CameraIntrinsics, camera_T_board: np.ndarray,
                       board: Board, samples: int = BIAS_NODES) -> np.ndarray:
    """Perspective bias of every dot (n, 2) px, row-major: the centroid of the area of the
    dot's image minus the image of the dot's centre.

    The area and first moments of the dot's image are boundary integrals (Green's theorem)
    over the printed circle's angle ``t``: ``A = 1/2 integral (x y' - y x') dt`` and
    ``A c = 1/3 integral (x, y) (x y' - y x') dt``, with ``(x, y)`` the boundary's pixels
    relative to the image of the centre (full camera model, distortion included) and
    ``(x', y')`` their derivatives in ``t`` (the chain rule through the pose, the
    perspective division and the distortion, as :mod:`.refine` differentiates it). The
    integrands are smooth and periodic, so the trapezoidal rule on ``samples`` equally
    spaced angles converges geometrically (:data:`BIAS_NODES`). On the 20 views of
    benchmarks/camera_speed.py (k1 0.12 and -0.4) it agrees with the Richardson-extrapolated
    centroid of 4096- and 8192-chord polygons to 1.6e-8 px (that reference's own rounding),
    where the polygon of 256 chords (this function before, :func:`polygon_centre_bias`)
    was 1.5e-5 and 3.2e-5 px off (tests/camera/test_detect.py). A charuco board's corners
    have no such bias (zeros).
    """
    if board.kind == "charuco":
        return np.zeros((board.count, 2))
    angles = np.linspace(0, 2 * np.pi, samples, endpoint=False)
    cos, sin = np.cos(angles), np.sin(angles)
    T = np.asarray(camera_T_board, dtype=float)
    rot, t = T[:3, :3], T[:3, 3]
    centres = board.dot_positions() @ rot.T + t                    # (n, 3) camera frame, m
    radii = board.dot_radii()[:, None]
    # boundary p = centre + r (cos R[:, 0] + sin R[:, 1]); its derivative in t, (n, s) each
    p = [centres[:, i, None] + radii * (rot[i, 0] * cos + rot[i, 1] * sin) for i in range(3)]
    dp = [radii * (rot[i, 1] * cos - rot[i, 0] * sin) for i in range(3)]
    if np.any(p[2] <= 0) or np.any(centres[:, 2] <= 0):
        raise DataError("camera: a point lies behind the camera (z <= 0)")
    ux, uy = p[0] / p[2], p[1] / p[2]
    dux, duy = (dp[0] - ux * dp[2]) / p[2], (dp[1] - uy * dp[2]) / p[2]
    k1, k2 = intrinsics.k1, intrinsics.k2
    if k1 == 0.0 and k2 == 0.0:
        dx, dy, ddx, ddy = ux, uy, dux, duy
        cdx, cdy = centres[:, 0] / centres[:, 2], centres[:, 1] / centres[:, 2]
    else:
        every = np.stack([np.concatenate([ux.ravel(), centres[:, 0] / centres[:, 2]]),
                          np.concatenate([uy.ravel(), centres[:, 1] / centres[:, 2]])], -1)
        distorted = intrinsics.distort_normalized(every)
        m = ux.size
        dx, dy = distorted[:m, 0].reshape(ux.shape), distorted[:m, 1].reshape(ux.shape)
        cdx, cdy = distorted[m:, 0], distorted[m:, 1]
        # dd = (I - a d d^T) du / g (see refine.py's module text)
        rho = dx * dx + dy * dy
        g = 1.0 + rho * (k1 + k2 * rho)
        c = 2.0 * (k1 + 2.0 * k2 * rho)
        a = c / (g + c * rho)
        along = a * (dx * dux + dy * duy)
        ddx, ddy = (dux - along * dx) / g, (duy - along * dy) / g
    fx, fy = intrinsics.fx, intrinsics.fy
    x, y = fx * (dx - cdx[:, None]), fy * (dy - cdy[:, None])
    sweep = x * (fy * ddy) - y * (fx * ddx)                          # x y' - y x'
    area = sweep.sum(axis=1) / 2
    return np.stack([(x * sweep).sum(axis=1), (y * sweep).sum(axis=1)], -1) \
        / (3 * area[:, None])


def polygon_centre_bias(intrinsics: CameraIntrinsics, camera_T_board: np.ndarray,
                        board: Board, samples: int = 256) -> np.ndarray:
    """:func:`circle_centre_bias` by the centroid of the polygon through ``samples``
    projected boundary points (exact to O(1/samples^2)): the former method, kept as the
    independent reference of the tests and benchmarks/camera_speed.py."""
    angles = np.linspace(0, 2 * np.pi, samples, endpoint=False)
    ring = np.stack([np.cos(angles), np.sin(angles), np.zeros(samples)], -1)
    centres = board.dot_positions()
    boundary = centres[:, None, :] + board.dot_radii()[:, None, None] * ring
    pix = project_points(intrinsics, camera_T_board, boundary.reshape(-1, 3))
    pix = pix.reshape(len(centres), samples, 2)
    x, y = pix[..., 0], pix[..., 1]
    xn, yn = np.roll(x, -1, axis=1), np.roll(y, -1, axis=1)
    cross = x * yn - xn * y
    area = cross.sum(axis=1) / 2
    cx = ((x + xn) * cross).sum(axis=1) / (6 * area)
    cy = ((y + yn) * cross).sum(axis=1) / (6 * area)
    return np.stack([cx, cy], -1) - project_points(intrinsics, camera_T_board, centres)
