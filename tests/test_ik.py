"""Inverse kinematics: closed forms, family fit, configuration conventions, refinement.

The robots are standard DH tables written here, independently of the closed forms.
"""

from __future__ import annotations

import numpy as np
import pytest

from olp_compensate.compensation import ik
from olp_compensate.compensation.ik import (REASONS, IKSolution, OPWParameters, ReachBound,
                                            URParameters, branch_of, closed_form_forward,
                                            closed_form_inverse, configuration_bits, fit_family,
                                            opw_forward, opw_inverse, refine, solve, ur_forward,
                                            ur_inverse)
from olp_compensate.compensation.ik.configuration import (configuration_margins, select_on_branch,
                                                          shift_into)
from olp_compensate.compensation.ik.jacobians import nominal_jacobian
from olp_compensate.compensation.ik.solver import BLOCK, CLOSED_FORM_STEPS
from olp_compensate.errors import DataError, ModelError
from olp_compensate.kinematics.conventions import (pose_from_rotation_translation,
                                                   quat_wxyz_from_matrix, rot_x, rot_z,
                                                   rotvec_from_rotation)
from olp_compensate.programs.object_model.confdata import (abb_confdata, select_branch,
                                                           vplus_branch, vplus_configuration)

PI = np.pi


class DHRobot:
    """Standard DH chain: link i is ``Rz(sign_i q_i + offset_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``."""

    def __init__(self, a, alpha, d, offset, sign=(1,) * 6, base=None, tool=None):
        self.a, self.alpha, self.d, self.offset, self.sign = (
            np.asarray(v, dtype=float) for v in (a, alpha, d, offset, sign))
        self.base = np.eye(4) if base is None else np.asarray(base, dtype=float)
        self.tool = np.eye(4) if tool is None else np.asarray(tool, dtype=float)

    def perturbed(self, rng, length=1e-3, angle=np.deg2rad(0.1)):
        """The same robot with every DH parameter off by ~1 mm / ~0.1 deg."""
        return DHRobot(self.a + rng.normal(0, length, 6), self.alpha + rng.normal(0, angle, 6),
                       self.d + rng.normal(0, length, 6), self.offset + rng.normal(0, angle, 6),
                       self.sign, self.base, self.tool)

    def frames(self, q):
        q = np.atleast_2d(q)
        T = np.broadcast_to(self.base, (len(q), 4, 4)).copy()
        frames = [T]
        for i in range(6):
            theta = self.sign[i] * q[:, i] + self.offset[i]
            c, s = np.cos(theta), np.sin(theta)
            ca, sa = np.cos(self.alpha[i]), np.sin(self.alpha[i])
            A = np.zeros((len(q), 4, 4))
            A[:, 0] = np.stack([c, -s * ca, s * sa, self.a[i] * c], 1)
            A[:, 1] = np.stack([s, c * ca, -c * sa, self.a[i] * s], 1)
            A[:, 2, 1], A[:, 2, 2], A[:, 2, 3], A[:, 3, 3] = sa, ca, self.d[i], 1.0
            T = T @ A
            frames.append(T)
        return frames

    def fk(self, q):
        """base_T_flange (m, 4, 4) for q (m, 6)."""
        return self.frames(q)[-1] @ self.tool

    def fk_jacobian(self, q):
        """Poses and the analytic geometric Jacobian (m, 6, 6) in the base frame."""
        frames = self.frames(q)
        flange = frames[-1] @ self.tool
        jac = np.empty((len(flange), 6, 6))
        for i in range(6):
            z = frames[i][:, :3, 2] * self.sign[i]
            jac[:, :3, i] = np.cross(z, flange[:, :3, 3] - frames[i][:, :3, 3])
            jac[:, 3:, i] = z
        return flange, jac


# ABB IRB 2400 with ABB's joint directions: tool0 at (940, 0, 1455) mm, q = (0.70711, 0,
# 0.70711, 0) at q = 0.
IRB2400 = DHRobot([0.100, 0.705, 0.135, 0, 0, 0], [-PI / 2, 0, -PI / 2, PI / 2, -PI / 2, 0],
                  [0.615, 0, 0, 0.755, 0, 0.085], [0, -PI / 2, 0, 0, 0, PI])
IRB2400_OPW = OPWParameters(a1=0.100, a2=-0.135, b=0.0, c1=0.615, c2=0.705, c3=0.755,
                            c4=0.085, offsets=(0, 0, -PI / 2, 0, 0, 0))
IRB2400_LIMITS = np.deg2rad([[-180, 180], [-100, 110], [-60, 65], [-200, 200], [-120, 120],
                             [-400, 400]])
# IRB 6400-like arm, written with other DH sign conventions on purpose
IRB6400 = DHRobot([0.240, 1.050, 0.225, 0, 0, 0], [PI / 2, 0, PI / 2, -PI / 2, PI / 2, 0],
                  [0.800, 0, 0, 1.520, 0, 0.200], [0, PI / 2, 0, 0, 0, 0])
PUMA560 = DHRobot([0, 0.4318, 0.0203, 0, 0, 0], [PI / 2, 0, -PI / 2, PI / 2, -PI / 2, 0],
                  [0.67183, 0, 0.15005, 0.4318, 0, 0], [0] * 6)
UR5E = DHRobot([0, -0.425, -0.3922, 0, 0, 0], [PI / 2, 0, 0, PI / 2, -PI / 2, 0],
               [0.1625, 0, 0, 0.1333, 0.0997, 0.0996], [0] * 6)
