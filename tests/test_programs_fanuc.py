"""FANUC TP: .ls programs read and written back losslessly; the whole loop on a virtual
R-2000iC/165F (identify, compensate, run the written targets through a nominal FANUC
controller of the test's own, reach within 0.05 mm where the untouched program misses by
more)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.calibration.simulate import random_joints
from olp_compensate.compensation.dialect_program import compensate_pose_program
from olp_compensate.compensation.dialect_rules import ArmGeometry
from olp_compensate.compensation.ik import closed_form_inverse
from olp_compensate.kinematics.conventions import (euler_zyx_from_matrix, invert_pose,
                                                   matrix_from_euler_zyx)
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs.fanuc.reader import parse_fanuc_tp
from olp_compensate.programs.fanuc.rules import FANUC_TP, fanuc_letters, fanuc_rules, turn_number
from virtual_world import assert_the_gap_closed, identified_world, misses_mm, nominal_arm

ROBOT = load_robot("fanuc_r2000ic_165f")
TOOL_MM = (12.0, -5.0, 380.0, 0.0, 0.0, 0.0)

HEADER = """/PROG  CELL
/ATTR
OWNER\t\t= MNEDITOR;
COMMENT\t\t= "Pick cell";
PROG_SIZE\t= 2310;
CREATE\t\t= DATE 24-03-11  TIME 10:12:00;
MODIFIED\t= DATE 24-03-11  TIME 10:20:48;
FILE_NAME\t= ;
VERSION\t\t= 0;
LINE_COUNT\t= {lines};
MEMORY_SIZE\t= 2790;
PROTECT\t\t= READ_WRITE;
TCD:  STACK_SIZE\t= 0,
      TASK_PRIORITY\t= 50,
      TIME_SLICE\t= 0,
      BUSY_LAMP_OFF\t= 0,
      ABORT_REQUEST\t= 0,
      PAUSE_REQUEST\t= 0;
