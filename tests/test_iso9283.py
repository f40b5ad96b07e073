"""ISO 9283 AP and RP on hand-computed data, the five poses of the cube, and the test
program (checked by parsing it back and by pinocchio's forward kinematics)."""

from __future__ import annotations

import argparse
import json
import math

import numpy as np
import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.calibration.iso9283 import (iso_positions, iso_results, plan_iso_test,
                                                pose_result, rapid_program, vplus_program)
from olp_compensate.calibration.simulate import VirtualRobot
from olp_compensate.cli import cal_iso9283
from olp_compensate.cli.common import run_guarded
from olp_compensate.errors import DataError, UnreachableTarget
from olp_compensate.kinematics.conventions import MM, matrix_from_euler_zyz
from olp_compensate.kinematics.robot import load_robot


def qx(deg):
    """Quaternion (w, x, y, z) of a rotation by ``deg`` about x."""
    h = math.radians(deg) / 2
    return [math.cos(h), math.sin(h), 0.0, 0.0]


def qz(deg):
    h = math.radians(deg) / 2
    return [math.cos(h), 0.0, 0.0, math.sin(h)]


def test_ap_and_rp_by_hand():
    # P1: commanded (10, 3, 4) mm; attained (11, 0, 0), (9, 0, 0), (10, 0, 0) mm
    # barycentre (10, 0, 0): AP_P = sqrt(0 + 9 + 16) = 5 mm
    # l = 1, 1, 0 mm: mean 2/3; S_l = sqrt(((1/3)^2 + (1/3)^2 + (2/3)^2) / 2) = sqrt(1/3)
    # RP_l = 2/3 + 3 sqrt(1/3) = 2/3 + sqrt(3) mm
    r = pose_result("P1", np.array([[11, 0, 0], [9, 0, 0], [10, 0, 0]]) * MM,
                    np.array([10, 3, 4]) * MM,
                    np.array([qx(11), qx(13), qx(12)]), np.array(qx(10)))
    assert r.n == 3
    assert r.ap_p_m == pytest.approx(5.0 * MM, rel=1e-12)
    assert np.allclose(r.ap_xyz_m, np.array([0, -3, -4]) * MM)
    assert r.rp_l_m == pytest.approx((2 / 3 + math.sqrt(3)) * MM, rel=1e-12)
    # a: 11, 13, 12 deg against 10: mean 12 - 10 = 2 deg; S_a = 1 deg: RP_a = 3 deg
    assert np.degrees(r.ap_abc_rad) == pytest.approx([2.0, 0.0, 0.0], abs=1e-9)
    assert np.degrees(r.rp_abc_rad) == pytest.approx([3.0, 0.0, 0.0], abs=1e-9)


def test_angles_across_the_half_turn_and_the_json():
    # c commanded 179 deg; attained -179, -178, 179, 180 deg: deviations 2, 3, 0, 1 deg
    # mean 1.5 deg; squares about it 0.25 + 2.25 + 2.25 + 0.25 = 5: S = sqrt(5/3)
    attained = np.array([[0, 0, 1], [0, 0, 3], [0, 0, 2], [0, 0, 2]]) * MM
    results = iso_results(["P2"] * 4, attained, np.zeros((4, 3)),
                          np.array([qz(-179), qz(-178), qz(179), qz(180)]),
                          np.array([qz(179)] * 4))
    (r,) = results
    # barycentre (0, 0, 2): AP_P = 2; l = 1, 1, 0, 0: mean 0.5, S_l = sqrt(1/3)
    assert r.ap_p_m == pytest.approx(2.0 * MM)
    assert r.rp_l_m == pytest.approx((0.5 + math.sqrt(3)) * MM)
    assert math.degrees(r.ap_abc_rad[2]) == pytest.approx(1.5, abs=1e-9)
    assert math.degrees(r.rp_abc_rad[2]) == pytest.approx(3 * math.sqrt(5 / 3), abs=1e-9)


def test_commanded_pose_must_not_change_between_cycles():
    with pytest.raises(DataError, match="commanded position differs"):
        iso_results(["P1", "P1"], np.zeros((2, 3)), np.array([[0, 0, 0], [0, 0, 0.001]]))
    with pytest.raises(DataError, match="at least 2"):
        pose_result("P3", np.zeros((1, 3)), np.zeros(3))


def test_the_five_poses_of_the_cube():
    p = iso_positions(np.array([1000.0, 0.0, 800.0]) * MM, 400 * MM) / MM
    # C1 = (800, -200, 600), C7 = (1200, 200, 1000): P2 = C1 + 0.1 (C7 - C1)
    assert np.allclose(p[0], [1000, 0, 800])
    assert np.allclose(p[1], [840, -160, 640])
    assert np.allclose(p[2], [1160, -160, 640])     # near C2 = (1200, -200, 600)
    assert np.allclose(p[3], [1160, 160, 960])      # near C7
    assert np.allclose(p[4], [840, 160, 960])       # near C8 = (800, 200, 1000)
    # 10 % of the diagonal's length sqrt(3) * 400 mm from its corner
    assert np.linalg.norm(p[1] - [800, -200, 600]) == pytest.approx(0.1 * math.sqrt(3) * 400)


