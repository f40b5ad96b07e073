"""The stages of :func:`olp_compensate.compensation.ik.solve`, called one by one.

The arms and the independent checks (DH forward kinematics written in test_ik.py, the
triangle inequality of the data-sheet arm) are not the solver's own code.
"""

from __future__ import annotations

import numpy as np

from olp_compensate.compensation.ik import ReachBound, configuration_bits, refine
from olp_compensate.compensation.ik.configuration import flip_wrist
from olp_compensate.compensation.ik.solver import CLOSED_FORM_STEPS, SolveOptions, _BranchSolver
from olp_compensate.programs.object_model.confdata import abb_confdata
from test_ik import (IRB2400, IRB2400_LIMITS, IRB2400_OPW, _arm_forward, _chain, _stretched_elbow,
                     pose_errors)


def _solver(robot, target, confdata, limits=None, reach=None):
    return _BranchSolver(IRB2400_OPW, robot.fk_jacobian, target, confdata, limits,
                         SolveOptions(), reach)


def test_requested_bits_are_those_of_the_joints_that_made_the_target():
    rng = np.random.default_rng(0)
    q = rng.uniform(IRB2400_LIMITS[:, 0], IRB2400_LIMITS[:, 1], (300, 6))
    solver = _solver(IRB2400, IRB2400.fk(q), abb_confdata(IRB2400_OPW, q))
    np.testing.assert_array_equal(solver.requested(np.arange(300)),
                                  configuration_bits(IRB2400_OPW, q))


def test_verdict_marks_joints_on_another_configuration_branch_changed():
    """The flipped wrist reaches the same pose (checked by the DH model) on the other wrist
    configuration: 'branch_changed'; the joints that made the target: 'ok'; the same
    joints with axis 3 outside tightened limits: 'joint_limit'."""
    rng = np.random.default_rng(1)
    q = rng.uniform(IRB2400_LIMITS[:, 0] * 0.8, IRB2400_LIMITS[:, 1] * 0.8, (200, 6))
    q[:, 4] = rng.choice([-1.0, 1.0], 200) * rng.uniform(0.2, 1.5, 200)
    q[:, 3] = rng.uniform(-1.0, 1.0, 200)                   # flipped axis 4 stays in range
    target = IRB2400.fk(q)
    flipped = flip_wrist(IRB2400_OPW, q)
    same_pose = pose_errors(IRB2400.fk(flipped), target)
    assert same_pose[0].max() < 1e-12 and same_pose[1].max() < 1e-12
    rows = np.arange(200)
    solver = _solver(IRB2400, target, abb_confdata(IRB2400_OPW, q), IRB2400_LIMITS)
    assert set(solver.verdict(q, rows)[1]) == {"ok"}
    assert set(solver.verdict(flipped, rows)[1]) == {"branch_changed"}
    tight = IRB2400_LIMITS.copy()
    tight[2] = [np.min(q[:, 2]) + 1e-3, np.max(q[:, 2]) + 1.0]
    _, reason = _solver(IRB2400, target, abb_confdata(IRB2400_OPW, q), tight).verdict(q, rows)
    assert reason[np.argmin(q[:, 2])] == "joint_limit"
    np.testing.assert_array_equal(reason == "joint_limit", q[:, 2] < tight[2, 0])


def test_multi_start_recovers_targets_near_the_wrist_singularity():
    """2 to 20 mrad from axis 5 = 0 on a perturbed arm: Newton from the nominal start alone
    misses some (other configuration, or not converged in 12 steps); the multi-start from
    that same start reaches every one, to 1e-9, on the configuration asked for."""
    rng = np.random.default_rng(3)
    robot = IRB2400.perturbed(rng)
    n = 200
    q = rng.uniform(IRB2400_LIMITS[:, 0] * 0.9, IRB2400_LIMITS[:, 1] * 0.9, (n, 6))
    q[:, 4] = rng.choice([-1.0, 1.0], n) * rng.uniform(2e-3, 2e-2, n)
    target = robot.fk(q)
    conf = abb_confdata(IRB2400_OPW, q)
    solver = _solver(robot, target, conf, IRB2400_LIMITS)
    rows = solver.nominal_start(np.arange(n))
    assert len(rows) == n
    single = solver.check(refine(robot.fk_jacobian, solver.start, target, max_iterations=12),
                          rows)
    assert not single.success.all()
    solver.multi_start(rows, solver.start[rows], solver.start[rows], 12)
    result = solver.result
    assert result.success.all(), dict(zip(*np.unique(result.reason, return_counts=True)))
    reached = pose_errors(robot.fk(result.q), target)
    assert reached[0].max() <= 1e-9 and reached[1].max() <= 1e-9
    np.testing.assert_array_equal(abb_confdata(IRB2400_OPW, result.q)[:, 3], conf[:, 3])