DEFAULT_GROUP\t= 1,*,*,*,*;
CONTROL_CODE\t= 00000000 00000000;
/MN"""


def _f(value: float) -> str:
    """A number as FANUC writes it: 3 decimals, no leading zero, right-aligned in 9."""
    s = f"{value:.3f}"
    if s.startswith("0."):
        s = s[1:]
    elif s.startswith("-0."):
        s = "-" + s[2:]
    return f"{s:>9}"


def ls_program(targets, uf=0, ut=4, extra_mn=()):
    """A .ls text (CR LF) moving to P[1]..P[m] (J, L, and a C pair), plus a joint HOME."""
    mn = [f"  UFRAME_NUM={uf} ;", f"  UTOOL_NUM={ut} ;", "  !Approach the cell ;",
          "J P[99:HOME] 100% FINE    ;"]
    m = len(targets)
    k = 1
    while k <= m:
        if k + 1 <= m and k % 4 == 3:
            mn.append(f"C P[{k}]    ")
            mn.append(f"    :  P[{k + 1}] 200mm/sec CNT50    ;")
            k += 2
            continue
        mn.append(f"J P[{k}] 100% FINE    ;" if k % 2 else
                  f"L P[{k}:\"PT{k}\"] 500mm/sec CNT100    ;".replace('"', ""))
        k += 1
    mn += list(extra_mn)
    mn.append("J P[99:HOME] 100% FINE    ;")
    numbered = []
    n = 0
    for line in mn:
        if line.startswith("    :"):
            numbered.append(line)
            continue
        n += 1
        numbered.append(f"{n:4d}:{line}" if line[0] != " " else f"{n:4d}:{line}")
    pos = ["/POS"]
    for k, (values, letters, turns) in enumerate(targets, 1):
        x, y, z, w, p, r = values
        label = f':"PT{k}"' if k % 2 == 0 else ""
        pos += [f"P[{k}{label}]{{", "   GP1:",
                f"\tUF : {uf}, UT : {ut},\t\tCONFIG : '{' '.join(letters)}, "
                f"{', '.join(str(t) for t in turns)}',",
                f"\tX = {_f(x)}  mm,\tY = {_f(y)}  mm,\tZ = {_f(z)}  mm,",
                f"\tW = {_f(w)} deg,\tP = {_f(p)} deg,\tR = {_f(r)} deg", "};"]
    pos += ["P[99:\"HOME\"]{", "   GP1:", f"\tUF : {uf}, UT : {ut},",
            f"\tJ1= {_f(0)} deg,\tJ2= {_f(0)} deg,\tJ3= {_f(0)} deg,",
            f"\tJ4= {_f(0)} deg,\tJ5= {_f(-90)} deg,\tJ6= {_f(0)} deg", "};", "/END"]
    lines = [HEADER.format(lines=n)] + numbered + pos
    return "\r\n".join(lines) + "\r\n"


class FanucController:
    """The nominal FANUC controller of this test: the closed form fitted on pinocchio's
    forward kinematics of the data-sheet URDF; the branch with the written letters, J4, J5,
    J6 moved into the written revolutions."""

    def __init__(self):
        self.nominal, self.family = nominal_arm(ROBOT)
        self.geometry = ArmGeometry(ROBOT)

    def joints(self, base_T_flange, letters, turns):
        branches = ROBOT.controller_from_joints(closed_form_inverse(self.family,
                                                                    base_T_flange[None])[0])
        for q in branches:
            if np.all(np.isfinite(q)) and fanuc_letters(self.geometry, q) == tuple(letters):
                q = q.copy()
                for a, t in zip((3, 4, 5), turns):
                    q[a] = math.remainder(q[a], 2 * math.pi) + 2 * math.pi * t
                return q
        raise AssertionError(f"no branch with {letters}")


def _wpr(pose):
    abc = np.degrees(euler_zyx_from_matrix(pose[:3, :3]))
    return np.concatenate([pose[:3, 3] * 1e3, abc[::-1]])


def _targets_at(q_ctrl, tool_mm=TOOL_MM, controller=None):
    controller = controller or FanucController()
    tool = FANUC_TP.convention.pose(np.array(tool_mm))
    out = []
    for q in q_ctrl:
        pose = controller.nominal.flange_poses(q[None])[0] @ tool
        out.append((_wpr(pose), fanuc_letters(controller.geometry, q),
                    tuple(turn_number(math.degrees(v)) for v in q[3:6])))
    return out


def _program_joints(m, seed):
    q = random_joints(ROBOT, 8 * m, np.random.default_rng(seed), margin=0.3)
    q = q[np.abs(np.sin(q[:, 4])) > math.sin(math.radians(20))][:m].copy()
    # J4 and J6 turn +-360 deg: some targets in the next revolution (turn numbers +-1)
    for k in range(1, len(q), 3):
        axis = 5 if k % 2 else 3
        q[k, axis] -= math.copysign(2 * math.pi, q[k, axis])
    return q


def test_wpr_is_about_fixed_x_then_y_then_z():
    rot = FANUC_TP.convention.rotation
    assert np.allclose(rot(np.array([90.0, 0, 0])) @ [0, 1, 0], [0, 0, 1])   # W about x
    assert np.allclose(rot(np.array([0, 90.0, 0])) @ [0, 0, 1], [1, 0, 0])   # P about y
    # fixed axes: W then P is Ry(P) Rx(W)
    both = rot(np.array([90.0, 90.0, 0.0]))
    assert np.allclose(both, matrix_from_euler_zyx(0, math.pi / 2, 0)
                       @ matrix_from_euler_zyx(0, 0, math.pi / 2))
    rng = np.random.default_rng(0)
    for _ in range(20):
        wpr = rng.uniform(-170, 170, 3) * [1, 0.5, 1]
        back = FANUC_TP.convention.angles(rot(wpr), wpr + 1.0)
        assert np.allclose(back, wpr, atol=1e-9)


def test_turn_numbers_and_letters_of_known_poses():
    assert [turn_number(v) for v in (-540.0, -200.0, -179.9, 0.0, 179.9, 180.0, 539.9)] == \
        [-2, -1, 0, 0, 0, 1, 1]
    geometry = ArmGeometry(ROBOT)
    # J5 = -90: faceplate down (W, P, R = 180, 0, 0) with J4 = 0: 'N U T'
    q = np.radians([0.0, 0.0, 0.0, 0.0, -90.0, 0.0])
    assert fanuc_letters(geometry, q) == ("N", "U", "T")
    assert fanuc_letters(geometry, q * [1, 1, 1, 1, -1, 1]) == ("F", "U", "T")
    # J2 arm leaning back, J3 arm up: the wrist point behind J1 (back, 'B')
    assert fanuc_letters(geometry, np.radians([0.0, -60.0, 60.0, 0.0, -90.0, 0.0])) == \
        ("N", "U", "B")
    # J2 arm leaning back, J3 arm pointing down: the wrist above the J2-J3 line ('D')
    assert fanuc_letters(geometry, np.radians([0.0, -75.0, -60.0, 0.0, -90.0, 0.0])) == \
        ("N", "D", "T")
    pose = FanucController().nominal.flange_poses(q[None])[0]
    assert np.allclose(np.abs(_wpr(pose)[3:]), [180.0, 0.0, 0.0], atol=1e-6)


def test_parse_reads_records_motions_and_spans():
    text = ls_program(_targets_at(_program_joints(6, 1)))
    program = parse_fanuc_tp(text, "CELL.ls")
    names = [t.name for t in program.targets]
    assert names == [f"P[{k}]" for k in range(1, 7)] + ["P[99]"]
    assert program.targets[-1].kind == "joints" and len(program.targets[-1].numbers) == 6
    moves = [(m.instruction, m.target, m.tool, m.base) for m in program.motions]
    assert moves[0] == ("J", "P[99]", "UT4", "UF0")
    assert ("C", "P[3]", "UT4", "UF0") in moves and ("C", "P[4]", "UT4", "UF0") in moves
    p2 = program.targets[1]
    for number in p2.numbers + p2.config:
        assert text[number.start:number.end] == number.text
    assert [n.text for n in p2.config][:3] in (["N", "U", "T"], ["F", "U", "T"], ["N", "D", "T"],
                                               ["F", "D", "T"], ["N", "U", "B"], ["F", "U", "B"],
                                               ["N", "D", "B"], ["F", "D", "B"])
    assert p2.source[1] == text[:p2.numbers[0].start].count("\n") + 1


def test_nominal_calibration_gives_the_bytes_back():
    text = ls_program(_targets_at(_program_joints(8, 2)))
    program = parse_fanuc_tp(text, "CELL.ls", frames={"UT4": TOOL_MM})
    texts, report = compensate_pose_program(program, FANUC_TP, nominal_calibration(ROBOT))
    assert texts["CELL.ls"] == text
    statuses = [r.status for r in report.rows]
    assert statuses.count("ok") + statuses.count("singular") == 8, report.rows
    assert statuses.count("joint_target") == 1
    assert all(r.config_before == r.config_after for r in report.rows if r.status == "ok")


def test_runtime_unknown_and_unresolved_are_reported_never_dropped():
    extra = ["L PR[3:pounce] 500mm/sec FINE    ;", "L P[2] 100mm/sec FINE Offset,PR[5]    ;",
             "J P[R[7]] 50% FINE    ;", "L P[42] 100mm/sec FINE    ;"]
    text = ls_program(_targets_at(_program_joints(2, 3)), extra_mn=extra)
    program = parse_fanuc_tp(text, "CELL.ls")                 # UT4 defined nowhere
    _, report = compensate_pose_program(program, FANUC_TP, nominal_calibration(ROBOT))
    by_status = {}
    for r in report.rows:
        by_status.setdefault(r.status, []).append(r)
    assert len(by_status["runtime"]) == 3, by_status      # PR, Offset, P[R[7]]
    assert [r.target for r in by_status["unresolved"]].count("P[42]") == 1
    unresolved = [r for r in by_status["unresolved"] if r.target == "P[1]"]
    assert unresolved and "UT4 unknown" in unresolved[0].note
    assert report.exit_code == 2
    # a user frame without data is unresolved with its name
    text = ls_program(_targets_at(_program_joints(1, 4)), uf=3)
    _, report = compensate_pose_program(parse_fanuc_tp(text, "CELL.ls", frames={"UT4": TOOL_MM}),
                                        FANUC_TP, nominal_calibration(ROBOT))
    notes = [r.note for r in report.rows if r.status == "unresolved"]
    assert notes and "UF3 unknown" in notes[0]


def test_a_configuration_the_pose_cannot_have_is_reported():
    targets = _targets_at(_program_joints(1, 5))
    values, letters, turns = targets[0]
    other = ("N" if letters[0] == "F" else "F", letters[1], letters[2])
    text = ls_program([(values, other, (9, 0, 0))])
    _, report = compensate_pose_program(parse_fanuc_tp(text, "CELL.ls", frames={"UT4": TOOL_MM}),
                                        FANUC_TP, nominal_calibration(ROBOT))
    row = next(r for r in report.rows if r.target == "P[1]")
    # another configuration reaches the pose inside every range: 'branch_changed', the note
    # naming the configuration of the joints reported, which are in range and reach it
    assert row.status == "branch_changed", row.note
    q = np.radians(row.joints)
    assert not ROBOT.outside_ranges(q[None]).any()
    named = row.note.rsplit("only on another configuration: ", 1)[1]
    written = FANUC_TP.config(ArmGeometry(ROBOT), q, parse_fanuc_tp(
        text, "CELL.ls", frames={"UT4": TOOL_MM}).targets[0])
    assert named == FANUC_TP.config_words(written)
    assert written[3:] == tuple(turn_number(math.degrees(q[a]))
                                  for a in (3, 4, 5))


def test_turn_axes_are_a_setting():
    rules = fanuc_rules(turn_axes=(1, 4, 6))
    geometry = ArmGeometry(ROBOT)
    q = np.radians([10.0, 0.0, 0.0, 200.0, -60.0, -190.0])
    targets = _targets_at(q[None])
    program = parse_fanuc_tp(ls_program(targets), "CELL.ls")
    assert rules.config(geometry, q, program.targets[0]) == ("N", "U", "T", 0, 1, -1)
    assert FANUC_TP.config(geometry, q, program.targets[0]) == ("N", "U", "T", 1, 0, -1)


@pytest.fixture(scope="module")
def fanuc_world():
    return identified_world(ROBOT, 11, "UT4")


def test_compensated_fanuc_reaches_its_targets_on_the_virtual_robot(fanuc_world):
    virtual, cal = fanuc_world
    q = _program_joints(10, 7)
    tool_mm = tuple(np.round(virtual.tools["tcp"] * 1e4) / 10) + (0.0, 0.0, 0.0)
    tool = FANUC_TP.convention.pose(np.array(tool_mm))
    controller = FanucController()
    written = _targets_at(q, tool_mm, controller)
    text = ls_program(written)
    program = parse_fanuc_tp(text, "CELL.ls", frames={"UT4": tool_mm})
    texts, report = compensate_pose_program(program, FANUC_TP, cal)
    assert report.exit_code == 0, [(r.target, r.status, r.note) for r in report.rows]
    again = {t.name: t for t in parse_fanuc_tp(texts["CELL.ls"], "CELL.ls").targets}
    meant, before, after = [], [], []
    for k, (values, letters, turns) in enumerate(written, 1):
        values = np.array([float(_f(v)) for v in values])          # as written in the file
        meant.append((cal.device_T_base @ FANUC_TP.convention.pose(values))[:3, 3])
        before.append(controller.joints(FANUC_TP.convention.pose(values) @ invert_pose(tool),
                                        letters, turns))
        target = again[f"P[{k}]"]
        new_values = np.array([n.value for n in target.numbers])
        new_config = [n.text for n in target.config]
        after.append(controller.joints(FANUC_TP.convention.pose(new_values) @ invert_pose(tool),
                                       new_config[:3], [int(t) for t in new_config[3:]]))
    assert_the_gap_closed("FANUC R-2000iC/165F", *misses_mm(virtual, meant, before, after))
    # only the /POS numbers of P[1..10] changed; the /MN and header are untouched
    old_lines, new_lines = text.split("\r\n"), texts["CELL.ls"].split("\r\n")
    assert len(old_lines) == len(new_lines)
    changed = [a for a, b in zip(new_lines, old_lines) if a != b]
    assert changed and all(line.startswith(("\tX =", "\tW =", "\tUF :")) for line in changed)
    assert texts["CELL.ls"].split("/POS")[0] == text.split("/POS")[0]


def _record_program(body: str, mn: str = "   1:J P[1] 100% FINE    ;\n") -> str:
    return f"/PROG  T\n/ATTR\n/MN\n{mn}/POS\nP[1]{{\n   GP1:\n{body}}};\n/END\n"


@pytest.mark.parametrize("body, words", [
    ("\tUF : 0, UT : 0,\t\tCONFIG : 'N U T, 0, 0, 0',\n"
     "\tX = ********  mm,\tY = ********  mm,\tZ = ********  mm,\n"
     "\tW = ******** deg,\tP = ******** deg,\tR = ******** deg\n", "never taught"),
    ("\tUF : 1, UT : 3,\t\tCONFIG : 'F U T, 0, -1, 0',\n"
     "\tRX =  -397.527  mm,\tRY =    -3.242  mm,\tRZ =  3835.332  mm,\n"
     "\tRW =    95.813 deg,\tRP =   -45.094 deg,\tRR =  -145.882 deg\n", "RP, RR, RW, RX"),
])
def test_records_that_cannot_be_read_are_kept_and_reported(body, words):
    """A point never taught (``********``) or written in another representation (RX..RR)
    does not stop the file: the record is reported at its place, its motion as not read."""
    text = _record_program(body)
    program = parse_fanuc_tp(text, "t.ls")
    assert program.targets == []
    ((where, what),) = program.unknown
    assert where == ("t.ls", 6, 1) and words in what
    (motion,) = program.motions
    assert motion.runtime is not None
    texts, report = compensate_pose_program(program, fanuc_rules(),
                                            nominal_calibration(ROBOT))
    assert texts["t.ls"] == text
    assert sorted((r.status, r.line) for r in report.rows) == [
        ("runtime", 4), ("unknown_instruction", 6)]


def test_record_of_another_group_only():
    text = ("/PROG  T\n/ATTR\n/MN\n   1:J P[1] 100% FINE    ;\n/POS\nP[1]{\n   GP4:\n"
            "\tUF : 1, UT : 2,\t\n\tJ1=    40.000  mm\n};\n/END\n")
    program = parse_fanuc_tp(text, "t.ls")
    ((where, what),) = program.unknown
    assert where == ("t.ls", 6, 1) and "GP4 only" in what
    assert "group 1" in program.motions[0].runtime


# ---- user and tool frames from a backup's SYSFRAME.VA ------------------------------------

def _va_number(value: float) -> str:
    """A number as the .VA dump writes it: 3 decimals right-aligned in 9, ``.140`` for 0.14
    (but ``0.000`` for zero)."""
    return f"{value:9.3f}" if value == 0 else _f(value)


def _va_element(group: int, frame: int, values, head: str = "", config: str = "N D B, 0, 0, 0"):
    """One ``[g,n] =`` element of a POSITION array (values None: '' Uninitialized)."""
    if values is None:
        return [f"    [{group},{frame}] = '' Uninitialized"]
    x, y, z, w, p, r = values
    return [f"    [{group},{frame}] = {head}", f"  Group: {group}   Config: {config}",
            f"  X: {_va_number(x)}   Y: {_va_number(y)}   Z: {_va_number(z)}",
            f"  W: {_va_number(w)}   P: {_va_number(p)}   R: {_va_number(r)}"]


def sysframe_va(uframes: dict, utools: dict, size: int = 9, newline: str = "\r\n") -> str:
    """A SYSFRAME.VA text laid out as real backups are (written for these tests): other
    variables around, ``$MNUFRAME``/``$MNUTOOL`` arrays of two groups, group 2 all other
    values. ``uframes``/``utools``: frame number -> six values or None (uninitialized);
    the frames not named are zeros, as a controller keeps its unused frames."""
    lines = ["[*SYSTEM*]$CELL_FLOOR  Storage: SHADOW  Access: RW  : POSITION = ",
             "  Group: 1   Config: N D B, 0, 0, 0",
             "  X:   111.000   Y:   222.000   Z:   333.000",
             "  W:     0.000   P:     0.000   R:     0.000", ""]
    for name, frames, selected in (("$MNUFRAME", uframes, 2), ("$MNUTOOL", utools, 3)):
        lines.append(f"[*SYSTEM*]{name}  Storage: SHADOW  Access: RW  : "
                     f"ARRAY[2,{size}] OF POSITION")
        for n in range(1, size + 1):
            lines += _va_element(1, n, frames.get(n, (0.0,) * 6),
                                 head="'' " if n % 3 == 0 else "",
                                 config="N U T, 0, 0, 0" if n in frames else "N D B, 0, 0, 0")
        for n in range(1, size + 1):
            lines += _va_element(2, n, (9.0, 8.0, 7.0, 6.0, 5.0, 4.0), config="")
        lines += ["", f"[*SYSTEM*]{name}NUM  Storage: SHADOW  Access: RW  : ARRAY[2] OF BYTE",
                  f"  [1] = {selected}", "  [2] = 1", ""]
    return newline.join(lines) + newline


READER_TEXT = """[*SYSTEM*]$CELL_FLOOR  Storage: SHADOW  Access: RW  : POSITION = 
  Group: 1   Config: N D B, 0, 0, 0
  X:   100.000   Y:     0.000   Z:     0.000
  W:     0.000   P:     0.000   R:     0.000

