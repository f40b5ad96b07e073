"""Pose planning: planned poses are valid, beat random ones on the criterion and on the truth,
and the CLI plans a campaign that olp-cal simulate can measure."""

import numpy as np
import pytest

from olp_compensate.calibration.identify import IdentificationOptions, identify
from olp_compensate.calibration.pose_planning import (_Design, design_quality, plan_poses,
                                                      planning_space)
from olp_compensate.calibration.simulate import make_virtual_robot, random_joints
from olp_compensate.cli.cal import main
from olp_compensate.errors import DataError
from olp_compensate.io.measurements import read_measurements
from olp_compensate.io.poses import read_poses
from olp_compensate.kinematics.robot import load_robot

NOISE = 0.05e-3


@pytest.fixture(scope="module")
def robot():
    return load_robot("abb_irb2400")


@pytest.fixture(scope="module")
def space(robot):
    return planning_space(robot, n_candidates=3000, seed=1)


def test_planned_poses_are_candidates_within_the_joint_limits(robot, space):
    plan = plan_poses(space, 15)
    assert plan.joints.shape == (15, robot.n_joints)
    assert len(set(plan.indices.tolist())) == 15
    np.testing.assert_array_equal(plan.joints, space.candidates[plan.indices])
    urdf = robot.joints_from_controller(plan.joints)
    assert np.all(urdf >= robot.lower_limits) and np.all(urdf <= robot.upper_limits)
    # the same unknowns identify fits: registration, free geometry, one tool point
    assert plan.n_unknowns == 27 and {"j1.theta", "j1.d", "j6.theta"} <= set(plan.frozen)


@pytest.mark.parametrize("criterion", ["d", "i"])
def test_plan_beats_every_random_set_on_the_criterion(space, criterion):
    plan = plan_poses(space, 15, criterion)
    rng = np.random.default_rng(7)
    random = [design_quality(space, rng.choice(len(space.candidates), 15, replace=False))
              for _ in range(30)]
    if criterion == "d":
        assert plan.quality.log_det > max(q.log_det for q in random)
    else:
        assert plan.quality.expected_error < min(q.expected_error for q in random)
    assert plan.quality.expected_error < 0.8 * plan.random.expected_error


def test_rank_updates_match_a_fresh_design(space):
    rng = np.random.default_rng(3)
    chosen = list(rng.choice(len(space.candidates), 12, replace=False))
    design = _Design(space.blocks, chosen, space.test_information)
    swapped = design.values_after_swapping(chosen[4], "i")
    design.update(chosen[4], -1.0)
    design.update(99, +1.0)
    chosen[4] = 99
    fresh = _Design(space.blocks, chosen, space.test_information)
    for name in ("minv", "d", "q", "e"):
        np.testing.assert_allclose(getattr(design, name), getattr(fresh, name),
                                   rtol=1e-9, atol=1e-9 * np.abs(getattr(fresh, name)).max())
    assert swapped[99] == pytest.approx(-fresh.phi, rel=1e-10)
    assert fresh.log_det == pytest.approx(design.log_det, rel=1e-10)


def test_minimum_distance_between_planned_poses(robot, space):
    plan = plan_poses(space, 15, min_distance_deg=20.0)
    degrees = robot.to_degrees_or_mm(plan.joints)
    gaps = np.max(np.abs(degrees[:, None] - degrees[None]), axis=2)
    assert np.all(gaps[~np.eye(15, dtype=bool)] >= 20.0)


def test_too_few_poses_is_refused(space):
    with pytest.raises(DataError, match="at least 10 poses"):
        plan_poses(space, 9)


def _error_at_new_poses(robot, seed, joints=None, count=15):
    """Mean squared 3-D error (m^2) at 300 new poses of the model identified from ``joints``
    (default ``count`` random poses) on virtual robot ``seed``."""
    virtual = make_virtual_robot(robot, seed)
    rng = np.random.default_rng(100 + seed)
    q = random_joints(robot, count, rng) if joints is None else joints
    result = identify(robot, virtual.measure(q, NOISE, rng), IdentificationOptions(folds=0))
    test = random_joints(robot, 300, np.random.default_rng(200 + seed))
    names = np.array(["tcp"] * len(test), dtype=object)
    diff = result.calibration.predict_points(test, names) - virtual.true_points(test, names)
    return np.mean(np.sum(diff**2, axis=1))


def test_planned_poses_identify_better_than_random_ones(robot, space):
    """15 planned poses against 15 random ones on the same 4 virtual robots (truth at 300
    new poses). Measured: planned ~1.4x the noise, random ~2.5x."""
    plan = plan_poses(space, 15)
    seeds = range(40, 44)
    planned = np.sqrt(np.mean([_error_at_new_poses(robot, s, plan.joints) for s in seeds]))
    random = np.sqrt(np.mean([_error_at_new_poses(robot, s) for s in seeds]))
    assert planned < 0.8 * random
    assert planned < 2.0 * NOISE


