"""Targets that fail, solved with less repeated work and the same answers (issue 32, item 3):

- the solver, told that the configuration rule follows (``ruled``), stops the targets the
  reach bound proves out of reach after the closed form's first steps: the same verdicts,
  fewer steps, and the rule's final statuses and joints are those without it;
- the notes of a batch of joint_limit targets name each row's own axes (the words of all
  rows are converted at once);
- turning joints toward the controller's ranges is what an enumeration of the turns of
  each axis gives (the candidates of the search are turned so).
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from olp_compensate.calibration.simulate import random_joints
from olp_compensate.compensation.config_rule import decide, turn_toward_ranges
from olp_compensate.compensation.failures import explain_failures
from olp_compensate.compensation.ik import solve
from olp_compensate.compensation.pose import Compensator
from olp_compensate.kinematics.robot import load_robot
from virtual_world import identified_world


@pytest.fixture(scope="module")
def world():
    robot = load_robot("abb_irb2400")
    virtual, cal = identified_world(robot, 3)
    return Compensator(cal)


def _targets(comp: Compensator, n: int, seed: int, far_every: int = 3):
    """Flange poses of n random joints inside the ranges (URDF rad) and their confdata;
    every ``far_every``-th moved 2.5x away from the base (out of reach: further than the
    arm's length from axis 2 whatever the joints)."""
    robot = comp.robot
    q = robot.joints_from_controller(random_joints(robot, n, np.random.default_rng(seed),
                                                   margin=0.3))
    desired = comp.nominal_flange(q)
    far = np.arange(n) % far_every == 0
    desired[far, :3, 3] *= 2.5
    return desired, comp.confdata(q), far


def _reach_of_arm(comp: Compensator) -> float:
    """An upper bound (m) of the distance from the base origin to the flange: the sum of
    the distances between consecutive joint origins and to the flange, at zero."""
    frames = comp.robot.joint_frames_at_zero()
    points = np.concatenate([[np.zeros(3)], frames[:, :3, 3],
                             [comp.robot.flange_at_zero()[:3, 3]]])
    return float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1))) * 1.05


def test_the_ruled_solver_stops_proven_targets_early_with_the_same_answers(world):
    comp = world
    desired, confdata, far = _targets(comp, 60, seed=11)
    assert np.all(np.linalg.norm(desired[far, :3, 3], axis=1) > _reach_of_arm(comp))
    args = (comp.family, comp.real_flange_and_jacobian, desired, confdata, comp.limits)
    plain = solve(*args, reach=comp.reach)
    ruled = solve(*args, reach=comp.reach, ruled=True)
    # the same verdict on every target; the far ones unreachable, with fewer steps
    assert list(ruled.reason) == list(plain.reason)
    assert np.all(ruled.reason[far] == "unreachable")
    assert np.sum(ruled.iterations[far]) < np.sum(plain.iterations[far])
    reached = plain.success
    assert np.allclose(ruled.q[reached], plain.q[reached], atol=1e-9)
    # the rule's final statuses and joints: the same with and without
    ruled_final = decide(comp, comp.check_axis_ranges(ruled), desired, confdata)
    plain_final = decide(comp, comp.check_axis_ranges(plain), desired, confdata)
    assert list(ruled_final.reason) == list(plain_final.reason)
    assert np.allclose(ruled_final.q, plain_final.q, atol=1e-9, equal_nan=True)
    assert np.allclose(ruled_final.position_error_m, plain_final.position_error_m,
                       rtol=1e-9, equal_nan=True)
    # what a caller of compensate_flanges gets (the solver told that the rule follows)
    _, _, through, _ = comp.compensate_flanges(desired, None, confdata)
    assert list(through.reason) == list(plain_final.reason)
    assert np.allclose(through.q, plain_final.q, atol=1e-9, equal_nan=True)


