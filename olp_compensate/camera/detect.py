"""Subpixel centres of the board's dots in an image, ordered into the grid by the marker.

Steps (1 and 2 in :mod:`.blobs`, the others below):

1. :func:`paper_level` and :func:`dark_mask` - local contrast: the paper level is
   estimated by a grey closing (larger than any dot can appear) and a pixel is dark where
   :func:`darkness`, ``1 - I / paper``, exceeds a threshold, so uneven light and vignetting
   drop out; the mask is made in 8 bits by a limit on I per paper level.
2. :func:`find_blobs` - connected components of the mask, kept if they are filled
   ellipses (area against the area of the ellipse of equal second moments).
3. :func:`match_grid` - the marker is the blob largest against its neighbours; with its
   two nearest neighbours along the columns and the rows (column × row > 0 in the image,
   the camera sees the printed face) and the diagonal one, a board-to-image homography is
   grown ring by ring over the grid, refitted on every match.
4. :func:`refine_centres` - each dot's centre is the darkness-weighted centroid inside an
   ellipse slightly larger than the blob, against a background plane fitted on a ring
   around it; all dots at once, in windows cut from the full-resolution image. That is
   the centroid of the dot's *image*: under perspective it is not the
   image of the circle's centre; :func:`circle_centre_bias` gives the difference.

Pixel coordinates: integer values at pixel centres, X = column, Y = row.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np

from ..errors import DataError
from ..io.images import image_paths, read_grey
from .blobs import CONTRAST_THRESHOLDS, Blobs, _as_grey, dark_mask, find_blobs, paper_level
from .board import Board
from .model import CameraIntrinsics, project_points

BORDER_MARGIN_PX = 2
"""A dot whose window comes closer than this to the image border is not measured."""


@dataclass(frozen=True, eq=False)
class Detection:
    """The board found in one image.

    name : image name. pixels : (rows*cols, 2) dot centres, px (X, Y), row-major in the
    order of :meth:`Board.dot_positions`. area_px : (n,) blob areas above the threshold,
    px^2. contrast : (n,) peak darkness of each dot (0 paper .. 1 black).
    homography : (3, 3) board x, y (m) to pixels, fitted on all dots. homography_rms_px :
    RMS distance of the dots to it (lens distortion and noise), px.
    """

    name: str
    pixels: np.ndarray
    area_px: np.ndarray
    contrast: np.ndarray
    homography: np.ndarray
    homography_rms_px: float

    ok = True


@dataclass(frozen=True)
class DetectionFailure:
    """The board was not found whole in image ``name``; ``reason`` says why."""

    name: str
    reason: str

    ok = False


def fit_homography(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """3x3 homography mapping points ``src`` (n, 2) to ``dst`` (n, 2), n >= 4, by the
    normalized direct linear transform (least squares on all points)."""
    def normalizer(p):
        mean = p.mean(axis=0)
        scale = math.sqrt(2) / max(np.sqrt(((p - mean) ** 2).sum(axis=1)).mean(), 1e-12)
        return np.array([[scale, 0, -scale * mean[0]], [0, scale, -scale * mean[1]],
                         [0, 0, 1]])

    Ts, Td = normalizer(src), normalizer(dst)
    s = src @ Ts[:2, :2].T + Ts[:2, 2]
    d = dst @ Td[:2, :2].T + Td[:2, 2]
    n = len(s)
    A = np.zeros((2 * n, 9))
    A[0::2, 0:2], A[0::2, 2] = s, 1
    A[0::2, 6:8], A[0::2, 8] = -d[:, :1] * s, -d[:, 0]
    A[1::2, 3:5], A[1::2, 5] = s, 1
    A[1::2, 6:8], A[1::2, 8] = -d[:, 1:] * s, -d[:, 1]
    H = np.linalg.svd(A)[2][-1].reshape(3, 3)
    H = np.linalg.inv(Td) @ H @ Ts
    return H / H[2, 2]


def apply_homography(H: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (n, 2) mapped by the homography H (3, 3)."""
    p = np.asarray(points, dtype=float) @ H[:, :2].T + H[:, 2]
    return p[:, :2] / p[:, 2:3]