def test_the_multi_start_taken_in_blocks_changes_no_digit(monkeypatch):
    """Targets near the wrist singularity (some need the multi-start), others outside
    tightened axis ranges or out of reach (they go on to the fixed point): :func:`solve`
    with the multi-start three targets at a time gives every joint, reason, error and
    step count of the multi-start of all at once."""
    from olp_compensate.compensation.ik import solver as solver_module

    rng = np.random.default_rng(8)
    robot = IRB2400.perturbed(rng)
    n = 60
    q = rng.uniform(IRB2400_LIMITS[:, 0] * 0.9, IRB2400_LIMITS[:, 1] * 0.9, (n, 6))
    q[:40, 4] = rng.choice([-1.0, 1.0], 40) * rng.uniform(2e-3, 2e-2, 40)
    target = robot.fk(q)
    target[50:, :3, 3] *= 3.0                                   # out of reach
    tight = IRB2400_LIMITS.copy()
    tight[2] = [np.quantile(q[:, 2], 0.2), IRB2400_LIMITS[2, 1]]  # a fifth below axis 3's
    conf = abb_confdata(IRB2400_OPW, q)
    solved = []
    for block in (n, 3):
        monkeypatch.setattr(solver_module, "MULTI_START_BLOCK", block)
        solved.append(_solver(robot, target, conf, tight).solve()[0])
    whole, blocks = solved
    assert {"ok", "joint_limit", "unreachable"} <= set(whole.reason)
    for name in ("q", "reason", "success", "iterations", "position_error_m",
                 "rotation_error_rad"):
        np.testing.assert_array_equal(getattr(blocks, name), getattr(whole, name))


def test_reach_screening_proves_far_targets_unreachable_without_the_retries():
    """Wrist centres 10 um beyond c2 + hypot(a2, c3) from the circle of axis 2 (out of the
    data-sheet arm's reach by the triangle inequality) next to reachable targets: after the
    closed-form stage the screening gives the far ones status 1, so no retry stage has
    a row left: they took at most the closed-form steps."""
    rng = np.random.default_rng(6)
    n = 100
    q = _arm_forward(rng, IRB2400, n, _stretched_elbow(IRB2400))
    far = IRB2400.fk(q)
    c2, k = 0.705, np.hypot(0.135, 0.755)
    centre = far[:, :3, 3] - 0.085 * far[:, :3, 2]
    shoulder = 0.1 * centre[:, :2] / np.linalg.norm(centre[:, :2], axis=1)[:, None]
    outward = centre - np.column_stack([shoulder, np.full(n, 0.615)])
    distance = np.linalg.norm(outward, axis=1)
    far[:, :3, 3] += (c2 + k + 1e-5 - distance)[:, None] * outward / distance[:, None]
    near = _arm_forward(rng, IRB2400, n, _stretched_elbow(IRB2400) + 0.3)
    target = np.concatenate([IRB2400.fk(near), far])
    conf = abb_confdata(IRB2400_OPW, np.concatenate([near, q]))
    solver = _solver(IRB2400, target, conf, reach=ReachBound(*_chain(IRB2400)))
    solver.closed_form_stage()
    assert solver.result.success[:n].all() and not solver.result.success[n:].any()
    solver.screen_reach()
    np.testing.assert_array_equal(solver.status[n:], 1)
    assert len(solver.failed_rows()) == 0
    assert solver.result.iterations[n:].max() <= CLOSED_FORM_STEPS
    solver.fixed_point_retry()                   # nothing left to retry: nothing changes
    assert solver.result.iterations[n:].max() <= CLOSED_FORM_STEPS


def test_fixed_point_retry_solves_what_the_first_stages_left():
    """With one Newton step allowed per stage, the closed-form stage leaves targets of a
    perturbed arm unsolved; the fixed point onto the model (20 closed-form steps) and
    refine reach them on the configuration asked for."""
    rng = np.random.default_rng(4)
    robot = IRB2400.perturbed(rng)
    q = rng.uniform(IRB2400_LIMITS[:, 0] * 0.9, IRB2400_LIMITS[:, 1] * 0.9, (100, 6))
    target = robot.fk(q)
    conf = abb_confdata(IRB2400_OPW, q)
    solver = _BranchSolver(IRB2400_OPW, robot.fk_jacobian, target, conf, IRB2400_LIMITS,
                           SolveOptions(max_iterations=1), None)
    solver.closed_form_stage()
    left = solver.failed_rows()
    assert len(left) > 50
    solver.fixed_point_retry()
    assert solver.result.success[left].all()
    reached = pose_errors(robot.fk(solver.result.q[left]), target[left])
    assert reached[0].max() <= 1e-9 and reached[1].max() <= 1e-9
    np.testing.assert_array_equal(abb_confdata(IRB2400_OPW, solver.result.q[left])[:, 3],
                                  conf[left, 3])


def test_without_retries_the_rows_reached_at_once_are_the_same_and_the_others_left():
    """Targets near the wrist singularity of a perturbed arm, some of which only the
    retries reach: ``retries=False`` stops after the closed-form stage; the rows it reports
    reached are bit for bit the full solve's, the rows it leaves failed are the ones the
    retries work on (and reach), and they took no retry steps."""
    rng = np.random.default_rng(3)
    robot = IRB2400.perturbed(rng)
    n = 200
    q = rng.uniform(IRB2400_LIMITS[:, 0] * 0.9, IRB2400_LIMITS[:, 1] * 0.9, (n, 6))
    q[:, 4] = rng.choice([-1.0, 1.0], n) * rng.uniform(2e-3, 2e-2, n)
    target, conf = robot.fk(q), abb_confdata(IRB2400_OPW, q)
    full = _BranchSolver(IRB2400_OPW, robot.fk_jacobian, target, conf, IRB2400_LIMITS,
                         SolveOptions(max_iterations=12), None).solve()[0]
    first = _BranchSolver(IRB2400_OPW, robot.fk_jacobian, target, conf, IRB2400_LIMITS,
                          SolveOptions(max_iterations=12, retries=False), None).solve()[0]
    assert full.success.all()
    left = ~first.success
    assert 0 < left.sum() < n
    np.testing.assert_array_equal(first.q[~left], full.q[~left])
    assert first.iterations[left].max() <= CLOSED_FORM_STEPS
