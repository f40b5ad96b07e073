"""The controller's own model: UR files read and written back, the fit to reported poses,
olp-fix --controller on a virtual UR whose controller runs hidden deltas and whose real arm
differs from both, and the export of a calibrated arm as UR deltas and a D-H table.

Every vendor file here is written by the test from the public descriptions (UR's
calibration.conf [mounting] deltas, the .urp <kinematics> block, ROS's calibration YAML)."""

from __future__ import annotations

import csv
import gzip
import math
from pathlib import Path

import numpy as np
import pytest

from olp_compensate.calibration.calibration import Calibration
from olp_compensate.calibration.controller_fit import controller_chain, fit_controller
from olp_compensate.cli.cal import main as cal
from olp_compensate.cli.fix import main as fix
from olp_compensate.compensation.ik import refine
from olp_compensate.errors import ParseError
from olp_compensate.io.calibration_file import read_calibration, write_calibration
from olp_compensate.io.ur_kinematics import (UrKinematics, dumps_conf, dumps_urp, dumps_yaml,
                                             loads_conf, loads_urp, loads_yaml, segments_from_table)
from olp_compensate.kinematics.conventions import (invert_pose, quat_wxyz_from_matrix,
                                                   rotation_angle_between, rotation_from_rotvec,
                                                   rotvec_from_rotation)
from olp_compensate.kinematics.dh_table import UR_NOMINAL, DHTable, mdh_rows
from olp_compensate.kinematics.model import build_model, fixed_chain, forward
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs.urscript.reader import parse_urscript

NAME = "ur10e"
ROBOT = load_robot(NAME)
NOMINAL = UR_NOMINAL[NAME]


def hidden_deltas(seed: int, size_m: float = 1e-3, size_rad: float = 1e-3) -> DHTable:
    """Deltas of a factory calibration, about 1 mm and 0.06 deg a value."""
    rng = np.random.default_rng(seed)
    return DHTable(rng.normal(0, size_rad, 6), rng.normal(0, size_m, 6),
                   rng.normal(0, size_m, 6), rng.normal(0, size_rad, 6))


def conf_text(deltas: DHTable) -> str:
    """A calibration.conf as UR's description has it (deltas in rad and m)."""
    def row(values):
        return "[" + ", ".join(f"{v:.17g}" for v in values) + "]"
    return ("# factory calibration\n[mounting]\n"
            f"delta_theta = {row(deltas.theta)}\ndelta_a = {row(deltas.a)}\n"
            f"delta_d = {row(deltas.d)}\ndelta_alpha = {row(deltas.alpha)}\n"
            "joint_checksum = [1, 2, 3, 4, 5, 6]\ncalibration_status = 2\n")


# -- tables and files --------------------------------------------------------------------

@pytest.mark.parametrize("name", sorted(UR_NOMINAL))
def test_published_tables_are_the_bundled_urdfs(name):
    robot = load_robot(name)
    model = build_model(robot)
    q = np.random.default_rng(0).uniform(-math.pi, math.pi, (200, 6))
    urdf = forward(model, model.nominal, q).flange
    assert np.abs(UR_NOMINAL[name].flange(q) - urdf).max() < 1e-12


def test_conf_round_trip_keeps_every_number_and_key():
    deltas = hidden_deltas(1)
    first = loads_conf(conf_text(deltas), "calibration.conf")
    again = loads_conf(dumps_conf(first))
    for a, b, c in zip((first.deltas.theta, first.deltas.d, first.deltas.a, first.deltas.alpha),
                       (again.deltas.theta, again.deltas.d, again.deltas.a, again.deltas.alpha),
                       (deltas.theta, deltas.d, deltas.a, deltas.alpha)):
        assert np.array_equal(a, b) and np.array_equal(a, c)
    assert again.extra == {"joint_checksum": "[1, 2, 3, 4, 5, 6]", "calibration_status": "2"}


