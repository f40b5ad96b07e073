"""One image's board, whatever its kind (:data:`.board.KINDS`): which of its dots (or
corners) were found, and where.

Our dot boards and OpenCV's circle grids are found whole or not at all
(:func:`.detect.detect_dots`); a chessboard whole (:func:`.detect_opencv.find_chessboard_corners`);
a charuco board gives the corners it shows (:func:`.detect_opencv.charuco_corners`), so
that views with the board partly outside the image, or partly hidden, still calibrate.
Calibration and pose measurement take the found dots with their own board points
(:meth:`FoundView.points`), so a partial view needs nothing else.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .board import CORNER_KINDS, Board
from .detect import DetectionFailure, circle_centre_bias, detect_dots
from .detect_opencv import charuco_corners, find_chessboard_corners


@dataclass(frozen=True, eq=False)
class FoundView:
    """The board in image ``name``: ``pixels`` (m, 2) px (column, row) of the dots (or
    corners) found, ``indices`` (m,) their rows in :meth:`Board.dot_positions`, ``total``
    the board's number of dots."""

    name: str
    pixels: np.ndarray
    indices: np.ndarray
    total: int
    ok = True

    @property
    def partial(self) -> bool:
        """True when only some of the board's dots were found."""
        return len(self.indices) < self.total

    def points(self, board: Board) -> np.ndarray:
        """The found dots in the board frame (m, 3), m."""
        return board.dot_positions()[self.indices]

    def describe(self) -> str:
        """"" for a whole board, else e.g. " (31 of 54 corners: part of the board)"."""
        if not self.partial:
            return ""
        return f" ({len(self.indices)} of {self.total} corners: part of the board)"


def find_board(grey: np.ndarray, board: Board, name: str = "<image>"
               ) -> FoundView | DetectionFailure:
    """The board in an 8-bit grey image (h, w) (:class:`FoundView`), or why not."""
    if board.kind == "charuco":
        found = charuco_corners(grey, board)
        if isinstance(found, str):
            return DetectionFailure(name, found)
        return FoundView(name, found[0], found[1], board.count)
    if board.kind == "chessboard":
        corners = find_chessboard_corners(grey, board)
        if isinstance(corners, str):
            return DetectionFailure(name, corners)
        return FoundView(name, corners, np.arange(board.count), board.count)
    result = detect_dots(grey, board, name)
    if not result.ok:
        return result
    return FoundView(name, result.pixels, np.arange(board.count), board.count)


def centre_bias_of(board: Board, correct: bool = True
                   ) -> Callable[[object, np.ndarray], np.ndarray] | None:
    """The circle-centre bias function for :func:`.calibrate.calibrate` and
    :func:`.measure.measure_pose`, or None: corners have none, and ``correct`` False asks
    for the centroids as they are."""
    if not correct or board.kind in CORNER_KINDS:
        return None
    return lambda intrinsics, camera_T_board: circle_centre_bias(intrinsics, camera_T_board,
                                                                 board)
