"""Checks of the bundled robot descriptions in ``robots/``.

The robots are records (``robots/NAME.robot.json``); the URDF checked here is the one generated
from each record (:func:`olp_compensate.kinematics.robot.load_robot`). Every URDF is loaded with yourdfpy and with pinocchio. The pose of ``tool0`` computed by pinocchio
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

Robots of other makers (KUKA KR 16-2, FANUC R-2000iC/165F, Staubli TX2-60, UR10e) are checked the
same way against standard DH tables written here from the data-sheet dimensions, with the
controller's joint signs and zeros (see ``ControllerDhArm`` and robots/README.md). The FANUC has a
J2/J3 interaction: its J3 is the J3-arm angle from the horizontal (positive = up), so the serial
URDF joint_3 (axis -y) is ``J2 + J3`` (ROS-Industrial fanuc_driver ``J23_factor = 1``).
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
import pytest

pin = pytest.importorskip("pinocchio")
yourdfpy = pytest.importorskip("yourdfpy")

from olp_compensate.kinematics.robot import load_robot  # noqa: E402

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


class ControllerDhArm:
    """A 6R arm driven by the controller's axis values, as a standard DH table (m, deg).

    ``theta(q)`` maps controller axes (rad) to the DH thetas (signs and zero offsets of the
    controller); ``to_urdf(q)`` maps them to the URDF joints (identity unless coupled).
    """

    def __init__(self, a, d, alpha_deg, theta, ranges_deg, to_urdf=None):
        self.a, self.d = list(a), list(d)
        self.alpha = list(np.array(alpha_deg, dtype=float) * DEG)
        self.theta = theta
        self.ranges = np.array(ranges_deg, dtype=float) * DEG
        self._to_urdf = to_urdf

    def fk(self, q_controller) -> np.ndarray:
        return fk_dh(self.a, self.d, self.alpha, self.theta(np.asarray(q_controller, dtype=float)))

    def to_urdf(self, q_controller) -> np.ndarray:
        q = np.array(q_controller, dtype=float)
        return q if self._to_urdf is None else self._to_urdf(q)

    def random_controller(self, rng) -> np.ndarray:
        return rng.uniform(self.ranges[:, 0], self.ranges[:, 1])


def _fanuc_to_urdf(q):
    """FANUC J2/J3 interaction: URDF joint_3 (serial, FANUC J3 direction) = J2 + J3."""
    q = np.array(q, dtype=float)
    q[2] = q[1] + q[2]
    return q


# Controller axis ranges (deg), data sheets (see robots/README.md for the sources).
KR16_2_RANGES = [(-185, 185), (-155, 35), (-130, 154), (-350, 350), (-130, 130), (-350, 350)]
R2000IC_165F_RANGES = [(-185, 185), (-60, 76), (-132, 180), (-360, 360), (-125, 125), (-360, 360)]
TX2_60_RANGES = [(-180, 180), (-127.5, 127.5), (-152.5, 152.5), (-270, 270), (-121, 132.5),
                 (-270, 270)]
UR10E_RANGES = [(-360, 360)] * 6

OTHER = {
    # KUKA KR 16-2 data sheet: A2 675 mm up and 260 mm forward of A1, lower arm 680 mm, A4 axis
    # 35 mm below A3 (arm horizontal at zero), A3 to wrist centre 670 mm, flange 158 mm. KUKA
    # signs: A1 clockwise from above (theta1 = -A1), A2/A3/A5 positive down, A4/A6 about -x.
    "kuka_kr16_2": ControllerDhArm(
        a=[0.260, 0.680, 0.035, 0, 0, 0], d=[0.675, 0, 0, -0.670, 0, 0.158],
        alpha_deg=[-90, 0, -90, 90, 90, 0],
        theta=lambda q: [-q[0], q[1], q[2] + math.pi / 2, q[3], q[4], -q[5]],
        ranges_deg=KR16_2_RANGES),
    # FANUC R-2000iC/165F: base = FANUC world frame at the J2 height; J2 312 mm forward of J1,
    # J2 arm 1075 mm, J4 axis 225 mm above J3, J3 to wrist centre 1280 mm, faceplate 215 mm.
    # J3 is measured from the horizontal (theta3 = -(J2 + J3)); J3, J4, J5, J6 positive about
    # -y/-x (FANUC directions).
    "fanuc_r2000ic_165f": ControllerDhArm(
        a=[0.312, 1.075, 0.225, 0, 0, 0], d=[0, 0, 0, 1.280, 0, 0.215],
        alpha_deg=[-90, 0, -90, 90, -90, 0],
        theta=lambda q: [q[0], q[1] - math.pi / 2, -(q[1] + q[2]), -q[3], -q[4], -q[5]],
        ranges_deg=R2000IC_165F_RANGES, to_urdf=_fanuc_to_urdf),
    # Staubli TX2-60: base = Staubli world frame at the shoulder (axes 1 and 2 intersect), arm
    # 290 mm, 20 mm lateral offset, forearm 310 mm, flange 70 mm; zero = arm and forearm vertical.
    "staubli_tx2_60": ControllerDhArm(
        a=[0, 0.290, 0, 0, 0, 0], d=[0, 0.020, 0, 0.310, 0, 0.070],
        alpha_deg=[-90, 0, 90, -90, 90, 0],
        theta=lambda q: [q[0], q[1] - math.pi / 2, q[2] + math.pi / 2, q[3], q[4], q[5]],
        ranges_deg=TX2_60_RANGES),
    # Universal Robots UR10e DH table (UR's DH-parameters page).
    "ur10e": ControllerDhArm(
        a=[0, -0.6127, -0.57155, 0, 0, 0], d=[0.1807, 0, 0, 0.17415, 0.11985, 0.11655],
        alpha_deg=[90, 0, 0, 90, -90, 0], theta=lambda q: list(q), ranges_deg=UR10E_RANGES),
}

# Zero pose (all controller axes 0) from the data-sheet numbers: tool0 position (m) and the base
# directions of tool0's x and z axes.
ZERO_POSE = {
    "kuka_kr16_2": ((0.260 + 0.680 + 0.670 + 0.158, 0.0, 0.675 - 0.035), (0, 0, -1), (1, 0, 0)),
    "fanuc_r2000ic_165f": ((0.312 + 1.280 + 0.215, 0.0, 1.075 + 0.225), (0, 0, 1), (1, 0, 0)),
    "staubli_tx2_60": ((0.0, 0.020, 0.290 + 0.310 + 0.070), (1, 0, 0), (0, 0, 1)),
    "ur10e": ((-0.6127 - 0.57155, -(0.17415 + 0.11655), 0.1807 - 0.11985), (1, 0, 0), (0, -1, 0)),
}

# urdf_from_controller rows of the coupled robots among OTHER (the others have none: identity).
COUPLING = {"fanuc_r2000ic_165f": [[1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0], [0, 1, 1, 0, 0, 0],
                                   [0, 0, 0, 1, 0, 0], [0, 0, 0, 0, 1, 0], [0, 0, 0, 0, 0, 1]]}


# Expected total mass (kg) of base_link + link_1..link_6: (low, high).
TOTAL_MASS = {
    "abb_irb2400": (375.0, 385.0),
    "abb_irb2000": (300.0, 450.0),
    "abb_irb6400": (1900.0, 2300.0),
    "unimation_puma560": (60.0, 66.0),
    "ur5e": (20.0, 21.5),
    "kuka_kr16_2": (230.0, 240.0),           # 235 kg
    "fanuc_r2000ic_165f": (1050.0, 1130.0),  # about 1090 kg (unverified)
    "staubli_tx2_60": (50.0, 53.0),          # about 51.4 kg (unverified)
    "ur10e": (33.0, 34.0),                   # 33.5 kg
}

ALL = sorted(list(ABB) + list(DH) + list(OTHER))


# --------------------------------------------------------------------------- helpers


_GENERATED = tempfile.TemporaryDirectory(prefix="olp_robot_files_")


def urdf_path(name: str) -> Path:
    """The URDF generated from ``robots/NAME.robot.json``, written to a temporary file."""
    path = Path(_GENERATED.name) / f"{name}.urdf"
    if not path.exists():
        path.write_text(load_robot(name).urdf_text, encoding="utf-8")
    return path


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
    present = sorted(p.name[:-len(".robot.json")] for p in ROBOTS_DIR.glob("*.robot.json"))
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


@pytest.mark.parametrize("name", sorted(OTHER))
def test_other_zero_pose_numbers(name):
    """All controller axes 0: tool0 where the data-sheet numbers put it."""
    arm = OTHER[name]
    position, tool_x, tool_z = ZERO_POSE[name]
    model, data = load_pinocchio(name)
    pose = pin_tool0(model, data, arm.to_urdf(np.zeros(6)))
    assert np.max(np.abs(pose[:3, 3] - np.array(position))) < TOL, pose[:3, 3]
    assert np.allclose(pose[:3, 0], tool_x, atol=TOL) and np.allclose(pose[:3, 2], tool_z, atol=TOL)
    assert_pose_close(arm.fk(np.zeros(6)), pose)


@pytest.mark.parametrize("name", sorted(OTHER))
def test_other_random_configurations_against_dh(name):
    arm = OTHER[name]
    model, data = load_pinocchio(name)
    rng = np.random.default_rng(20240612)
    for _ in range(N_RANDOM):
        q_ctrl = arm.random_controller(rng)
        q_urdf = arm.to_urdf(q_ctrl)
        assert np.all(q_urdf >= model.lowerPositionLimit - 1e-12)
        assert np.all(q_urdf <= model.upperPositionLimit + 1e-12)
        assert_pose_close(pin_tool0(model, data, q_urdf), arm.fk(q_ctrl))


@pytest.mark.parametrize("name", sorted(OTHER))
def test_other_controller_files(name):
    """The record's controller part: the data-sheet axis ranges, sources, the coupling; the
    URDF limits equal the ranges (uncoupled joints) or their envelope (FANUC joint_3)."""
    import json

    doc = json.loads((ROBOTS_DIR / f"{name}.robot.json").read_text(encoding="utf-8"))
    assert doc["sources"] and all(isinstance(s, str) and s for s in doc["sources"])
    arm = OTHER[name]
    np.testing.assert_array_equal(np.array(doc["axis_ranges_deg"], dtype=float) * DEG, arm.ranges)
    coupling = load_robot(name).urdf_from_controller
    coupling = np.eye(6) if coupling is None else coupling
    np.testing.assert_array_equal(coupling, np.array(COUPLING.get(name, np.eye(6)), dtype=float))
    # the matrix is the reference model's map
    q = np.random.default_rng(5).uniform(-1, 1, 6)
    np.testing.assert_allclose(coupling @ q, arm.to_urdf(q), atol=1e-15)
    model, _ = load_pinocchio(name)
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    for i in range(6):
        row = coupling[i]
        positive, negative = np.where(row > 0, row, 0), np.where(row < 0, row, 0)
        expected_lower = arm.ranges[:, 0] @ positive + arm.ranges[:, 1] @ negative
        expected_upper = arm.ranges[:, 1] @ positive + arm.ranges[:, 0] @ negative
        assert abs(lower[i] - expected_lower) < 1e-12, (i, lower[i], expected_lower)
        assert abs(upper[i] - expected_upper) < 1e-12, (i, upper[i], expected_upper)


def test_fanuc_j2_j3_interaction():
    """FANUC's J3 is measured from the horizontal: J2 alone moves the J2 arm and keeps the J3
    arm's orientation; J3 positive raises the J3 arm; J5 positive tilts the faceplate up."""
    arm = OTHER["fanuc_r2000ic_165f"]
    model, data = load_pinocchio("fanuc_r2000ic_165f")
    zero = pin_tool0(model, data, arm.to_urdf(np.zeros(6)))
    small = 0.1
    pose = pin_tool0(model, data, arm.to_urdf([0, small, 0, 0, 0, 0]))
    assert np.allclose(pose[:3, :3], zero[:3, :3], atol=TOL)  # the J3 arm stays horizontal
    assert abs(pose[0, 3] - zero[0, 3] - 1.075 * math.sin(small)) < TOL  # J2 positive: forward
    assert pose[2, 3] < zero[2, 3]
    assert pin_tool0(model, data, arm.to_urdf([0, 0, small, 0, 0, 0]))[2, 3] > zero[2, 3]
    assert pin_tool0(model, data, arm.to_urdf([0, 0, 0, 0, small, 0]))[2, 3] > zero[2, 3]


