"""Checks of the bundled robot descriptions in ``robots/``.

Every URDF is loaded with yourdfpy and with pinocchio. The pose of ``tool0`` computed by pinocchio
is compared with an independent forward kinematics written here from the published numbers
(data-sheet dimensions, standard Denavit-Hartenberg tables), at the zero configuration and at
random configurations, to 1e-9 m.

ABB arms: the joint values fed to the reference model are the *controller's* axis values
(degrees in RAPID, radians here). The ABB arms modelled here have a parallel linkage between
axes 2 and 3: the controller's axis 3 is the upper-arm angle, so the serial URDF is driven with
``joint_3 = q3_ABB - q2_ABB`` (ROS-Industrial abb_driver ``J23_coupled``). The reference model
is the standard DH table (mm, deg)

    a     = [a1, a2, a3, 0, 0, 0]
    alpha = [-90, 0, -90, 90, -90, 0]
    d     = [d1, 0, 0, d4, 0, d6]
    theta = [q1, q2 - 90, q3 - q2, q4, q5, q6 + 180]

with all ABB joint signs +1 (axis 1 counter-clockwise seen from above, axis 2 positive tilts the
lower arm forward, axis 3 positive tilts the upper arm down, axis 5 positive tilts the flange
down).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

pin = pytest.importorskip("pinocchio")
yourdfpy = pytest.importorskip("yourdfpy")

ROBOTS_DIR = Path(__file__).resolve().parents[1] / "robots"
TOL = 1e-9
DEG = math.pi / 180.0
N_RANDOM = 25


# --------------------------------------------------------------------------- reference models


def dh_standard(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """Standard DH link transform Rz(theta) Tz(d) Tx(a) Rx(alpha)."""
    ct, st = math.cos(theta), math.sin(theta)
    ca, sa = math.cos(alpha), math.sin(alpha)
    return np.array([
        [ct, -st * ca, st * sa, a * ct],
        [st, ct * ca, -ct * sa, a * st],
        [0.0, sa, ca, d],
        [0.0, 0.0, 0.0, 1.0],
    ])


def fk_dh(a, d, alpha, theta) -> np.ndarray:
    pose = np.eye(4)
    for i in range(6):
        pose = pose @ dh_standard(theta[i], d[i], a[i], alpha[i])
    return pose


class AbbArm:
    """An ABB 6-axis arm with a J2/J3 parallel linkage, from data-sheet dimensions in mm."""

    def __init__(self, d1, a1, a2, a3, d4, d6, ranges_deg):
        self.d1, self.a1, self.a2, self.a3, self.d4, self.d6 = (v * 1e-3 for v in (d1, a1, a2, a3, d4, d6))
        self.ranges = np.array(ranges_deg, dtype=float) * DEG

    def fk(self, q_controller) -> np.ndarray:
        q1, q2, q3, q4, q5, q6 = q_controller
        a = [self.a1, self.a2, self.a3, 0.0, 0.0, 0.0]
        d = [self.d1, 0.0, 0.0, self.d4, 0.0, self.d6]
        alpha = np.array([-90.0, 0.0, -90.0, 90.0, -90.0, 0.0]) * DEG
        theta = [q1, q2 - math.pi / 2, q3 - q2, q4, q5, q6 + math.pi]
        return fk_dh(a, d, alpha, theta)

    @staticmethod
    def to_urdf(q_controller) -> np.ndarray:
        q = np.array(q_controller, dtype=float)
        q[2] = q_controller[2] - q_controller[1]
        return q

    def zero_position(self) -> np.ndarray:
        return np.array([self.a1 + self.d4 + self.d6, 0.0, self.d1 + self.a2 + self.a3])

    def random_controller(self, rng) -> np.ndarray:
        return rng.uniform(self.ranges[:, 0], self.ranges[:, 1])


class DhArm:
    """A standard-DH arm; the URDF joint values are the DH thetas (no offsets)."""

    def __init__(self, a, d, alpha):
        self.a, self.d, self.alpha = list(a), list(d), list(alpha)

    def fk(self, q) -> np.ndarray:
        return fk_dh(self.a, self.d, self.alpha, q)


IRB2400_RANGES = [(-180, 180), (-100, 110), (-60, 65), (-200, 200), (-120, 120), (-400, 400)]

ABB = {
    # IRB 2400-12/1.55 data sheet dimensions (mm).
    "abb_irb2400": AbbArm(615, 100, 705, 135, 755, 85, IRB2400_RANGES),
    # IRB 2000: as the IRB 2400 but p_x1 = 0 (Motta 2006); other values assumed from the 2400.
    "abb_irb2000": AbbArm(615, 0, 705, 135, 755, 85, IRB2400_RANGES),
    # IRB 6400R/2.8-200 (robotkinematicscatalogue; unverified against ABB).
    "abb_irb6400": AbbArm(800, 240, 1050, 225, 1520, 200,
                          [(-170, 170), (-70, 70), (-28, 35), (-300, 300), (-120, 120), (-300, 300)]),
}

DH = {
    # Corke, Robotics Toolbox for Python, models/DH/Puma560.py (base at the mounting surface).
    "unimation_puma560": DhArm([0, 0.4318, 0.0203, 0, 0, 0], [0.67183, 0, 0.15005, 0.4318, 0, 0],
                               [math.pi / 2, 0, -math.pi / 2, math.pi / 2, -math.pi / 2, 0]),
    # Universal Robots, DH parameters of the UR5e.
    "ur5e": DhArm([0, -0.425, -0.3922, 0, 0, 0], [0.1625, 0, 0, 0.1333, 0.0997, 0.0996],
                  [math.pi / 2, 0, 0, math.pi / 2, -math.pi / 2, 0]),
}

# Expected total mass (kg) of base_link + link_1..link_6: (low, high).
TOTAL_MASS = {
    "abb_irb2400": (375.0, 385.0),
    "abb_irb2000": (300.0, 450.0),
    "abb_irb6400": (1900.0, 2300.0),
    "unimation_puma560": (60.0, 66.0),
    "ur5e": (20.0, 21.5),
}

ALL = sorted(list(ABB) + list(DH))


# --------------------------------------------------------------------------- helpers


def urdf_path(name: str) -> Path:
    return ROBOTS_DIR / f"{name}.urdf"


def load_pinocchio(name: str):
    model = pin.buildModelFromXML(urdf_path(name).read_text(encoding="utf-8"))
    return model, model.createData()


def pin_tool0(model, data, q) -> np.ndarray:
    pin.framesForwardKinematics(model, data, np.asarray(q, dtype=float))
    return data.oMf[model.getFrameId("tool0")].homogeneous.copy()


def assert_pose_close(actual, expected, tol=TOL):
    assert np.max(np.abs(actual[:3, 3] - expected[:3, 3])) < tol, (actual, expected)
    assert np.max(np.abs(actual[:3, :3] - expected[:3, :3])) < tol, (actual, expected)


def quat_wxyz(rotation) -> np.ndarray:
    q = pin.Quaternion(rotation)
    out = np.array([q.w, q.x, q.y, q.z])
    return out if out[0] >= 0 else -out


# --------------------------------------------------------------------------- tests


def test_all_files_present():
    present = sorted(p.stem for p in ROBOTS_DIR.glob("*.urdf"))
    assert set(ALL) <= set(present)
    assert (ROBOTS_DIR / "README.md").is_file()


@pytest.mark.parametrize("name", ALL)
def test_yourdfpy_structure(name):
    urdf = yourdfpy.URDF.load(str(urdf_path(name)), load_meshes=False,
                              build_collision_scene_graph=False, load_collision_meshes=False)
    robot = urdf.robot
    link_names = {link.name for link in robot.links}
    assert {"base_link", "tool0"} | {f"link_{i}" for i in range(1, 7)} <= link_names
    joints = {j.name: j for j in robot.joints}
    parents = ["base_link"] + [f"link_{i}" for i in range(1, 6)]
    for i in range(1, 7):
        j = joints[f"joint_{i}"]
        assert j.type == "revolute"
        assert j.parent == parents[i - 1] and j.child == f"link_{i}"
        assert j.axis is not None and abs(np.linalg.norm(j.axis) - 1.0) < 1e-12
        assert j.mimic is None
        lim = j.limit
        assert lim is not None
        assert np.isfinite(lim.lower) and np.isfinite(lim.upper) and lim.lower < 0.0 < lim.upper
        assert lim.effort > 0 and lim.velocity > 0
    tool = joints["joint_6-tool0"]
    assert tool.type == "fixed" and tool.parent == "link_6" and tool.child == "tool0"
    movable = [j for j in robot.joints if j.type != "fixed"]
    assert len(movable) == 6

    total = 0.0
    for link in robot.links:
        if link.name == "tool0":
            continue
        inertial = link.inertial
        assert inertial is not None, link.name
        assert inertial.mass > 0, link.name
        total += inertial.mass
        inertia = np.asarray(inertial.inertia)
        assert np.allclose(inertia, inertia.T)
        eig = np.linalg.eigvalsh(inertia)
        assert eig.min() > 0, (link.name, eig)
        # principal moments of a rigid body obey the triangle inequality
        assert eig[0] + eig[1] >= eig[2] * (1 - 1e-9), (link.name, eig)
    low, high = TOTAL_MASS[name]
    assert low <= total <= high, total


@pytest.mark.parametrize("name", ALL)
def test_pinocchio_model(name):
    model, data = load_pinocchio(name)
    assert model.nq == 6 and model.nv == 6 and model.njoints == 7
    assert [model.names[i] for i in range(1, 7)] == [f"joint_{i}" for i in range(1, 7)]
    for i in range(1, 7):
        assert model.joints[i].nq == 1 and "R" in model.joints[i].shortname()  # revolute
    assert np.all(np.isfinite(model.lowerPositionLimit)) and np.all(np.isfinite(model.upperPositionLimit))
    assert np.all(model.lowerPositionLimit < model.upperPositionLimit)
    assert np.all(model.effortLimit > 0) and np.all(model.velocityLimit > 0)
    assert all(model.inertias[i].mass > 0 for i in range(1, 7))
    assert model.existFrame("tool0")
    # gravity torques at random poses stay below the joint efforts (efforts are not nonsense)
    rng = np.random.default_rng(7)
    for _ in range(50):
        q = rng.uniform(model.lowerPositionLimit, model.upperPositionLimit)
        tau = pin.computeGeneralizedGravity(model, data, q)
        assert np.all(np.abs(tau) <= model.effortLimit), (q, tau)


@pytest.mark.parametrize("name", sorted(ABB))
def test_abb_zero_pose(name):
    arm = ABB[name]
    model, data = load_pinocchio(name)
    pose = pin_tool0(model, data, np.zeros(6))
    assert np.max(np.abs(pose[:3, 3] - arm.zero_position())) < TOL, pose[:3, 3]
    expected_q = np.array([math.sqrt(0.5), 0.0, math.sqrt(0.5), 0.0])
    assert np.max(np.abs(quat_wxyz(pose[:3, :3]) - expected_q)) < TOL
    # tool z along base x, tool x along base -z
    assert np.allclose(pose[:3, 2], [1, 0, 0], atol=TOL)
    assert np.allclose(pose[:3, 0], [0, 0, -1], atol=TOL)
    assert_pose_close(arm.fk(np.zeros(6)), pose)


def test_irb2400_zero_pose_numbers():
    model, data = load_pinocchio("abb_irb2400")
    pose = pin_tool0(model, data, np.zeros(6))
    assert np.max(np.abs(pose[:3, 3] - np.array([0.940, 0.0, 1.455]))) < TOL


@pytest.mark.parametrize("name", sorted(ABB))
def test_abb_random_configurations_against_dh(name):
    arm = ABB[name]
    model, data = load_pinocchio(name)
    rng = np.random.default_rng(20240611)
    for _ in range(N_RANDOM):
        q_ctrl = arm.random_controller(rng)
        q_urdf = arm.to_urdf(q_ctrl)
        assert np.all(q_urdf >= model.lowerPositionLimit - 1e-12)
        assert np.all(q_urdf <= model.upperPositionLimit + 1e-12)
        assert_pose_close(pin_tool0(model, data, q_urdf), arm.fk(q_ctrl))


@pytest.mark.parametrize("name", sorted(ABB))
def test_abb_joint_directions(name):
    """Controller-convention checks that do not use the DH table."""
    arm = ABB[name]
    model, data = load_pinocchio(name)
    zero = pin_tool0(model, data, np.zeros(6))[:3, 3]
    small = 0.1
    # axis 1 positive: counter-clockwise from above -> flange moves to +y
    p = pin_tool0(model, data, arm.to_urdf([small, 0, 0, 0, 0, 0]))[:3, 3]
    assert p[1] > zero[1]
    # axis 2 positive alone: lower arm forward, upper arm keeps its orientation (parallel linkage)
    pose = pin_tool0(model, data, arm.to_urdf([0, small, 0, 0, 0, 0]))
    assert pose[0, 3] > zero[0]
    assert np.allclose(pose[:3, :3], pin_tool0(model, data, np.zeros(6))[:3, :3], atol=TOL)
    assert abs(pose[0, 3] - zero[0] - arm.a2 * math.sin(small)) < TOL
    # axis 3 positive: upper arm down -> flange moves down
    p = pin_tool0(model, data, arm.to_urdf([0, 0, small, 0, 0, 0]))[:3, 3]
    assert p[2] < zero[2]
    # axis 5 positive: flange tilts down
    p = pin_tool0(model, data, arm.to_urdf([0, 0, 0, 0, small, 0]))[:3, 3]
    assert p[2] < zero[2]


@pytest.mark.parametrize("name", sorted(DH))
def test_dh_robots_against_dh_table(name):
    arm = DH[name]
    model, data = load_pinocchio(name)
    assert_pose_close(pin_tool0(model, data, np.zeros(6)), arm.fk(np.zeros(6)))
    rng = np.random.default_rng(11)
    for _ in range(N_RANDOM):
        q = rng.uniform(model.lowerPositionLimit, model.upperPositionLimit)
        assert_pose_close(pin_tool0(model, data, q), arm.fk(q))


def test_ur5e_zero_pose_numbers():
    model, data = load_pinocchio("ur5e")
    pose = pin_tool0(model, data, np.zeros(6))
    # UR DH at zero: flange at x = a2 + a3, y = -(d4 + d6), z = d1 - d5, z-axis along -y
    assert np.max(np.abs(pose[:3, 3] - np.array([-0.8172, -0.2329, 0.0628]))) < TOL
    assert np.allclose(pose[:3, 2], [0, -1, 0], atol=TOL)


def test_puma560_zero_pose_numbers():
    model, data = load_pinocchio("unimation_puma560")
    pose = pin_tool0(model, data, np.zeros(6))
    # Corke's qz ('L' pose: upper arm horizontal, forearm vertical): x = a2 + a3, y = -d3,
    # z = d1 + d4, tool z up
    assert np.max(np.abs(pose[:3, 3] - np.array([0.4318 + 0.0203, -0.15005, 0.67183 + 0.4318]))) < TOL
    assert np.allclose(pose[:3, :3], np.eye(3), atol=TOL)


@pytest.mark.parametrize("name", ALL)
def test_yourdfpy_agrees_with_pinocchio(name):
    urdf = yourdfpy.URDF.load(str(urdf_path(name)), load_meshes=False,
                              build_collision_scene_graph=False, load_collision_meshes=False)
    model, data = load_pinocchio(name)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(model.lowerPositionLimit, model.upperPositionLimit)
        urdf.update_cfg({f"joint_{i + 1}": q[i] for i in range(6)})
        pose = urdf.get_transform("tool0", "base_link")
        assert_pose_close(np.asarray(pose), pin_tool0(model, data, q))


@pytest.mark.parametrize("name", ALL)
def test_own_urdf_reader_agrees_with_yourdfpy(name):
    """olp_compensate.urdf reads every joint as yourdfpy does (origin, axis, limits)."""
    from olp_compensate.urdf import read_urdf_chain

    theirs = yourdfpy.URDF.load(str(urdf_path(name)), load_meshes=False,
                                build_collision_scene_graph=False,
                                load_collision_meshes=False).robot
    ours = read_urdf_chain(urdf_path(name).read_text(), name)
    assert ours.name == theirs.name
    assert ours.links == {link.name for link in theirs.links}
    assert [j.name for j in ours.joints] == [j.name for j in theirs.joints]
    for a, b in zip(ours.joints, theirs.joints):
        assert (a.type, a.parent, a.child, a.mimic) == (b.type, b.parent, b.child, b.mimic is not None)
        np.testing.assert_allclose(a.origin, np.eye(4) if b.origin is None else b.origin,
                                   atol=1e-15)
        if b.axis is None or a.type == "fixed":
            continue
        np.testing.assert_allclose(a.axis, b.axis, atol=0)
        assert (a.limit.lower, a.limit.upper, a.limit.velocity, a.limit.effort) == \
            (b.limit.lower, b.limit.upper, b.limit.velocity, b.limit.effort)


def test_own_urdf_reader_rpy_matches_yourdfpy_on_a_general_origin():
    from olp_compensate.urdf import read_urdf_chain

    text = ('<robot name="r"><link name="a"/><link name="b"/>'
            '<joint name="j" type="revolute"><parent link="a"/><child link="b"/>'
            '<origin xyz="0.1 -0.2 0.3" rpy="0.3 -1.1 2.5"/><axis xyz="0 1 0"/>'
            '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>')
    ours = read_urdf_chain(text).joints[0].origin
    theirs = yourdfpy.URDF.load(__import__("io").BytesIO(text.encode()), load_meshes=False,
                                build_collision_scene_graph=False,
                                load_collision_meshes=False).robot.joints[0].origin
    np.testing.assert_allclose(ours, theirs, atol=1e-14)


@pytest.mark.parametrize("text, message", [
    ("not xml at all", "not a readable URDF"),
    ("<sdf/>", "expected <robot>"),
    ('<robot><joint name="j" type="fixed"><parent link="a"/></joint></robot>', "needs <parent"),
    ('<robot><joint name="j" type="fixed"><parent link="a"/><child link="b"/>'
     '<origin xyz="0 0"/></joint></robot>', "must hold 3 numbers"),
    ('<robot><joint name="j" type="revolute"><parent link="a"/><child link="b"/>'
     '<limit lower="x"/></joint></robot>', "is not a number"),
])
def test_own_urdf_reader_rejects_bad_text(text, message):
    from olp_compensate.errors import ModelError
    from olp_compensate.urdf import read_urdf_chain

    with pytest.raises(ModelError, match=message):
        read_urdf_chain(text, "bad.urdf")
