"""A robot description: the serial chain of a URDF, from its root link to the flange.

The URDF is read by :mod:`olp_compensate.kinematics.urdf`; dynamics (gravity torques) are computed with pinocchio from
the same text. Joint frames, axes and limits are kept exactly as the URDF gives them (metres,
radians); the calibration model (:mod:`olp_compensate.kinematics.model`) is built from them.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from ..data import data_folder
from ..errors import ModelError
from .record_urdf import urdf_and_document
from .records import RECORD_SUFFIX, RobotRecord, read_record
from .urdf import UrdfDocument, read_urdf_chain

FLANGE_LINK = "tool0"

# SHA-256 from CPython's own module (3.11: _sha256, 3.12+: _sha2), the digest hashlib gives,
# without importing hashlib (OpenSSL and every algorithm: 2-4 ms of a command's start, issue
# 32); hashlib's on a Python built without it.
try:
    from _sha256 import sha256
except ImportError:
    try:
        from _sha2 import sha256
    except ImportError:
        from hashlib import sha256


@dataclass(frozen=True)
class Joint:
    """One movable joint of the chain.

    ``parent_T_joint`` is the joint frame in the frame of the previous movable joint (or of
    the root link for the first joint) at zero position, fixed joints in between folded in.
    ``axis`` is the unit motion axis in the joint frame; ``kind`` is ``'revolute'`` (radians)
    or ``'prismatic'`` (metres).
    """

    name: str
    kind: str
    parent_T_joint: np.ndarray
    axis: np.ndarray
    lower: float
    upper: float
    velocity: float
    effort: float
    child_link: str

    @property
    def unit(self) -> str:
        """Unit of the joint reading at the edges: ``'deg'`` or ``'mm'``."""
        return "deg" if self.kind == "revolute" else "mm"


@dataclass(frozen=True)
class Robot:
    """A serial arm read from a URDF (base = root link, flange = ``tool0``)."""

    name: str
    urdf_text: str
    joints: tuple[Joint, ...]
    last_T_flange: np.ndarray
    base_link: str
    flange_link: str = FLANGE_LINK
    source: str = field(default="", compare=False)
    urdf_from_controller: np.ndarray | None = None
    """(n, n) map from controller axis values to URDF joints (ABB parallel linkage: joint 3
    = q3 - q2); None means the identity. Every public joint array is in controller axes."""
    axis_ranges: np.ndarray | None = field(default=None, compare=False)
    """(n, 2) the controller's axis ranges (data sheet), rad or m, in controller axes; None:
    the URDF limits of the joints that are controller axes as they are."""
    record: RobotRecord | None = field(default=None, compare=False, repr=False)
    """The robot record the URDF was generated from (None for a URDF file)."""

    @property
    def n_joints(self) -> int:
        return len(self.joints)

    @property
    def lower_limits(self) -> np.ndarray:
        """Lower joint limits, shape (n,), rad or m."""
        return np.array([j.lower for j in self.joints])

    @property
    def upper_limits(self) -> np.ndarray:
        """Upper joint limits, shape (n,), rad or m."""
        return np.array([j.upper for j in self.joints])

    @property
    def controller_ranges(self) -> np.ndarray:
        """(n, 2) lower and upper range of each controller axis, rad or m.

        The data sheet's ranges when the robot file gives them; otherwise the URDF limits of
        the joints that are controller axes unchanged, and no bound (inf) on the axes a
        coupling mixes (their limits then apply to the URDF joints only).
        """
        if self.axis_ranges is not None:
            return self.axis_ranges
        ranges = np.stack([self.lower_limits, self.upper_limits], 1)
        if self.urdf_from_controller is not None:
            plain = np.all(np.isclose(self.urdf_from_controller, np.eye(self.n_joints)), axis=1)
            ranges[~plain] = (-np.inf, np.inf)
        return ranges

    def outside_ranges(self, q_controller: np.ndarray, tolerance: float = 1e-9) -> np.ndarray:
        """(m, n) bool: where controller axes ``q_controller (m, n)`` (rad, m) lie outside the
        controller's axis ranges or put a URDF joint outside its limits (``tolerance`` in
        rad or m)."""
        q = np.atleast_2d(np.asarray(q_controller, dtype=float))
        ranges = self.controller_ranges
        outside = (q < ranges[:, 0] - tolerance) | (q > ranges[:, 1] + tolerance)
        joints = self.joints_from_controller(q)
        outside |= (joints < self.lower_limits - tolerance) | (joints > self.upper_limits + tolerance)
        return outside

    @cached_property
    def fingerprint(self) -> str:
        """SHA-256 of the kinematic chain (joint kinds, frames, axes, flange; rounded to 1e-9).

        Two URDFs that differ only in formatting, meshes or inertials share a fingerprint;
        any change of geometry changes it.
        """
        h = sha256()
        for j in self.joints:
            h.update(j.kind.encode())
            h.update(np.round(j.parent_T_joint, 9).tobytes())
            h.update(np.round(j.axis, 9).tobytes())
        h.update(np.round(self.last_T_flange, 9).tobytes())
        if self.urdf_from_controller is not None:
            h.update(np.round(self.urdf_from_controller, 9).tobytes())
        return "sha256:" + h.hexdigest()

    def joint_frames_at_zero(self) -> np.ndarray:
        """Joint frames at the zero position in the base frame, shape (n, 4, 4)."""
        frames = []
        current = np.eye(4)
        for j in self.joints:
            current = current @ j.parent_T_joint
            frames.append(current)
        return np.array(frames)

    def joint_axes_at_zero(self) -> tuple[np.ndarray, np.ndarray]:
        """Points on and unit directions of the joint axes at zero, base frame, each (n, 3)."""
        frames = self.joint_frames_at_zero()
        points = frames[:, :3, 3]
        directions = np.einsum("nij,nj->ni", frames[:, :3, :3], np.array([j.axis for j in self.joints]))
        return points, directions

    def flange_at_zero(self) -> np.ndarray:
        """The flange pose at the zero position in the base frame, (4, 4)."""
        return self.joint_frames_at_zero()[-1] @ self.last_T_flange

    def joints_from_controller(self, q: np.ndarray) -> np.ndarray:
        """URDF joint values (m, n) from controller axis values (m, n), both SI."""
        q = np.asarray(q, dtype=float)
        return q if self.urdf_from_controller is None else q @ self.urdf_from_controller.T

    def controller_from_joints(self, joints: np.ndarray) -> np.ndarray:
        """Controller axis values (m, n) from URDF joint values (m, n), both SI."""
        joints = np.asarray(joints, dtype=float)
        if self.urdf_from_controller is None:
            return joints
        return joints @ self._controller_from_urdf_t

    @cached_property
    def _controller_from_urdf_t(self) -> np.ndarray:
        """The transpose of the inverse of :attr:`urdf_from_controller` (the robot is
        immutable: inverted once, not on each call)."""
        return np.linalg.inv(self.urdf_from_controller).T

    def to_radians_or_metres(self, readings: np.ndarray) -> np.ndarray:
        """Joint readings in edge units (deg, mm) -> SI (rad, m), shape (m, n)."""
        scale = np.array([np.pi / 180.0 if j.kind == "revolute" else 1e-3 for j in self.joints])
        return np.asarray(readings, dtype=float) * scale

    def to_degrees_or_mm(self, joints: np.ndarray) -> np.ndarray:
        """Joint values in SI (rad, m) -> edge units (deg, mm), shape (m, n)."""
        scale = np.array([180.0 / np.pi if j.kind == "revolute" else 1e3 for j in self.joints])
        return np.asarray(joints, dtype=float) * scale

    @cached_property
    def pinocchio_model(self):
        """The pinocchio model of the whole URDF (for gravity and independent checks)."""
        import pinocchio as pin

        return pin.buildModelFromXML(self.urdf_text)

    def pinocchio_joint_ids(self) -> list[int]:
        """pinocchio joint ids of the chain's joints, in chain order."""
        model = self.pinocchio_model
        return [model.getJointId(j.name) for j in self.joints]