def test_notes_of_a_batch_name_each_rows_own_axes(world):
    """Targets past the ranges of different axes, explained together: each note lists
    exactly the axes of that row's reported joints outside the controller's ranges, with
    their values (deg, two decimals) and the side."""
    comp = world
    robot = comp.robot
    ranges = robot.controller_ranges
    rng = np.random.default_rng(8)
    q_ctrl = random_joints(robot, 40, rng, margin=0.3)
    for k in range(len(q_ctrl)):               # one axis of 2, 3 and 5 past an end
        axis, side = (1, 2, 4)[k % 3], k % 2
        q_ctrl[k, axis] = ranges[axis, side] + np.radians(8.0 if side else -8.0)
    q = robot.joints_from_controller(q_ctrl)
    desired = comp.nominal_flange(q)
    _, _, solution, _ = comp.compensate_flanges(desired, None, comp.confdata(q))
    reports = explain_failures(comp, solution, desired, comp.confdata(q))
    limited = [k for k, r in enumerate(reports) if r is not None and r.status == "joint_limit"]
    assert len(limited) >= 10
    lo, hi = np.degrees(ranges[:, 0]), np.degrees(ranges[:, 1])
    for k in limited:
        joints_deg = np.degrees(reports[k].joints)
        out = [a for a in range(6) if joints_deg[a] < lo[a] - 1e-7 or joints_deg[a] > hi[a] + 1e-7]
        named = [int(a) - 1 for a in re.findall(r"axis (\d) = ", reports[k].note)]
        assert named == out, (k, reports[k].note)
        for a in out:
            side = "below" if joints_deg[a] < lo[a] else "above"
            assert f"axis {a + 1} = {joints_deg[a]:.2f} deg" in reports[k].note
            assert f"deg {side} the controller's range" in reports[k].note


@pytest.mark.parametrize("name", ["abb_irb2400", "ur5e", "staubli_tx2_60"])
def test_turn_toward_ranges_is_the_enumeration_of_turns(name):
    robot = load_robot(name)
    ranges = robot.controller_ranges
    rng = np.random.default_rng(4)
    q = rng.uniform(-14.0, 14.0, (300, robot.n_joints))
    got = turn_toward_ranges(robot, q)
    for i in range(len(q)):
        for a, joint in enumerate(robot.joints):
            value = q[i, a]
            if joint.kind != "revolute":
                assert got[i, a] == value
                continue
            want = _enumerated_turn(value, *ranges[a])
            assert got[i, a] == pytest.approx(want, abs=1e-12), (i, a)
    assert np.array_equal(turn_toward_ranges(robot, q.reshape(30, 10, -1)).reshape(q.shape),
                          got)


def _enumerated_turn(value: float, lo: float, hi: float) -> float:
    """The enumeration the rule's turns must equal: of the seven whole turns of ``value``
    (rad) that fit in [lo, hi] (1e-9 slack), the one nearest zero (the first on a tie);
    else ``value`` wrapped into [-pi, pi)."""
    fits = [value + 2 * np.pi * t for t in range(-3, 4)
            if np.isfinite(lo) and np.isfinite(hi)
            and lo - 1e-9 <= value + 2 * np.pi * t <= hi + 1e-9]
    return min(fits, key=abs) if fits else (value + np.pi) % (2 * np.pi) - np.pi


@pytest.mark.parametrize("name", ["abb_irb2400", "ur5e", "staubli_tx2_60", "kuka_kr16_2"])
def test_turn_toward_ranges_near_zero_and_at_the_range_ends_is_the_enumeration(name):
    """The values a search's candidates mostly hold (inside their ranges, under 3 rad,
    left as they are by a shortcut) and those at the shortcut's and the ranges' edges:
    bit for bit the enumeration of the seven turns (the turn nearest zero of those that
    fit, the first on a tie; else wrapped), -0.0 included."""
    robot = load_robot(name)
    ranges = robot.controller_ranges
    rng = np.random.default_rng(5)
    edges = np.r_[ranges[np.isfinite(ranges)], 3.0, -3.0, np.pi, -np.pi, 0.0, -0.0,
                  2 * np.pi, -2 * np.pi]
    nudges = np.r_[0.0, 1e-15, -1e-15, 1e-9, -1e-9, 1.0000001e-9, -1.0000001e-9]
    values = np.r_[rng.uniform(-3.5, 3.5, 600), (edges[:, None] + nudges).ravel(), -0.0]
    n = robot.n_joints
    q = np.stack([np.roll(values, 37 * a) for a in range(n)], axis=1)
    got = turn_toward_ranges(robot, q)
    for i in range(len(q)):
        for a, joint in enumerate(robot.joints):
            value = q[i, a]
            if joint.kind != "revolute":
                continue
            want = _enumerated_turn(value, *ranges[a])
            assert np.float64(got[i, a]).tobytes() == np.float64(want).tobytes(), (i, a)


