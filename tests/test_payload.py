"""The load the arm carries: read from each dialect's program, overridden by --payload-kg,
and used with a calibration that holds joint compliance: a virtual IRB 6400 whose joints
yield under gravity, identified with payloads, runs a RAPID program with a 60 kg gun."""

from __future__ import annotations

import csv
import dataclasses

import numpy as np
import pytest

from olp_compensate.calibration.calibration import ToolPoint, nominal_calibration
from olp_compensate.calibration.effects import JointCompliance
from olp_compensate.calibration.identify import IdentificationOptions, identify
from olp_compensate.calibration.simulate import HiddenEffect, make_virtual_robot, random_joints
from olp_compensate.cli.fix import main as fix
from olp_compensate.compensation.ik import refine
from olp_compensate.compensation.pose import Compensator
from olp_compensate.io.calibration_file import write_calibration
from olp_compensate.kinematics.conventions import (invert_pose, matrix_from_quat_wxyz,
                                                   quat_wxyz_from_matrix)
from olp_compensate.kinematics.model import fixed_chain
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs import loads
from olp_compensate.programs.krl.payload import loads_with as krl_loads_with
from olp_compensate.programs.payloads import program_loads
from olp_compensate.programs.rapid.payload import loads_of as rapid_loads_of

ROBOT = load_robot("abb_irb6400")
GUN_KG = 60.0


# -- what each dialect states ------------------------------------------------------------

def test_urscript_set_payload_literal_and_runtime():
    text = ("def p():\n  set_payload(2.5, [0.01, 0.0, 0.1])\n  movel(p[.4,.1,.3,0,3.14,0])\n"
            "  set_payload(m_var)\n  set_target_payload(2.5, [0.01, 0, 0.1], [0,0,0,0,0,0])\nend\n")
    found = program_loads("urscript", {"p.script": text})
    assert len(found.loads) == 1                       # the same load twice is one load
    load = found.loads[0]
    assert load.kg == 2.5 and load.cog_mm == pytest.approx((10.0, 0.0, 100.0))
    assert load.source == "set_payload at p.script:2"
    assert found.runtime == ("p.script:4: set_payload(m_var)",)


def test_krl_load_literal_and_load_data_from_config():
    src = ("DEF cell()\n$LOAD={M 60.0,CM {X 0.0,Y 0.0,Z 250.0,A 0,B 0,C 0},J {X 1,Y 1,Z 1}}\n"
           "$LOAD=LOAD_DATA[2]\n$LOAD=my_load\nEND\n")
    config = "LOAD_DATA[2]={M 12.5,CM {X 10.0,Y -5.0,Z 80.0,A 0,B 0,C 0},J {X 0,Y 0,Z 0}}\n"
    found = krl_loads_with({"CELL.src": src}, config)
    assert [(x.kg, x.cog_mm) for x in found.loads] == [(60.0, (0.0, 0.0, 250.0)),
                                                         (12.5, (10.0, -5.0, 80.0))]
    assert found.runtime == ("CELL.src:4: $LOAD=my_load",)


def test_fanuc_payload_schedule_is_run_time():
    text = "/PROG CELL\n/MN\n   1:  PAYLOAD[2] ;\n   2:J P[1] 100% FINE ;\n/POS\n/END\n"
    found = program_loads("fanuc", {"CELL.ls": text})
    assert found.loads == () and found.runtime[0].startswith("CELL.ls:3: PAYLOAD[2]")