[*SYSTEM*]$MNUFRAME  Storage: SHADOW  Access: RW  : ARRAY[2,4] OF POSITION
    [1,1] = 
  Group: 1   Config: N D B, 0, 0, 0
  X:     0.000   Y:     0.000   Z:     0.000
  W:     0.000   P:     0.000   R:     0.000
    [1,2] = 'Fixture A'
  Group: 1   Config: N U T, 0, 0, 0
  X:  1200.000   Y:  -350.000   Z:   450.000
  W:      .140   P:     -.080   R:    90.000
    [1,3] = '' Uninitialized
    [1,4] = 
  Group: 1   Config: N D B, 0, 0, 0
  X: ********   Y: ********   Z: ********
  W: ********   P: ********   R: ********
    [2,1] = 
  Group: 2   Config: 
  X:    55.000   Y:    66.000   Z:    77.000
  W:     0.000   P:     0.000   R:     0.000
    [2,2] = 
  Group: 2   Config: 
  X:    55.000   Y:    66.000   Z:    77.000
  W:     0.000   P:     0.000   R:     0.000

[*SYSTEM*]$MNUFRAMENUM  Storage: SHADOW  Access: RW  : ARRAY[2] OF BYTE
  [1] = 2
  [2] = 1

$MNUTOOL  Storage: CMOS  Access: RW  : ARRAY[1,3] OF POSITION
  [1,1] = '' Group: 1
    X:  -1.314   Y: -109.600   Z: 764.587
    W: -180.000   P:   0.000   R: -90.000
  [1,3] = 'Gripper' Group: 1
    X:  12.500   Y: 0.000   Z: 1.25e2   W: 0.000   P: -90.000   R: 0.000