@pytest.mark.parametrize("pool", [1, 5, 64])
def test_pooled_newton_gives_each_row_what_the_whole_batch_gives(world, pool):
    """Newton on a pool of rows, a finished row's place taken by the next (the search's,
    issue 32 item 3), ends every row where damped Newton of the whole batch at once ends
    it, after the same steps with the same verdict: rows that converge in a few steps,
    rows out of reach that stall, rows that run out of steps, rows without a start. (Not
    bit for bit: numpy's batched products round differently for batches of other sizes,
    here by up to 5e-14 rad; the whole batch's rows leave it as they finish too.)"""
    from olp_compensate.compensation.ik.newton import damped_newton, pooled_newton

    comp = world
    robot = comp.robot
    desired, _, far = _targets(comp, 40, seed=21)
    rng = np.random.default_rng(21)
    q0 = robot.joints_from_controller(random_joints(robot, 40, rng, margin=0.3))
    q0[5] = np.nan
    fk = comp.real_flange_and_jacobian
    whole = damped_newton(fk, q0, desired, 1e-9, 1e-9, 30, 0.5)
    pooled = pooled_newton(fk, q0, desired, 1e-9, 1e-9, 30, 0.5, pool)
    names = ("q", "jac", "err", "iterations", "converged", "stalled")
    whole = list(whole)
    whole[1] = whole[1][whole[4]]         # pooled keeps the converged rows' Jacobians only
    for name, a, b in zip(names, whole, pooled):
        assert np.array_equal(np.isnan(a), np.isnan(b)), name
        if name in ("q", "jac", "err"):
            assert np.allclose(a, b, rtol=0, atol=1e-12, equal_nan=True), name
        else:
            assert np.array_equal(a, b), name
    converged, stalled, iterations = whole[4], whole[5], whole[3]
    assert converged.any() and stalled[far].any() and (iterations == 30).any()


@pytest.mark.parametrize("name", ["abb_irb2400", "abb_irb6400", "ur5e"])
def test_range_words_name_each_axis_past_its_range_then_each_urdf_joint(name):
    """The words of a failure note for joints outside the ranges, row by row: each
    controller axis outside its range in axis order (value, how far, which side, the
    range; deg), then each URDF joint outside its limits that no axis named, from the
    robot's own numbers (not the code's tables)."""
    from olp_compensate.compensation.failures import _Ranges, _range_words

    robot = load_robot(name)
    ranges = robot.controller_ranges
    rng = np.random.default_rng(7)
    span = np.where(np.isfinite(ranges), ranges, np.sign(ranges) * 4.0)
    q = rng.uniform(span[:, 0] - 0.6, span[:, 1] + 0.6, (400, robot.n_joints))
    q[::7] = np.clip(q[::7], span[:, 0], span[:, 1])        # rows with nothing to name
    got = _range_words(_Ranges.of(robot), q)
    assert len(got) == len(q)
    lo_deg, hi_deg = np.degrees(ranges[:, 0]), np.degrees(ranges[:, 1])
    some = 0
    for i in range(len(q)):
        want = []
        named = set()
        for a in range(robot.n_joints):
            if ranges[a, 0] - 1e-9 <= q[i, a] <= ranges[a, 1] + 1e-9:
                continue
            named.add(a)
            v = float(np.degrees(q[i, a]))
            below = v < lo_deg[a]
            past = lo_deg[a] - v if below else v - hi_deg[a]
            want.append(f"axis {a + 1} = {v:.2f} deg is {past:.2f} deg "
                        f"{'below' if below else 'above'} the controller's range "
                        f"{lo_deg[a]:g}..{hi_deg[a]:g} deg")
        joints = robot.joints_from_controller(q[i][None])[0]
        for j, joint in enumerate(robot.joints):
            if j in named or (robot.lower_limits[j] - 1e-9 <= joints[j]
                              <= robot.upper_limits[j] + 1e-9):
                continue
            want.append(f"URDF {joint.name} = {np.degrees(joints[j]):.2f} deg is outside its "
                        f"limits {np.degrees(robot.lower_limits[j]):.2f}.."
                        f"{np.degrees(robot.upper_limits[j]):.2f} deg")
        assert got[i] == want, (i, got[i], want)
        some += bool(want)
    assert some > 100


