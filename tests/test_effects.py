"""Effect terms: analytic derivatives against finite differences, the model against the
virtual robot's independent truth, the calibration hook and the calib.json round trip."""

import json
from dataclasses import replace

import numpy as np
import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.calibration.effects import (Backlash, Conditions, GearHarmonic, JointCompliance,
                                                JointScale, ThermalExpansion, effect_from_dict,
                                                effect_inputs, make_effect)
from olp_compensate.calibration.gravity import gravity_model
from olp_compensate.calibration.identify import IdentificationOptions, identify, measurement_inputs
from olp_compensate.calibration.problem import IdentificationProblem
from olp_compensate.calibration.simulate import (HiddenEffect, UNIT_VALUES, make_virtual_robot,
                                                 random_joints, scaled_effect)
from olp_compensate.errors import DataError, ModelError
from olp_compensate.io.calibration_file import (calibration_from_dict, calibration_to_dict,
                                                dumps_calibration)
from olp_compensate.kinematics.model import build_model
from olp_compensate.kinematics.robot import load_robot

ABB = load_robot("abb_irb2400")  # controller axes differ from the URDF joints (J2/J3 linkage)


def _joints(robot, n, seed):
    return random_joints(robot, n, np.random.default_rng(seed))


@pytest.mark.parametrize("robot_name", ["abb_irb2400", "ur5e"])
def test_load_torque_is_minus_the_gradient_of_the_potential_energy(robot_name):
    """Sign and controller-axis mapping checked against pinocchio's potential energy."""
    import pinocchio as pin

    robot = load_robot(robot_name)
    model = robot.pinocchio_model
    data = model.createData()
    payload, point = np.array([7.0]), np.array([[0.05, -0.02, 0.12]])

    def energy(q_ctrl):
        urdf = robot.joints_from_controller(q_ctrl[None])[0]
        config = pin.neutral(model)
        for jid, value in zip(robot.pinocchio_joint_ids(), urdf):
            config[model.joints[jid].idx_q] = value
        pin.framesForwardKinematics(model, data, config)
        flange = data.oMf[model.getFrameId(robot.flange_link)]
        height = (flange.act(point[0]))[2]
        return pin.computePotentialEnergy(model, data, config) + payload[0] * 9.81 * height

    q = _joints(robot, 3, 1)
    tau, dtau = gravity_model(robot).load_torque(q, np.repeat(payload, 3), np.repeat(point, 3, 0),
                                                 derivatives=True)
    eps = 1e-6
    for k in range(3):
        grad = np.array([(energy(q[k] + eps * e) - energy(q[k] - eps * e)) / (2 * eps)
                         for e in np.eye(robot.n_joints)])
        np.testing.assert_allclose(tau[k], -grad, atol=1e-5 * max(1.0, np.abs(grad).max()))
        tau_p, _ = gravity_model(robot).load_torque(q[k:k + 1] + eps * np.eye(robot.n_joints),
                                                    np.repeat(payload, robot.n_joints),
                                                    np.repeat(point, robot.n_joints, 0))
        tau_m, _ = gravity_model(robot).load_torque(q[k:k + 1] - eps * np.eye(robot.n_joints),
                                                    np.repeat(payload, robot.n_joints),
                                                    np.repeat(point, robot.n_joints, 0))
        fd = ((tau_p - tau_m) / (2 * eps)).T  # [i, j] = d tau_i / d q_j
        np.testing.assert_allclose(dtau[k], fd, atol=1e-5 * max(1.0, np.abs(fd).max()))


EFFECTS = [JointCompliance(joint=2, values=(3e-6,)),
           GearHarmonic(joint=1, order=2, values=(2e-4, -1e-4)),
           Backlash(joint=2, values=(4e-4,)), JointScale(joint=3, values=(5e-4,))]


