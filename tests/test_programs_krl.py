"""KUKA KRL: .src + .dat read and written back losslessly; the whole loop on a virtual
KR 16-2 (identify, compensate, run the written targets through a nominal KUKA controller
of the test's own, reach within 0.05 mm where the untouched program misses by more)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.calibration.simulate import random_joints
from olp_compensate.compensation.dialect_program import compensate_pose_program
from olp_compensate.compensation.dialect_rules import ArmGeometry
from olp_compensate.programs.krl.rules import KRL, krl_status, krl_turn
from olp_compensate.compensation.ik import closed_form_inverse
from olp_compensate.kinematics.conventions import (euler_zyx_from_matrix, invert_pose,
                                                   matrix_from_euler_zyx)
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs.krl.reader import parse_krl, status_text, status_value
from olp_compensate.programs.targets import Number
from virtual_world import assert_the_gap_closed, identified_world, misses_mm, nominal_arm

ROBOT = load_robot("kuka_kr16_2")
TOOL_MM = np.array([12.0, -5.0, 180.0, 0.0, 0.0, 0.0])      # TOOL_DATA[1] in $config.dat

CONFIG_DAT = """DEFDAT  $CONFIG
;FOLD TOOL DATA
DECL FRAME TOOL_DATA[16]
TOOL_DATA[1]={X 12.0,Y -5.0,Z 180.0,A 0.0,B 0.0,C 0.0}
BASE_DATA[1]={X 1200.0,Y 300.0,Z 150.0,A 30.0,B 0.0,C 0.0}
;ENDFOLD
ENDDAT
"""


def _aggregate(values, s, t, binary=False):
    x, y, z, a, b, c = values
    st = f"S 'B{s:03b}',T 'B{t:06b}'" if binary else f"S {s},T {t}"
    return (f"{{X {x:.3f},Y {y:.3f},Z {z:.3f},A {a:.4f},B {b:.4f},C {c:.4f},{st},"
            f"E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}}")


def krl_module(targets, base_no=0):
    """(.src, .dat) texts: XP1..XPm moved to with PTP/LIN through inline-form folds."""
    dat = ["&ACCESS RVP", "&REL 1", "DEFDAT  CELL", ";FOLD EXTERNAL DECLARATIONS",
           ";ENDFOLD (EXTERNAL DECLARATIONS)",
           "DECL E6AXIS XHOME={A1 0.0,A2 -90.0,A3 90.0,A4 0.0,A5 0.0,A6 0.0,E1 0.0,E2 0.0,"
           "E3 0.0,E4 0.0,E5 0.0,E6 0.0}",
           "DECL FDAT FHOME={TOOL_NO 0,BASE_NO 0,IPO_FRAME #BASE,POINT2[] \" \"}"]
    src = ["&ACCESS RVP", "&REL 1", "DEF CELL( )", ";FOLD INI", ";ENDFOLD (INI)",
           ";FOLD PTP HOME  Vel= 100 % DEFAULT;%{PE}", "FDAT_ACT=FHOME",
           "BAS(#PTP_PARAMS,100)", "PTP XHOME", ";ENDFOLD"]
    for k, (values, s, t) in enumerate(targets, 1):
        dat.append(f"DECL E6POS XP{k}={_aggregate(values, s, t, binary=k % 3 == 0)}")
        dat.append(f"DECL FDAT FP{k}={{TOOL_NO 1,BASE_NO {base_no},IPO_FRAME #BASE,"
                   f"POINT2[] \" \"}}")
        move = "PTP" if k % 2 else "LIN"
        src += [f";FOLD {move} P{k} Vel=100 % PDAT{k} Tool[1] Base[{base_no}];%{{PE}}",
                "$BWDSTART=FALSE", f"FDAT_ACT=FP{k}",
                f"BAS(#{'PTP' if k % 2 else 'CP'}_PARAMS,100)", f"{move} XP{k} ", ";ENDFOLD"]
    dat.append("ENDDAT")
    src += ["PTP XHOME", "END"]
    return "\r\n".join(src) + "\r\n", "\r\n".join(dat) + "\r\n"


class KukaController:
    """The nominal KUKA controller of this test: the closed form fitted on pinocchio's
    forward kinematics of the data-sheet URDF; the branch whose status matches S, axes
    turned to T's signs."""

    def __init__(self):
        self.nominal, self.family = nominal_arm(ROBOT)
        self.geometry = ArmGeometry(ROBOT)

    def joints(self, base_T_flange, s, t):
        branches = ROBOT.controller_from_joints(closed_form_inverse(self.family,
                                                                    base_T_flange[None])[0])
        for q in branches:
            if np.all(np.isfinite(q)) and krl_status(self.geometry, q) == s:
                q = q.copy()
                for i in range(6):
                    if (q[i] < 0) != bool(t >> i & 1):
                        q[i] += -2 * math.pi if q[i] >= 0 else 2 * math.pi
                return q
        raise AssertionError(f"no branch with S={s}")


