"""Pictures of the board: the sheet to print (SVG in mm, PNG at a stated dpi) and the
detection picture for the report.

The printed sheet is :meth:`Board.sheet_extent`; on the page, board x runs to the right and
board y down (so the reader faces the printed side, seeing it from board z < 0, as the
camera does). A scale bar (100 mm unless board.json says otherwise) with its label and the board parameters sit in the margin
below the last row, away from the grid.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

from ..kinematics.conventions import MM
from ..errors import DataError
from ..io.atomic import write_bytes_atomic, write_text_atomic
from .board import Board


_TEXT_MM = 3.0  # height of the small text, mm
MAX_PNG_PIXELS = 60e6
"""Largest PNG drawn, pixels (an A1 sheet at 300 dpi); the SVG has no such limit."""
PAPER_MM = {"A4": (210.0, 297.0), "Letter": (215.9, 279.4)}
"""Paper sizes, mm (ISO 216; ANSI letter)."""
PRINTER_MARGIN_MM = 5.0
"""Unprintable border of an office printer on each side, mm."""


def fits_on(board: Board) -> list[str]:
    """The paper sizes (of :data:`PAPER_MM`) whose printable area holds the sheet, in
    either orientation."""
    sheet = board.sheet_extent()
    w, h = sorted((sheet.width / MM, sheet.height / MM))
    return [name for name, (pw, ph) in PAPER_MM.items()
            if w <= pw - 2 * PRINTER_MARGIN_MM and h <= ph - 2 * PRINTER_MARGIN_MM]


def check_png_size(board: Board, dpi: float) -> None:
    """:class:`DataError` when the PNG at ``dpi`` would exceed :data:`MAX_PNG_PIXELS` or the
    dpi is outside 50-2400."""
    if not np.isfinite(dpi) or not 50 <= dpi <= 2400:
        raise DataError(f"board drawing: dpi must be 50-2400, got {dpi!r}")
    sheet = board.sheet_extent()
    pixels = (sheet.width / MM * dpi / 25.4) * (sheet.height / MM * dpi / 25.4)
    if pixels > MAX_PNG_PIXELS:
        raise DataError(f"board drawing: a {sheet.width / MM:.0f} x {sheet.height / MM:.0f} mm "
                        f"sheet at {dpi:g} dpi is {pixels / 1e6:.0f} million pixels, above "
                        f"{MAX_PNG_PIXELS / 1e6:.0f} million; lower --dpi or print the SVG")


def _layout(board: Board) -> dict:
    """Page geometry in mm, origin at the sheet's top-left corner."""
    sheet = board.sheet_extent()
    width, height = sheet.width / MM, sheet.height / MM
    x0, y0 = -sheet.x_min / MM, -sheet.y_min / MM  # page position of dot (0, 0)
    last_row = y0 + (board.rows - 1) * board.pitch_m / MM
    margin = sheet.y_max / MM - (board.rows - 1) * board.pitch_m / MM
    bar_y = last_row + 0.5 * margin
    return {"width": width, "height": height, "x0": x0, "y0": y0, "bar_x": x0,
            "bar_y": bar_y, "bar_h": 1.0, "label_y": bar_y + 1.0,
            "params_y": min(last_row + 0.85 * margin, height - 1.0)}


def _parameters_text(board: Board) -> str:
    if board.kind != "olp-dots":
        return (f"{board.kind} {board.rows} x {board.cols}, pitch {board.pitch_m / MM:g} mm, "
                f"dot {board.dot_diameter_m / MM:g} mm - print at 100 %")
    return (f"{board.rows} x {board.cols} dots, pitch {board.pitch_m / MM:g} mm, "
            f"dot {board.dot_diameter_m / MM:g} mm, marker (row 0, col 0) "
            f"{board.marker_diameter_m / MM:g} mm - print at 100 %")


def _drawable(board: Board) -> None:
    if board.kind == "charuco":
        raise DataError("board drawing: a charuco board is printed from OpenCV's "
                        "CharucoBoard.generateImage, not drawn here")
    if board.kind == "chessboard":
        raise DataError("board drawing: chessboards are not drawn here (OpenCV's "
                        "samples/data/chessboard.png, or any print with measured squares)")