def test_urp_round_trip_and_linearised_table_is_the_same_arm():
    # a "linearised" table: joints 2-3 tilted so that d reaches hundreds of metres, as UR
    # programs show; it must be read as the exact arm it is
    from olp_compensate.kinematics.dh_table import dh_from_chain

    arm = real_arm(2)            # Hayati tilts between the parallel axes 2, 3, 4
    chain = fixed_chain(arm.model, arm.values)
    table = dh_from_chain(chain, NOMINAL).table
    xml = ('<?xml version="1.0"?>\n<URProgram name="cell">\n'
           '  <kinematics status="LINEARIZED" validChecksum="true">\n'
           + "".join(f'    <{k} value="{", ".join(f"{v:.17g}" for v in vals)}"/>\n'
                     for k, vals in (("deltaTheta", table.theta), ("a", table.a),
                                     ("d", table.d), ("alpha", table.alpha)))
           + '    <jointChecksum value="-1, -1, -1, -1, -1, -1"/>\n  </kinematics>\n'
           '  <children/>\n</URProgram>\n')
    first = loads_urp(gzip.compress(xml.encode()), "cell.urp")
    again = loads_urp(dumps_urp(first))
    assert np.array_equal(first.table.d, again.table.d)
    assert np.array_equal(first.table.alpha, again.table.alpha)
    assert again.extra["jointChecksum"] == "-1, -1, -1, -1, -1, -1"
    q = np.random.default_rng(3).uniform(-math.pi, math.pi, (300, 6))
    assert np.abs(first.chain().flange(q) - chain.flange(q)).max() < 1e-9
    assert np.abs(table.d).max() > 1.0         # the common normals far away: linearised


def test_yaml_round_trip_and_same_arm_as_the_dh_table():
    controller = NOMINAL.plus(hidden_deltas(4).theta, hidden_deltas(4).d, hidden_deltas(4).a,
                              hidden_deltas(4).alpha)
    controller = DHTable(controller.theta, controller.d, controller.a,
                         np.r_[controller.alpha[:5], 0.0])
    controller = DHTable(controller.theta, controller.d, np.r_[controller.a[:5], 0.0],
                         controller.alpha)
    rows = segments_from_table(controller)
    text = "kinematics:\n" + "".join(
        f"  {name}:\n" + "".join(f"    {k}: {v:.17g}\n" for k, v in
                                 zip(("x", "y", "z", "roll", "pitch", "yaw"), row))
        for name, row in zip(("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2",
                              "wrist_3"), rows)) + "  hash: calib_123\n"
    first = loads_yaml(text, "cal.yaml")
    again = loads_yaml(dumps_yaml(first))
    assert np.array_equal(first.segments, again.segments)
    assert again.extra == {"hash": "calib_123"}
    q = np.random.default_rng(5).uniform(-math.pi, math.pi, (300, 6))
    assert np.abs(first.chain().flange(q) - controller.flange(q)).max() < 1e-12


@pytest.mark.parametrize("name,text,line", [
    ("bad.conf", "[mounting]\ndelta_theta = [0, 0, 0, 0, 0, 0]\ndelta_a = [0, 0, x, 0, 0, 0]\n",
     3),
    ("short.conf", "[mounting]\ndelta_theta = [0, 0, 0]\n", 2),
    ("bad.yaml", "kinematics:\n  shoulder:\n    x: 0\n    y: abc\n", 4),
])
def test_malformed_sources_exit_1_with_file_and_line(tmp_path, capsys, name, text, line):
    path = tmp_path / name
    path.write_text(text)
    assert cal(["controller", str(path), "--robot", NAME, "-o", str(tmp_path / "c.json")]) == 1
    err = capsys.readouterr().err
    assert f"{path}:{line}" in err and "Traceback" not in err
    assert not (tmp_path / "c.json").exists()


def test_malformed_urp_names_the_line(tmp_path, capsys):
    path = tmp_path / "p.urp"
    path.write_bytes(gzip.compress(b'<URProgram>\n<kinematics>\n<deltaTheta value="0, 0"/>\n'
                                   b'</kinematics></URProgram>'))
    assert cal(["controller", str(path), "--robot", NAME, "-o", str(tmp_path / "c.json")]) == 1
    assert f"{path}:3" in capsys.readouterr().err
    with pytest.raises(ParseError):
        loads_urp(b"<URProgram><kinem", "x.urp")


# -- the controller model from a UR file, and from reported poses -------------------------

