"""Kawasaki AS dumps (and V+ files with stray carriage returns) through olp-fix's path.

The dumps are written here in the layout of real controller saves (a ``.***`` header,
one-line ``.NETCONF`` entries, ``.ROBOTDATA1``/``.SYSDATA``/``.AUXDATA``/``.INTER_PANEL_D``
sections full of numbers, programs with local variables, ``.TRANS`` lines with external
axes, ``.JOINTS``, ``.REALS``, ``.STRINGS``), with transformations computed from the
nominal Puma 560 so that they are reachable. Which bytes may change is decided by an
independent line scanner below, not by the parser under test.
"""

from __future__ import annotations

import dataclasses
import gc
import re

import numpy as np
import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.calibration.simulate import random_joints
from olp_compensate.errors import ParseError
from olp_compensate.kinematics.conventions import euler_zyz_from_matrix
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs import loads
from olp_compensate.programs.object_model.task import compensate_program

N_TRANS = 8

HEADER = """.***************************************************************************
.*=== AS GROUP ===         : ASX_000000000 2020/01/01 00:00
.*
.***************************************************************************
.NETCONF     10.0.0.2,"cell-7",255.255.255.0,10.0.0.1,0.0.0.0,0.0.0.0," "
.NETCONF2     10.0.1.2,255.255.255.0,0.0.0.0
.ROBOTDATA1
ZROBOT.TYPE    11   2   6 1234      -12345   XX010N-A001 ( 2020-01-01 00:00 )
ZZERO         268435456 268435456 268435456 268435456 268435456 268435456   1610612736
.END
.SYSDATA
BASE           -120.000   143.000     0.000     0.000     0.000     0.000
TOOL1             0.000     0.000   150.000     0.000     0.000     0.000
.END
.AUXDATA
N_INT1    "s_start  "
.END
.INTER_PANEL_D
0,1,"  RUN","","","",10,15,4,2,2005,0
.END
.SIG_COMMENT
.END
"""


@pytest.fixture(scope="module")
def puma():
    robot = load_robot("unimation_puma560")
    return robot, nominal_calibration(robot)


def transformation_lines(cal, robot, n: int, seed: int) -> list[str]:
    """``name x y z o a t`` lines (mm, ZYZ degrees) of nominal flange poses; every
    third line carries one external axis value after the six."""
    rng = np.random.default_rng(seed)
    q = random_joints(robot, n, rng)
    flange = cal.flange_poses(q)
    lines = []
    for k, f in enumerate(flange):
        values = np.concatenate([f[:3, 3] * 1000.0, np.degrees(euler_zyz_from_matrix(f[:3, :3]))])
        ext = " 1250.500000" if k % 3 == 2 else ""
        lines.append(f"p{k} " + " ".join(f"{v:.6f}" for v in values) + ext)
    return lines


def dump(trans_lines: list[str], newline: str = "\n") -> str:
    """A whole AS dump around ``trans_lines``."""
    moves = "".join(f"  LMOVE p{k}\n" for k in range(len(trans_lines) - 1))
    text = (HEADER + ".PROGRAM main() #0\n  .n = 0\n  TOOL NULL\n  JMOVE #home\n" + moves
            + "  .n = .n + 1\n.END\n.TRANS\n" + "\n".join(trans_lines) + "\n.END\n"
            + ".JOINTS\n#home 0.000000 -45.000000 180.000000 0.000000 45.000000 0.000000\n"
            + ".END\n.REALS\nn = 3\n.END\n.STRINGS\n$msg = \"a;b 1 2 3 4 5 6\"\n.END\n")
    return text.replace("\n", newline)


def sections(text: str) -> list[tuple[str, list[str]]]:
    """The dump cut at its section headers (independent of the parser): (header, lines)
    for every section, one-line entry and header comment, in order."""
    out: list[tuple[str, list[str]]] = []
    inside = False
    for line in text.split("\n"):
        bare = line.rstrip("\r")
        if not inside and bare.startswith("."):
            out.append((bare, []))
            has_value = len(bare.split(None, 1)) > 1 and not bare.startswith(".PROGRAM")
            inside = not (bare.startswith(".*") or has_value)
        elif inside and bare.strip().upper() == ".END":
            inside = False
        elif out:
            out[-1][1].append(line)
    return out


def perturbed(cal):
    """The nominal calibration with every parameter moved by 0.3 mm / 0.3 mrad."""
    return dataclasses.replace(cal, values=cal.values + 3e-4)


@pytest.mark.parametrize("newline", ["\n", "\r\n", "\r\r\n"])
def test_nominal_calibration_gives_the_dump_back_byte_for_byte(puma, newline):
    robot, cal = puma
    text = dump(transformation_lines(cal, robot, N_TRANS, seed=1), newline)
    data = text.encode("latin-1")
    out, report = compensate_program(data, "vplus", cal, file="cell.as")
    assert out.encode("latin-1") == data
    assert report.edits == 0
    assert sum(r.status == "ok" for r in report.rows) == N_TRANS - 1


