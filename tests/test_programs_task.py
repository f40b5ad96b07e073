"""Whole RAPID tasks of several modules (tests/tasks/cell_task): tools in CalibData.mod,
work objects in WObjData.mod, motions in Weld.mod and Pick.mod, a system module user.sys
with data, a LOCAL work object in Weld.mod hiding the global one, a PERS declared in two
modules, a tool declared nowhere; and robot-to-robot transfer (``taught_on``).

Truth comes from outside the code under test: the module files themselves (the task
concatenated into one module by this test), the literal scanner of
test_programs_accounting, and virtual robots (pinocchio on perturbed URDFs) driven by an
independent nominal controller (test_compensate.World).
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.calibration.identify import IdentificationOptions, identify
from olp_compensate.calibration.simulate import make_virtual_robot, random_joints
from olp_compensate.compensation.pose import Compensator
from olp_compensate.errors import DataError
from olp_compensate.kinematics.conventions import MM, invert_pose, pose_from_rotation_translation
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs import load, loads
from olp_compensate.programs.object_model.task import compensate_program
from olp_compensate.programs.object_model.task import compensate_task
from olp_compensate.programs.semantics import resolve_task
from test_compensate import (NOISE_M, World, as_program_tool, rapid_module, read_rapid_targets,
                             written_targets)
from test_programs_accounting import literal_places

FOLDER = Path(__file__).parent / "tasks" / "cell_task"
ORDER = ("CalibData.mod", "WObjData.mod", "Weld.mod", "Pick.mod", "user.sys")


def task_programs():
    return [load(FOLDER / name) for name in ORDER]


@pytest.fixture(scope="module")
def nominal():
    return Compensator(nominal_calibration(load_robot("abb_irb2400")))


@pytest.fixture(scope="module")
def robot_a():
    return World("abb_irb2400", seed=5)


class _WorldWithToolOf(World):
    """Another arm (``seed``) carrying a copy of ``other``'s tool, each point mounted about
    a millimetre off: as a cell's second robot with the same tool design."""

    def __init__(self, seed: int, other: World):
        rng = np.random.default_rng(seed)
        self.robot = other.robot
        drawn = make_virtual_robot(self.robot, seed=seed, n_points=3)
        tools = {k: v + rng.normal(0, 1e-3, 3) for k, v in other.virtual.tools.items()}
        self.virtual = dataclasses.replace(drawn, tools=tools,
                                           tool_rotations=dict(other.virtual.tool_rotations))
        meas = self.virtual.measure(random_joints(self.robot, 60, rng), NOISE_M, rng)
        self.calibration = as_program_tool(
            identify(self.robot, meas, IdentificationOptions(folds=0)).calibration)
        self.nominal, self.family, self.limits = other.nominal, other.family, other.limits


@pytest.fixture(scope="module")
def robot_b(robot_a):
    return _WorldWithToolOf(9, robot_a)


def test_nominal_calibration_gives_every_module_back_byte_for_byte(nominal):
    programs = task_programs()
    texts, report = compensate_task(programs, nominal)
    for name, text in zip(ORDER, texts):
        assert text.encode("latin-1") == (FOLDER / name).read_bytes(), name
    assert report.edits == 0
    assert {r.file for r in report.rows} == {str(FOLDER / n) for n in ("Weld.mod", "Pick.mod",
                                                                      "user.sys")}


def concatenated() -> str:
    """The task as one module, written by this test from the files: each module's body in
    order, Weld's LOCAL wTable renamed wTableL (a module has one name space), Pick's second
    declaration of the PERS pShared dropped, user.sys's data kept."""
    bodies = []
    for name in ORDER:
        lines = (FOLDER / name).read_text("latin-1").splitlines()
        body = lines[1:lines.index("ENDMODULE")]
        if name == "Weld.mod":
            body = [re.sub(r"\bwTable\b", "wTableL", x).replace("LOCAL PERS", "PERS")
                    for x in body]
        if name == "Pick.mod":
            body = [x for x in body if not x.strip().startswith("PERS robtarget pShared")]
        bodies += body
    return "\n".join(["MODULE Whole", *bodies, "ENDMODULE", ""])