@pytest.fixture(scope="module")
def controller_json(tmp_path_factory):
    """(controller.json from a calibration.conf with hidden deltas, the true table)."""
    folder = tmp_path_factory.mktemp("controller")
    deltas = hidden_deltas(11)
    (folder / "calibration.conf").write_text(conf_text(deltas))
    out = folder / "controller.json"
    assert cal(["controller", str(folder / "calibration.conf"), "--robot", NAME, "-o",
                str(out)]) == 0
    truth = NOMINAL.plus(deltas.theta, deltas.d, deltas.a, deltas.alpha)
    return out, truth


def test_controller_json_is_the_controllers_chain(controller_json):
    path, truth = controller_json
    controller = read_calibration(path, ROBOT)
    assert controller.validation.method.startswith("controller model: UR calibration.conf")
    q = np.random.default_rng(6).uniform(-math.pi, math.pi, (1000, 6))
    ours = controller_chain(controller).flange(q)
    theirs = truth.flange(q)
    assert np.abs(ours[:, :3, 3] - theirs[:, :3, 3]).max() < 1e-9
    assert np.abs(ours[:, :3, :3] - theirs[:, :3, :3]).max() < 1e-9


def reported_csv(path: Path, q_ctrl, poses, decimals: int = 6, noise_mm: float = 0.0,
                 seed: int = 0):
    """What a pendant shows: joints in deg, pose in mm and a quaternion, ``decimals``."""
    rng = np.random.default_rng(seed)
    with open(path, "w", newline="") as stream:
        out = csv.writer(stream)
        out.writerow([*(f"q{k + 1}_deg" for k in range(6)), "x_mm", "y_mm", "z_mm", "qw",
                      "qx", "qy", "qz"])
        for q, pose in zip(q_ctrl, poses):
            xyz = pose[:3, 3] * 1e3 + rng.normal(0, noise_mm, 3)
            quat = quat_wxyz_from_matrix(pose[:3, :3])
            out.writerow([f"{v:.{decimals}f}" for v in (*np.degrees(q), *xyz, *quat)])


def test_fit_from_50_reported_poses_reproduces_the_controller(tmp_path, capsys):
    truth = NOMINAL.plus(*(getattr(hidden_deltas(21), k) for k in ("theta", "d", "a", "alpha")))
    rng = np.random.default_rng(21)
    q = rng.uniform(-math.pi, math.pi, (50, 6))
    reported_csv(tmp_path / "poses.csv", q, truth.flange(q))
    out = tmp_path / "controller.json"
    assert cal(["controller", str(tmp_path / "poses.csv"), "--robot", NAME, "-o",
                str(out)]) == 0
    printed = capsys.readouterr().out
    assert "reproduces every row to its written precision" in printed
    controller = read_calibration(out, ROBOT)
    new = rng.uniform(-math.pi, math.pi, (1000, 6))
    ours, theirs = controller_chain(controller).flange(new), truth.flange(new)
    position_mm = np.linalg.norm(ours[:, :3, 3] - theirs[:, :3, 3], axis=1) * 1e3
    angle_deg = np.degrees(rotation_angle_between(ours[:, :3, :3], theirs[:, :3, :3]))
    assert position_mm.max() < 0.01 and angle_deg.max() < 0.001
    assert np.isfinite(controller.std[~np.isin(controller.model.names, ["j6.theta"])]).all()


def test_fit_says_when_the_rows_are_not_reproduced(tmp_path, capsys):
    truth = NOMINAL.plus(*(getattr(hidden_deltas(22), k) for k in ("theta", "d", "a", "alpha")))
    q = np.random.default_rng(22).uniform(-math.pi, math.pi, (50, 6))
    reported_csv(tmp_path / "poses.csv", q, truth.flange(q), noise_mm=0.05)
    assert cal(["controller", str(tmp_path / "poses.csv"), "--robot", NAME, "-o",
                str(tmp_path / "c.json")]) == 0
    assert "does NOT reproduce" in capsys.readouterr().out


def test_fit_of_a_named_tool_finds_the_tool():
    truth = NOMINAL.plus(*(getattr(hidden_deltas(23), k) for k in ("theta", "d", "a", "alpha")))
    tool = np.eye(4)
    tool[:3, :3] = rotation_from_rotvec(np.array([0.1, -0.2, 0.3]))
    tool[:3, 3] = (0.01, -0.02, 0.2)
    q = np.random.default_rng(23).uniform(-math.pi, math.pi, (40, 6))
    fit = fit_controller(ROBOT, q, truth.flange(q) @ tool, origin="test", tool="gun")
    new = np.random.default_rng(24).uniform(-math.pi, math.pi, (200, 6))
    cal_ = fit.calibration
    frames = forward(cal_.model, cal_.values, new).flange
    gun = cal_.tools["gun"]
    from olp_compensate.kinematics.conventions import matrix_from_quat_wxyz
    t = np.eye(4)
    t[:3, :3], t[:3, 3] = matrix_from_quat_wxyz(gun.quat_wxyz), gun.xyz_m
    assert np.abs(frames @ t - truth.flange(new) @ tool).max() < 1e-9


