"""URScript: every ``p[...]`` literal of a script in a report row (counted by a scanner of
this test's own), relative waypoints, ``.urscript`` files, damaged scripts refused at their
place."""

from __future__ import annotations

import re

import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.compensation.dialect_program import compensate_pose_program
from olp_compensate.programs.urscript.rules import URSCRIPT
from olp_compensate.errors import ParseError
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs.urscript.reader import parse_urscript

ROBOT = load_robot("ur10e")

# shaped like a Polyscope export: a Direction node, force mode, relative waypoints, a
# function with a default pose, a TCP assigned then set, payload settings
SCRIPT = """def cell():
  set_tcp(p[0.0,0.0,0.15,0.0,0.0,0.0])
  set_payload(1.2, [0.0, 0.0, 0.06])
  global gripper_tcp=p[0.0,0.01,0.2,0.0,0.0,0.0]
  global Waypoint_1_p=p[-.420, -.180, .350, 2.2214, -2.2214, 0.0]
  global Waypoint_1_q=[0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
  global Waypoint_2_from_p=p[-.420, -.180, .350, 2.2214, -2.2214, 0.0]
  global Waypoint_2_to_p=p[-.420, -.180, .250, 2.2214, -2.2214, 0.0]
  def approach(where=p[-.400, -.200, .300, 2.2214, -2.2214, 0.0]):
    movel(pose_trans(where, p[0, 0, -.05, 0, 0, 0]), a=1.2, v=0.25)
  end
  movej(get_inverse_kin(Waypoint_1_p, qnear=Waypoint_1_q), a=1.4, v=1.05)
  set_tcp(gripper_tcp)
  movel(pose_add(get_actual_tcp_pose(), pose_sub(Waypoint_2_to_p, Waypoint_2_from_p)), a=1.2, v=0.25)
  $ 7 "Direction: Tool Z-"
  global move_thread_flag_7=0
  target = calculate_point_to_move_towards(p[0.0,0.0,0.0,0.0,0.0,0.0], [0.0,0.0,-1.0], 0.1)
  movel(target, a=1.2, v=0.25)
  force_mode(p[0.0,0.0,0.0,0.0,0.0,0.0], [0, 0, 1, 0, 0, 0], [0.0, 0.0, 20.0, 0.0, 0.0, 0.0], 2, [0.1, 0.1, 0.15, 0.35, 0.35, 0.35])
  movel(p[-.380, -.150, .300, 2.2214, -2.2214, 0.0], a=1.2, v=0.25)
  end_force_mode()
  approach()
end
"""


def _literals(text: str) -> list[tuple[int, int]]:
    """(line, column) of every ``p[`` pose literal outside comments: this test's scanner."""
    out = []
    for n, line in enumerate(text.split("\n"), 1):
        code = line.split("#", 1)[0]
        out += [(n, m.start() + 1) for m in re.finditer(r"(?<![\w.])p\[", code)]
    return out


def _report(text: str):
    return compensate_pose_program(parse_urscript(text, "cell.script"), URSCRIPT,
                                   nominal_calibration(ROBOT))


def test_every_pose_literal_has_a_row():
    texts, report = _report(SCRIPT.replace("$ 7", "# $ 7"))
    assert texts["cell.script"] == SCRIPT.replace("$ 7", "# $ 7")
    places = {(r.line, r.column) for r in report.rows}
    literals = _literals(SCRIPT)
    assert len(literals) == 10
    # a literal's row sits at its "p[" (not named) or at its first number (named targets)
    for line, column in literals:
        code = SCRIPT.split("\n")[line - 1]
        first_number = column + code[column - 1:].index("[")
        assert (line, column) in places or (line, first_number + 1) in places, (line, column)
    rows = {r.line: r for r in report.rows if r.target.startswith("p[")}
    assert rows[2].status == "frame" and "set_tcp" in rows[2].note
    assert rows[4].status == "frame"
    assert rows[9].status == "runtime" and "default argument of approach()" in rows[9].note
    assert rows[10].status == "runtime" and "pose_trans" in rows[10].note
    assert rows[17].status == "runtime" and "Direction node" in rows[17].note
    assert rows[19].status == "frame" and "force_mode" in rows[19].note
    relative = [r for r in report.rows if r.target.startswith("Waypoint_2_")]
    assert len(relative) == 2 and all(r.status == "runtime" and "pose_sub" in r.note
                                      for r in relative)
    assert {r.status for r in report.rows if r.line in (5, 20)} <= {"ok", "singular"}


def test_a_urscript_file_needs_no_dialect(tmp_path):
    from olp_compensate.cli.fix import main
    from olp_compensate.io.calibration_file import write_calibration

    program = tmp_path / "cell.urscript"
    program.write_text(SCRIPT.replace("$ 7", "# $ 7"))
    model = tmp_path / "calib.json"
    write_calibration(model, nominal_calibration(ROBOT))
    out = tmp_path / "out.urscript"
    assert main([str(program), "--model", str(model), "-o", str(out), "-q"]) == 2
    assert out.read_bytes() == program.read_bytes()


@pytest.mark.parametrize("old, new, line, column, words", [
    ("p[-.380, -.150", "p[-.380, -.15E+", 20, 18, "malformed number"),
    ("p[-.380, -.150", "p[nan, -.150", 20, 11, "malformed number 'nan'"),
    ("approach()\nend\n", "approach()\n", 22, 13, "'def' at line 1"),
])
def test_damaged_scripts_are_refused_at_their_place(old, new, line, column, words):
    text = SCRIPT.replace("$ 7", "# $ 7").replace(old, new, 1)
    assert text != SCRIPT
    with pytest.raises(ParseError) as info:
        parse_urscript(text, "cell.script")
    assert (info.value.line, info.value.column) == (line, column), str(info.value)
    assert words in info.value.message


def test_binary_and_utf16_scripts_are_refused():
    utf16 = SCRIPT.encode("utf-16").decode("latin-1")
    with pytest.raises(ParseError, match="UTF-16") as info:
        parse_urscript(utf16, "cell.script")
    assert (info.value.line, info.value.column) == (1, 1)
    binary = (SCRIPT[:40] + "\x00\x13\x88" + SCRIPT[40:])
    with pytest.raises(ParseError, match="binary") as info:
        parse_urscript(binary, "cell.script")
    assert (info.value.line, info.value.column) == (2, 29)


def test_a_crlf_script_cut_short_is_refused_too():
    text = "def a():\r\n  if x:\r\n    movel(p[0,0,0,0,0,0])\r\n  end\r\n"
    with pytest.raises(ParseError, match="'def' at line 1") as info:
        parse_urscript(text, "a.script")
    assert (info.value.line, info.value.column) == (4, 6)
    parse_urscript(text + "end\r\n", "a.script")