def test_every_location_line_is_a_target_and_nothing_else_is(puma):
    robot, cal = puma
    text = dump(transformation_lines(cal, robot, N_TRANS, seed=2))
    program = loads(text, "vplus")
    cut = dict(sections(text))
    want_trans = [line.split()[0] for line in cut[".TRANS"] if line.strip()]
    want_joints = [line.split()[0] for line in cut[".JOINTS"] if line.strip()]
    assert [t.name for t in program.targets] == want_trans
    assert [t.name for t in program.joint_targets] == want_joints
    # no number of another section is a target: every target's numbers lie on a line
    # of .TRANS or .JOINTS
    lines = text.split("\n")
    start_of = {i: sum(len(x) + 1 for x in lines[:i]) for i in range(len(lines))}
    location_rows = [i for i, x in enumerate(lines) if x in cut[".TRANS"] + cut[".JOINTS"]
                     and x.strip()]
    spans = [(start_of[i], start_of[i] + len(lines[i])) for i in location_rows]
    for t in program.targets + program.joint_targets:
        for n in t.numbers:
            assert any(a <= n.start and n.end <= b for a, b in spans), (t.name, n)


def test_perturbed_calibration_changes_only_transformation_numbers(puma):
    robot, cal = puma
    text = dump(transformation_lines(cal, robot, N_TRANS, seed=3))
    out, report = compensate_program(text, "vplus", perturbed(cal), file="cell.as")
    before, after = sections(text), sections(out)
    assert [h for h, _ in before] == [h for h, _ in after]
    changed = 0
    for (head, lines0), (_, lines1) in zip(before, after):
        if head != ".TRANS":
            assert lines0 == lines1, head   # every other section byte for byte
            continue
        for old, new in zip(lines0, lines1):
            w0, w1 = old.split(), new.split()
            assert w0[0] == w1[0] and len(w0) == len(w1)
            assert w0[7:] == w1[7:]        # external axes stay as written
            assert re.sub(r"\S+", "#", old) == re.sub(r"\S+", "#", new)  # same spacing
            changed += w0[1:7] != w1[1:7]
    used = [r for r in report.rows if r.status == "ok"]
    assert changed == len(used) == N_TRANS - 1
    assert out != text


def test_every_transformation_is_in_the_report_with_its_line_and_column(puma):
    robot, cal = puma
    text = dump(transformation_lines(cal, robot, N_TRANS, seed=4))
    _, report = compensate_program(text, "vplus", perturbed(cal), file="cell.as")
    lines = text.split("\n")
    first = lines.index(".TRANS") + 1
    rows = {(r.line, r.column): r for r in report.rows}
    for k in range(N_TRANS):
        row = rows[(first + k + 1, 1)]
        assert row.target == f"p{k}"
        assert row.status == ("ok" if k < N_TRANS - 1 else "unused"), row


def test_unclosed_bare_header_does_not_swallow_a_program_or_locations():
    text = (".NETCONF\n.PROGRAM a()\n  LMOVE x\n.END\n.AUXDATA\nN_INT1 \"a\"\n"
            ".TRANS\nx 500 0 400 0 180 0\n.END\n")
    program = loads(text, "vplus")
    assert [t.name for t in program.targets] == ["x"]
    assert [m.target_name for m in program.motions] == ["x"]


def test_a_local_variable_named_like_end_is_a_step():
    text = ".PROGRAM a()\n.ENDLESS = 1\n.ends = 2\n  LMOVE x\n.END\n"
    program = loads(text, "vplus")
    assert program.routines[0].span == (0, len(text) - 1)
    assert [m.target_name for m in program.motions] == ["x"]


def test_a_program_without_end_is_a_parse_error_at_the_next_program():
    text = ".PROGRAM a()\n  LMOVE x\n.PROGRAM b()\n.END\n"
    with pytest.raises(ParseError) as info:
        loads(text, "vplus", "cell.as")
    assert info.value.line == 3
    assert info.value.context.splitlines()[-1].strip() == "^"


def test_matrix_form_in_a_v_plus_locations_section_is_still_refused():
    text = ".LOCATIONS\na 1 0 0 0 1 0 0 0 1 500 0 400\n.END\n"
    with pytest.raises(ParseError, match="expected 6 numbers"):
        loads(text, "vplus")


def test_parsing_leaves_the_garbage_collector_alone(monkeypatch, puma):
    """Only the command line may pause the collector (regression: vplus.py did)."""
    robot, cal = puma
    text = dump(transformation_lines(cal, robot, 3, seed=5))

    def refuse():
        raise AssertionError("the library switched the garbage collector off")

    monkeypatch.setattr(gc, "disable", refuse)
    assert len(loads(text, "vplus").targets) == 3


def test_stray_carriage_returns_are_white_space():
    """A converter that wrote '\\r\\r\\n' (and a lone '\\r' inside a line)."""
    data = (b"; converted\r\r\n.PROGRAM go()\r\r\n    MOVE a\r\r\n    MOVES #b\r\r\n.END\r\r\n"
            b".LOCATIONS\r\r\na 500.0 0.0\r400.0 0.0 180.0 0.0\r\r\n"
            b"#b 0.0 -90.0 180.0 0.0 0.0 0.0 ; park\r\r\n.END\r\r\n")
    program = loads(data, "vplus")
    assert [(t.name, t.location.line, t.location.column) for t in program.targets] == [
        ("a", 7, 1)]
    assert [n.text for n in program.targets[0].numbers] == [
        "500.0", "0.0", "400.0", "0.0", "180.0", "0.0"]
    assert [(t.name, t.location.line) for t in program.joint_targets] == [("#b", 8)]
    assert [(m.target_name, m.location.line) for m in program.motions] == [("a", 3), ("#b", 4)]
    assert program.text.encode("latin-1") == data
