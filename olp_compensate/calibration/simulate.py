"""Virtual robots with known truth, for tests, benchmarks and planning a measurement campaign.

A virtual robot is the nominal URDF with a random rigid error on every joint origin (about
1 mm and 0.1 degree per link), a zero offset on every joint, a measuring device placed
anywhere, and measured points on the tool. Its truth is evaluated with pinocchio on the
perturbed URDF model, a code path independent of :mod:`olp_compensate.kinematics.model`.

It may also hide non-geometric effects (:class:`HiddenEffect`), evaluated here on their own
terms and independently of :mod:`olp_compensate.calibration.effects`: gravity torques come from
``pinocchio.computeGeneralizedGravity`` on the *true* (perturbed) model at the *true*
joints, with the payload added through the flange frame's Jacobian; compliance is solved as
a fixed point (the arm sags until the spring balances gravity); thermal expansion scales
every joint placement of the pinocchio model. Joint effects act on the controller axes.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace

import numpy as np

from ..kinematics.conventions import matrix_from_quat_wxyz, quat_wxyz_from_matrix, rotation_from_rotvec
from ..errors import DataError, ModelError
from .measurements import Measurements
from ..kinematics.robot import Robot

TRUTH_FORMAT = "olp-compensate virtual robot"
HIDDEN_KINDS = ("joint_compliance", "gear_harmonic", "backlash", "thermal_expansion", "joint_scale")
CYCLIC_KIND = "cyclic_error"
"""A cyclic angle error of any orders (:func:`random_cyclic_error`); not in HIDDEN_KINDS,
which the classic benchmark cycles through."""
HIDDEN_UNITS = {"joint_compliance": "rad/N.m", "gear_harmonic": "rad", "backlash": "rad",
                "thermal_expansion": "1/K", "joint_scale": "rad/rad", CYCLIC_KIND: "rad"}


@dataclass(frozen=True)
class HiddenEffect:
    """A non-geometric effect of a virtual robot (truth; SI units).

    ``kind`` one of :data:`HIDDEN_KINDS`; ``joint`` 0-based controller axis (None for
    thermal expansion); ``value``: compliance c (rad/N.m, dq = c * load torque), harmonic
    amplitude A (rad, dq = A sin(k q + phase)), backlash gap w (rad, dq = w/2 * sign of the
    load torque, or -w/2 * approach direction), expansion coefficient alpha (1/K, lengths
    times 1 + alpha (T - T0)), or scale s (dq = s q); cyclic error: dq = value *
    sum_i w_i sin(k_i q + phi_i) over ``band`` = ((k_i, w_i, phi_i), ...).
    """

    kind: str
    joint: int | None
    value: float
    order: int = 1
    phase_rad: float = 0.0
    reference_temperature_c: float = 20.0
    band: tuple[tuple[int, float, float], ...] = ()

    def cyclic(self, angle: float) -> float:
        """The cyclic error's dq at the axis value ``angle`` (rad)."""
        return self.value * sum(w * np.sin(k * angle + phi) for k, w, phi in self.band)

    @property
    def dominant_order(self) -> int:
        """The order of largest weight of a cyclic error's band."""
        return int(max(self.band, key=lambda t: abs(t[1]))[0])

    @property
    def label(self) -> str:
        if self.joint is None:
            return self.kind
        order = f" k={self.order}" if self.kind == "gear_harmonic" else ""
        return f"{self.kind}{order} j{self.joint + 1}"

    def to_dict(self) -> dict:
        return {"kind": self.kind, "joint": None if self.joint is None else self.joint + 1,
                "value": self.value, "unit": HIDDEN_UNITS[self.kind], "order": self.order,
                "phase_rad": self.phase_rad,
                "reference_temperature_c": self.reference_temperature_c,
                **({"band": [list(t) for t in self.band]} if self.band else {})}

    @classmethod
    def from_dict(cls, doc: dict) -> "HiddenEffect":
        return cls(kind=doc["kind"], joint=None if doc["joint"] is None else int(doc["joint"]) - 1,
                   value=float(doc["value"]), order=int(doc.get("order", 1)),
                   phase_rad=float(doc.get("phase_rad", 0.0)),
                   reference_temperature_c=float(doc.get("reference_temperature_c", 20.0)),
                   band=tuple((int(k), float(w), float(p)) for k, w, p in doc.get("band", ())))