def robot_from_urdf_text(text: str, name: str | None = None, source: str = "",
                         flange_link: str = FLANGE_LINK,
                         urdf_from_controller: np.ndarray | None = None,
                         axis_ranges: np.ndarray | None = None) -> Robot:
    """Read the serial chain root -> ``flange_link`` from URDF text.

    Raises :class:`ModelError` when the text is not a URDF, has no flange link, or the chain
    holds joint kinds other than revolute, continuous, prismatic and fixed.
    """
    where = source or "<urdf>"
    return robot_from_document(read_urdf_chain(text, where), text, name, source, flange_link,
                               urdf_from_controller, axis_ranges)


def robot_from_document(robot: UrdfDocument, text: str, name: str | None = None,
                        source: str = "", flange_link: str = FLANGE_LINK,
                        urdf_from_controller: np.ndarray | None = None,
                        axis_ranges: np.ndarray | None = None) -> Robot:
    """:func:`robot_from_urdf_text` of the already read ``robot``, whose text is ``text``."""
    where = source or "<urdf>"
    joints_by_child = {j.child: j for j in robot.joints}
    links = robot.links
    if flange_link not in links:
        raise ModelError(f"{where}: the URDF has no link '{flange_link}' (the flange frame)")
    chain = []
    link = flange_link
    while link in joints_by_child:
        joint = joints_by_child[link]
        chain.append(joint)
        link = joint.parent
    chain.reverse()
    base_link = link
    joints: list[Joint] = []
    pending = np.eye(4)
    for j in chain:
        pending = pending @ j.origin
        if j.type == "fixed":
            continue
        if j.type not in ("revolute", "continuous", "prismatic"):
            raise ModelError(f"{where}: joint '{j.name}' is of type '{j.type}'; "
                             "only revolute, continuous, prismatic and fixed joints are supported")
        if j.mimic:
            raise ModelError(f"{where}: joint '{j.name}' mimics another joint; not a serial arm")
        axis = np.array([1.0, 0.0, 0.0]) if j.axis is None else np.asarray(j.axis, dtype=float)
        norm = np.linalg.norm(axis)
        if norm < 1e-12:
            raise ModelError(f"{where}: joint '{j.name}' has a zero axis")
        limit = j.limit
        lower = -np.inf if limit is None or limit.lower is None or j.type == "continuous" else limit.lower
        upper = np.inf if limit is None or limit.upper is None or j.type == "continuous" else limit.upper
        joints.append(Joint(
            name=j.name, kind="prismatic" if j.type == "prismatic" else "revolute",
            parent_T_joint=pending, axis=axis / norm, lower=float(lower), upper=float(upper),
            velocity=float(limit.velocity) if limit is not None and limit.velocity else np.inf,
            effort=float(limit.effort) if limit is not None and limit.effort else np.inf,
            child_link=j.child))
        pending = np.eye(4)
    if len(joints) < 2:
        raise ModelError(f"{where}: the chain from '{base_link}' to '{flange_link}' has "
                         f"{len(joints)} movable joint(s); a robot arm needs at least 2")
    coupling = None
    if urdf_from_controller is not None:
        coupling = np.asarray(urdf_from_controller, dtype=float)
        if coupling.shape != (len(joints), len(joints)) or abs(np.linalg.det(coupling)) < 1e-9:
            raise ModelError(f"{where}: urdf_from_controller must be an invertible "
                             f"{len(joints)}x{len(joints)} matrix")
    ranges = None
    if axis_ranges is not None:
        ranges = np.asarray(axis_ranges, dtype=float)
        if (ranges.shape != (len(joints), 2) or np.any(np.isnan(ranges))
                or np.any(ranges[:, 0] > ranges[:, 1])):
            raise ModelError(f"{where}: axis ranges must be (lower, upper) for each of the "
                             f"{len(joints)} axes, lower <= upper")
    return Robot(name=name or robot.name, urdf_text=text, joints=tuple(joints),
                 last_T_flange=pending, base_link=base_link, flange_link=flange_link,
                 source=source, urdf_from_controller=coupling, axis_ranges=ranges)


