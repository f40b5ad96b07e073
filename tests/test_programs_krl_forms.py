"""KRL as real programs write it: declarations without DECL, CONST and GLOBAL, STRUC values
holding frames, points of $config.dat, functions, arrays indexed at run time, the geometric
operator ':' (motions and frame assignments), damaged files. Every target literal is
counted by this test's own scanner and found in the report."""

from __future__ import annotations

import re

import numpy as np
import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.compensation.dialect_program import compensate_pose_program
from olp_compensate.programs.krl.rules import KRL
from olp_compensate.errors import ParseError
from olp_compensate.programs.krl.reader import parse_krl
from test_programs_krl import ROBOT, _program_joints, _targets_at
from virtual_world import identified_world

CONFIG = """DEFDAT  $CONFIG
DECL FRAME TOOL_DATA[16]
TOOL_DATA[1]={X 12.0,Y -5.0,Z 180.0,A 0.0,B 0.0,C 0.0}
DECL E6AXIS XHOME={A1 0.0,A2 -90.0,A3 90.0,A4 0.0,A5 0.0,A6 0.0,E1 0.0}
DECL E6POS XSERVICE={service}
DECL E6POS XUNUSED={X 1000.0,Y 10.0,Z 900.0,A 0.0,B 90.0,C 0.0,S 2,T 2}
ENDDAT
"""


def _agg(values, s=None, t=None):
    x, y, z, a, b, c = values
    st = "" if s is None else f",S {s},T {t}"
    return f"{{X {x:.3f},Y {y:.3f},Z {z:.3f},A {a:.4f},B {b:.4f},C {c:.4f}{st}}}"


def cell(seed=3):
    """(.src, .dat) of a cell using every declaration form; targets reachable by the KR 16."""
    written = _targets_at(_program_joints(10, seed))
    v = [w[0] for w in written]
    st = [(w[1], w[2]) for w in written]
    dat = "\n".join([
        "DEFDAT  CELL PUBLIC",
        "STRUC CNCPOS FRAME fCnC, REAL grFeedrate",
        "DECL CNCPOS gsCNC1[3]",
        f"gsCNC1[1]={{fCnC {_agg(v[0])}, grFeedrate 2000}}",
        f"DECL E6POS XP1={_agg(v[1], *st[1])}",
        f"E6POS XP2={_agg(v[2], *st[2])}",
        f"DECL CONST POS XC={_agg(v[3], *st[3])}",
        f"GLOBAL E6POS XG={_agg(v[4], *st[4])}",
        f"DECL GLOBAL E6POS XG2={_agg(v[5], *st[5])}",
        "DECL E6POS basePos[2]",
        f"basePos[1]={_agg(v[6], *st[6])}",
        f"basePos[2]={_agg(v[7], *st[7])}",
        "DECL FDAT FP1={TOOL_NO 1,BASE_NO 0,IPO_FRAME #BASE}",
        "ENDDAT", ""])
    src = "\n".join([
        "DEF CELL( )",
        "DECL INT i",
        "FDAT_ACT=FP1",
        "BAS(#PTP_PARAMS,100)",
        "PTP XHOME",
        "PTP XSERVICE",
        "LIN XP1",
        "LIN XP2",
        "LIN XC",
        "LIN XG",
        "LIN XG2",
        "LIN gsCNC1[1].fCNC",
        "FOR i=1 TO 2",
        "  SPTP basePos[i]",
        "ENDFOR",
        "LIN XP1 : {X 0.0,Y 0.0,Z -40.0,A 0.0,B 0.0,C 0.0}",
        "SLIN calcTopPos(XP1, 50.0)",
        f"LIN {_agg(v[8], *st[8])}",
        "END",
        "",
        "DEFFCT E6POS calcTopPos(p:IN, dz:IN)",
        "  DECL E6POS p",
        "  DECL REAL dz",
        "  p.Z = p.Z + dz",
        "  RETURN p",
        "ENDFCT", ""])
    return src, dat, CONFIG.replace("{service}", _agg(v[9], *st[9]))


