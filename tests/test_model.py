"""The calibration model against independent truth: pinocchio FK and finite differences."""

import numpy as np
import pytest

from olp_compensate.kinematics.model import (build_model, fixed_chain, forward, joint_frames,
                                             spread_joints)
from olp_compensate.kinematics.robot import bundled_robot_names, load_robot
from olp_compensate.calibration.simulate import random_joints
from urdf_factory import IRB2400_DH, dh_urdf
from olp_compensate.kinematics.robot import robot_from_urdf_text


@pytest.mark.parametrize("name", bundled_robot_names())
def test_nominal_model_matches_pinocchio(name):
    import pinocchio as pin

    robot = load_robot(name)
    model = build_model(robot)
    rng = np.random.default_rng(0)
    q_ctrl = random_joints(robot, 25, rng)
    q = robot.joints_from_controller(q_ctrl)
    ours = forward(model, model.nominal, q).flange
    pm = robot.pinocchio_model
    data = pm.createData()
    frame = pm.getFrameId("tool0")
    for qk, pose in zip(q, ours):
        pin.framesForwardKinematics(pm, data, qk)
        np.testing.assert_allclose(pose, data.oMf[frame].homogeneous, atol=1e-12)


def test_parallel_axes_get_hayati_and_others_dh():
    model = build_model(load_robot("abb_irb2400"))
    assert model.conventions == ("dh", "hayati", "dh", "dh", "dh")
    ur = build_model(load_robot("ur5e"))
    assert ur.conventions == ("dh", "hayati", "hayati", "dh", "dh")
    assert build_model(load_robot("abb_irb2400"), "dh").conventions == ("dh",) * 5


@pytest.mark.parametrize("name,convention", [("abb_irb2400", "auto"), ("ur5e", "auto"),
                                             ("unimation_puma560", "dh")])
def test_analytic_jacobian_matches_central_differences(name, convention):
    robot = load_robot(name)
    model = build_model(robot, convention)
    rng = np.random.default_rng(1)
    values = model.nominal + rng.normal(0, 1e-3, model.n_parameters)
    q = robot.joints_from_controller(random_joints(robot, 7, rng))
    tool = rng.normal(0, 0.1, (7, 3))
    res = forward(model, values, q, tool, jacobian=True)
    h = 1e-6
    for k in range(model.n_parameters):
        dv = np.zeros_like(values)
        dv[k] = h
        plus = forward(model, values + dv, q, tool)
        minus = forward(model, values - dv, q, tool)
        np.testing.assert_allclose(res.dpoint_dparam[:, :, k], (plus.points - minus.points) / (2 * h),
                                   atol=1e-8)
        # angular part: the skew part of R_plus R_minus^T is skew(omega * 2h) + O(h^3)
        rel = plus.flange[:, :3, :3] @ np.swapaxes(minus.flange[:, :3, :3], 1, 2)
        omega = np.stack([rel[:, 2, 1] - rel[:, 1, 2], rel[:, 0, 2] - rel[:, 2, 0],
                          rel[:, 1, 0] - rel[:, 0, 1]], axis=1) / (4 * h)
        np.testing.assert_allclose(res.drot_dparam[:, :, k], omega, atol=1e-7)
    for j in range(model.n_joints):
        dq = np.zeros_like(q)
        dq[:, j] = h
        plus = forward(model, values, q + dq, tool).points
        minus = forward(model, values, q - dq, tool).points
        np.testing.assert_allclose(res.dpoint_dq[:, :, j], (plus - minus) / (2 * h), atol=1e-8)


def test_dh_table_robot_built_in_code_matches_its_table():
    from urdf_factory import dh_forward

    robot = robot_from_urdf_text(dh_urdf(IRB2400_DH))
    model = build_model(robot)
    q = np.random.default_rng(2).uniform(-3, 3, (20, 6))
    np.testing.assert_allclose(forward(model, model.nominal, q).flange, dh_forward(IRB2400_DH, q),
                               atol=1e-9)


def _central_differences(model, values, q, tool, h=1e-6):
    """(dpoint/dparam (m, 3, P), dpoint/dq (m, 3, n)) by central differences."""
    dpar = np.zeros((len(q), 3, model.n_parameters))
    for k in range(model.n_parameters):
        dv = np.zeros_like(values)
        dv[k] = h
        dpar[:, :, k] = (forward(model, values + dv, q, tool).points
                         - forward(model, values - dv, q, tool).points) / (2 * h)
    dq = np.zeros((len(q), 3, model.n_joints))
    for j in range(model.n_joints):
        step = np.zeros_like(q)
        step[:, j] = h
        dq[:, :, j] = (forward(model, values, q + step, tool).points
                       - forward(model, values, q - step, tool).points) / (2 * h)
    return dpar, dq


def test_jacobian_of_chains_that_share_parameters_or_joints():
    """Steps sharing a parameter and a joint moving two steps take forward's general path
    (sums over steps), a prismatic joint its translation branch."""
    import dataclasses

    robot = load_robot("abb_irb2400")
    model = build_model(robot)
    steps = list(model.steps)
    steps[6] = dataclasses.replace(steps[6], parameter=2)  # two steps, one parameter
    steps[1] = dataclasses.replace(steps[1], joint=2)  # joint 3 moves a second step
    moving = [s for s, step in enumerate(model.steps) if step.joint == 1][0]
    prismatic = list(model.steps)
    prismatic[moving] = dataclasses.replace(prismatic[moving], rotation=False)
    rng = np.random.default_rng(3)
    q = robot.joints_from_controller(random_joints(robot, 5, rng))
    tool = rng.normal(0, 0.1, (5, 3))
    for variant in (dataclasses.replace(model, steps=tuple(steps)),
                    dataclasses.replace(model, steps=tuple(prismatic))):
        values = variant.nominal + rng.normal(0, 1e-3, variant.n_parameters)
        res = forward(variant, values, q, tool, jacobian=True)
        dpar, dq = _central_differences(variant, values, q, tool)
        np.testing.assert_allclose(res.dpoint_dparam, dpar, atol=1e-8)
        np.testing.assert_allclose(res.dpoint_dq, dq, atol=1e-8)


