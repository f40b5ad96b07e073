"""The device frame's motion the poses leave open is named as the rigid motion it is
(:mod:`olp_compensate.calibration.device_motions`), checked against virtual robots whose
controller (the nominal model, as a real controller interpolates) puts the tool point on a
line, on a plane, or all over the workspace.

On a line, the device frame can turn about that line without moving a measured point: the
identification must name the line (direction and a point, device frame). The truth is the
line the noise-free points of the real (virtual) arm lie nearest (their principal axis);
they are off a straight line by the arm's errors (the controller's line is straight in the
nominal model), so the tolerance is that deviation plus the noise: the start registration
puts the nominal line onto the measured points by least squares, and cannot miss their line
by more than the points scatter about it. On a plane no rigid motion but the identity fixes
the points (three non-collinear points fix a rigid body), so nothing of the device frame may
be named; spread poses neither."""

import json

import numpy as np
import pytest

from olp_compensate.calibration.device_motions import _motion, _text
from olp_compensate.calibration.identify import IdentificationOptions, identify
from olp_compensate.calibration.simulate import make_virtual_robot, random_joints
from olp_compensate.cli.cal_identify import report
from olp_compensate.io.calibration_file import dumps_calibration
from olp_compensate.calibration.unknowns import UnknownLayout
from olp_compensate.kinematics.conventions import rotation_from_rotvec, rotvec_from_rotation
from olp_compensate.kinematics.model import build_model, forward
from olp_compensate.kinematics.robot import load_robot

ROBOT = "staubli_tx2_90l"
NOISE = 0.05e-3
ARM_LENGTH_ERROR, ARM_ANGLE_ERROR = 0.2e-3, np.radians(0.02)
"""The virtual arm's errors (per joint origin): an accurate arm, whose line in the nominal
model is straight to about a millimetre on the real one (the ASTL LINE session's points lie
within 0.3 mm of theirs)."""
REFERENCE = np.radians([0.0, 10.0, 80.0, 5.0, 30.0, 15.0])


def _nominal_flange(robot, q):
    """Flange poses (m, 4, 4) of the nominal model at controller joints q, base frame, m."""
    model = build_model(robot, "auto")
    return forward(model, model.nominal, robot.joints_from_controller(q)).flange


def _constrained_poses(robot, n, seed, residual):
    """Controller joints (k <= n, 6) from random starts near a reference pose, moved by
    minimum-norm Newton steps (finite differences) until ``residual(flange, index)`` (n, r)
    of the nominal flange poses vanishes (as the controller puts its nominal model on a
    path). Poses that leave the limits or do not converge are dropped."""
    rng = np.random.default_rng(seed)
    q = REFERENCE + rng.normal(0.0, 0.15, (n, 6))
    index = np.arange(n)
    for _ in range(40):
        e = residual(_nominal_flange(robot, q), index)
        jac = np.empty((n, e.shape[1], 6))
        for k in range(6):
            step = q.copy()
            step[:, k] += 1e-7
            jac[:, :, k] = (residual(_nominal_flange(robot, step), index) - e) / 1e-7
        q -= np.einsum("mkr,mr->mk", np.linalg.pinv(jac), e)
    ok = (np.abs(residual(_nominal_flange(robot, q), index)).max(axis=1) < 1e-10) & np.all(
        (q > robot.lower_limits + 0.05) & (q < robot.upper_limits - 0.05), axis=1)
    return q[ok]


