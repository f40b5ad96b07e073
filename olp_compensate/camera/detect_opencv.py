"""The boards users own already: OpenCV's symmetric and asymmetric circle grids, found by
``cv2.findCirclesGrid`` (its blob detector, then its grid ordering), ChArUco boards, found
by ``cv2.aruco.CharucoDetector`` (its sub-pixel corners used as they are; a partly visible
board gives the corners it shows), and plain chessboards, found whole by
``cv2.findChessboardCornersSB``, so ``olp-cal camera`` reads them as it reads its own board
(:mod:`.board`, ``"kind"``).

OpenCV orders the centres row by row, ``cols`` per row, as :meth:`.Board.dot_positions`
lays the dots out for these kinds. The blob detector's default largest blob (5,000 px^2) is
lifted to the image's share per dot so that near views of large circles are found; the
circle-centre bias correction applies as for our board. A symmetric grid has no marker:
its orientation is ambiguous by a half turn (OpenCV's own caveat), and so is a
chessboard's, which a calibration does not mind and a pose measurement does
(:func:`check_measurable`).
"""

from __future__ import annotations

import numpy as np

from ..errors import DataError
from .board import Board

GRID_SHRINKS = (1.0, 0.5, 0.25)
"""Scales at which a circle grid is searched, in turn (:func:`find_opencv_grid`)."""
MIN_SEARCH_PX = 240
"""No circle-grid search in a copy whose shorter side would be below this (px)."""

CHESSBOARD_SEARCH_PX = 1600
"""``cv2.findChessboardCornersSB`` searches images shrunk to this longest side (px); it took
18 s on an 8-megapixel photograph, 0.7 s on a 960 x 540 one. The corners are then refined
on the full image (``cv2.cornerSubPix``)."""

MIN_CORNERS = 8
"""Fewest charuco corners a partly visible board must show (over at least two rows and two
columns) to be used: as many as calibration and pose measurement need of any view
(:data:`.rac.MIN_POINTS`); fewer fix the pose poorly and may be a misreading."""


def _detector(grey: np.ndarray, board: Board):
    import cv2

    params = cv2.SimpleBlobDetector_Params()
    # no dot can be larger than the image's share per dot (a larger limit lets the dark
    # background in); OpenCV's other defaults kept: they reject noise blobs
    params.maxArea = max(float(params.maxArea), grey.size / board.count)
    return cv2.SimpleBlobDetector_create(params)


def find_opencv_grid(grey: np.ndarray, board: Board) -> np.ndarray | None:
    """Centres (rows*cols, 2) px in :meth:`Board.dot_positions` order, or None. Rough
    centres: they only order the dots, which our blobs then measure. The grid is searched
    in the image as it is, then in copies shrunk by 2 and 4 (:data:`GRID_SHRINKS`):
    ``cv2.findCirclesGrid`` finds every dot of a large sensor's view and still fails to
    order them when they lie far apart in pixels (an 11 x 4 asymmetric grid found at
    1280 x 960 px was lost at 1920 x 1440)."""
    import cv2

    flags = (cv2.CALIB_CB_SYMMETRIC_GRID if board.kind == "opencv-circles"
             else cv2.CALIB_CB_ASYMMETRIC_GRID)
    for shrink in GRID_SHRINKS:
        if shrink < 1.0 and min(grey.shape) * shrink < MIN_SEARCH_PX:
            break
        small = grey if shrink == 1.0 else cv2.resize(grey, None, fx=shrink, fy=shrink,
                                                      interpolation=cv2.INTER_AREA)
        found, centres = cv2.findCirclesGrid(small, (board.cols, board.rows), flags=flags,
                                             blobDetector=_detector(small, board))
        if found and centres is not None and len(centres) == board.count:
            return (centres.reshape(-1, 2).astype(float) + 0.5) / shrink - 0.5
    return None


def right_handed(board: Board, centres: np.ndarray) -> np.ndarray | None:
    """``centres`` (n, 2) px ordered so that the board frame is seen from its printed side
    (z < 0): board x and y turn the same way as image columns and rows (positive Jacobian
    determinant of board plane -> image at the grid's centre). A mirrored symmetric grid is
    put right by reversing each row; a mirrored asymmetric one gives None."""
    import cv2

    flat = board.dot_positions()[:, :2]
    H, _ = cv2.findHomography(flat, centres)
    if H is None:
        return None
    centre = board.centre()[:2]
    step = board.pitch_m
    corners = np.array([centre, centre + [step, 0.0], centre + [0.0, step]])
    at = cv2.perspectiveTransform(corners[None], H)[0]
    du, dv = at[1] - at[0], at[2] - at[0]
    if du[0] * dv[1] - du[1] * dv[0] > 0:
        return centres
    if board.kind in ("opencv-circles", "chessboard"):
        rows, cols = board.grid_shape
        return centres.reshape(rows, cols, 2)[:, ::-1].reshape(-1, 2)
    return None


