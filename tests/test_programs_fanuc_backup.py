"""FANUC backups beyond SYSFRAME.VA: the turn axes of SYSMAST.VA (or stated), the position
registers of POSREG.VA, SCARA configurations kept with a reason. Truth: the joints the
targets were made from (turn axes), the virtual robot's real TCP (registers)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.compensation.dialect_program import compensate_pose_program
from olp_compensate.compensation.files import ProgramFiles, compensate_files
from olp_compensate.programs.fanuc.rules import FANUC_TP, fanuc_letters, turn_number
from olp_compensate.errors import ParseError
from olp_compensate.kinematics.conventions import invert_pose
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs.backup_files import BackupFiles, parse_turn_axes
from olp_compensate.programs.fanuc.backup import read_position_registers, read_turn_axes
from olp_compensate.programs.fanuc.reader import parse_fanuc_tp
from test_programs_fanuc import (ROBOT, TOOL_MM, FanucController, _f, _program_joints, _wpr,
                                 ls_program)
from virtual_world import assert_the_gap_closed, identified_world, misses_mm

SYSMAST = """[*SYSTEM*]$SCR_GRP  Storage: CMOS  Access: RW  : ARRAY[1] OF SCR_GRP_T
 Field: $SCR_GRP[1].$MY_GRP_NUM Access: RO: UBYTE = 1
 Field: $SCR_GRP[1].$ROBOT_MODEL Access: RO: STRING[32] = 'R-2000iB/165F'
 Field: $SCR_GRP[1].$TURN_AXIS  ARRAY[3] OF INTEGER
  [1] = 1
  [2] = 4
  [3] = 6
 Field: $SCR_GRP[1].$AXS_XYZ_MAP  ARRAY[9] OF BYTE
  [1] = 1
  [2] = 2
"""


def _target_146(q):
    """(values, letters, turns on J1, J4, J6) of the TCP pose at controller joints ``q``."""
    controller = FanucController()
    tool = FANUC_TP.convention.pose(np.array(TOOL_MM))
    pose = controller.nominal.flange_poses(q[None])[0] @ tool
    turns = tuple(turn_number(math.degrees(q[a])) for a in (0, 3, 5))
    return _wpr(pose), fanuc_letters(controller.geometry, q), turns


def _write(tmp_path, name, text):
    path = tmp_path / name
    path.write_bytes(text.encode("latin-1"))
    return path


@pytest.fixture()
def turn_cell(tmp_path):
    """A program whose CONFIG turn numbers are for J1, J4, J6 (J4 at 200 deg: turn 1 on
    J4, which J5 cannot have), its SYSMAST.VA and the joints it was made from."""
    q = np.radians([[10.0, 5.0, -10.0, 200.0, -60.0, 30.0],
                    [-20.0, 10.0, 0.0, -30.0, -45.0, 190.0]])
    text = ls_program([_target_146(row) for row in q])
    ls = _write(tmp_path, "CELL.ls", text)
    va = _write(tmp_path, "SYSFRAME.VA",
                "[*SYSTEM*]$MNUTOOL  Storage: CMOS  Access: RW  : ARRAY[1,4] OF POSITION\n"
                "  [1,4] = '' Group: 1\n" +
                "  X: {}   Y: {}   Z: {}\n  W: {}   P: {}   R: {}\n".format(
                    *(_f(v).strip() if v else "0.000" for v in TOOL_MM)))
    return dict(q=q, text=text, ls=ls, sysframe=va,
                sysmast=_write(tmp_path, "SYSMAST.VA", SYSMAST))


def test_sysmast_turn_axes_are_read():
    axes = read_turn_axes(SYSMAST, "SYSMAST.VA")
    assert axes.axes == (1, 4, 6) and axes.source == "SYSMAST.VA:4"
    one_line = "[*SYSTEM*]$SCR_GRP  Storage: CMOS\n Field: $SCR_GRP[1].$TURN_AXIS = 4, 5, 6\n"
    assert read_turn_axes(one_line, "S.VA").axes == (4, 5, 6)
    assert read_turn_axes("[*SYSTEM*]$SCR_GRP  Storage: CMOS\n", "S.VA") is None
    with pytest.raises(ParseError) as info:
        read_turn_axes(SYSMAST.replace("[2] = 4", "[2] = x"), "S.VA")
    assert (info.value.line, info.value.column) == (6, 9)
    assert parse_turn_axes("1,4,6") == (1, 4, 6)


def test_turn_numbers_read_for_the_backups_axes(turn_cell):
    files = ProgramFiles("fanuc", (turn_cell["ls"],), ("CELL.ls",))
    nominal = nominal_calibration(ROBOT)
    plain = compensate_files(files, nominal, frames_path=turn_cell["sysframe"])
    rows = {r.target: r for r in plain.report.rows}
    assert rows["P[1]"].status != "ok"          # read for J4, J5, J6: J5 a turn away
    for given in ([turn_cell["sysframe"], turn_cell["sysmast"]],
                  BackupFiles((str(turn_cell["sysframe"]),), turn_axes=(1, 4, 6))):
        result = compensate_files(files, nominal, frames_path=given)
        assert result.data[0] == turn_cell["text"].encode("latin-1")
        rows = {r.target: r for r in result.report.rows}
        for k, q in enumerate(turn_cell["q"], 1):
            row = rows[f"P[{k}]"]
            assert row.status == "ok", row
            np.testing.assert_allclose(row.joints, np.degrees(q), atol=1e-3)
        assert any("J1, J4, J6" in w for w in result.report.warnings)


def test_olp_fix_fanuc_turn_axes_option(turn_cell, tmp_path):
    from olp_compensate.cli.fix import main
    from olp_compensate.io.calibration_file import write_calibration

    model = tmp_path / "calib.json"
    write_calibration(model, nominal_calibration(ROBOT))
    out = tmp_path / "out.ls"
    args = [str(turn_cell["ls"]), "--model", str(model), "-o", str(out), "-q",
            "--config", str(turn_cell["sysframe"])]
    assert main(args + ["--fanuc-turn-axes", "1,4,6"]) == 0
    assert out.read_bytes() == turn_cell["ls"].read_bytes()
    assert main(args + ["--config", str(turn_cell["sysmast"])]) == 0
    assert main(args + ["--fanuc-turn-axes", "1,4,4"]) == 1
    assert main(args + ["--fanuc-turn-axes", "0,4"]) == 1


SCARA = """/PROG  SC
/ATTR
/MN
   1:J P[1] 100% FINE    ;
   2:L P[2] 100mm/sec FINE    ;