def test_task_compensates_like_its_modules_concatenated(robot_a):
    cal = Compensator(robot_a.calibration)
    programs = task_programs()
    texts, report = compensate_task(programs, cal)
    one_text, one_report = compensate_program(concatenated(), "rapid", cal)
    whole = {t.name: t.texts for t in loads(one_text, "rapid").targets}
    written = {}
    for text, program in zip(texts, programs):
        for t in loads(text, "rapid", program.file).targets:
            written.setdefault(t.name, []).append(t.texts)
    assert set(written) == set(whole)
    for name, versions in written.items():       # pShared twice: one variable
        assert all(v == whole[name] for v in versions), name
    one_rows = {(r.target, r.status, r.tool, r.wobj.replace("wTableL", "wTable"))
                for r in one_report.rows}
    task_rows = {(r.target, r.status, r.tool, r.wobj) for r in report.rows}
    assert task_rows == one_rows
    moved = [r for r in report.rows if r.status == "ok"]
    assert len(moved) == 9   # pShared twice: in Weld.mod and Pick.mod
    assert all(np.linalg.norm(r.correction_mm) > 0.1 for r in moved)   # not a no-op
    assert texts[0] == programs[0].text and texts[1] == programs[1].text   # data only


def test_local_work_object_hides_the_global_one_in_its_module_only():
    programs = task_programs()
    weld, pick, system = resolve_task(programs)[2:5]
    by_name = lambda res: {t.name: res.pairs[p] for t, p in   # noqa: E731
                           zip(res.entry_targets, res.entry_pairs.tolist())}
    local = by_name(weld)["pWeld10"].base_T_wobj[:3, 3] / MM
    shared = by_name(pick)["pTable"].base_T_wobj[:3, 3] / MM
    np.testing.assert_allclose(local, [760, -80, 380], atol=1e-9)    # Weld.mod line 3
    np.testing.assert_allclose(shared, [700, -150, 420], atol=1e-9)  # WObjData.mod line 3
    tool = by_name(system)["pService"].flange_T_tool[:3, 3] / MM       # from user.sys
    np.testing.assert_allclose(tool, [0, 0, 120], atol=1e-9)


def test_tool_declared_in_no_module_is_unresolved_by_name(nominal):
    _, report = compensate_task(task_programs(), nominal)
    (row,) = [r for r in report.rows if r.target == "pLost"]
    assert row.status == "unresolved" and row.tool == "tMissing"
    assert "tMissing" in row.note
    assert row.file == str(FOLDER / "Pick.mod") and row.line == 5


def test_unused_means_moved_to_in_no_module(nominal):
    _, report = compensate_task(task_programs(), nominal)
    status = {r.target: r.status for r in report.rows}
    assert status["pNever"] == "unused"
    assert status["pService"] == "ok"   # declared in user.sys, moved to in Pick.mod
    assert status["pShared"] == "ok"    # declared in Weld.mod, moved to in Pick.mod
    # a call of a routine of another module is not an unknown instruction
    assert "unknown_instruction" not in status.values()
    (never,) = [r for r in report.rows if r.target == "pNever"]
    assert "any module of the task" in never.note


def test_every_robtarget_literal_of_the_task_is_accounted_for(nominal):
    _, report = compensate_task(task_programs(), nominal)
    for name in ORDER:
        path = FOLDER / name
        reported = {(r.line, r.column) for r in report.rows if r.file == str(path)}
        missing = [p for p in literal_places(path.read_text("latin-1")) if p not in reported]
        assert not missing, f"{name}: literals not in the report: {missing}"


PERS_A = ("MODULE A\n  PERS robtarget pP:=[[900,0,800],[0,0,1,0],[0,0,0,0],"
          "[9E9,9E9,9E9,9E9,9E9,9E9]];\n  PERS tooldata tT;\nENDMODULE\n")
PERS_B = ("MODULE B\n  PERS robtarget pP:=[[901,0,800],[0,0,1,0],[0,0,0,0],"
          "[9E9,9E9,9E9,9E9,9E9,9E9]];\n  PERS tooldata tT:=[TRUE,[[0,0,100],[1,0,0,0]],"
          "[1,[0,0,1],[1,0,0,0],0,0,0]];\n  PROC main()\n    MoveL pP,v100,fine,tT;\n"
          "  ENDPROC\nENDMODULE\n")


def test_a_pers_declared_in_two_modules_is_one_variable(nominal):
    a, b = loads(PERS_A, "rapid", "A.mod"), loads(PERS_B, "rapid", "B.mod")
    res_a, res_b = resolve_task([a, b])
    # the first declaration's value: A's pP (900 mm), moved to in B with B's tT (the
    # tooldata declared without a value in A refers to the one with a value)
    (flange,) = res_a.base_T_flange
    np.testing.assert_allclose(flange[:3, 3] / MM, [900, 0, 800 + 100], atol=1e-9)
    assert any("another value" in w for w in res_b.warnings)
    assert len(res_b.entry_uses[0]) == 1   # B's own literal: the same variable, same use
    _, report = compensate_task([a, b], nominal)
    assert [r.status for r in report.rows] == ["ok", "ok"]


def test_one_module_is_the_task_of_one_module(robot_a):
    program = load(FOLDER / "Weld.mod")
    cal = Compensator(robot_a.calibration)
    text, report = compensate_program(program, None, cal)
    (text2,), report2 = compensate_task([program], cal)
    assert text == text2 and report.to_csv() == report2.to_csv()