@dataclass(frozen=True)
class ControllerFile:
    """What a ``NAME.controller.json`` sidecar says of the robot's controller.

    urdf_from_controller : (n, n) controller axes -> URDF joints, or None (identity).
    axis_ranges : (n, 2) the data sheet's axis ranges in rad/m (the file holds degrees for
        revolute axes, ``axis_ranges_deg``), or None.
    """

    urdf_from_controller: np.ndarray | None = None
    axis_ranges_deg: np.ndarray | None = None


def read_controller_file(path: Path, where: str) -> ControllerFile:
    """The sidecar at ``path`` (an empty :class:`ControllerFile` when there is none)."""
    if not path.is_file():
        return ControllerFile()
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        coupling = doc.get("urdf_from_controller")
        ranges = doc.get("axis_ranges_deg")
        return ControllerFile(
            urdf_from_controller=None if coupling is None else np.array(coupling, dtype=float),
            axis_ranges_deg=None if ranges is None else np.array(ranges, dtype=float))
    except (OSError, ValueError, TypeError, AttributeError) as exc:
        raise ModelError(f"{where}: not a valid controller file ({exc})") from None


def _with_controller(text: str, name: str, source: str, controller: ControllerFile) -> Robot:
    robot = robot_from_urdf_text(text, name=name, source=source,
                                 urdf_from_controller=controller.urdf_from_controller)
    if controller.axis_ranges_deg is None:
        return robot
    return robot_from_urdf_text(text, name=name, source=source,
                                urdf_from_controller=controller.urdf_from_controller,
                                axis_ranges=ranges_from_edge_units(robot, controller.axis_ranges_deg))


