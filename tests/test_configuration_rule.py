"""The configuration rule, the same on every path (RAPID, KRL, FANUC, VAL3, URScript):

- ``ok`` only on the configuration asked for, inside every controller range;
- ``branch_changed`` only when another configuration reaches the target inside every range,
  the note naming exactly that one (its joints are reported: checked here by the test's
  own nominal controller, a closed form fitted on pinocchio's forward kinematics, and an
  enumeration of every branch and turn);
- ``joint_limit`` when only configurations outside a range reach it, ``unreachable`` when
  none does (a target 5 m away);
- notes never show a joint outside [-180, 180] deg unless the controller's range itself
  goes further;
- the written confdata is the quadrant of the joints written (checked by running the
  written target through the test's own nominal controller).
"""

from __future__ import annotations

import itertools
import math
import re

import numpy as np
import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.calibration.simulate import random_joints
from olp_compensate.compensation.dialect_program import compensate_pose_program
from olp_compensate.compensation.dialect_rules import ArmGeometry
from olp_compensate.compensation.ik import branch_of, closed_form_inverse
from olp_compensate.compensation.pose import Compensator
from olp_compensate.kinematics.conventions import (MM, euler_xyz_from_matrix, euler_zyx_from_matrix,
                                                   quat_wxyz_from_matrix)
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs import loads
from olp_compensate.programs.fanuc.reader import parse_fanuc_tp
from olp_compensate.programs.fanuc.rules import FANUC_TP, fanuc_letters, turn_number
from olp_compensate.programs.krl.reader import parse_krl
from olp_compensate.programs.krl.rules import KRL, krl_status, krl_turn
from olp_compensate.programs.object_model.task import compensate_program
from olp_compensate.programs.val3.reader import parse_val3
from olp_compensate.programs.val3.rules import VAL3, val3_config
import test_programs_fanuc as fanuc_case
import test_programs_krl as krl_case
import test_programs_val3 as val3_case
from virtual_world import identified_world, nominal_arm

ROBOTS = {"rapid": "abb_irb2400", "krl": "kuka_kr16_2", "fanuc": "fanuc_r2000ic_165f",
          "val3": "staubli_tx2_60"}


class Truth:
    """A robot's nominal arm as the test's own controller sees it: pinocchio's forward
    kinematics of the data-sheet URDF and a closed form fitted on it."""

    def __init__(self, name: str):
        self.robot = load_robot(name)
        self.nominal, self.family = nominal_arm(self.robot)
        self.geometry = ArmGeometry(self.robot)

    def flange(self, q_ctrl: np.ndarray) -> np.ndarray:
        return self.nominal.flange_poses(np.atleast_2d(q_ctrl))

    def solutions(self, flange: np.ndarray) -> np.ndarray:
        """Every controller joint vector ``(k, n)`` that puts the flange on ``flange``:
        each branch of the closed form that forward kinematics confirms, with every whole
        turn (-1, 0, +1) of each revolute axis (in range or not)."""
        robot = self.robot
        branches = robot.controller_from_joints(closed_form_inverse(self.family,
                                                                    flange[None])[0])
        branches = branches[np.all(np.isfinite(branches), axis=1)]
        if not len(branches):
            return np.zeros((0, robot.n_joints))
        reach = np.array([np.allclose(f, flange, atol=1e-8) for f in self.flange(branches)])
        branches = branches[reach]
        revolute = [a for a, j in enumerate(robot.joints) if j.kind == "revolute"]
        turns = np.zeros((3 ** len(revolute), robot.n_joints))
        turns[:, revolute] = 2 * np.pi * np.array(
            list(itertools.product((-1, 0, 1), repeat=len(revolute))))
        return (branches[:, None, :] + turns[None]).reshape(-1, robot.n_joints)

    def in_range(self, flange: np.ndarray) -> np.ndarray:
        """The :meth:`solutions` inside every range and limit, each confirmed by forward
        kinematics (whole turns of coupled axes included)."""
        q = self.solutions(flange)
        q = q[~self.robot.outside_ranges(q).any(axis=1)] if len(q) else q
        if len(q):
            assert all(np.allclose(f, flange, atol=1e-8) for f in self.flange(q))
        return q


_TRUTHS: dict = {}


def truth(dialect: str) -> Truth:
    if dialect not in _TRUTHS:
        _TRUTHS[dialect] = Truth(ROBOTS[dialect])
    return _TRUTHS[dialect]