@dataclass(frozen=True, eq=False)
class _GridMatch:
    blob_of_dot: np.ndarray  # (rows*cols,) blob index or -1
    homography: np.ndarray  # grid (c, r) -> pixels

    @property
    def found(self) -> int:
        return int(np.sum(self.blob_of_dot >= 0))


def _grow(board: Board, blobs: Blobs, tree, start: dict[tuple[int, int], int]) -> _GridMatch:
    """Grow a grid match from a few (r, c) -> blob seeds, ring by ring."""
    rows, cols = board.rows, board.cols
    blob_of_dot = np.full(rows * cols, -1)
    for (r, c), b in start.items():
        blob_of_dot[r * cols + c] = b
    used = set(start.values())
    grid = board.dot_grid()
    dot_area = math.pi / 4 * (board.dot_diameter_m / board.pitch_m) ** 2  # in pitch^2
    while True:
        matched = blob_of_dot >= 0
        H = fit_homography(grid[matched][:, ::-1].astype(float),
                           blobs.centres[blob_of_dot[matched]])
        # blob areas against the areas the homography predicts (perspective changes them)
        dots = np.nonzero(matched)[0][1:]  # all but the marker
        typical = float(np.median(blobs.areas[blob_of_dot[dots]]
                                  / _image_area(H, grid[dots][:, ::-1], dot_area)))
        rr, cc = grid[matched, 0], grid[matched, 1]
        r_lo, r_hi = max(rr.min() - 1, 0), min(rr.max() + 1, rows - 1)
        c_lo, c_hi = max(cc.min() - 1, 0), min(cc.max() + 1, cols - 1)
        todo = np.nonzero(~matched & (grid[:, 0] >= r_lo) & (grid[:, 0] <= r_hi)
                          & (grid[:, 1] >= c_lo) & (grid[:, 1] <= c_hi))[0]
        if todo.size == 0:
            break
        cr = grid[todo][:, ::-1].astype(float)
        predicted = apply_homography(H, cr)
        step_c = np.linalg.norm(apply_homography(H, cr + [1, 0]) - predicted, axis=1)
        step_r = np.linalg.norm(apply_homography(H, cr + [0, 1]) - predicted, axis=1)
        tolerance = 0.3 * np.minimum(step_c, step_r)
        expected_area = typical * _image_area(H, cr, dot_area)
        distance, nearest = tree.query(predicted)
        added = 0
        for k in np.argsort(distance):
            b = int(nearest[k])
            if distance[k] > tolerance[k] or b in used:
                continue
            if not 0.33 < blobs.areas[b] / expected_area[k] < 3:
                continue
            blob_of_dot[todo[k]] = b
            used.add(b)
            added += 1
        if added == 0:
            break
    matched = blob_of_dot >= 0
    H = fit_homography(grid[matched][:, ::-1].astype(float), blobs.centres[blob_of_dot[matched]])
    return _GridMatch(blob_of_dot, H)


def _image_area(H: np.ndarray, points: np.ndarray, area: float) -> np.ndarray:
    """Image area (px^2) of a small ``area`` at ``points`` (n, 2) mapped by H (3, 3):
    ``area * |det H| / w^3``, the homography's local Jacobian determinant."""
    w = points @ H[2, :2] + H[2, 2]
    return area * abs(np.linalg.det(H)) / np.abs(w) ** 3


