"""``olp-cal tool`` end to end: marks files, the RAPID tooldata rewrite, the wizard on stdin.

The robot is the calibrated model of a virtual robot (``simulate`` without noise, then
``identify``): it reproduces the virtual robot's measured points exactly, but its base and
flange frames are its own (axis 1's zero and height and axis 6's zero are not observable),
so the changed tool's truth is stated in the model's flange frame, as the tool command
reports it. Touch joints come from numerical inverse kinematics on that model.
"""

from __future__ import annotations

import io
import json
import sys
import time

import numpy as np
import pytest
from scipy.optimize import least_squares

from olp_compensate import programs
from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.cli.cal import main
from olp_compensate.kinematics.conventions import MM, rotation_from_rotvec
from olp_compensate.io.calibration_file import read_calibration
from olp_compensate.programs.targets import Edit
from olp_compensate.kinematics.robot import load_robot

ROBOT = "abb_irb2400"
TOOL_M = np.array([12.345, -45.678, 234.567]) * MM  # the changed tool, model flange frame
Q_HOME = np.radians([5.0, 10.0, 15.0, 0.0, 50.0, 0.0])
MARKS_M = np.array([[1.10, -0.25, 0.40], [1.25, 0.10, 0.40], [1.05, 0.30, 0.42],
                    [1.30, -0.05, 0.38], [0.95, 0.05, 0.45], [1.15, 0.20, 0.40]])
TILTS_DEG = [(0, 0, 0), (35, 0, 0), (-35, 0, 0), (0, 35, 0), (0, -35, 0), (20, 20, 40)]
FIXED_TILTS_DEG = [(0, 0, 0), (60, 0, 0), (-60, 0, 0), (0, 60, 0), (0, -60, 0), (40, 40, 120)]
POINT_M = np.array([1.1, 0.1, 0.4])

PROGRAM = (
    "MODULE CellA\r\n"
    "  ! spot gun, drawing rev. C \xd8 12 \xb0\r\n"
    "  PERS tooldata tGun:=[TRUE,[[10.5,-40,230.25],[0.7071068,0,0.7071068,0]],"
    "[2.5,[0,0,120.5],[1,0,0,0],0.01,0.02,0.03]];\r\n"
    "  PERS tooldata tOther := [TRUE,[[0,0,100],[1,0,0,0]],[1,[0,0,50],[1,0,0,0],0,0,0]];\r\n"
    "  CONST robtarget p10 := [[900,0,800],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\r\n"
    "  PROC main()\r\n"
    "    MoveL p10, v100, fine, tGun;  ! uses the gun\r\n"
    "  ENDPROC\r\n"
    "ENDMODULE\r\n").encode("latin-1")


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    """calib.json of a virtual robot (noise-free identification) and its kinematics."""
    folder = tmp_path_factory.mktemp("tool")
    meas, calib = folder / "meas.csv", folder / "calib.json"
    assert main(["simulate", "--robot", ROBOT, "--poses", "40", "--noise-mm", "0",
                 "--seed", "21", "-o", str(meas)]) == 0
    assert main(["identify", str(meas), "--robot", ROBOT, "--folds", "0", "-o",
                 str(calib)]) == 0
    return calib, read_calibration(calib).flange_poses


def touches(flange_pose, points_m, tilts_deg):
    """Joints (m, 6) rad putting the changed tool's tip on each point with the flange turned
    by each tilt (rotation vector about base axes, deg) from its home orientation."""
    home = flange_pose(Q_HOME[None])[0, :3, :3]
    out = []
    for point, tilt in zip(points_m, tilts_deg):
        target = rotation_from_rotvec(np.radians(tilt)) @ home

        def error(q):
            pose = flange_pose(q[None])[0]
            return np.concatenate([pose[:3, :3] @ TOOL_M + pose[:3, 3] - point,
                                   0.5 * (pose[:3, :3] - target).ravel()])
        sol = least_squares(error, Q_HOME, xtol=1e-15, ftol=1e-15, gtol=1e-15)
        assert np.max(np.abs(sol.fun)) < 1e-9
        out.append(sol.x)
    return np.array(out)


def write_marks(path, joints, marks_m=None, frame=None, tool=None):
    """A marks CSV as a technician would fill it (deg, mm; empty coordinates: fixed point)."""
    lines = [f"# tool: {tool}"] if tool else []
    lines.append("mark," + ",".join(f"q{k + 1}_deg" for k in range(joints.shape[1]))
                 + ",x_mm,y_mm,z_mm" + (",frame" if frame else ""))
    for k, q in enumerate(joints):
        xyz = ",," if marks_m is None else ",".join(f"{v / MM:.4f}" for v in marks_m[k])
        lines.append(f"M{k + 1}," + ",".join(f"{v:.6f}" for v in np.degrees(q)) + "," + xyz
                     + (f",{frame}" if frame else ""))
    path.write_text("\n".join(lines) + "\n")
    return path