@pytest.mark.parametrize("effect", EFFECTS, ids=lambda e: e.label)
def test_basis_derivative_matches_finite_differences(effect):
    q = _joints(ABB, 5, 2)
    inputs = effect_inputs(ABB, q, derivatives=True)
    eps = 1e-6
    fd = np.empty((5, effect.n_parameters, ABB.n_joints))
    for j in range(ABB.n_joints):
        step = np.zeros(ABB.n_joints)
        step[j] = eps
        up = effect.basis(effect_inputs(ABB, q + step))
        down = effect.basis(effect_inputs(ABB, q - step))
        fd[:, :, j] = (up - down) / (2 * eps)
    scale = max(np.abs(fd).max(), 1.0)
    np.testing.assert_allclose(effect.basis_dq(inputs), fd, atol=1e-6 * scale)


def test_identification_jacobian_with_effects_matches_finite_differences():
    robot = ABB
    virtual = make_virtual_robot(robot, 3, n_points=2)
    rng = np.random.default_rng(4)
    meas = virtual.measure(_joints(robot, 12, 5), 0.0, rng,
                           temperature_c=rng.uniform(15, 35, 12), payload_kg=rng.uniform(0, 10, 12))
    effects = [*EFFECTS, ThermalExpansion(values=(2e-5,), reference_temperature_c=22.0)]
    model = build_model(robot)
    inputs = measurement_inputs(robot, meas, virtual.tools, effects)
    urdf = replace(meas, joints=robot.joints_from_controller(meas.joints))
    free = np.arange(3, model.n_parameters)
    problem = IdentificationProblem(model, urdf, model.nominal, free, sorted(virtual.tools),
                                    virtual.device_T_base, effects, inputs,
                                    robot.urdf_from_controller)
    x = problem.pack(model.nominal, virtual.device_T_base,
                     np.array([virtual.tools[n] for n in sorted(virtual.tools)]))
    x = x + np.random.default_rng(6).normal(0, 1e-3, len(x)) * np.abs(x).clip(1e-3)
    _, jac = problem.residuals_and_jacobian(x)
    fd = np.empty_like(jac)
    for k in range(len(x)):
        h = 1e-7 * max(1.0, abs(x[k]))
        step = np.zeros(len(x))
        step[k] = h
        fd[:, k] = (problem.residuals(x + step) - problem.residuals(x - step)) / (2 * h)
    scale = np.maximum(np.abs(fd).max(axis=0), 1e-9)
    worst = np.max(np.abs(jac - fd) / scale, axis=0)
    names = problem.names()
    assert np.all(worst < 1e-5), {names[k]: worst[k] for k in np.argsort(-worst)[:3]}


def test_actual_joints_contract_and_jacobian():
    cal = nominal_calibration(ABB)
    q = ABB.joints_from_controller(_joints(ABB, 4, 7))
    same, none = cal.actual_joints(q, jacobian=True)
    assert none is None and np.array_equal(same, q)
    cal = replace(cal, effects=tuple(EFFECTS))
    actual, jac = cal.actual_joints(q, jacobian=True)
    assert actual.shape == (4, 6) and jac.shape == (4, 6, 6)
    np.testing.assert_array_equal(actual, cal.actual_joints(q))
    eps = 1e-6
    for j in range(6):
        step = np.zeros(6)
        step[j] = eps
        fd = (cal.actual_joints(q + step) - cal.actual_joints(q - step)) / (2 * eps)
        np.testing.assert_allclose(jac[:, :, j], fd, atol=1e-7)
    # one joint vector in, one out
    single, single_jac = cal.actual_joints(q[0], jacobian=True)
    np.testing.assert_allclose(single, actual[0])
    np.testing.assert_allclose(single_jac, jac[0])


def test_thermal_expansion_changes_nothing_at_the_reference_temperature():
    cal = nominal_calibration(ABB)
    cal = replace(cal, effects=(ThermalExpansion(values=(2e-5,), reference_temperature_c=21.0),))
    q = _joints(ABB, 5, 8)
    plain = nominal_calibration(ABB).flange_poses(q)
    np.testing.assert_array_equal(cal.flange_poses(q), plain)
    hot = cal.flange_poses(q, Conditions(temperature_c=np.full(5, 31.0)))
    np.testing.assert_allclose(hot[:, :3, 3], plain[:, :3, 3] * (1 + 2e-5 * 10.0))
    np.testing.assert_array_equal(hot[:, :3, :3], plain[:, :3, :3])