def test_the_searchs_early_stops_give_the_rules_answers_of_a_full_refinement(
        world, monkeypatch):
    """The configuration rule's search sets aside the starts that end far outside the
    ranges by their first step's bound (refining only the ones the rule reports) and stops
    the starts that crawl behind one that reached its target (issue 32 item 3): on an
    identified IRB 2400, targets in range, out of range and out of reach get the statuses,
    on-asked flags and joints (to 1e-7 rad) that the search without those stops gives."""
    import olp_compensate.compensation.ik.stalls as stalls
    import olp_compensate.compensation.rule_search as rule_search

    comp = world
    robot = comp.robot
    rng = np.random.default_rng(29)
    q = robot.joints_from_controller(random_joints(robot, 90, rng, margin=0.05,
                                                   within_ranges=False))
    desired = comp.nominal_flange(q)
    desired[::9, :3, 3] *= 2.5                                  # out of reach
    confdata = comp.confdata(q)
    parked = []
    real = rule_search.FarOutside

    class Counted(real):
        def __call__(self, *args):
            park = super().__call__(*args)
            parked.append(int(np.sum(park)))
            return park

    monkeypatch.setattr(rule_search, "FarOutside", Counted)
    early = comp.solve_real(desired, confdata)
    monkeypatch.setattr(rule_search, "FarOutside",
                        lambda *args: real(*args, factor=np.inf))     # never sets aside
    monkeypatch.setattr(stalls, "CRAWL_RELATIVE", -1.0)              # never crawls
    full = comp.solve_real(desired, confdata)
    assert sum(parked) >= 50
    statuses = set(full.reason)
    assert {"joint_limit", "branch_changed", "unreachable"} <= statuses, statuses
    assert list(early.reason) == list(full.reason)
    assert np.array_equal(early.on_asked, full.on_asked)
    assert np.array_equal(np.isnan(early.q), np.isnan(full.q))
    gap = np.remainder(early.q - full.q + np.pi, 2 * np.pi) - np.pi
    assert np.nanmax(np.abs(gap)) < 1e-7