@dataclass(frozen=True)
class VirtualRobot:
    """A nominal robot plus known errors.

    ``origin_errors``: (n, 6) per joint, translation (m) then rotation vector (rad), applied
    on the right of each joint origin; ``joint_offsets``: (n,) rad or m, true joint =
    reading + offset; ``device_T_base``: (4, 4); ``tools``: name -> (3,) flange frame, m;
    ``effects``: hidden non-geometric effects; ``tool_rotations``: name -> (3, 3) rotation of
    the tool's frame in the flange frame (missing: the flange's own), which a full-pose
    device measures. A payload sits at the tool point 'tcp' (else the first tool point).
    """

    robot: Robot
    origin_errors: np.ndarray
    joint_offsets: np.ndarray
    device_T_base: np.ndarray
    tools: dict[str, np.ndarray]
    seed: int | None = None
    notes: dict = field(default_factory=dict)
    effects: tuple[HiddenEffect, ...] = ()
    tool_rotations: dict[str, np.ndarray] = field(default_factory=dict)

    def _pinocchio(self):
        import pinocchio as pin

        model = self.robot.pinocchio_model.copy()
        for jid, err in zip(self.robot.pinocchio_joint_ids(), self.origin_errors):
            model.jointPlacements[jid] = model.jointPlacements[jid] * pin.SE3(
                rotation_from_rotvec(err[3:]), err[:3].copy())
        return pin, model

    @staticmethod
    def _configuration(pin, model, ids, urdf_joints):
        qp = pin.neutral(model)
        for jid, value in zip(ids, urdf_joints):
            j = model.joints[jid]
            if j.nq == 2:  # continuous joint: (cos, sin)
                qp[j.idx_q:j.idx_q + 2] = np.cos(value), np.sin(value)
            else:
                qp[j.idx_q] = value
        return qp

    def _payload_point(self) -> np.ndarray:
        if not self.tools:
            return np.zeros(3)
        return np.asarray(self.tools["tcp"] if "tcp" in self.tools else self.tools[sorted(self.tools)[0]])

    def flange_poses(self, joints: np.ndarray, payload_kg=None, temperature_c=None,
                     directions=None) -> np.ndarray:
        """True flange poses (m, 4, 4), base frame, for controller readings (m, n), rad/m;
        optional per-row ``payload_kg`` (m,), ``temperature_c`` (m,), approach
        ``directions`` (m, n) (+1/-1/0) feed the hidden effects."""
        pin, model = self._pinocchio()
        data = model.createData()
        frame = model.getFrameId(self.robot.flange_link)
        ids = self.robot.pinocchio_joint_ids()
        idx_v = [model.joints[i].idx_v for i in ids]
        joints = np.atleast_2d(np.asarray(joints, dtype=float))
        m = len(joints)
        coupling = (np.eye(self.robot.n_joints) if self.robot.urdf_from_controller is None
                    else self.robot.urdf_from_controller)
        placements = [model.jointPlacements[k].copy() for k in range(model.njoints)]
        frame_placement = model.frames[frame].placement.copy()
        thermal = [e for e in self.effects if e.kind == "thermal_expansion"]
        joint_effects = [e for e in self.effects if e.kind != "thermal_expansion"]
        uses_gravity = any(e.kind in ("joint_compliance", "backlash") for e in joint_effects)
        payload_point = self._payload_point()
        gravity = model.gravity.linear.copy()
        out = np.empty((m, 4, 4))
        for k in range(m):
            scale = 1.0
            if thermal:
                if temperature_c is None:
                    raise DataError("the virtual robot expands with temperature: give temperatures")
                scale += sum(e.value * (temperature_c[k] - e.reference_temperature_c) for e in thermal)
                for jid in range(1, model.njoints):
                    model.jointPlacements[jid] = pin.SE3(placements[jid].rotation,
                                                         scale * placements[jid].translation)
                model.frames[frame].placement = pin.SE3(frame_placement.rotation,
                                                        scale * frame_placement.translation)
            reading = joints[k]
            actual = reading.copy()
            for _ in range(4 if uses_gravity else 1):  # compliance: fixed point of the sag
                urdf = coupling @ actual + self.joint_offsets
                qp = self._configuration(pin, model, ids, urdf)
                load = np.zeros(self.robot.n_joints)
                if uses_gravity:
                    load_urdf = -pin.computeGeneralizedGravity(model, data, qp)[idx_v]
                    mass = 0.0 if payload_kg is None else float(payload_kg[k])
                    if mass:
                        jac = pin.computeFrameJacobian(model, data, qp, frame,
                                                       pin.LOCAL_WORLD_ALIGNED)
                        lever = data.oMf[frame].rotation @ payload_point
                        point_jac = jac[:3] - np.cross(lever[:, None], jac[3:], axis=0)
                        load_urdf = load_urdf + (point_jac.T @ (mass * gravity))[idx_v]
                    load = coupling.T @ load_urdf  # virtual work: controller-axis torques
                dq = np.zeros(self.robot.n_joints)
                for e in joint_effects:
                    j = e.joint
                    if e.kind == "joint_compliance":
                        dq[j] += e.value * load[j]
                    elif e.kind == "gear_harmonic":
                        dq[j] += e.value * np.sin(e.order * reading[j] + e.phase_rad)
                    elif e.kind == "joint_scale":
                        dq[j] += e.value * reading[j]
                    elif e.kind == CYCLIC_KIND:
                        dq[j] += e.cyclic(reading[j])
                    elif e.kind == "backlash":
                        d = 0.0 if directions is None else directions[k][j]
                        if d != 0:
                            side = -np.sign(d)
                        else:
                            side = np.sign(load[j]) if abs(load[j]) > 1e-6 else 0.0
                        dq[j] += 0.5 * e.value * side
                actual = reading + dq
            urdf = coupling @ actual + self.joint_offsets
            qp = self._configuration(pin, model, ids, urdf)
            pin.framesForwardKinematics(model, data, qp)
            out[k] = data.oMf[frame].homogeneous
        return out

    def true_points(self, joints: np.ndarray, names, payload_kg=None, temperature_c=None,
                    directions=None) -> np.ndarray:
        """Noise-free positions (m, 3) of the named tool points in the device frame, m."""
        flange = self.flange_poses(joints, payload_kg, temperature_c, directions)
        local = np.array([self.tools[n] for n in names]).reshape(-1, 3)
        base = flange[:, :3, 3] + np.einsum("mij,mj->mi", flange[:, :3, :3], local)
        return base @ self.device_T_base[:3, :3].T + self.device_T_base[:3, 3]

    def tool_rotation(self, name: str) -> np.ndarray:
        """Rotation (3, 3) of tool ``name``'s frame in the flange frame."""
        return np.asarray(self.tool_rotations.get(name, np.eye(3)), dtype=float)

    def true_frames(self, joints: np.ndarray, names, payload_kg=None, temperature_c=None,
                    directions=None) -> np.ndarray:
        """Noise-free poses (m, 4, 4) of the named tools' frames in the device frame, m."""
        flange = self.flange_poses(joints, payload_kg, temperature_c, directions)
        names = list(names)
        local = np.array([self.tools[n] for n in names]).reshape(-1, 3)
        turn = np.array([self.tool_rotation(n) for n in names]).reshape(-1, 3, 3)
        frames = np.zeros((len(flange), 4, 4))
        frames[:, :3, :3] = self.device_T_base[:3, :3] @ flange[:, :3, :3] @ turn
        base = flange[:, :3, 3] + np.einsum("mij,mj->mi", flange[:, :3, :3], local)
        frames[:, :3, 3] = base @ self.device_T_base[:3, :3].T + self.device_T_base[:3, 3]
        frames[:, 3, 3] = 1.0
        return frames

    def measure(self, joints: np.ndarray, noise_m: float, rng: np.random.Generator,
                points_per_pose: list[str] | None = None, payload_kg=None, temperature_c=None,
                time_s=None, directions=None, pose_ids=None,
                orientation_noise_rad: float | None = None) -> Measurements:
        """Measure every tool point (or the given names) at each joint vector, with Gaussian
        noise of ``noise_m`` per axis. Per pose (P,): ``payload_kg``, ``temperature_c``,
        ``time_s``; ``directions`` (P, n) approach directions, +1/-1 (0: unknown);
        ``pose_ids`` (default '1', '2', ...; repeat one to measure a pose again).
        With ``orientation_noise_rad`` (rad per axis, a small rotation of the tool frame
        about its own axes) also the orientation of each tool's frame, as a full-pose device
        does (``Measurements.orientation``)."""
        names = points_per_pose or sorted(self.tools)
        joints = np.atleast_2d(joints)
        per = len(names)

        def rows(a):
            return None if a is None else np.repeat(np.asarray(a, dtype=float), per, axis=0)

        q = np.repeat(joints, per, axis=0)
        point_names = np.array(names * len(joints), dtype=object)
        ids = [str(k + 1) for k in range(len(joints))] if pose_ids is None else list(pose_ids)
        pose_ids = np.array([ids[k] for k in range(len(joints)) for _ in names], dtype=object)
        payload, temperature, when, direction = (rows(payload_kg), rows(temperature_c),
                                                 rows(time_s), rows(directions))
        orientation = None
        if orientation_noise_rad is None:
            points = self.true_points(q, point_names, payload, temperature, direction)
        else:
            frames = self.true_frames(q, point_names, payload, temperature, direction)
            points = frames[:, :3, 3]
        points = points + rng.normal(0.0, noise_m, (len(q), 3))
        if orientation_noise_rad is not None:
            turn = rotation_from_rotvec(rng.normal(0.0, orientation_noise_rad, (len(q), 3)))
            orientation = quat_wxyz_from_matrix(frames[:, :3, :3] @ turn)
        return Measurements(joints=q, points=points, pose_ids=pose_ids, point_names=point_names,
                            orientation=orientation,
                            payload_kg=payload, temperature_c=temperature, time_s=when,
                            directions=direction, rows=np.arange(len(q)) + 1,
                            source="<virtual robot>")

    def to_json(self) -> str:
        """The truth file (mm and degrees; hidden effects in SI with their units)."""
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
            "tools": {n: {"xyz_mm": (v * 1e3).tolist(),
                          "quat_wxyz": quat_wxyz_from_matrix(self.tool_rotation(n)).tolist()}
                      for n, v in self.tools.items()},
            "hidden_effects": [e.to_dict() for e in self.effects],
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
                   seed=doc.get("seed"),
                   effects=tuple(HiddenEffect.from_dict(e) for e in doc.get("hidden_effects", [])),
                   tool_rotations={n: matrix_from_quat_wxyz(t["quat_wxyz"])
                                   for n, t in doc["tools"].items() if t.get("quat_wxyz")})


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
    50-250 mm from the flange, each with its frame at a random orientation (drawn after
    everything else, so a seed gives the same errors, device and points as before)."""
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
    rotations = {name: random_rotation(rng) for name in tools}
    return VirtualRobot(robot=robot, origin_errors=errors, joint_offsets=offsets,
                        device_T_base=device, tools=tools, seed=seed, tool_rotations=rotations)


def random_joints(robot: Robot, n: int, rng: np.random.Generator, margin: float = 0.1,
                  within_ranges: bool = True) -> np.ndarray:
    """n controller joint vectors (n, joints) whose URDF joints lie uniformly inside the limits
    shrunk by ``margin`` (revolute joints also kept within +-170 degrees) and, with
    ``within_ranges``, whose controller axes lie inside the controller's axis ranges shrunk
    alike (draws outside are redrawn, so a parallel-linkage arm gets only poses its
    controller accepts). ``within_ranges=False``: the URDF joints' envelope only."""
    lower = np.maximum(robot.lower_limits, [-np.radians(170) if j.kind == "revolute" else -np.inf
                                            for j in robot.joints])
    upper = np.minimum(robot.upper_limits, [np.radians(170) if j.kind == "revolute" else np.inf
                                            for j in robot.joints])
    span = upper - lower
    ranges = robot.controller_ranges if within_ranges else np.full((robot.n_joints, 2), np.inf) * [-1, 1]
    finite = np.isfinite(ranges).all(axis=1)
    half = np.where(finite, margin * (ranges[:, 1] - ranges[:, 0]) / 2, 0.0)
    low, high = ranges[:, 0] + half, ranges[:, 1] - half
    chosen = np.zeros((0, robot.n_joints))
    for _ in range(1000):
        urdf_joints = rng.uniform(lower + margin * span / 2, upper - margin * span / 2,
                                  (n, robot.n_joints))
        q = robot.controller_from_joints(urdf_joints)
        inside = np.all((q >= low) & (q <= high), axis=1)
        chosen = np.concatenate([chosen, q[inside]])
        if len(chosen) >= n:
            return chosen[:n]
    raise ModelError(f"{robot.name}: the URDF limits and the controller's axis ranges leave "
                     "(almost) no joint values that satisfy both")