@pytest.mark.parametrize("kind,joint,order", [("joint_compliance", 1, 1), ("gear_harmonic", 2, 3),
                                              ("backlash", 2, 1), ("joint_scale", 0, 1),
                                              ("thermal_expansion", None, 1)])
def test_model_reproduces_the_virtual_robots_independent_truth(kind, joint, order):
    """Noise-free data of a robot with one hidden effect: geometry + that effect fit the
    truth (to far below any noise; compliance to first order) and recover its value."""
    virtual = make_virtual_robot(ABB, 9)
    rng = np.random.default_rng(10)
    q = _joints(ABB, 40, 11)
    temperature = rng.uniform(15.0, 30.0, 40)
    hidden = HiddenEffect(kind, joint, UNIT_VALUES[kind], order=order, phase_rad=0.7)
    hidden = scaled_effect(virtual, hidden, q, 0.3e-3, temperature_c=temperature)
    meas = replace(virtual, effects=(hidden,)).measure(q, 0.0, rng, temperature_c=temperature)
    effect = make_effect(kind, joint, ABB.n_joints, order=order)
    plain = identify(ABB, meas, IdentificationOptions(folds=0))
    result = identify(ABB, meas, IdentificationOptions(folds=0, effects=(effect,)))
    assert plain.residual_rms > 0.05e-3
    assert result.residual_rms < (3e-6 if kind == "joint_compliance" else 1e-6)
    (fitted,) = result.calibration.effects
    if kind == "gear_harmonic":
        truth = hidden.value * np.array([np.cos(hidden.phase_rad), np.sin(hidden.phase_rad)])
        np.testing.assert_allclose(fitted.values, truth, rtol=1e-6)
    elif kind == "thermal_expansion":  # the geometry is identified at T0 = mean temperature
        t0 = fitted.reference_temperature_c
        assert t0 == pytest.approx(temperature.mean())
        expected = hidden.value / (1 + hidden.value * (t0 - hidden.reference_temperature_c))
        assert fitted.values[0] == pytest.approx(expected, rel=1e-3)
    else:
        assert fitted.values[0] == pytest.approx(hidden.value, rel=1e-2)


def test_an_effect_the_poses_cannot_separate_is_reported_not_fitted():
    virtual = make_virtual_robot(ABB, 12)
    rng = np.random.default_rng(13)
    q = _joints(ABB, 30, 14)
    q[:, 3] = np.radians(25.0)  # axis 4 never moves: its scale is its zero offset
    meas = virtual.measure(q, 0.05e-3, rng)
    effects = (JointScale(joint=3), JointCompliance(joint=0), JointCompliance(joint=2))
    result = identify(ABB, meas, IdentificationOptions(folds=0, effects=effects))
    assert "cannot be separated" in result.dropped_effects["joint_scale j4"]
    assert "has no effect" in result.dropped_effects["joint_compliance j1"]  # vertical axis 1
    assert [e.label for e in result.calibration.effects] == ["joint_compliance j3"]


def test_calibration_file_round_trip_with_effects():
    rng = np.random.default_rng(15)
    virtual = make_virtual_robot(ABB, 15)
    meas = virtual.measure(_joints(ABB, 30, 16), 0.05e-3, rng,
                           temperature_c=rng.uniform(18, 28, 30))
    effects = (GearHarmonic(joint=4, order=2), ThermalExpansion(), Backlash(joint=1))
    cal = identify(ABB, meas, IdentificationOptions(folds=0, effects=effects)).calibration
    doc = json.loads(dumps_calibration(cal))
    assert [(e["kind"], e["joint"]) for e in doc["effects"]] == [
        ("gear_harmonic", 5), ("thermal_expansion", None), ("backlash", 2)]
    assert doc["effects"][0]["order"] == 2 and doc["effects"][0]["unit"] == {"a": "rad", "b": "rad"}
    back = calibration_from_dict(doc)
    assert back.effects == cal.effects
    q = _joints(ABB, 6, 17)
    np.testing.assert_allclose(back.predict_points(q, ["tcp"] * 6), cal.predict_points(q, ["tcp"] * 6))
    # a file written before effects existed has an empty list and still reads
    old = calibration_to_dict(nominal_calibration(ABB))
    assert old["effects"] == [] and calibration_from_dict(old).effects == ()
    bad = json.loads(json.dumps(doc))
    bad["effects"][0]["kind"] = "gear_wobble"
    with pytest.raises(ModelError, match="effects"):
        calibration_from_dict(bad)