def rapid_module(targets, configs, gun_mm, cog_mm, kg=GUN_KG, extra=""):
    lines = ["MODULE Cell", "  ! olp-robot: abb_irb6400",
             f"  PERS tooldata gun := [TRUE,[[{gun_mm[0]:.3f},{gun_mm[1]:.3f},{gun_mm[2]:.3f}],"
             f"[1,0,0,0]],[{kg:g},[{cog_mm[0]:.3f},{cog_mm[1]:.3f},{cog_mm[2]:.3f}],[1,0,0,0],"
             f"0,0,0]];",
             "  PERS tooldata grip := [TRUE,[[0,0,150],[1,0,0,0]],[5,[0,0,60],[1,0,0,0],0,0,0]];"]
    for k, (pose, conf) in enumerate(zip(targets, configs), 1):
        q = quat_wxyz_from_matrix(pose[:3, :3])
        xyz = pose[:3, 3] * 1e3
        lines.append(f"  CONST robtarget p{k} := [[{xyz[0]:.3f},{xyz[1]:.3f},{xyz[2]:.3f}],"
                     f"[{q[0]:.8f},{q[1]:.8f},{q[2]:.8f},{q[3]:.8f}],"
                     f"[{conf[0]},{conf[1]},{conf[2]},{conf[3]}],[9E9,9E9,9E9,9E9,9E9,9E9]];")
    lines += ["  PROC main()"]
    lines += [f"    MoveL p{k}, v100, fine, gun;" for k in range(1, len(targets) + 1)]
    lines += [extra, "  ENDPROC", "ENDMODULE"]
    return "\n".join(lines) + "\n"


def test_rapid_loads_of_the_tools_moved_with_and_gripload():
    text = rapid_module([np.eye(4)], [(0, 0, 0, 0)], (0, 0, 300), (0, 0, 250),
                        extra="    GripLoad piece;")
    program = loads(text, "rapid", "cell.mod")
    found = program_loads("rapid", {"cell.mod": text})
    assert found == rapid_loads_of([program])
    assert [(x.kg, x.cog_mm, x.source) for x in found.loads] == [
        (60.0, (0.0, 0.0, 250.0), "tooldata gun")]      # grip is declared, never moved with
    assert found.runtime == ("cell.mod:8: GripLoad piece",)


# -- a compliant arm under a 60 kg gun ----------------------------------------------------

COMPLIANCE = {1: 4e-7, 2: 6e-7, 4: 2e-6}     # rad/N.m on axes 2, 3, 5 (0-based keys)


@pytest.fixture(scope="module")
def compliant_world(tmp_path_factory):
    """(virtual arm with compliance, calib.json identified with payloads, folder)."""
    folder = tmp_path_factory.mktemp("payload")
    virtual = make_virtual_robot(ROBOT, 61)
    virtual = dataclasses.replace(virtual, effects=tuple(
        HiddenEffect("joint_compliance", j, c) for j, c in COMPLIANCE.items()))
    rng = np.random.default_rng(61)
    q = random_joints(ROBOT, 90, rng)
    payload = rng.choice([0.0, 30.0, 60.0], len(q))
    meas = virtual.measure(q, 0.01e-3, rng, payload_kg=payload)
    options = IdentificationOptions(folds=0, effects=tuple(JointCompliance(joint=j)
                                                           for j in COMPLIANCE))
    cal = identify(ROBOT, meas, options).calibration
    tools = dict(cal.tools)
    tools["gun"] = ToolPoint(xyz_m=cal.tools["tcp"].xyz_m, for_programs=True)   # olp-cal tool
    cal = dataclasses.replace(cal, tools=tools)
    write_calibration(folder / "cal.json", cal)
    return virtual, cal, folder


def _program(virtual, cal, seed):
    rng = np.random.default_rng(seed)
    q = random_joints(ROBOT, 8, rng, margin=0.3)
    nominal = Compensator(nominal_calibration(ROBOT))
    tool = np.eye(4)
    tool[:3, 3] = virtual.tools["tcp"]
    flanges = nominal.nominal_flange(ROBOT.joints_from_controller(q))
    configs = nominal.confdata(ROBOT.joints_from_controller(q))
    tcp_mm = virtual.tools["tcp"] * 1e3
    return rapid_module(flanges @ tool, configs, tcp_mm, tcp_mm), tool