def _target_literals(text: str) -> list[tuple[int, int]]:
    """(line, column) of every innermost aggregate with an X or an A1 field that is not a
    TOOL_DATA/BASE_DATA frame: this test's own scanner."""
    out = []
    for n, line in enumerate(text.split("\n"), 1):
        code = line.split(";", 1)[0]
        if re.match(r"\s*(TOOL_DATA|BASE_DATA)\b", code):
            continue
        for m in re.finditer(r"\{[^{}]*\}", code):
            if re.search(r"(?:^|[{,])\s*(X|A1)\s+[-+.\d]", m.group()[1:]):
                out.append((n, m.start() + 1))
    return out


def _run(calibration, seed=3):
    src, dat, config = cell(seed)
    program = parse_krl(src, dat, "CELL.src", "CELL.dat", {"$config.dat": config})
    texts, report = compensate_pose_program(program, KRL, calibration)
    return src, dat, config, texts, report


def test_every_literal_of_every_form_has_a_row_and_nothing_moves_with_the_nominal_model():
    src, dat, config, texts, report = _run(nominal_calibration(ROBOT))
    assert texts["CELL.src"] == src and texts["CELL.dat"] == dat
    assert "$config.dat" not in texts or texts["$config.dat"] == config
    places = {(r.file, r.line, r.column) for r in report.rows}
    for file, text in (("CELL.src", src), ("CELL.dat", dat)):
        literals = _target_literals(text)
        assert literals
        for line, column in literals:
            assert (file, line, column) in places, (file, line, column)
    assert len(_target_literals(dat)) == 8 and len(_target_literals(src)) == 2
    rows = {r.target: r for r in report.rows}
    for name in ("XP2", "XC", "XG", "XG2", "gsCNC1[1].fCnC", "basePos[1]", "basePos[2]"):
        assert rows[name].status in ("ok", "singular"), rows[name]
        assert rows[name].tool == "TOOL_DATA[1]"
    assert rows["XHOME"].status == "joint_target" and rows["XHOME"].file == "$config.dat"
    # a Cartesian point of $config.dat: solved, its values reported, the file not written
    assert rows["XSERVICE"].status == "config_point" and "set it to (" in rows["XSERVICE"].note
    assert "XUNUSED" not in rows
    assert rows["basePos[i]"].status == "runtime"
    call = rows["calcTopPos(..)"]
    assert call.status == "runtime" and "DEFFCT at line 21" in call.note
    # ':' of a point and a literal: the literal's row, never an 'ok' for XP1 from it
    composed = next(r for r in report.rows if r.file == "CELL.src" and r.line == 16)
    assert composed.status in ("ok", "singular") and "XP1 : this target" in composed.note
    assert sum(1 for r in report.rows if r.target == "XP1") == 1     # its own LIN only


def test_a_point_moved_to_only_through_the_operator_is_not_reported_ok():
    src = "DEF m( )\nLIN XP1 : {X 0,Y 0,Z 100,A 0,B 0,C 0}\nEND\n"
    dat = "DEFDAT m\nDECL E6POS XP1={X 1000,Y 0,Z 900,A 0,B 90,C 0,S 2,T 2}\nENDDAT\n"
    _, report = compensate_pose_program(parse_krl(src, dat, "m.src", "m.dat"), KRL,
                                        nominal_calibration(ROBOT))
    (xp1,) = [r for r in report.rows if r.target == "XP1"]
    assert xp1.status == "unused" and "left operand of ':'" in xp1.note
    # two names: not written back, run time with the reason
    src = "DEF m( )\nLIN XP1 : XP1\nLIN $POS_ACT : {X 0,Y 0,Z 10,A 0,B 0,C 0}\nEND\n"
    _, report = compensate_pose_program(parse_krl(src, dat, "m.src", "m.dat"), KRL,
                                        nominal_calibration(ROBOT))
    runtime = [r for r in report.rows if r.status == "runtime"]
    assert len(runtime) == 2 and "only 'point : {literal}'" in runtime[0].note
    assert "system variable" in runtime[1].note
    assert not any(r.status == "ok" for r in report.rows)


def _compose(a, b):
    return KRL.convention.pose(np.asarray(a, float)) @ KRL.convention.pose(np.asarray(b, float))