@pytest.mark.parametrize("args,message", [
    (("gear_wobble", 1), "unknown effect kind 'gear_wobble'"),
    (("joint_compliance", 6), "joint 7 is out of range"),
    (("thermal_expansion", 2), "give no joint"),
    (("backlash", None), "give its number"),
])
def test_bad_effect_requests_are_data_errors(args, message):
    with pytest.raises(DataError, match=message):
        make_effect(*args, n_joints=6)


def test_thermal_expansion_without_a_temperature_column_is_a_data_error():
    rng = np.random.default_rng(18)
    meas = make_virtual_robot(ABB, 18).measure(_joints(ABB, 30, 19), 0.05e-3, rng)
    with pytest.raises(DataError, match="temperature_c"):
        identify(ABB, meas, IdentificationOptions(effects=(ThermalExpansion(),)))


def test_effect_dict_round_trip():
    for effect in [*EFFECTS, ThermalExpansion(values=(1e-5,), reference_temperature_c=20.5)]:
        effect = effect.with_values(effect.values, std=[1e-7] * effect.n_parameters)
        assert effect_from_dict(json.loads(json.dumps(effect.to_dict())), 6) == effect
    unknown = effect_from_dict(EFFECTS[0].to_dict(), 6)  # std NaN: written as null
    assert EFFECTS[0].to_dict()["std"] == {"c": None} and np.isnan(unknown.std[0])


def test_backlash_follows_the_approach_direction_where_it_is_given(tmp_path):
    from olp_compensate.io.measurements import read_measurements, write_measurements

    virtual = make_virtual_robot(ABB, 20)
    rng = np.random.default_rng(21)
    q = _joints(ABB, 40, 22)
    directions = np.zeros((40, 6))
    directions[:25, 3] = rng.choice([-1.0, 1.0], 25)  # axis 4: known for 25 poses
    hidden = HiddenEffect("backlash", 3, 2e-3)
    meas = replace(virtual, effects=(hidden,)).measure(q, 0.0, rng, directions=directions)
    path = tmp_path / "meas.csv"
    units = [j.unit for j in ABB.joints]
    write_measurements(path, meas, units)
    meas = read_measurements(path, units)
    np.testing.assert_array_equal(meas.directions[:, 3], directions[:, 3])
    result = identify(ABB, meas, IdentificationOptions(folds=0, effects=(Backlash(joint=3),)))
    assert result.residual_rms < 2e-6  # the file rounds to 1 um
    assert result.calibration.effects[0].values[0] == pytest.approx(2e-3, rel=1e-3)


def test_payload_feeds_the_gravity_torque_of_compliance():
    virtual = make_virtual_robot(ABB, 23)
    rng = np.random.default_rng(24)
    q = _joints(ABB, 40, 25)
    payload = rng.choice([0.0, 10.0, 20.0], 40)
    hidden = HiddenEffect("joint_compliance", 4, 5e-5)  # axis 5 mostly carries the payload
    meas = replace(virtual, effects=(hidden,)).measure(q, 0.0, rng, payload_kg=payload)
    result = identify(ABB, meas, IdentificationOptions(folds=0, effects=(JointCompliance(joint=4),)))
    assert result.residual_rms < 3e-6
    cal = result.calibration
    assert cal.effects[0].values[0] == pytest.approx(5e-5, rel=2e-2)
    names = ["tcp"] * 40
    loaded = cal.predict_points(q, names, Conditions(payload_kg=payload))
    np.testing.assert_allclose(loaded, meas.points, atol=1e-5)
    assert np.abs(cal.predict_points(q, names) - meas.points).max() > 1e-4  # payload matters
