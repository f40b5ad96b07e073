"""Virtual robots with known truth, for tests, benchmarks and planning a measurement campaign.

A virtual robot is the nominal URDF with a random rigid error on every joint origin (about
1 mm and 0.1 degree per link), a zero offset on every joint, a measuring device placed
anywhere, and measured points on the tool. Its truth is evaluated with pinocchio on the
perturbed URDF model, a code path independent of :mod:`olp_compensate.model`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from .conventions import matrix_from_quat_wxyz, quat_wxyz_from_matrix, rotation_from_rotvec
from .errors import ModelError
from .io.measurements import Measurements
from .robot import Robot

TRUTH_FORMAT = "olp-compensate virtual robot"


@dataclass(frozen=True)
class VirtualRobot:
    """A nominal robot plus known errors.

    ``origin_errors``: (n, 6) per joint, translation (m) then rotation vector (rad), applied
    on the right of each joint origin; ``joint_offsets``: (n,) rad or m, true joint =
    reading + offset; ``device_T_base``: (4, 4); ``tools``: name -> (3,) flange frame, m.
    """

    robot: Robot
    origin_errors: np.ndarray
    joint_offsets: np.ndarray
    device_T_base: np.ndarray
    tools: dict[str, np.ndarray]
    seed: int | None = None
    notes: dict = field(default_factory=dict)

    def _pinocchio(self):
        import pinocchio as pin

        model = self.robot.pinocchio_model.copy()
        for jid, err in zip(self.robot.pinocchio_joint_ids(), self.origin_errors):
            model.jointPlacements[jid] = model.jointPlacements[jid] * pin.SE3(
                rotation_from_rotvec(err[3:]), err[:3].copy())
        return pin, model

    def flange_poses(self, joints: np.ndarray) -> np.ndarray:
        """True flange poses (m, 4, 4), base frame, for controller readings (m, n), rad/m."""
        pin, model = self._pinocchio()
        data = model.createData()
        frame = model.getFrameId(self.robot.flange_link)
        ids = self.robot.pinocchio_joint_ids()
        out = np.empty((len(joints), 4, 4))
        urdf_joints = self.robot.joints_from_controller(np.atleast_2d(joints)) + self.joint_offsets
        for k, reading in enumerate(urdf_joints):
            qp = pin.neutral(model)
            for jid, value in zip(ids, reading):
                j = model.joints[jid]
                if j.nq == 2:  # continuous joint: (cos, sin)
                    qp[j.idx_q:j.idx_q + 2] = np.cos(value), np.sin(value)
                else:
                    qp[j.idx_q] = value
            pin.framesForwardKinematics(model, data, qp)
            out[k] = data.oMf[frame].homogeneous
        return out

    def true_points(self, joints: np.ndarray, names) -> np.ndarray:
        """Noise-free positions (m, 3) of the named tool points in the device frame, m."""
        flange = self.flange_poses(joints)
        local = np.array([self.tools[n] for n in names]).reshape(-1, 3)
        base = flange[:, :3, 3] + np.einsum("mij,mj->mi", flange[:, :3, :3], local)
        return base @ self.device_T_base[:3, :3].T + self.device_T_base[:3, 3]

    def measure(self, joints: np.ndarray, noise_m: float, rng: np.random.Generator,
                points_per_pose: list[str] | None = None) -> Measurements:
        """Measure every tool point (or the given names) at each joint vector, with Gaussian
        noise of ``noise_m`` per axis."""
        names = points_per_pose or sorted(self.tools)
        joints = np.atleast_2d(joints)
        q = np.repeat(joints, len(names), axis=0)
        point_names = np.array(names * len(joints), dtype=object)
        pose_ids = np.array([str(k + 1) for k in range(len(joints)) for _ in names], dtype=object)
        points = self.true_points(q, point_names) + rng.normal(0.0, noise_m, (len(q), 3))
        return Measurements(joints=q, points=points, pose_ids=pose_ids, point_names=point_names,
                            rows=np.arange(len(q)) + 1, source="<virtual robot>")

    def to_json(self) -> str:
        """The truth file (mm and degrees)."""
        doc = {
            "format": TRUTH_FORMAT, "version": 1, "robot": self.robot.name,
            "fingerprint": self.robot.fingerprint, "seed": self.seed,
            "origin_errors": [{"joint": k + 1, "xyz_mm": (e[:3] * 1e3).tolist(),
                               "rotvec_deg": np.degrees(e[3:]).tolist()}
                              for k, e in enumerate(self.origin_errors)],
            "joint_offsets": self.robot.to_degrees_or_mm(self.joint_offsets[None])[0].tolist(),
            "joint_offsets_unit": [j.unit for j in self.robot.joints],
            "device_T_base": {"xyz_mm": (self.device_T_base[:3, 3] * 1e3).tolist(),
                              "quat_wxyz": quat_wxyz_from_matrix(self.device_T_base[:3, :3]).tolist()},
            "tools": {n: {"xyz_mm": (v * 1e3).tolist()} for n, v in self.tools.items()},
            **self.notes,
        }
        return json.dumps(doc, indent=2) + "\n"

    @classmethod
    def from_json(cls, text: str, robot: Robot) -> "VirtualRobot":
        doc = json.loads(text)
        if doc.get("format") != TRUTH_FORMAT or doc.get("version") != 1:
            raise ModelError("not an olp-compensate virtual robot truth file (version 1)")
        if doc["fingerprint"] != robot.fingerprint:
            raise ModelError(f"the truth file was made for robot '{doc['robot']}', not {robot.name}")
        errors = np.array([e["xyz_mm"] + e["rotvec_deg"] for e in doc["origin_errors"]])
        errors[:, :3] *= 1e-3
        errors[:, 3:] = np.radians(errors[:, 3:])
        pose = np.eye(4)
        pose[:3, :3] = matrix_from_quat_wxyz(doc["device_T_base"]["quat_wxyz"])
        pose[:3, 3] = np.array(doc["device_T_base"]["xyz_mm"]) * 1e-3
        return cls(robot=robot, origin_errors=errors,
                   joint_offsets=robot.to_radians_or_metres(np.array(doc["joint_offsets"])[None])[0],
                   device_T_base=pose,
                   tools={n: np.array(t["xyz_mm"]) * 1e-3 for n, t in doc["tools"].items()},
                   seed=doc.get("seed"))


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly distributed random rotation matrix (3, 3)."""
    quat = rng.normal(size=4)
    return matrix_from_quat_wxyz(quat / np.linalg.norm(quat))