def _reached(virtual, out_text, report_path, tool, kg):
    """Where the true TCP goes, device frame, for each written target: the data-sheet
    controller takes the joints nearest the report's, the real arm carries ``kg``."""
    program = loads(out_text, "rapid", "out.mod")
    nominal = fixed_chain(*(lambda c: (c.model, c.values))(nominal_calibration(ROBOT)))
    rows = [r for r in csv.DictReader(open(report_path)) if r["status"] in ("ok", "singular")]
    by_name = {t.name: t for t in program.targets}
    out = []
    for row in rows:
        t = by_name[row["target"]]
        pose = np.eye(4)
        pose[:3, 3] = np.array([n.value for n in t.position]) * 1e-3
        pose[:3, :3] = matrix_from_quat_wxyz(np.array([n.value for n in t.orientation]))
        start = ROBOT.joints_from_controller(
            np.radians([[float(row[f"q{k + 1}_deg"]) for k in range(6)]]))
        solution = refine(nominal.flange_and_jacobian, start, (pose @ invert_pose(tool))[None],
                          None, 1e-12, 1e-12, 50)
        assert solution.success[0]
        q_ctrl = ROBOT.controller_from_joints(solution.q)
        out.append(virtual.true_frames(q_ctrl, ["tcp"], payload_kg=[kg])[0, :3, 3])
    return np.array(out), rows


def test_rapid_program_with_a_60_kg_gun_is_compensated_under_its_load(compliant_world, tmp_path,
                                                                      capsys):
    virtual, cal, folder = compliant_world
    text, tool = _program(virtual, cal, 62)
    (tmp_path / "cell.mod").write_text(text)
    program = loads(text, "rapid", "cell.mod")
    meant = np.array([(cal.device_T_base @ pose_of(t))[:3, 3] for t in program.targets])
    misses = {}
    for label, extra in (("under", []), ("without", ["--payload-kg", "0"])):
        out, report = tmp_path / f"{label}.mod", tmp_path / f"{label}.csv"
        code = fix([str(tmp_path / "cell.mod"), "--model", str(folder / "cal.json"), "-o",
                    str(out), "--report", str(report), *extra])
        assert code == 0, capsys.readouterr()
        reached, rows = _reached(virtual, out.read_text(), report, tool, GUN_KG)
        misses[label] = np.linalg.norm(reached - meant, axis=1) * 1e3
        words = ("load 60 kg" if label == "under" else "load 0 kg")
        assert all(words in r["note"] for r in rows), rows[0]["note"]
    print(f"60 kg gun: compensated under the load, max miss {misses['under'].max():.4f} mm; "
          f"compensated without it {misses['without'].min():.3f}..{misses['without'].max():.3f} mm")
    assert misses["under"].max() < 0.05, misses
    assert misses["without"].max() > 0.2


def pose_of(target):
    pose = np.eye(4)
    pose[:3, 3] = np.array([n.value for n in target.position]) * 1e-3
    pose[:3, :3] = matrix_from_quat_wxyz(np.array([n.value for n in target.orientation]))
    return pose


def test_several_loads_are_refused_and_the_override_decides(compliant_world, tmp_path, capsys):
    virtual, cal, folder = compliant_world
    text, _ = _program(virtual, cal, 63)
    text = text.replace("MoveL p2, v100, fine, gun;", "MoveL p2, v100, fine, grip;")
    (tmp_path / "cell.mod").write_text(text)
    assert fix([str(tmp_path / "cell.mod"), "--model", str(folder / "cal.json"), "-o",
                str(tmp_path / "o.mod")]) == 1
    err = capsys.readouterr().err
    assert "several loads" in err and "--payload-kg" in err and "Traceback" not in err
    assert fix([str(tmp_path / "cell.mod"), "--model", str(folder / "cal.json"), "-o",
                str(tmp_path / "o.mod"), "--payload-kg", "60", "--payload-cog-mm", "0,0,250"]) == 0
    assert fix([str(tmp_path / "cell.mod"), "--model", str(folder / "cal.json"), "-o",
                str(tmp_path / "p.mod"), "--payload-cog-mm", "0,0"]) == 1
    assert "--payload-cog-mm" in capsys.readouterr().err


