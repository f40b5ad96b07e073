"""The linear, guess-free start of the tool points and device frame
(:func:`olp_compensate.calibration.registration._linear_start`) against virtual robots: it is
refused when the flange orientation barely changes (its regressors cannot split the measured
points' offset between tool and device frame; the ASTL SURFACE session got a tool 24.5 m
away from it, held there), kept when the orientation varies, and the refusal does not depend
on the length unit."""

import numpy as np

from olp_compensate.calibration.identify import IdentificationOptions, identify
from olp_compensate.calibration.problem import point_index
from olp_compensate.calibration.registration import _linear_start, register_device
from olp_compensate.calibration.simulate import make_virtual_robot, random_joints
from olp_compensate.cli.cal_identify import report
from olp_compensate.kinematics.conventions import rotation_angle_between, rotvec_from_rotation
from olp_compensate.kinematics.model import build_model, forward
from olp_compensate.kinematics.robot import load_robot
from virtual_world import axis1_poses

NOISE = 0.05e-3
ROBOT = "staubli_tx2_90l"


def _nominal_flange(robot, q):
    """Flange poses (m, 4, 4) of the nominal model, base frame, for controller joints q."""
    model = build_model(robot, "auto")
    return forward(model, model.nominal, robot.joints_from_controller(q)).flange


def _fixed_orientation_poses(robot, n, seed):
    """Controller joints (n, 6) whose nominal flange keeps one orientation (the controller
    moving a tool over a surface, as the ASTL sessions do): axes 1-3 random, the wrist
    solved for the orientation of a reference pose by Newton steps (finite differences),
    then every joint value rounded to 1e-6 deg (as the ASTL sessions report them); poses whose wrist
    leaves the limits or does not converge are dropped."""
    rng = np.random.default_rng(seed)
    reference = np.radians([0.0, 10.0, 80.0, 5.0, 30.0, 15.0])
    target = _nominal_flange(robot, reference[None])[0, :3, :3]
    q = np.tile(reference, (n, 1))
    q[:, 0] = rng.uniform(-0.8, 0.8, n)
    q[:, 1] = rng.uniform(-0.3, 0.5, n)
    q[:, 2] = rng.uniform(1.0, 1.8, n)

    def error(qs):
        return rotvec_from_rotation(target.T @ _nominal_flange(robot, qs)[:, :3, :3])

    for _ in range(30):
        e = error(q)
        jac = np.empty((n, 3, 3))
        for k in range(3):
            step = q.copy()
            step[:, 3 + k] += 1e-7
            jac[:, :, k] = (error(step) - e) / 1e-7
        q[:, 3:] -= np.linalg.solve(jac, e[:, :, None])[:, :, 0]
    ok = ((np.linalg.norm(error(q), axis=1) < 1e-10)
          & np.all((q > robot.lower_limits) & (q < robot.upper_limits), axis=1))
    return np.radians(np.round(np.degrees(q[ok]), 6))


def _start_inputs(robot, q, meas):
    """register_device's inputs: nominal flange (m, 4, 4), points (m, 3), point index."""
    return _nominal_flange(robot, q), meas.points, point_index(meas.point_names, ["tcp"])


def test_the_poses_built_keep_the_orientation_and_spread_the_positions():
    robot = load_robot(ROBOT)
    q = _fixed_orientation_poses(robot, 80, 1)
    flange = _nominal_flange(robot, q)
    assert len(q) >= 60
    spread = rotation_angle_between(flange[:1, :3, :3], flange[:, :3, :3])
    assert np.max(spread) < np.radians(1e-3)         # the rounding only
    # the positions span 3-D (the device frame's rotation is determined by them)
    centred = flange[:, :3, 3] - flange[:, :3, 3].mean(axis=0)
    assert np.linalg.svd(centred, compute_uv=False)[-1] > 0.05 * np.sqrt(len(q))


def test_a_fixed_orientation_refuses_the_linear_start_and_holds_a_tool_at_zero():
    robot = load_robot(ROBOT)
    virtual = make_virtual_robot(robot, seed=3)
    q = _fixed_orientation_poses(robot, 80, 1)
    meas = virtual.measure(q, NOISE, np.random.default_rng(2))
    flange, points, index = _start_inputs(robot, q, meas)
    assert _linear_start(flange[:, :3, :3], flange[:, :3, 3], points, index, 1) is None
    device, tools = register_device(flange, points, index, 1)
    assert np.linalg.norm(tools[0]) < 1e-6           # the zero start, unmoved
    # The device frame's start: the truth's rotation, and its translation carrying the
    # tool's constant offset in the device frame (D_t + D_R R0 t: what the points see).
    truth_flange = virtual.flange_poses(q)
    rotation0 = truth_flange[0, :3, :3]
    truth = virtual.device_T_base
    seen = truth[:3, 3] + truth[:3, :3] @ rotation0 @ virtual.tools["tcp"]
    # (within what the nominal model's errors allow: 0.1 deg per joint zero, 1 mm per axis
    # per joint origin; measured 0.32-0.40 deg and 2.4-4.9 mm over seeds 3, 5, 7)
    assert np.degrees(rotation_angle_between(device[:3, :3], truth[:3, :3])) < 1.0
    assert np.linalg.norm(device[:3, 3] - seen) < 10e-3

    result = identify(robot, meas, IdentificationOptions(folds=3))
    cal = result.calibration
    assert {"tool.tcp.x", "tool.tcp.y", "tool.tcp.z"} <= set(cal.frozen)
    assert np.linalg.norm(cal.tools["tcp"].xyz_m) < 1e-6
    assert "tool tcp: (0.000, 0.000, 0.000) mm" in report(result)  # no "-0.000"
    assert np.degrees(rotation_angle_between(cal.device_T_base[:3, :3], truth[:3, :3])) < 1.0
    assert np.linalg.norm(cal.device_T_base[:3, 3] - seen) < 10e-3
    # the model predicts the truth on new poses of the same kind, to the noise level
    q_new = _fixed_orientation_poses(robot, 40, 9)
    error = np.linalg.norm(cal.predict_points(q_new, ["tcp"] * len(q_new))
                           - virtual.true_points(q_new, ["tcp"] * len(q_new)), axis=1)
    assert np.sqrt(np.mean(error**2)) < 2 * NOISE