def test_derivatives_are_not_overwritten_by_later_evaluations():
    """forward reuses its derivative block only once nothing refers to it any more."""
    robot = load_robot("abb_irb2400")
    model = build_model(robot)
    q = robot.joints_from_controller(random_joints(robot, 20, np.random.default_rng(4)))
    first = forward(model, model.nominal, q, jacobian=True)
    kept = first.drot_dq  # one view is enough to keep the block
    expected = {name: getattr(first, name).copy()
                for name in ("dpoint_dparam", "drot_dparam", "dpoint_dq", "drot_dq")}
    del first
    for shift in (1e-3, 2e-3, 3e-3):  # released results are recycled, the kept one is not
        forward(model, model.nominal + shift, q, jacobian=True)
    np.testing.assert_array_equal(kept, expected["drot_dq"])
    again = forward(model, model.nominal, q, jacobian=True)
    for name, value in expected.items():
        np.testing.assert_array_equal(getattr(again, name), value)


@pytest.mark.parametrize("name", bundled_robot_names())
def test_fixed_chain_is_the_model_at_fixed_values(name):
    """The fused per-joint chain (used by inverse kinematics) gives the poses and joint
    Jacobian of forward(), at the nominal values and at perturbed ones (a calibrated arm),
    and knows its joint frames at zero."""
    robot = load_robot(name)
    model = build_model(robot)
    rng = np.random.default_rng(5)
    q = random_joints(robot, 500, rng)
    for values in (model.nominal, model.nominal + rng.normal(0, 1e-3, model.n_parameters)):
        chain = fixed_chain(model, values)
        assert chain is not None   # every bundled arm is six revolute joints
        pose, jac = chain.flange_and_jacobian(q)
        ref = forward(model, values, q, jacobian=True)
        np.testing.assert_allclose(pose, ref.flange, rtol=0, atol=1e-12)
        np.testing.assert_allclose(jac, np.concatenate([ref.dpoint_dq, ref.drot_dq], axis=1),
                                   rtol=0, atol=1e-12)
        many = np.concatenate([q] * 9)[:4100]   # more than one block of FixedChain.flange
        np.testing.assert_allclose(chain.flange(many), np.concatenate([ref.flange] * 9)[:4100],
                                   rtol=0, atol=1e-12)
        frames, flange = chain.frames()
        np.testing.assert_allclose(frames, joint_frames(model, values, np.zeros(6)), atol=1e-12)
        np.testing.assert_allclose(flange, forward(model, values, np.zeros((1, 6))).flange[0],
                                   atol=1e-12)


def test_spread_joints_cover_every_axis_and_depend_only_on_the_seed():
    """The configurations that check a fixed chain and a fitted IK family reach near both
    ends of [-pi, pi] on every axis, in every third of it, and are distinct per seed."""
    q = spread_joints(50, 6)
    assert q.shape == (50, 6) and np.all(np.abs(q) <= np.pi)
    np.testing.assert_array_equal(q, spread_joints(50, 6, 0))
    assert q.min(axis=0).max() < -0.9 * np.pi and q.max(axis=0).min() > 0.9 * np.pi
    for lo, hi in ((-np.pi, -np.pi / 3), (-np.pi / 3, np.pi / 3), (np.pi / 3, np.pi)):
        assert np.all(np.sum((q >= lo) & (q < hi), axis=0) >= 5)
    assert not np.any(np.isclose(q[:, None, :], spread_joints(50, 6, 1)[None]).all(axis=2))


def test_a_reusable_array_is_never_handed_out_while_something_refers_to_it():
    from olp_compensate.kinematics.buffers import reusable_array
    first = reusable_array("test-pool", (4, 5), slots=2)
    view = first[1:]
    second = reusable_array("test-pool", (4, 5), slots=2)
    assert second is not first                # `first` itself is still held
    del first
    assert reusable_array("test-pool", (4, 5), slots=2) is not view.base  # the view holds it
    del view, second
    again = reusable_array("test-pool", (4, 5), slots=2)
    assert reusable_array("test-pool", (4, 5), slots=2) is not again


def test_forward_jacobians_of_two_evaluations_do_not_share_memory():
    robot = load_robot("abb_irb2400")
    model = build_model(robot)
    rng = np.random.default_rng(3)
    q1, q2 = rng.uniform(-1, 1, (2, 50, 6))
    a = forward(model, model.nominal, q1, jacobian=True)
    kept = a.dpoint_dparam.copy()
    b = forward(model, model.nominal, q2, jacobian=True)
    np.testing.assert_array_equal(a.dpoint_dparam, kept)  # b did not write into a's block
    assert not np.shares_memory(a.dpoint_dparam, b.dpoint_dparam)


def test_batched_joint_frames_equal_one_by_one():
    from olp_compensate.kinematics.model import joint_frames_batch

    for name in ("abb_irb2400", "fanuc_r2000ic_165f", "ur5e"):
        robot = load_robot(name)
        model = build_model(robot)
        q = np.random.default_rng(3).uniform(-2.0, 2.0, (20, robot.n_joints))
        batch = joint_frames_batch(model, model.nominal, q)
        for row, frames in zip(q, batch):
            assert np.array_equal(frames, joint_frames(model, model.nominal, row))