[*SYSTEM*]$MNUTOOLNUM  Storage: CMOS  Access: RW  : ARRAY[1] OF BYTE
  [1] = 3
"""


def test_sysframe_va_reader_reads_group_1_frames_at_their_numbers():
    from olp_compensate.programs.fanuc.frames import read_system_frames

    for newline in ("\n", "\r\n"):
        frames = read_system_frames(READER_TEXT.replace("\n", newline), "SYSFRAME.VA")
        assert frames.frames == {
            "UF1": (0.0, 0.0, 0.0, 0.0, 0.0, 0.0),             # zeros: a frame it holds
            "UF2": (1200.0, -350.0, 450.0, 0.14, -0.08, 90.0),
            "UT1": (-1.314, -109.6, 764.587, -180.0, 0.0, -90.0),
            "UT3": (12.5, 0.0, 125.0, 0.0, -90.0, 0.0)}
        # uninitialized (the word, or ********) at their element's line and column
        assert frames.uninitialized == {"UF3": (15, 5, "$MNUFRAME[1,3]"),
                                        "UF4": (16, 5, "$MNUFRAME[1,4]")}
        assert frames.counts == {"UF": 4, "UT": 2}          # group 2 and $...NUM not read
        assert "UF3 ($MNUFRAME[1,3]) is uninitialized" in frames.why_unknown("UF3")
        assert frames.why_unknown("UF3").startswith("SYSFRAME.VA:15:5: ")
        assert "no element [1,2]" in frames.why_unknown("UT2")
        assert frames.why_unknown("UF2") is None and frames.why_unknown("UF0") is None


def test_sysframe_va_of_one_variable_only():
    from olp_compensate.programs.fanuc.frames import read_system_frames

    text = READER_TEXT.split("$MNUTOOL  Storage")[0]
    frames = read_system_frames(text, "SYSTEM.VA")
    assert set(frames.frames) == {"UF1", "UF2"} and "UT" not in frames.counts
    assert frames.why_unknown("UT1") == "SYSTEM.VA: UT1: the file has no $MNUTOOL"


@pytest.mark.parametrize("old, new, line, column, words", [
    ("Y:  -350.000", "Y:  -35O.000", 13, 22, "Y = '-35O.000' is not a number"),
    ("  W:      .140   P:     -.080   R:    90.000\n", "", 11, 5, "[1,2] has no W, P, R"),
    ("R:    90.000", "R:    90.000   R: 1.0", 14, 48, "R given twice"),
    ("  X:  1200.000   Y:  -350.000   Z:   450.000",
     "  J1 =  1200.000 deg  J2 = -350.000 deg", 13, 3, "joint values"),
    ("    [1,2] = 'Fixture A'", "    [2] = 'Fixture A'", 11, 6,
     "expected an element [group,frame]"),
    ("    [1,2] = 'Fixture A'", "    [1,0] = 'Fixture A'", 11, 6, "frame 0"),
    ("    [1,2] = 'Fixture A'", "    [1,2] = Fixture A", 11, 13, "cannot read 'Fixture A'"),
    ("$MNUTOOL  Storage", "$MNUFRAME  Storage", 33, 1, "$MNUFRAME is given twice"),
])
def test_a_sysframe_entry_that_cannot_be_read_is_a_parse_error(old, new, line, column, words):
    from olp_compensate.errors import ParseError
    from olp_compensate.programs.fanuc.frames import read_system_frames

    assert old in READER_TEXT
    with pytest.raises(ParseError) as info:
        read_system_frames(READER_TEXT.replace(old, new, 1), "SYSFRAME.VA")
    assert (info.value.file, info.value.line, info.value.column) == ("SYSFRAME.VA", line, column)
    assert words in info.value.message, info.value.message
    assert str(info.value).startswith(f"SYSFRAME.VA:{line}:{column}: ")


def test_a_file_without_frames_is_a_parse_error():
    from olp_compensate.errors import ParseError
    from olp_compensate.programs.fanuc.frames import read_system_frames

    with pytest.raises(ParseError, match=r"neither \$MNUFRAME nor \$MNUTOOL") as info:
        read_system_frames("[*SYSTEM*]$MNUFRAMENUM  Storage: SHADOW  Access: RW  : ARRAY[1] "
                           "OF BYTE\n  [1] = 2\n", "$config.dat")
    assert (info.value.line, info.value.column) == (1, 1)


UF2_MM = (1150.25, -320.5, 410.75, 1.5, -2.25, 30.0)
"""The cell's user frame 2 (as the controller holds it; 3 decimals as the .VA writes)."""