UR5E_PARAMS = URParameters(d1=0.1625, a2=-0.425, a3=-0.3922, d4=0.1333, d5=0.0997, d6=0.0996)
ROBOTS = {"irb2400": IRB2400, "irb6400": IRB6400, "puma560": PUMA560, "ur5e": UR5E}


def pose_errors(a, b):
    """Position (m) and rotation (rad) distances between pose batches, each (m,)."""
    rot = rotvec_from_rotation(np.swapaxes(a[:, :3, :3], 1, 2) @ b[:, :3, :3])
    return np.linalg.norm(a[:, :3, 3] - b[:, :3, 3], axis=1), np.linalg.norm(rot, axis=1)


def angle_diff(a, b):
    return np.abs(np.mod(a - b + PI, 2 * PI) - PI)


# --------------------------------------------------------------------------- forward

def test_irb2400_zero_pose_is_abb_home():
    T = opw_forward(IRB2400_OPW, np.zeros((1, 6)))[0]
    np.testing.assert_allclose(T[:3, 3], [0.940, 0.0, 1.455], atol=1e-12)
    np.testing.assert_allclose(quat_wxyz_from_matrix(T[:3, :3]),
                               [np.sqrt(0.5), 0, np.sqrt(0.5), 0], atol=1e-12)


def test_opw_forward_matches_independent_dh_irb2400():
    rng = np.random.default_rng(0)
    q = rng.uniform(-PI, PI, (200, 6))
    np.testing.assert_allclose(opw_forward(IRB2400_OPW, q), IRB2400.fk(q), atol=1e-12)


def test_irb2400_axes_move_as_abb_defines_them():
    """Positive axis 2 tilts the lower arm forward, positive 3 and 5 tilt down."""
    home = opw_forward(IRB2400_OPW, np.zeros((1, 6)))[0]
    for axis, coordinate, sign in ((1, 0, +1), (2, 2, -1), (4, 2, -1)):
        q = np.zeros((1, 6))
        q[0, axis] = 0.01
        moved = opw_forward(IRB2400_OPW, q)[0]
        assert sign * (moved[coordinate, 3] - home[coordinate, 3]) > 0, axis


def test_ur_forward_matches_independent_dh():
    rng = np.random.default_rng(0)
    q = rng.uniform(-2 * PI, 2 * PI, (200, 6))
    np.testing.assert_allclose(ur_forward(UR5E_PARAMS, q), UR5E.fk(q), atol=1e-12)


# --------------------------------------------------------------------------- inverse

@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_fk_of_every_ik_branch_is_the_pose(name):
    robot = ROBOTS[name]
    params = fit_family(robot.fk)
    rng = np.random.default_rng(0)
    q = rng.uniform(-PI, PI, (500, 6))
    target = robot.fk(q)
    solutions = closed_form_inverse(params, target)
    assert solutions.shape == (500, 8, 6)
    for k in range(8):
        ok = np.all(np.isfinite(solutions[:, k]), axis=1)
        assert ok.sum() > 100, (name, k)
        reached = robot.fk(solutions[ok, k])
        np.testing.assert_allclose(reached, target[ok], atol=1e-10)
        assert np.all(branch_of(params, solutions[ok, k]) == k), (name, k)
    # the branch of the generating joints reproduces them (away from the wrist singularity)
    well = np.abs(np.sin(params.model_angles(q)[:, 4])) > 1e-3
    chosen = solutions[np.arange(500), branch_of(params, q)]
    assert np.max(angle_diff(chosen, q)[well]) < 1e-9


def test_unreachable_branches_are_nan_not_errors():
    far = pose_from_rotation_translation(np.eye(3), [5.0, 0.0, 0.0])
    assert np.all(np.isnan(opw_inverse(IRB2400_OPW, far[None])))
    assert np.all(np.isnan(ur_inverse(UR5E_PARAMS, far[None])))


def test_singular_wrist_closed_form_sets_axis4_to_zero():
    q = np.array([[0.3, 0.2, -0.1, 1.0, 0.0, -0.4]])
    solutions = opw_inverse(IRB2400_OPW, opw_forward(IRB2400_OPW, q))
    np.testing.assert_allclose(solutions[0, 0], [0.3, 0.2, -0.1, 0.0, 0.0, 0.6], atol=1e-12)
    np.testing.assert_allclose(opw_forward(IRB2400_OPW, solutions[:, 0]),
                               opw_forward(IRB2400_OPW, q), atol=1e-12)


# --------------------------------------------------------------------------- family fit

def test_fit_family_finds_the_published_irb2400_parameters():
    params = fit_family(IRB2400.fk)
    assert isinstance(params, OPWParameters)
    for name in ("a1", "a2", "b", "c1", "c2", "c3", "c4"):
        assert getattr(params, name) == pytest.approx(getattr(IRB2400_OPW, name), abs=1e-12)
    np.testing.assert_allclose(params.offsets, IRB2400_OPW.offsets, atol=1e-12)
    assert params.signs == (1,) * 6
    assert params.base_T_root is None and params.tip_T_flange is None


def test_fit_family_puma560_uses_the_lateral_offset_b():
    params = fit_family(PUMA560.fk)
    assert isinstance(params, OPWParameters)
    assert abs(params.b) == pytest.approx(0.15005, abs=1e-12)
    assert (params.a1, params.c1, params.c2, params.c3) == pytest.approx(
        (0.0, 0.67183, 0.4318, 0.4318), abs=1e-12)
    assert abs(params.a2) == pytest.approx(0.0203, abs=1e-12)


def test_fit_family_ur5e():
    params = fit_family(UR5E.fk)
    assert isinstance(params, URParameters)
    for name in ("d1", "a2", "a3", "d4", "d5", "d6"):
        assert getattr(params, name) == pytest.approx(getattr(UR5E_PARAMS, name), abs=1e-12)