def test_one_axis_of_rotation_refuses_it_and_finds_the_identifiable_part_of_the_tool():
    # The geometry exact (no joint errors): the wrist stands still, so every error of links
    # 4-6 would be a constant offset of the tool; without them the tool's truth is defined.
    robot = load_robot(ROBOT)
    virtual = make_virtual_robot(robot, seed=2, length_error_m=0.0, angle_error_rad=0.0)
    q = axis1_poses(robot, 60, 3)
    meas = virtual.measure(q, NOISE, np.random.default_rng(5))
    flange, points, index = _start_inputs(robot, q, meas)
    assert _linear_start(flange[:, :3, :3], flange[:, :3, 3], points, index, 1) is None
    cal = identify(robot, meas, IdentificationOptions(folds=0)).calibration
    # axis 1 (base z) in the flange frame: the true flange's, constant over these poses
    axis = virtual.flange_poses(q[:1])[0, :3, :3].T @ [0.0, 0.0, 1.0]
    miss = cal.tools["tcp"].xyz_m - virtual.tools["tcp"]
    assert np.linalg.norm(miss - (miss @ axis) * axis) < 0.1e-3   # across the axis: found
    assert "tool.tcp.x" in cal.frozen                              # along it: held ...
    assert np.linalg.norm(cal.tools["tcp"].xyz_m) < 0.5            # ... at a sane value


def test_varied_orientations_keep_the_linear_start_and_recover_the_truth():
    robot = load_robot(ROBOT)
    virtual = make_virtual_robot(robot, seed=11, device_distance_m=4.0)
    virtual.tools["tcp"] = np.array([0.25, -0.3, 0.4])  # far from the flange
    rng = np.random.default_rng(4)
    q = random_joints(robot, 50, rng)
    meas = virtual.measure(q, NOISE, rng)
    flange, points, index = _start_inputs(robot, q, meas)
    start = _linear_start(flange[:, :3, :3], flange[:, :3, 3], points, index, 1)
    assert start is not None
    # the start, from the nominal model (1 mm, 0.1 deg errors per joint), near the truth
    assert np.linalg.norm(start[0] - virtual.tools["tcp"]) < 0.02
    result = identify(robot, meas, IdentificationOptions(folds=0))
    cal = result.calibration
    assert not any(n.startswith(("tool.", "base.")) for n in cal.frozen)
    # the tool absorbs the last joint's origin error (1 mm per axis), the device frame the
    # first's: the right basin, and the truth predicted on new poses to the noise level
    assert np.linalg.norm(cal.tools["tcp"].xyz_m - virtual.tools["tcp"]) < 5e-3
    assert np.linalg.norm(cal.device_T_base[:3, 3] - virtual.device_T_base[:3, 3]) < 10e-3
    q_new = random_joints(robot, 40, rng)
    error = np.linalg.norm(cal.predict_points(q_new, ["tcp"] * len(q_new))
                           - virtual.true_points(q_new, ["tcp"] * len(q_new)), axis=1)
    assert np.sqrt(np.mean(error**2)) < 2 * NOISE


def test_the_refusal_does_not_depend_on_the_length_unit():
    robot = load_robot(ROBOT)
    virtual = make_virtual_robot(robot, seed=3)
    for q in (_fixed_orientation_poses(robot, 60, 1), random_joints(robot, 40,
                                                                      np.random.default_rng(8))):
        meas = virtual.measure(q, NOISE, np.random.default_rng(2))
        flange, points, index = _start_inputs(robot, q, meas)
        in_m = _linear_start(flange[:, :3, :3], flange[:, :3, 3], points, index, 1)
        in_mm = _linear_start(flange[:, :3, :3], 1e3 * flange[:, :3, 3], 1e3 * points, index, 1)
        assert (in_m is None) == (in_mm is None)
        if in_m is not None:
            np.testing.assert_allclose(in_mm, 1e3 * in_m, rtol=1e-6)
