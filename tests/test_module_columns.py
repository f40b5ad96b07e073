"""The column path of a RAPID module (programs/rapid/module_columns.py) against the object
path it replaces for big modules: the same bytes and report wherever both solve the same
batch, the targets reached on the virtual robot when solved chunk by chunk, and the
object path wherever the module's targets are not plain."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from olp_compensate.compensation.pose import Compensator
from olp_compensate.compensation.report import ReportRows
from olp_compensate.errors import ParseError
from olp_compensate.kinematics.conventions import (MM, invert_pose, quat_wxyz_from_matrix,
                                                   rotation_angle_between)
from olp_compensate.programs import loads
from olp_compensate.programs.object_model.task import compensate_task
from olp_compensate.programs.rapid.column_plans import plan as _plan
from olp_compensate.programs.rapid.module_columns import compensate_rapid_module
from olp_compensate.programs.rapid.reader import parse_rapid_columns
from test_compensate import (TOLERANCE_M, World, _frames, _world, rapid_module, read_rapid_targets,
                             written_targets)

HERE = Path(__file__).parent
MODULES = sorted([*HERE.glob("programs/rapid_*/input.*"), *HERE.glob("tasks/*/*.mod"),
                  HERE.parent / "samples" / "cell_a.mod"])

SPECIAL = """MODULE Special
  PERS tooldata tGun:=[TRUE,[[120.5,0,210],[0.92388,0,0.382683,0]],[2.5,[0,0,80],[1,0,0,0],0,0,0]];
  PERS tooldata tFixed:=[FALSE,[[900,100,600],[1,0,0,0]],[1,[0,0,0],[1,0,0,0],0,0,0]];
  PERS wobjdata wHeld:=[TRUE,TRUE,"",[[0,0,150],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
  PERS wobjdata wTable:=[FALSE,TRUE,"",[[700,-300,300],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
  CONST robtarget pA:=[[1100.5,-20.25,950],[0.5,0,0.866025,0],[-1,-1,0,1],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pNever:=[[1000,0,900],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pZero:=[[1000,0,900],[0,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  PERS robtarget pOdd:=[[1000,0,900],[0,0,1,0],[0,0.5,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pFar:=[[9000,0,900],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  VAR robtarget pUnknownTool:=[[1000,0,900],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pTable:=[[300,250,120.25],[0,0.707107,0.707107,0],[0,1,-1,1],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pHeld:=[[50,20,-30],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  PROC main()
    MoveJ pA,v500,z10,tGun;
    MoveL pZero,v500,z10,tGun;
    MoveL pOdd,v500,z10,tGun;
    MoveL pFar,v500,z10,tGun;
    MoveL pUnknownTool,v500,z10,tNowhere;
    MoveL pTable,v500,fine,tGun\\WObj:=wTable;
    MoveL pA,v500,z10,tGun;
    MoveL pHeld,v500,fine,tFixed\\WObj:=wHeld;
  ENDPROC
ENDMODULE
"""
"""Every row the column path makes as an object: unused, zero quaternion, confdata no
integer, out of reach, unknown tool; a stationary tool; a target moved to twice."""


@pytest.fixture(scope="module")
def comp():
    return Compensator(_world("abb_irb2400").calibration)


def _both(text: str, file: str, comp, unused: str, taught_on=None):
    try:
        (expected,), report = compensate_task([loads(text, "rapid", file)], comp,
                                              unused=unused, taught_on=taught_on)
    except ParseError:
        with pytest.raises(ParseError):
            compensate_rapid_module(text, file, comp, unused=unused, teacher=taught_on)
        return None
    got, columns_report = compensate_rapid_module(text, file, comp, unused=unused,
                                                  teacher=taught_on)
    assert got == expected
    _same_report(columns_report, report)
    return columns_report


def _same_report(columns_report, report) -> None:
    """The column path's report says what the object path's does, row for row."""
    assert columns_report.to_csv() == report.to_csv()
    assert columns_report.warnings == report.warnings
    assert (columns_report.edits, columns_report.exit_code, columns_report.counts()) == \
        (report.edits, report.exit_code, report.counts())
    _same_rows(list(columns_report.rows), list(report.rows))
    _same_rows(columns_report.problem_rows(), report.problem_rows())
    assert columns_report.largest_correction() == report.largest_correction()


def _same_rows(got, expected) -> None:
    """Rows equal field by field; the joints of a target solved in another batch than the
    object path's (a chunk, the retries) may differ in their last digits (1e-6 deg)."""
    assert len(got) == len(expected)
    for a, b in zip(got, expected):
        assert dataclasses.replace(a, joints=()) == dataclasses.replace(b, joints=())
        np.testing.assert_allclose(np.asarray(a.joints, float), np.asarray(b.joints, float),
                                   rtol=0, atol=1e-6)


def _taken(text: str) -> bool:
    program, columns = parse_rapid_columns(text)
    return len(columns.targets) > 0 and _plan(program, columns) is not None


@pytest.mark.parametrize("unused", ["skip", "tool0"])
@pytest.mark.parametrize("path", MODULES, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_columns_give_the_object_paths_text_and_report(path, unused, comp):
    text = path.read_bytes().decode("latin-1")
    _both(text, str(path), comp, unused)


@pytest.mark.parametrize("unused", ["skip", "tool0"])
def test_every_row_kind_of_the_column_path(unused, comp):
    assert _taken(SPECIAL)
    report = _both(SPECIAL, "special.mod", comp, unused)
    status = {r.target: r.status for r in report.rows}
    assert isinstance(report.rows, ReportRows)
    assert status["pNever"] == ("unused" if unused == "skip" else "ok")
    assert (status["pZero"], status["pOdd"]) == ("bad_target", "bad_target")
    assert status["pFar"] in ("unreachable", "not_converged")
    assert status["pUnknownTool"] == "unresolved"
    assert (status["pA"], status["pTable"], status["pHeld"]) == ("ok", "ok", "ok")
    assert [r.target for r in report.rows] == [
        "pA", "pNever", "pZero", "pOdd", "pFar", "pUnknownTool", "pTable", "pHeld"]


def test_transfer_in_columns_is_the_object_paths(comp):
    teacher = Compensator(World("abb_irb2400", seed=5).calibration)
    assert _taken(SPECIAL)
    report = _both(SPECIAL, "special.mod", comp, "skip", taught_on=teacher)
    assert report.counts()["ok"] == 3


def _left_in_columns(text: str) -> list[str]:
    """The table targets that stay in columns once the rows whose meaning is not plain
    went to the object path (the module's plan made on what is left)."""
    from olp_compensate.programs.rapid.module_columns import _plain_parts

    ((program, columns),) = _plain_parts([parse_rapid_columns(text)])
    assert _plan(program, columns) is not None
    return columns.targets.names


@pytest.mark.parametrize("change, why, objects", [
    ("    MoveJ Offs(pNever,0,0,50),v500,z10,tGun\\WObj:=wTable;\n",
     "moved to only through Offs()", {"pNever"}),
    ("    MoveL pTable,v500,z10,tGun;\n", "two tool/work-object pairs", {"pTable"}),
    ("    MyRoutine pA;\n", "handed to a routine", {"pA"}),
    ("    pHeld := pA;\n", "copied", {"pA", "pHeld"}),
    ("    MoveL pMissing,v500,z10,tGun;\n", "unknown target", set()),
])
def test_targets_whose_meaning_is_not_plain_take_the_object_path(change, why, objects, comp):
    """Only those targets (and their motions) leave the columns: the module's other
    targets stay there, and the text and report are the object path's."""
    text = SPECIAL.replace("  ENDPROC", change + "  ENDPROC")
    assert not _taken(text), why
    names = ["pA", "pNever", "pZero", "pOdd", "pFar", "pUnknownTool", "pTable", "pHeld"]
    assert _left_in_columns(text) == [n for n in names if n not in objects], why
    _both(text, "special.mod", comp, "skip")


@pytest.mark.parametrize("change", [
    "    MoveL Offs(pA,0,0,10),v500,z10,tGun;\n",
    "    MoveJ Offs(pA,0,0,50),v500,z10,tGun;\n    MoveL RelTool(pA,0,0,-20),v500,z10,tGun;\n",
    "    MoveL RelTool(pTable,0,0,-20),v500,z10,tFixed;\n",   # another pair than its MoveL
    "    MoveL Offs(pFar,0,0,10),v500,z10,tGun;\n    MoveL Offs(pUnknownTool,0,0,1),"
    "v500,z10,tGun;\n"])
def test_a_target_also_displaced_at_run_time_stays_in_columns(change, comp):
    """Offs()/RelTool() of a target that motions also move to by name is a ``runtime``
    row of its own and leaves the target's meaning (pair, notes) as it is: the target
    stays a table row, the text and report are the object path's."""
    text = SPECIAL.replace("  ENDPROC", change + "  ENDPROC")
    assert _taken(text)
    assert _left_in_columns(text) == ["pA", "pNever", "pZero", "pOdd", "pFar",
                                      "pUnknownTool", "pTable", "pHeld"]
    report = _both(text, "special.mod", comp, "skip")
    runtime = [r for r in report.rows if r.status == "runtime"]
    assert len(runtime) == change.count("Move")
    assert all(r.target.startswith(("Offs(", "RelTool(")) for r in runtime)


def test_a_target_moved_to_only_through_offs_takes_its_pairs_from_them(comp):
    text = SPECIAL.replace("  ENDPROC", "    MoveJ Offs(pNever,0,0,50),v500,z10,"
                           "tGun\\WObj:=wTable;\n  ENDPROC")
    report = _both(text, "special.mod", comp, "skip")
    (row,) = [r for r in report.rows if r.target == "pNever"]
    assert (row.tool, row.wobj) == ("tGun", "wTable")
    assert row.note.endswith("moved to only through Offs()")


LOCAL_TARGET = "    VAR robtarget pLoc:=[[1050,30,920],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"


@pytest.mark.parametrize("declared, moves, in_columns", [
    ("main", "    MoveL pLoc,v500,z10,tGun;\n", True),
    ("main", "", True),                                         # unused
    ("main", "    MoveL Offs(pLoc,0,0,5),v500,z10,tGun;\n    MoveL pLoc,v500,z10,tGun;\n",
     True),
    ("other", "    MoveL pLoc,v500,z10,tGun;\n", False),     # another routine's name
    ("both", "    MoveL pLoc,v500,z10,tGun;\n", False),      # declared in two routines
])
def test_a_routines_own_targets_are_table_rows_where_their_name_is_plain(
        declared, moves, in_columns, comp):
    """A routine's ``VAR``/``CONST robtarget`` is a table row with its routine; moved to
    from another routine (where the name is another target's or none's) or declared in
    two routines it goes to the object path. Text and report are the object path's."""
    text = SPECIAL.replace("  ENDPROC", moves + "  ENDPROC")
    other = "  PROC other()\n" + (LOCAL_TARGET if declared != "main" else "") + \
        "    MoveL pA,v500,z10,tGun;\n  ENDPROC\n"
    if declared in ("main", "both"):
        text = text.replace("  PROC main()\n", "  PROC main()\n" + LOCAL_TARGET)
    text = text.replace("ENDMODULE", other + "ENDMODULE")
    program, columns = parse_rapid_columns(text)
    assert {r for r in columns.targets.routines if r} == (
        {"main", "other"} if declared == "both" else {declared})
    assert _taken(text) == in_columns
    assert ("pLoc" in _left_in_columns(text)) == in_columns
    report = _both(text, "special.mod", comp, "tool0" if not moves else "skip")
    rows = [r for r in report.rows if r.target == "pLoc"]
    assert len(rows) == 1 + (declared in ("other", "both"))
    if declared == "other":   # main's motion names no target main can see
        assert [r.note for r in rows if r.status == "unresolved"] == ["unknown target pLoc"]
    else:
        assert (rows[0].status, rows[0].tool) == ("ok", "tGun" if moves else "tool0")


def test_local_task_and_pers_declarations_in_a_routine_are_left_to_the_builder(comp):
    for word in ("PERS", "LOCAL VAR", "TASK PERS"):
        text = SPECIAL.replace("  PROC main()\n", "  PROC main()\n" + LOCAL_TARGET.replace(
            "VAR", word)).replace("  ENDPROC", "    MoveL pLoc,v500,z10,tGun;\n  ENDPROC")
        try:
            program, columns = parse_rapid_columns(text)
        except ParseError:
            with pytest.raises(ParseError):
                loads(text, "rapid", "special.mod")
            continue
        assert not any(columns.targets.routines), word
        # the object alone in its batch: its correction may differ in the last bit
        (expected,), report = compensate_task([loads(text, "rapid", "s.mod")], comp)
        got, columns_report = compensate_rapid_module(text, "s.mod", comp)
        assert (got, columns_report.to_csv()) == (expected, report.to_csv())


def test_a_target_declared_twice_takes_the_object_path(comp):
    text = SPECIAL.replace("  PROC main()", "  CONST robtarget pa:=[[1,2,3],[1,0,0,0],"
                           "[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n  PROC main()")
    assert not _taken(text)
    assert "pA" not in _left_in_columns(text) and "pa" not in _left_in_columns(text)
    _both(text, "special.mod", comp, "skip")


def test_a_realistic_module_keeps_its_plain_targets_in_columns(comp):
    """Offs/RelTool approaches, routine-local targets, several tools and work objects: the
    plain targets stay in columns, the module gives the object path's text and report."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from compensate import generate_realistic_module

    text = generate_realistic_module(120, seed=4)
    left = _left_in_columns(text)
    assert left == [f"p{k}" for k in range(120) if k % 10 != 9] + [
        f"p{k}" for k in range(9, 120, 10)]   # Offs/RelTool and routine-local ones too
    report = _both(text, "real.mod", comp, "skip")
    assert isinstance(report.rows, ReportRows)


def test_chunked_column_path_reaches_the_targets_on_the_virtual_robot():
    """Solved 5 targets at a time: the real tool reaches what the program meant."""
    world = _world("abb_irb2400")
    program_tool, wobj, tool_rot, _ = _frames(world, 3)
    q = world.program_joints(23, seed=22)
    numbers = written_targets(world, q, program_tool, wobj)
    text = rapid_module(numbers, program_tool[:3, 3] / MM, quat_wxyz_from_matrix(tool_rot),
                        wobj[:3, 3] / MM, quat_wxyz_from_matrix(wobj[:3, :3]))
    assert _taken(text)
    out, report = compensate_rapid_module(text, "loop.mod", Compensator(world.calibration),
                                          chunk=5)
    assert report.exit_code == 0 and len(report.rows) == len(numbers)
    _, cart, _ = read_rapid_targets(out)
    _, original, _ = read_rapid_targets(text)
    real_tool = world.real_tool(tool_rot)
    errors = []
    for k in range(1, len(numbers) + 1):
        frame = wobj if k % 2 else np.eye(4)
        intended = world.desired_in_device(frame @ original[f"p{k}"][0])
        pose, conf = cart[f"p{k}"]
        q_ctrl = world.controller((frame @ pose @ invert_pose(program_tool))[None], conf[None])
        reached = world.real_tcp_in_device(q_ctrl, real_tool)[0]
        errors.append(np.linalg.norm(reached[:3, 3] - intended[:3, 3]))
        assert rotation_angle_between(reached[:3, :3], intended[:3, :3]) < math.radians(0.005)
    assert max(errors) < TOLERANCE_M, np.array(errors) / MM


def test_two_processes_give_one_process_text_and_report_byte_for_byte(monkeypatch):
    """With jobs=2 the second half of the chunks, then of the retries' batches, is solved
    in a forked process: the text, CSV, counts and warnings are one process's exactly,
    with targets out of reach, bad and unused rows in both halves (their retries gathered
    across the processes)."""
    from olp_compensate.compensation import forked
    from olp_compensate.programs.rapid import module_columns

    world = _world("abb_irb2400")
    program_tool, wobj, tool_rot, _ = _frames(world, 3)
    numbers = written_targets(world, world.program_joints(30, seed=5), program_tool, wobj)
    numbers[3] = (numbers[3][0] + 5000.0, *numbers[3][1:])       # out of reach, first half
    numbers[26] = (numbers[26][0] + 5000.0, *numbers[26][1:])     # and second half
    numbers[24] = (numbers[24][0], np.zeros(4), numbers[24][2])   # zero quaternion
    text = rapid_module(numbers, program_tool[:3, 3] / MM, quat_wxyz_from_matrix(tool_rot),
                        wobj[:3, 3] / MM, quat_wxyz_from_matrix(wobj[:3, :3]))
    text = text.replace("    MoveL p29,", "    ! MoveL p29,")                   # unused
    assert _taken(text)
    comp = Compensator(world.calibration)
    monkeypatch.setattr(module_columns, "PARALLEL_MIN", 0)
    monkeypatch.setattr(module_columns, "RETRY_CHUNK", 1)   # the retries shared too
    forks = []
    monkeypatch.setattr(forked.ForkedItems, "__init__", _counted(forked.ForkedItems.__init__,
                                                                forks))
    one, one_report = module_columns.compensate_rapid_task([text], ["loop.mod"], comp,
                                                           chunk=4, jobs=1)
    assert not forks
    two, two_report = module_columns.compensate_rapid_task([text], ["loop.mod"], comp,
                                                           chunk=4, jobs=2)
    assert len(forks) == 2 * forked.can_fork()      # the chunks, then the retries
    assert two[0].encode("latin-1") == one[0].encode("latin-1")
    assert "".join(two_report.csv_chunks()) == "".join(one_report.csv_chunks())
    assert two_report.counts() == one_report.counts()
    assert {"unreachable", "bad_target", "unused", "ok"} <= set(one_report.counts())
    assert two_report.warnings == one_report.warnings
    assert two_report.edits == one_report.edits


def test_the_retries_in_batches_of_any_size_give_the_same_bytes(monkeypatch):
    """The targets not reached at once (out of reach, axis 3 beyond its range, the wrist
    near its singularity) retried one at a time, three at a time, or all in one batch: the
    same text, CSV and counts (each target's retry is its own, whatever the others of its
    batch)."""
    from olp_compensate.programs.rapid import module_columns

    world = _world("abb_irb2400")
    program_tool, wobj, tool_rot, _ = _frames(world, 3)
    robot = world.robot
    q_ctrl = robot.controller_from_joints(world.program_joints(30, seed=7))
    q_ctrl[[4, 12, 20], 2] = np.radians(80.0)                      # range -60..65 deg
    q_ctrl[[6, 14, 22, 28], 4] = [0.004, -0.006, 0.01, -0.003]     # rad from the singularity
    numbers = written_targets(world, robot.joints_from_controller(q_ctrl), program_tool, wobj)
    for k in (2, 9, 17, 25):                                        # out of reach
        numbers[k] = (numbers[k][0] + 5000.0, *numbers[k][1:])
    text = rapid_module(numbers, program_tool[:3, 3] / MM, quat_wxyz_from_matrix(tool_rot),
                        wobj[:3, 3] / MM, quat_wxyz_from_matrix(wobj[:3, :3]))
    comp = Compensator(world.calibration)
    results = []
    for size in (1, 3, 10_000):
        monkeypatch.setattr(module_columns, "RETRY_CHUNK", size)
        results.append(module_columns.compensate_rapid_task([text], ["batch.mod"], comp,
                                                            chunk=8))
    (text_one, report_one), *others = results
    assert {"ok", "unreachable", "joint_limit", "branch_changed"} <= set(report_one.counts())
    for new_text, report in others:
        assert new_text[0].encode("latin-1") == text_one[0].encode("latin-1")
        assert "".join(report.csv_chunks()) == "".join(report_one.csv_chunks())


def test_without_a_process_to_fork_everything_runs_in_this_one(monkeypatch):
    """A fork or temporary file refused (a process limit, a full disk) is no error: the
    module is compensated in this process, with the same result."""
    from olp_compensate.compensation import forked
    from olp_compensate.programs.rapid import module_columns

    world = _world("abb_irb2400")
    program_tool, wobj, tool_rot, _ = _frames(world, 3)
    numbers = written_targets(world, world.program_joints(12, seed=6), program_tool, wobj)
    text = rapid_module(numbers, program_tool[:3, 3] / MM, quat_wxyz_from_matrix(tool_rot),
                        wobj[:3, 3] / MM, quat_wxyz_from_matrix(wobj[:3, :3]))
    comp = Compensator(world.calibration)
    monkeypatch.setattr(module_columns, "PARALLEL_MIN", 0)
    (one,), one_report = module_columns.compensate_rapid_task([text], ["m.mod"], comp, chunk=4)

    def refused(self, *args):
        raise BlockingIOError(11, "Resource temporarily unavailable")

    monkeypatch.setattr(forked.ForkedItems, "__init__", refused)
    (two,), two_report = module_columns.compensate_rapid_task([text], ["m.mod"], comp,
                                                              chunk=4, jobs=2)
    assert two.spliced() == one.spliced() != text
    assert "".join(two_report.csv_chunks()) == "".join(one_report.csv_chunks())


def _counted(function, calls: list):
    def counted(*args, **kwargs):
        calls.append(args)
        return function(*args, **kwargs)
    return counted


def test_report_rows_read_like_a_tuple(comp):
    report = _both(SPECIAL, "special.mod", comp, "skip")
    rows = list(report.rows)
    assert len(report.rows) == len(rows) == 8
    assert report.rows[0] == rows[0] and report.rows[-1] == rows[-1]
    assert report.rows[2:5] == rows[2:5]
    assert report.problem_rows() == [r for r in rows if not r.fine]


# ---- whole tasks ----------------------------------------------------------------------

TASK = HERE / "tasks" / "cell_task"
TASK_ORDER = ("CalibData.mod", "WObjData.mod", "Weld.mod", "Pick.mod", "user.sys")

CALIB_DATA = """MODULE CalibData
  PERS tooldata tGun:=[TRUE,[[120.5,0,210],[0.92388,0,0.382683,0]],[2.5,[0,0,80],[1,0,0,0],0,0,0]];
  PERS wobjdata wTable:=[FALSE,TRUE,"",[[700,-300,300],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
ENDMODULE
"""


def _task_both(texts, names, comp, unused="skip"):
    from olp_compensate.programs.rapid.module_columns import compensate_rapid_task

    expected, report = compensate_task([loads(t, "rapid", n) for t, n in zip(texts, names)],
                                       comp, unused=unused)
    got, columns_report = compensate_rapid_task(texts, names, comp, unused=unused, chunk=7)
    assert [new.spliced() for new in got] == expected
    _same_report(columns_report, report)
    return columns_report


def _task_plans(texts, names):
    from olp_compensate.programs.rapid.column_plans import task_plans as plans

    parsed = [parse_rapid_columns(t, n) for t, n in zip(texts, names)]
    return [p is not None for p in plans([p for p, _ in parsed], [c for _, c in parsed])]


@pytest.mark.parametrize("unused", ["skip", "tool0"])
def test_the_cell_task_through_the_task_path_is_the_object_paths(unused, comp):
    """The golden task shares its targets across modules (a PERS in two modules, targets
    moved to from another module): no module is plain, the result is the object path's."""
    texts = [(TASK / name).read_bytes().decode("latin-1") for name in TASK_ORDER]
    assert not any(_task_plans(texts, TASK_ORDER))
    _task_both(texts, TASK_ORDER, comp, unused)


def _motion_module(name: str, prefix: str, tool: str = "tGun") -> str:
    """A module of plain targets (from SPECIAL's reachable ones) moved to with the task's
    tool and work object, declared in another module."""
    targets = [line for line in SPECIAL.splitlines()
               if "CONST robtarget pA" in line or "robtarget pTable" in line]
    decls = [line.replace(" pA:=", f" {prefix}A:=").replace(" pTable:=", f" {prefix}T:=")
             for line in targets]
    return "\n".join([f"MODULE {name}", *decls, "  PROC main()",
                      f"    MoveJ {prefix}A,v500,z10,{tool};",
                      f"    MoveL {prefix}T,v500,fine,{tool}\\WObj:=wTable;",
                      "  ENDPROC", "ENDMODULE", ""])


def test_a_module_using_its_own_targets_and_the_tasks_tools_takes_the_columns(comp):
    texts = [CALIB_DATA, _motion_module("Cell", "c"), _motion_module("Other", "o")]
    names = ["CalibData.mod", "Cell.mod", "Other.mod"]
    assert _task_plans(texts, names) == [False, True, True]
    report = _task_both(texts, names, comp)
    assert report.counts() == {"ok": 4}
    assert [r.file for r in report.rows] == ["Cell.mod"] * 2 + ["Other.mod"] * 2


def test_targets_another_module_moves_to_or_declares_take_the_object_path(comp):
    user = _motion_module("User", "c").replace("MoveJ cA", "MoveJ oA")   # Other's target
    texts = [CALIB_DATA, user, _motion_module("Other", "o")]
    names = ["CalibData.mod", "User.mod", "Other.mod"]
    assert _task_plans(texts, names) == [False, False, False]
    _task_both(texts, names, comp)
    again = [CALIB_DATA, _motion_module("Cell", "c"), _motion_module("Twin", "c")]
    assert _task_plans(again, ["CalibData.mod", "Cell.mod", "Twin.mod"]) == [False] * 3
    _task_both(again, ["CalibData.mod", "Cell.mod", "Twin.mod"], comp)


def _displaced_rows(text: str) -> tuple[list[str], list[str]]:
    """(the Offs()/RelTool() motions kept as rows of the column parse, those made objects
    of the program), each as the expressions written."""
    from olp_compensate.programs.rapid.displaced import DisplacedMoves
    from olp_compensate.programs.rapid.module_columns import _plain_parts

    tables = [DisplacedMoves()]
    ((program, _),) = _plain_parts([parse_rapid_columns(text, "m.mod", tables[0])], tables)
    rows = [tables[0].objects(i, text, "m.mod")[1].expression
            for i in range(len(tables[0]))] if tables[0] is not None else []
    return rows, [u.runtime.expression for u in program.motions if u.runtime is not None]


def test_offs_and_reltool_motions_are_table_rows_where_their_target_is(comp):
    """A plain Offs()/RelTool() motion of a target kept in the table is a row of the
    column parse, not an object; one whose target leaves the table (moved to only
    through it, declared twice, not declared) is an object; the text and report are the
    object path's either way."""
    text = SPECIAL.replace("  ENDPROC", (
        "    MoveL Offs(pA,0,0,10),v500,z10,tGun;\n"
        "    MoveL RelTool(pTable, 0, 0, -20),v500,z10,tGun\\WObj:=wTable;\n"
        "    MoveJ Offs(pNever,0,0,50),v500,z10,tGun\\WObj:=wTable;\n"
        "    MoveL Offs(pGone,0,0,5),v500,z10,tGun;\n"
        "    MoveL Offs(pa,1,2,3),v500,z10,tGun;\n"
        "  ENDPROC"))
    rows, objects = _displaced_rows(text)
    assert rows == ["Offs(pA,0,0,10)", "RelTool(pTable, 0, 0, -20)", "Offs(pa,1,2,3)"]
    assert objects == ["Offs(pNever,0,0,50)", "Offs(pGone,0,0,5)"]
    report = _both(text, "special.mod", comp, "skip")
    runtime = [r for r in report.rows if r.status == "runtime"]
    assert [r.target for r in runtime] == rows[:2] + objects + rows[2:]
    assert [r.line for r in runtime] == sorted(r.line for r in runtime)
    problems = report.problem_rows()
    assert [r.target for r in problems if r.status == "runtime"] == [r.target for r in runtime]
    twice = text.replace("  PROC main()", "  CONST robtarget pA:=[[1,2,3],[1,0,0,0],[0,0,0,0],"
                         "[9E9,9E9,9E9,9E9,9E9,9E9]];\n  PROC main()")
    rows, objects = _displaced_rows(twice)
    assert "Offs(pA,0,0,10)" in objects and "Offs(pa,1,2,3)" in objects
    assert rows == ["RelTool(pTable, 0, 0, -20)"]


def test_the_realistic_modules_displaced_motions_are_rows(comp):
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from compensate import generate_realistic_module

    text = generate_realistic_module(120, seed=4)
    rows, objects = _displaced_rows(text)
    assert objects == []
    assert len(rows) == text.count("Offs(") + text.count("RelTool(") > 0


def test_load_notes_leave_the_displaced_motions_in_their_table(comp):
    """A load-sensitive model's notes (cli/fix_models.with_load_notes) on the column path's
    report: the CSV is that of the object path's report noted the same way, and the
    Offs()/RelTool() rows stay rows of their table (not one object each)."""
    from olp_compensate.cli.fix_models import with_load_notes
    from olp_compensate.programs.rapid.displaced import RowsWithDisplaced

    text = SPECIAL.replace("  ENDPROC", (
        "    MoveL Offs(pA,0,0,10),v500,z10,tGun;\n"
        "    MoveL RelTool(pTable, 0, 0, -20),v500,z10,tGun\\WObj:=wTable;\n"
        "    MoveJ Offs(pNever,0,0,50),v500,z10,tGun\\WObj:=wTable;\n"
        "  ENDPROC"))
    (_,), report = compensate_task([loads(text, "rapid", "special.mod")], comp, unused="skip")
    _, columns_report = compensate_rapid_module(text, "special.mod", comp, unused="skip")
    assert isinstance(columns_report.rows.others, RowsWithDisplaced)
    noted = with_load_notes(columns_report, None, [], True)
    expected = with_load_notes(report, None, [], True)
    assert isinstance(noted.rows.others, RowsWithDisplaced)
    assert noted.rows.others.table is columns_report.rows.others.table
    assert noted.to_csv() == expected.to_csv()
    assert "compensated with no payload" in noted.to_csv()
    assert noted.to_csv() != columns_report.to_csv()
