"""VAL3 projects: the motions of the ``.pgx`` programs say which point is reached with which
tool; each point is compensated with that tool in its own frame (checked against the
data-file path, itself checked on the virtual robot), run-time motions are named."""

from __future__ import annotations

import re

import numpy as np

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.compensation.dialect_program import compensate_pose_program
from olp_compensate.compensation.files import ProgramFiles, compensate_files
from olp_compensate.programs.val3.rules import VAL3
from olp_compensate.programs.val3.reader import parse_val3
from test_programs_val3 import ROBOT, _attrs, _points_at, _program_joints, dtx_attributes
from virtual_world import identified_world

VACUUM_MM = (10.0, -20.0, 150.0, 0.0, 0.0, 90.0)

PGX = """<?xml version="1.0" encoding="utf-8"?>
<Programs xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xmlns="http://www.staubli.com/robotics/VAL3/Program/2">
  <Program name="start">
    <Locals>
      <Local name="i" type="num" xsi:type="array" size="1" />
    </Locals>
    <Code><![CDATA[begin
  // pick, then place in a loop
  movej(jHome, flange, mNomSpeed)
  movej(pPick, tGripper, mNomSpeed)
  movel(appro(pPick[0], trApp), tGripper, mNomSpeed)
  for i = 0 to 2
    movel(pPlace[i], tVacuum, mNomSpeed)
  endFor
  call place(pPlace[1])
  call place(pPick[1])
  movej(jPark, flange, mNomSpeed)
end]]></Code>
  </Program>
  <Program name="place">
    <Parameters xmlns="http://www.staubli.com/robotics/VAL3/Param/1">
      <Parameter name="x_pTarget" type="pointRx" xsi:type="element" />
    </Parameters>
    <Code><![CDATA[begin
  movel(x_pTarget, tVacuum, mNomSpeed)
end]]></Code>
  </Program>
</Programs>
"""


def project(seed=7):
    """(the .dtx text: pPick[0..1] and tGripper, pPlace[0..2] and tVacuum; pPlace alone)."""
    q = _program_joints(5, seed)
    picks = _points_at(q[:2])
    places = _points_at(q[2:], tool_mm=VACUUM_MM)
    dtx = dtx_attributes(picks)
    block = ['    <Data name="pPlace" access="public" xsi:type="array" type="pointRx" size="3">']
    for k, (values, config) in enumerate(places):
        words = 'shoulder="%s" elbow="%s" wrist="%s"' % config
        block.append(f'      <Value key="{k}" {_attrs(values)} {words} fatherId="world[0]" />')
    block += ["    </Data>",
              '    <Data name="tVacuum" access="public" xsi:type="array" type="tool" size="1">',
              f'      <Value key="0" {_attrs(VACUUM_MM)} fatherId="flange[0]" />', "    </Data>"]
    block.append('    <Data name="jPark" access="private" xsi:type="array" type="jointRx" '
                 'size="1" />')
    full = dtx.replace("  </Datas>", "\r\n".join(block) + "\r\n  </Datas>")
    alone = dtx_attributes(places, tool_mm=VACUUM_MM).replace('name="tGripper"',
                                                               'name="tVacuum"')
    return full, alone


def test_motions_of_the_pgx_choose_each_points_tool(tmp_path):
    dtx, _ = project()
    (tmp_path / "cell.dtx").write_bytes(dtx.encode("latin-1"))
    (tmp_path / "start.pgx").write_bytes(PGX.encode("latin-1"))
    files = ProgramFiles("val3", (tmp_path / "cell.dtx",), ("cell.dtx",))
    result = compensate_files(files, nominal_calibration(ROBOT))
    assert result.data[0] == dtx.encode("latin-1")
    rows = {}
    for r in result.report.rows:
        rows.setdefault(r.target, []).append(r)
    (pick,) = rows["pPick[0]"]
    assert pick.status in ("ok", "singular") and pick.tool == "tGripper[0]", pick
    (passed,) = rows["pPick[1]"]                  # only passed to another program
    assert passed.status == "runtime" and "passed to place() (start.pgx:16)" in passed.note
    assert "jPark" not in str(rows)               # a jointRx declared without values
    for k in range(3):
        (place,) = rows[f"pPlace[{k}]"]
        assert place.status in ("ok", "singular") and place.tool == "tVacuum[0]", place
    runtime = {r.target: r for r in result.report.rows if r.status == "runtime"}
    assert "appro(pPick[0], trApp)" in runtime and runtime["pPlace[i]"].file == "start.pgx"
    assert runtime["pPlace[i]"].line == 13
    assert "parameter or local variable of program place" in runtime["x_pTarget"].note
    assert not any("not read" in w for w in result.report.warnings)


def test_each_point_is_compensated_as_with_its_tool_alone():
    """pPlace reached with tVacuum (from the .pgx) gets the same numbers as a data file
    whose only tool is tVacuum (the data-file path, checked on the virtual robot)."""
    _, cal = identified_world(ROBOT, 6, "tVacuum[0]")
    dtx, alone = project()
    texts, report = compensate_pose_program(
        parse_val3({"cell.dtx": dtx}, programs={"start.pgx": PGX}), VAL3, cal)
    reference, _ = compensate_pose_program(parse_val3({"cell.dtx": alone}), VAL3, cal)
    new = {t.name: t for t in parse_val3({"cell.dtx": texts["cell.dtx"]}).targets}
    ref = {t.name: t for t in parse_val3({"cell.dtx": reference["cell.dtx"]}).targets}
    changed = 0
    for k in range(3):
        got = [n.text for n in new[f"pPlace[{k}]"].numbers]
        want = [n.text for n in ref[f"pPick[{k}]"].numbers]
        assert got == want
        changed += got != [n.text for n in parse_val3({"c": dtx}).targets[0].numbers]
    assert changed


def test_a_dtx_of_bare_points_is_refused():
    import pytest

    from olp_compensate.errors import ParseError

    with pytest.raises(ParseError) as info:
        parse_val3({"f.dtx": '<valuePoint index="0"><tpValue x="1" /></valuePoint>\n'
                             '<valuePoint index="1"><tpValue x="2" /></valuePoint>\n'})
    assert (info.value.line, info.value.column) == (2, 1)
    np.testing.assert_equal(info.value.file, "f.dtx")


def _value_places(text: str) -> list[int]:
    """Lines of every ``<Value`` of a pointRx or jointRx container: this test's scanner."""
    out, kind = [], None
    for n, line in enumerate(text.split("\r\n"), 1):
        container = re.search(r'<Data\b[^>]*\btype="(\w+)"', line)
        if container:
            kind = container.group(1) if not line.rstrip().endswith("/>") else None
        elif "</Data>" in line:
            kind = None
        elif "<Value" in line and kind in ("pointRx", "jointRx"):
            out.append(n)
    return out


def test_every_point_and_joint_value_has_a_row(tmp_path):
    dtx, _ = project()
    _, report = compensate_pose_program(
        parse_val3({"cell.dtx": dtx}, programs={"start.pgx": PGX}), VAL3,
        nominal_calibration(ROBOT))
    lines = {r.line for r in report.rows if r.file == "cell.dtx"}
    places = _value_places(dtx)
    assert len(places) == 6                    # jHome, pPick[0..1], pPlace[0..2]
    assert set(places) <= lines, sorted(set(places) - lines)
