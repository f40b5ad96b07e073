"""The board's length reference on the camera commands' command lines (``--scale-bar-mm``,
``--reference``) and the scale line they print (:mod:`olp_compensate.camera.scale`)."""

from __future__ import annotations

import numpy as np

from ..camera.board import Board
from ..camera.scale import BoardScale, from_scale_bar, read_reference, unverified_note
from ..kinematics.conventions import MM


def add_scale_arguments(p, inherit: bool = False) -> None:
    """``--scale-bar-mm`` / ``--reference``: the board's length reference
    (:mod:`olp_compensate.camera.scale`)."""
    g = p.add_mutually_exclusive_group()
    more = " (default: the scale camera.json records)" if inherit else ""
    g.add_argument("--scale-bar-mm", type=float, metavar="L",
                   help="the printed scale bar as measured with a caliper, mm (nominal: "
                        "board.json's scale_bar_mm, 100)" + more)
    g.add_argument("--reference", metavar="CSV",
                   help="measured distances between dots: row_a, col_a, row_b, col_b, "
                        "distance_mm" + more)


def board_scale(args, board: Board, recorded: BoardScale | None = None) -> BoardScale:
    """The scale the options give, else ``recorded`` (camera.json's) when verified, else
    unverified."""
    if args.scale_bar_mm is not None:
        return from_scale_bar(args.scale_bar_mm, board.scale_bar_m / MM)
    if args.reference:
        return read_reference(args.reference, board)
    return recorded if recorded is not None and recorded.verified else BoardScale()


def print_scale(scale: BoardScale, distances_mm) -> None:
    """The scale line, and once the unverified warning at the median working distance."""
    print(f"board scale: {scale.summary()}")
    if not scale.verified and len(distances_mm):
        print(unverified_note(float(np.median(distances_mm))))