def test_cli_plan_then_simulate_the_campaign(tmp_path, robot, capsys):
    poses, meas = tmp_path / "poses.csv", tmp_path / "meas.csv"
    assert main(["plan", "--robot", "abb_irb2400", "--poses", "12", "--candidates", "1500",
                 "--seed", "2", "-o", str(poses)]) == 0
    out = capsys.readouterr().out
    assert "expected model error" in out and "random poses" in out and "12 poses" in out
    header = [ln for ln in poses.read_text().splitlines() if not ln.startswith("#")][0]
    assert header == "pose,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg"
    planned = read_poses(poses, [j.unit for j in robot.joints])
    assert len(planned.joints) == 12
    assert main(["simulate", "--robot", "abb_irb2400", "--joints", str(poses), "--seed", "5",
                 "--points", "2", "-o", str(meas)]) == 0
    measured = read_measurements(meas, [j.unit for j in robot.joints])
    assert measured.n_poses == 12 and measured.n_rows == 24
    np.testing.assert_allclose(measured.joints[::2], planned.joints, atol=1e-7)
    assert list(measured.pose_ids[::2]) == planned.pose_ids
    assert main(["identify", str(meas), "--robot", "abb_irb2400", "--folds", "0"]) == 0


def test_cli_plan_from_given_candidates(tmp_path, robot, capsys):
    from olp_compensate.io.poses import write_poses

    given = tmp_path / "reachable.csv"
    write_poses(given, random_joints(robot, 400, np.random.default_rng(9)),
                [j.unit for j in robot.joints])
    out = tmp_path / "poses.csv"
    assert main(["plan", "--robot", "abb_irb2400", "--poses", "15", "--from", str(given),
                 "--criterion", "d", "-o", str(out)]) == 0
    chosen = read_poses(out, [j.unit for j in robot.joints]).joints
    pool = read_poses(given, [j.unit for j in robot.joints]).joints
    assert all(np.any(np.all(np.abs(pool - q) < 1e-9, axis=1)) for q in chosen)


@pytest.mark.parametrize("argv, words", [
    (["plan", "--robot", "abb_irb2400", "--poses", "5"], "at least 10 poses"),
    (["plan", "--robot", "no_such_robot", "--poses", "15"], "unknown robot"),
    (["plan", "--robot", "abb_irb2400", "--poses", "15", "--tool", "1,2"], "--tool"),
    (["plan", "--robot", "abb_irb2400", "--poses", "15", "--freeze", "j9.a"], "j9.a"),
])
def test_cli_plan_bad_input_is_one_line(tmp_path, capsys, argv, words):
    out = tmp_path / "poses.csv"
    assert main(argv + ["-o", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("olp-cal: error:") and words in err[0]
    assert not out.exists()


def test_cli_simulate_joints_bad_input(tmp_path, capsys):
    poses = tmp_path / "poses.csv"
    poses.write_text("pose,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n1,0,0,0,0,0,0\n"
                     "2,0,0,0,0,500,0\n")
    out = tmp_path / "meas.csv"
    assert main(["simulate", "--robot", "abb_irb2400", "--joints", str(poses), "-o", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "poses.csv:3" in err[0] and "q5" in err[0]
    assert main(["simulate", "--robot", "abb_irb2400", "--joints", str(poses), "--poses", "3",
                 "-o", str(out)]) == 1
    assert "either --poses" in capsys.readouterr().err


def test_csv_rows_of_another_width_are_refused_with_file_and_line():
    """Pose lists and measurements share one row loop: blank and '#' rows are skipped, a
    row with more or fewer fields than the header names its line."""
    from olp_compensate.errors import DataError
    from olp_compensate.io.measurements import parse_measurements
    from olp_compensate.io.poses import parse_poses

    units = ["deg"] * 6
    poses = "pose,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n1,0,0,0,0,0,0\n\n# note\n2,0,0,0,0,0\n"
    with pytest.raises(DataError, match=r"^p\.csv:5: 6 fields, the header has 7$"):
        parse_poses(poses, units, "p.csv")
    meas = ("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,x_mm,y_mm,z_mm\n"
            "0,0,0,0,0,0,1,2,3\n#c\n0,0,0,0,0,0,1,2,3,4\n")
    with pytest.raises(DataError, match=r"^m\.csv:4: 10 fields, the header has 9$"):
        parse_measurements(meas, units, "m.csv")
    assert len(parse_poses(poses.rsplit("2,", 1)[0], units, "p.csv").joints) == 1
