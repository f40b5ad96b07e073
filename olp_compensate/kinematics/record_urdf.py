"""The URDF of a robot record (:mod:`olp_compensate.kinematics.records`), generated in memory.

Joint frames are computed from the record's geometry at the controller's zero (all axes 0):
for an ``opw`` record in the ROS-Industrial layout (link frames parallel to the base frame,
joint origins pure translations between points on consecutive axes, axes along the base
axes), for a ``dh`` record as DH frames (joint origin = constant part of the previous DH row).
Numbers are snapped (1e-12 m, multiples of 90 degrees) so that a record describing a
hand-written URDF gives the same numbers, and so the same kinematic fingerprint.
"""

from __future__ import annotations

import math

import numpy as np

from .records import MASS_SHARES, LinkInertial, RobotRecord
from .urdf import UrdfDocument, UrdfJoint, UrdfLimit, pose_from_xyz_rpy

LINKS = ("base_link", "link_1", "link_2", "link_3", "link_4", "link_5", "link_6")


def _rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _snap(value: float, step: float = 0.0) -> float:
    """``value`` rounded to 1e-12, or to a multiple of ``step`` within 1e-12; never -0.0."""
    if step:
        k = round(value / step)
        if abs(value - k * step) < 1e-12:
            value = {0: 0.0, 1: math.pi / 2, -1: -math.pi / 2, 2: math.pi,
                     -2: math.pi}.get(k, k * step)
    else:
        value = round(value, 12)
    return 0.0 if value == 0 else float(value)


def rpy_from_matrix(R: np.ndarray) -> tuple[float, float, float]:
    """Fixed-axis roll, pitch, yaw (rad) with R = Rz(y) Ry(p) Rx(r), as a URDF ``<origin>``;
    at pitch = +-90 degrees the yaw is 0."""
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    if abs(abs(pitch) - math.pi / 2) < 1e-9:
        roll, yaw = math.atan2(-R[1, 2], R[1, 1]), 0.0
    else:
        roll, yaw = math.atan2(R[2, 1], R[2, 2]), math.atan2(R[1, 0], R[0, 0])
    half = math.pi / 2
    return _snap(roll, half), _snap(pitch, half), _snap(yaw, half)


def _rotation_deg(rpy_deg) -> np.ndarray:
    return pose_from_xyz_rpy((0, 0, 0), np.radians(rpy_deg))[:3, :3]


def opw_zero_layout(g: dict):
    """Joint origins (translations, base frame), URDF axes and the flange pose at zero.

    Returns (origins (6, 3) m, axes (6, 3), flange_xyz (3,) m from joint 6, flange_R (3, 3)).
    """
    theta = -np.radians(g["offsets_deg"])
    R1 = _rz(theta[0])
    R2 = R1 @ _ry(theta[1])
    R3 = R1 @ _ry(theta[1] + theta[2])
    R4 = R3 @ _rz(theta[3])
    R5 = R4 @ _ry(theta[4])
    R6 = R5 @ _rz(theta[5])
    p = [np.zeros(3), R1 @ [g["a1"], 0.0, g["c1"] - g["base_height"]]]
    p.append(p[1] + R2 @ [0.0, g["b"], g["c2"]])
    p.append(p[2] + R3 @ [g["a2"], 0.0, 0.0])
    p.append(p[3] + R3 @ [0.0, 0.0, g["c3"]])
    p.append(p[4])
    axes = np.array([[0, 0, 1.0], R1[:, 1], R1[:, 1], R3[:, 2], R4[:, 1], R5[:, 2]])
    axes = axes * np.array(g["signs"])[:, None]
    origins = np.array([p[0]] + [p[k] - p[k - 1] for k in range(1, 6)])
    flange_R = R6 @ _rotation_deg(g["flange_rpy_deg"])
    return origins, axes, R6 @ [0.0, 0.0, g["c4"]], flange_R


def _dh_row(d, a, alpha) -> np.ndarray:
    return pose_from_xyz_rpy((a, 0.0, d), (alpha, 0.0, 0.0))


