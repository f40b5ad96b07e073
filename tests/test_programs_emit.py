"""The splice emitter: number style, edit builders, --emit joints."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from olp_compensate.errors import DataError
from olp_compensate.kinematics.conventions import matrix_from_euler_zyz
from olp_compensate.programs import (Edit, dumps, edits_for_targets, format_like, joint_emit_edits,
                                     joint_target_edits, load, loads, splice, target_edits,
                                     tool_edits)
from olp_compensate.programs.emit import (EditColumns, EditsInTurn, SplicedText, aligned_quaternion,
                                          nearest_euler_zyz_deg)
from olp_compensate.programs.semantics import written_values

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("original, value, decimals, expected", [
    ("1020.35", 1020.1234567, 3, "1020.123"),
    ("1020.35", 1020.1, 3, "1020.100"),
    ("100", 100.25, 3, "100.250"),
    ("0.707107", 0.70710678, 6, "0.707107"),
    ("0.7071068", 0.70710678, 6, "0.7071068"),  # more decimals kept
    ("0", -0.00001, 3, "0.000"),  # no "-0.000"
    ("-0.5", -0.25, 3, "-0.250"),
    ("+12", 12.5, 3, "+12.500"),
    (".5", 0.75, 3, ".750"),
    ("-.5", -0.75, 3, "-.750"),
    ("5.", 5.5, 3, "5.500"),
    ("1.10307E-06", 1.2e-6, 3, "1.20000E-06"),
    ("1.05E+03", 1050.1234, 3, "1.050123E+03"),
    ("9E9", 8.5e9, 3, "8.500000000000E9"),
    ("2.5e1", 25.5, 4, "2.55000e1"),
    ("-1.5E+02", -150.25, 3, "-1.50250E+02"),
    ("90.000", 90.00004, 4, "90.0000"),
])
def test_format_like(original, value, decimals, expected):
    s = format_like(original, value, decimals)
    assert s == expected
    assert abs(float(s) - value) <= 0.5 * 10.0 ** -decimals + 1e-12


def test_format_rejects_nan():
    with pytest.raises(DataError):
        format_like("1.0", float("nan"), 3)


def test_splice_checks_overlap_and_order():
    assert splice("abcdef", [Edit(4, 5, "E"), Edit(0, 1, "A")]) == "AbcdEf"
    assert splice("abc", [Edit(1, 1, "x"), Edit(1, 1, "y")]) == "axybc"
    with pytest.raises(DataError, match="overlapping"):
        splice("abcdef", [Edit(0, 3, "x"), Edit(2, 4, "y")])
    with pytest.raises(DataError, match="outside"):
        splice("abc", [Edit(2, 9, "x")])


def test_spliced_text_written_in_blocks_is_the_splice():
    """A SplicedText merges its runs of edits by offset (the earlier run first at one
    offset) and gives the same bytes whole and in blocks of any size."""
    rng = np.random.default_rng(4)
    text = "".join(rng.choice(list("ab;\r\n\u00e9[],.0123456789"), 5000))
    cuts = np.sort(rng.choice(len(text), 600, replace=False)).reshape(-1, 2)
    edits = [Edit(int(a), int(b), "x" * int(rng.integers(0, 9))) for a, b in cuts]
    runs = [edits[0::3], EditColumns(*(list(c) for c in zip(*edits[1::3]))), edits[2::3]]
    expected = splice(text, edits + [Edit(0, 0, "<"), Edit(0, 0, ">")])
    spliced = SplicedText(text, [[Edit(0, 0, "<")], *runs, [Edit(0, 0, ">")]])
    assert spliced.spliced() == expected
    assert len(spliced) == len(edits) + 2
    for block in (1, 7, 1000, 1 << 20):
        pieces = list(spliced.blocks("latin-1", block))
        assert b"".join(pieces) == expected.encode("latin-1")
        assert all(len(piece) >= block for piece in pieces[:-1])
    assert spliced.encode("latin-1") == expected.encode("latin-1")
    assert SplicedText(text).encode("latin-1") == text.encode("latin-1")
    with pytest.raises(DataError, match="overlapping"):
        list(SplicedText(text, [[Edit(0, 3, "x")], [Edit(2, 4, "y")]]).blocks("latin-1"))


def test_quaternion_sign_is_kept_and_unchanged_numbers_stay():
    program = load(ROOT / "samples" / "cell_a.mod")
    t = program.target("p10")
    q = t.orientation_values()
    assert target_edits(t, orientation=-q) == []  # same rotation, same text
    assert np.allclose(aligned_quaternion(-q, q), q / np.linalg.norm(q))
    assert target_edits(t, position_mm=t.position_mm(), config=t.config_values()) == []


def test_config_and_external_edits():
    program = load(ROOT / "samples" / "cell_a.mod")
    t = program.target("p10")
    edits = target_edits(t, config=[0, 0, 0, 1], external=[9e9] * 5 + [12.5])
    out = loads(dumps(program, edits), "rapid").target("p10")
    assert out.config_values() == (0, 0, 0, 1)
    assert out.external[-1].text == "1.250000E+01" or out.external[-1].value == 12.5
    with pytest.raises(DataError, match="integers"):
        target_edits(t, config=[0, 0.5, 0, 0])
    with pytest.raises(DataError, match="expected 3 values"):
        target_edits(t, position_mm=[1, 2])


@pytest.mark.parametrize("name, index", [("spare", None), ("tray", (3,)), ("fixture", None)])
def test_vplus_edit_keeps_euler_branch(name, index):
    program = load(ROOT / "samples" / "cell_b.pg")
    t = program.target(name, index)
    ref, r = t.orientation_values(), t.rotation()
    # an unchanged rotation keeps its numbers, also at pitch 180 (gimbal lock)
    np.testing.assert_allclose(nearest_euler_zyz_deg(r, ref), ref, atol=1e-9)
    tilt = matrix_from_euler_zyz(0.0, np.deg2rad(0.01), 0.0)
    ypr = nearest_euler_zyz_deg(r @ tilt, ref)
    if abs(ref[1] % 180) > 1:  # away from gimbal lock the angles move by about the tilt
        assert np.allclose(ypr, ref, atol=0.02)
    edits = target_edits(t, position_mm=t.position_mm() + [0.5, 0, 0], orientation=ypr)
    out = loads(dumps(program, edits), "vplus").target(name, index)
    np.testing.assert_allclose(out.rotation(), r @ tilt, atol=2e-6)
    np.testing.assert_allclose(out.position_mm(), t.position_mm() + [0.5, 0, 0], atol=5e-4)


def test_joint_and_tool_edits():
    program = load(ROOT / "samples" / "cell_a.mod")
    j = program.joint_targets[0]
    out = dumps(program, joint_target_edits(j, [1, 2, 3, 4, 5, 6]))
    assert "[[1.0000,2.0000,3.0000,4.0000,5.0000,6.0000],[9E+09" in out
    tool = program.tools[0]
    out = loads(dumps(program, tool_edits(tool, [121, 0.5, 209.75])), "rapid").tools[0]
    assert [n.text for n in out.position] == ["121.000", "0.500", "209.750"]


def test_emit_joints_rapid():
    program = load(ROOT / "samples" / "cell_a.mod")
    p10, p20 = program.target("p10"), program.target("p20")
    inline = [t for t in program.targets if t.storage == "inline"][0]
    joints = {p10: [1, 2, 3, 4, 5, 6], p20: [-1, -2, -3, -4, -5, -6], inline: [0] * 6}
    text = dumps(program, joint_emit_edits(program, joints))
    again = loads(text, "rapid")
    names = [j.name for j in again.joint_targets]
    assert names == ["jHome", "p10", "p20", None]
    assert "CONST jointtarget p10:=[[1.0000,2.0000,3.0000,4.0000,5.0000,6.0000],[9E+09" in text
    moves = [(m.instruction, m.target_name) for m in again.motions if m.target_name in
             ("p10", "p20") or m.inline is not None]
    assert moves == [("MoveAbsJ", "p10"), ("MoveAbsJ", "p20"), ("MoveAbsJ", None)]
    assert len(again.targets) == len(program.targets) - 3


def test_emit_joints_refuses_what_cannot_take_a_joint_target():
    program = load(ROOT / "samples" / "cell_a.mod")
    with pytest.raises(DataError, match="MoveC"):
        joint_emit_edits(program, {program.target("p30"): [0] * 6})
    with pytest.raises(DataError, match="whole"):
        joint_emit_edits(program, {program.target("pWeld", (1,)): [0] * 6})
    welds = [t for t in program.targets if t.name == "pWeld"]
    with pytest.raises(DataError, match="Offs"):
        joint_emit_edits(program, {t: [0] * 6 for t in welds})


def test_emit_joints_vplus():
    program = load(ROOT / "samples" / "cell_b.pg")
    fixture = program.target("fixture")
    drop = program.target("drop")
    text = dumps(program, joint_emit_edits(program, {fixture: [10, -80, 170, 0, 5, 0],
                                                     drop: [1, 2, 3, 4, 5, 6]}))
    assert "\n#fixture      10.0000 -80.0000 170.0000 0.0000 5.0000 0.0000\n" in text
    assert "APPRO #fixture, 80" in text and "MOVES #fixture" in text
    assert "SET #drop = #PPOINT(1.0000,2.0000,3.0000,4.0000,5.0000,6.0000)" in text
    again = loads(text, "vplus")
    assert {j.name for j in again.joint_targets} >= {"#fixture", "#drop"}
    with pytest.raises(DataError, match="frame"):
        joint_emit_edits(program, {program.target("inspect"): [0] * 6})
    with pytest.raises(DataError, match="whole"):
        joint_emit_edits(program, {program.target("tray", (1,)): [0] * 6})


@pytest.mark.parametrize("name", ["cell_a.mod", "cell_b.pg"])
def test_batch_and_single_target_edits_agree(name):
    program = load(ROOT / "samples" / name)
    targets = program.targets
    rng = np.random.default_rng(1)
    pos = np.array([t.position_mm() for t in targets]) + rng.normal(0, 0.5, (len(targets), 3))
    ori = np.array([t.orientation_values() for t in targets])
    if program.dialect == "rapid":
        ori = -(ori + rng.normal(0, 1e-3, ori.shape))  # the sign is for the emitter to fix
    else:
        ori = ori + rng.normal(0, 0.01, ori.shape)
    ori[0] = targets[0].orientation_values()  # one orientation left as it is
    batch = dumps(program, edits_for_targets(program, pos, ori))
    single = []
    for t, p, o in zip(targets, pos, ori):
        single += target_edits(t, position_mm=p, orientation=o)
    assert batch == dumps(program, single)
    # the written numbers handed over (as resolve converts them) change nothing
    written = written_values(targets)
    assert edits_for_targets(program, pos, ori, written=written) == \
        edits_for_targets(program, pos, ori)
    with pytest.raises(DataError, match="shape"):
        edits_for_targets(program, pos[:-1])
    with pytest.raises(DataError, match="written: expected shape"):
        edits_for_targets(program, pos, ori, written=written[:-1])


def test_unnormalized_quaternion_kept_when_unchanged_and_rewritten_whole_when_not():
    text = ("MODULE Q\n  CONST robtarget p1:=[[1,2,3],[0,0,2,0],[0,0,0,0],"
            "[9E9,9E9,9E9,9E9,9E9,9E9]];\n  PERS tooldata t1:=[TRUE,[[0,0,100],[2,0,0,0]],"
            "[1,[0,0,1],[1,0,0,0],0,0,0]];\nENDMODULE\n")
    program = loads(text, "rapid")
    (target,), (tool,) = program.targets, program.tools
    assert target_edits(target, orientation=[0, 0, -1, 0]) == []   # same rotation, other sign
    assert tool_edits(tool, quat_wxyz=[1, 0, 0, 0]) == []
    turned = [0, 0.1, 0.99498744, 0]
    new = loads(dumps(program, target_edits(target, orientation=turned)
                      + tool_edits(tool, quat_wxyz=turned)), "rapid")
    for numbers in (new.targets[0].orientation, new.tools[0].orientation):
        np.testing.assert_allclose([n.value for n in numbers], turned, atol=1e-6)


def _module_of(styles: list[str]):
    """A RAPID module of robtargets p0, p1... whose position and orientation are written
    as ``styles[k]`` (the literal up to the confdata)."""
    lines = ["MODULE M"]
    for k, s in enumerate(styles):
        lines.append(f"  CONST robtarget p{k}:={s},[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];")
    lines.append("ENDMODULE")
    return loads("\n".join(lines), "rapid")


def _moved_a_little(targets, rng):
    """New positions (mm, ~0.5 off) and orientations (quaternions, ~1e-3 off, not
    normalized) for ``targets``."""
    pos = np.array([t.position_mm() for t in targets]) + rng.normal(0, 0.5, (len(targets), 3))
    ori = np.array([t.orientation_values() for t in targets], float)
    ori = ori / np.linalg.norm(ori, axis=1, keepdims=True) + rng.normal(0, 1e-3, ori.shape)
    return pos, ori


def test_batch_fast_path_writes_what_the_general_path_writes():
    """The one-format-per-target path of edits_for_targets gives the same text as the
    number-by-number path, for plain numbers and for every style it must leave to it."""
    styles = ["[[1,2,3],[1,0,0,0]", "[[1.5,-2.25,3.125],[0.5,0.5,0.5,0.5]",
              "[[+1.5,.5,-.5],[1,0,0,0]", "[[1E2,2.5e-01,3],[1,0,0,0]",
              "[[1.12345,2,3],[0.70710678,0.70710678,0,0]", "[ [1, 2 ,3] ,\r\n [1,0,0,0]",
              "[[1,2,3],[1,0,0,0]", "[[1,2,3], ! 5,6\n [1,0,0,0]",
              "[[1,2,3], ! pick - top.\n [1,0,0,0]", "[[1,2,3], ! pick\n [1,0,0,0]",
              "[[1,2,3], ! 50% s\n [1,0,0,0]", "[[1,2,3], ! pick\n [1,0,0,0]",
              "[[1,2,3],[1,0,0,0]"]
    program = _module_of(styles)
    targets = program.targets
    pos, ori = _moved_a_little(targets, np.random.default_rng(3))
    pos[0] = [-0.0001, 0.0004, -0.00049]    # round to zero: never "-0.000"
    ori[6] = [np.sqrt(1 - 3e-14), -1e-7, 1e-7, -1e-7]
    batch = dumps(program, edits_for_targets(program, pos, ori))
    single = []
    for t, p, o in zip(targets, pos, ori):
        single += target_edits(t, position_mm=p, orientation=o)
    assert batch == dumps(program, single)
    assert not re.search(r"-0\.0+(?![0-9])", batch) and "[[0.000,0.000,0.000]" in batch


def test_batch_edits_agree_with_target_edits_across_span_forms():
    """Every target's edit from edits_for_targets writes what target_edits writes, in a
    module whose many tight targets are checked all at once while the others (blanks or a
    comment inside, a long or non-Latin-1 comment, exponents, more decimals than the new
    value gets, a sign or point the plain form lacks, part of a target unchanged) are
    matched one by one or take the general path."""
    rng = np.random.default_rng(7)
    tight = [f"[[{x:.2f},{y:.1f},{z:.0f}],[0.5,-0.5,0.5,-0.5]" for x, y, z in
             rng.uniform(-2000, 2000, (40, 3))]
    odd = ["[[1E2,2.5e-01,3],[1,0,0,0]",                  # first target: not plain
           "[ [1, 2 ,3] ,\r\n [0.5,0.5,-0.5,0.5]", "[[1,2,3], ! pick\n [0.5,0.5,-0.5,0.5]",
           "[[1,2,3], ! " + "long " * 250 + "\n [0.5,0.5,-0.5,0.5]",
           "[[1,2,3], ! Schweißpunkt \u20ac\n [0.5,0.5,-0.5,0.5]",
           "[[1,2,3], ! 5,6\n [1,0,0,0]", "[[1.12345,2,3],[1,0,0,0]",
           "[[1.1234,2.5,3],[0.5,0.5,-0.5,0.5]", "[[1,2,3],[0.5,0.5,-0.5,0.5000001]",
           "[[-.5,1,2],[0.5,0.5,-0.5,0.5]", "[[1,2,3],[-.5,0.5,-0.5,0.5]",
           "[[1,2,3],[0.70710678,0.70710678,0,0]", "[[+1.5,.5,-.5],[1,0,0,0]",
           "[[5.,-0,3],[0,0,2,0]", "[[1,2,3],[1,0,0,0]"]
    styles = [odd[0]] + tight[:20] + odd[1:] + tight[20:]
    program = _module_of(styles)
    targets = program.targets
    pos, ori = _moved_a_little(targets, rng)
    pos[3] = targets[3].position_mm()                      # orientation only
    ori[5] = targets[5].orientation_values()               # position only
    pos[7], ori[7] = targets[7].position_mm(), targets[7].orientation_values()  # unchanged
    batch = iter(edits_for_targets(program, pos, ori))
    for t, p, o in zip(targets, pos, ori):
        single = target_edits(t, position_mm=p, orientation=o)
        if single:
            assert splice(program.text, [next(batch)]) == splice(program.text, single), \
                t.display_name
    assert next(batch, None) is None


@pytest.mark.parametrize("parts", ["both", "position", "orientation"])
@pytest.mark.parametrize("separators", ["one", "several"])
def test_batch_edits_of_plain_spans_at_once_agree_with_target_edits(parts, separators):
    """Where every target's span is of the plain form, edits_for_targets reads them all
    with one regex pass and writes those of one template with one format: each edit is
    what target_edits writes, whether the targets share one template or several (blanks,
    a comment holding '%'), for the position, the orientation or both."""
    rng = np.random.default_rng(11)
    forms = ["[[{:.2f},{:.1f},{:.0f}],[0.5,-0.5,0.5,-0.5]"]
    if separators == "several":
        forms += ["[[{:.2f}, {:.1f}, {:.0f}],[0.5,-0.5,0.5,-0.5]",
                  "[[{:.3f},{:.1f},{:.0f}], ! pick %s %d\n [0.5,-0.5,0.5,-0.5]"]
    styles = [forms[k % len(forms)].format(*xyz) for k, xyz in
              enumerate(rng.uniform(-2000, 2000, (60, 3)))]
    program = _module_of(styles)
    targets = program.targets
    pos, ori = _moved_a_little(targets, rng)
    pos[4] = [-0.0001, 0.0004, -0.00049]    # round to zero: never "-0.000"
    pos[5] = [12.0625, -0.0625, 2.5]        # halves that binary holds exactly
    pos, ori = (None, ori) if parts == "orientation" else (pos, None) \
        if parts == "position" else (pos, ori)
    batch = edits_for_targets(program, pos, ori)
    assert len(batch) == len(targets)
    for k, (t, edit) in enumerate(zip(targets, batch)):
        single = target_edits(t, position_mm=None if pos is None else pos[k],
                              orientation=None if ori is None else ori[k])
        assert splice(program.text, [edit]) == splice(program.text, single), t.display_name


def test_edit_runs_one_after_the_other_are_read_as_one_run():
    from array import array

    runs = [EditColumns(array("q", [0, 5]), array("q", [1, 6]), ["a", "b"]),
            EditColumns(array("q", []), array("q", []), []),
            [Edit(9, 12, "c")]]
    joined = EditsInTurn(runs)
    assert list(joined) == list(joined) == [(0, 1, "a"), (5, 6, "b"), (9, 12, "c")]
    assert len(joined) == 3
    assert SplicedText("0123456789abcdef", [joined]).spliced() == "a" "1234" "b" "678" "c" "cdef"
