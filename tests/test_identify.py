"""Identification against virtual robots whose truth is known (pinocchio on a perturbed URDF)."""

import numpy as np
import pytest

from olp_compensate.kinematics.conventions import rotation_from_rotvec
from olp_compensate.errors import DataError
from olp_compensate.calibration.cross_validation import pose_folds
from olp_compensate.calibration.identify import IdentificationOptions, identify
from olp_compensate.calibration.unknowns import UnknownLayout
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.calibration.simulate import make_virtual_robot, random_joints

NOISE = 0.05e-3


def _truth_equivalent(robot, virtual):
    """The model parameters equivalent to the virtual robot: a noise-free fit on many poses."""
    rng = np.random.default_rng(99)
    meas = virtual.measure(random_joints(robot, 400, rng), 0.0, rng)
    result = identify(robot, meas, IdentificationOptions(folds=0))
    assert result.residual_max < 1e-9  # the model is complete: it reproduces the truth exactly
    return result.calibration.values


def test_recovers_virtual_robot_within_three_reported_sigmas():
    robot = load_robot("abb_irb2400")
    virtual = make_virtual_robot(robot, seed=5)
    truth = _truth_equivalent(robot, virtual)
    rng = np.random.default_rng(6)
    result = identify(robot, virtual.measure(random_joints(robot, 40, rng), NOISE, rng))
    cal = result.calibration
    free = ~np.isnan(cal.std)
    z = np.abs(cal.values[free] - truth[free]) / cal.std[free]
    assert np.all(z < 3.0), dict(zip(np.array(cal.model.names)[free], z.round(2)))
    assert 0.7 * NOISE * np.sqrt(3) < result.heldout_rms < 1.5 * NOISE * np.sqrt(3)


@pytest.mark.slow
def test_reported_deviations_agree_with_monte_carlo():
    robot = load_robot("abb_irb2400")
    virtual = make_virtual_robot(robot, seed=8)
    joints = random_joints(robot, 30, np.random.default_rng(9))
    estimates, reported = [], []
    for run in range(40):
        rng = np.random.default_rng(100 + run)
        result = identify(robot, virtual.measure(joints, NOISE, rng), IdentificationOptions(folds=0))
        estimates.append(result.calibration.values)
        reported.append(result.calibration.std)
    free = ~np.isnan(reported[0])
    empirical = np.std(np.array(estimates)[:, free], axis=0, ddof=1)
    predicted = np.mean(np.array(reported)[:, free], axis=0)
    ratio = empirical / predicted
    # 40 runs: the sample std is within about +-25 % of the true one (2 sigma)
    assert np.all((ratio > 0.6) & (ratio < 1.5)), ratio


def test_pose_set_without_joint_4_motion_names_what_it_cannot_separate():
    robot = load_robot("abb_irb2400")
    virtual = make_virtual_robot(robot, seed=2)
    rng = np.random.default_rng(3)
    joints = random_joints(robot, 40, rng)
    joints[:, 3] = np.radians(12.0)
    result = identify(robot, virtual.measure(joints, NOISE, rng))
    inseparable = {name for name, why in result.identifiability.frozen.items()
                   if "cannot be separated" in why}
    assert inseparable, result.identifiability.frozen
    assert all(name.startswith(("j3.", "j4.", "j5.")) for name in inseparable), inseparable
    assert result.heldout_rms < 3 * NOISE * np.sqrt(3)


@pytest.mark.parametrize("angle_deg", [90.0, 179.0, 180.0])
def test_device_far_away_and_rotated_converges(angle_deg):
    robot = load_robot("ur5e")
    virtual = make_virtual_robot(robot, seed=4)
    device = np.eye(4)
    device[:3, :3] = rotation_from_rotvec(np.radians(angle_deg) * np.array([0.6, 0.0, 0.8]))
    device[:3, 3] = [3.0, -4.0, 0.5]  # about 5 m away
    from dataclasses import replace
    virtual = replace(virtual, device_T_base=device)
    rng = np.random.default_rng(7)
    result = identify(robot, virtual.measure(random_joints(robot, 30, rng), NOISE, rng))
    assert result.residual_rms < 2 * NOISE * np.sqrt(3)
    np.testing.assert_allclose(result.calibration.device_T_base[:3, 3], device[:3, 3], atol=5e-3)


def test_several_points_per_pose_leave_the_last_joint_zero_to_the_tools():
    # Turning every tool point about axis 6 is the same as changing j6.theta, however many
    # points a pose has: j6.theta is held (with that reason), not a tool coordinate.
    robot = load_robot("abb_irb2400")
    virtual = make_virtual_robot(robot, seed=11, n_points=3)
    rng = np.random.default_rng(12)
    result = identify(robot, virtual.measure(random_joints(robot, 25, rng), NOISE, rng))
    frozen = result.identifiability.frozen
    assert "redundant with the tools" in frozen["j6.theta"]
    assert not [name for name in frozen if name.startswith("tool.")], frozen
    assert not result.identifiability.weak
    assert set(result.calibration.tools) == {"tcp", "p2", "p3"}
    for name, point in virtual.tools.items():
        np.testing.assert_allclose(result.calibration.tools[name].xyz_m, point, atol=2e-3)


def test_robust_fit_lists_the_outliers():
    robot = load_robot("abb_irb2400")
    virtual = make_virtual_robot(robot, seed=13)
    rng = np.random.default_rng(14)
    meas = virtual.measure(random_joints(robot, 40, rng), NOISE, rng)
    meas.points[[5, 17]] += [[2e-3, 0, 0], [0, -3e-3, 1e-3]]
    result = identify(robot, meas, IdentificationOptions(robust=True))
    assert sorted(result.outlier_rows) == [6, 18]
    assert result.residual_rms < 1.5 * NOISE * np.sqrt(3)