def ranges_from_edge_units(robot: Robot, ranges) -> np.ndarray:
    """Axis ranges (n, 2) in deg/mm (files) -> rad/m."""
    ranges = np.asarray(ranges, dtype=float)
    if ranges.shape != (robot.n_joints, 2):
        raise ModelError(f"{robot.source or robot.name}: axis ranges must be (lower, upper) "
                         f"for each of the {robot.n_joints} axes")
    return robot.to_radians_or_metres(ranges.T).T


def robot_from_record(record: RobotRecord) -> Robot:
    """The robot of a record: its generated URDF, coupling and controller axis ranges."""
    text, document = urdf_and_document(record)
    if document is None:
        document = read_urdf_chain(text, record.source or "<urdf>")
    robot = robot_from_document(document, text, name=record.name, source=record.source,
                                urdf_from_controller=record.coupling)
    return dataclasses.replace(robot, record=record,
                               axis_ranges=ranges_from_edge_units(robot, record.axis_ranges_deg))


def bundled_robot_names() -> list[str]:
    """Names of the robots shipped in ``robots/`` (records ``NAME.robot.json``, and any
    plain ``NAME.urdf``)."""
    names = set()
    for p in data_folder("robots").iterdir():
        if p.name.endswith(RECORD_SUFFIX):
            names.add(p.name[:-len(RECORD_SUFFIX)])
        elif p.name.endswith(".urdf"):
            names.add(p.name[:-5])
    return sorted(names)


def bundled_record(name: str) -> RobotRecord | None:
    """The shipped record ``robots/NAME.robot.json``, or None when there is none."""
    resource = data_folder("robots") / f"{name}{RECORD_SUFFIX}"
    if not resource.is_file():
        return None
    record = read_record(resource, f"robots/{name}{RECORD_SUFFIX}")
    if record.name != name:
        raise ModelError(f"robots/{name}{RECORD_SUFFIX}: the record is named '{record.name}'")
    return record


def library_records() -> list[RobotRecord]:
    """The records of every bundled robot that is a record, sorted by name."""
    return [r for r in (bundled_record(n) for n in bundled_robot_names()) if r is not None]


def _load_urdf_file(path: Path, name_or_path: str) -> Robot:
    if not path.is_file():
        raise ModelError(f"{name_or_path}: no such URDF file")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelError(f"{name_or_path}: cannot read URDF ({exc})") from None
    sidecar = path.with_suffix(".controller.json")
    return _with_controller(text, path.stem, str(path), read_controller_file(sidecar, str(sidecar)))


def load_robot(name_or_path: str) -> Robot:
    """A bundled robot by name (``abb_irb2400``), a robot record by path (``*.robot.json``)
    or any serial-arm URDF by path."""
    path = Path(name_or_path)
    if name_or_path.endswith(RECORD_SUFFIX):
        if not path.is_file():
            raise ModelError(f"{name_or_path}: no such robot record")
        return robot_from_record(read_record(path))
    if path.suffix.lower() == ".urdf" or path.is_file():
        return _load_urdf_file(path, name_or_path)
    record = bundled_record(name_or_path)
    if record is not None:
        return robot_from_record(record)
    resource = data_folder("robots") / f"{name_or_path}.urdf"
    if not resource.is_file():
        import difflib  # only for this message

        names = bundled_robot_names()
        close = ([n for n in names if name_or_path.lower() in n][:3]
                 or difflib.get_close_matches(name_or_path, names, n=3, cutoff=0.6))
        hint = f"did you mean {', '.join(close)}? " if close else ""
        raise ModelError(f"unknown robot '{name_or_path}' ({hint}`olp-cal robots` lists the "
                         "bundled robots; or give a path to a .robot.json or a .urdf)")
    sidecar = data_folder("robots") / f"{name_or_path}.controller.json"
    controller = read_controller_file(sidecar, f"robots/{name_or_path}.controller.json")
    return _with_controller(resource.read_text(encoding="utf-8"), name_or_path,
                            f"robots/{name_or_path}.urdf", controller)