def _seeds(board: Board, blobs: Blobs, tree) -> Iterator[dict[tuple[int, int], int]]:
    """Candidate starts: marker, its column and row neighbours and the diagonal dot."""
    n = len(blobs.areas)
    if n < 4:
        return
    k = min(9, n)
    _, neighbours = tree.query(blobs.centres, k=k)
    expected = (board.marker_diameter_m / board.dot_diameter_m) ** 2
    neighbour_area = np.median(blobs.areas[neighbours[:, 1:5]], axis=1)
    ratio = blobs.areas / neighbour_area
    score = np.abs(np.log(ratio / expected))
    candidates = [i for i in np.argsort(score) if score[i] < math.log(2.0)]
    for m in candidates[:8]:
        centre = blobs.centres[m]
        near = [int(j) for j in neighbours[m, 1:]
                if 0.5 < expected * blobs.areas[j] / blobs.areas[m] < 2.0]
        pairs = []
        for a in near:
            for b in near:
                if a == b:
                    continue
                va, vb = blobs.centres[a] - centre, blobs.centres[b] - centre
                la, lb = np.linalg.norm(va), np.linalg.norm(vb)
                cross = (va[0] * vb[1] - va[1] * vb[0]) / (la * lb)
                # the column direction turns to the row direction by +40..140 degrees
                if cross < math.sin(math.radians(40)) or max(la, lb) > 2.5 * min(la, lb):
                    continue
                diagonal = blobs.centres[a] + vb
                dd, d = tree.query(diagonal)
                if dd > 0.3 * min(la, lb) or d in (m, a, b):
                    continue
                pairs.append((la + lb, a, b, int(d)))
        for _, a, b, d in sorted(pairs)[:3]:
            yield {(0, 0): int(m), (0, 1): a, (1, 0): b, (1, 1): d}


def match_grid(board: Board, blobs: Blobs) -> _GridMatch | str:
    """The blob of every dot (grid match), or the reason there is none."""
    from scipy.spatial import cKDTree

    if len(blobs.areas) < 4:
        return f"found {len(blobs.areas)} dot-like blobs, need {board.count}"
    tree = cKDTree(blobs.centres)
    best = None
    for seed in _seeds(board, blobs, tree):
        match = _grow(board, blobs, tree, seed)
        if match.found == board.count:
            return match
        if best is None or match.found > best.found:
            best = match
    if best is None:
        return "no marker dot"
    return best


def _missing_reason(board: Board, blobs: Blobs, match: _GridMatch, shape) -> str:
    height, width = shape
    missing = np.nonzero(match.blob_of_dot < 0)[0]
    grid = board.dot_grid()
    predicted = apply_homography(match.homography, grid[missing][:, ::-1].astype(float))
    outside = ((predicted[:, 0] < 0) | (predicted[:, 0] > width - 1)
               | (predicted[:, 1] < 0) | (predicted[:, 1] > height - 1))
    found = f"found {match.found} of {board.count} dots"
    if np.any(outside):
        r, c = grid[missing[np.argmax(outside)]]
        count = int(outside.sum())
        dots = f"dot ({r}, {c})" if count == 1 else f"{count} dots, e.g. ({r}, {c}),"
        return f"{found}: board touches the image border ({dots} outside the image)"
    if np.any(blobs.touches_border):
        from scipy.spatial import cKDTree

        tree = cKDTree(blobs.centres[blobs.touches_border])
        step = np.median(np.linalg.norm(np.diff(apply_homography(
            match.homography, np.array([[0.0, 0.0], [1.0, 0.0]])), axis=0), axis=1))
        dist, _ = tree.query(predicted)
        if np.any(dist < 0.5 * step):
            return f"{found}: board touches the image border"
    return f"{found} (dots hidden or not dark enough)"


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
    height, width = grey.shape
    n = len(indices)
    centres = blobs.centres[indices].astype(float)
    axes_var, axes = np.linalg.eigh(blobs.covariances[indices])  # (n, 2), (n, 2, 2)
    semi = 2 * np.sqrt(np.maximum(axes_var, 0.25))
    grow = np.maximum(2.5, 0.35 * semi.min(axis=1))[:, None]
    window = semi + grow
    outer = window + grow
    half = np.ceil(outer.max(axis=1)).astype(int) + 2
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
            update, new_centres, peak = _centroids(grey, origin[k], centres[k], axes[k],
                                                   window[k], outer[k], int(size))
            active[k[~update]] = False
            centres[k[update]] = new_centres[update]
            contrast[k[update]] = peak[update]
    return centres, contrast, inside


