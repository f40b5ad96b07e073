"""Issue 25: camera and ISO 9283 inputs that passed through as NaN, printed nonsense or ran
into a memory error are refused with one line, nothing written."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from olp_compensate.camera.assess import _ratio
from olp_compensate.camera.board import Board, write_board
from olp_compensate.camera.render import RenderOptions, random_views, render_board
from olp_compensate.cli.cal import main
from olp_compensate.io.camera_file import read_camera
from olp_compensate.io.images import write_png

ROOT = Path(__file__).resolve().parents[2]
BOARD = Board(rows=9, cols=7, pitch_m=0.022, dot_diameter_m=0.005, marker_diameter_m=0.008)


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    return err


def test_board_size_is_bounded_before_anything_is_written(tmp_path, capsys):
    out = tmp_path / "board.json"
    assert main(["camera", "board", "--rows", "2000", "--cols", "2000", "-o", str(out),
                 "--svg", str(tmp_path / "b.svg")]) == 1
    assert "at most 100 dots per side" in _one_line_error(capsys)
    assert not out.exists() and not (tmp_path / "b.svg").exists()
    assert main(["camera", "board", "--rows", "100", "--cols", "100", "-o", str(out),
                 "--png", str(tmp_path / "b.png")]) == 1      # 2.5 m at 300 dpi
    assert "million pixels" in _one_line_error(capsys) and not out.exists()


def test_camera_measure_refuses_nan_joints(tmp_path, capsys):
    camera = read_camera(ROOT / "samples" / "camera.json")
    write_board(BOARD, tmp_path / "board.json")
    (tmp_path / "img").mkdir()
    pose = random_views(BOARD, camera.intrinsics, 1, np.random.default_rng(1))[0]
    write_png(tmp_path / "img" / "a.png", render_board(BOARD, camera.intrinsics, pose,
                                                       RenderOptions(supersample=2)))
    (tmp_path / "joints.csv").write_text("image,q1_deg,q2_deg\na.png,nan,3\n")
    out = tmp_path / "meas.csv"
    assert main(["camera", "measure", str(tmp_path / "img"), "--camera",
                 str(ROOT / "samples" / "camera.json"), "--board", str(tmp_path / "board.json"),
                 "--joints", str(tmp_path / "joints.csv"), "-o", str(out)]) == 1
    assert "joints.csv:2: column 'q1_deg'" in _one_line_error(capsys) and not out.exists()


@pytest.mark.parametrize("value", ["nan", "inf", "-1"])
def test_iso9283_report_refuses_a_load_that_is_not_one(tmp_path, capsys, value):
    out = tmp_path / "iso.json"
    assert main(["iso9283", "report", str(ROOT / "samples" / "marks.csv"), "--json", str(out),
                 f"--load-kg={value}"]) == 1
    assert "--load-kg" in _one_line_error(capsys) and not out.exists()


def test_assess_refuses_a_move_beyond_any_stage_and_prints_small_ratios(tmp_path, capsys):
    write_board(BOARD, tmp_path / "board.json")
    (tmp_path / "moves.csv").write_text("image,dx_mm,dy_mm,dz_mm\na.png,0,0,0\n"
                                        "b.png,1e308,0,0\nc.png,0,10,0\n")
    assert main(["camera", "assess", str(tmp_path), "--camera",
                 str(ROOT / "samples" / "camera.json"), "--board", str(tmp_path / "board.json"),
                 "--moves", str(tmp_path / "moves.csv")]) == 1
    assert "moves.csv:3: dx_mm" in _one_line_error(capsys)
    assert _ratio(2500.4) == "1:2,500" and _ratio(float("inf")) == "1:inf"
    assert _ratio(5.0) == "1:5" and _ratio(1e-305) == "1:1e-305"       # not '1:0'