def test_fit_family_irb6400_like():
    params = fit_family(IRB6400.fk)
    assert isinstance(params, OPWParameters)
    assert (params.a1, abs(params.a2), params.c1, params.c2, params.c3, params.c4) == \
        pytest.approx((0.240, 0.225, 0.800, 1.050, 1.520, 0.200), abs=1e-12)


@pytest.mark.parametrize("name", ["irb2400", "ur5e"])
def test_fit_family_with_base_tool_and_joint_conventions(name):
    """Ceiling mount, a tool frame off the flange axis, reversed joints and zero offsets."""
    robot = ROBOTS[name]
    base = pose_from_rotation_translation(rot_x(PI) @ rot_z(0.4), [0.3, -0.2, 2.0])
    tool = pose_from_rotation_translation(rot_x(0.3), [0.01, 0.02, 0.1])
    odd = DHRobot(robot.a, robot.alpha, robot.d, robot.offset + [0.1, 0.2, 0.3, 0.4, 0.5, 0.6],
                  sign=(-1, 1, -1, 1, -1, -1), base=base, tool=tool)
    params = fit_family(odd.fk)
    assert type(params) is type(fit_family(robot.fk))
    rng = np.random.default_rng(0)
    q = rng.uniform(-PI, PI, (100, 6))
    np.testing.assert_allclose(closed_form_forward(params, q), odd.fk(q), atol=1e-10)
    solutions = closed_form_inverse(params, odd.fk(q))
    ok = np.all(np.isfinite(solutions), axis=2)
    assert ok.mean() > 0.5
    np.testing.assert_allclose(odd.fk(solutions[ok]), odd.fk(q)[np.nonzero(ok)[0]], atol=1e-10)


def test_fit_family_rejects_other_robots():
    offset_wrist = DHRobot([0.1, 0.705, 0.135, 0, 0.02, 0], IRB2400.alpha, IRB2400.d,
                           IRB2400.offset)
    assert fit_family(offset_wrist.fk) is None
    assert fit_family(IRB2400.fk, n_joints=7) is None

    def geared(q):                      # axis 6 turns at half speed: not a plain revolute
        q = np.array(q, dtype=float)
        q[:, 5] *= 0.5
        return IRB2400.fk(q)

    assert fit_family(geared) is None


# --------------------------------------------------------------------------- confdata

def test_abb_confdata_of_known_configurations():
    conf = abb_confdata(IRB2400_OPW, np.deg2rad([
        [0, 0, 0, 0, 0, 0],                   # home: everything in front, axis 5 = 0
        [-10, 0, 0, 100, -30, -200],          # wrist negative
        [0, 30, -85, 0, 40, 0],               # upper arm folded up: behind the lower arm
        [0, -90, 40, 0, 40, 0],               # lower arm back: wrist centre behind axis 1
        [-90, 0, 0, -90, 30, 359.9],          # quadrant boundaries
    ]))
    np.testing.assert_array_equal(conf, [[0, 0, 0, 0], [-1, 1, -3, 1], [0, 0, 0, 2],
                                         [0, 0, 0, 4], [-1, -1, 3, 0]])


def test_confdata_selects_the_generating_joints():
    rng = np.random.default_rng(0)
    q = rng.uniform(IRB2400_LIMITS[:, 0], IRB2400_LIMITS[:, 1], (2000, 6))
    q = q[np.abs(np.sin(q[:, 4])) > 1e-3]
    conf = abb_confdata(IRB2400_OPW, q)
    chosen, found = select_branch(opw_inverse(IRB2400_OPW, opw_forward(IRB2400_OPW, q)), conf,
                                  IRB2400_LIMITS)
    assert found.all()
    np.testing.assert_allclose(chosen, q, atol=1e-9)


def test_select_branch_reports_limits_and_missing_branches():
    q = np.deg2rad([[10, 20, 10, 30, 40, 50]])
    solutions = opw_inverse(IRB2400_OPW, opw_forward(IRB2400_OPW, q))
    conf = abb_confdata(IRB2400_OPW, q)
    tight = IRB2400_LIMITS.copy()
    tight[4] = [-0.1, 0.1]
    assert not select_branch(solutions, conf, tight)[1][0]
    solutions[0, conf[0, 3]] = np.nan
    assert not select_branch(solutions, conf)[1][0]
    with pytest.raises(DataError, match="cfx"):
        select_branch(solutions, [[0, 0, 0, 9]])


def test_nominal_joints_on_branch_are_the_selected_branch():
    """The one-branch closed form gives the joints select_branch picks among all eight,
    and NaN where that branch is missing."""
    rng = np.random.default_rng(3)
    q = rng.uniform(IRB2400_LIMITS[:, 0], IRB2400_LIMITS[:, 1], (500, 6))
    q = q[np.abs(np.sin(q[:, 4])) > 1e-3]
    T = opw_forward(IRB2400_OPW, q)
    conf = abb_confdata(IRB2400_OPW, q)
    got = ik.nominal_joints_on_branch(IRB2400_OPW, T, conf, IRB2400_LIMITS)
    chosen, found = select_branch(opw_inverse(IRB2400_OPW, T), conf, IRB2400_LIMITS)
    assert found.all()
    np.testing.assert_allclose(got, chosen, atol=1e-12)
    np.testing.assert_allclose(got, q, atol=1e-9)
    far = T[:1].copy()
    far[0, :3, 3] = [5.0, 0.0, 0.5]          # 5 m away: no branch reaches it
    assert np.isnan(ik.nominal_joints_on_branch(IRB2400_OPW, far, conf[:1])).all()


