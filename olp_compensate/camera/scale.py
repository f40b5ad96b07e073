"""The board's scale: a stated unknown, fixed only by a length reference.

The views and the robot's joints cannot tell a board printed 0.1 % large from the nominal
one: every measured camera position scales about the board's dot (0, 0) by the print's
error, the arm's identified lengths follow, and the cross-validated residual stays as small
as before. Only a measured length fixes it:

- the printed scale bar measured with a caliper (``--scale-bar-mm L``; its nominal length
  is board.json's ``scale_bar_mm``, 100 mm as :mod:`.drawing` prints it);
- distances between dots measured on a CMM (``--reference FILE``: ``row_a, col_a, row_b,
  col_b, distance_mm``), the factor fitted by least squares.

The factor (printed / nominal, isotropic) scales the board's pitch and dot sizes; the
intrinsics do not depend on it, every length measured with the board does. Without a
reference, :func:`unverified_note` says what a typical office print error (0.1-0.3 %) does
to a length at the distance the commands work at.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import DataError
from ..io.measurements import parse_cell_number, read_csv_text
from ..kinematics.conventions import MM

if TYPE_CHECKING:  # annotations only (olp-cal identify imports this module for one check)
    from .board import Board

PRINT_ERROR = (0.001, 0.003)
"""A typical office printer's scale error, fraction (0.1-0.3 %)."""
MAX_SCALE_ERROR = 0.05
"""Largest believable print error, fraction: a factor further from 1 is a wrong reference
(the bar misread, another board), refused."""
SOURCES = ("unverified", "scale bar", "reference")
REFERENCE_COLUMNS = ("row_a", "col_a", "row_b", "col_b", "distance_mm")
SCALE_LINE = "# board scale: "
"""Start of the metadata line ``camera measure --joints`` writes; ``identify`` reads it."""


@dataclass(frozen=True)
class BoardScale:
    """The printed board's size against board.json: ``factor`` printed / nominal; ``source``
    one of :data:`SOURCES`; ``detail`` how it was found, in words; ``residual_mm`` the RMS
    misfit of a reference's distances (None otherwise)."""

    factor: float = 1.0
    source: str = "unverified"
    detail: str = "board.json's nominal pitch, not checked against a length reference"
    residual_mm: float | None = None

    @property
    def verified(self) -> bool:
        return self.source != "unverified"

    def to_dict(self) -> dict:
        """The ``scale`` entry of camera.json."""
        return {"source": self.source, "factor": self.factor, "detail": self.detail,
                "residual_mm": self.residual_mm}

    @classmethod
    def from_dict(cls, doc: dict | None) -> "BoardScale":
        """From camera.json's ``scale`` entry (files without one: unverified)."""
        if not doc:
            return cls()
        return cls(factor=float(doc["factor"]), source=doc["source"], detail=doc["detail"],
                   residual_mm=doc.get("residual_mm"))

    def summary(self) -> str:
        """One line for printouts and CSV metadata."""
        if not self.verified:
            return f"unverified ({self.detail})"
        return (f"{self.source}: printed board {self.factor:.6f} x nominal "
                f"({(self.factor - 1) * 100:+.3f} %); {self.detail}")


def _check_factor(factor: float, what: str) -> None:
    if not (math.isfinite(factor) and abs(factor - 1) <= MAX_SCALE_ERROR):
        raise DataError(f"{what}: gives the printed board {factor:.5g} times its nominal size; "
                        f"a print is within {MAX_SCALE_ERROR * 100:g} % (wrong length, or "
                        f"another board?)")


def from_scale_bar(measured_mm: float, nominal_mm: float) -> BoardScale:
    """The scale from the printed bar measured ``measured_mm`` long (nominal
    ``nominal_mm``)."""
    what = f"--scale-bar-mm {measured_mm:g}"
    if not (math.isfinite(measured_mm) and measured_mm > 0):
        raise DataError(f"{what}: expected the measured length of the printed bar, mm")
    factor = measured_mm / nominal_mm
    _check_factor(factor, f"{what} (the bar's nominal length is {nominal_mm:g} mm)")
    return BoardScale(factor=factor, source="scale bar",
                      detail=f"scale bar measured {measured_mm:g} mm, nominal {nominal_mm:g} mm")


