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
4. :func:`refine_centres` and :func:`robust_centres` (:mod:`.centres`) - each dot's
   centre, first the darkness-weighted centroid inside an ellipse slightly larger than the
   blob against a background plane fitted on a ring around it, then the centroid of a
   smooth step of the darkness, which only the dot's edge moves (its noise is the edge's
   alone). Both are centres of the dot's *image*: under perspective that is not the image
   of the circle's centre; :func:`circle_centre_bias` gives the difference.

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
from .centres import (BORDER_MARGIN_PX, circle_centre_bias, ellipse_centres,  # noqa: F401
                      refine_centres, robust_centres)

METHODS = ("centroid", "darkness", "ellipse")
"""The centre estimates :func:`detect_dots` offers (the first is the default)."""


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


def detect_dots(image: np.ndarray, board: Board, name: str = "<image>",
                method: str = "centroid") -> Detection | DetectionFailure:
    """Find every dot of ``board`` in an 8-bit grey (h, w) or RGB (h, w, 3) image.

    method : "centroid" (edge-weighted centroid, :func:`robust_centres`, the default and
    the more accurate), "darkness" (darkness-weighted centroid, :func:`refine_centres`,
    the default before; it spends the noise of every pixel near the dot) or "ellipse"
    (centre of an ellipse fitted to the blob contour).
    Returns a :class:`Detection`, or a :class:`DetectionFailure` with the reason.
    """
    if method not in METHODS:
        raise DataError(f"detect: method must be one of {', '.join(METHODS)}, got {method!r}")
    grey = _as_grey(image)
    if board.kind == "charuco":
        from .detect_opencv import find_charuco_corners

        corners = find_charuco_corners(grey, board)
        if isinstance(corners, str):
            return DetectionFailure(name, corners)
        return _detection(name, board, corners, np.full(board.count, np.nan),
                          np.full(board.count, np.nan))
    if board.kind != "olp-dots":
        return _detect_opencv(grey, board, name, method)
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
    elif method == "centroid":
        centres = robust_centres(grey, blobs, indices, centres).centres
    H = fit_homography(board.dot_positions()[:, :2], centres)
    rms = float(np.sqrt(np.mean(np.sum(
        (apply_homography(H, board.dot_positions()[:, :2]) - centres) ** 2, axis=1))))
    return Detection(name=name, pixels=centres, area_px=blobs.areas[indices],
                     contrast=contrast, homography=H, homography_rms_px=rms)


def _detect_opencv(grey: np.ndarray, board: Board, name: str,
                   method: str = "centroid") -> Detection | DetectionFailure:
    """An OpenCV circle grid as a :class:`Detection`: ``cv2.findCirclesGrid`` orders the
    dots (:mod:`.detect_opencv`), our blobs and centre estimates (``method``) measure them."""
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
    if method == "ellipse":
        centres = ellipse_centres(blobs, indices)
    elif method == "centroid":
        centres = robust_centres(grey, blobs, indices, centres).centres
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