def test_solve_with_nominal_gives_the_controller_joints_of_the_target():
    """On the nominal model itself, the solution and the nominal joints coincide; on a
    perturbed model the nominal joints are still the nominal controller's."""
    rng = np.random.default_rng(4)
    q = rng.uniform(IRB2400_LIMITS[:, 0], IRB2400_LIMITS[:, 1], (200, 6))
    q = q[np.abs(np.sin(q[:, 4])) > 0.1]
    T = opw_forward(IRB2400_OPW, q)
    conf = abb_confdata(IRB2400_OPW, q)
    real = IRB2400.perturbed(rng)
    solution, nominal = ik.solve_with_nominal(IRB2400_OPW, real.fk_jacobian, T, conf,
                                              IRB2400_LIMITS)
    np.testing.assert_allclose(nominal, q, atol=1e-9)
    reached = solution.success
    assert reached.mean() > 0.95
    np.testing.assert_allclose(real.fk(solution.q[reached]), T[reached], atol=1e-8)
    assert np.abs(solution.q[reached] - q[reached]).max() > 1e-4   # the model differs


@pytest.mark.parametrize("name", ["ur5e", "puma560"])
def test_confdata_round_trip_other_families(name):
    params = fit_family(ROBOTS[name].fk)
    rng = np.random.default_rng(0)
    q = rng.uniform(-PI, PI, (1000, 6))
    q = q[np.abs(np.sin(params.model_angles(q)[:, 4])) > 1e-3]
    chosen, found = select_branch(closed_form_inverse(params, closed_form_forward(params, q)),
                                  abb_confdata(params, q))
    assert found.all()
    np.testing.assert_allclose(chosen, q, atol=1e-9)


def test_vplus_flags_name_each_puma_branch_once():
    params = fit_family(PUMA560.fk)
    rng = np.random.default_rng(0)
    q = rng.uniform(-PI, PI, (300, 6))
    q = q[np.abs(np.sin(q[:, 4])) > 1e-3]
    solutions = opw_inverse(params, PUMA560.fk(q))
    complete = np.all(np.isfinite(solutions), axis=(1, 2))
    flags = vplus_configuration(params, solutions[complete].reshape(-1, 6)).reshape(-1, 8, 3)
    codes = flags @ [4, 2, 1]
    assert all(len(set(row)) == 8 for row in codes.tolist())
    righty, above, flip = vplus_configuration(params, q).T
    chosen, found = vplus_branch(params, solutions, righty, above, flip)
    assert found.all()
    np.testing.assert_allclose(angle_diff(chosen, q), 0, atol=1e-9)


def test_vplus_puma_reaching_forward_elbow_up_is_above():
    params = fit_family(PUMA560.fk)
    # Corke's "nominal" working pose: lower arm 45 deg forward, forearm down
    righty, above, flip = vplus_configuration(params, [[0, PI / 4, PI, 0, PI / 4, 0]])[0]
    assert above and not flip
    assert righty == (params.b < 0)
    # at q = 0 the forearm points straight up: the elbow is below the shoulder-wrist line
    assert not vplus_configuration(params, np.zeros((1, 6)))[0, 1]


# --------------------------------------------------------------------------- refinement

def test_analytic_jacobian_matches_finite_differences():
    rng = np.random.default_rng(0)
    robot = IRB2400.perturbed(rng)
    q = rng.uniform(-PI, PI, (20, 6))
    poses, jac = robot.fk_jacobian(q)
    h = 1e-6
    for i in range(6):
        dq = np.zeros(6)
        dq[i] = h
        plus, minus = robot.fk(q + dq), robot.fk(q - dq)
        linear = (plus[:, :3, 3] - minus[:, :3, 3]) / (2 * h)
        angular = rotvec_from_rotation(plus[:, :3, :3] @ np.swapaxes(minus[:, :3, :3], 1, 2))
        np.testing.assert_allclose(jac[:, :3, i], linear, atol=1e-8)
        np.testing.assert_allclose(jac[:, 3:, i], angular / (2 * h), atol=1e-8)


def test_refine_converges_on_a_perturbed_model():
    rng = np.random.default_rng(0)
    robot = IRB2400.perturbed(rng)
    q_true = rng.uniform(IRB2400_LIMITS[:, 0] * 0.9, IRB2400_LIMITS[:, 1] * 0.9, (500, 6))
    # Newton alone, from the nominal closed form: away from singularities (solve() handles
    # those)
    q_true = q_true[np.all(configuration_bits(IRB2400_OPW, q_true, 0.05) >= 0, axis=1)]
    target = robot.fk(q_true)
    q0 = select_branch(opw_inverse(IRB2400_OPW, target), abb_confdata(IRB2400_OPW, q_true))[0]
    result = refine(robot.fk_jacobian, q0, target)
    assert isinstance(result, IKSolution)
    assert result.success.all(), set(result.reason)
    assert result.position_error_m.max() <= 1e-9
    assert result.rotation_error_rad.max() <= 1e-9
    reached = pose_errors(robot.fk(result.q), target)
    assert reached[0].max() <= 1e-9 and reached[1].max() <= 1e-9