def test_the_operator_is_compensated_as_the_composed_target():
    """``LIN XP1 : {dz}`` compensated and composed again equals the compensated target
    written as one point (the direct path, checked on the virtual robot elsewhere)."""
    _, cal = identified_world(ROBOT, 5, "TOOL_DATA[1]")
    values, s, t = _targets_at(_program_joints(1, 4))[0]
    offset = (5.0, -3.0, -20.0, 2.0, 0.0, 0.0)
    direct_pose = _compose(values, offset)
    direct = np.concatenate([direct_pose[:3, 3] * 1e3, KRL.convention.angles(
        direct_pose[:3, :3], np.zeros(3))])
    x = ",".join(f"{k} {w:.4f}" for k, w in zip("XYZABC", offset))
    dat = f"DEFDAT m\nDECL E6POS XP1={_agg(values, s, t)}\nDECL E6POS XQ={_agg(direct, s, t)}\n" \
          f"DECL FDAT FP1={{TOOL_NO 1,BASE_NO 0,IPO_FRAME #BASE}}\nENDDAT\n"
    src = f"DEF m( )\nFDAT_ACT=FP1\nBAS(#PTP_PARAMS,100)\nLIN XP1 : {{{x}}}\nLIN XQ\nEND\n"
    config = "DEFDAT $CONFIG\nTOOL_DATA[1]={X 12.0,Y -5.0,Z 180.0,A 0.0,B 0.0,C 0.0}\nENDDAT\n"
    program = parse_krl(src, dat, "m.src", "m.dat", config)
    texts, report = compensate_pose_program(program, KRL, cal)
    assert all(r.status in ("ok", "singular", "unused") for r in report.rows), \
        [(r.target, r.status, r.note) for r in report.rows]
    again = {t.name or f"line{t.source[1]}": t
             for t in parse_krl(texts["m.src"], texts["m.dat"], "m.src", "m.dat").targets}
    new_xp1 = [n.value for n in again["XP1"].numbers]
    assert new_xp1 == [float(v) for v in _agg(values)[1:-1].replace(",", " ").split()[1::2]]
    new_right = [n.value for n in again["line4"].numbers]
    new_xq = [n.value for n in again["XQ"].numbers]
    got = _compose(new_xp1, new_right)
    want = KRL.convention.pose(np.array(new_xq))
    assert np.max(np.abs(got[:3, 3] - want[:3, 3])) * 1e3 < 2e-3        # mm, 3 decimals
    assert np.max(np.abs(got[:3, :3] - want[:3, :3])) < 1e-5
    assert np.max(np.abs(np.array(new_right) - np.array(offset))) > 1e-3   # it did change


def test_frame_assignment_with_the_operator_composes_the_tool():
    src = ("DEF m( )\nTOOL_DATA[2] = TOOL_DATA[1] : {X 0,Y 0,Z 50,A 0,B 0,C 0}\n"
           "BAS(#TOOL,2)\nLIN XP1\nEND\n")
    dat = "DEFDAT m\nDECL E6POS XP1={X 1000,Y 0,Z 900,A 0,B 90,C 0,S 2,T 2}\nENDDAT\n"
    program = parse_krl(src, dat, "m.src", "m.dat", CONFIG)
    np.testing.assert_allclose(program.frames["TOOL_DATA[2]"],
                               (12.0, -5.0, 230.0, 0.0, 0.0, 0.0), atol=1e-9)
    assert any("m.src:2: TOOL_DATA[2] = TOOL_DATA[1]" in n for n in program.notes)
    program = parse_krl(src.replace("TOOL_DATA[1] :", "TOOL_DATA[7] :"), dat, "m.src", "m.dat",
                        CONFIG)
    assert "TOOL_DATA[2]" not in program.frames
    _, report = compensate_pose_program(program, KRL, nominal_calibration(ROBOT))
    (row,) = [r for r in report.rows if r.target == "XP1"]
    assert row.status == "unresolved" and "TOOL_DATA[2]" in row.note