def _joints_shown_are_wrapped(note: str, robot) -> None:
    """Every 'axis k = v deg' of a note lies in [-180, 180] or inside the axis's range."""
    ranges = np.degrees(robot.controller_ranges)
    for axis, value in re.findall(r"axis (\d) = (-?[0-9.]+) deg", note):
        a, v = int(axis) - 1, float(value)
        lo, hi = ranges[a]
        assert -180.0 <= v <= 180.0 or lo <= v <= hi, note


# ---- programs of each dialect: one target at a pose, with a configuration -------------

def _tcp(dialect: str) -> np.ndarray:
    """flange_T_tool of each dialect's program (m)."""
    if dialect == "rapid":
        return np.eye(4)
    rules = {"krl": KRL, "fanuc": FANUC_TP, "val3": VAL3}[dialect]
    tool = {"krl": krl_case.TOOL_MM, "fanuc": fanuc_case.TOOL_MM, "val3": val3_case.TOOL_MM}
    return rules.convention.pose(np.asarray(tool[dialect], float))


def _config_of(dialect: str, q: np.ndarray):
    t = truth(dialect)
    if dialect == "rapid":
        return tuple(int(c) for c in np.concatenate([
            np.floor(q[[0, 3, 5]] / (np.pi / 2)),
            branch_of(t.family, t.robot.joints_from_controller(q[None]))]))
    if dialect == "krl":
        return krl_status(t.geometry, q), krl_turn(q)
    if dialect == "fanuc":
        return fanuc_letters(t.geometry, q), tuple(turn_number(math.degrees(v)) for v in q[3:6])
    return val3_config(t.geometry, q)


def _words(dialect: str, config) -> str:
    if dialect == "rapid":
        return "[" + ",".join(str(c) for c in config) + "]"
    if dialect == "krl":
        return f"S {config[0]} T {config[1]}"
    if dialect == "fanuc":
        return FANUC_TP.config_words(tuple(config[0]) + tuple(config[1]))
    return " ".join(config)


def run(dialect: str, tcp_pose: np.ndarray, config):
    """Compensate a one-target program of ``dialect`` (TCP pose in the base frame, m) with
    the nominal calibration; its row."""
    robot = truth(dialect).robot
    cal = nominal_calibration(robot)
    if dialect == "rapid":
        pos = ",".join(f"{v:.3f}" for v in tcp_pose[:3, 3] / MM)
        quat = ",".join(f"{v:.6f}" for v in quat_wxyz_from_matrix(tcp_pose[:3, :3]))
        conf = ",".join(str(c) for c in config)
        text = (f"MODULE T\n  CONST robtarget p1:=[[{pos}],[{quat}],[{conf}],"
                f"[9E9,9E9,9E9,9E9,9E9,9E9]];\n  PROC main()\n    MoveJ p1,v100,fine,tool0;\n"
                f"  ENDPROC\nENDMODULE\n")
        _, report = compensate_program(text, "rapid", Compensator(cal))
        return next(r for r in report.rows if r.target == "p1")
    if dialect == "krl":
        values = np.concatenate([tcp_pose[:3, 3] / MM,
                                 np.degrees(euler_zyx_from_matrix(tcp_pose[:3, :3]))])
        src, dat = krl_case.krl_module([(values, config[0], config[1])])
        program = parse_krl(src, dat, "CELL.src", "CELL.dat", krl_case.CONFIG_DAT,
                            "$config.dat")
        _, report = compensate_pose_program(program, KRL, cal)
        return next(r for r in report.rows if r.target == "XP1")
    if dialect == "fanuc":
        wpr = fanuc_case._wpr(tcp_pose)
        text = fanuc_case.ls_program([(wpr, config[0], config[1])])
        program = parse_fanuc_tp(text, "CELL.ls", frames={"UT4": fanuc_case.TOOL_MM})
        _, report = compensate_pose_program(program, FANUC_TP, cal)
        return next(r for r in report.rows if r.target == "P[1]")
    values = np.concatenate([tcp_pose[:3, 3] / MM,
                             np.degrees(euler_xyz_from_matrix(tcp_pose[:3, :3]))])
    program = parse_val3({"cell.dtx": val3_case.dtx_attributes([(values, config)])})
    _, report = compensate_pose_program(program, VAL3, cal)
    return next(r for r in report.rows if r.status not in ("joint_target",))