@pytest.mark.parametrize("name, limits", [
    ("irb2400", IRB2400_LIMITS),
    ("irb6400", np.deg2rad([[-180, 180], [-70, 70], [-28, 105], [-300, 300], [-120, 120],
                            [-300, 300]])),
    ("ur5e", np.tile([-PI, PI], (6, 1))),
])
def test_solve_reaches_every_target_on_the_requested_branch(name, limits):
    rng = np.random.default_rng(0)
    nominal = ROBOTS[name]
    robot = nominal.perturbed(rng)
    params = fit_family(nominal.fk)
    q_true = rng.uniform(limits[:, 0] * 0.95, limits[:, 1] * 0.95, (2000, 6))
    target = robot.fk(q_true)
    conf = abb_confdata(params, q_true)
    result = solve(params, robot.fk_jacobian, target, conf, limits)
    assert result.success.all(), dict(zip(*np.unique(result.reason, return_counts=True)))
    reached = pose_errors(robot.fk(result.q), target)
    assert reached[0].max() <= 1e-9 and reached[1].max() <= 1e-9
    # the requested configuration, within quadrant tolerance for axes 1, 4, 6
    np.testing.assert_array_equal(abb_confdata(params, result.q)[:, 3], conf[:, 3])
    assert np.all(result.q >= limits[:, 0]) and np.all(result.q <= limits[:, 1])
    # away from singularities, the joints that made the target
    well = np.all(configuration_bits(params, q_true, 0.05) >= 0, axis=1)
    assert well.sum() > 1000
    np.testing.assert_allclose(result.q[well], q_true[well], atol=1e-6)


def test_solve_without_confdata_picks_a_reachable_branch():
    rng = np.random.default_rng(0)
    robot = IRB2400.perturbed(rng)
    q_true = rng.uniform(IRB2400_LIMITS[:, 0] * 0.9, IRB2400_LIMITS[:, 1] * 0.9, (200, 6))
    result = solve(IRB2400_OPW, robot.fk_jacobian, robot.fk(q_true), limits=IRB2400_LIMITS)
    assert result.success.all()


def test_target_beyond_nominal_reach_is_solved_on_the_calibrated_model():
    """The real lower arm is 5 mm longer: the nominal closed form has no solution, the
    stretched-arm start still converges."""
    longer = DHRobot(IRB2400.a + [0, 0.005, 0, 0, 0, 0], IRB2400.alpha, IRB2400.d,
                     IRB2400.offset)
    elbow_straight = -PI / 2 - np.arctan2(-0.135, 0.755)
    q_true = np.array([[0.3, 0.4, elbow_straight + 0.02, 0.5, 0.6, 0.7]])
    target = longer.fk(q_true)
    assert np.all(np.isnan(opw_inverse(IRB2400_OPW, target)))
    result = solve(IRB2400_OPW, longer.fk_jacobian, target, abb_confdata(IRB2400_OPW, q_true))
    assert result.success[0]
    np.testing.assert_allclose(result.q, q_true, atol=1e-9)


def test_unreachable_target_is_a_value_not_an_exception():
    rng = np.random.default_rng(0)
    robot = IRB2400.perturbed(rng)
    targets = robot.fk(np.zeros((3, 6)))
    targets[1, :3, 3] = [4.0, 1.0, 0.5]                        # far outside the workspace
    targets[2, :3, 3] = [1.9, 0.0, 0.7]                        # just beyond full stretch
    result = solve(IRB2400_OPW, robot.fk_jacobian, targets, [[0, 0, 0, 0]] * 3)
    assert result.success.tolist() == [True, False, False]
    assert result.reason.tolist() == ["ok", "unreachable", "unreachable"]
    stuck = refine(robot.fk_jacobian, np.zeros((1, 6)), targets[1:2])
    assert not stuck.success[0] and stuck.reason[0] == "unreachable"
    assert set(result.reason) <= set(REASONS)


def test_wrist_singularity_is_reached_and_flagged():
    q_true = np.array([[0.3, 0.2, -0.1, 0.8, 0.0, -0.4]])
    # the perturbed model's axes 4 and 6 are never exactly aligned: reached, near-singular
    robot = IRB2400.perturbed(np.random.default_rng(0))
    target = robot.fk(q_true)
    result = solve(IRB2400_OPW, robot.fk_jacobian, target, abb_confdata(IRB2400_OPW, q_true))
    assert result.success[0] and result.reason[0] in ("singular", "ok")
    assert result.position_error_m[0] <= 1e-9 and result.rotation_error_rad[0] <= 1e-9
    # on the nominal model they are: reached, and flagged
    target = IRB2400.fk(q_true)
    exact = refine(IRB2400.fk_jacobian, q_true + [[1e-3, -1e-3, 1e-3, 0.1, 0.0, -0.1]], target)
    assert exact.success[0] and exact.reason[0] == "singular"
    assert exact.position_error_m[0] <= 1e-9 and exact.rotation_error_rad[0] <= 1e-9
    result = solve(IRB2400_OPW, IRB2400.fk_jacobian, target, abb_confdata(IRB2400_OPW, q_true))
    assert result.success[0] and result.reason[0] == "singular"


def test_joint_limits_are_reported():
    rng = np.random.default_rng(0)
    robot = IRB2400.perturbed(rng)
    q_true = np.deg2rad([[10, 20, 10, 30, 40, 50]])
    target = robot.fk(q_true)
    conf = abb_confdata(IRB2400_OPW, q_true)
    tight = IRB2400_LIMITS.copy()
    tight[2] = [-0.2, 0.1]                                      # axis 3 must be ~0.17 rad
    assert solve(IRB2400_OPW, robot.fk_jacobian, target, conf, tight).reason[0] == "joint_limit"
    result = refine(robot.fk_jacobian, q_true + 0.01, target, tight)
    assert result.reason[0] == "joint_limit" and not result.success[0]
    assert result.position_error_m[0] <= 1e-9                   # reached, but not allowed