def board_svg(board: Board) -> str:
    """The board as an SVG document in mm (1 user unit = 1 mm), exact circles."""
    _drawable(board)
    g = _layout(board)
    dots = []
    for (x, y, _), r in zip(board.dot_positions() / MM, board.dot_radii() / MM):
        dots.append(f'    <circle cx="{g["x0"] + x:.4f}" cy="{g["y0"] + y:.4f}" r="{r:.4f}"/>')
    bar_end = g["bar_x"] + board.scale_bar_m / MM
    return "\n".join([
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<svg xmlns="http://www.w3.org/2000/svg" version="1.1" width="{g["width"]:.4f}mm" '
        f'height="{g["height"]:.4f}mm" viewBox="0 0 {g["width"]:.4f} {g["height"]:.4f}">',
        f"  <title>Calibration board: {_parameters_text(board)}</title>",
        f'  <rect id="sheet" x="0" y="0" width="{g["width"]:.4f}" height="{g["height"]:.4f}" '
        'fill="#ffffff"/>',
        '  <g id="dots" fill="#000000" stroke="none">',
        *dots,
        "  </g>",
        '  <g id="scale-bar" fill="#000000">',
        f'    <rect x="{g["bar_x"]:.4f}" y="{g["bar_y"]:.4f}" width="{board.scale_bar_m / MM:.4f}" '
        f'height="{g["bar_h"]:.4f}"/>',
        f'    <text x="{bar_end + 3:.4f}" y="{g["label_y"]:.4f}" font-family="sans-serif" '
        f'font-size="{_TEXT_MM}">{board.scale_bar_m / MM:g} mm</text>',
        "  </g>",
        f'  <text id="parameters" x="{g["bar_x"]:.4f}" y="{g["params_y"]:.4f}" '
        f'font-family="sans-serif" font-size="{_TEXT_MM * 0.8:g}">{_parameters_text(board)}'
        "</text>",
        "</svg>",
        "",
    ])


def write_board_svg(board: Board, path: str | Path) -> None:
    """Write :func:`board_svg` to ``path`` atomically."""
    write_text_atomic(path, board_svg(board))


def board_image(board: Board, dpi: float = 300.0) -> np.ndarray:
    """The board as an 8-bit grey image (h, w) at ``dpi`` dots per inch (antialiased)."""
    import cv2

    _drawable(board)
    check_png_size(board, dpi)
    g = _layout(board)
    px = dpi / 25.4  # pixels per mm
    width, height = int(round(g["width"] * px)), int(round(g["height"] * px))
    ink = np.zeros((height, width), np.float32)  # coverage of each pixel by ink, 0..1

    def page_px(v_mm):  # pixel-centre convention: the page edge is at -0.5 px
        return v_mm * px - 0.5

    for (x, y, _), r in zip(board.dot_positions() / MM, board.dot_radii() / MM):
        _add_disc(ink, page_px(g["x0"] + x), page_px(g["y0"] + y), r * px)
    bar_mm = board.scale_bar_m / MM
    _add_box(ink, page_px(g["bar_x"]), page_px(g["bar_x"] + bar_mm),
             page_px(g["bar_y"]), page_px(g["bar_y"] + g["bar_h"]))
    image = np.rint(255 * (1 - np.clip(ink, 0, 1))).astype(np.uint8)
    font = cv2.FONT_HERSHEY_SIMPLEX
    scale = _TEXT_MM * px / cv2.getTextSize("0", font, 1.0, 1)[0][1]
    thickness = max(1, int(round(scale * 1.5)))
    cv2.putText(image, f"{bar_mm:g} mm",
                (int((g["bar_x"] + bar_mm + 3) * px), int(g["label_y"] * px)), font,
                scale, 0, thickness, cv2.LINE_AA)
    cv2.putText(image, _parameters_text(board), (int(g["bar_x"] * px), int(g["params_y"] * px)),
                font, scale * 0.8, 0, thickness, cv2.LINE_AA)
    return image


def _add_disc(ink: np.ndarray, cx: float, cy: float, radius: float) -> None:
    """Add a disc's coverage (px; area exact to ~0.1 % for radii above 5 px)."""
    height, width = ink.shape
    x0, x1 = max(int(cx - radius) - 2, 0), min(int(cx + radius) + 3, width)
    y0, y1 = max(int(cy - radius) - 2, 0), min(int(cy + radius) + 3, height)
    ys, xs = np.mgrid[y0:y1, x0:x1]
    ink[y0:y1, x0:x1] += np.clip(radius + 0.5 - np.hypot(xs - cx, ys - cy), 0, 1)


def _add_box(ink: np.ndarray, x0: float, x1: float, y0: float, y1: float) -> None:
    """Add an axis-aligned rectangle's exact coverage (px, pixel-centre coordinates)."""
    xs, ys = np.arange(ink.shape[1]), np.arange(ink.shape[0])
    cover_x = np.clip(np.minimum(xs + 0.5, x1) - np.maximum(xs - 0.5, x0), 0, 1)
    cover_y = np.clip(np.minimum(ys + 0.5, y1) - np.maximum(ys - 0.5, y0), 0, 1)
    ink += np.outer(cover_y, cover_x).astype(np.float32)