def _targets_in_frame(q_ctrl, tool_mm, uf_mm, controller):
    """(values in UF, letters, turns) of the TCP poses at controller joints ``q_ctrl``."""
    tool = FANUC_TP.convention.pose(np.array(tool_mm))
    base_T_uf = FANUC_TP.convention.pose(np.array(uf_mm))
    out = []
    for q in q_ctrl:
        pose = invert_pose(base_T_uf) @ controller.nominal.flange_poses(q[None])[0] @ tool
        out.append((_wpr(pose), fanuc_letters(controller.geometry, q),
                    tuple(turn_number(math.degrees(v)) for v in q[3:6])))
    return out


@pytest.fixture(scope="module")
def uf2_cell(fanuc_world):
    """A program in UF 2 / UT 3 for the virtual robot, its SYSFRAME.VA, the controller, and
    the calibration with its measured point named as the program's tool (UT3)."""
    import dataclasses

    from olp_compensate.calibration.calibration import ToolPoint

    virtual, cal = fanuc_world
    tools = dict(cal.tools)
    tools["UT3"] = ToolPoint(xyz_m=cal.tools["tcp"].xyz_m, for_programs=True)
    cal = dataclasses.replace(cal, tools=tools)
    tool_mm = tuple(np.round(virtual.tools["tcp"] * 1e4) / 10) + (0.0, 0.0, 0.0)
    controller = FanucController()
    written = _targets_in_frame(_program_joints(8, 21), tool_mm, UF2_MM, controller)
    text = ls_program(written, uf=2, ut=3)
    va = sysframe_va({2: UF2_MM, 5: (1.0, 2.0, 3.0, 0.0, 0.0, 0.0)},
                     {3: tool_mm, 1: (0.0, 0.0, 100.0, 0.0, 0.0, 0.0)})
    return dict(virtual=virtual, cal=cal, tool_mm=tool_mm, controller=controller,
                written=written, text=text, va=va)