DIALECTS = ["rapid", "krl", "fanuc", "val3"]


# ---- (c) out of reach -------------------------------------------------------------------

@pytest.mark.parametrize("dialect", DIALECTS)
def test_a_target_5_m_away_is_unreachable(dialect):
    """x = 5,000 mm: no configuration reaches it; 'unreachable', whatever the written
    configuration says (it was 'branch_changed' for KRL, FANUC, VAL3)."""
    t = truth(dialect)
    q_home = np.radians([0.0, 10.0, 10.0, 0.0, 45.0, 0.0])
    pose = t.flange(q_home)[0] @ _tcp(dialect)
    pose[:3, 3] = [5.0, 0.0, 1.0]
    row = run(dialect, pose, _config_of(dialect, q_home))
    assert row.status == "unreachable", row.note
    assert "out of reach on every configuration" in row.note
    _joints_shown_are_wrapped(row.note, t.robot)
    assert not len(t.solutions(pose @ np.linalg.inv(_tcp(dialect))))


# ---- (a) only outside the ranges ----------------------------------------------------------

def _only_outside(dialect: str, seed: int = 4):
    """Controller joints with axis 2 or 3 just past its range whose pose no configuration
    reaches inside the ranges (checked by enumeration)."""
    t = truth(dialect)
    robot = t.robot
    ranges = robot.controller_ranges
    for q in random_joints(robot, 300, np.random.default_rng(seed), margin=0.3):
        if abs(math.sin(q[4])) < 0.3:
            continue
        for axis, side in ((2, 1), (2, 0), (1, 1), (1, 0)):
            q_out = q.copy()
            q_out[axis] = ranges[axis, side] + np.radians(6.0 if side else -6.0)
            flange = t.flange(q_out)[0]
            joints = robot.joints_from_controller(q_out[None])[0]
            if np.any(joints < robot.lower_limits - 0.5) or np.any(joints > robot.upper_limits + 0.5):
                continue
            if len(t.solutions(flange)) and not len(t.in_range(flange)):
                return q_out, axis
    pytest.fail(f"{dialect}: no pose only an out-of-range configuration reaches")


@pytest.mark.parametrize("dialect", DIALECTS)
def test_a_target_only_outside_the_ranges_is_joint_limit(dialect):
    t = truth(dialect)
    q_out, axis = _only_outside(dialect)
    pose = t.flange(q_out)[0] @ _tcp(dialect)
    row = run(dialect, pose, _config_of(dialect, q_out))
    assert row.status == "joint_limit", row.note
    assert "no configuration reaches it inside the axis ranges" in row.note
    assert re.search(r"axis \d = -?[0-9.]+ deg is [0-9.]+ deg (above|below) the "
                     r"controller's range", row.note), row.note
    _joints_shown_are_wrapped(row.note, t.robot)
    # the joints reported reach the pose, and lie outside a range
    q = np.radians(row.joints)
    assert np.allclose(t.flange(q)[0], pose @ np.linalg.inv(_tcp(dialect)), atol=1e-4)
    assert t.robot.outside_ranges(q[None]).any()


# ---- (b) another configuration inside the ranges ------------------------------------------