def tool_xyz_mm(calib_path, name):
    return np.array(json.loads(calib_path.read_text())["tools"][name]["xyz_mm"])


def one_line_error(capsys, *words):
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, err
    return err


def test_known_marks_recover_the_tcp_and_rewrite_the_tooldata(model, tmp_path, capsys):
    calib, fk = model
    rng = np.random.default_rng(0)
    joints = touches(fk, MARKS_M, TILTS_DEG)
    known = MARKS_M + rng.normal(0.0, 0.05 * MM, MARKS_M.shape)  # marks known to 0.05 mm
    marks = write_marks(tmp_path / "marks.csv", joints, known)
    prog = tmp_path / "cell_a.mod"
    prog.write_bytes(PROGRAM)
    out = tmp_path / "calib_new.json"
    assert main(["tool", "--robot", ROBOT, "--model", str(calib), "--name", "tGun",
                 "--marks", str(marks), "-o", str(out), "--update-program", str(prog)]) == 0
    text = capsys.readouterr().out
    xyz = tool_xyz_mm(out, "tGun")
    assert np.linalg.norm(xyz - TOOL_M / MM) < 0.1
    for words in ("known marks", "M6", "residual per touch", "+/-", "condition number",
                  "RAPID: PERS tooldata tGun := [TRUE,[[", "[2.5,[0,0,120.5],[1,0,0,0],0.01,"
                  "0.02,0.03]];", f"wrote {out}", "cell_a_tGun.mod"):
        assert words in text, words
    cal = read_calibration(out)
    assert cal.tools["tGun"].quat_wxyz is None  # touches cannot see the orientation
    assert np.all(cal.tools["tGun"].std_m < 0.1 * MM)
    assert "tcp" in cal.tools  # the model's other tools are kept
    # the new tool is one for programs; the identification's measured point stays not one
    assert cal.tools["tGun"].for_programs and not cal.tools["tcp"].for_programs

    written = tmp_path / "cell_a_tGun.mod"
    assert prog.read_bytes() == PROGRAM  # the input is never touched
    before, after = programs.loads(PROGRAM, "rapid"), programs.load(written)
    old = next(t for t in before.tools if t.name == "tGun")
    new = next(t for t in after.tools if t.name == "tGun")
    assert np.allclose([n.value for n in new.position], xyz, atol=0.0005)
    assert [n.value for n in new.orientation] == [n.value for n in old.orientation]
    # every other byte is unchanged: the new text is the old one with only the 3 numbers spliced
    expected = programs.splice(before.text, [Edit(o.start, o.end, n.text)
                                             for o, n in zip(old.position, new.position)])
    assert after.text == expected and written.read_bytes() == expected.encode("latin-1")
    other = [t for t in after.tools if t.name == "tOther"][0]
    assert [n.text for n in other.position] == ["0", "0", "100"]


def test_default_outputs_go_beside_the_inputs_never_over_them(model, tmp_path, capsys):
    calib, fk = model
    joints = touches(fk, MARKS_M[:4], TILTS_DEG[:4])
    local = tmp_path / "calib.json"
    local.write_bytes(calib.read_bytes())
    marks = write_marks(tmp_path / "touches.csv", joints, MARKS_M[:4], tool="tGun")
    prog = tmp_path / "cell_a.mod"
    prog.write_bytes(PROGRAM)
    assert main(["tool", "--model", str(local), "--marks", str(marks),
                 "--update-program", str(prog)]) == 0
    assert np.linalg.norm(tool_xyz_mm(tmp_path / "calib_tGun.json", "tGun") - TOOL_M / MM) < 1e-3
    assert (tmp_path / "cell_a_tGun.mod").exists() and local.read_bytes() == calib.read_bytes()
    capsys.readouterr()
    for args in (["-o", str(local)], ["-o", str(marks)], ["--program-out", str(prog)]):
        assert main(["tool", "--model", str(local), "--marks", str(marks),
                     "--update-program", str(prog)] + args) == 1
        one_line_error(capsys, "is an input", "choose another output file")
    assert local.read_bytes() == calib.read_bytes() and prog.read_bytes() == PROGRAM