def read_reference(path: str | Path, board: Board) -> BoardScale:
    """The scale fitted to measured distances between dots (CSV: ``row_a, col_a, row_b,
    col_b, distance_mm``; ``#`` lines skipped): factor = sum(d_meas d_nom) / sum(d_nom^2)."""
    source = str(path)
    text = read_csv_text(path, "a reference CSV (row_a, col_a, row_b, col_b, distance_mm)")
    numbered = [(n, line) for n, line in enumerate(text.splitlines(), start=1)
                if line.strip() and not line.lstrip().startswith("#")]
    if not numbered:
        raise DataError(f"{source}: empty; expected a header {', '.join(REFERENCE_COLUMNS)}")
    rows = list(csv.reader(io.StringIO("\n".join(line for _, line in numbered))))
    header = [h.strip() for h in rows[0]]
    missing = [c for c in REFERENCE_COLUMNS if c not in header]
    if missing:
        raise DataError(f"{source}:{numbered[0][0]}: missing column(s) {', '.join(missing)}")
    nominal, measured = [], []
    for (line, _), record in zip(numbered[1:], rows[1:]):
        if len(record) != len(header):
            raise DataError(f"{source}:{line}: {len(record)} fields, the header has "
                            f"{len(header)}")
        cell = dict(zip(header, record))
        dots = []
        for column, size in zip(REFERENCE_COLUMNS[:4], board.grid_shape * 2):
            value = parse_cell_number(cell[column], source, line, column)
            if value != int(value) or not 0 <= value < size:
                raise DataError(f"{source}:{line}: column '{column}': {cell[column].strip()} "
                                f"is not a dot of the {board.grid_shape[0]} x "
                                f"{board.grid_shape[1]} grid")
            dots.append(int(value))
        positions = board.dot_positions()
        a = positions[dots[0] * board.grid_shape[1] + dots[1], :2]
        b = positions[dots[2] * board.grid_shape[1] + dots[3], :2]
        length = float(np.linalg.norm(a - b))
        if length == 0:
            raise DataError(f"{source}:{line}: the two dots are the same")
        nominal.append(length)
        measured.append(parse_cell_number(cell["distance_mm"], source, line,
                                          "distance_mm") * MM)
    if not nominal:
        raise DataError(f"{source}: no data rows after the header")
    nominal, measured = np.array(nominal), np.array(measured)
    factor = float(nominal @ measured / (nominal @ nominal))
    _check_factor(factor, source)
    residual = float(np.sqrt(np.mean((measured - factor * nominal) ** 2)) / MM)
    return BoardScale(factor=factor, source="reference", residual_mm=residual,
                      detail=f"{len(nominal)} measured distances in {Path(source).name}, RMS "
                             f"misfit {residual:.3f} mm")


def unverified_rows(metadata) -> bool:
    """Whether a measurement CSV's metadata lines say its rows were measured with a board
    of unverified scale."""
    return any(line.startswith(SCALE_LINE + "unverified") for line in metadata)


def scaled_board(board: Board, scale: BoardScale) -> Board:
    """``board`` as printed: pitch and dot sizes times ``scale.factor``."""
    if scale.factor == 1.0:
        return board
    return replace(board, pitch_m=board.pitch_m * scale.factor,
                   dot_diameter_m=board.dot_diameter_m * scale.factor,
                   marker_diameter_m=board.marker_diameter_m * scale.factor)


def unverified_note(distance_mm: float) -> str:
    """The warning printed once by a command measuring lengths with an unverified board:
    what a typical print error does at ``distance_mm`` (the median working distance)."""
    low, high = (distance_mm * e for e in PRINT_ERROR)
    return (f"WARNING: board scale unverified (board.json's nominal pitch): a print error of "
            f"{PRINT_ERROR[0] * 100:g}-{PRINT_ERROR[1] * 100:g} % scales every measured length "
            f"by as much, {low:.2f}-{high:.2f} mm at the {distance_mm:.0f} mm working distance "
            f"here, and the robot identified from it; measure the printed scale bar "
            f"(--scale-bar-mm) or dots (--reference)")