@pytest.mark.parametrize("old, new, line, column, words", [
    ("Z 900,A 0", "Z 2E+,A 0", 2, 30, "malformed number '2E+'"),
    ("Z 900,A 0", "Z nan,A 0", 2, 30, "nan is not a finite number"),
    ("Z 900,A 0", "Z 9.0.0,A 0", 2, 30, "malformed number '9.0.0'"),
])
def test_damaged_numbers_are_refused_at_their_place(old, new, line, column, words):
    dat = "DEFDAT m\nDECL E6POS XP1={X 1000,Y 0,Z 900,A 0,B 90,C 0,S 2,T 2}\nENDDAT\n"
    bad = dat.replace(old, new)
    with pytest.raises(ParseError) as info:
        parse_krl("DEF m( )\nLIN XP1\nEND\n", bad, "m.src", "m.dat")
    assert (info.value.file, info.value.line, info.value.column) == ("m.dat", line, column)
    assert words in info.value.message


def test_binary_and_utf16_files_are_refused():
    dat = "DEFDAT m\nDECL E6POS XP1={X 1000,Y 0,Z 900,A 0,B 90,C 0,S 2,T 2}\nENDDAT\n"
    with pytest.raises(ParseError, match="UTF-16") as info:
        parse_krl(None, dat.encode("utf-16-le").decode("latin-1"), "m.src", "m.dat")
    assert (info.value.file, info.value.line, info.value.column) == ("m.dat", 1, 2)
    with pytest.raises(ParseError, match="binary") as info:
        parse_krl("DEF m( )\n\x00\x01LIN XP1\nEND\n", dat, "m.src", "m.dat")
    assert (info.value.file, info.value.line, info.value.column) == ("m.src", 2, 1)


def test_assignments_in_the_src_are_run_time_and_their_literals_have_rows():
    src = ("DEF m( )\nDECL INT n\n$TOOL = {FRAME: X 0,Y 0,Z 120,A 0,B 0,C 0}\n"
           "TOOL_DATA[n] = TOOL_DATA[11] :{X 0,Y 0,Z 5,A 0,B 0,C 0}\n"
           "XP1 = {X 900,Y 10,Z 800,A 0,B 90,C 0}\nLIN XP1\nXP2.Z = XP2.Z + 10\nLIN XP2\n"
           "LIN XP3\nEND\n")
    dat = ("DEFDAT m\nDECL E6POS XP1={X 1000,Y 0,Z 900,A 0,B 90,C 0,S 2,T 2}\n"
           "DECL E6POS XP2={X 1000,Y 0,Z 900,A 0,B 90,C 0,S 2,T 2}\n"
           "DECL E6POS XP3={X 1000,Y 0,Z 900,A 0,B 90,C 0,S 2,T 2}\nENDDAT\n")
    _, report = compensate_pose_program(parse_krl(src, dat, "m.src", "m.dat"), KRL,
                                        nominal_calibration(ROBOT))
    rows = {(r.file, r.line): r for r in report.rows}
    assert rows["m.src", 3].status == "frame" and rows["m.src", 4].status == "frame"
    assert rows["m.src", 5].status == "runtime" and "assigned to XP1" in rows["m.src", 5].note
    assert rows["m.src", 6].status == "runtime" and "XP1 is assigned" in rows["m.src", 6].note
    assert rows["m.src", 8].status == "runtime" and "line 7" in rows["m.src", 8].note
    assert rows["m.dat", 4].status != "runtime"               # XP3: moved to as declared
    for line, column in _target_literals(src):
        assert ("m.src", line) in rows, line


def test_tool_and_base_set_in_the_src_take_their_own_frames():
    """``$TOOL = {..}`` (as RoboDK's posts write) is that frame, never the tool in force
    before it; ``$TOOL`` set from anything computed leaves its targets unresolved."""
    src = ("DEF m( )\nBAS(#TOOL,1)\nLIN XP1\n$TOOL = {FRAME: X 12.0,Y -5.0,Z 180.0,A 0,B 0,C 0}\n"
           "LIN XP2\n$TOOL = TOOL_DATA[n]\nLIN XP3\nEND\n")
    dat = ("DEFDAT m\nDECL E6POS XP1={X 1000,Y 0,Z 900,A 0,B 90,C 0,S 2,T 2}\n"
           "DECL E6POS XP2={X 1000,Y 50,Z 900,A 0,B 90,C 0,S 2,T 2}\n"
           "DECL E6POS XP3={X 1000,Y 90,Z 900,A 0,B 90,C 0,S 2,T 2}\nENDDAT\n")
    program = parse_krl(src, dat, "m.src", "m.dat", CONFIG)
    assert program.frames["$TOOL@L4"] == (12.0, -5.0, 180.0, 0.0, 0.0, 0.0)
    _, report = compensate_pose_program(program, KRL, nominal_calibration(ROBOT))
    rows = {r.target: r for r in report.rows}
    assert rows["XP1"].tool == "TOOL_DATA[1]" and rows["XP2"].tool == "$TOOL@L4"
    assert rows["XP2"].status != "unresolved"              # solved with that frame
    assert rows["XP3"].status == "unresolved" and "TOOL_DATA[n]" in rows["XP3"].note


