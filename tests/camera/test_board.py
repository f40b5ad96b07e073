"""Board, board.json and the printable drawings (SVG in mm, PNG with its dpi)."""

import json
import struct
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from olp_compensate.camera.board import Board, read_board, write_board
from olp_compensate.camera.drawing import board_png, board_svg, draw_detection
from olp_compensate.errors import DataError

BOARD = Board(rows=9, cols=9, pitch_m=0.025, dot_diameter_m=0.005, marker_diameter_m=0.008)
SVG = "{http://www.w3.org/2000/svg}"


def test_dot_positions_row_major_in_board_frame():
    board = Board(3, 4, 0.02, 0.004, 0.007)
    p = board.dot_positions()
    assert p.shape == (12, 3)
    r, c = 2, 3
    np.testing.assert_allclose(p[r * board.cols + c], [c * 0.02, r * 0.02, 0.0])
    np.testing.assert_allclose(p[1], [0.02, 0.0, 0.0])  # index 1 is row 0, column 1
    assert board.dot_radii()[0] == pytest.approx(0.0035)
    assert np.all(board.dot_radii()[1:] == pytest.approx(0.002))


def test_sheet_extends_one_pitch_beyond_the_outer_dots():
    s = BOARD.sheet_extent()
    last = 8 * 0.025
    for edge_gap in (-s.x_min, s.x_max - last, -s.y_min, s.y_max - last):
        assert edge_gap >= 0.025 + 0.004 - 1e-12  # one pitch beyond the marker's edge


def test_board_json_round_trip(tmp_path):
    path = tmp_path / "board.json"
    write_board(BOARD, path)
    assert json.loads(path.read_text()) == {"rows": 9, "cols": 9, "pitch_mm": 25.0,
                                            "dot_diameter_mm": 5.0, "marker_diameter_mm": 8.0}
    assert read_board(path) == BOARD
    assert [p.name for p in tmp_path.iterdir()] == ["board.json"]  # no temporary file left


def test_board_json_missing_key_names_file_and_key(tmp_path):
    path = tmp_path / "board.json"
    path.write_text(json.dumps({"rows": 9, "cols": 9, "pitch_mm": 25.0,
                                "marker_diameter_mm": 8.0}))
    with pytest.raises(DataError, match=r"board\.json: missing key 'dot_diameter_mm'"):
        read_board(path)


@pytest.mark.parametrize("change, message", [
    ({"rows": 2}, "rows must be an integer >= 3"),
    ({"pitch_mm": -25.0}, "must be a positive number"),
    ({"pitch_mm": 8.0}, "overlap"),
    ({"marker_diameter_mm": 5.0}, "marker diameter"),
    ({"cols": 9.5}, "'cols' must be an integer"),
])
def test_board_json_invalid_values(tmp_path, change, message):
    data = {"rows": 9, "cols": 9, "pitch_mm": 25.0, "dot_diameter_mm": 5.0,
            "marker_diameter_mm": 8.0, **change}
    path = tmp_path / "board.json"
    path.write_text(json.dumps(data))
    with pytest.raises(DataError, match=message) as info:
        read_board(path)
    assert "board.json" in str(info.value)


def test_svg_has_physical_size_scale_bar_and_marker():
    root = ET.fromstring(board_svg(BOARD))
    s = BOARD.sheet_extent()
    assert root.get("width") == f"{s.width * 1000:.4f}mm"
    assert root.get("height") == f"{s.height * 1000:.4f}mm"
    assert [float(v) for v in root.get("viewBox").split()] == pytest.approx(
        [0, 0, s.width * 1000, s.height * 1000])  # one user unit is one millimetre
    circles = root.findall(f"{SVG}g[@id='dots']/{SVG}circle")
    assert len(circles) == 81
    radii = np.array([float(c.get("r")) for c in circles])
    assert radii[0] == pytest.approx(4.0) and np.all(radii[1:] == pytest.approx(2.5))
    centres = np.array([[float(c.get("cx")), float(c.get("cy"))] for c in circles])
    np.testing.assert_allclose(centres - centres[0], BOARD.dot_positions()[:, :2] * 1000,
                               atol=1e-3)
    bar = root.find(f"{SVG}g[@id='scale-bar']")
    assert float(bar.find(f"{SVG}rect").get("width")) == pytest.approx(100.0)
    assert bar.find(f"{SVG}text").text == "100 mm"
    assert "pitch 25 mm" in root.find(f"{SVG}text[@id='parameters']").text


def _png_chunks(data: bytes) -> dict:
    pos, chunks = 8, {}
    while pos < len(data):
        length = struct.unpack(">I", data[pos:pos + 4])[0]
        chunks.setdefault(data[pos + 4:pos + 8], data[pos + 8:pos + 8 + length])
        pos += 12 + length
    return chunks


def test_png_records_dpi_and_prints_at_scale():
    import cv2

    dpi = 200
    data = board_png(BOARD, dpi)
    ppm_x, ppm_y, unit = struct.unpack(">IIB", _png_chunks(data)[b"pHYs"])
    assert (ppm_x, ppm_y, unit) == (round(dpi / 0.0254), round(dpi / 0.0254), 1)
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert image is not None  # the inserted chunk keeps the file valid
    s = BOARD.sheet_extent()
    px_per_m = dpi / 0.0254
    assert image.shape == (round(s.height * px_per_m), round(s.width * px_per_m))
    # dot (r, c) printed at the right place: dark at its centre, light half a pitch away
    for r, c in [(0, 0), (0, 8), (8, 0), (4, 5)]:
        x = (c * BOARD.pitch_m - s.x_min) * px_per_m - 0.5
        y = (r * BOARD.pitch_m - s.y_min) * px_per_m - 0.5
        assert image[round(y), round(x)] < 30
        assert image[round(y), round(x + BOARD.pitch_m / 2 * px_per_m)] > 225
    # the marker's ink area against a dot's: (8/5)^2
    half = int(0.006 * px_per_m)

    def ink(r, c):
        x = round((c * BOARD.pitch_m - s.x_min) * px_per_m)
        y = round((r * BOARD.pitch_m - s.y_min) * px_per_m)
        return np.sum(255.0 - image[y - half:y + half, x - half:x + half]) / 255

    assert ink(0, 0) / ink(3, 3) == pytest.approx(2.56, rel=0.02)


def test_draw_detection_marks_dots_and_magnified_residuals():
    grey = np.full((200, 300), 128, np.uint8)
    pixels = np.array([[50.0, 50.0], [150.0, 100.0]])
    residuals = np.array([[0.0, 0.0], [0.5, 0.0]])
    rgb = draw_detection(grey, pixels, residuals, magnify=100)
    assert rgb.shape == (200, 300, 3) and rgb.dtype == np.uint8
    red = (rgb[..., 0] > 200) & (rgb[..., 1] < 80)
    ys, xs = np.nonzero(red[60:, :])
    # the arrow of dot 1 reaches 0.5 px * 100 = 50 px to its right
    assert xs.max() == pytest.approx(200, abs=2)
    assert not red[40:60, 40:60].any()  # zero residual: no arrow at dot 0
    assert rgb[50 - 5:50 + 6, 50 - 5:50 + 6, 2].max() > 200  # the marker ring is blue
