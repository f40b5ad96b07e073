"""Full-pose rows: orientation equations in identification, against virtual robots."""

import json
from dataclasses import replace

import numpy as np
import pytest

from olp_compensate.calibration.effects import (GearHarmonic, JointCompliance, JointScale,
                                                ThermalExpansion)
from olp_compensate.calibration.identify import IdentificationOptions, identify, measurement_inputs
from olp_compensate.calibration.problem import IdentificationProblem
from olp_compensate.calibration.simulate import (VirtualRobot, make_virtual_robot, random_joints,
                                                 random_rotation)
from olp_compensate.cli.cal import main
from olp_compensate.errors import DataError
from olp_compensate.io.calibration_file import calibration_from_dict, calibration_to_dict
from olp_compensate.io.measurements import (format_measurements, parse_measurements,
                                            read_measurements)
from olp_compensate.kinematics.conventions import (matrix_from_quat_wxyz, quat_wxyz_from_matrix,
                                                   rotation_angle_between, rotvec_from_rotation)
from olp_compensate.kinematics.model import build_model
from olp_compensate.kinematics.robot import load_robot

ABB = load_robot("abb_irb2400")
NOISE = 0.05e-3
ANGLE_NOISE = np.radians(0.01)
UNITS = ["deg"] * 6


def _measure(virtual, poses, seed, angle_noise=ANGLE_NOISE, **kwargs):
    rng = np.random.default_rng(seed)
    # the URDF joints' envelope, where the README's orientation figures were measured
    return virtual.measure(random_joints(ABB, poses, rng, within_ranges=False), NOISE, rng,
                           orientation_noise_rad=angle_noise, **kwargs)


def _problem(meas, free_names=None, effects=(), inputs=None, rotations=None, weight=0.3):
    """An identification problem at the virtual truth's neighbourhood (URDF joints)."""
    model = build_model(ABB)
    urdf = replace(meas, joints=ABB.joints_from_controller(meas.joints))
    names = free_names or [n for n in model.names if n not in ("j1.theta", "j1.d")]
    free = np.array([model.index(n) for n in names])
    tools = sorted(set(meas.point_names))
    rng = np.random.default_rng(0)
    rotations = rotations or {"tcp": random_rotation(rng)}
    device = np.eye(4)
    device[:3, :3] = random_rotation(rng)
    device[:3, 3] = [1.5, -0.4, 0.3]
    return IdentificationProblem(model, urdf, model.nominal, free, tools, device, effects, inputs,
                                 ABB.urdf_from_controller, rotations, weight)


def test_orientation_jacobian_matches_central_differences():
    virtual = make_virtual_robot(ABB, 3, n_points=2)
    rng = np.random.default_rng(4)
    n = 14
    meas = virtual.measure(random_joints(ABB, n, rng), NOISE, rng,
                           temperature_c=rng.uniform(15, 35, n), payload_kg=rng.uniform(0, 10, n),
                           orientation_noise_rad=ANGLE_NOISE)
    orientation = meas.orientation.copy()
    orientation[meas.point_names == "p2"] = np.nan   # p2: position-only rows
    orientation[[1, 7]] = np.nan                    # two tcp rows without orientation too
    meas = replace(meas, orientation=orientation)
    effects = [JointCompliance(joint=2, values=(3e-6,)), JointScale(joint=3, values=(5e-4,)),
               GearHarmonic(joint=4, order=2, values=(2e-4, -1e-4)),
               ThermalExpansion(values=(2e-5,), reference_temperature_c=22.0)]
    inputs = measurement_inputs(ABB, meas, virtual.tools, effects)
    problem = _problem(meas, effects=effects, inputs=inputs)
    assert problem.rotated_tools == ["tcp"] and problem.n_oriented == n - 2
    x = problem.pack(problem.model.nominal, problem.unpack(np.zeros(problem.n_unknowns))[1],
                     np.array([virtual.tools[t] for t in problem.tool_names]))
    x = x + np.random.default_rng(6).normal(0, 1e-3, len(x)) * np.abs(x).clip(1e-3)
    layout = problem.layout
    x[layout.registration_rotation] = [0.3, -0.2, 0.4]   # registration far from its reference
    x[layout.tool_rotation(0)] = [0.2, 0.1, -0.25]       # tool rotation far from its reference
    residual, jac = problem.residuals_and_jacobian(x)
    assert jac.shape == (3 * meas.n_rows + 3 * problem.n_oriented, problem.n_unknowns)
    np.testing.assert_array_equal(residual, problem.residuals(x))
    fd = np.empty_like(jac)
    for k in range(len(x)):
        h = 1e-6 * max(1.0, abs(x[k]))
        step = np.zeros(len(x))
        step[k] = h
        fd[:, k] = (problem.residuals(x + step) - problem.residuals(x - step)) / (2 * h)
    rows = slice(3 * meas.n_rows, None)  # the orientation rows, checked on their own scale
    for block in (slice(None), rows):
        scale = np.maximum(np.abs(fd[block]).max(axis=0), 1e-9)
        worst = np.max(np.abs(jac[block] - fd[block]) / scale, axis=0)
        names = problem.names()
        assert np.all(worst < 1e-6), {names[k]: worst[k] for k in np.argsort(-worst)[:3]}
    # orientation rows see every rotation (registration, angles, joint effects, tool frame)
    # and no translation (device origin, link lengths, tool points, thermal expansion)
    names = np.array(problem.names())
    blind = names[np.abs(jac[rows]).max(axis=0) == 0]
    lengths = {p.name for p in problem.model.parameters if p.unit == "m"} & set(names)
    points = {f"tool.{t}.{a}" for t in problem.tool_names for a in "xyz"}
    expected = {"base.tx", "base.ty", "base.tz", "thermal_expansion.alpha"} | lengths | points
    assert set(blind) == expected, set(blind) ^ expected