UNIT_VALUES = {"joint_compliance": 1e-6, "gear_harmonic": 1e-4, "backlash": 1e-4,
               "thermal_expansion": 1e-5, "joint_scale": 1e-4, CYCLIC_KIND: 1e-4}
"""A small value of each hidden kind, the starting point for scaling to a wanted size."""


def load_torque_rms(robot: Robot, joints: np.ndarray) -> np.ndarray:
    """RMS over the poses (m, n) of the gravity load torque about each controller axis
    (n,), N.m, on the nominal robot without payload (pinocchio)."""
    virtual = VirtualRobot(robot=robot, origin_errors=np.zeros((robot.n_joints, 6)),
                           joint_offsets=np.zeros(robot.n_joints), device_T_base=np.eye(4),
                           tools={})
    import pinocchio as pin

    model = robot.pinocchio_model
    data = model.createData()
    ids = robot.pinocchio_joint_ids()
    idx_v = [model.joints[i].idx_v for i in ids]
    coupling = np.eye(robot.n_joints) if robot.urdf_from_controller is None else robot.urdf_from_controller
    torques = []
    for reading in np.atleast_2d(joints):
        qp = virtual._configuration(pin, model, ids, coupling @ reading)
        tau = -pin.computeGeneralizedGravity(model, data, qp)[idx_v]
        torques.append(coupling.T @ tau)
    return np.sqrt(np.mean(np.square(torques), axis=0))