def _session(kind: str, seed: int = 4):
    """(virtual robot, controller joints, identification result) of a session whose nominal
    tool point runs along a 500 mm line keeping the flange's orientation (as the ASTL LINE
    session), lies on a plane (``plane``: the orientation kept too, as ASTL SURFACE;
    ``plane-turning``: the wrist turning freely), or spreads everywhere."""
    robot = load_robot(ROBOT)
    virtual = make_virtual_robot(robot, seed=seed, length_error_m=ARM_LENGTH_ERROR,
                                 angle_error_rad=ARM_ANGLE_ERROR)
    tool = virtual.tools["tcp"]
    reference = _nominal_flange(robot, REFERENCE[None])[0]
    turn, start = reference[:3, :3], reference[:3, 3] + reference[:3, :3] @ tool
    u, w = np.array([0.2, 0.9, 0.3]), np.array([-0.3, 0.1, 0.6])
    u /= np.linalg.norm(u)
    w -= (w @ u) * u
    w /= np.linalg.norm(w)
    along = np.linspace(-0.25, 0.25, 70)
    rng = np.random.default_rng(seed)
    across = rng.uniform(-0.2, 0.2, 70)

    def residual(flange, index):
        tcp = flange[:, :3, 3] + flange[:, :3, :3] @ tool
        if kind == "line":
            place = tcp - (start + along[index, None] * u)
        else:
            place = tcp - (start + along[index, None] * u + across[index, None] * w)
            place = place[:, :1] if kind == "plane-turning" else place
        if kind == "plane-turning":
            return ((tcp - start) @ np.cross(u, w))[:, None]
        return np.hstack([place, rotvec_from_rotation(turn.T @ flange[:, :3, :3])])

    if kind == "spread":
        q = random_joints(robot, 60, rng)
    else:
        q = _constrained_poses(robot, 70, seed, residual)
    meas = virtual.measure(q, NOISE, np.random.default_rng(seed + 1))
    return virtual, q, identify(robot, meas, IdentificationOptions(folds=0))


@pytest.fixture(scope="module")
def line():
    return _session("line")


def test_the_line_session_names_the_measured_points_line(line):
    virtual, q, result = line
    assert len(q) >= 50
    motions = result.identifiability.motions
    assert len(motions) == 1, result.identifiability.frozen
    (name, motion), = motions.items()
    assert name.startswith("base.") and motion.kind == "rotation"
    assert not motion.tools
    # the truth: the line nearest the arm's noise-free points, device frame
    points = virtual.true_points(q, ["tcp"] * len(q))
    centroid = points.mean(axis=0)
    truth = np.linalg.svd(points - centroid)[2][0]
    off = points - centroid
    deviation = np.linalg.norm(off - np.outer(off @ truth, truth), axis=1).max()
    half_length = np.abs(off @ truth).max()
    tolerance_m = deviation + 4 * NOISE
    angle = np.arccos(min(1.0, abs(float(motion.direction @ truth))))
    assert angle < tolerance_m / half_length, (np.degrees(angle), deviation)
    gap = motion.point_mm * 1e-3 - centroid
    assert np.linalg.norm(gap - (gap @ truth) * truth) < tolerance_m
    # it is said: in the report (a warning and the frozen list) and in calib.json
    text = report(result)
    assert f"WARNING: {motion.text}" in text and f"  {name}: {motion.text}" in text
    assert "measure points off that line" in motion.text
    assert motion.farthest_mm < 1e3 * tolerance_m
    held = json.loads(dumps_calibration(result.calibration))["device_T_base"]["held"]
    assert held == {name.split(".")[1]: motion.text}