def test_last_joint_zero_is_redundant_with_the_tool_rotation():
    # With the tool's rotation unknown, turning the tool about axis 6 is j6.theta: the
    # Jacobian has an exact null vector, so identify holds j6.theta and says why.
    virtual = make_virtual_robot(ABB, 7)
    meas = _measure(virtual, 20, 8)
    model = build_model(ABB)
    with_zero = _problem(meas, [n for n in model.names if n not in ("j1.theta", "j1.d")])
    without = _problem(meas, [n for n in model.names if n not in ("j1.theta", "j1.d", "j6.theta")])
    for problem, expect_null in ((with_zero, True), (without, False)):
        x = problem.pack(model.nominal, problem.unpack(np.zeros(problem.n_unknowns))[1],
                         np.array([virtual.tools["tcp"]]))
        _, jac = problem.residuals_and_jacobian(x)
        _, s, vt = np.linalg.svd(jac / np.linalg.norm(jac, axis=0))
        if expect_null:
            assert s[-1] / s[0] < 1e-12
            null = dict(zip(problem.names(), np.abs(vt[-1])))
            assert null["j6.theta"] > 0.3 and max(null[f"tool.tcp.r{a}"] for a in "xyz") > 0.2
        else:
            assert s[-1] / s[0] > 1e-3
    result = identify(ABB, meas, IdentificationOptions(folds=0))
    assert "tool rotations" in result.identifiability.frozen["j6.theta"]
    assert not [n for n in result.identifiability.frozen if n.startswith("tool.")]
    assert not result.identifiability.weak


@pytest.fixture(scope="module")
def one_point_fits():
    """A virtual robot measured at 15 poses, one point each, with orientation; its
    identification with and without the orientation columns, and the truth-equivalent
    full-pose fit (noise-free, 400 poses)."""
    virtual = make_virtual_robot(ABB, 24)
    meas = _measure(virtual, 15, 124)
    options = IdentificationOptions(folds=5)
    full = identify(ABB, meas, options)
    position_only = identify(ABB, replace(meas, orientation=None), options)
    rng = np.random.default_rng(99)
    exact = virtual.measure(random_joints(ABB, 400, rng), 0.0, rng, orientation_noise_rad=0.0)
    truth = identify(ABB, exact, IdentificationOptions(folds=0))
    assert truth.residual_max < 1e-9 and truth.orientation_max < 1e-9  # the model is complete
    return virtual, meas, full, position_only, truth


def test_one_point_with_orientation_recovers_the_geometry_within_three_sigmas(one_point_fits):
    virtual, meas, full, position_only, truth = one_point_fits
    cal, ref = full.calibration, truth.calibration
    free = ~np.isnan(cal.std)
    z = np.abs(cal.values[free] - ref.values[free]) / cal.std[free]
    assert np.all(z < 3.0), dict(zip(np.array(cal.model.names)[free], z.round(2)))
    tool, tool_ref = cal.tools["tcp"], ref.tools["tcp"]
    assert np.all(np.abs(tool.xyz_m - tool_ref.xyz_m) < 3 * tool.std_m)
    turn = rotvec_from_rotation(matrix_from_quat_wxyz(tool_ref.quat_wxyz).T
                                @ matrix_from_quat_wxyz(tool.quat_wxyz))
    assert np.all(np.abs(turn) < 3 * tool.rot_std_rad), (turn, tool.rot_std_rad)
    # the orientation rows tighten the wrist: every shared parameter is at least as precise
    assert np.all(cal.std[free] <= 1.01 * position_only.calibration.std[free])
    assert full.n_equations == 6 * meas.n_rows and full.n_orientation_rows == meas.n_rows
    assert full.n_unknowns == position_only.n_unknowns + 3
    # residuals in their own units: the noise is 0.05 mm and 0.01 deg per axis
    assert 0.5 * NOISE * np.sqrt(3) < full.residual_rms < 1.2 * NOISE * np.sqrt(3)
    assert 0.5 * ANGLE_NOISE * np.sqrt(3) < full.orientation_rms < 1.2 * ANGLE_NOISE * np.sqrt(3)
    assert full.heldout_orientation_rms > full.orientation_rms
    assert position_only.orientation_rms is None and position_only.n_orientation_rows == 0