def test_a_load_changed_at_run_time_is_stated(compliant_world, tmp_path, capsys):
    virtual, cal, folder = compliant_world
    text, _ = _program(virtual, cal, 64)
    text = text.replace("  ENDPROC", "    GripLoad piece;\n  ENDPROC")
    (tmp_path / "cell.mod").write_text(text)
    assert fix([str(tmp_path / "cell.mod"), "--model", str(folder / "cal.json"), "-o",
                str(tmp_path / "o.mod")]) == 0
    out = capsys.readouterr().out
    assert "GripLoad piece: the load changes here at run time" in out


def test_urscript_set_payload_feeds_the_compliance_of_a_ur(tmp_path):
    """A UR10e whose axes 2 and 3 yield (the calibration is the truth here), a URScript with
    set_payload(8, [0, 0, 0.1]): the real TCP reaches the targets under that load."""
    import test_controller_model as t
    from olp_compensate.calibration.effects import Conditions

    arm = t.real_arm(81)
    effects = tuple(JointCompliance(joint=j).with_values(np.array([c]), np.array([0.0]))
                    for j, c in ((1, 2e-5), (2, 3e-5)))
    arm = dataclasses.replace(arm, effects=effects)
    write_calibration(tmp_path / "real.json", arm)
    tool = np.eye(4)
    tool[:3, 3] = t.TCP[:3]
    meant = t.NOMINAL.flange(t._path(81, 6)) @ tool
    text = t.ur_program(meant).replace("  movej(", "  set_payload(8, [0, 0, 0.1])\n  movej(", 1)
    (tmp_path / "cell.script").write_text(text)
    misses = {}
    for label, extra in (("under", []), ("without", ["--payload-kg", "0"])):
        out, report = tmp_path / f"{label}.script", tmp_path / f"{label}.csv"
        assert fix([str(tmp_path / "cell.script"), "--model", str(tmp_path / "real.json"),
                    "-o", str(out), "--report", str(report), "-q", *extra]) == 0
        rows = [r for r in csv.DictReader(open(report)) if r["status"] in ("ok", "singular")]
        if label == "under":
            assert all("load 8 kg at [0, 0, 100] mm (set_payload at" in r["note"] for r in rows)
        written = [x for x in t.parse_urscript(out.read_text(), "o").targets if x.kind == "pose"]
        chain = t.NOMINAL.chain()                   # the data-sheet controller
        reached = []
        for target, row in zip(written, rows):
            values = np.array([n.value for n in target.numbers])
            pose = np.eye(4)
            pose[:3, :3], pose[:3, 3] = t.rotation_from_rotvec(values[3:]), values[:3]
            start = np.radians([[float(row[f"q{k + 1}_deg"]) for k in range(6)]])
            solution = refine(chain.flange_and_jacobian, start,
                              (pose @ invert_pose(tool))[None], None, 1e-12, 1e-12, 50)
            loaded = Conditions(payload_kg=np.array([8.0]),
                                payload_point_m=np.array([[0.0, 0.0, 0.1]]))
            reached.append(arm.flange_poses(solution.q, loaded)[0] @ tool)
        misses[label] = np.linalg.norm(np.array(reached)[:, :3, 3] - meant[:, :3, 3], axis=1) * 1e3
    assert misses["under"].max() < 0.05, misses
    assert misses["without"].max() > 0.1, misses


def test_rapid_task_tool_declared_in_another_module():
    data = ("MODULE CalibData\n  PERS tooldata gun := [TRUE,[[0,0,300],[1,0,0,0]],"
            "[60,[0,0,250],[1,0,0,0],0,0,0]];\nENDMODULE\n")
    main = ("MODULE Main\n  CONST robtarget p1 := [[1000,0,1000],[0,0,1,0],[0,0,0,0],"
            "[9E9,9E9,9E9,9E9,9E9,9E9]];\n  PROC main()\n    MoveL p1, v100, fine, gun;\n"
            "  ENDPROC\nENDMODULE\n")
    programs = [loads(data, "rapid", "CalibData.mod"), loads(main, "rapid", "Main.mod")]
    found = rapid_loads_of(programs)
    assert [(x.kg, x.source) for x in found.loads] == [(60.0, "tooldata gun")]
