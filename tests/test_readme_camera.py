"""The README runs as written (issue 25 item 7): the camera section's commands on the
shipped samples and the files they generate, the default board on A4 and Letter, and the
worked example's printed figures against a real run."""

from __future__ import annotations

import contextlib
import io
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from olp_compensate.camera.board import Board, read_board
from olp_compensate.camera.drawing import fits_on
from olp_compensate.cli.cal import main

ROOT = Path(__file__).resolve().parents[1]


def _section(title: str) -> str:
    text = (ROOT / "README.md").read_text()
    start = text.index(title)
    return text[start:text.index("\n## ", start + 5)]


def _commands(title: str) -> list[str]:
    return [ln[2:].split("  #")[0].strip() for ln in _section(title).splitlines()
            if ln.startswith("$ olp-")]


def test_worked_example_prints_what_the_readme_shows(tmp_path, monkeypatch):
    """Each output line the README shows is printed by the run ('...' elides lines; a
    line ending in '...' is a prefix)."""
    monkeypatch.chdir(tmp_path)
    lines = _section("## Worked example").splitlines()
    start = next(k for k, ln in enumerate(lines) if ln.startswith("$ olp-cal identify"))
    shown = []
    for line in lines[start + 1:]:
        if line.startswith("$ ") or line.startswith("```"):
            break
        shown.append(line)
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        for command in _commands("## Worked example")[:2]:
            assert main(shlex.split(command)[1:]) == 0
    out = printed.getvalue().splitlines()
    assert "condition number (unit-scaled Jacobian): 20.7" in shown
    for line in shown:
        if line.strip() in ("", "..."):
            continue
        if line.endswith("..."):
            assert any(o.startswith(line[:-3].rstrip()) for o in out), line
        else:
            assert line in out, line


def test_the_default_board_prints_on_a4_and_letter_as_the_readme_says(tmp_path):
    assert main(["camera", "board", "-o", str(tmp_path / "board.json")]) == 0
    board = read_board(tmp_path / "board.json")
    assert fits_on(board) == ["A4", "Letter"]
    sheet = board.sheet_extent()
    stated = re.search(r"(\d+) x (\d+) mm, A4 or Letter", _section("## The camera"))
    assert (int(stated.group(1)), int(stated.group(2))) == (round(sheet.width * 1e3),
                                                            round(sheet.height * 1e3))
    old = Board(rows=9, cols=9, pitch_m=0.025, dot_diameter_m=0.005, marker_diameter_m=0.008)
    assert fits_on(old) == []                      # the 258 mm board the README had


@pytest.mark.slow
def test_the_camera_section_runs_as_written_in_a_fresh_folder(tmp_path):
    shutil.copytree(ROOT / "samples", tmp_path / "samples")
    bin_dir = Path(sys.executable).parent
    commands = _commands("## The camera")
    assert len(commands) == 5
    for command in commands:
        words = shlex.split(command)
        done = subprocess.run([str(bin_dir / words[0])] + words[1:], cwd=tmp_path,
                              capture_output=True, text=True, timeout=900)
        assert done.returncode == 0, (command, done.stderr)
        assert "Traceback" not in done.stderr
        if "simulate" in command:
            assert "rendered 20 of 20 views" in done.stderr
        assert "unverified" not in done.stdout        # the scale bar was given
    assert (tmp_path / "calib.json").exists() and (tmp_path / "camera.html").exists()