def test_one_point_with_orientation_predicts_new_poses_better(one_point_fits):
    virtual, meas, full, position_only, _ = one_point_fits
    test = random_joints(ABB, 1000, np.random.default_rng(7), within_ranges=False)
    names = ["tcp"] * len(test)
    truth = virtual.true_frames(test, names)

    def rms(cal):
        diff = cal.predict_points(test, names) - truth[:, :3, 3]
        return np.sqrt(np.mean(np.sum(diff**2, axis=1)))

    with_orientation, without = rms(full.calibration), rms(position_only.calibration)
    assert with_orientation < 0.8 * without, (with_orientation, without)  # measured: 0.56x
    angles = rotation_angle_between(full.calibration.predict_rotations(test, names),
                                    truth[:, :3, :3])
    assert np.sqrt(np.mean(angles**2)) < ANGLE_NOISE  # the tool frame, better than one reading
    with pytest.raises(DataError, match="orientation"):
        position_only.calibration.predict_rotations(test[:1], ["tcp"])


@pytest.mark.slow
def test_reported_deviations_with_orientation_agree_with_monte_carlo():
    virtual = make_virtual_robot(ABB, 8)
    joints = random_joints(ABB, 20, np.random.default_rng(9))
    estimates, reported = [], []
    for run in range(40):
        rng = np.random.default_rng(100 + run)
        result = identify(ABB, virtual.measure(joints, NOISE, rng, orientation_noise_rad=ANGLE_NOISE),
                          IdentificationOptions(folds=0))
        tool = result.calibration.tools["tcp"]
        estimates.append(np.concatenate([result.calibration.values,
                                         rotvec_from_rotation(matrix_from_quat_wxyz(tool.quat_wxyz))]))
        reported.append(np.concatenate([result.calibration.std, tool.rot_std_rad]))
    free = ~np.isnan(reported[0])
    empirical = np.std(np.array(estimates)[:, free], axis=0, ddof=1)
    predicted = np.mean(np.array(reported)[:, free], axis=0)
    ratio = empirical / predicted
    assert np.all((ratio > 0.6) & (ratio < 1.5)), ratio


def test_robust_fit_rejects_an_orientation_outlier():
    virtual = make_virtual_robot(ABB, 13)
    meas = _measure(virtual, 40, 14)
    orientation = meas.orientation.copy()
    bad = matrix_from_quat_wxyz(orientation[9]) @ matrix_from_quat_wxyz(
        [np.cos(np.radians(0.1)), np.sin(np.radians(0.1)), 0, 0])  # turned by 0.2 deg
    orientation[9] = quat_wxyz_from_matrix(bad)
    points = meas.points.copy()
    points[22] += [0, 2e-3, 0]
    result = identify(ABB, replace(meas, orientation=orientation, points=points),
                      IdentificationOptions(robust=True, folds=0))
    assert sorted(result.outlier_rows) == [10, 23]
    assert result.orientation_max < 4.5 * ANGLE_NOISE
    assert result.n_equations == 6 * (meas.n_rows - 2)


def test_mixed_tools_and_empty_orientation_cells(tmp_path):
    # p2 has no orientation: it stays a position-only tool; the file round-trips.
    virtual = make_virtual_robot(ABB, 11, n_points=2)
    meas = _measure(virtual, 20, 12)
    orientation = meas.orientation.copy()
    orientation[meas.point_names == "p2"] = np.nan
    meas = replace(meas, orientation=orientation)
    path = tmp_path / "m.csv"
    path.write_text(format_measurements(meas, UNITS))
    again = read_measurements(path, UNITS)
    np.testing.assert_allclose(again.orientation, meas.orientation, atol=1e-8)
    result = identify(ABB, again, IdentificationOptions(folds=3))
    tools = result.calibration.tools
    assert tools["p2"].quat_wxyz is None and tools["tcp"].quat_wxyz is not None
    assert result.n_orientation_rows == 20 and result.n_equations == 3 * 40 + 3 * 20
    assert "tool.tcp.rz" in result.unknown_names and "tool.p2.rz" not in result.unknown_names
    # calib.json keeps the tool frame and the orientation figures; older files read as before
    doc = json.loads(json.dumps(calibration_to_dict(result.calibration)))
    assert len(doc["tools"]["tcp"]["quat_wxyz"]) == 4 and len(doc["tools"]["tcp"]["rot_std_deg"]) == 3
    assert doc["validation"]["orientation_rms_deg"] > 0
    cal = calibration_from_dict(doc)
    np.testing.assert_allclose(cal.tools["tcp"].rot_std_rad, tools["tcp"].rot_std_rad)
    assert cal.validation.heldout_orientation_max_deg == doc["validation"]["heldout_orientation_max_deg"]
    for key in ("orientation_rms_deg", "orientation_max_deg", "heldout_orientation_rms_deg",
                "heldout_orientation_max_deg"):
        del doc["validation"][key]
    del doc["tools"]["tcp"]["rot_std_deg"]
    old = calibration_from_dict(doc)
    assert old.validation.orientation_rms_deg is None and old.tools["tcp"].rot_std_rad is None