# -- olp-fix --controller on a virtual UR -------------------------------------------------

TCP = (0.0, 0.0, 0.12, 0.0, 0.0, 0.0)


def _fmt(v: float) -> str:
    return f"{v:.7f}"


def ur_program(poses) -> str:
    lines = ["def cell():", f"  set_tcp(p[{', '.join(map(_fmt, TCP))}])",
             "  movej([0.3, -1.2, 1.4, -1.8, -1.57, 0.2], a=1.4, v=1.05)"]
    for pose in poses:
        numbers = [*pose[:3, 3], *rotvec_from_rotation(pose[:3, :3])]
        lines.append(f"  movel(p[{', '.join(map(_fmt, numbers))}], a=1.2, v=0.25)")
    return "\n".join(lines + ["end", "cell()"]) + "\n"


def real_arm(seed: int) -> Calibration:
    """The real arm: the data sheet with errors of about 1 mm and 0.06 deg (its truth)."""
    model = build_model(ROBOT)
    rng = np.random.default_rng(seed)
    scale = np.array([1e-3 if p.unit == "m" else 1e-3 for p in model.parameters])
    values = model.nominal + rng.normal(0, 1, model.n_parameters) * scale
    return Calibration(robot=ROBOT, model=model, values=values,
                       std=np.full(model.n_parameters, np.nan))


def _path(seed: int, m: int):
    rng = np.random.default_rng(seed)
    q, out = np.array([0.3, -1.2, 1.4, -1.8, -1.57, 0.2]), []
    while len(out) < m:
        step = q + rng.uniform(-0.3, 0.3, 6)
        if abs(math.sin(step[4])) > 0.45 and abs(math.sin(step[2])) > 0.35:
            q = step
            out.append(q.copy())
    return np.array(out)


def _reached(text: str, report: Path, controller_table: DHTable, real: Calibration):
    """Where the real tool goes for each written target: the controller (its true table)
    takes the joints nearest those the report gives, the real arm goes there."""
    program = parse_urscript(text, "out.script")
    written = [t for t in program.targets if t.kind == "pose"]
    rows = [r for r in csv.DictReader(open(report)) if r["status"] in ("ok", "singular")]
    assert len(rows) == len(written)
    tool = np.eye(4)
    tool[:3, 3] = TCP[:3]
    reached = []
    chain = controller_table.chain()
    real_chain = fixed_chain(real.model, real.values)
    for target, row in zip(written, rows):
        values = np.array([n.value for n in target.numbers])
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = rotation_from_rotvec(values[3:]), values[:3]
        start = np.radians([float(row[f"q{k + 1}_deg"]) for k in range(6)])
        solution = refine(chain.flange_and_jacobian, start[None], (pose @ invert_pose(tool))[None],
                          None, 1e-12, 1e-12, 50)
        assert solution.success[0]
        reached.append(real_chain.flange(solution.q)[0] @ tool)
    return np.array(reached)