def test_branch_change_is_reported():
    rng = np.random.default_rng(0)
    robot = IRB2400.perturbed(rng)
    q_true = np.array([[0.3, 0.2, -0.1, 0.8, -0.02, -0.4]])
    start = q_true.copy()
    start[0, 4] = 0.02                                          # the other wrist branch

    def wrist_sign(q):
        return (np.sin(q[:, 4]) < 0).astype(int)

    result = refine(robot.fk_jacobian, start, robot.fk(q_true), configuration=wrist_sign)
    assert result.reason[0] == "branch_changed" and not result.success[0]


def test_iteration_limit_is_reported():
    rng = np.random.default_rng(0)
    robot = IRB2400.perturbed(rng)
    q_true = np.array([[0.3, 0.2, -0.1, 0.8, 0.5, -0.4]])
    result = refine(robot.fk_jacobian, q_true + 0.2, robot.fk(q_true), max_iterations=1)
    assert result.reason[0] == "not_converged" and result.iterations[0] == 1


# --------------------------------------------------------------------------- validation

def test_inputs_are_validated_with_their_names():
    with pytest.raises(DataError, match="base_T_flange"):
        opw_inverse(IRB2400_OPW, np.zeros((3, 3)))
    with pytest.raises(DataError, match="q"):
        opw_forward(IRB2400_OPW, np.zeros((2, 5)))
    with pytest.raises(DataError, match="limits"):
        refine(IRB2400.fk_jacobian, np.zeros((1, 6)), IRB2400.fk(np.zeros((1, 6))), [[0, 1]])
    with pytest.raises(ModelError, match="signs"):
        OPWParameters(0.1, -0.1, 0, 0.6, 0.7, 0.7, 0.08, signs=(1, 2, 1, 1, 1, 1))
    with pytest.raises(ModelError, match="fk_jacobian"):
        refine(lambda q: (IRB2400.fk(q), np.zeros((len(q), 3, 6))), np.zeros((1, 6)),
               IRB2400.fk(np.zeros((1, 6))))


# --------------------------------------------------------------------------- solver internals

@pytest.mark.parametrize("name", sorted(ROBOTS))
@pytest.mark.parametrize("odd", [False, True])
def test_nominal_jacobian_is_the_geometric_jacobian(name, odd):
    """The closed-form Newton of solve() maps joint steps through the nominal Jacobian."""
    robot = ROBOTS[name]
    if odd:
        robot = DHRobot(robot.a, robot.alpha, robot.d, robot.offset + [0.1, 0.2, 0.3, 0.4, 0.5,
                                                                       0.6],
                        sign=(-1, 1, -1, 1, -1, -1),
                        base=pose_from_rotation_translation(rot_x(PI) @ rot_z(0.4),
                                                            [0.3, -0.2, 2.0]),
                        tool=pose_from_rotation_translation(rot_x(0.3), [0.01, 0.02, 0.1]))
    params = fit_family(robot.fk)
    q = np.random.default_rng(0).uniform(-PI, PI, (100, 6))
    np.testing.assert_allclose(nominal_jacobian(params, q), robot.fk_jacobian(q)[1],
                               atol=1e-12)


def test_select_all_axes_at_once_is_the_per_axis_shift():
    rng = np.random.default_rng(0)
    q = rng.uniform(-7, 7, (3000, 6))
    q[:200] = np.round(q[:200] / (PI / 2)) * (PI / 2)                 # quadrant boundaries
    q[rng.random(3000) < 0.05] = np.nan
    conf = np.concatenate([rng.integers(-4, 4, (3000, 3)), rng.integers(0, 8, (3000, 1))], 1)
    for limits in (None, IRB2400_LIMITS):
        for tolerance in (np.inf, PI / 4):
            got, status = select_on_branch(q, conf, limits, tolerance)
            want = q.copy()
            quadrant_ok = np.ones(len(q), bool)
            for j in range(6):
                lim = None if limits is None else limits[j]
                if j in (0, 3, 5):
                    lower = conf[:, (0, 3, 5).index(j)] * (PI / 2)
                    want[:, j], dist = shift_into(q[:, j], lim, lower, lower + PI / 2)
                    quadrant_ok &= ~(dist > tolerance)
                elif lim is not None:
                    want[:, j], _ = shift_into(q[:, j], lim, np.full(len(q), lim[0]),
                                                   np.full(len(q), lim[1]))
            np.testing.assert_array_equal(got, want)
            within = (np.ones(len(q), bool) if limits is None else
                      np.all((want >= limits[:, 0]) & (want <= limits[:, 1]), axis=1))
            np.testing.assert_array_equal(status, np.where(
                np.isnan(q).any(1), 1, np.where(~within, 2, np.where(~quadrant_ok, 3, 0))))


def test_solve_takes_two_newton_steps_away_from_singularities():
    """Newton in the closed form's coordinates: two model updates for regular targets."""
    rng = np.random.default_rng(1)
    robot = IRB2400.perturbed(rng)
    q_true = rng.uniform(IRB2400_LIMITS[:, 0] * 0.9, IRB2400_LIMITS[:, 1] * 0.9, (1000, 6))
    q_true = q_true[np.all(configuration_bits(IRB2400_OPW, q_true, 0.1) >= 0, axis=1)]
    calls = []

    def model(q):
        calls.append(len(q))
        return robot.fk_jacobian(q)

    result = solve(IRB2400_OPW, model, robot.fk(q_true), abb_confdata(IRB2400_OPW, q_true),
                   IRB2400_LIMITS)
    assert result.success.all()
    assert np.mean(result.iterations <= 2) > 0.9 and result.iterations.max() <= 4
    assert calls[:3] == [len(q_true)] * 3 and sum(calls[3:]) < 0.1 * len(q_true)


