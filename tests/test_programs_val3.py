"""Stäubli VAL3: .dtx data files (both layouts) read and written back losslessly; the whole
loop on a virtual TX2-60 (identify, compensate, run the written points through a nominal
Stäubli controller of the test's own, reach within 0.05 mm where the untouched points miss
by more)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from olp_compensate.calibration.calibration import ToolPoint, nominal_calibration
from olp_compensate.calibration.simulate import random_joints
from olp_compensate.compensation.dialect_program import compensate_pose_program
from olp_compensate.compensation.dialect_rules import ArmGeometry
from olp_compensate.compensation.ik import closed_form_inverse
from olp_compensate.kinematics.conventions import (euler_xyz_from_matrix, invert_pose, rot_x, rot_y,
                                                   rot_z)
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs.val3.reader import parse_val3
from olp_compensate.programs.val3.rules import VAL3, val3_config
from virtual_world import assert_the_gap_closed, identified_world, misses_mm, nominal_arm

ROBOT = load_robot("staubli_tx2_60")
TOOL_MM = (0.0, 0.0, 120.0, 0.0, 0.0, 0.0)


def _attrs(values):
    return " ".join(f'{k}="{v:.3f}"' for k, v in zip(("x", "y", "z", "rx", "ry", "rz"), values))


def dtx_attributes(points, tool_mm=TOOL_MM, father="world[0]", frame=None):
    """A VAL3 s7-style data file (CR LF): values as attributes of <Value>."""
    lines = ['<?xml version="1.0" encoding="utf-8" ?>',
             '<Database xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" '
             'xmlns="http://www.staubli.com/robotics/VAL3/Data/2">', "  <Datas>",
             '    <!-- cell data, exported by SRS -->']
    if frame is not None:
        lines += ['    <Data name="fPart" access="public" xsi:type="array" type="frame" size="1">',
                  f'      <Value key="0" {_attrs(frame)} fatherId="world[0]" />', "    </Data>"]
    lines += ['    <Data name="jHome" access="public" xsi:type="array" type="jointRx" size="1">',
              '      <Value key="0" j3="90" j5="90" />', "    </Data>",
              '    <Data name="mNomSpeed" access="public" xsi:type="array" type="mdesc" size="1">',
              '      <Value key="0" accel="100" vel="100" decel="100" blend="off" />',
              "    </Data>",
              f'    <Data name="pPick" access="public" xsi:type="array" type="pointRx" '
              f'size="{len(points)}">']
    for k, (values, config) in enumerate(points):
        words = 'shoulder="%s" elbow="%s" wrist="%s"' % config
        lines.append(f'      <Value key="{k}" {_attrs(values)} {words} fatherId="{father}" />')
    lines += ["    </Data>",
              '    <Data name="tGripper" access="public" xsi:type="array" type="tool" size="1">',
              f'      <Value key="0" {_attrs(tool_mm)} fatherId="flange[0]" ioLink="valve1" />',
              "    </Data>", "  </Datas>", "</Database>"]
    return "\r\n".join(lines) + "\r\n"


def dtx_elements(points):
    """An older data file (CR LF): one <point> per target, values as child elements."""
    lines = ['<?xml version="1.0" encoding="utf-8" ?>', "<database>", "  <datas>"]
    for k, (values, config) in enumerate(points):
        lines += [f'    <point name="p{k + 1}" public="false" privilege="0" >',
                  '      <pFather alias="" name="world" fatherIndex="0" />',
                  '      <valuePoint index="0" >',
                  f"        <tpValue {_attrs(values)} />",
                  '        <cpValue shoulder="%s" elbow="%s" wrist="%s"/>' % config,
                  "      </valuePoint>", "    </point>"]
    lines += ['    <joint name="jPark" public="false" privilege="0" >',
              '      <valueJoint index="0" >',
              '        <jointValue j1="0.000" j2="0.000" j3="90.000" j4="0.000" j5="90.000" '
              'j6="0.000" />', "      </valueJoint>", "    </joint>", "  </datas>", "</database>"]
    return "\r\n".join(lines) + "\r\n"


class StaubliController:
    """The nominal Stäubli controller of this test: the closed form fitted on pinocchio's
    forward kinematics of the data-sheet URDF; the branch with the written configuration."""

    def __init__(self):
        self.nominal, self.family = nominal_arm(ROBOT)
        self.geometry = ArmGeometry(ROBOT)

    def joints(self, base_T_flange, config):
        branches = ROBOT.controller_from_joints(closed_form_inverse(self.family,
                                                                    base_T_flange[None])[0])
        for q in branches:
            if np.all(np.isfinite(q)) and val3_config(self.geometry, q) == tuple(config):
                return q
        raise AssertionError(f"no branch with {config}")


def _numbers(pose):
    return np.concatenate([pose[:3, 3] * 1e3, np.degrees(euler_xyz_from_matrix(pose[:3, :3]))])


def _points_at(q_ctrl, tool_mm=TOOL_MM, controller=None, base=np.eye(4)):
    controller = controller or StaubliController()
    tool = VAL3.convention.pose(np.array(tool_mm))
    return [(_numbers(invert_pose(base) @ controller.nominal.flange_poses(q[None])[0] @ tool),
             val3_config(controller.geometry, q)) for q in q_ctrl]


def _program_joints(m, seed):
    q = random_joints(ROBOT, 8 * m, np.random.default_rng(seed), margin=0.3)
    return q[np.abs(np.sin(q[:, 4])) > math.sin(math.radians(20))][:m]


def test_rx_ry_rz_turn_about_x_then_new_y_then_new_z():
    rot = VAL3.convention.rotation
    r = np.radians([20.0, 30.0, 40.0])
    assert np.allclose(rot(np.degrees(r)), rot_x(r[0]) @ rot_y(r[1]) @ rot_z(r[2]))
    # ry turns about the NEW y (after rx): Rx(90) Ry(90) takes z to x, and y to z
    assert np.allclose(rot(np.array([90.0, 90.0, 0.0])) @ [0, 0, 1], [1, 0, 0])
    assert np.allclose(rot(np.array([90.0, 90.0, 0.0])) @ [0, 1, 0], [0, 0, 1])
    rng = np.random.default_rng(0)
    for _ in range(20):
        angles = rng.uniform(-170, 170, 3) * [1, 0.5, 1]
        assert np.allclose(VAL3.convention.angles(rot(angles), angles + 1.0), angles, atol=1e-9)


def test_configuration_words_of_known_poses():
    geometry = ArmGeometry(ROBOT)
    reach_forward = np.radians([0.0, 30.0, 60.0, 0.0, 40.0, 0.0])
    assert val3_config(geometry, reach_forward) == ("lefty", "epositive", "wpositive")
    assert val3_config(geometry, reach_forward * [1, 1, -1, 1, -1, 1])[1:] == \
        ("enegative", "wnegative")
    # the other shoulder for (nearly) the same wrist point: J1 half a turn, leaning back
    reach_back = np.radians([180.0, -30.0, -60.0, 0.0, 40.0, 0.0])
    assert val3_config(geometry, reach_back)[0] == "righty"
    assert val3_config(geometry, np.radians([0.0, -30.0, -60.0, 0.0, 40.0, 0.0]))[0] == "righty"


@pytest.mark.parametrize("layout", ["attributes", "elements"])
def test_parse_reads_points_joints_and_spans(layout):
    points = _points_at(_program_joints(3, 1))
    text = dtx_attributes(points) if layout == "attributes" else dtx_elements(points)
    program = parse_val3({"cell.dtx": text})
    poses = [t for t in program.targets if t.kind == "pose"]
    joints = [t for t in program.targets if t.kind == "joints"]
    assert len(poses) == 3 and len(joints) == 1
    names = [t.name for t in poses]
    assert names == (["pPick[0]", "pPick[1]", "pPick[2]"] if layout == "attributes"
                     else ["p1[0]", "p2[0]", "p3[0]"])
    for target in poses:
        for number in target.numbers + target.config:
            assert text[number.start:number.end] == number.text
        assert target.frame[0] == "world[0]"
    assert [n.text for n in poses[1].config] == list(points[1][1])
    if layout == "attributes":
        assert program.frames["tGripper[0]"] == pytest.approx(TOOL_MM)
        assert all(m.tool == "tGripper[0]" for m in program.motions)
        assert any("tGripper[0]" in note for note in program.notes)
    else:
        assert all(m.tool is None for m in program.motions)
        assert any("flange" in note for note in program.notes)


@pytest.mark.parametrize("layout", ["attributes", "elements"])
def test_nominal_calibration_gives_the_bytes_back(layout):
    points = _points_at(_program_joints(8, 2), TOOL_MM if layout == "attributes" else (0,) * 6)
    text = dtx_attributes(points) if layout == "attributes" else dtx_elements(points)
    program = parse_val3({"cell.dtx": text})
    texts, report = compensate_pose_program(program, VAL3, nominal_calibration(ROBOT))
    assert texts["cell.dtx"] == text
    statuses = [r.status for r in report.rows]
    assert statuses.count("ok") + statuses.count("singular") == 8, report.rows
    assert statuses.count("joint_target") == 1


def test_frames_of_the_file_and_unknown_frames():
    frame = (400.0, -120.0, 30.0, 0.0, 0.0, 35.0)
    base = VAL3.convention.pose(np.array(frame))
    points = _points_at(_program_joints(3, 3), base=base)
    text = dtx_attributes(points, father="fPart[0]", frame=frame)
    texts, report = compensate_pose_program(parse_val3({"cell.dtx": text}), VAL3,
                                            nominal_calibration(ROBOT))
    assert texts["cell.dtx"] == text
    assert [r.status for r in report.rows].count("ok") == 3
    text = dtx_attributes(points, father="fTable[0]")
    _, report = compensate_pose_program(parse_val3({"cell.dtx": text}), VAL3,
                                        nominal_calibration(ROBOT))
    unresolved = [r for r in report.rows if r.status == "unresolved"]
    assert len(unresolved) == 3 and "fTable[0]" in unresolved[0].note


def test_a_value_left_out_is_inserted_as_an_attribute():
    points = _points_at(_program_joints(1, 4))
    text = dtx_attributes(points)
    ry = ' ry="%.3f"' % points[0][0][4]
    text = text.replace(ry, "", 1)                       # pPick[0] leaves ry out: ry = 0
    program = parse_val3({"cell.dtx": text})
    assert program.targets[1].numbers[4].value == 0 and "ry left out" in program.notes[0]
    # a real gripper 0.3 deg tilted and 0.4 mm off: every number of the point changes
    cal = nominal_calibration(ROBOT)
    tilt = np.array([math.cos(math.radians(0.15)), math.sin(math.radians(0.15)), 0.0, 0.0])
    tools = {"tGripper[0]": ToolPoint(xyz_m=np.array([0.0004, 0.0, 0.120]), quat_wxyz=tilt,
                                      for_programs=True)}
    cal = cal.__class__(**{**cal.__dict__, "tools": tools})
    texts, report = compensate_pose_program(program, VAL3, cal)
    assert next(r for r in report.rows if r.target == "pPick[0]").status in ("ok", "singular")
    new = texts["cell.dtx"]
    line = next(x for x in new.split("\r\n") if 'key="0" x=' in x and "shoulder" in x)
    assert ' ry="' in line and line.index(' ry="') > line.index("fatherId")  # inserted at the end
    again = next(t for t in parse_val3({"cell.dtx": new}).targets if t.name == "pPick[0]")
    assert abs(again.numbers[4].value) > 0.01
    assert [a for a, b in zip(new.split("\r\n"), text.split("\r\n")) if a != b] == [line]


@pytest.fixture(scope="module")
def staubli_world():
    return identified_world(ROBOT, 21, "tGripper[0]")


def test_compensated_val3_reaches_its_points_on_the_virtual_robot(staubli_world):
    virtual, cal = staubli_world
    q = _program_joints(10, 7)
    tool_mm = tuple(np.round(virtual.tools["tcp"] * 1e4) / 10) + (0.0, 0.0, 0.0)
    tool = VAL3.convention.pose(np.array(tool_mm))
    controller = StaubliController()
    written = _points_at(q, tool_mm, controller)
    text = dtx_attributes(written, tool_mm)
    texts, report = compensate_pose_program(parse_val3({"cell.dtx": text}), VAL3, cal)
    assert report.exit_code == 0, [(r.target, r.status, r.note) for r in report.rows]
    again = {t.name: t for t in parse_val3({"cell.dtx": texts["cell.dtx"]}).targets}
    meant, before, after = [], [], []
    for k, (values, config) in enumerate(written):
        values = np.round(values, 3)                                   # as written
        meant.append((cal.device_T_base @ VAL3.convention.pose(values))[:3, 3])
        before.append(controller.joints(VAL3.convention.pose(values) @ invert_pose(tool),
                                        config))
        target = again[f"pPick[{k}]"]
        new = np.array([n.value for n in target.numbers])
        after.append(controller.joints(VAL3.convention.pose(new) @ invert_pose(tool),
                                       [n.text for n in target.config]))
    assert_the_gap_closed("Staubli TX2-60", *misses_mm(virtual, meant, before, after))
    changed = [a for a, b in zip(texts["cell.dtx"].split("\r\n"), text.split("\r\n")) if a != b]
    assert changed and all(line.startswith('      <Value key="') for line in changed)
    assert sum(1 for line in changed if "pPick" in line) == 0        # only value lines