def dh_zero_layout(g: dict):
    """DH joint origins as 4x4 poses (6 joints + flange), and the URDF axes (6, 3)."""
    offsets = np.radians(g["offsets_deg"])
    alpha = np.radians(g["alpha_deg"])
    poses = []
    for i in range(7):
        T = np.eye(4) if i == 0 else _dh_row(g["d"][i - 1], g["a"][i - 1], alpha[i - 1])
        if i < 6:
            T[:3, :3] = T[:3, :3] @ _rz(offsets[i])
        poses.append(T)
    poses[6][:3, :3] = poses[6][:3, :3] @ _rotation_deg(g.get("flange_rpy_deg", (0, 0, 0)))
    axes = np.array([[0, 0, float(s)] for s in g["signs"]])
    return poses, axes


def joint_origins(record: RobotRecord) -> tuple[list, np.ndarray]:
    """((xyz, rpy) of joint_1..joint_6 and of the flange joint, URDF axes (6, 3))."""
    g = record.geometry
    if g["kind"] == "opw":
        origins, axes, flange_xyz, flange_R = opw_zero_layout(g)
        out = [(tuple(origins[k]), (0.0, 0.0, 0.0)) for k in range(6)]
        out.append((tuple(flange_xyz), rpy_from_matrix(flange_R)))
    else:
        poses, axes = dh_zero_layout(g)
        out = [(tuple(T[:3, 3]), rpy_from_matrix(T[:3, :3])) for T in poses]
    out = [(tuple(_snap(v) for v in xyz), rpy) for xyz, rpy in out]
    return out, np.array([[_snap(v) for v in axis] for axis in axes])


def joint_limits_deg(record: RobotRecord) -> np.ndarray:
    """(6, 2) limits of the URDF joints: the axis ranges mapped through the coupling (the
    envelope of each coupled joint over the ranges' box)."""
    ranges = record.axis_ranges_deg
    if record.coupling is None:
        return ranges.copy()
    lows = np.minimum(record.coupling * ranges[:, 0], record.coupling * ranges[:, 1]).sum(1)
    highs = np.maximum(record.coupling * ranges[:, 0], record.coupling * ranges[:, 1]).sum(1)
    return np.stack([lows, highs], 1)


def estimated_inertials(record: RobotRecord, origins: list) -> tuple[LinkInertial, ...]:
    """Placeholder inertials from the total mass (README rule): shares ``MASS_SHARES``,
    centre of mass half way to the next joint, a solid sphere's inertia."""
    total = record.mass_kg if record.mass_kg is not None else 10.0 * (record.payload_kg or 5.0)
    out = []
    for k, share in enumerate(MASS_SHARES):
        mass = round(total * share, 6)
        step = np.array(origins[k][0])
        com = tuple(_snap(v / 2) for v in step)
        radius = max(0.05, float(np.linalg.norm(step)) / 2)
        i = round(0.4 * mass * radius ** 2, 6)
        out.append(LinkInertial(mass, com, (i, 0.0, 0.0, i, 0.0, i)))
    return tuple(out)


def _num(v: float) -> str:
    return repr(float(v)) if v != int(v) or abs(v) >= 1e15 else str(int(v))


def _xml_text(text: str) -> str:
    """``text`` with ``&``, ``<`` and ``>`` escaped (as ``xml.sax.saxutils.escape``, whose
    import pulls in urllib and http.client: 25-60 ms of every command's start)."""
    return text.replace("&", "&amp;").replace(">", "&gt;").replace("<", "&lt;")


def _xyz(values) -> str:
    return " ".join(_num(v) for v in values)


def _comment(record: RobotRecord) -> str:
    return ("<!-- generated from " + record.name + ".robot.json ("
            + _xml_text(f"{record.maker} {record.model}").replace("--", "- -")
            + "); do not edit -->")


def _well_formed_comment(comment: str) -> bool:
    """True when the XML comment parses: no ``--`` inside, only XML 1.0 characters (the
    record's name is checked when it is read; numbers are written by :func:`_num`)."""
    body = comment[4:-3]
    return "--" not in body and all(_xml_char(c) for c in body)