def test_solve_in_blocks_near_singularities():
    """More targets than one block, a fifth of them 2 to 20 mm (or 0.002 to 0.02 in
    sin(theta5)) from the shoulder or wrist singularity: all reached on the requested
    configuration, as target by target. (Closer than the model's errors, ~1 mm, the model
    can have several solutions per configuration, and one may be missed.)"""
    rng = np.random.default_rng(2)
    robot = IRB2400.perturbed(rng)
    q = rng.uniform(IRB2400_LIMITS[:, 0] * 0.95, IRB2400_LIMITS[:, 1] * 0.95, (60000, 6))
    margins = np.abs(configuration_margins(IRB2400_OPW, q))[:, [0, 2]]
    near = q[np.all(margins > 2e-3, axis=1) & np.any(margins < 2e-2, axis=1)][:1000]
    q_true = np.concatenate([q[:BLOCK * 2], near])
    target = robot.fk(q_true)
    conf = abb_confdata(IRB2400_OPW, q_true)
    result = solve(IRB2400_OPW, robot.fk_jacobian, target, conf, IRB2400_LIMITS)
    assert result.success.all(), dict(zip(*np.unique(result.reason, return_counts=True)))
    reached = pose_errors(robot.fk(result.q), target)
    assert reached[0].max() <= 1e-9 and reached[1].max() <= 1e-9
    np.testing.assert_array_equal(abb_confdata(IRB2400_OPW, result.q)[:, 3], conf[:, 3])
    one = solve(IRB2400_OPW, robot.fk_jacobian, target[-5:], conf[-5:], IRB2400_LIMITS)
    np.testing.assert_allclose(one.q, result.q[-5:], atol=1e-8)


def test_solve_of_no_targets():
    result = solve(IRB2400_OPW, IRB2400.fk_jacobian, np.zeros((0, 4, 4)), np.zeros((0, 4)))
    assert result.q.shape == (0, 6) and result.success.shape == (0,)


# --------------------------------------------------------------------------- reach bound

def _chain(robot):
    """Joint frames at zero (6, 4, 4) and the flange at zero (4, 4) of a DH robot whose
    joints turn about +z: what :class:`ReachBound` takes."""
    frames = robot.frames(np.zeros((1, 6)))
    return np.array([f[0] for f in frames[:6]]), (frames[6] @ robot.tool)[0]


def _stretched_elbow(robot):
    """Axis-3 angle (rad) of the stretched elbow: the one that puts the wrist centre
    (frame 4's origin) farthest from axis 2 (frame 1's origin), by a scan in 0.03 mrad."""
    t = np.linspace(-PI, PI, 200001)
    q = np.zeros((len(t), 6))
    q[:, 2] = t
    frames = robot.frames(q)
    return t[np.argmax(np.linalg.norm(frames[4][:, :3, 3] - frames[1][:, :3, 3], axis=1))]


def _arm_forward(rng, robot, n, elbow):
    """n joint vectors (rad) of ``robot`` with the elbow at ``elbow`` (n,), the arm
    reaching forward (axis 2 in 0.4..1.2 rad) and the wrist away from its singularity."""
    q = rng.uniform(-PI, PI, (n, 6))
    q[:, 1] = rng.uniform(0.4, 1.2, n)
    q[:, 2] = elbow
    q[:, 4] = rng.uniform(0.3, 2.5, n) * rng.choice([-1.0, 1.0], n)
    return q