def test_a_start_its_first_step_cannot_take_to_the_pose_is_never_set_aside(world):
    """FarOutside sets aside only starts in Newton's regime: a start whose error its first
    step takes away (``J d = e``) qualifies when far outside a range; a start at a
    singularity whose error lies where the arm cannot move (``J^T e = 0``: a zero step)
    never does, however far outside it lies (such a start stalls: a stretched arm short of
    a target out of reach); nor do the closed form's starts of targets out of reach."""
    from olp_compensate.compensation.ik import closed_form_inverse
    from olp_compensate.compensation.ik.residuals import pose_error
    from olp_compensate.compensation.ik.stalls import FarOutside

    comp = world
    robot = comp.robot
    revolute = np.array([j.kind == "revolute" for j in robot.joints])
    outside = np.tile([[10.0, 10.5]], (robot.n_joints, 1))    # every start far outside
    park = FarOutside(robot.controller_from_joints, outside, revolute)
    q = np.array([[0.3, 0.2, 0.1, 0.4, 0.0, -0.2]])
    for width in (0.02, 2e-5):                 # the calibrated wrist's singular q5
        trial = np.repeat(q, 2001, axis=0)
        trial[:, 4] += np.linspace(-width, width, 2001)
        smallest = np.linalg.svd(comp.real_flange_and_jacobian(trial)[1], compute_uv=False)
        q = trial[[np.argmin(smallest[:, -1] / smallest[:, 0])]]
    _, jac = comp.real_flange_and_jacobian(q)
    u, sv, _ = np.linalg.svd(jac[0])
    assert sv[-1] < 1e-6 * sv[0]
    dq = np.array([[1e-3, -2e-3, 1e-3, 0.0, 2e-3, 1e-3]])
    e = np.stack([1e-3 * u[:, -1], jac[0] @ dq[0]])           # unmovable; taken by dq
    parked = park(np.arange(2), np.repeat(q, 2, axis=0), np.repeat(jac, 2, axis=0), e)
    assert list(parked) == [False, True]
    desired, _, far = _targets(comp, 40, seed=17)
    starts = closed_form_inverse(comp.family, desired, clip=True)        # (m, 8, n)
    rows = np.repeat(np.arange(len(desired)), starts.shape[1])
    flat = starts.reshape(-1, starts.shape[2])
    given = np.all(np.isfinite(flat), axis=1)
    flat, rows = flat[given], rows[given]
    poses, jac = comp.real_flange_and_jacobian(flat)
    err = pose_error(desired[rows], poses)
    parked = park(np.arange(len(flat)), flat, np.array(jac), err)
    assert not np.any(parked[far[rows]])
    assert np.mean(parked[~far[rows]]) > 0.5


def _enumerated_past(q: np.ndarray, robot) -> float:
    """How far joints ``q (n,)`` (controller rad/m) lie past ``robot``'s ranges, by the
    enumeration of the seven whole turns of each revolute axis: per axis the least of
    max(lo - v, v - hi) over its turns v (positive outside, else minus the room left),
    -inf for an axis that holds every value (no finite range, or a full turn or more);
    the largest over the axes."""
    worst = -np.inf
    for a, joint in enumerate(robot.joints):
        lo, hi = robot.controller_ranges[a]
        if not (np.isfinite(lo) and np.isfinite(hi)):
            continue
        if joint.kind == "revolute":
            if hi - lo >= 2 * np.pi:
                continue
            values = [q[a] + 2 * np.pi * t for t in range(-4, 5)]
        else:
            values = [q[a]]
        worst = max(worst, min(max(lo - v, v - hi) for v in values))
    return worst


@pytest.mark.parametrize("name", ["abb_irb2400", "ur5e", "staubli_tx2_60", "kuka_kr16_2",
                                  "fanuc_r2000ic_165f"])
def test_past_ranges_is_the_enumeration_of_turns_and_agrees_with_the_rules_turns(name):
    """The set-aside test's closed form (:func:`~olp_compensate.compensation.ik.stalls.
    past_ranges`, issue 32) against the enumeration of turns; and where it says a start
    lies outside (or inside) the ranges by more than 1e-9, the rule's own turns
    (:func:`turn_toward_ranges`) put it outside (inside) too."""
    from olp_compensate.compensation.ik.stalls import past_ranges

    robot = load_robot(name)
    revolute = np.array([joint.kind == "revolute" for joint in robot.joints])
    rng = np.random.default_rng(8)
    q = rng.uniform(-14.0, 14.0, (400, robot.n_joints))
    q[:100] = robot.controller_ranges[:, 0] + rng.uniform(-0.3, 0.3, (100, robot.n_joints))
    got = past_ranges(q, robot.controller_ranges, revolute)
    outside = robot.outside_ranges(turn_toward_ranges(robot, q)).any(axis=1)
    for i in range(len(q)):
        want = _enumerated_past(q[i], robot)
        assert got[i] == pytest.approx(want, abs=1e-12), i
        if want > 1e-9:
            assert outside[i], i
        elif want < -1e-9:
            assert not outside[i], i
    if name == "ur5e":                   # every axis a full turn both ways: holds any value
        assert np.all(got == -np.inf)
    else:
        assert np.any(got > 1e-9) and np.any(got < -1e-9)