def _truth(robot, tool_m):
    return VirtualRobot(robot=robot, origin_errors=np.zeros((6, 6)), joint_offsets=np.zeros(6),
                        device_T_base=np.eye(4), tools={"tcp": np.asarray(tool_m, float)})


def test_rapid_program_reaches_the_poses_in_the_standards_order():
    robot = load_robot("abb_irb2400")
    tool = np.array([0.0, 0.0, 0.15])
    plan = plan_iso_test(nominal_calibration(robot), np.array([0.95, 0.0, 0.8]), 0.4,
                         cycles=30, tool_m=tool)
    # pinocchio's forward kinematics of the solved joints puts the TCP on the poses
    reached = _truth(robot, tool).true_points(plan.joints, ["tcp"] * 5)
    assert np.allclose(reached, plan.positions_m, atol=1e-7)
    assert not robot.outside_ranges(plan.joints).any()
    text = rapid_program(plan)
    from olp_compensate import programs

    program = programs.loads(text, "rapid")
    targets = {t.name: t for t in program.targets if t.name}
    assert set(targets) >= {"P1", "P2", "P3", "P4", "P5"}
    moves = [line.split()[1].split(",")[0] for line in text.splitlines()
             if line.strip().startswith("MoveL")]
    assert moves == ["P1", "P5", "P4", "P3", "P2"]
    assert "FOR cycle FROM 1 TO 30 DO" in text
    # every pose is approached along the tool's z axis from the same side
    assert text.count("MoveJ RelTool(") == 5
    for name, conf in zip(("P1", "P2", "P3", "P4", "P5"), plan.config):
        assert f"[{','.join(str(int(c)) for c in conf)}]" in text.split(f"robtarget {name}:=")[1] \
            .split(";")[0]


def test_vplus_program_for_the_puma():
    robot = load_robot("unimation_puma560")
    plan = plan_iso_test(nominal_calibration(robot), np.array([0.45, 0.15, 0.1]), 0.2,
                         cycles=3, same_branch=True)
    text = vplus_program(plan)
    from olp_compensate import programs

    program = programs.loads(text, "vplus")
    assert {t.name for t in program.targets if t.name} >= {"p1", "p2", "p3", "p4", "p5"}
    location = [line for line in text.splitlines() if line.startswith("p4 ")][0].split()
    xyz = np.array([float(v) for v in location[1:4]])
    rotation = matrix_from_euler_zyz(*np.radians([float(v) for v in location[4:7]]))
    assert np.allclose(xyz, plan.positions_m[3] / MM, atol=1e-3)
    assert np.allclose(rotation, plan.rotation, atol=1e-4)
    assert [ln.split()[1] for ln in text.splitlines() if ln.strip().startswith("MOVES")] == \
        ["p1", "p5", "p4", "p3", "p2"]


def test_an_unreachable_cube_is_refused_naming_the_pose():
    robot = load_robot("abb_irb2400")
    with pytest.raises(UnreachableTarget, match=r"pose P1 at \(3000.0, 0.0, 800.0\) mm"):
        plan_iso_test(nominal_calibration(robot), np.array([3.0, 0.0, 0.8]), 0.2)


def _run(argv):
    parser = argparse.ArgumentParser()
    cal_iso9283.add_arguments(parser)
    args = parser.parse_args(argv)
    return run_guarded(lambda: cal_iso9283.run(args), 0, "olp-cal")


def test_cli_plan_and_report(tmp_path, capsys):
    out = tmp_path / "cycle.mod"
    assert _run(["plan", "--cube", "950,0,800,400", "--cycles", "5", "--robot",
                 "abb_irb2400", "-o", str(out)]) == 0
    assert "FOR cycle FROM 1 TO 5 DO" in out.read_text()
    assert _run(["plan", "--cube", "3000,0,800,200", "--robot", "abb_irb2400", "-o",
                 str(tmp_path / "far.pg")]) == 1
    err = capsys.readouterr().err
    assert "P1" in err and len(err.strip().splitlines()) == 1
    rows = ["pose,cycle,x_mm,y_mm,z_mm,xc_mm,yc_mm,zc_mm"]
    for cycle, x in enumerate((11, 9, 10), start=1):
        rows.append(f"P1,{cycle},{x},0,0,10,3,4")
    for cycle, z in enumerate((1, 3, 2, 2), start=1):
        rows.append(f"P2,{cycle},0,0,{z},0,0,0")
    (tmp_path / "meas.csv").write_text("\n".join(rows) + "\n")
    assert _run(["report", str(tmp_path / "meas.csv"), "--json", str(tmp_path / "iso.json"),
                 "--html", str(tmp_path / "iso.html"), "--load-kg", "12",
                 "--instrument", "laser tracker"]) == 0
    printed = capsys.readouterr().out
    assert "worst pose: AP_P 5.0000 mm at P1" in printed and "load 12 kg" in printed
    doc = json.loads((tmp_path / "iso.json").read_text())
    assert [p["pose"] for p in doc["poses"]] == ["P1", "P2"]
    assert doc["poses"][0]["AP_P_mm"] == pytest.approx(5.0)
    assert doc["poses"][1]["RP_l_mm"] == pytest.approx(0.5 + math.sqrt(3))
    assert "AP_a_deg" not in doc["poses"][0]
    assert doc["conditions"] == {"load_kg": 12.0, "instrument": "laser tracker"}
    assert "<img" in (tmp_path / "iso.html").read_text()
