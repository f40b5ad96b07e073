"""The few URDF elements a serial arm needs, read with the standard library.

Only ``<robot name>``, ``<link name>`` and each ``<joint>``'s type, parent, child,
``<origin xyz rpy>`` (metres; fixed-axis roll, pitch, yaw in radians: R = Rz(y) Ry(p) Rx(r)),
``<axis xyz>``, ``<limit lower upper velocity effort>`` and ``<mimic>`` are read, as the URDF
specification defines them (wiki.ros.org/urdf/XML/joint). Reading a URDF must not cost a
command's start-up the import of a mesh library; :mod:`olp_compensate.io.urdf_export` writes
URDFs with yourdfpy.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..errors import ModelError

if TYPE_CHECKING:  # parsing imports it: a bundled robot is built without XML (robot.py)
    import xml.etree.ElementTree as ET


@dataclass(frozen=True)
class UrdfLimit:
    """``<limit>``: positions in rad (m for prismatic joints), velocity, effort; None when
    the attribute is absent."""

    lower: float | None
    upper: float | None
    velocity: float | None
    effort: float | None


@dataclass(frozen=True)
class UrdfJoint:
    """One ``<joint>``: ``origin`` is parent_link_T_joint (4, 4), metres."""

    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray | None
    limit: UrdfLimit | None
    mimic: bool


@dataclass(frozen=True)
class UrdfDocument:
    """A URDF's robot name, link names and joints, in file order."""

    name: str
    links: frozenset[str]
    joints: tuple[UrdfJoint, ...]


def _floats(element: ET.Element | None, attribute: str, count: int, where: str,
            default: list[float] | None) -> list[float] | None:
    if element is None or element.get(attribute) is None:
        return default
    words = element.get(attribute).split()
    try:
        values = [float(w) for w in words]
    except ValueError:
        values = []
    if len(values) != count:
        raise ModelError(f"{where}: <{element.tag} {attribute}=\"{element.get(attribute)}\"> "
                         f"must hold {count} numbers")
    return values


def _optional_float(element: ET.Element, attribute: str, where: str) -> float | None:
    text = element.get(attribute)
    if text is None:
        return None
    try:
        return float(text)
    except ValueError:
        raise ModelError(f"{where}: <limit {attribute}=\"{text}\"> is not a number") from None


def pose_from_xyz_rpy(xyz, rpy) -> np.ndarray:
    """4x4 pose of a URDF ``<origin>``: translation (m), fixed-axis roll-pitch-yaw (rad)."""
    roll, pitch, yaw = rpy
    cr, sr, cp, sp, cy, sy = (np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch),
                              np.cos(yaw), np.sin(yaw))
    pose = np.eye(4)
    pose[:3, :3] = [[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                    [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                    [-sp, cp * sr, cp * cr]]
    pose[:3, 3] = xyz
    return pose


def read_urdf_chain(text: str, where: str = "<urdf>") -> UrdfDocument:
    """Parse URDF text; raises :class:`ModelError` naming ``where`` for text that is not
    XML, not a ``<robot>``, or has a joint without parent, child or with bad numbers."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise ModelError(f"{where}: not a readable URDF ({exc})") from None
    if root.tag != "robot":
        raise ModelError(f"{where}: not a readable URDF (root element <{root.tag}>, "
                         "expected <robot>)")
    links = frozenset(link.get("name", "") for link in root.findall("link"))
    joints = []
    for element in root.findall("joint"):
        name = element.get("name", "")
        here = f"{where}: joint '{name}'"
        parent, child = element.find("parent"), element.find("child")
        if parent is None or child is None or not parent.get("link") or not child.get("link"):
            raise ModelError(f"{here} needs <parent link=...> and <child link=...>")
        origin = element.find("origin")
        xyz = _floats(origin, "xyz", 3, here, [0.0, 0.0, 0.0])
        rpy = _floats(origin, "rpy", 3, here, [0.0, 0.0, 0.0])
        axis = _floats(element.find("axis"), "xyz", 3, here, None)
        limit_element = element.find("limit")
        limit = None if limit_element is None else UrdfLimit(
            *(_optional_float(limit_element, a, here) for a in ("lower", "upper", "velocity",
                                                                 "effort")))
        joints.append(UrdfJoint(
            name=name, type=element.get("type", ""), parent=parent.get("link"),
            child=child.get("link"), origin=pose_from_xyz_rpy(xyz, rpy),
            axis=None if axis is None else np.array(axis), limit=limit,
            mimic=element.find("mimic") is not None))
    return UrdfDocument(name=root.get("name", ""), links=links, joints=tuple(joints))