def _asked_elsewhere(dialect: str, seed: int = 7):
    """(joints inside every range, the configuration words of a solution of the same pose
    that lies outside the ranges whatever its turns, and no solution with that
    configuration is in range)."""
    t = truth(dialect)
    robot = t.robot
    for q in random_joints(robot, 300, np.random.default_rng(seed), margin=0.3):
        if abs(math.sin(q[4])) < 0.3:
            continue
        flange = t.flange(q)[0]
        inside = t.in_range(flange)
        if not len(inside):
            continue
        good = {_words(dialect, _config_of(dialect, s)) for s in inside}
        for other in t.solutions(flange)[(3 ** 6) // 2::3 ** 6]:    # each branch, no turn
            config = _config_of(dialect, other)
            if _words(dialect, config) not in good and _configuration_out(dialect, other, good):
                return q, config, inside
    pytest.fail(f"{dialect}: no pose with a configuration only outside the ranges")


def _configuration_out(dialect: str, other: np.ndarray, good: set) -> bool:
    """Whether the configuration of ``other`` (a solution outside the ranges) differs
    from every in-range solution's even where the dialect leaves turns free."""
    if dialect == "rapid":
        cfx = _config_of(dialect, other)[3]
        return all(not w.endswith(f",{cfx}]") for w in good)
    if dialect == "krl":
        s = _config_of(dialect, other)[0]
        return all(not w.startswith(f"S {s} ") for w in good)
    if dialect == "fanuc":
        letters = " ".join(_config_of(dialect, other)[0])
        return all(not w.startswith(letters) for w in good)
    return True


@pytest.mark.parametrize("dialect", DIALECTS)
def test_another_in_range_configuration_is_branch_changed_naming_it(dialect):
    t = truth(dialect)
    q, asked, inside = _asked_elsewhere(dialect)
    pose = t.flange(q)[0] @ _tcp(dialect)
    row = run(dialect, pose, asked)
    assert row.status == "branch_changed", row.note
    found = re.search(r"only on another configuration: ([^;]+)", row.note)
    assert found, row.note
    named = found.group(1).strip()
    # the joints reported: inside every range, on the pose, on the configuration named
    q_row = np.radians(row.joints)
    assert not t.robot.outside_ranges(q_row[None]).any(), row.joints
    assert np.allclose(t.flange(q_row)[0], pose @ np.linalg.inv(_tcp(dialect)), atol=1e-4)
    assert named == _words(dialect, _config_of(dialect, q_row))
    # ... and an independent in-range solution has that configuration
    assert named in {_words(dialect, _config_of(dialect, s)) for s in inside}
    _joints_shown_are_wrapped(row.note, t.robot)


# ---- (d) confdata: the quadrant of the joints written -------------------------------------

@pytest.fixture(scope="module")
def irb2400_world():
    robot = load_robot("abb_irb2400")
    return identified_world(robot, 3)


def test_written_confdata_is_the_quadrant_the_controller_takes(irb2400_world):
    """Targets with axis 4 or 6 within half a degree of a quadrant border, compensated on
    an identified IRB 2400: the written target, run through the test's own nominal
    controller (the written cfx's branch, the turn of each axis nearest its written
    quadrant), gives joints whose quadrants are the written cf1, cf4, cf6; and some
    targets did cross a border (cf4/cf6 rewritten)."""
    _, cal = irb2400_world
    t = truth("rapid")
    robot = t.robot
    rng = np.random.default_rng(11)
    q = random_joints(robot, 400, rng, margin=0.35)
    q = q[np.abs(np.sin(q[:, 4])) > 0.4][:120]
    borders = np.radians([-90.0, 0.0, 90.0])
    q[:, 3] = rng.choice(borders, len(q)) + np.radians(rng.uniform(-0.5, 0.5, len(q)))
    q[:, 5] = rng.choice(borders, len(q)) + np.radians(rng.uniform(-0.5, 0.5, len(q)))
    lines = ["MODULE Q"]
    conf_in = []
    for k, qk in enumerate(q, 1):
        pose = t.flange(qk)[0]
        conf = _config_of("rapid", qk)
        conf_in.append(conf)
        pos = ",".join(f"{v:.3f}" for v in pose[:3, 3] / MM)
        quat = ",".join(f"{v:.7f}" for v in quat_wxyz_from_matrix(pose[:3, :3]))
        lines.append(f"  CONST robtarget p{k}:=[[{pos}],[{quat}],[{','.join(map(str, conf))}],"
                     f"[9E9,9E9,9E9,9E9,9E9,9E9]];")
    lines += ["  PROC main()"] + [f"    MoveJ p{k},v100,fine,tool0;" for k in range(1, len(q) + 1)]
    lines += ["  ENDPROC", "ENDMODULE", ""]
    text, report = compensate_program("\n".join(lines), "rapid", Compensator(cal))
    written = {tg.name: tg for tg in loads(text, "rapid").targets}
    rows = {r.target: r for r in report.rows}
    crossed = checked = 0
    for k in range(1, len(q) + 1):
        row = rows[f"p{k}"]
        if row.status not in ("ok", "singular"):
            continue
        target = written[f"p{k}"]
        conf = np.array(target.config_values(), int)
        # the test's own controller on the written target
        branches = robot.controller_from_joints(closed_form_inverse(t.family, target.pose()[None])[0])
        q_c = branches[conf[3]].copy()
        for j, a in enumerate((0, 3, 5)):
            centre = (conf[j] + 0.5) * np.pi / 2
            q_c[a] += 2 * np.pi * np.round((centre - q_c[a]) / (2 * np.pi))
        quadrant = np.floor(q_c[[0, 3, 5]] / (np.pi / 2)).astype(int)
        near_border = np.abs(np.remainder(q_c[[0, 3, 5]] + np.pi / 4, np.pi / 2)
                             - np.pi / 4) < 1e-5
        assert np.all((quadrant == conf[:3]) | near_border), (k, np.degrees(q_c), conf)
        checked += 1
        crossed += int(np.any(conf[:3] != np.array(conf_in[k - 1][:3])))
    assert checked >= 100 and crossed >= 5, (checked, crossed)


# ---- property: every ok/branch_changed row of the golden programs is inside the ranges ----

def _golden_reports():
    """(case name, robot, report) of every golden program that parses and of the task,
    with the nominal calibration of the maker's robot (as the golden tests run them)."""
    import test_programs_golden as golden
    from olp_compensate.programs.object_model.task import compensate_task
    from olp_compensate.errors import ParseError
    from test_programs_task import task_programs

    for case in golden.CASES:
        dialect = golden._pose_dialect(case)
        try:
            if dialect is None:
                robot = load_robot("abb_irb2400")
                _, report = compensate_program(golden.load(golden._input(case)), None,
                                               nominal_calibration(robot))
            else:
                robot = load_robot(golden.MAKER_ROBOT[dialect])
                _, report = golden._compensate_case(golden._pose_inputs(case, dialect), dialect)
        except ParseError:          # the cases of malformed programs
            continue
        yield case.name, robot, report
    robot = load_robot("abb_irb2400")
    _, report = compensate_task(task_programs(), Compensator(nominal_calibration(robot)))
    yield "cell_task", robot, report


def test_reported_joints_of_golden_and_task_programs_are_in_range():
    """Every 'ok', 'singular' or 'branch_changed' row of the golden programs and the task
    reports joints inside the controller's ranges; every failure note shows joints in
    [-180, 180] deg or their range's own form."""
    seen = 0
    for name, robot, report in _golden_reports():
        for row in report.rows:
            if row.status in ("ok", "singular", "branch_changed") and row.joints:
                q = robot.to_radians_or_metres(np.array(row.joints)[None])
                assert not robot.outside_ranges(q).any(), (name, row)
                seen += 1
            if row.status in ("joint_limit", "branch_changed", "unreachable", "not_converged"):
                _joints_shown_are_wrapped(row.note, robot)
    assert seen > 20


def test_urscript_targets_5_m_away_are_unreachable_and_the_rest_ok():
    """URScript writes no configuration: a pose 5 m away is 'unreachable' (never
    'branch_changed'), its neighbours in the script stay 'ok'; joints in notes wrapped."""
    import test_programs_urscript as ur_case
    from olp_compensate.programs.urscript.rules import URSCRIPT
    from olp_compensate.programs.urscript.reader import parse_urscript

    q = ur_case._walk(3, 2)
    poses = ur_case._targets_at(q)
    poses[1] = poses[1].copy()
    poses[1][:3] = [5.0, 0.0, 0.5]
    program = parse_urscript(ur_case.script(poses, q), "cell.script")
    _, report = compensate_pose_program(program, URSCRIPT, nominal_calibration(ur_case.ROBOT))
    statuses = {r.target: r.status for r in report.rows    # set_tcp's pose: a 'frame' row
                if r.status not in ("joint_target", "frame")}
    assert statuses == {"Waypoint_1_p": "ok", "Waypoint_2_p": "unreachable",
                        "<inline>": "ok"}, report.rows
    for row in report.rows:
        _joints_shown_are_wrapped(row.note, ur_case.ROBOT)


def test_krl_targets_at_the_range_ends_on_an_identified_robot():
    """KRL targets with A1, A4 or A6 within a degree of their range's end, compensated on
    an identified KR 16: none 'not_converged'; 'branch_changed' keeps the asked S (only a
    turn differs: the configuration nearest the asked one is named) but next to the
    shoulder singularity, and reports
    joints inside every range that put the calibrated arm on the target; notes wrapped."""
    from olp_compensate.compensation.pose import Compensator as Comp

    robot = krl_case.ROBOT
    _, cal = identified_world(robot, 11, "TOOL_DATA[1]")
    rng = np.random.default_rng(3)
    q = random_joints(robot, 300, rng, margin=0.05)
    ranges = robot.controller_ranges
    for a in (0, 3, 5):
        pick = rng.random(len(q)) < 0.5
        end = np.where(rng.random(pick.sum()) < 0.5, ranges[a, 0] + np.radians(0.5),
                       ranges[a, 1] - np.radians(0.5))
        q[pick, a] = end + np.radians(rng.uniform(-0.4, 0.4, pick.sum()))
    q = q[np.abs(np.sin(q[:, 4])) > 0.2][:80]
    src, dat = krl_case.krl_module(krl_case._targets_at(q))
    program = parse_krl(src, dat, "CELL.src", "CELL.dat", krl_case.CONFIG_DAT, "$config.dat")
    _, report = compensate_pose_program(program, KRL, cal)
    comp = Comp(cal)
    real_tool = np.eye(4)
    real_tool[:3, 3] = cal.tools["TOOL_DATA[1]"].xyz_m
    statuses = [r.status for r in report.rows]
    assert "not_converged" not in statuses and statuses.count("branch_changed") >= 5
    by_name = {t.name: t for t in program.targets}
    kept_s = changed = 0
    for row in report.rows:
        _joints_shown_are_wrapped(row.note, robot)
        if row.status != "branch_changed":
            continue
        asked = re.search(r"asked for configuration S (\d+) T \d+", row.note)
        named = re.search(r"only on another configuration: S (\d+) T \d+", row.note)
        assert asked and named, row.note
        kept_s += asked.group(1) == named.group(1)
        changed += 1
        q_row = np.radians(row.joints)
        assert not robot.outside_ranges(q_row[None]).any()
        target = KRL.convention.pose(np.array([n.value for n in by_name[row.target].numbers]))
        flange, _ = comp.real_flange_and_jacobian(robot.joints_from_controller(q_row[None]))
        # the real TCP (calibrated tool) on the target (base 0: the robot base)
        assert np.allclose(flange[0] @ real_tool, target, atol=1e-5), row.target
    # S changes only where the wrist point is next to axis 1 (S's bit 0 is undetermined)
    assert kept_s >= 0.8 * changed, (kept_s, changed)


def test_the_search_solves_every_start_as_refine_alone_would(irb2400_world):
    """The rule's search (shared across the batch: two branches the closed form stretches to
    the same joints, out of reach, are solved once; a start that is none is not solved)
    gives, start by start, what a damped Newton of that start alone gives: the same
    verdict, end joints and errors; except a start it stopped early because it had
    stalled behind another start of its target (issue 32 item 3): that one did not reach
    the target alone either, and alone it ends further from it than the start the rule
    keeps (it could not have been the one kept)."""
    from olp_compensate.compensation.config_rule import SEARCH_STEPS, search, turn_toward_ranges
    from olp_compensate.compensation.ik import refine

    virtual, cal = irb2400_world
    comp = Compensator(cal)
    robot = comp.robot
    rng = np.random.default_rng(5)
    q = robot.joints_from_controller(random_joints(robot, 6, rng, margin=0.2,
                                                   within_ranges=False))
    desired = comp.nominal_flange(q)
    desired[:2, :3, 3] *= 3.0                                  # out of reach
    starts = closed_form_inverse(comp.family, desired, clip=True)
    copies = sum(len(s) - len(np.unique(s, axis=0)) for s in starts[:2])
    assert copies >= 1                                        # the stretched arm's copies
    own = q + 0.05
    own[1] = np.nan                                           # no own end: not solved
    found = search(comp, desired, own)
    every = np.concatenate([starts, own[:, None]], axis=1)
    score = found.position_error_m + 0.1 * found.rotation_error_rad
    stopped = set_aside = 0
    for i in range(len(desired)):
        for j, start in enumerate(every[i]):
            if not np.all(np.isfinite(start)):
                assert found.reason[i, j] == "unreachable"
                assert not np.isfinite(found.position_error_m[i, j])
                continue
            alone = refine(comp.real_flange_and_jacobian, start[None], desired[i][None],
                           None, 1e-9, 1e-9, SEARCH_STEPS)
            end = robot.controller_from_joints(alone.q)[0]
            if np.isnan(found.position_error_m[i, j]):
                # set aside (issue 32 item 3): alone it reaches the pose outside a range,
                # the travel after its first step no longer than that step (the premise
                # of FarOutside's bound)
                set_aside += 1
                assert found.rough[i, j] and found.reason[i, j] == "ok", (i, j)
                assert not found.inside[i, j] and alone.success[0], (i, j)
                turned = turn_toward_ranges(robot, end[None])
                assert robot.outside_ranges(turned).any(), (i, j)
                gap = np.remainder(found.q[i, j] - end + np.pi, 2 * np.pi) - np.pi
                first = robot.controller_from_joints(start[None])[0]
                step = np.remainder(found.q[i, j] - first + np.pi, 2 * np.pi) - np.pi
                assert np.max(np.abs(gap)) <= np.max(np.abs(step)), (i, j)
                continue
            turns = (found.q[i, j] - end) / (2 * np.pi)        # whole turns apart, per axis
            if not np.allclose(turns, np.round(turns), atol=1e-9):
                stopped += 1
                assert found.reason[i, j] == "unreachable" and not alone.success[0], (i, j)
                alone_score = alone.position_error_m[0] + 0.1 * alone.rotation_error_rad[0]
                assert alone_score > np.min(score[i]) + 1e-5, (i, j)
                continue
            assert found.reason[i, j] == alone.reason[0], (i, j)
            assert np.isclose(found.position_error_m[i, j], alone.position_error_m[0],
                              rtol=1e-9, atol=1e-12)
    assert stopped >= 1                  # the out-of-reach targets' starts behind the best
    assert set_aside >= 1                # branches far outside the ranges


def test_targets_near_the_wrist_singularity_are_reached_as_asked(irb2400_world):
    """Targets the identified arm reaches inside its ranges 2 to 20 mrad from axis 5 = 0:
    the closed form and its Newton leave some unsolved; the solver's retries and the
    rule's search solve every one as asked: 'ok', the branch of the joints that made it
    (axes 4 and 6 may trade a quadrant there, and the calibrated arm can have two
    solutions of one branch a few mrad apart), reached to 1e-9 m and 1e-9 rad. Leaving
    out the solver's closed-form fixed point where the rule's search follows (tried for
    issue 32: over the public corpus it turned no target into a success) loses some."""
    from olp_compensate.compensation.ik import solve

    _, cal = irb2400_world
    comp = Compensator(cal)
    robot = comp.robot
    rng = np.random.default_rng(11)
    q_ctrl = random_joints(robot, 300, rng, margin=0.2)
    q_ctrl[:, 4] = rng.choice([-1.0, 1.0], 300) * rng.uniform(2e-3, 2e-2, 300)
    q = robot.joints_from_controller(q_ctrl)
    desired = comp.real_flange_and_jacobian(q)[0]
    confdata = comp.confdata(q)
    first = solve(comp.family, comp.real_flange_and_jacobian, desired, confdata, comp.limits,
                  retries=False)
    assert (~first.success).sum() >= 5                  # the retries and the rule have work
    joints, _, solution, _ = comp.compensate_flanges(desired, desired, confdata)
    assert set(solution.reason) <= {"ok", "singular"}, set(solution.reason)
    np.testing.assert_array_equal(comp.confdata(joints)[:, 3], confdata[:, 3])
    reached = comp.real_flange_and_jacobian(joints)[0]
    assert np.abs(reached[:, :3, 3] - desired[:, :3, 3]).max() <= 1e-9
    assert np.abs(reached[:, :3, :3] - desired[:, :3, :3]).max() <= 1e-9


def test_a_target_near_the_wrist_and_shoulder_singularities_is_reached_as_asked(
        irb2400_world):
    """Axis 5 at -0.94 deg and the wrist centre near axis 1 (found among 3,000 targets of the
    test above): the nominal start needs more Newton steps than the multi-start's first
    twelve, and the fixed point goes to another solution of the configuration (axis 1 at
    6 deg, axis 5 at -19 deg) that the quadrant check rejects. The solver's last
    multi-start from the nominal start, with the full budget, reaches the joints that made
    the target: 'ok', not 'branch_changed'."""
    _, cal = irb2400_world
    comp = Compensator(cal)
    robot = comp.robot
    q_ctrl = np.radians([[35.45, -76.79, 50.5, -9.39, -0.94, 79.97]])
    q = robot.joints_from_controller(q_ctrl)
    desired = comp.real_flange_and_jacobian(q)[0]
    joints, _, solution, _ = comp.compensate_flanges(desired, desired, comp.confdata(q))
    assert list(solution.reason) == ["ok"]
    np.testing.assert_allclose(robot.controller_from_joints(joints), q_ctrl, atol=1e-9)