def test_a_routine_that_may_set_the_frames_makes_motions_without_one_run_time():
    """A cell whose routine sets ``FDAT_ACT``/``$TOOL`` at run time (``MoveSettings(nBase,
    nTool, ..)``, as a public milling cell does): a motion after it, with no tool or base
    set in the file, is never solved with the flange or the robot base; a frame set after
    the call is used again, and without the call the flange is taken as before, noted."""
    dat = ("DEFDAT m\nDECL E6POS XP1={X 1000,Y 0,Z 900,A 0,B 90,C 0,S 2,T 2}\n"
           "DECL E6POS XP2={X 1000,Y 50,Z 900,A 0,B 90,C 0,S 2,T 2}\n"
           "DECL E6POS XP3={X 1000,Y 90,Z 900,A 0,B 90,C 0,S 2,T 2}\nENDDAT\n")
    src = ("DEF m( )\nIF (n > 0) THEN\nWAIT SEC 0.1\nENDIF\nMoveSettings(11, 20, 100, 500)\n"
           "LIN XP1\nLIN XP2 : {X 0,Y 4,Z 0,A 0,B 0,C 0}\nBAS(#TOOL,1)\nBAS(#BASE,0)\n"
           "LIN XP3\nEND\n")
    _, report = compensate_pose_program(parse_krl(src, dat, "m.src", "m.dat", CONFIG), KRL,
                                        nominal_calibration(ROBOT))
    rows = {(r.file, r.line): r for r in report.rows}
    first = rows["m.src", 6]
    assert first.status == "runtime" and "MoveSettings() (line 5)" in first.note
    assert rows["m.dat", 2].status == "unused"                # written back unchanged
    composed = rows["m.src", 7]
    assert composed.status == "runtime" and "MoveSettings()" in composed.note
    assert rows["m.dat", 4].tool == "TOOL_DATA[1]"
    assert rows["m.dat", 4].status not in ("runtime", "unresolved", "unused")
    plain = src.replace("MoveSettings(11, 20, 100, 500)\n", "\n")
    _, report = compensate_pose_program(parse_krl(plain, dat, "m.src", "m.dat", CONFIG), KRL,
                                        nominal_calibration(ROBOT))
    first = next(r for r in report.rows if (r.file, r.line) == ("m.dat", 2))
    assert first.status not in ("runtime", "unused") and "taken as the flange" in first.note


def test_older_inline_forms_load_the_fdat_frames_with_bas_frames():
    """KSS 4-style folds (``BAS(#PTP_DAT)``, ``FDAT_ACT=F1``, ``BAS(#FRAMES)``): KUKA's
    BAS.SRC runs ``FRAMES()`` there, which sets $TOOL and $BASE from ``FDAT_ACT``."""
    dat = ("DEFDAT m\nDECL E6POS XP1={X 1000,Y 0,Z 900,A 0,B 90,C 0,S 2,T 2}\n"
           "DECL FDAT FP1={TOOL_NO 1,BASE_NO 0,IPO_FRAME #BASE}\nENDDAT\n")
    src = ("DEF m( )\nA20(ARC_INI)\nBAS(#PTP_DAT)\nFDAT_ACT=FP1\nBAS(#FRAMES)\n"
           "BAS(#VEL_PTP,100)\nPTP XP1\nEND\n")
    program = parse_krl(src, dat, "m.src", "m.dat", CONFIG)
    assert program.motions[0].tool == "TOOL_DATA[1]" and program.motions[0].runtime is None
    assert program.motions[0].base == "BASE_DATA[0]"