@pytest.mark.parametrize("seed, error", [(0, 1e-3), (1, 1e-3), (2, 5e-3)])
def test_reach_bound_never_rejects_a_reachable_target(seed, error):
    """Targets the arm (DH parameters off by ~1 or 5 mm and 0.1 or 0.5 deg, so axes 2 and
    3 not parallel, axes 4, 5, 6 not meeting) reaches by construction, with the elbow
    within 0.05 rad of stretched (a third within 5 urad), a quarter near the wrist
    singularity: none is declared out of reach, with or without the wrist configuration
    asked for."""
    rng = np.random.default_rng(seed)
    robot = IRB2400.perturbed(rng, length=error, angle=np.deg2rad(100 * error))
    reach = ReachBound(*_chain(robot))
    n = 3000
    q = rng.uniform(-PI, PI, (n, 6))
    q[:, 2] = _stretched_elbow(robot) + rng.uniform(-0.05, 0.05, n) * rng.choice(
        [1.0, 1e-2, 1e-4], n)
    q[: n // 4, 4] = rng.normal(0.0, 0.01, n // 4)
    target = robot.fk(q)
    wrist = configuration_bits(IRB2400_OPW, q)[:, 2]
    assert not reach.unreachable(target, wrist, IRB2400_OPW).any()
    assert not reach.unreachable(target).any()


def test_targets_just_inside_the_stretched_reach_are_solved():
    """Elbow 1 to 30 mrad from stretched (the wrist centre 0.5 um to 0.5 mm inside the
    reach): every target reached to 1e-9 on the requested configuration, none rejected."""
    rng = np.random.default_rng(5)
    robot = IRB2400.perturbed(rng)
    n = 2000
    q = rng.uniform(IRB2400_LIMITS[:, 0] * 0.9, IRB2400_LIMITS[:, 1] * 0.9, (n, 6))
    q[:, 2] = _stretched_elbow(robot) + rng.choice([-1.0, 1.0], n) * rng.uniform(1e-3, 3e-2, n)
    target = robot.fk(q)
    conf = abb_confdata(IRB2400_OPW, q)
    result = solve(IRB2400_OPW, robot.fk_jacobian, target, conf,
                   reach=ReachBound(*_chain(robot)))
    assert result.success.all(), dict(zip(*np.unique(result.reason, return_counts=True)))
    reached = pose_errors(robot.fk(result.q), target)
    assert reached[0].max() <= 1e-9 and reached[1].max() <= 1e-9
    np.testing.assert_array_equal(abb_confdata(IRB2400_OPW, result.q)[:, 3], conf[:, 3])


def test_targets_beyond_the_exact_reach_are_unreachable_without_restarts():
    """The data-sheet arm has a spherical wrist: its centre is at most c2 + hypot(a2, c3)
    from the circle axis 2 turns on (triangle inequality), so wrist centres 10 um beyond
    are out of reach; 10 um inside (elbow bent to match) they are reached. The rejected
    ones take the first Newton steps only, the restarts none."""
    rng = np.random.default_rng(6)
    c2, k = 0.705, np.hypot(0.135, 0.755)
    n = 200
    bend = np.arccos(((c2 + k - 1e-5) ** 2 - c2 ** 2 - k ** 2) / (2 * c2 * k))
    elbow = _stretched_elbow(IRB2400)
    inside = _arm_forward(rng, IRB2400, n, elbow + rng.choice([-1.0, 1.0], n) * bend)
    stretched = _arm_forward(rng, IRB2400, n, elbow)
    beyond = IRB2400.fk(stretched)
    centre = beyond[:, :3, 3] - 0.085 * beyond[:, :3, 2]
    shoulder = 0.1 * centre[:, :2] / np.linalg.norm(centre[:, :2], axis=1)[:, None]
    outward = centre - np.column_stack([shoulder, np.full(n, 0.615)])
    distance = np.linalg.norm(outward, axis=1)
    beyond[:, :3, 3] += (c2 + k + 1e-5 - distance)[:, None] * outward / distance[:, None]
    target = np.concatenate([IRB2400.fk(inside), beyond])
    conf = abb_confdata(IRB2400_OPW, np.concatenate([inside, stretched]))
    reach = ReachBound(*_chain(IRB2400))
    assert reach.unreachable(target).tolist() == [False] * n + [True] * n
    result = solve(IRB2400_OPW, IRB2400.fk_jacobian, target, conf, reach=reach)
    assert result.success[:n].all() and not result.success[n:].any()
    assert set(result.reason[n:]) == {"unreachable"}
    assert result.iterations[n:].max() <= CLOSED_FORM_STEPS
    reached = pose_errors(IRB2400.fk(result.q[:n]), target[:n])
    assert reached[0].max() <= 1e-9 and reached[1].max() <= 1e-9
    without = solve(IRB2400_OPW, IRB2400.fk_jacobian, target[n:], conf[n:])
    assert set(without.reason) == {"unreachable"} and without.iterations.min() > 20


def test_targets_just_beyond_a_calibrated_arms_reach_are_proven_unreachable():
    """On an arm off by ~1 mm per link, whose wrist axes miss each other, targets 0.1 to
    0.3 mm beyond a stretched arm: nearly all proven out of reach on the requested wrist
    configuration, and rejected after the first Newton steps. An independent search (Newton
    from the 8 nominal solutions, 30 random starts and 20 near the stretched arm) finds no
    solution with that wrist for any of them."""
    rng = np.random.default_rng(5)
    robot = IRB2400.perturbed(rng)
    reach = ReachBound(*_chain(robot))
    n = 300
    q = _arm_forward(rng, robot, n, _stretched_elbow(robot))
    frames = robot.frames(q)
    outward = frames[4][:, :3, 3] - frames[1][:, :3, 3]
    target = robot.fk(q)
    push = rng.uniform(1e-4, 3e-4, n) / np.linalg.norm(outward, axis=1)
    target[:, :3, 3] += push[:, None] * outward
    wrist = configuration_bits(IRB2400_OPW, q)[:, 2]
    proven = reach.unreachable(target, wrist, IRB2400_OPW)
    assert proven.mean() > 0.95
    result = solve(IRB2400_OPW, robot.fk_jacobian, target, abb_confdata(IRB2400_OPW, q),
                   reach=reach)
    assert set(result.reason[proven]) == {"unreachable"}
    assert result.iterations[proven].max() <= CLOSED_FORM_STEPS
    for i in np.flatnonzero(proven)[:20]:
        starts = closed_form_inverse(IRB2400_OPW, target[i:i + 1])[0]
        starts = np.concatenate([starts[np.all(np.isfinite(starts), axis=1)],
                                 rng.uniform(-PI, PI, (30, 6)),
                                 q[i] + rng.normal(0.0, 0.05, (20, 6))])
        found = refine(robot.fk_jacobian, starts, np.repeat(target[i:i + 1], len(starts), 0))
        same_wrist = configuration_bits(IRB2400_OPW, found.q)[:, 2] == wrist[i]
        assert not np.any(found.success & same_wrist), i


def test_reach_bound_rejects_malformed_chains():
    with pytest.raises(ModelError, match="6 joint frames"):
        ReachBound(np.zeros((5, 4, 4)), np.eye(4))
    frames, flange = _chain(IRB2400)
    parallel = frames.copy()
    parallel[4] = parallel[3]                      # axis 5 on axis 4
    with pytest.raises(ModelError, match="axes 4 and 5"):
        ReachBound(parallel, flange)
    assert not ReachBound(frames, flange).unreachable(np.zeros((0, 4, 4))).any()