def make_virtual_robot(robot: Robot, seed: int, length_error_m: float = 1e-3,
                       angle_error_rad: float = np.radians(0.1), n_points: int = 1,
                       device_distance_m: float = 2.0) -> VirtualRobot:
    """A virtual robot with errors drawn from ``seed``: per joint origin N(0, length) per
    axis and N(0, angle) per rotation axis, zero offsets N(0, angle), a device at a random
    orientation ``device_distance_m`` away, and ``n_points`` tool points ('tcp', 'p2', ...)
    50-250 mm from the flange."""
    rng = np.random.default_rng(seed)
    n = robot.n_joints
    errors = np.hstack([rng.normal(0, length_error_m, (n, 3)), rng.normal(0, angle_error_rad, (n, 3))])
    offsets = np.array([rng.normal(0, angle_error_rad) if j.kind == "revolute"
                        else rng.normal(0, length_error_m) for j in robot.joints])
    device = np.eye(4)
    device[:3, :3] = random_rotation(rng)
    direction = rng.normal(size=3)
    device[:3, 3] = device_distance_m * direction / np.linalg.norm(direction)
    tools = {}
    for k in range(n_points):
        name = "tcp" if k == 0 else f"p{k + 1}"
        tools[name] = np.array([rng.uniform(-0.08, 0.08), rng.uniform(-0.08, 0.08),
                                rng.uniform(0.05, 0.25)])
    return VirtualRobot(robot=robot, origin_errors=errors, joint_offsets=offsets,
                        device_T_base=device, tools=tools, seed=seed)


def random_joints(robot: Robot, n: int, rng: np.random.Generator, margin: float = 0.1) -> np.ndarray:
    """n controller joint vectors (n, joints) whose URDF joints lie uniformly inside the limits
    shrunk by ``margin`` (revolute joints also kept within +-170 degrees)."""
    lower = np.maximum(robot.lower_limits, [-np.radians(170) if j.kind == "revolute" else -np.inf
                                            for j in robot.joints])
    upper = np.minimum(robot.upper_limits, [np.radians(170) if j.kind == "revolute" else np.inf
                                            for j in robot.joints])
    span = upper - lower
    urdf_joints = rng.uniform(lower + margin * span / 2, upper - margin * span / 2, (n, robot.n_joints))
    return robot.controller_from_joints(urdf_joints)
