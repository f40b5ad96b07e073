"""Kawasaki AS: transformations used only as TOOL/BASE operands have rows, a location a
motion builds on (``LMOVE tframe + TRANS(..)``) is compensated under the BASE in force, a
save holding only its header says it holds no program."""

from __future__ import annotations

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.cli.fix import main
from olp_compensate.io.calibration_file import write_calibration
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs import loads
from olp_compensate.programs.object_model.task import compensate_task

ROBOT = load_robot("unimation_puma560")
PROGRAM = """.PROGRAM main()
  TOOL tgrip
  BASE bframe
  LMOVE tframe + TRANS(0,0,50)
  JMOVE p1
.END
.TRANS
tgrip 0.000 0.000 150.000 0.000 0.000 0.000
bframe 100.000 50.000 0.000 0.000 0.000 0.000
tframe 600.000 -100.000 250.000 0.000 180.000 0.000
p1 500.000 0.000 400.000 0.000 180.000 0.000
.END
"""


def test_frame_operands_have_rows_and_a_built_on_location_takes_the_base():
    program = loads(PROGRAM, "vplus", "op.as")
    (text,), report = compensate_task([program], nominal_calibration(ROBOT))
    assert text == PROGRAM
    rows = {r.target: r for r in report.rows}
    assert rows["tgrip"].status == "frame" and (rows["tgrip"].line, rows["tgrip"].column) == (8, 1)
    assert rows["bframe"].status == "frame" and "TOOL or BASE" in rows["bframe"].note
    assert rows["tframe"].wobj == "bframe" == rows["p1"].wobj
    assert rows["tframe"].status in ("ok", "singular") and rows["tframe"].tool == "tgrip"
    assert report.exit_code == 2                      # the compound motion is run time


def test_a_save_holding_only_its_header_has_no_program(tmp_path, capsys):
    save = tmp_path / "empty.as"
    save.write_bytes(b".***************************************\r\n.*=== AS GROUP ===   : "
                     b"ASX_000 2020/01/01 00:00\r\n.*\r\n.***************************\r\n")
    model = tmp_path / "calib.json"
    write_calibration(model, nominal_calibration(ROBOT))
    capsys.readouterr()
    assert main([str(save), "--model", str(model), "-o", str(tmp_path / "out.as"), "-q"]) == 1
    err = capsys.readouterr().err
    assert "holding only its header" in err and "cut short" not in err
    assert not (tmp_path / "out.as").exists()


def test_every_location_line_has_a_row():
    """Each line of the .TRANS section (this test's scanner) is in the report."""
    section = PROGRAM.split(".TRANS")[1]
    first = PROGRAM[:PROGRAM.index(".TRANS")].count("\n") + 2
    lines = [first + k for k, line in enumerate(section.split("\n")[1:])
             if line.strip() and not line.startswith(".END")]
    assert len(lines) == 4
    (_, ), report = compensate_task([loads(PROGRAM, "vplus", "op.as")],
                                    nominal_calibration(ROBOT))
    assert set(lines) <= {r.line for r in report.rows}