def test_fixed_point_recovers_the_tcp(model, tmp_path, capsys):
    calib, fk = model
    rng = np.random.default_rng(1)
    touched = POINT_M + rng.normal(0.0, 0.05 * MM, (6, 3))  # where the tip really landed
    marks = write_marks(tmp_path / "pin.csv", touches(fk, touched, FIXED_TILTS_DEG))
    out = tmp_path / "out.json"
    assert main(["tool", "--robot", ROBOT, "--model", str(calib), "--name", "tPin",
                 "--marks", str(marks), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert np.linalg.norm(tool_xyz_mm(out, "tPin") - TOOL_M / MM) < 0.1
    assert "fixed point" in text and "fixed point in the base frame" in text
    assert "placeholder" in text  # no program, no --mass-kg: the load data is a placeholder


def test_nominal_kinematics_without_model(tmp_path, capsys):
    fk = nominal_calibration(load_robot(ROBOT)).flange_poses
    joints = touches(fk, MARKS_M, TILTS_DEG)
    marks = write_marks(tmp_path / "m.csv", joints, MARKS_M)
    assert main(["tool", "--robot", ROBOT, "--name", "tGun", "--marks", str(marks),
                 "--mass-kg", "3.5"]) == 0
    text = capsys.readouterr().out
    assert "nominal abb_irb2400" in text and "not saved" in text and "[3.5,[0,0,0]" in text
    assert not list(tmp_path.glob("*.json"))
    out = tmp_path / "nominal_tGun.json"
    assert main(["tool", "--robot", ROBOT, "--name", "tGun", "--marks", str(marks),
                 "-o", str(out)]) == 0
    cal = read_calibration(out)
    assert np.array_equal(cal.values, cal.model.nominal)
    assert np.linalg.norm(cal.tools["tGun"].xyz_m - TOOL_M) < 1e-6


def test_world_frame_marks(model, tmp_path, capsys):
    calib, fk = model
    joints = touches(fk, MARKS_M, TILTS_DEG)
    world_T_base = np.eye(4)
    world_T_base[:3, :3] = rotation_from_rotvec([0.02, -0.03, 1.2])
    world_T_base[:3, 3] = [2.0, -1.0, 0.1]
    world = MARKS_M @ world_T_base[:3, :3].T + world_T_base[:3, 3]
    marks = write_marks(tmp_path / "w.csv", joints, world)
    out = tmp_path / "w.json"
    assert main(["tool", "--model", str(calib), "--name", "tGun", "--marks", str(marks),
                 "--frame", "world", "-o", str(out)]) == 0
    assert "world_T_base" in capsys.readouterr().out
    assert np.linalg.norm(tool_xyz_mm(out, "tGun") - TOOL_M / MM) < 1e-3
    conflicting = write_marks(tmp_path / "c.csv", joints, world, frame="base")
    assert main(["tool", "--model", str(calib), "--name", "tGun", "--marks",
                 str(conflicting), "--frame", "world"]) == 1
    one_line_error(capsys, "c.csv:2: column 'frame' says 'base'")


def test_nearly_identical_orientations_are_refused(model, tmp_path, capsys):
    calib, fk = model
    rng = np.random.default_rng(3)
    tilts = [(0, 0, 0), (0.5, 0, 0), (0, 0.5, 0), (0.3, 0.3, 0.2)]
    joints = touches(fk, POINT_M + rng.normal(0, 0.05 * MM, (4, 3)), tilts)
    marks = write_marks(tmp_path / "alike.csv", joints)
    out = tmp_path / "never.json"
    assert main(["tool", "--model", str(calib), "--name", "tPin", "--marks", str(marks),
                 "-o", str(out)]) == 1
    one_line_error(capsys, "cannot determine the tool",
                   "rotate the tool by at least 30 degrees about two different axes")
    assert not out.exists()


def test_bad_input_gives_one_line_and_exit_1(model, tmp_path, capsys):
    calib, fk = model
    joints = touches(fk, MARKS_M[:3], TILTS_DEG[:3])
    good = write_marks(tmp_path / "good.csv", joints, MARKS_M[:3])
    cases = [
        (["--robot", ROBOT, "--name", "t", "--marks", str(tmp_path / "missing.csv")],
         "missing.csv: cannot read"),
        (["--robot", "kuka_nonexistent", "--name", "t", "--marks", str(good)],
         "unknown robot 'kuka_nonexistent'"),
        (["--model", str(calib), "--name", "tGun", "--marks", str(good), "--update-program",
          str(tmp_path / "cell_a.mod")], "declares no tooldata named tGun"),
        (["--model", str(calib), "--name", "1bad", "--marks", str(good)], "tool name '1bad'"),
        (["--model", str(calib), "--name", "t", "--marks", str(good), "--ur", "127.0.0.1"],
         "--ur is for the wizard"),
    ]
    (tmp_path / "cell_a.mod").write_bytes(PROGRAM.replace(b"tGun", b"tGrip"))
    lines = good.read_text().splitlines()
    nan = tmp_path / "nan.csv"
    nan.write_text("\n".join(lines[:2] + [lines[2].replace(lines[2].split(",")[3], "nan", 1)]
                             + lines[3:]) + "\n")
    cases.append((["--model", str(calib), "--name", "t", "--marks", str(nan)],
                  "nan.csv:3: column 'q3_deg': nan is not a finite number"))
    for args, message in cases:
        assert main(["tool"] + args) == 1, args
        one_line_error(capsys, message)


def _stdin(monkeypatch, answers):
    monkeypatch.setattr(sys, "stdin", io.StringIO("".join(a + "\n" for a in answers)))


def deg_text(q_rad) -> str:
    return " ".join(f"{v:.6f}" for v in np.degrees(q_rad))


def test_wizard_on_stdin_writes_the_tool_and_its_touches(model, tmp_path, capsys,
                                                         monkeypatch):
    calib, fk = model
    rng = np.random.default_rng(5)
    joints = touches(fk, MARKS_M, TILTS_DEG)
    known_mm = (MARKS_M + rng.normal(0, 0.05 * MM, MARKS_M.shape)) / MM
    answers = ["1", "b"]
    for k in range(6):
        answers += [" ".join(f"{v:.4f}" for v in known_mm[k]), deg_text(joints[k])]
    answers += ["done", "y"]
    _stdin(monkeypatch, answers)
    out = tmp_path / "calib_gun.json"
    prog = tmp_path / "cell_a.mod"
    prog.write_bytes(PROGRAM)
    assert main(["tool", "--model", str(calib), "--name", "tGun", "-o", str(out),
                 "--update-program", str(prog)]) == 0
    text = capsys.readouterr().out
    assert "Tool: tGun" in text and "Fit with 3 touches" in text and "Written" in text
    assert "RAPID: PERS tooldata tGun := [TRUE,[[" in text
    xyz = tool_xyz_mm(out, "tGun")
    assert np.linalg.norm(xyz - TOOL_M / MM) < 0.1
    assert (tmp_path / "cell_a_tGun.mod").exists()
    touches_file = tmp_path / "calib_gun_marks.csv"
    # the saved touches give the same tool through --marks
    again = tmp_path / "again.json"
    assert main(["tool", "--model", str(calib), "--marks", str(touches_file),
                 "-o", str(again)]) == 0
    assert np.allclose(tool_xyz_mm(again, "tGun"), xyz, atol=1e-3)


def test_wizard_fixed_point_typed_without_outputs(tmp_path, capsys, monkeypatch):
    fk = nominal_calibration(load_robot(ROBOT)).flange_poses
    joints = touches(fk, np.tile(POINT_M, (6, 1)), FIXED_TILTS_DEG)
    _stdin(monkeypatch, ["tPin", "2"] + [deg_text(q) for q in joints] + ["done"])
    assert main(["tool", "--robot", ROBOT]) == 0
    text = capsys.readouterr().out
    assert "Nothing will be saved" in text and "PERS tooldata tPin" in text
    assert "Tool tPin (fixed point, 6 touches)" in text
    assert not list(tmp_path.iterdir())


def test_wizard_end_of_input_cancels(model, tmp_path, capsys, monkeypatch):
    calib, _ = model
    _stdin(monkeypatch, ["1", "b", "1000 0 500"])
    assert main(["tool", "--model", str(calib), "--name", "tGun", "-o",
                 str(tmp_path / "x.json")]) == 1
    captured = capsys.readouterr()
    assert "Cancelled; nothing written." in captured.out
    assert "cancelled" in captured.err and not list(tmp_path.iterdir())


def test_wizard_ur_connection_refused_is_clear_and_fast(capsys, monkeypatch):
    _stdin(monkeypatch, [])
    start = time.monotonic()
    assert main(["tool", "--robot", ROBOT, "--name", "tGun", "--ur", "127.0.0.77",
                 "--connect-timeout-s", "1"]) == 1
    assert time.monotonic() - start < 3.0
    one_line_error(capsys, "connection refused by 127.0.0.77:30004")