def effect_rms(virtual: VirtualRobot, effect: HiddenEffect, joints: np.ndarray,
               payload_kg=None, temperature_c=None, directions=None) -> float:
    """RMS over the poses (m, n) of how far ``effect`` alone moves the measured points
    (every tool point), m: the size the hidden-effect tests are stated in."""
    names = sorted(virtual.tools)
    q = np.repeat(np.atleast_2d(joints), len(names), axis=0)
    point_names = names * len(np.atleast_2d(joints))

    def rows(a):
        return None if a is None else np.repeat(np.asarray(a, float), len(names), axis=0)

    others = tuple(e for e in virtual.effects if e != effect)
    base = replace(virtual, effects=others).true_points(q, point_names, rows(payload_kg),
                                                        rows(temperature_c), rows(directions))
    moved = replace(virtual, effects=others + (effect,)).true_points(
        q, point_names, rows(payload_kg), rows(temperature_c), rows(directions))
    return float(np.sqrt(np.mean(np.sum((moved - base) ** 2, axis=1))))


def scaled_effect(virtual: VirtualRobot, effect: HiddenEffect, joints: np.ndarray,
                  target_rms_m: float, **conditions) -> HiddenEffect:
    """``effect`` with its value scaled so that it moves the measured points by
    ``target_rms_m`` RMS over ``joints`` (see :func:`effect_rms`); keeps the sign."""
    value = effect.value if effect.value != 0 else UNIT_VALUES[effect.kind]
    for _ in range(2):  # compliance is slightly nonlinear (the sag changes the torque)
        trial = replace(effect, value=value)
        size = effect_rms(virtual, trial, joints, **conditions)
        if size == 0:
            raise DataError(f"{effect.label} does not move the measured points at these poses")
        value *= target_rms_m / size
    return replace(effect, value=value)


