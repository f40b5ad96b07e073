"""The calibration board: a grid of dark printed circles on a light sheet, and board.json.

Board frame: origin at the centre of dot (0, 0), x towards increasing column, y towards
increasing row, z = x × y (the camera looks at the printed face from z < 0). Dot (r, c) is
at ``(c * pitch, r * pitch, 0)``; "dot" means the centre of the printed circle. Dot (0, 0)
is the *marker*: drawn with ``marker_diameter`` so that the orientation is unambiguous.

board.json (mm at the file edge)::

    {"rows": 9, "cols": 9, "pitch_mm": 25.0, "dot_diameter_mm": 5.0,
     "marker_diameter_mm": 8.0}

plus, optionally, ``"kind"`` (:data:`KINDS`; default "olp-dots", this module's board):
"opencv-circles" is OpenCV's symmetric circle grid (``rows`` x ``cols`` circles, ``pitch``
apart, no marker; its orientation is ambiguous by a half turn, so it calibrates a camera but
does not measure poses), "opencv-acircles" OpenCV's asymmetric grid (row r, column c at
``((2 c + r % 2) pitch, r pitch)``, as OpenCV's samples lay it out; ``cols`` circles per
row); both found by ``cv2.findCirclesGrid``; "charuco" is OpenCV's ChArUco board, ``cols`` x
``rows`` squares of ``pitch_mm`` with ArUco markers of ``marker_mm`` from ``dictionary``
(an OpenCV name, e.g. "DICT_4X4_50"), its "dots" the (rows - 1) x (cols - 1) inner chessboard
corners at ``((c + 1) pitch, (r + 1) pitch)`` (OpenCV's board frame, origin at the board's
corner), found by ``cv2.aruco.CharucoDetector`` (a view may show part of the board); it is
not drawn or rendered here (OpenCV's ``generateImage`` prints it). "chessboard" is a plain
chessboard of ``cols`` x ``rows`` squares of ``pitch_mm`` (its "dots" the inner corners,
laid out as a charuco board's), found whole by ``cv2.findChessboardCornersSB``; like a
symmetric circle grid it has no marker, so it calibrates but does not measure poses.

And, optionally, ``"scale_bar_mm"``: the nominal length of the printed scale bar (default
:data:`SCALE_BAR_MM`; written only when it differs), which the user measures on the print
to fix the board's scale (:mod:`.scale`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..kinematics.conventions import MM
from ..errors import DataError
from ..io.atomic import write_text_atomic

BOARD_KEYS = ("rows", "cols", "pitch_mm", "dot_diameter_mm", "marker_diameter_mm")
KINDS = ("olp-dots", "opencv-circles", "opencv-acircles", "charuco", "chessboard")
"""Board kinds board.json may name (module docstring)."""
CORNER_KINDS = ("charuco", "chessboard")
"""Kinds whose "dots" are chessboard corners: no circle-centre bias, (rows - 1) x (cols - 1)
inner corners of ``rows`` x ``cols`` squares."""
READ_KINDS = KINDS
SCALE_BAR_MM = 100.0
"""Nominal length of the printed scale bar, mm (board.json's optional ``scale_bar_mm``)."""
MAX_DOTS_PER_SIDE = 100
"""Most rows or columns of a board: 100 x 100 dots, far beyond any calibration board (a
2000 x 2000 board took minutes into a memory error)."""
MAX_SHEET_M = 3.0
"""Largest sheet side, m (a board is printed and glued flat on a rigid plate)."""


@dataclass(frozen=True)
class SheetExtent:
    """The light sheet around the dots, a rectangle in the board frame (m)."""

    x_min: float
    x_max: float
    y_min: float
    y_max: float

    @property
    def width(self) -> float:
        """Extent along board x, m."""
        return self.x_max - self.x_min

    @property
    def height(self) -> float:
        """Extent along board y, m."""
        return self.y_max - self.y_min


@dataclass(frozen=True)
class Board:
    """A dot board. rows, cols : grid size (>= 3 each). pitch_m : centre-to-centre distance
    (m). dot_diameter_m : printed circle diameter (m). marker_diameter_m : diameter of dot
    (0, 0), larger than the others (m)."""

    rows: int
    cols: int
    pitch_m: float
    dot_diameter_m: float
    marker_diameter_m: float
    scale_bar_m: float = SCALE_BAR_MM * MM
    kind: str = "olp-dots"
    dictionary: str = ""

    def __post_init__(self):
        if self.kind not in READ_KINDS:
            known = ", ".join(f'"{k}"' for k in READ_KINDS)
            raise DataError(f"board: kind {self.kind!r} is not read yet (known: {known})"
                            if self.kind in KINDS else
                            f"board: unknown kind {self.kind!r} (known: {known})")
        for name in ("rows", "cols"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) \
                    or value < 3:
                raise DataError(f"board: {name} must be an integer >= 3, got {value!r}")
            if value > MAX_DOTS_PER_SIDE:
                raise DataError(f"board: {name} = {value}: at most {MAX_DOTS_PER_SIDE} dots "
                                f"per side")
        for name in ("pitch_m", "dot_diameter_m", "marker_diameter_m", "scale_bar_m"):
            value = getattr(self, name)
            if not isinstance(value, (int, float, np.floating, np.integer)) \
                    or not math.isfinite(value) or value <= 0:
                raise DataError(f"board: {name} must be a positive number, got {value!r}")
        if self.kind == "charuco":
            self._check_charuco()
            return
        if self.kind == "chessboard":
            return
        if self.kind == "olp-dots" and self.marker_diameter_m <= self.dot_diameter_m * 1.2:
            raise DataError(
                f"board: the marker diameter ({self.marker_diameter_m / MM:g} mm) must be at "
                f"least 1.2 times the dot diameter ({self.dot_diameter_m / MM:g} mm) to be "
                "told apart")
        # the marker and its neighbour must leave a gap of at least one dot radius
        neighbour = self.pitch_m * (math.sqrt(2) if self.kind == "opencv-acircles" else 1.0)
        largest = self.marker_diameter_m if self.kind == "olp-dots" else self.dot_diameter_m
        gap = neighbour - (largest + self.dot_diameter_m) / 2
        if gap < self.dot_diameter_m / 2:
            raise DataError(
                f"board: dots overlap or nearly touch: pitch {self.pitch_m / MM:g} mm leaves "
                f"{gap / MM:g} mm between the marker and its neighbour, need at least "
                f"{self.dot_diameter_m / 2 / MM:g} mm")
        sheet = self.sheet_extent()
        if max(sheet.width, sheet.height) > MAX_SHEET_M:
            raise DataError(f"board: the sheet would be {sheet.width / MM:.0f} x "
                            f"{sheet.height / MM:.0f} mm; at most {MAX_SHEET_M / MM:.0f} mm "
                            f"a side (fewer dots or a smaller pitch)")

    def _check_charuco(self) -> None:
        if not self.dictionary.startswith("DICT_"):
            raise DataError(f"board: a charuco board names its ArUco dictionary as OpenCV "
                            f"does (e.g. \"DICT_4X4_50\"), got {self.dictionary!r}")
        if self.dot_diameter_m >= self.pitch_m:
            raise DataError(f"board: the markers ({self.dot_diameter_m / MM:g} mm) must be "
                            f"smaller than the squares ({self.pitch_m / MM:g} mm)")

    @property
    def grid_shape(self) -> tuple[int, int]:
        """(rows, columns) of the dots (a charuco board's or chessboard's inner corners)."""
        if self.kind in CORNER_KINDS:
            return self.rows - 1, self.cols - 1
        return self.rows, self.cols

    @property
    def count(self) -> int:
        """Number of dots, rows * cols (a charuco board, a chessboard: its inner corners)."""
        rows, cols = self.grid_shape
        return rows * cols

    def dot_positions(self) -> np.ndarray:
        """Dot centres, shape (rows*cols, 3), m, board frame, row-major (index r*cols + c);
        an asymmetric grid's row r is shifted by ``r % 2`` pitches, its dots 2 pitches
        apart."""
        r, c = np.divmod(np.arange(self.count), self.grid_shape[1])
        if self.kind == "opencv-acircles":
            c = 2 * c + r % 2
        elif self.kind in CORNER_KINDS:
            r, c = r + 1, c + 1
        return np.stack([c * self.pitch_m, r * self.pitch_m, np.zeros(self.count)], -1)

    def centre(self) -> np.ndarray:
        """The middle of the dot grid's extent (3,), board frame, m."""
        p = self.dot_positions()
        return (p.min(axis=0) + p.max(axis=0)) / 2

    def nearest_dot(self, x: np.ndarray, y: np.ndarray):
        """(dot x, dot y, inside the grid, is the marker) of the dot nearest to board points
        (x, y) (m) whenever they lie within half a pitch of one (arrays like ``x``)."""
        p = self.pitch_m
        r = np.rint(y / p)
        if self.kind == "opencv-acircles":
            shift = np.mod(r, 2)
            j = np.rint((x / p - shift) / 2)
            c, inside_c = 2 * j + shift, (j >= 0) & (j < self.cols)
        else:
            c = np.rint(x / p)
            inside_c = (c >= 0) & (c < self.cols)
        inside = inside_c & (r >= 0) & (r < self.rows)
        marker = (c == 0) & (r == 0) if self.kind == "olp-dots" else np.zeros_like(inside)
        return c * p, r * p, inside, marker

    def dot_grid(self) -> np.ndarray:
        """(row, column) of every dot, shape (rows*cols, 2), int, row-major."""
        r, c = np.divmod(np.arange(self.count), self.grid_shape[1])
        return np.stack([r, c], -1)

    def dot_radii(self) -> np.ndarray:
        """Printed radius of every dot, shape (rows*cols,), m (index 0 is the marker)."""
        radii = np.full(self.count,
                        0.0 if self.kind in CORNER_KINDS else self.dot_diameter_m / 2)
        if self.kind == "olp-dots":
            radii[0] = self.marker_diameter_m / 2
        return radii

    def sheet_extent(self) -> SheetExtent:
        """The light sheet the dots are printed on: one pitch beyond the outer dots' edges."""
        if self.kind in CORNER_KINDS:
            return SheetExtent(0.0, self.cols * self.pitch_m, 0.0, self.rows * self.pitch_m)
        margin = self.pitch_m + float(np.max(self.dot_radii()))
        last = self.dot_positions().max(axis=0)
        return SheetExtent(-margin, last[0] + margin, -margin, last[1] + margin)


def board_from_dict(data: dict, source: str = "<board>") -> Board:
    """A :class:`Board` from the board.json mapping (mm); ``source`` names it in errors."""
    if not isinstance(data, dict):
        raise DataError(f"{source}: expected a JSON object with keys {', '.join(BOARD_KEYS)}, "
                        f"got {type(data).__name__}")
    kind = data.get("kind", "olp-dots")
    if not isinstance(kind, str):
        raise DataError(f"{source}: 'kind' must be a string, got {kind!r}")
    if kind == "charuco":
        return _charuco_from_dict(data, source)
    if kind == "chessboard":
        return _chessboard_from_dict(data, source)
    if kind != "olp-dots" and "marker_diameter_mm" not in data:
        data = {**data, "marker_diameter_mm": data.get("dot_diameter_mm")}
    for key in BOARD_KEYS:
        if key not in data:
            raise DataError(f"{source}: missing key '{key}'")
    for key in ("rows", "cols"):
        if isinstance(data[key], bool) or not isinstance(data[key], int):
            raise DataError(f"{source}: '{key}' must be an integer, got {data[key]!r}")
    for key in BOARD_KEYS[2:]:
        if isinstance(data[key], bool) or not isinstance(data[key], (int, float)):
            raise DataError(f"{source}: '{key}' must be a number, got {data[key]!r}")
    bar = data.get("scale_bar_mm", SCALE_BAR_MM)
    if isinstance(bar, bool) or not isinstance(bar, (int, float)):
        raise DataError(f"{source}: 'scale_bar_mm' must be a number, got {bar!r}")
    try:
        return Board(rows=data["rows"], cols=data["cols"], pitch_m=data["pitch_mm"] * MM,
                     dot_diameter_m=data["dot_diameter_mm"] * MM,
                     marker_diameter_m=data["marker_diameter_mm"] * MM,
                     scale_bar_m=bar * MM, kind=kind)
    except DataError as exc:
        raise DataError(f"{source}: {exc}") from None


def _charuco_from_dict(data: dict, source: str) -> Board:
    for key in ("rows", "cols", "pitch_mm", "marker_mm", "dictionary"):
        if key not in data:
            raise DataError(f"{source}: a charuco board needs '{key}' (rows, cols: squares; "
                            f"pitch_mm: square side; marker_mm; dictionary)")
    for key in ("pitch_mm", "marker_mm"):
        if isinstance(data[key], bool) or not isinstance(data[key], (int, float)):
            raise DataError(f"{source}: '{key}' must be a number, got {data[key]!r}")
    if not isinstance(data["dictionary"], str):
        raise DataError(f"{source}: 'dictionary' must be a string")
    try:
        return Board(rows=data["rows"], cols=data["cols"], pitch_m=data["pitch_mm"] * MM,
                     dot_diameter_m=data["marker_mm"] * MM,
                     marker_diameter_m=data["marker_mm"] * MM, kind="charuco",
                     dictionary=data["dictionary"])
    except DataError as exc:
        raise DataError(f"{source}: {exc}") from None


def _chessboard_from_dict(data: dict, source: str) -> Board:
    for key in ("rows", "cols", "pitch_mm"):
        if key not in data:
            raise DataError(f"{source}: a chessboard needs '{key}' (rows, cols: squares; "
                            f"pitch_mm: square side)")
    if isinstance(data["pitch_mm"], bool) or not isinstance(data["pitch_mm"], (int, float)):
        raise DataError(f"{source}: 'pitch_mm' must be a number, got {data['pitch_mm']!r}")
    try:
        return Board(rows=data["rows"], cols=data["cols"], pitch_m=data["pitch_mm"] * MM,
                     dot_diameter_m=data["pitch_mm"] * MM,
                     marker_diameter_m=data["pitch_mm"] * MM, kind="chessboard")
    except DataError as exc:
        raise DataError(f"{source}: {exc}") from None


def board_to_dict(board: Board) -> dict:
    """The board.json mapping (mm) of ``board``."""
    if board.kind == "chessboard":
        return {"kind": "chessboard", "rows": int(board.rows), "cols": int(board.cols),
                "pitch_mm": _mm(board.pitch_m)}
    if board.kind == "charuco":
        return {"kind": "charuco", "rows": int(board.rows), "cols": int(board.cols),
                "pitch_mm": _mm(board.pitch_m), "marker_mm": _mm(board.dot_diameter_m),
                "dictionary": board.dictionary}
    doc = {"rows": int(board.rows), "cols": int(board.cols),
           "pitch_mm": _mm(board.pitch_m), "dot_diameter_mm": _mm(board.dot_diameter_m),
           "marker_diameter_mm": _mm(board.marker_diameter_m)}
    if _mm(board.scale_bar_m) != SCALE_BAR_MM:
        doc["scale_bar_mm"] = _mm(board.scale_bar_m)
    if board.kind != "olp-dots":
        doc["kind"] = board.kind
    return doc


def _mm(metres: float) -> float:
    # 25.0 mm stays 25.0 in the file, not 25.000000000000004
    return round(float(metres) / MM, 9)


def read_board(path: str | Path) -> Board:
    """Read board.json (mm) into a :class:`Board` (m)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror})") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise DataError(f"{path}:{exc.lineno}:{exc.colno}: not valid JSON ({exc.msg})") from None
    return board_from_dict(data, str(path))


def write_board(board: Board, path: str | Path) -> None:
    """Write ``board`` as board.json (mm), atomically (temporary file, then rename)."""
    write_text_atomic(path, json.dumps(board_to_dict(board), indent=2) + "\n")