def _reach_mm(cell, new_text):
    """(untouched, compensated) distances, mm, from each target's meant point to where the
    virtual robot's real TCP goes when the nominal controller runs the program."""
    virtual, controller = cell["virtual"], cell["controller"]
    tool = FANUC_TP.convention.pose(np.array(cell["tool_mm"]))
    uf = FANUC_TP.convention.pose(np.array(UF2_MM))
    again = {t.name: t for t in parse_fanuc_tp(new_text, "CELL.ls").targets}
    meant, before, after = [], [], []
    for k, (values, letters, turns) in enumerate(cell["written"], 1):
        values = np.array([float(_f(v)) for v in values])          # as written in the file
        meant.append((cell["cal"].device_T_base @ uf @ FANUC_TP.convention.pose(values))[:3, 3])
        before.append(controller.joints(
            uf @ FANUC_TP.convention.pose(values) @ invert_pose(tool), letters, turns))
        target = again[f"P[{k}]"]
        new_values = np.array([n.value for n in target.numbers])
        new_config = [n.text for n in target.config]
        after.append(controller.joints(
            uf @ FANUC_TP.convention.pose(new_values) @ invert_pose(tool), new_config[:3],
            [int(t) for t in new_config[3:]]))
    return misses_mm(virtual, meant, before, after)