def charuco_corners(grey: np.ndarray, board: Board) -> tuple[np.ndarray, np.ndarray] | str:
    """The corners a charuco board shows: (pixels (m, 2) px, their indices (m,) in
    :meth:`Board.dot_positions` order, increasing), or why none can be used (fewer than
    :data:`MIN_CORNERS`, or all on one row or column)."""
    import cv2

    dictionary_id = getattr(cv2.aruco, board.dictionary, None)
    if not isinstance(dictionary_id, int):
        raise DataError(f"board: OpenCV has no ArUco dictionary {board.dictionary!r}")
    opencv_board = cv2.aruco.CharucoBoard((board.cols, board.rows), board.pitch_m,
                                          board.dot_diameter_m,
                                          cv2.aruco.getPredefinedDictionary(dictionary_id))
    corners, ids, _, _ = cv2.aruco.CharucoDetector(opencv_board).detectBoard(grey)
    found = 0 if ids is None else len(ids)
    if found < MIN_CORNERS:
        return (f"{found} of the charuco board's {board.count} corners found "
                f"(cv2.aruco.CharucoDetector), need at least {MIN_CORNERS}")
    ids = np.asarray(ids).ravel()
    order = np.argsort(ids)
    indices = ids[order].astype(int)
    rows, cols = np.divmod(indices, board.grid_shape[1])
    if len(set(rows.tolist())) < 2 or len(set(cols.tolist())) < 2:
        return (f"the {found} charuco corners found lie on one row or column: they do not "
                f"fix the board's pose")
    return np.asarray(corners, dtype=float).reshape(-1, 2)[order], indices


def find_charuco_corners(grey: np.ndarray, board: Board) -> np.ndarray | str:
    """A charuco board's inner corners (n, 2) px in :meth:`Board.dot_positions` order, or
    why not: every corner must be found (as every dot of our boards must)."""
    found = charuco_corners(grey, board)
    if isinstance(found, str):
        return found
    corners, indices = found
    if len(indices) != board.count:
        return (f"{len(indices)} of the charuco board's {board.count} corners found "
                f"(cv2.aruco.CharucoDetector): the whole board must be in view")
    return corners


def find_chessboard_corners(grey: np.ndarray, board: Board) -> np.ndarray | str:
    """A chessboard's inner corners (n, 2) px in :meth:`Board.dot_positions` order (up to
    the board's half-turn ambiguity), by ``cv2.findChessboardCornersSB``, or why not."""
    import cv2

    rows, cols = board.grid_shape
    flags = cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
    shrink = min(1.0, CHESSBOARD_SEARCH_PX / max(grey.shape))
    small = grey if shrink == 1.0 else cv2.resize(grey, None, fx=shrink, fy=shrink,
                                                  interpolation=cv2.INTER_AREA)
    found, corners = cv2.findChessboardCornersSB(small, (cols, rows), flags=flags)
    if not found or corners is None or len(corners) != board.count:
        return (f"no {board.rows} x {board.cols}-square chessboard ({rows} x {cols} inner "
                f"corners) found whole (cv2.findChessboardCornersSB)")
    corners = corners.reshape(-1, 2).astype(float)
    if shrink < 1.0:
        corners = _full_resolution(grey, (corners + 0.5) / shrink - 0.5, (rows, cols))
    ordered = right_handed(board, corners)
    if ordered is None:
        return "the chessboard's corners could not be ordered"
    return ordered


def _full_resolution(grey: np.ndarray, corners: np.ndarray, shape) -> np.ndarray:
    """Corners found on a shrunk image (n, 2), scaled back (px), refined on the full image
    by ``cv2.cornerSubPix`` in a window of a quarter of the corner spacing."""
    import cv2

    grid = corners.reshape(*shape, 2)
    spacing = min(np.median(np.linalg.norm(np.diff(grid, axis=0), axis=2)),
                  np.median(np.linalg.norm(np.diff(grid, axis=1), axis=2)))
    half = int(np.clip(spacing / 4, 2, 30))
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 0.001)
    refined = cv2.cornerSubPix(grey, corners.astype(np.float32).reshape(-1, 1, 2),
                               (half, half), (-1, -1), criteria)
    return refined.reshape(-1, 2).astype(float)


def check_measurable(board: Board) -> None:
    """:class:`DataError` for a board whose views do not fix the board frame."""
    if board.kind in ("opencv-circles", "chessboard"):
        what = ("a symmetric circle grid (opencv-circles)" if board.kind == "opencv-circles"
                else "a chessboard")
        raise DataError(f"board: {what} is ambiguous by a half turn, so a camera pose "
                        "measured on it may be turned 180 deg; use it to calibrate the "
                        "camera, and measure with an olp-dots, opencv-acircles or charuco "
                        "board")