def test_bad_task_arguments_are_refused(nominal):
    with pytest.raises(DataError):
        compensate_task([], nominal)
    with pytest.raises(DataError):
        compensate_task([load(FOLDER / "Weld.mod"), load(Path(__file__).parents[1] / "samples"
                                                         / "cell_b.pg")], nominal)
    with pytest.raises(DataError):
        compensate_task(task_programs(), nominal, emit="both")


# ---- robot-to-robot transfer ------------------------------------------------------

def _tcp_in_base(world: World, q_ctrl: np.ndarray) -> np.ndarray:
    """(m, 3) the true 'tcp' point at controller joints, in the robot's base frame as its
    calibration defines it (through the measuring device both place the robot in), m."""
    point = np.append(world.virtual.tools["tcp"], 1.0)
    device = world.virtual.device_T_base @ world.virtual.flange_poses(q_ctrl) @ point
    return (invert_pose(world.calibration.device_T_base) @ device[..., None])[:, :3, 0]


def _reached(world: World, text: str, program_tool, wobj) -> dict:
    """target name -> where the world's real tcp goes when its nominal controller runs
    the program (odd targets in wTable, even in wobj0), base frame, m."""
    _, cart, _ = read_rapid_targets(text)
    out = {}
    for name, (pose, conf) in cart.items():
        frame = wobj if int(name[1:]) % 2 else np.eye(4)
        q = world.controller((frame @ pose @ invert_pose(program_tool))[None], conf[None])
        out[name] = _tcp_in_base(world, q)[0]
    return out


@pytest.fixture(scope="module")
def taught_program(robot_a):
    """A program taught on robot A: targets at A's nominal TCP, tool 'tcp' (the name of
    the calibrated point of both robots)."""
    q = robot_a.program_joints(8, seed=1)
    tool = pose_from_rotation_translation(np.eye(3), np.round(
        robot_a.calibration.tools["tcp"].xyz_m / MM, 1) * MM)
    wobj = pose_from_rotation_translation(np.eye(3), np.array([0.05, -0.02, 0.01]))
    numbers = written_targets(robot_a, q, tool, wobj)
    text = rapid_module(numbers, tool[:3, 3] / MM, [1, 0, 0, 0], wobj[:3, 3] / MM,
                        [1, 0, 0, 0])
    return text, tool, wobj


def test_transfer_puts_b_real_tool_where_a_real_tool_went(robot_a, robot_b, taught_program):
    text, tool, wobj = taught_program
    meant = _reached(robot_a, text, tool, wobj)
    new, report = compensate_program(text, "rapid", robot_b.calibration,
                                     taught_on=robot_a.calibration)
    # p1 lies at the edge of the workspace (arm stretched): B's arm falls 0.8 mm short of
    # where A's tool went; it must be reported so, the others met
    ok = [r.target for r in report.rows if r.status == "ok"]
    assert len(ok) >= len(meant) - 1, [r.note for r in report.rows]
    assert all(r.status in ("ok", "unreachable") for r in report.rows)
    after = _reached(robot_b, new, tool, wobj)
    before = _reached(robot_b, text, tool, wobj)
    errors = [np.linalg.norm(after[k] - meant[k]) for k in ok]
    misses = [np.linalg.norm(before[k] - meant[k]) for k in ok]
    assert max(errors) < 0.05e-3, errors
    assert min(misses) > 0.3e-3 and max(misses) > 1e-3, misses   # untouched: mm off


def test_transfer_to_the_same_robot_gives_the_input_back(robot_b, taught_program):
    text, _, _ = taught_program
    for taught_on in (robot_b.calibration, Compensator(robot_b.calibration)):
        new, report = compensate_program(text, "rapid", robot_b.calibration,
                                         taught_on=taught_on)
        assert new.encode("latin-1") == text.encode("latin-1")
        assert all(r.status == "ok" for r in report.rows)


def test_local_names_skip_comments_strings_and_routines():
    from olp_compensate.programs.rapid.task_scope import local_data_names

    text = ('MODULE M\n  LOCAL PERS tooldata tA:=[TRUE,[[0,0,1],[1,0,0,0]],'
            '[1,[0,0,1],[1,0,0,0],0,0,0]];\n'
            '  ! LOCAL VAR num inComment;\n'
            '  VAR string s:="LOCAL CONST num inString";\n'
            '  local\n    CONST num lowerCase:=1;\n'
            '  VAR num nolocal:=1;\n'
            '  LOCAL PROC helper()\n  ENDPROC\nENDMODULE\n')
    assert local_data_names(loads(text, "rapid")) == {"ta", "lowercase"}