def png_with_dpi(png: bytes, dpi: float) -> bytes:
    """``png`` with a pHYs chunk (pixels per metre) so it prints at ``dpi``; an existing
    pHYs chunk is replaced."""
    signature = b"\x89PNG\r\n\x1a\n"
    if not png.startswith(signature):
        raise DataError("board drawing: not PNG data")
    ppm = int(round(dpi / 0.0254))
    data = struct.pack(">IIB", ppm, ppm, 1)
    chunk = struct.pack(">I", len(data)) + b"pHYs" + data \
        + struct.pack(">I", zlib.crc32(b"pHYs" + data) & 0xFFFFFFFF)
    out, pos = [signature], len(signature)
    while pos < len(png):
        length = struct.unpack(">I", png[pos:pos + 4])[0]
        kind = png[pos + 4:pos + 8]
        end = pos + 12 + length
        if kind != b"pHYs":
            out.append(png[pos:end])
        if kind == b"IHDR":
            out.append(chunk)
        pos = end
    return b"".join(out)


def board_png(board: Board, dpi: float = 300.0) -> bytes:
    """PNG bytes of :func:`board_image`, with its dpi recorded (pHYs) to print at scale."""
    import cv2

    ok, encoded = cv2.imencode(".png", board_image(board, dpi))
    if not ok:
        raise DataError("board drawing: cannot encode the PNG")
    return png_with_dpi(encoded.tobytes(), dpi)


def write_board_png(board: Board, path: str | Path, dpi: float = 300.0) -> None:
    """Write :func:`board_png` to ``path`` atomically."""
    write_bytes_atomic(path, board_png(board, dpi))


def draw_detection(image: np.ndarray, detected_pixels: np.ndarray,
                   residual_pixels: np.ndarray | None = None,
                   magnify: float = 100.0) -> np.ndarray:
    """RGB picture (h, w, 3) uint8 of a detection: ``image`` (grey or RGB, uint8) with each
    detected dot (n, 2) px circled (dot 0, the marker, in blue; the others in green; dot 1
    and the last one numbered) and, if given, residuals (n, 2) px drawn as red arrows
    ``magnify`` times longer, with the factor written in the corner."""
    import cv2

    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim not in (2, 3):
        raise DataError(f"draw_detection: expected an 8-bit image, got {image.dtype} "
                        f"{image.shape}")
    rgb = cv2.cvtColor(image, cv2.COLOR_GRAY2RGB) if image.ndim == 2 else image[..., :3].copy()
    pixels = np.asarray(detected_pixels, dtype=float).reshape(-1, 2)
    shift = 4
    one = 1 << shift
    size = max(3.0, 0.006 * max(rgb.shape[:2]))
    line = max(1, int(round(size / 4)))
    for k, (x, y) in enumerate(pixels):
        if not np.all(np.isfinite((x, y))):
            continue
        colour = (40, 90, 255) if k == 0 else (0, 200, 0)
        centre = (int(round(x * one)), int(round(y * one)))
        cv2.circle(rgb, centre, int(size * one), colour, line, cv2.LINE_AA, shift)
        if k in (1, len(pixels) - 1):
            cv2.putText(rgb, str(k), (int(x + size), int(y - size)), cv2.FONT_HERSHEY_SIMPLEX,
                        size / 12, colour, line, cv2.LINE_AA)
    if residual_pixels is not None:
        residuals = np.asarray(residual_pixels, dtype=float).reshape(-1, 2)
        if residuals.shape != pixels.shape:
            raise DataError(f"draw_detection: {len(residuals)} residuals for {len(pixels)} dots")
        for (x, y), (dx, dy) in zip(pixels, residuals):
            if not np.all(np.isfinite((x, y, dx, dy))):
                continue
            tip = (int(round((x + magnify * dx) * one)), int(round((y + magnify * dy) * one)))
            cv2.arrowedLine(rgb, (int(round(x * one)), int(round(y * one))), tip,
                            (230, 30, 30), line, cv2.LINE_AA, shift, 0.25)
        cv2.putText(rgb, f"residuals x{magnify:g}", (10, int(10 + 3 * size)),
                    cv2.FONT_HERSHEY_SIMPLEX, size / 8, (230, 30, 30), line, cv2.LINE_AA)
    return rgb