def test_kuka_joint_directions():
    """KUKA: A1 positive turns clockwise seen from above; A2 = -90, A3 = +90 (home) puts the
    lower arm vertical and the forearm horizontal; A5 positive tilts the flange down."""
    arm = OTHER["kuka_kr16_2"]
    model, data = load_pinocchio("kuka_kr16_2")
    zero = pin_tool0(model, data, np.zeros(6))[:3, 3]
    assert pin_tool0(model, data, [0.1, 0, 0, 0, 0, 0])[1, 3] < 0.0
    home = pin_tool0(model, data, [0, -math.pi / 2, math.pi / 2, 0, 0, 0])
    assert np.max(np.abs(home[:3, 3] - [0.260 + 0.670 + 0.158, 0, 0.675 + 0.680 - 0.035])) < TOL
    assert np.allclose(home[:3, 2], [1, 0, 0], atol=TOL)
    assert pin_tool0(model, data, [0, 0, 0, 0, 0.1, 0])[2, 3] < zero[2]
    assert_pose_close(home, arm.fk([0, -math.pi / 2, math.pi / 2, 0, 0, 0]))


@pytest.mark.parametrize("name", sorted(OTHER))
def test_other_closed_form_family_fits(name):
    """Each new arm is a spherical-wrist (OPW) or UR-type arm, so the package's closed-form
    IK family fits its URDF chain."""
    from olp_compensate.compensation.ik import OPWParameters, URParameters, fit_family

    model, data = load_pinocchio(name)

    def flange(q):
        return np.array([pin_tool0(model, data, row) for row in np.atleast_2d(q)])

    family = fit_family(flange)
    expected = URParameters if name == "ur10e" else OPWParameters
    assert isinstance(family, expected), family


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
    """olp_compensate.kinematics.urdf reads every joint as yourdfpy does (origin, axis, limits)."""
    from olp_compensate.kinematics.urdf import read_urdf_chain

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
    from olp_compensate.kinematics.urdf import read_urdf_chain

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
    from olp_compensate.kinematics.urdf import read_urdf_chain

    with pytest.raises(ModelError, match=message):
        read_urdf_chain(text, "bad.urdf")