def test_urscript_with_controller_reaches_the_targets(tmp_path, controller_json, capsys):
    controller_path, truth = controller_json
    real = real_arm(31)
    write_calibration(tmp_path / "real.json", real)
    q = _path(31, 8)
    tool = np.eye(4)
    tool[:3, 3] = TCP[:3]
    meant = truth.flange(q) @ tool           # taught on the pendant: the controller's poses
    program = tmp_path / "cell.script"
    program.write_text(ur_program(meant))
    misses = {}
    for label, extra in (("with", ["--controller", str(controller_path)]), ("without", [])):
        out, report = tmp_path / f"{label}.script", tmp_path / f"{label}.csv"
        assert fix([str(program), "--model", str(tmp_path / "real.json"), "-o", str(out),
                    "--report", str(report), *extra]) == 0
        printed = capsys.readouterr()
        reached = _reached(out.read_text(), report, truth, real)
        misses[label] = np.linalg.norm(reached[:, :3, 3] - meant[:, :3, 3], axis=1) * 1e3
        assert ("UR controllers run their own factory calibration" in printed.err) == (
            label == "without")
        if label == "with":
            assert f"controller model {controller_path}" in printed.out
    assert misses["with"].max() < 0.05, misses
    # without it the controller's model and the data sheet differ at the joints taken:
    # the miss is that difference
    real_q = np.array([[np.radians(float(r[f"q{k + 1}_deg"])) for k in range(6)]
                       for r in csv.DictReader(open(tmp_path / "with.csv"))
                       if r["status"] in ("ok", "singular")])
    difference = np.linalg.norm((truth.flange(real_q) - NOMINAL.flange(real_q))[:, :3, 3]
                                + ((truth.flange(real_q)[:, :3, :3] - NOMINAL.flange(real_q)[:, :3, :3])
                                   @ tool[:3, 3]), axis=1) * 1e3
    print(f"miss with --controller {misses['with'].max():.4f} mm; without "
          f"{misses['without'].min():.3f}..{misses['without'].max():.3f} mm; controller vs data "
          f"sheet {difference.min():.3f}..{difference.max():.3f} mm")
    assert np.allclose(misses["without"], difference, atol=0.05)
    assert misses["without"].min() > 0.5


def test_controller_of_another_robot_is_refused(tmp_path, capsys):
    assert cal(["nominal", "--robot", "ur5e", "-o", str(tmp_path / "ur5e.json")]) == 0
    write_calibration(tmp_path / "real.json", real_arm(1))
    program = tmp_path / "cell.script"
    program.write_text(ur_program(NOMINAL.flange(_path(2, 2))))
    assert fix([str(program), "--model", str(tmp_path / "real.json"), "--controller",
                str(tmp_path / "ur5e.json"), "-o", str(tmp_path / "o.script")]) == 1
    assert "same robot model" in capsys.readouterr().err
    assert not (tmp_path / "o.script").exists()


# -- export --------------------------------------------------------------------------------

def test_export_ur_calibration_and_dh_table_hold_the_identified_arm(tmp_path, capsys):
    real = real_arm(41)
    write_calibration(tmp_path / "real.json", real)
    conf = tmp_path / "calibration.conf"
    assert cal(["export", "--model", str(tmp_path / "real.json"), "--format",
                "ur-calibration", "-o", str(conf)]) == 0
    printed = capsys.readouterr().out
    assert "what the table cannot hold" in printed
    # the deltas, added to the data sheet as a UR controller does, are the identified arm
    table = loads_conf(conf.read_text()).chain(NOMINAL)
    q = np.random.default_rng(41).uniform(-math.pi, math.pi, (500, 6))
    arm = fixed_chain(real.model, real.values)
    assert np.abs(table.flange(q) - arm.flange(q)).max() < 1e-7     # d of metres: 10 nm
    # the D-H/MDH table CSV: both conventions rebuilt from the CSV alone give the arm
    out = tmp_path / "dh.csv"
    assert cal(["export", "--model", str(tmp_path / "real.json"), "--format", "dh-table",
                "-o", str(out)]) == 0
    rows = list(csv.DictReader(line for line in open(out) if not line.startswith("#")))
    joints = [r for r in rows if r["joint"] != "flange"]
    dh = DHTable(*(np.array([float(r[c]) for r in joints]) * s for c, s in
                   (("theta_deg", math.pi / 180), ("d_mm", 1e-3), ("a_mm", 1e-3),
                    ("alpha_deg", math.pi / 180))))
    assert np.abs(dh.flange(q) - arm.flange(q)).max() < 1e-6
    assert np.abs(_mdh_flange(joints, rows[-1], q) - arm.flange(q)).max() < 1e-6