def _files(tmp_path, cell, va=None):
    from olp_compensate.compensation.files import ProgramFiles

    ls = tmp_path / "CELL.ls"
    ls.write_bytes(cell["text"].encode("latin-1"))
    config = tmp_path / "SYSFRAME.VA"
    config.write_bytes((cell["va"] if va is None else va).encode("latin-1"))
    return ProgramFiles("fanuc", (ls,), ("CELL.ls",)), config


def test_frames_from_sysframe_va_compensate_a_program_in_uf2_ut3(uf2_cell, tmp_path):
    from olp_compensate.compensation.files import compensate_files

    files, config = _files(tmp_path, uf2_cell)
    result = compensate_files(files, uf2_cell["cal"], frames_path=config)
    report = result.report
    assert report.exit_code == 0, [(r.target, r.status, r.note) for r in report.rows]
    rows = [r for r in report.rows if r.target.startswith("P[") and r.target != "P[99]"]
    assert len(rows) == 8 and all(r.wobj == "UF2" and r.tool == "UT3" for r in rows)
    assert all("real TCP of UT3 from the calibration" in r.note for r in rows)
    new_text = result.data[0].decode("latin-1")
    assert_the_gap_closed("FANUC UF2/UT3 from SYSFRAME.VA", *_reach_mm(uf2_cell, new_text))
    assert new_text.split("/POS")[0] == uf2_cell["text"].split("/POS")[0]


def test_frames_from_sysframe_va_with_the_nominal_calibration_give_the_bytes_back(uf2_cell,
                                                                                 tmp_path):
    from olp_compensate.compensation.files import compensate_files

    files, config = _files(tmp_path, uf2_cell)
    result = compensate_files(files, nominal_calibration(ROBOT), frames_path=config)
    assert result.data[0] == uf2_cell["text"].encode("latin-1")
    statuses = [r.status for r in result.report.rows]
    assert statuses.count("ok") + statuses.count("singular") == 8, result.report.rows
    assert result.report.warnings == ()


def test_without_the_sysframe_va_the_frames_are_unresolved_and_named(uf2_cell, tmp_path):
    from olp_compensate.compensation.files import compensate_files

    files, _ = _files(tmp_path, uf2_cell)
    # the nominal calibration has no tool UT3: the tool is named
    result = compensate_files(files, nominal_calibration(ROBOT))
    assert result.data[0] == uf2_cell["text"].encode("latin-1")
    unresolved = [r for r in result.report.rows if r.status == "unresolved"]
    assert len(unresolved) == 8 and all("UT3 unknown" in r.note for r in unresolved)
    # a calibration with a tool UT3 gives the tool; the user frame is then named
    result = compensate_files(files, uf2_cell["cal"])
    unresolved = [r for r in result.report.rows if r.status == "unresolved"]
    assert len(unresolved) == 8 and all("UF2 unknown" in r.note for r in unresolved)
    assert result.report.exit_code == 2