/POS
P[1]{
   GP1:
\tUF : 0, UT : 0,\t\tCONFIG : 'L, 0, 0, -1',
\tX =   400.000  mm,\tY =   100.000  mm,\tZ =   -50.000  mm,
\tW =      .000 deg,\tP =      .000 deg,\tR =    45.000 deg
};
P[2]{
   GP1:
\tUF : 0, UT : 0,\t\tCONFIG : 'N U T, 0, 0, 0',
\tX =  1500.000  mm,\tY =      .000  mm,\tZ =  1000.000  mm,
\tW =   180.000 deg,\tP =      .000 deg,\tR =      .000 deg
};
/END
"""


def test_a_scara_configuration_is_reported_not_refused():
    program = parse_fanuc_tp(SCARA, "SC.ls")
    texts, report = compensate_pose_program(program, FANUC_TP, nominal_calibration(ROBOT))
    assert texts["SC.ls"] == SCARA
    rows = {(r.target, r.status): r for r in report.rows}
    row = rows[("P[1]", "unresolved")]
    assert (row.line, row.column) == (10, 8) and "SCARA" in row.note and "'L, 0, 0, -1'" in row.note
    assert ("P[1]", "runtime") in rows                      # its motion, with the reason
    assert any(r.target == "P[2]" and r.status in ("ok", "singular") for r in report.rows)


# ---- position registers ------------------------------------------------------------------

def _va(value: float) -> str:
    return f"{value:9.3f}" if value == 0 else _f(value)


def posreg_va(registers) -> str:
    """A POSREG.VA as a backup writes it; registers: n -> (values, letters, turns) |
    'joints' | None (uninitialized)."""
    lines = ["[*POSREG*]$POSREG  Storage: SHADOW  Access: RW  : ARRAY[1,100] OF Position Reg"]
    for n, value in sorted(registers.items()):
        if value is None:
            lines.append(f"    [1,{n}] =   '' Uninitialized")
        elif value == "joints":
            lines += [f"    [1,{n}] =   'HOME'   Group: 1",
                      "  J1 =    60.000 deg   J2 =   -50.000 deg   J3 =    10.000 deg ",
                      "  J4 =   -10.000 deg   J5 =   -95.000 deg   J6 =   -50.000 deg ", ""]
        else:
            values, letters, turns = value
            x, y, z, w, p, r = (_va(v) for v in values)
            lines += [f"    [1,{n}] =   'PR{n}' ",
                      f"  Group: 1   Config: {' '.join(letters)}, "
                      f"{', '.join(str(t) for t in turns)}",
                      f"  X: {x}   Y: {y}   Z: {z}", f"  W: {w}   P: {p}   R: {r}",
                      "  EXT1:  ******** mm  "]
    lines.append("[*POSREG*]$MAXPREGNUM  Storage: CMOS  Access: RW  : INTEGER = 100")
    return "\r\n".join(lines) + "\r\n"


@pytest.fixture(scope="module")
def register_world():
    return identified_world(ROBOT, 11, "UT4")


def _register_program():
    extra = ["J PR[1:Pick] 100% FINE    ;", "L PR[2] 500mm/sec FINE    ;",
             "PR[3]=LPOS    ;", "J PR[3] 100% FINE    ;", "J PR[4] 100% FINE    ;",
             "J PR[7] 100% FINE    ;", "L PR[1] 100mm/sec FINE Offset,PR[6]    ;",
             "J PR[5:HOME] 100% FINE    ;"]
    return extra


def test_position_registers_are_solved_and_their_values_reported(register_world):
    virtual, cal = register_world
    tool_mm = tuple(np.round(virtual.tools["tcp"] * 1e4) / 10) + (0.0, 0.0, 0.0)
    tool = FANUC_TP.convention.pose(np.array(tool_mm))
    controller = FanucController()
    q = _program_joints(3, 17)
    written = []
    for row in q:
        pose = controller.nominal.flange_poses(row[None])[0] @ tool
        written.append((_wpr(pose), fanuc_letters(controller.geometry, row),
                        tuple(turn_number(math.degrees(v)) for v in row[3:6])))
    va = posreg_va({1: written[0], 2: written[1], 3: written[2], 4: None, 5: "joints"})
    registers = read_position_registers(va, "POSREG.VA")
    assert sorted(registers.registers) == ["PR[1]", "PR[2]", "PR[3]", "PR[5]"]
    lines = va.split("\r\n")
    assert registers.uninitialized == {
        "PR[4]": (lines.index("    [1,4] =   '' Uninitialized") + 1, 5)}
    text = ls_program([], extra_mn=_register_program())
    program = parse_fanuc_tp(text, "CELL.ls", frames={"UT4": tool_mm}, registers=registers)
    texts, report = compensate_pose_program(program, FANUC_TP, cal)
    assert texts["CELL.ls"] == text and report.exit_code == 2
    by_target = {}
    for r in report.rows:
        by_target.setdefault(r.target, []).append(r)
    runtime = {r.target: r.note for r in report.rows if r.status == "runtime"}
    assert "set by the program (line" in runtime["PR[3]"]
    assert "uninitialized in POSREG.VA" in runtime["PR[4]"]
    assert "not in POSREG.VA" in runtime["PR[7]"]
    assert "Offset" in runtime["PR[1]"]
    assert [r.status for r in by_target["PR[5]"]] == ["joint_target"]
    meant, before, after = [], [], []
    for k, name in ((0, "PR[1]"), (1, "PR[2]")):
        (row,) = [r for r in by_target[name] if r.file == "POSREG.VA"]
        assert row.status == "register" and row.tool == "UT4", row
        values, letters, turns = written[k]
        values = np.array([float(_va(v)) for v in values])
        lines = va.split("\r\n")
        x_line = next(i for i, t in enumerate(lines) if f"'PR{k + 1}'" in t) + 2
        assert (row.line, row.column) == (
            x_line + 1, lines[x_line].index(_va(written[k][0][0]).strip(), 4) + 1)
        found = re.search(r"set it to \(([^)]*)\) with configuration '([^']*)'", row.note)
        new = np.array([float(v) for v in found.group(1).split(",")])
        config = [c.strip() for c in found.group(2).split(",")]
        meant.append((cal.device_T_base @ FANUC_TP.convention.pose(values))[:3, 3])
        before.append(controller.joints(FANUC_TP.convention.pose(values) @ invert_pose(tool),
                                        letters, turns))
        after.append(controller.joints(FANUC_TP.convention.pose(new) @ invert_pose(tool),
                                       config[:3], [int(t) for t in config[3:]]))
    assert_the_gap_closed("FANUC position registers from POSREG.VA",
                          *misses_mm(virtual, meant, before, after))


def test_without_posreg_a_register_is_runtime_and_named():
    text = ls_program([], extra_mn=["J PR[12:Drop] 100% FINE    ;"])
    _, report = compensate_pose_program(parse_fanuc_tp(text, "C.ls", frames={"UT4": TOOL_MM}),
                                        FANUC_TP, nominal_calibration(ROBOT))
    (row,) = [r for r in report.rows if r.target == "PR[12]"]
    assert row.status == "runtime" and "PR[12] is a position register" in row.note
    assert "POSREG.VA" in row.note


def test_a_posreg_value_that_is_not_a_number_is_refused_at_its_place():
    va = posreg_va({1: ((1.0, 2.0, 3.0, 0.0, 0.0, 0.0), ("N", "U", "T"), (0, 0, 0))})
    bad = va.replace("    2.000", "  2.0e+x", 1)
    with pytest.raises(ParseError) as info:
        read_position_registers(bad, "POSREG.VA")
    line = bad.split("\r\n")[3]
    assert (info.value.line, info.value.column) == (4, line.index("2.0e+x") + 1)
    assert "not a finite number" in str(info.value)


def _record_spans(text: str) -> list[tuple[int, int]]:
    """(first line, last line) of every ``P[n]{ ... };`` record: this test's own scanner."""
    lines = text.replace("\r\n", "\n").split("\n")
    out, start = [], None
    for n, line in enumerate(lines, 1):
        if re.match(r"\s*P\[\s*\d+[^\]]*\]\s*\{", line):
            start = n
        if start is not None and line.strip().startswith("};"):
            out.append((start, n))
            start = None
    return out