def _mdh_flange(joints, flange_row, q):
    """Craig's chain Rx(alpha_i-1) Tx(a_i-1) Rz(q_i + theta_i) Tz(d_i), then the flange row."""
    def rx(a):
        c, s = math.cos(a), math.sin(a)
        return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])

    def rz(a):
        c, s = math.cos(a), math.sin(a)
        return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])

    def t(x=0.0, z=0.0):
        out = np.eye(4)
        out[0, 3], out[2, 3] = x, z
        return out
    out = []
    for qk in q:
        pose = np.eye(4)
        for k, r in enumerate(joints):
            pose = (pose @ rx(math.radians(float(r["mdh_alpha_prev_deg"])))
                    @ t(x=float(r["mdh_a_prev_mm"]) * 1e-3)
                    @ rz(qk[k] + math.radians(float(r["mdh_theta_deg"])))
                    @ t(z=float(r["mdh_d_mm"]) * 1e-3))
        pose = (pose @ t(x=float(flange_row["mdh_a_prev_mm"]) * 1e-3)
                @ rx(math.radians(float(flange_row["mdh_alpha_prev_deg"]))))
        out.append(pose)
    return np.array(out)


def test_export_refuses_ur_format_for_other_robots(tmp_path, capsys):
    assert cal(["nominal", "--robot", "abb_irb2400", "-o", str(tmp_path / "n.json")]) == 0
    assert cal(["export", "--model", str(tmp_path / "n.json"), "--format", "ur-calibration",
                "-o", str(tmp_path / "c.conf")]) == 1
    assert "Universal Robots" in capsys.readouterr().err


def test_mdh_rows_match_dh():
    rows, tail = mdh_rows(NOMINAL)
    assert rows[0, 0] == 0 and rows[1, 0] == pytest.approx(math.pi / 2)
    assert np.allclose(tail, np.eye(4))


def test_ur_kinematics_dumps_conf_needs_nominal():
    kin = UrKinematics(form="conf", deltas=hidden_deltas(1))
    with pytest.raises(Exception):
        kin.chain()


def test_rapid_controller_models_that_change_nothing(tmp_path):
    """The data sheet as --controller gives the bytes of a run without it; the real arm as
    its own controller needs no correction at all."""
    robot = load_robot("abb_irb2400")
    model = build_model(robot)
    values = model.nominal + np.random.default_rng(51).normal(0, 5e-4, model.n_parameters)
    real = Calibration(robot=robot, model=model, values=values,
                       std=np.full(model.n_parameters, np.nan))
    write_calibration(tmp_path / "real.json", real)
    assert cal(["nominal", "--robot", "abb_irb2400", "-o", str(tmp_path / "nominal.json")]) == 0
    sample = Path(__file__).resolve().parents[1] / "samples" / "cell_a.mod"
    runs = {}
    for label, extra in (("plain", []), ("nominal", ["--controller", str(tmp_path / "nominal.json")]),
                         ("itself", ["--controller", str(tmp_path / "real.json")])):
        out, report = tmp_path / f"{label}.mod", tmp_path / f"{label}.csv"
        assert fix([str(sample), "--model", str(tmp_path / "real.json"), "-o", str(out),
                    "--report", str(report), "-q", *extra]) == 2
        runs[label] = (out.read_bytes(), list(csv.DictReader(open(report))))
    assert runs["nominal"] == runs["plain"]
    assert runs["itself"][0] == sample.read_bytes()
    moved = [r for r in runs["itself"][1] if r["status"] == "ok"]
    assert moved and all(abs(float(r[k])) < 1e-6 for r in moved for k in ("dx_mm", "dy_mm", "dz_mm"))


def test_taught_on_the_same_arm_through_its_controller_changes_nothing(tmp_path,
                                                                       controller_json):
    """Targets taught on the pendant of this very robot: read through its controller's model
    they are where its real tool went, and written back through it they come back as they
    were (the reading and the writing use the one controller model)."""
    controller_path, truth = controller_json
    write_calibration(tmp_path / "real.json", real_arm(71))
    tool = np.eye(4)
    tool[:3, 3] = TCP[:3]
    program = tmp_path / "cell.script"
    program.write_text(ur_program(truth.flange(_path(71, 6)) @ tool))
    common = [str(program), "--model", str(tmp_path / "real.json"), "--taught-on",
              str(tmp_path / "real.json"), "-q"]
    assert fix([*common, "-o", str(tmp_path / "a.script"), "--controller",
                str(controller_path)]) == 0
    assert (tmp_path / "a.script").read_text() == program.read_text()