def _targets_at(q_ctrl, base=np.eye(4), tool_mm=TOOL_MM, controller=None):
    """(six numbers, S, T) of the nominal TCP (``tool_mm``, TOOL_DATA[1]'s X..C) at
    controller joints q."""
    controller = KukaController() if controller is None else controller
    tool = KRL.convention.pose(np.asarray(tool_mm, float))
    out = []
    for q in q_ctrl:
        pose = invert_pose(base) @ controller.nominal.flange_poses(q[None])[0] @ tool
        values = np.concatenate([pose[:3, 3] * 1e3,
                                 np.degrees(euler_zyx_from_matrix(pose[:3, :3]))])
        out.append((values, krl_status(controller.geometry, q), krl_turn(q)))
    return out


def _program_joints(m, seed):
    q = random_joints(ROBOT, 6 * m, np.random.default_rng(seed), margin=0.35)
    q = q[np.abs(np.sin(q[:, 4])) > math.sin(math.radians(20))]
    return q[:m]


def test_abc_convention_is_z_then_new_y_then_new_x():
    r = matrix_from_euler_zyx(*np.radians([90.0, 0.0, 0.0]))
    assert np.allclose(r @ [1, 0, 0], [0, 1, 0])              # A turns x towards y
    r = matrix_from_euler_zyx(*np.radians([0.0, 90.0, 0.0]))
    assert np.allclose(r @ [0, 0, 1], [1, 0, 0])              # B turns z towards x
    r = matrix_from_euler_zyx(*np.radians([90.0, 90.0, 0.0]))
    assert np.allclose(r @ [0, 0, 1], [0, 1, 0])              # B about the NEW y


def test_status_and_turn_read_and_written_in_every_form():
    for text, value in (("2", 2), ("'B010'", 2), ("'B110'", 6), ("'H1A'", 26), ("35", 35)):
        number = Number(0, len(text), text)
        assert status_value(number) == value
        assert status_text(number, value) == text
    assert status_text(Number(0, 6, "'B010'"), 6) == "'B110'"
    with pytest.raises(ValueError):
        status_value(Number(0, 4, "2.50"))


def test_kuka_status_of_the_home_pose():
    geometry = ArmGeometry(ROBOT)
    home = np.radians([0.0, -90.0, 90.0, 0.0, 30.0, 0.0])
    # KUKA: home is in the basic area, elbow up (bit 1), A5 positive: S = 'B010'
    assert krl_status(geometry, home) == 2
    assert krl_status(geometry, home * [1, 1, 1, 1, -1, 1]) == 6
    assert krl_turn(home) == 0b000010


def test_parse_reads_targets_frames_and_motions():
    src, dat = krl_module(_targets_at(_program_joints(3, 1)))
    program = parse_krl(src, dat, "CELL.src", "CELL.dat", CONFIG_DAT, "$config.dat")
    names = [t.name for t in program.targets]
    assert names == ["XHOME", "XP1", "XP2", "XP3"]
    assert program.targets[0].kind == "joints"
    assert program.frames["TOOL_DATA[1]"] == (12.0, -5.0, 180.0, 0.0, 0.0, 0.0)
    moves = [(m.instruction, m.target, m.tool, m.base) for m in program.motions]
    assert moves[0] == ("PTP", "XHOME", "TOOL_DATA[0]", "BASE_DATA[0]")
    assert moves[2] == ("LIN", "XP2", "TOOL_DATA[1]", "BASE_DATA[0]")
    # every number of XP2 points at its own text
    xp2 = program.targets[2]
    for number in xp2.numbers + xp2.config:
        assert dat[number.start:number.end] == number.text
    assert xp2.source[0] == "CELL.dat" and xp2.source[1] == dat[:xp2.numbers[0].start].count("\n") + 1