def _centroids(grey, origin, centre, axes, window, outer, half):
    """One step of :func:`refine_centres` for k dots, each in the (2 half + 1)^2 window
    around ``origin`` (k, 2) int, inside the image: (k,) bool "weights positive", (k, 2)
    centroids, (k,) peak contrasts."""
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
    weight *= inner
    w_row, w_col = weight.sum(axis=2), weight.sum(axis=1)
    total = w_row.sum(1)
    ok = total > 0
    safe = np.where(ok, total, 1.0)
    centroid = np.stack([(w_col * xs).sum(1), (w_row * ys).sum(1)], -1) / safe[:, None]
    peak = weight.max(axis=(1, 2))  # the inner maximum wherever the total is positive
    return ok, centroid, peak


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


def detect_dots(image: np.ndarray, board: Board, name: str = "<image>",
                method: str = "centroid") -> Detection | DetectionFailure:
    """Find every dot of ``board`` in an 8-bit grey (h, w) or RGB (h, w, 3) image.

    method : "centroid" (darkness-weighted centroid, the default and the more accurate)
    or "ellipse" (centre of an ellipse fitted to the blob contour).
    Returns a :class:`Detection`, or a :class:`DetectionFailure` with the reason.
    """
    if method not in ("centroid", "ellipse"):
        raise DataError(f"detect: method must be 'centroid' or 'ellipse', got {method!r}")
    grey = _as_grey(image)
    if board.kind == "charuco":
        from .detect_opencv import find_charuco_corners

        corners = find_charuco_corners(grey, board)
        if isinstance(corners, str):
            return DetectionFailure(name, corners)
        return _detection(name, board, corners, np.full(board.count, np.nan),
                          np.full(board.count, np.nan))
    if board.kind != "olp-dots":
        return _detect_opencv(grey, board, name)
    paper = paper_level(grey, board)
    first = None
    for threshold in CONTRAST_THRESHOLDS:
        blobs = find_blobs(dark_mask(grey, paper, threshold))
        match = match_grid(board, blobs)
        if not isinstance(match, str) and match.found == board.count:
            break
        if isinstance(match, str):
            if np.any(blobs.touches_border):
                match += " (dot-like blobs touch the image border: board cut off?)"
            failure = DetectionFailure(name, match)
        else:
            failure = DetectionFailure(name, _missing_reason(board, blobs, match, grey.shape))
        first = first or failure
    else:
        return first  # the reason at the standard threshold
    indices = match.blob_of_dot
    if np.any(blobs.touches_border[indices]):
        return DetectionFailure(name, "board touches the image border")
    centres, contrast, inside = refine_centres(grey, blobs, indices)
    if not np.all(inside):
        r, c = board.dot_grid()[np.argmin(inside)]
        return DetectionFailure(name, f"board touches the image border (dot ({r}, {c}))")
    if method == "ellipse":
        centres = ellipse_centres(blobs, indices)
    H = fit_homography(board.dot_positions()[:, :2], centres)
    rms = float(np.sqrt(np.mean(np.sum(
        (apply_homography(H, board.dot_positions()[:, :2]) - centres) ** 2, axis=1))))
    return Detection(name=name, pixels=centres, area_px=blobs.areas[indices],
                     contrast=contrast, homography=H, homography_rms_px=rms)