def test_the_three_ur_files_of_one_controller_give_one_model(tmp_path, capsys):
    deltas = hidden_deltas(91)
    deltas = DHTable(deltas.theta, deltas.d, np.r_[deltas.a[:5], 0.0],
                     np.r_[deltas.alpha[:5], 0.0])         # the YAML form holds no a6, alpha6
    table = NOMINAL.plus(deltas.theta, deltas.d, deltas.a, deltas.alpha)
    (tmp_path / "calibration.conf").write_text(conf_text(deltas))
    (tmp_path / "prog.urp").write_bytes(dumps_urp(UrKinematics(form="urp", table=table)))
    (tmp_path / "cal.yaml").write_text(dumps_yaml(UrKinematics(
        form="yaml", segments=segments_from_table(table))))
    q = np.random.default_rng(91).uniform(-math.pi, math.pi, (500, 6))
    for name in ("calibration.conf", "prog.urp", "cal.yaml"):
        out = tmp_path / f"{name}.json"
        assert cal(["controller", str(tmp_path / name), "--robot", NAME, "-o", str(out)]) == 0
        chain = controller_chain(read_calibration(out))
        assert np.abs(chain.flange(q) - table.flange(q)).max() < 1e-9, name
    assert "ROS UR calibration YAML" in capsys.readouterr().out


def test_urp_notes_uncalibrated_programs_and_foreign_waypoints():
    nominal = ('<kinematics status="NOT_INITIALIZED"><deltaTheta value="0,0,0,0,0,0"/>'
               '<a value="0,-0.6127,-0.57155,0,0,0"/><d value="0.1807,0,0,0.17415,0.11985,'
               '0.11655"/><alpha value="1.5707963267948966,0,0,1.5707963267948966,'
               '-1.5707963267948966,0"/></kinematics>')
    waypoint = nominal.replace("kinematics", "Kinematics").replace('"0,0,0,0,0,0"',
                                                                   '"0.001,0,0,0,0,0"')
    text = f"<URProgram>{nominal}<children><Waypoint><position>{waypoint}</position>" \
           f"</Waypoint></children></URProgram>"
    notes = loads_urp(text.encode(), "p.urp").notes
    assert any("NOT_INITIALIZED" in n for n in notes)
    assert any("1 waypoint(s) carry other kinematics" in n for n in notes)


def test_a_folder_with_controller_gives_the_bytes_of_each_program_alone(tmp_path,
                                                                        controller_json):
    controller_path, truth = controller_json
    write_calibration(tmp_path / "real.json", real_arm(95))
    tool = np.eye(4)
    tool[:3, 3] = TCP[:3]
    (tmp_path / "in").mkdir()
    for k in range(3):
        (tmp_path / "in" / f"p{k}.script").write_text(
            ur_program(truth.flange(_path(95 + k, 3)) @ tool))
    common = ["--model", str(tmp_path / "real.json"), "--controller", str(controller_path),
              "-q"]
    assert fix([str(tmp_path / "in"), "-o", str(tmp_path / "out"), "-j", "2", *common]) == 0
    for k in range(3):
        alone = tmp_path / f"alone{k}.script"
        assert fix([str(tmp_path / "in" / f"p{k}.script"), "-o", str(alone), *common]) == 0
        assert (tmp_path / "out" / f"p{k}.script").read_bytes() == alone.read_bytes()


def test_export_of_an_arm_with_compliance_fits_what_dh_can_hold():
    """D-H cannot hold a pose-dependent deflection; the fitted table holds more of it than
    the exact geometry's, measured on poses the fit never saw."""
    import dataclasses

    from olp_compensate.calibration.dh_export import export_dh
    from olp_compensate.calibration.effects import JointCompliance
    from olp_compensate.calibration.simulate import random_joints

    arm = dataclasses.replace(real_arm(43), effects=(
        JointCompliance(joint=1).with_values(np.array([2e-6]), np.array([0.0])),))
    result = export_dh(arm, NOMINAL, 500, seed=3)
    q = random_joints(ROBOT, 500, np.random.default_rng(99))
    truth = arm.flange_poses(q)
    q_urdf = ROBOT.joints_from_controller(q)

    def rms(table):
        d = table.chain().flange(q_urdf)[:, :3, 3] - truth[:, :3, 3]
        return float(np.sqrt(np.mean(np.sum(d ** 2, axis=1)))) * 1e3

    assert result.fitted and result.max_mm > 0.01            # something is not held
    assert rms(result.table) < 0.9 * rms(result.exact.table)