def test_the_rotation_named_moves_no_predicted_point(line):
    """An independent check of the screw: turning the fitted device frame by 1 mrad about
    the named line moves the predicted points by far less than a turn about a line 100 mm
    off it does (the points lie on the named line, not beside it)."""
    virtual, q, result = line
    motion = next(iter(result.identifiability.motions.values()))
    points = virtual.true_points(q, ["tcp"] * len(q))
    a, p0 = motion.direction, motion.point_mm * 1e-3
    side = np.cross(a, [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)

    def moved(through):
        return np.linalg.norm(np.cross(1e-3 * a, points - through), axis=1).max()
    assert moved(p0) < 0.05 * moved(p0 + 0.1 * side)


@pytest.mark.parametrize("kind", ["plane", "plane-turning"])
def test_points_on_a_plane_leave_the_device_frame_determined(kind):
    virtual, q, result = _session(kind)
    assert len(q) >= 50
    ident = result.identifiability
    assert ident.motions == {}
    assert not [n for n in ident.frozen if n.startswith("base.")], ident.frozen


def test_spread_poses_name_nothing():
    _, _, result = _session("spread")
    ident = result.identifiability
    assert ident.motions == {}
    assert "device frame's" not in report(result)


class _Stub:
    """The parts of an identification problem :func:`_motion` reads: the layout, the start
    registration (r0, t0) and the measured points, device frame."""

    def __init__(self, rng):
        self.layout = UnknownLayout.build([], ["tcp"])
        self.r0 = rotation_from_rotvec(rng.normal(size=3))
        self.t0 = rng.normal(0.0, 2.0, 3)
        self.measured = rng.normal(0.0, 0.3, (20, 3)) + [1.0, -2.0, 0.5]


def _registration_step(stub, axis, through, pitch_m_per_rad, angle):
    """The unknown-vector change (registration part) that screws the device frame by
    ``angle`` about the line through ``through`` along ``axis`` (device frame), advancing
    ``pitch * angle`` along it, at the start (phi = 0): inverted by hand from
    ``device_T_base = (R0 Exp(phi), t0 + R0 rho)``."""
    w = angle * axis
    v = -np.cross(w, through) + pitch_m_per_rad * w
    dx = np.zeros(stub.layout.size)
    dx[stub.layout.registration_rotation] = stub.r0.T @ w
    dx[stub.layout.registration_translation] = stub.r0.T @ (v + np.cross(w, stub.t0))
    return dx


def _moved(stub, dx, eps, points):
    """Where device-frame points go when the registration moves by ``eps * dx`` (the
    problem's own registration formula, finite step): the robot base's points are fixed,
    so a point p of the device frame goes to T(eps) T(0)^-1 p."""
    layout = stub.layout
    turn = stub.r0 @ rotation_from_rotvec(eps * dx[layout.registration_rotation])
    shift = stub.t0 + stub.r0 @ (eps * dx[layout.registration_translation])
    base = (points - stub.t0) @ stub.r0
    return base @ turn.T + shift


@pytest.mark.parametrize("pitch", [0.0, 0.05])
def test_the_screw_named_is_the_registration_change_by_finite_steps(pitch):
    """A known screw of the device frame, built by hand into the registration's unknowns,
    is named back (axis, the point of the axis nearest the points, pitch), and a finite step
    of the registration formula moves the named axis' points only along the axis."""
    stub = _Stub(np.random.default_rng(3))
    axis = np.array([2.0, -1.0, 0.5]) / np.linalg.norm([2.0, -1.0, 0.5])
    through = np.array([0.3, 0.1, -0.4])
    dx = _registration_step(stub, axis, through, pitch, 1.0)
    centroid = stub.measured.mean(axis=0)
    extent = np.sqrt(np.mean(np.sum((stub.measured - centroid) ** 2, axis=1)))
    kind, direction, point_mm, pitch_mm_per_deg, _ = _motion(stub, dx, centroid, extent,
                                                             stub.measured)
    assert kind == ("rotation" if pitch == 0.0 else "screw")
    assert abs(abs(direction @ axis) - 1.0) < 1e-12
    foot = through + axis * (axis @ (centroid - through))
    np.testing.assert_allclose(point_mm * 1e-3, foot, atol=1e-12)
    assert pitch_mm_per_deg == pytest.approx(np.radians(1.0) * pitch * 1e3, abs=1e-12)
    on_axis = foot + np.outer([-1.0, 0.0, 2.0], axis)
    eps = 1e-6
    step = _moved(stub, dx, eps, on_axis) - on_axis
    np.testing.assert_allclose(step, np.outer([1.0] * 3, eps * pitch * axis), atol=1e-11)


def test_a_translation_is_named_as_one():
    stub = _Stub(np.random.default_rng(4))
    along = np.array([0.0, 0.6, 0.8])
    dx = np.zeros(stub.layout.size)
    dx[stub.layout.registration_translation] = stub.r0.T @ along
    kind, direction, point_mm, _, farthest = _motion(stub, dx, stub.measured.mean(axis=0),
                                                     0.5, stub.measured)
    assert kind == "translation" and point_mm is None and farthest is None
    np.testing.assert_allclose(direction, along, atol=1e-12)
    text = _text(kind, direction, point_mm, 0.0, farthest, ("tcp",))
    assert "translation along (0.0000, 0.6000, 0.8000) together with tool point tcp" in text
