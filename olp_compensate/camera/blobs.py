"""The first two steps of dot detection (:mod:`.detect`): which pixels are dark against the
local paper level, and the connected blobs of them that may be dots.

Pixel coordinates: integer values at pixel centres, X = column, Y = row.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import DataError
from .board import Board

CONTRAST_THRESHOLDS = (0.3, 0.15, 0.5)
"""A pixel belongs to a blob where ``1 - I / paper`` exceeds the threshold (printed dots:
~0.8); the next one is tried when the board is not found whole (faint or blurred dots,
dots touching dark shapes)."""


@dataclass(frozen=True, eq=False)
class Blobs:
    """Candidate dots: centres (m, 2) px, areas (m,) px^2, covariances (m, 2, 2) px^2 of
    the blob pixels, boxes (m, 4) x, y, w, h and touches_border (m,) bool."""

    centres: np.ndarray
    areas: np.ndarray
    covariances: np.ndarray
    boxes: np.ndarray
    touches_border: np.ndarray
    labels: np.ndarray = field(repr=False)
    label_ids: np.ndarray = field(repr=False)


def _as_grey(image: np.ndarray) -> np.ndarray:
    import cv2

    image = np.asarray(image)
    if image.ndim == 3 and image.shape[2] in (3, 4):
        image = cv2.cvtColor(image[..., :3], cv2.COLOR_RGB2GRAY)
    if image.ndim != 2:
        raise DataError(f"detect: expected a grey (h, w) or colour (h, w, 3) image, got shape "
                        f"{image.shape}")
    if image.dtype != np.uint8:
        raise DataError(f"detect: expected an 8-bit image, got {image.dtype}")
    return image


def largest_dot_px(board: Board, width: int, height: int) -> float:
    """An upper bound on the marker's diameter in an image that holds the whole board, px."""
    span = max(width, height) / (min(board.rows, board.cols) - 1)
    return 2.0 * span * board.marker_diameter_m / board.pitch_m


def paper_level(grey: np.ndarray, board: Board) -> np.ndarray:
    """Grey level of the paper under every pixel (uint8, same shape as ``grey``): a grey
    closing wider than the largest dot the image can hold (:func:`largest_dot_px`), on the
    image reduced about twelve times per dot, smoothed and enlarged back."""
    import cv2

    height, width = grey.shape
    size = largest_dot_px(board, width, height) * 1.3
    step = max(1, int(size // 12))
    small = cv2.resize(grey, (max(1, width // step), max(1, height // step)),
                       interpolation=cv2.INTER_AREA) if step > 1 else grey
    k = int(math.ceil(size / step)) | 1
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))
    paper = cv2.morphologyEx(small, cv2.MORPH_CLOSE, kernel, borderType=cv2.BORDER_REPLICATE)
    paper = cv2.blur(paper, (3, 3))
    if step > 1:
        paper = cv2.resize(paper, (width, height), interpolation=cv2.INTER_LINEAR)
    return paper


def darkness(grey: np.ndarray, board: Board, paper: np.ndarray | None = None) -> np.ndarray:
    """Local contrast ``1 - I / max(paper, I, 8)`` (float32, same shape; 0 paper .. 1
    black), paper from :func:`paper_level` unless given. :func:`dark_mask` thresholds it
    without computing it."""
    paper = paper_level(grey, board) if paper is None else paper
    paper = np.maximum(paper.astype(np.float32), np.maximum(grey, 8).astype(np.float32))
    return 1.0 - grey.astype(np.float32) / paper


@functools.lru_cache(maxsize=None)
def _grey_limits(threshold: float) -> np.ndarray:
    """(256,) uint8: for paper level p, the number of grey levels I whose :func:`darkness`
    exceeds ``threshold`` (float32, as there); darkness falls with I, so those are the I
    below the entry."""
    grey = np.arange(256, dtype=np.float32)
    paper = np.maximum(grey[:, None], np.maximum(grey, 8)[None, :])  # [paper, grey]
    dark = 1.0 - grey[None, :] / paper > threshold
    return dark.sum(axis=1).astype(np.uint8)


def dark_mask(grey: np.ndarray, paper: np.ndarray,
              threshold: float = CONTRAST_THRESHOLDS[0]) -> np.ndarray:
    """uint8 mask (255 where ``darkness(grey) > threshold``, else 0), by a per-paper-level
    limit on the grey level: two 8-bit passes, no float image."""
    import cv2

    if not 0 < threshold < 1:
        raise DataError(f"detect: threshold must be between 0 and 1, got {threshold!r}")
    return cv2.compare(grey, cv2.LUT(paper, _grey_limits(float(threshold))), cv2.CMP_LT)


MIN_BOX_FILL = 0.1
"""A component whose pixels fill less than this of its bounding box is no dot (a filled
ellipse fills pi/4 of it upright, 0.25 at 45 degrees and elongation 6) and gets no
moments."""


def find_blobs(mask: np.ndarray, min_area: int = 6) -> Blobs:
    """Dark filled ellipses: connected components of ``mask`` (non-zero = dark, see
    :func:`dark_mask`) whose area matches that of the ellipse of equal second moments."""
    import cv2

    height, width = mask.shape
    # BBDT (Grana's block-based labelling): half the time of the default (Spaghetti) on
    # these masks with OpenCV 4.x-5.x on one core; labels numbered the same way
    n, labels, stats, _ = cv2.connectedComponentsWithStatsWithAlgorithm(
        mask, 8, cv2.CV_32S, cv2.CCL_BBDT)
    x, y, w, h, area = (stats[:, k] for k in range(5))
    candidate = (area >= min_area) & (area >= MIN_BOX_FILL * w * h)
    candidate[0] = False  # the background component
    ids = np.nonzero(candidate)[0]
    # moments of each candidate inside its bounding box, px relative to the box
    moments = np.empty((len(ids), 5))
    for k, b in enumerate(ids):
        box = labels[y[b]:y[b] + h[b], x[b]:x[b] + w[b]] == b
        m = cv2.moments(box.view(np.uint8), binaryImage=True)
        moments[k] = (m["m10"], m["m01"], m["mu20"], m["mu11"], m["mu02"])
    count = area[ids].astype(float)
    mx = x[ids] + moments[:, 0] / count
    my = y[ids] + moments[:, 1] / count
    cxx = moments[:, 2] / count + 1 / 12  # + pixel's own extent
    cxy = moments[:, 3] / count
    cyy = moments[:, 4] / count + 1 / 12
    det = np.maximum(cxx * cyy - cxy * cxy, 1e-9)
    fill = count / (4 * np.pi * np.sqrt(det))
    trace = cxx + cyy
    disc = np.sqrt(np.maximum(trace * trace / 4 - det, 0))
    elongation = np.sqrt((trace / 2 + disc) / np.maximum(trace / 2 - disc, 1e-9))
    tolerance = np.where(count < 40, 0.3, 0.15)
    keep = (np.abs(fill - 1) < tolerance) & (elongation < 6)
    ids = ids[keep]
    xk, yk, wk, hk = x[ids], y[ids], w[ids], h[ids]
    border = (xk == 0) | (yk == 0) | (xk + wk == width) | (yk + hk == height)
    cov = np.stack([np.stack([cxx, cxy], -1), np.stack([cxy, cyy], -1)], -2)[keep]
    return Blobs(centres=np.stack([mx, my], -1)[keep], areas=count[keep], covariances=cov,
                 boxes=stats[ids, :4], touches_border=border, labels=labels, label_ids=ids)