def test_trust_region_solver_agrees_with_levenberg_marquardt():
    robot = load_robot("unimation_puma560")
    virtual = make_virtual_robot(robot, seed=15)
    rng = np.random.default_rng(16)
    meas = virtual.measure(random_joints(robot, 30, rng), NOISE, rng)
    lm = identify(robot, meas, IdentificationOptions(folds=0))
    trf = identify(robot, meas, IdentificationOptions(folds=0, solver="trf"))
    np.testing.assert_allclose(lm.calibration.values, trf.calibration.values, atol=1e-7)


def test_too_few_equations_is_a_clear_error():
    robot = load_robot("abb_irb2400")
    virtual = make_virtual_robot(robot, seed=1)
    rng = np.random.default_rng(1)
    with pytest.raises(DataError, match="equations"):
        identify(robot, virtual.measure(random_joints(robot, 8, rng), NOISE, rng))


def _folds_by_membership(pose_ids, k):
    """The fold assignment as first published (README figures rest on it): the sorted
    distinct ids, permuted with seed 0, cut into k near-equal parts; a row is in the fold
    whose part holds its id (one membership test per row and fold)."""
    unique = sorted(set(pose_ids.tolist()))
    order = np.random.default_rng(0).permutation(len(unique))
    parts = np.array_split(np.array(unique, dtype=object)[order], k)
    return [np.array([pid in set(part.tolist()) for pid in pose_ids]) for part in parts]


@pytest.mark.parametrize("seed", range(6))
def test_pose_folds_keep_the_published_assignment(seed):
    rng = np.random.default_rng(seed)
    n_poses = int(rng.integers(2, 60))
    # ids as a user writes them: numbers (lexical order differs from numeric), names
    ids = [str(v) for v in rng.choice(10_000, n_poses, replace=False)]
    ids = [f"P{v}" if rng.random() < 0.3 else v for v in ids]
    rows = rng.permutation(np.repeat(ids, rng.integers(1, 4, n_poses)))  # repeated poses
    for dtype in (object, str):
        pose_ids = np.array(rows, dtype=dtype)
        for k in sorted({2, 3, 5, n_poses}):
            folds = pose_folds(pose_ids, k)
            expected = _folds_by_membership(pose_ids, k)
            assert len(folds) == k
            for got, want in zip(folds, expected):
                np.testing.assert_array_equal(got, want)
            assert np.array_equal(np.sum(folds, axis=0), np.ones(len(rows)))  # a partition


def test_unknown_layout_names_every_unknown_once_in_order():
    layout = UnknownLayout.build(geometry_names=["j1.a", "j2.beta"], tool_names=["p2", "tcp"],
                                 rotated_tools=["tcp"],
                                 effect_names=[["joint_compliance j2.c"],
                                               ["gear_harmonic k=1 j3.a",
                                                "gear_harmonic k=1 j3.b"]])
    names = layout.names()
    assert layout.size == len(names) == 6 + 2 + 6 + 3 + 3
    groups = [layout.registration, layout.geometry, layout.tool_points, layout.tool_rotations,
              *layout.effects]
    covered = np.concatenate([np.arange(layout.size)[g] for g in groups])
    np.testing.assert_array_equal(covered, np.arange(layout.size))  # in order, no gap, no overlap
    assert names[layout.geometry] == ["j1.a", "j2.beta"]
    assert names[layout.tool_point(1)] == ["tool.tcp.x", "tool.tcp.y", "tool.tcp.z"]
    assert names[layout.tool_rotation(0)] == ["tool.tcp.rx", "tool.tcp.ry", "tool.tcp.rz"]
    assert names[layout.registration_rotation] == ["base.rx", "base.ry", "base.rz"]
    assert names[layout.effects[1]] == ["gear_harmonic k=1 j3.a", "gear_harmonic k=1 j3.b"]
    assert layout.n_geometric == layout.effect_block.start == 6 + 2 + 6 + 3
    assert [layout.count(g) for g in groups] == [6, 2, 6, 3, 1, 2]


def test_result_layout_places_the_tool_deviations():
    robot = load_robot("abb_irb2400")
    virtual = make_virtual_robot(robot, seed=21, n_points=2)
    rng = np.random.default_rng(22)
    result = identify(robot, virtual.measure(random_joints(robot, 20, rng), NOISE, rng),
                      IdentificationOptions(folds=0))
    layout = result.layout
    names = result.unknown_names
    assert names[layout.tool_point(0)] == ["tool.p2.x", "tool.p2.y", "tool.p2.z"]
    std = result.calibration.tools["tcp"].std_m
    np.testing.assert_array_equal(result.unknown_std[layout.tool_point(1)], std)
    free = ~np.isnan(result.calibration.std)
    assert list(np.array(result.calibration.model.names)[free]) == names[layout.geometry]


def test_an_unknown_parameter_to_freeze_is_named_in_library_terms():
    robot = load_robot("abb_irb2400")
    virtual = make_virtual_robot(robot, seed=1)
    rng = np.random.default_rng(1)
    meas = virtual.measure(random_joints(robot, 20, rng), NOISE, rng)
    with pytest.raises(DataError, match=r"IdentificationOptions\.freeze: no parameter named "
                                        r"'j9\.zz'") as error:
        identify(robot, meas, IdentificationOptions(freeze=("j9.zz",)))
    assert "--" not in str(error.value)
    with pytest.raises(DataError, match=r"IdentificationOptions\.solver"):
        identify(robot, meas, IdentificationOptions(solver="newton"))