def test_nominal_calibration_gives_the_bytes_back():
    src, dat = krl_module(_targets_at(_program_joints(6, 2)))
    program = parse_krl(src, dat, "CELL.src", "CELL.dat", CONFIG_DAT, "$config.dat")
    texts, report = compensate_pose_program(program, KRL, nominal_calibration(ROBOT))
    assert texts["CELL.src"] == src and texts["CELL.dat"] == dat
    statuses = [r.status for r in report.rows]
    assert statuses.count("ok") + statuses.count("singular") == 6, report.rows
    assert statuses.count("joint_target") == 1


def test_runtime_unknown_and_unresolved_are_reported_never_dropped():
    src, dat = krl_module(_targets_at(_program_joints(2, 3)))
    src = src.replace("PTP XHOME\r\nEND", "LIN_REL {X 10.0}\r\nPTP $POS_ACT\r\nLIN XNOWHERE\r\n"
                      "PTP {X 500,Y 0,Z 900}\r\nEND")
    program = parse_krl(src, dat, "CELL.src", "CELL.dat")        # no $config.dat
    _, report = compensate_pose_program(program, KRL, nominal_calibration(ROBOT))
    by_status = {}
    for r in report.rows:
        by_status.setdefault(r.status, []).append(r)
    assert len(by_status["runtime"]) == 3          # LIN_REL, $POS_ACT, the partial aggregate
    assert [r.target for r in by_status["unresolved"]].count("XNOWHERE") == 1
    # tool TOOL_DATA[1] is defined nowhere given: every XPk says so
    unresolved_tools = [r for r in by_status["unresolved"] if r.target.startswith("XP")]
    assert len(unresolved_tools) == 2 and "TOOL_DATA[1] unknown" in unresolved_tools[0].note
    assert report.exit_code == 2


@pytest.fixture(scope="module")
def kuka_world():
    return identified_world(ROBOT, 5, "TOOL_DATA[1]")


def test_compensated_krl_reaches_its_targets_on_the_virtual_robot(kuka_world):
    virtual, cal = kuka_world
    q = _program_joints(10, 7)
    # the program's TOOL_DATA[1]: the data-sheet tool = the true tcp, rounded to 0.1 mm
    tool_mm = np.concatenate([np.round(virtual.tools["tcp"] * 1e4) / 10, [0.0, 0.0, 0.0]])
    config = CONFIG_DAT.replace("{X 12.0,Y -5.0,Z 180.0,",
                                "{X %.1f,Y %.1f,Z %.1f," % tuple(tool_mm[:3]))
    tool = KRL.convention.pose(tool_mm)
    controller = KukaController()
    written = _targets_at(q, tool_mm=tool_mm, controller=controller)
    src, dat = krl_module(written)
    program = parse_krl(src, dat, "CELL.src", "CELL.dat", config, "$config.dat")
    texts, report = compensate_pose_program(program, KRL, cal)
    assert report.exit_code == 0, [(r.target, r.status, r.note) for r in report.rows]
    again = parse_krl(texts["CELL.src"], texts["CELL.dat"], "CELL.src", "CELL.dat")
    new = {t.name: t for t in again.targets}
    meant, before, after = [], [], []
    for k, (values, s, t) in enumerate(written, 1):
        meant.append((cal.device_T_base @ KRL.convention.pose(values))[:3, 3])
        # the untouched program: the controller's joints for the written target
        before.append(controller.joints(KRL.convention.pose(values) @ invert_pose(tool), s, t))
        target = new[f"XP{k}"]
        after_values = np.array([n.value for n in target.numbers])
        after_s, after_t = (status_value(n) for n in target.config)
        after.append(controller.joints(KRL.convention.pose(after_values) @ invert_pose(tool),
                                       after_s, after_t))
    assert_the_gap_closed("KUKA KR 16-2", *misses_mm(virtual, meant, before, after))
    # only target numbers changed: the .src is untouched, the .dat differs in XPk lines only
    assert texts["CELL.src"] == src
    changed = [a for a, b in zip(texts["CELL.dat"].split("\r\n"), dat.split("\r\n")) if a != b]
    assert changed and all(line.startswith("DECL E6POS XP") for line in changed)