@pytest.mark.parametrize("text", [
    SCARA,
    ls_program([(np.array([1500.0, 0.0, 1000.0, 180.0, 0.0, 0.0]), ("N", "U", "T"), (0, 0, 0)),
                (np.array([1400.0, 200.0, 900.0, 180.0, 0.0, 30.0]), ("N", "U", "T"), (0, 0, 0)),
                (np.array([1300.0, -200.0, 800.0, 180.0, 0.0, -30.0]), ("N", "U", "T"), (0, 0, 0))],
               extra_mn=["J PR[3] 100% FINE    ;"]),
], ids=["scara", "cell"])
def test_every_position_record_has_a_row(text):
    from pathlib import Path

    golden = (Path(__file__).parent / "programs" / "fanuc_frames_and_motions" / "input.ls")
    for source in (text, golden.read_bytes().decode("latin-1")):
        _, report = compensate_pose_program(parse_fanuc_tp(source, "C.ls", frames={
            "UT4": TOOL_MM}), FANUC_TP, nominal_calibration(ROBOT))
        lines = [r.line for r in report.rows if r.file == "C.ls"]
        spans = _record_spans(source)
        assert spans
        for first, last in spans:
            assert any(first <= line <= last for line in lines), (first, last)


def test_a_backup_of_several_makers_gives_each_its_own_files(turn_cell, tmp_path):
    """``--config SYSFRAME.VA --config $config.dat`` over a folder of FANUC and KRL
    programs: each dialect reads its own files and skips the other maker's."""
    krl_config = _write(tmp_path, "$config.dat", "DEFDAT $CONFIG\nTOOL_DATA[1]={X 0,Y 0,Z 100,"
                                                 "A 0,B 0,C 0}\nENDDAT\n")
    both = [turn_cell["sysframe"], krl_config, turn_cell["sysmast"]]
    files = ProgramFiles("fanuc", (turn_cell["ls"],), ("CELL.ls",))
    result = compensate_files(files, nominal_calibration(ROBOT), frames_path=both)
    assert result.data[0] == turn_cell["text"].encode("latin-1")
    assert all(r.status == "ok" for r in result.report.rows if r.target in ("P[1]", "P[2]"))
    src = _write(tmp_path, "m.src", "DEF m( )\nBAS(#TOOL,1)\nLIN XP1\nEND\n")
    dat = _write(tmp_path, "m.dat", "DEFDAT m\nDECL E6POS XP1={X 1000,Y 0,Z 900,A 0,B 90,"
                                    "C 0}\nENDDAT\n")
    result = compensate_files(ProgramFiles("krl", (src, dat), ("m.src", "m.dat")),
                              nominal_calibration(load_robot("kuka_kr16_2")), frames_path=both)
    (row,) = [r for r in result.report.rows if r.target == "XP1"]
    assert row.tool == "TOOL_DATA[1]" and row.status != "unresolved"
    with pytest.raises(ParseError, match="holds none of"):
        compensate_files(files, nominal_calibration(ROBOT),
                         frames_path=[_write(tmp_path, "NUMREG.VA", "[*NUMREG*]$NUMREG  "
                                             "Storage: SHADOW\n  [1] = 1\n")])