def _detect_opencv(grey: np.ndarray, board: Board, name: str) -> Detection | DetectionFailure:
    """An OpenCV circle grid as a :class:`Detection`: ``cv2.findCirclesGrid`` orders the
    dots (:mod:`.detect_opencv`), our blobs and darkness-weighted centroids measure them."""
    from .detect_opencv import find_opencv_grid, right_handed

    rough = find_opencv_grid(grey, board)
    if rough is None:
        return DetectionFailure(name, f"no {board.rows} x {board.cols} {board.kind} grid "
                                      f"found (cv2.findCirclesGrid)")
    rough = right_handed(board, rough)
    if rough is None:
        return DetectionFailure(name, f"the {board.kind} grid was found mirrored")
    blobs = find_blobs(dark_mask(grey, paper_level(grey, board), CONTRAST_THRESHOLDS[0]))
    if not len(blobs.areas):
        return DetectionFailure(name, "no dark dots below the paper level")
    indices = _match_blobs(board, rough, blobs)
    if indices is None:
        return DetectionFailure(name, "the circle grid's dots do not match one blob each")
    if np.any(blobs.touches_border[indices]):
        return DetectionFailure(name, "board touches the image border")
    centres, contrast, inside = refine_centres(grey, blobs, indices)
    if not np.all(inside):
        return DetectionFailure(name, "board touches the image border")
    return _detection(name, board, centres, blobs.areas[indices], contrast)


def _detection(name, board, centres, area, contrast) -> Detection:
    """A :class:`Detection` of ``centres`` (n, 2) px with the board's homography."""
    flat = board.dot_positions()[:, :2]
    H = fit_homography(flat, centres)
    rms = float(np.sqrt(np.mean(np.sum((apply_homography(H, flat) - centres) ** 2, axis=1))))
    return Detection(name=name, pixels=centres, area_px=area, contrast=contrast,
                     homography=H, homography_rms_px=rms)


def _match_blobs(board: Board, rough: np.ndarray, blobs: Blobs) -> np.ndarray | None:
    """The blob of every dot (n,), from OpenCV's ordered centres ``rough`` (n, 2) px: a
    homography fitted with RANSAC (OpenCV now and then puts a corner dot on its neighbour)
    predicts each dot, the nearest blob within a quarter of the dot spacing is taken, and
    the match is redone once on the matched blobs; None when a dot has no blob of its own."""
    import cv2

    flat = board.dot_positions()[:, :2]
    grid = rough.reshape(board.rows, board.cols, 2)
    spacing = float(np.median(np.linalg.norm(np.diff(grid, axis=1), axis=2)))
    H, _ = cv2.findHomography(flat, rough, cv2.RANSAC, 0.1 * spacing)
    if H is None:
        return None
    indices = None
    for _ in range(2):
        predicted = apply_homography(H, flat)
        gap = np.linalg.norm(predicted[:, None, :] - blobs.centres[None, :, :], axis=2)
        indices = np.argmin(gap, axis=1)
        if (len(set(indices.tolist())) < board.count
                or np.max(gap[np.arange(board.count), indices]) > 0.25 * spacing):
            return None
        H = fit_homography(flat, blobs.centres[indices])
    return indices


def detect_many(images: str | Path | Iterable[str | Path], board: Board,
                method: str = "centroid") -> Iterator[Detection | DetectionFailure]:
    """Detect the board in every image of IMAGES (a folder, sorted by name, or a list of
    files); an unreadable image or one without the whole board yields a
    :class:`DetectionFailure` naming it, and the others go on."""
    for path in image_paths(images):
        try:
            grey = read_grey(path)
        except DataError as exc:
            yield DetectionFailure(path.name, f"cannot read: {exc}")
            continue
        yield detect_dots(grey, board, path.name, method)


def circle_centre_bias(intrinsics: CameraIntrinsics, camera_T_board: np.ndarray,
                       board: Board, samples: int = 256) -> np.ndarray:
    """Perspective bias of every dot (n, 2) px, row-major: the centroid of the area of the
    dot's image minus the image of the dot's centre.

    The printed circle's boundary is projected through the full camera model
    (``samples`` points, distortion included) and the centroid of the enclosed polygon
    taken (exact to O(1/samples^2)). Subtract it from detected centroids to get the
    images of the dot centres; ``camera_T_board`` (4, 4, m) from a first calibration pass.
    A charuco board's corners have no such bias (zeros).
    """
    if board.kind == "charuco":
        return np.zeros((board.count, 2))
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