def test_taught_on_the_same_robot_gives_the_bytes_back(kuka_world):
    """Robot-to-robot transfer with A = B: the pose to reach is where A's real tool went at
    A's nominal joints for the target; B = A reaches it at the same joints, whose nominal
    forward kinematics is the written target."""
    _, cal = kuka_world
    q = _program_joints(5, 9)
    tool_mm = np.array([0.0, 0.0, 180.0, 0.0, 0.0, 0.0])
    config = CONFIG_DAT.replace("{X 12.0,Y -5.0,Z 180.0,", "{X 0.0,Y 0.0,Z 180.0,")
    written = _targets_at(q, tool_mm=tool_mm)
    src, dat = krl_module(written)
    program = parse_krl(src, dat, "CELL.src", "CELL.dat", config, "$config.dat")
    texts, report = compensate_pose_program(program, KRL, cal, taught_on=cal)
    assert report.exit_code == 0, [(r.target, r.status, r.note) for r in report.rows]
    assert texts["CELL.dat"] == dat and texts["CELL.src"] == src
    # and transferring to the nominal robot changes them (the real A is not the nominal)
    moved, _ = compensate_pose_program(program, KRL, nominal_calibration(ROBOT), taught_on=cal)
    assert moved["CELL.dat"] != dat


def test_inline_axis_aggregate_is_a_joint_target():
    """``PTP {A1 0, A2 -90, ...}`` (a home move written inline) is an axis target kept as
    written, not a Cartesian aggregate missing X..C."""
    src = "DEF m( )\nPTP {A1 0, A2 -90, A3 90, A4 0, A5 90, A6 0}\nEND\n"
    program = parse_krl(src, None, "m.src")
    (target,) = program.targets
    assert target.kind == "joints" and [n.text for n in target.numbers] == \
        ["0", "-90", "90", "0", "90", "0"]
    assert target.source == ("m.src", 2, 5)
    (motion,) = program.motions
    assert motion.inline == 0 and motion.runtime is None
    texts, report = compensate_pose_program(program, KRL, nominal_calibration(ROBOT))
    assert texts["m.src"] == src
    assert [(r.status, r.line, r.column) for r in report.rows] == [("joint_target", 2, 5)]


def test_array_declared_without_value_and_variable_index():
    dat = ("DEFDAT m\nDECL E6POS XPATH[2]\n"
           "XPATH[1]={X 985.6,Y 409.0,Z 949.3,A 150.0,B 3.9,C 147.8,S 2,T 43}\nENDDAT\n")
    src = "DEF m( )\nDECL INT I\nFOR I=1 TO 2\n  LIN XPATH[I]\nENDFOR\nEND\n"
    program = parse_krl(src, dat, "m.src", "m.dat")
    assert [t.name for t in program.targets] == ["XPATH[1]"]
    (motion,) = program.motions
    assert motion.target == "XPATH[I]" and "indexed at run time" in motion.runtime


@pytest.mark.parametrize("zero_axes_bits", [0, 0b101001])
def test_axes_taught_at_zero_keep_their_turn_bits(zero_axes_bits):
    """A target taught with A1, A4 and A6 at exactly 0 (as home-like targets are): read
    back from its rounded numbers the solver finds them a few microradians either side of
    0, which is no sign; the written T bits of those axes hold whichever way they are
    written (A2's bit, a real sign, is as taught)."""
    q = np.radians([[0.0, -80.0, 100.0, 0.0, 40.0, 0.0], [0.0, -60.0, 80.0, 0.0, 70.0, 0.0]])
    targets = [(values, s, t | zero_axes_bits) for values, s, t in _targets_at(q)]
    assert all(t == 0b10 | zero_axes_bits for _, _, t in targets)
    src, dat = krl_module(targets)
    program = parse_krl(src, dat, "CELL.src", "CELL.dat", CONFIG_DAT, "$config.dat")
    texts, report = compensate_pose_program(program, KRL, nominal_calibration(ROBOT))
    statuses = [r.status for r in report.rows if r.status != "joint_target"]
    assert statuses == ["ok", "ok"], [(r.status, r.note) for r in report.rows]
    assert texts["CELL.src"] == src and texts["CELL.dat"] == dat