def test_an_uninitialized_frame_is_unresolved_with_the_frame_and_the_file(uf2_cell, tmp_path):
    from olp_compensate.compensation.files import compensate_files

    va = sysframe_va({2: None}, {3: uf2_cell["tool_mm"]})
    files, config = _files(tmp_path, uf2_cell, va)
    result = compensate_files(files, uf2_cell["cal"], frames_path=config)
    assert result.data[0] == uf2_cell["text"].encode("latin-1")      # never as identity
    unresolved = [r for r in result.report.rows if r.status == "unresolved"]
    assert len(unresolved) == 8 and all(r.wobj == "UF2" and "UF2 unknown" in r.note
                                        for r in unresolved)
    line = va.split("\r\n").index("    [1,2] = '' Uninitialized") + 1
    (warning,) = result.report.warnings
    assert warning.startswith(f"{config}:{line}:5: UF2 ($MNUFRAME[1,2]) is uninitialized"), \
        warning
    # a tool frame the file does not hold: named with the file too
    va = sysframe_va({2: UF2_MM}, {}, size=2)
    files, config = _files(tmp_path, uf2_cell, va)
    result = compensate_files(files, nominal_calibration(ROBOT), frames_path=config)
    assert all("UT3 unknown" in r.note for r in result.report.rows if r.status == "unresolved")
    (warning,) = result.report.warnings
    assert warning.startswith(f"{config}: UT3 is not in the file") and "tool3" in warning


def test_a_frame_the_program_sets_at_run_time_does_not_take_the_backups_value(uf2_cell,
                                                                              tmp_path):
    """``UFRAME[2]=PR[5]`` in /MN: UF2 is not what SYSFRAME.VA holds while the program
    runs, so its targets stay unresolved (never compensated in a stale frame), with a
    warning at that line."""
    from olp_compensate.compensation.files import compensate_files

    statement = "   2:  UFRAME[2]=PR[5] ;\r\n"
    text = uf2_cell["text"].replace("   2:  UTOOL_NUM", statement + "   2:  UTOOL_NUM", 1)
    line = text[:text.index(statement)].count("\n") + 1
    cell = dict(uf2_cell, text=text)
    files, config = _files(tmp_path, cell)
    result = compensate_files(files, uf2_cell["cal"], frames_path=config)
    assert result.data[0] == cell["text"].encode("latin-1")
    unresolved = [r for r in result.report.rows if r.status == "unresolved"]
    assert len(unresolved) == 8 and all("UF2 unknown" in r.note for r in unresolved)
    assert any(w.startswith(f"CELL.ls:{line}: UF2 is set at run time")
               and "SYSFRAME.VA" in w for w in result.report.warnings), result.report.warnings


def test_olp_fix_reads_the_frames_of_a_sysframe_va(uf2_cell, tmp_path, capsys):
    import csv

    from olp_compensate.cli.fix import main
    from olp_compensate.io.calibration_file import write_calibration

    _, config = _files(tmp_path, uf2_cell)
    prog, model = tmp_path / "CELL.ls", tmp_path / "calib.json"
    write_calibration(model, uf2_cell["cal"])
    out, report = tmp_path / "out.ls", tmp_path / "report.csv"
    assert main([str(prog), "--config", str(config), "--model", str(model), "-o", str(out),
                 "--report", str(report), "-q"]) == 0
    assert_the_gap_closed("FANUC, olp-fix --config SYSFRAME.VA",
                          *_reach_mm(uf2_cell, out.read_bytes().decode("latin-1")))
    with open(report, newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["target"] not in ("P[99]",)]
    assert len(rows) == 8 and {r["wobj"] for r in rows} == {"UF2"}
    # without --config: the targets are reported, the program written back unchanged
    assert main([str(prog), "--model", str(model), "-o", str(tmp_path / "plain.ls"),
                 "-q"]) == 2
    assert (tmp_path / "plain.ls").read_bytes() == prog.read_bytes()
    # a frame entry that cannot be read: one line with file:line:column, exit 1, no output
    capsys.readouterr()
    bad = uf2_cell["va"].replace("-320.500", "-320,500", 1)
    assert bad != uf2_cell["va"]
    config.write_bytes(bad.encode("latin-1"))
    assert main([str(prog), "--config", str(config), "--model", str(model), "-o",
                 str(tmp_path / "bad.ls"), "-q"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    line = bad.split("\r\n").index(next(s for s in bad.split("\r\n") if "-320,500" in s)) + 1
    assert len(err) == 1 and f"SYSFRAME.VA:{line}:" in err[0] and "not a number" in err[0], err
    assert not (tmp_path / "bad.ls").exists()
