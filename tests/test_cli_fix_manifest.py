"""``olp-fix --manifest``: a plant's programs, each with its own calibration, in one run;
hashes in every report row; ``--changed-only`` re-runs only what changed."""

from __future__ import annotations

import csv
import hashlib
import shutil
from pathlib import Path

import pytest

from olp_compensate import __version__
from olp_compensate.cli.cal import main as cal
from olp_compensate.cli.fix import main as fix
from olp_compensate.cli.fix_manifest import _controller_option

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "samples"


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    folder = tmp_path_factory.mktemp("plant_models")
    assert cal(["identify", str(SAMPLES / "irb2400_measurements.csv"), "--robot",
                "abb_irb2400", "-o", str(folder / "irb2400.json")]) == 0
    assert cal(["nominal", "--robot", "unimation_puma560", "-o", str(folder / "puma.json")]) == 0
    return folder


@pytest.fixture()
def plant(models, tmp_path):
    for name in ("irb2400.json", "puma.json"):
        shutil.copy(models / name, tmp_path / name)
    (tmp_path / "backups").mkdir()
    shutil.copy(SAMPLES / "cell_a.mod", tmp_path / "backups" / "cell_a.mod")
    shutil.copy(SAMPLES / "cell_b.pg", tmp_path / "backups" / "cell_b.pg")
    (tmp_path / "plant.csv").write_text(
        "# plant Hall 2\n"
        "robot, calibration, controller, input, output\n"
        "R1, irb2400.json, , backups/cell_a.mod, out/r1.mod\n"
        "R2, puma.json, , backups/cell_b.pg, out/r2.pg\n")
    (tmp_path / "out").mkdir()
    return tmp_path


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_every_program_with_its_own_calibration_and_hashes(plant, tmp_path_factory, capsys):
    assert fix(["--manifest", str(plant / "plant.csv")]) == 2
    printed = capsys.readouterr().out
    assert "2 programs: 2 compensated, 0 skipped" in printed
    alone = tmp_path_factory.mktemp("alone")
    for robot, model, program, out in (("R1", "irb2400.json", "cell_a.mod", "r1.mod"),
                                       ("R2", "puma.json", "cell_b.pg", "r2.pg")):
        report = alone / f"{robot}.csv"
        fix([str(plant / "backups" / program), "--model", str(plant / model), "-o",
             str(alone / out), "--report", str(report), "-q"])
        assert (plant / "out" / out).read_bytes() == (alone / out).read_bytes()
        rows = [r for r in csv.DictReader((plant / "plant_report.csv").open())
                if r["robot"] == robot]
        expected = list(csv.DictReader(report.open()))
        assert len(rows) == len(expected) > 0
        for got, want in zip(rows, expected):
            assert got["input_sha256"] == _sha(plant / "backups" / program)
            assert got["calibration_sha256"] == _sha(plant / model)
            assert got["olp_compensate_version"] == __version__
            assert {k: got[k] for k in want} == want


def test_changed_only_skips_what_did_not_change(plant, capsys):
    assert fix(["--manifest", str(plant / "plant.csv"), "-q"]) == 2
    first = (plant / "out" / "r1.mod").stat().st_mtime_ns
    assert fix(["--manifest", str(plant / "plant.csv"), "--changed-only"]) == 2
    assert "0 compensated, 2 skipped" in capsys.readouterr().out
    assert (plant / "out" / "r1.mod").stat().st_mtime_ns == first
    rows = list(csv.DictReader((plant / "plant_report.csv").open()))
    assert [r["status"] for r in rows] == ["unchanged", "unchanged"]
    assert rows[0]["input_sha256"] == _sha(plant / "backups" / "cell_a.mod")
    with open(plant / "backups" / "cell_b.pg", "ab") as stream:
        stream.write(b"; edited at the robot\n")
    assert fix(["--manifest", str(plant / "plant.csv"), "--changed-only"]) == 2
    assert "1 compensated, 1 skipped" in capsys.readouterr().out
    # a new calibration of R1: compensated again
    calib = plant / "irb2400.json"
    calib.write_text(calib.read_text().replace("\n", "\n ", 1))
    assert fix(["--manifest", str(plant / "plant.csv"), "--changed-only"]) == 2
    assert "1 compensated, 1 skipped" in capsys.readouterr().out
    rows = list(csv.DictReader((plant / "plant_report.csv").open()))
    assert {r["calibration_sha256"] for r in rows if r["robot"] == "R1"} == {_sha(calib)}


def test_controller_column_and_bad_rows(plant, capsys):
    manifest = plant / "plant.csv"
    manifest.write_text(manifest.read_text().replace("R1, irb2400.json, ,",
                                                     "R1, irb2400.json, factory.json,"))
    code = fix(["--manifest", str(manifest)])
    out = capsys.readouterr()
    if not _controller_option():
        assert code == 1
        assert "plant.csv:3: controller" in out.err and "leave the column empty" in out.err
        assert "1 compensated, 0 skipped (input, calibration and olp-compensate version " \
               "unchanged), 1 failed" in out.out
        rows = list(csv.DictReader((plant / "plant_report.csv").open()))
        assert rows[0]["status"] == "error" and rows[1]["robot"] == "R2"
    manifest.write_text("robot, calibration, input, output\nR1, a.json, b.mod, c.mod\n")
    assert fix(["--manifest", str(manifest)]) == 1
    err = capsys.readouterr().err
    assert "plant.csv:1: manifest header lacks controller" in err and "Traceback" not in err
