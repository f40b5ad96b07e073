"""olp-fix end to end: outputs, report, exit codes and one clear line for bad input."""

from __future__ import annotations

import csv
import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from olp_compensate.cli.cal import main as cal
from olp_compensate.cli.fix import main as fix
from olp_compensate.programs import load

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "samples"


@pytest.fixture(scope="module")
def calibrations(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fix")
    nominal = folder / "nominal.json"
    assert cal(["nominal", "--robot", "abb_irb2400", "-o", str(nominal)]) == 0
    identified = folder / "irb2400.json"
    assert cal(["identify", str(SAMPLES / "irb2400_measurements.csv"), "--robot",
                "abb_irb2400", "-o", str(identified)]) == 0
    puma = folder / "puma.json"
    assert cal(["nominal", "--robot", "unimation_puma560", "-o", str(puma)]) == 0
    return folder, nominal, identified, puma


@pytest.mark.parametrize("name, robot", [("cell_a.mod", "abb_irb2400"),
                                         ("cell_b.pg", "unimation_puma560")])
def test_nominal_calibration_output_is_byte_identical(tmp_path, name, robot):
    model = tmp_path / "nominal.json"
    assert cal(["nominal", "--robot", robot, "-o", str(model)]) == 0
    program = tmp_path / name
    shutil.copy(SAMPLES / name, program)
    code = fix([str(program), "--model", str(model), "-q"])
    out = program.with_name(f"{program.stem}_compensated{program.suffix}")
    assert out.read_bytes() == (SAMPLES / name).read_bytes()
    assert program.read_bytes() == (SAMPLES / name).read_bytes()
    assert code == 2  # both samples hold targets that cannot be compensated (reported)


def test_report_has_one_row_per_target_use_with_units(calibrations, tmp_path, capsys):
    _, _, identified, _ = calibrations
    out, report = tmp_path / "out.mod", tmp_path / "report.csv"
    code = fix([str(SAMPLES / "cell_a.mod"), "--model", str(identified), "-o", str(out),
                "--report", str(report)])
    assert code == 2
    printed = capsys.readouterr().out
    assert "runtime" in printed and "Offs(pWeld{1}" in printed and "mm" in printed
    rows = list(csv.DictReader(report.open()))
    header = list(rows[0])
    for column in ("target", "file", "line", "status", "dx_mm", "dy_mm", "dz_mm", "drot_deg",
                   *(f"q{k}_deg" for k in range(1, 7))):
        assert column in header
    by_name = {r["target"]: r for r in rows}
    assert by_name["p10"]["status"] == "ok" and by_name["p10"]["line"] == "15"
    assert by_name["jHome"]["status"] == "joint_target"
    assert by_name["pService"]["status"] == "unused"
    assert {r["status"] for r in rows if r["target"].startswith(("Offs", "RelTool"))} == {"runtime"}
    shift = [np.hypot(np.hypot(float(r["dx_mm"]), float(r["dy_mm"])), float(r["dz_mm"]))
             for r in rows if r["status"] == "ok"]
    assert 0.1 < max(shift) < 20
    # only numbers changed: with every number masked, the texts are identical
    number = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")
    before, after = load(SAMPLES / "cell_a.mod").text, load(out).text
    assert before != after
    assert number.sub("#", before) == number.sub("#", after)


def test_all_compensated_exits_zero(calibrations, tmp_path):
    _, _, identified, _ = calibrations
    program = tmp_path / "simple.mod"
    program.write_text("MODULE Simple\n"
                       "  CONST robtarget p1:=[[950,0,1100],[0,0,1,0],[0,0,0,0],"
                       "[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
                       "  PROC main()\n    MoveJ p1,v100,fine,tool0;\n  ENDPROC\nENDMODULE\n")
    assert fix([str(program), "--model", str(identified), "-q"]) == 0
    assert (tmp_path / "simple_compensated.mod").read_text() != program.read_text()
    assert fix([str(program), "--model", str(identified), "-q", "--emit", "joints",
                "-o", str(tmp_path / "joints.mod")]) == 0
    text = (tmp_path / "joints.mod").read_text()
    assert "CONST jointtarget p1" in text and "MoveAbsJ p1" in text


def test_one_big_module_on_two_processes_writes_what_one_process_writes(
        calibrations, tmp_path, monkeypatch):
    """-j 2 on one module shares its chunks of targets with a forked process (chunks of
    8 targets and no size floor here); the program and report are -j 1's byte for byte."""
    from olp_compensate.compensation import forked
    from olp_compensate.programs.rapid import module_columns

    _, _, identified, _ = calibrations
    rng = np.random.default_rng(3)
    decls, moves = [], []
    for k, (x, y, z) in enumerate(rng.uniform([800, -300, 700], [1100, 300, 1200], (40, 3))):
        decls.append(f"  CONST robtarget p{k}:=[[{x:.2f},{y:.2f},{z:.2f}],[0,0,1,0],"
                     f"[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];")
        moves.append(f"    MoveL p{k},v100,fine,tool0;")
    program = tmp_path / "big.mod"
    program.write_text("\n".join(["MODULE Big", *decls, "  PROC main()", *moves, "  ENDPROC",
                                  "ENDMODULE", ""]))
    monkeypatch.setattr(module_columns, "PARALLEL_MIN", 0)
    monkeypatch.setitem(module_columns.compensate_rapid_task.__kwdefaults__, "chunk", 8)
    forks = []
    start = forked.ForkedItems.__init__
    monkeypatch.setattr(forked.ForkedItems, "__init__",
                        lambda self, *args: forks.append(args) or start(self, *args))
    outputs = {}
    for jobs in ("1", "2"):
        out, report = tmp_path / f"j{jobs}.mod", tmp_path / f"j{jobs}.csv"
        assert fix([str(program), "--model", str(identified), "-q", "-j", jobs, "-o", str(out),
                    "--report", str(report)]) == 0
        outputs[jobs] = out.read_bytes(), report.read_bytes()
    assert len(forks) == forked.can_fork()
    assert outputs["2"] == outputs["1"]
    assert outputs["1"][0] != program.read_bytes()


def test_refuses_to_overwrite_the_input(calibrations, tmp_path, capsys):
    _, nominal, _, _ = calibrations
    program = tmp_path / "cell.mod"
    shutil.copy(SAMPLES / "cell_a.mod", program)
    assert fix([str(program), "--model", str(nominal), "-o", str(program)]) == 1
    assert "refusing to overwrite" in capsys.readouterr().err
    assert program.read_bytes() == (SAMPLES / "cell_a.mod").read_bytes()


def test_parse_error_points_at_line_and_column_with_a_caret(calibrations, tmp_path, capsys):
    _, nominal, _, _ = calibrations
    program = tmp_path / "broken.mod"
    program.write_text("MODULE M\n  CONST robtarget p1:=[[1,2,3],[1,0,0,0],[0,0,0,0]],\n"
                       "ENDMODULE\n")
    assert fix([str(program), "--model", str(nominal)]) == 1
    err = capsys.readouterr().err
    assert f"{program}:2:" in err and "^" in err
    assert not (tmp_path / "broken_compensated.mod").exists()


def test_binary_file_is_a_clean_error(calibrations, tmp_path, capsys):
    _, nominal, _, _ = calibrations
    program = tmp_path / "image.mod"
    program.write_bytes(bytes(range(256)) * 4)
    assert fix([str(program), "--model", str(nominal)]) == 1
    assert "Traceback" not in capsys.readouterr().err


def test_calibration_of_another_robot_is_refused(calibrations, capsys):
    _, _, _, puma = calibrations
    assert fix([str(SAMPLES / "cell_a.mod"), "--model", str(puma), "--robot", "abb_irb2400",
                "-q"]) == 1
    assert "unimation_puma560" in capsys.readouterr().err


def test_unknown_robot_and_missing_model_are_one_line(tmp_path, capsys):
    assert fix([str(SAMPLES / "cell_a.mod"), "--model", str(tmp_path / "none.json")]) == 1
    assert fix([str(SAMPLES / "cell_a.mod"), "--model", str(tmp_path / "none.json"),
                "--robot", "no_such_robot"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("olp-fix: error:") for line in err)


def test_the_command_flushes_its_summary_and_exits_with_the_run_code(tmp_path, calibrations):
    """The console entry point leaves without interpreter teardown: what it printed must
    still arrive whole, the files must be complete, and the exit code must be the run's."""
    import subprocess
    import sys

    _, _, identified, _ = calibrations
    program = tmp_path / "cell_a.mod"
    shutil.copy(SAMPLES / "cell_a.mod", program)
    args = [str(program), "--model", str(identified), "--report", str(tmp_path / "r.csv")]
    buffered = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    done = subprocess.run([sys.executable, "-m", "olp_compensate.cli.fix", *args],
                          capture_output=True, text=True, env=buffered)
    in_process = tmp_path / "in_process"
    in_process.mkdir()
    code = fix([str(program), "--model", str(identified), "-o",
                str(in_process / "out.mod"), "--report", str(in_process / "r.csv"), "-q"])
    assert done.returncode == code == 2
    assert done.stdout.startswith("olp-fix: ")
    assert done.stdout.rstrip().splitlines()[-1].endswith("r.csv")   # the last line arrived
    assert ((tmp_path / "cell_a_compensated.mod").read_bytes()
            == (in_process / "out.mod").read_bytes())
    assert (tmp_path / "r.csv").read_text() == (in_process / "r.csv").read_text()


def test_a_closed_stdout_is_no_traceback_and_the_files_are_written(tmp_path, calibrations):
    """`olp-fix ... | head`: the reader of the summary went away before it was printed."""
    import subprocess
    import sys

    _, _, identified, _ = calibrations
    program = tmp_path / "cell_a.mod"
    shutil.copy(SAMPLES / "cell_a.mod", program)
    proc = subprocess.Popen([sys.executable, "-m", "olp_compensate.cli.fix", str(program),
                             "--model", str(identified), "--report", str(tmp_path / "r.csv")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait() == 2 and "Traceback" not in err and "Broken pipe" not in err
    written = load(tmp_path / "cell_a_compensated.mod")
    assert len(written.targets) == len(load(program).targets)
    assert (tmp_path / "r.csv").read_text().startswith("target,file,line")