HEADER = "pose,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,x_mm,y_mm,z_mm,qw,qx,qy,qz\n"
JOINTS = "1,0,0,0,0,30,0,1000,0,1000,"


@pytest.mark.parametrize("cells, message", [
    ("0,0,0,0", r"f\.csv:3: columns 'qw', 'qx', 'qy', 'qz': quaternion of zero length"),
    ("1,nan,0,0", r"f\.csv:3: column 'qx': nan is not a finite number"),
    ("1,0,,0", r"f\.csv:3: column 'qy': empty"),
    ("1,0,x,0", r"f\.csv:3: column 'qy': 'x' is not a number"),
])
def test_bad_quaternion_names_file_row_and_column(cells, message):
    text = HEADER + JOINTS + "1,0,0,0\n" + JOINTS + cells + "\n"
    with pytest.raises(DataError, match=message) as info:
        parse_measurements(text, UNITS, "f.csv")
    assert "\n" not in str(info.value)


def test_quaternion_columns_all_or_none_and_normalized():
    with pytest.raises(DataError, match="missing qz"):
        parse_measurements(HEADER.replace(",qz", "") + JOINTS + "1,0,0\n", UNITS, "f.csv")
    meas = parse_measurements(HEADER + JOINTS + "2,0,0,0\n" + JOINTS + ",,,\n", UNITS, "f.csv")
    np.testing.assert_array_equal(meas.orientation[0], [1, 0, 0, 0])
    assert np.all(np.isnan(meas.orientation[1]))


def test_truth_file_carries_the_tool_rotation_and_old_files_still_read():
    virtual = make_virtual_robot(ABB, 5)
    again = VirtualRobot.from_json(virtual.to_json(), ABB)
    np.testing.assert_allclose(again.tool_rotation("tcp"), virtual.tool_rotation("tcp"), atol=1e-12)
    doc = json.loads(virtual.to_json())
    del doc["tools"]["tcp"]["quat_wxyz"]
    old = VirtualRobot.from_json(json.dumps(doc), ABB)
    np.testing.assert_array_equal(old.tool_rotation("tcp"), np.eye(3))


def test_cli_simulate_with_orientation_then_identify(tmp_path, capsys):
    meas, truth, calib = tmp_path / "m.csv", tmp_path / "truth.json", tmp_path / "calib.json"
    assert main(["simulate", "--robot", "abb_irb2400", "--poses", "20", "--seed", "2",
                 "--orientation-noise-deg", "0.01", "-o", str(meas), "--truth", str(truth)]) == 0
    header = [ln for ln in meas.read_text().splitlines() if not ln.startswith("#")][0]
    assert header.endswith("qw,qx,qy,qz")
    assert len(json.loads(truth.read_text())["tools"]["tcp"]["quat_wxyz"]) == 4
    capsys.readouterr()
    assert main(["identify", str(meas), "--robot", "abb_irb2400", "-o", str(calib)]) == 0
    out = capsys.readouterr().out
    assert "120 equations (20 rows with orientation)" in out
    line = next(ln for ln in out.splitlines() if ln.startswith("orientation residual:"))
    rms = float(line.split("RMS ")[1].split(" deg")[0])
    assert 0.005 < rms < 0.03, line
    assert "held-out orientation: RMS" in out and "tool tcp frame: quaternion" in out
    assert "j6.theta: redundant with the tools" in out
    assert json.loads(calib.read_text())["tools"]["tcp"]["quat_wxyz"] is not None
    bad = tmp_path / "bad.csv"
    bad.write_text(HEADER + JOINTS + "0,0,0,0\n")
    assert main(["identify", str(bad), "--robot", "abb_irb2400"]) == 1
    err = capsys.readouterr().err.strip()
    assert "bad.csv:2:" in err and "quaternion of zero length" in err and "\n" not in err