def random_hidden_effect(robot: Robot, rng: np.random.Generator, joints: np.ndarray,
                         kind: str | None = None, joint: int | None = None,
                         kinds=HIDDEN_KINDS) -> HiddenEffect:
    """A hidden effect drawn from ``rng`` (value = the kind's unit value; scale it with
    :func:`scaled_effect`). Compliance and backlash go on axes whose RMS gravity torque over
    ``joints`` is at least 5 % of the largest; harmonics (order 1-3, random phase) and
    scale on any revolute axis; thermal expansion only when in ``kinds``."""
    kind = kind or str(rng.choice(list(kinds)))
    if kind not in HIDDEN_KINDS:
        raise DataError(f"unknown effect kind '{kind}' (known: {', '.join(HIDDEN_KINDS)})")
    if kind == "thermal_expansion":
        return HiddenEffect(kind, None, UNIT_VALUES[kind] * rng.uniform(1.0, 2.5))
    revolute = [j for j, spec in enumerate(robot.joints) if spec.kind == "revolute"]
    if kind in ("joint_compliance", "backlash"):
        rms = load_torque_rms(robot, joints)
        allowed = [j for j in revolute if rms[j] >= 0.05 * rms.max()]
    else:
        allowed = revolute
    if joint is None:
        joint = int(rng.choice(allowed))
    sign = 1.0 if kind in ("joint_compliance", "backlash") else float(rng.choice([-1.0, 1.0]))
    return HiddenEffect(kind, joint, sign * UNIT_VALUES[kind],
                        order=int(rng.integers(1, 4)) if kind == "gear_harmonic" else 1,
                        phase_rad=float(rng.uniform(-np.pi, np.pi)) if kind == "gear_harmonic" else 0.0)


def random_cyclic_error(robot: Robot, rng: np.random.Generator, orders=(5, 40),
                        band: bool = False, joint: int | None = None) -> HiddenEffect:
    """A hidden cyclic angle error on a random revolute axis (or ``joint``): one order
    drawn in ``orders`` (inclusive), or with ``band`` that order plus two neighbours at
    weights 0.5 and 0.3; random phases; value 1e-4 rad (scale it with
    :func:`scaled_effect`)."""
    revolute = [j for j, spec in enumerate(robot.joints) if spec.kind == "revolute"]
    joint = int(rng.choice(revolute)) if joint is None else joint
    order = int(rng.integers(orders[0], orders[1] + 1))
    terms = [(order, 1.0)]
    if band:
        terms += [(max(1, order - 1), 0.5), (order + 2, 0.3)]
    return HiddenEffect(CYCLIC_KIND, joint, UNIT_VALUES[CYCLIC_KIND],
                        band=tuple((k, w, float(rng.uniform(-np.pi, np.pi))) for k, w in terms))