def _xml_char(c: str) -> bool:
    """``c`` is an XML 1.0 ``Char`` (a regular expression of these ranges costs 5 ms to
    compile)."""
    return ("\x20" <= c <= "\ud7ff" or c in "\t\n\r" or "\ue000" <= c <= "\ufffd"
            or c >= "\U00010000")


def _parsed(value: float) -> float:
    """``value`` as a URDF reader reads it back from the text :func:`_num` writes."""
    return float(_num(value))


def _origin(xyz, rpy) -> np.ndarray:
    return pose_from_xyz_rpy([_parsed(v) for v in xyz], [_parsed(v) for v in rpy])


def urdf_and_document(record: RobotRecord) -> tuple[str, UrdfDocument | None]:
    """The URDF text of ``record`` (:func:`urdf_from_record`) and the document a URDF reader
    makes of it, built from the same numbers as they read back from the text (so the same
    :class:`~olp_compensate.kinematics.robot.Robot` to the bit, without the XML parser: 3-5 ms
    of a command's start); None for the document when the text must be parsed to say what
    is wrong with it (a maker or model that no XML comment can hold)."""
    origins, axes = joint_origins(record)
    limits = np.radians(joint_limits_deg(record))
    inertials = record.links or estimated_inertials(record, origins)
    comment = _comment(record)
    lines = ['<?xml version="1.0"?>', comment, f'<robot name="{record.name}">']
    for name, link in zip(LINKS, inertials):
        lines += [f'  <link name="{name}">', "    <inertial>",
                  f'      <origin xyz="{_xyz(link.com)}" rpy="0 0 0"/>',
                  f'      <mass value="{_num(link.mass)}"/>',
                  '      <inertia ixx="{}" ixy="{}" ixz="{}" iyy="{}" iyz="{}" izz="{}"/>'.format(
                      *(_num(v) for v in link.inertia)),
                  "    </inertial>", "  </link>"]
    lines.append('  <link name="tool0"/>')
    joints = []
    for k in range(6):
        xyz, rpy = origins[k]
        # URDF requires effort and velocity; 0 says "not given in the record"
        effort = 0 if record.effort_nm is None else record.effort_nm[k]
        speed = 0 if record.max_speed_deg_s is None else math.radians(record.max_speed_deg_s[k])
        attrs = (f'lower="{_num(limits[k, 0])}" upper="{_num(limits[k, 1])}" '
                 f'effort="{_num(effort)}" velocity="{_num(speed)}"')
        lines += [f'  <joint name="joint_{k + 1}" type="revolute">',
                  f'    <parent link="{LINKS[k]}"/>', f'    <child link="{LINKS[k + 1]}"/>',
                  f'    <origin xyz="{_xyz(xyz)}" rpy="{_xyz(rpy)}"/>',
                  f'    <axis xyz="{_xyz(axes[k])}"/>', f"    <limit {attrs}/>", "  </joint>"]
        limit = UrdfLimit(_parsed(limits[k, 0]), _parsed(limits[k, 1]), _parsed(speed),
                          _parsed(effort))
        joints.append(UrdfJoint(f"joint_{k + 1}", "revolute", LINKS[k], LINKS[k + 1],
                                _origin(xyz, rpy), np.array([_parsed(v) for v in axes[k]]),
                                limit, False))
    xyz, rpy = origins[6]
    lines += ['  <joint name="joint_6-tool0" type="fixed">', '    <parent link="link_6"/>',
              '    <child link="tool0"/>', f'    <origin xyz="{_xyz(xyz)}" rpy="{_xyz(rpy)}"/>',
              "  </joint>", "</robot>", ""]
    joints.append(UrdfJoint("joint_6-tool0", "fixed", "link_6", "tool0", _origin(xyz, rpy),
                            None, None, False))
    document = UrdfDocument(record.name, frozenset(LINKS + ("tool0",)), tuple(joints))
    return "\n".join(lines), (document if _well_formed_comment(comment) else None)


def urdf_from_record(record: RobotRecord) -> str:
    """The URDF text of ``record``: links base_link, link_1..link_6, tool0; joints joint_1..6
    (revolute, limits = the controller's ranges through the coupling) and joint_6-tool0."""
    return urdf_and_document(record)[0]
