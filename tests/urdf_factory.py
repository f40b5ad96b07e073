"""Small robots built in code: URDF text from a standard Denavit-Hartenberg table.

Used by tests that need a robot without reading robots/ (pinocchio's habit: tests need no
paths). Frame i of the table is link i; ``tool0`` is frame 6.
"""

from __future__ import annotations

import numpy as np


def _rpy(rotation: np.ndarray) -> tuple[float, float, float]:
    """URDF roll-pitch-yaw (fixed axes x, y, z) of a rotation matrix."""
    pitch = np.arcsin(-np.clip(rotation[2, 0], -1, 1))
    roll = np.arctan2(rotation[2, 1], rotation[2, 2])
    yaw = np.arctan2(rotation[1, 0], rotation[0, 0])
    return roll, pitch, yaw


def dh_transform(a, alpha, d, theta) -> np.ndarray:
    """Standard D-H: Rz(theta) Tz(d) Tx(a) Rx(alpha), (4, 4)."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st],
                     [0, sa, ca, d], [0, 0, 0, 1.0]])


def dh_forward(table, q) -> np.ndarray:
    """Flange poses (m, 4, 4) of a D-H table (rows a, alpha, d, theta_offset) at joints (m, n)."""
    q = np.atleast_2d(q)
    out = np.empty((len(q), 4, 4))
    for k, qk in enumerate(q):
        t = np.eye(4)
        for (a, alpha, d, off), qi in zip(table, qk):
            t = t @ dh_transform(a, alpha, d, off + qi)
        out[k] = t
    return out


def dh_urdf(table, name: str = "dh_robot", limit: float = np.pi, masses=None) -> str:
    """URDF text whose tool0 forward kinematics equals the D-H table's.

    Joint i+1 sits at D-H frame i; its origin carries the previous row's transform with the
    row's theta offset folded into the next joint's origin rotation.
    """
    n = len(table)
    masses = masses or [5.0] * n
    parts = [f'<robot name="{name}">', '<link name="base_link"/>']
    prev = np.eye(4)  # transform still to be emitted before the next joint
    for i, (a, alpha, d, off) in enumerate(table):
        origin = prev @ dh_transform(0, 0, 0, off)
        xyz = " ".join(f"{v:.12g}" for v in origin[:3, 3])
        rpy = " ".join(f"{v:.12g}" for v in _rpy(origin[:3, :3]))
        parent = "base_link" if i == 0 else f"link_{i}"
        parts.append(
            f'<link name="link_{i + 1}"><inertial><origin xyz="{a / 2:.6g} 0 0" rpy="0 0 0"/>'
            f'<mass value="{masses[i]}"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" '
            f'izz="0.1"/></inertial></link>')
        parts.append(
            f'<joint name="joint_{i + 1}" type="revolute"><parent link="{parent}"/>'
            f'<child link="link_{i + 1}"/><origin xyz="{xyz}" rpy="{rpy}"/>'
            f'<axis xyz="0 0 1"/><limit lower="{-limit}" upper="{limit}" effort="100" '
            f'velocity="2"/></joint>')
        prev = dh_transform(a, alpha, d, 0.0)
    xyz = " ".join(f"{v:.12g}" for v in prev[:3, 3])
    rpy = " ".join(f"{v:.12g}" for v in _rpy(prev[:3, :3]))
    parts.append('<link name="tool0"/>')
    parts.append(f'<joint name="joint_{n}-tool0" type="fixed"><parent link="link_{n}"/>'
                 f'<child link="tool0"/><origin xyz="{xyz}" rpy="{rpy}"/></joint>')
    parts.append("</robot>")
    return "\n".join(parts)


IRB2400_DH = [  # a, alpha, d, theta offset (m, rad); ABB zero: tool0 at (0.940, 0, 1.455)
    (0.100, -np.pi / 2, 0.615, 0.0),
    (0.705, 0.0, 0.0, -np.pi / 2),
    (0.135, -np.pi / 2, 0.0, 0.0),
    (0.0, np.pi / 2, 0.755, 0.0),
    (0.0, -np.pi / 2, 0.0, 0.0),
    (0.0, 0.0, 0.085, np.pi),
]

PUMA560_DH = [
    (0.0, np.pi / 2, 0.67183, 0.0),
    (0.4318, 0.0, 0.0, 0.0),
    (0.0203, -np.pi / 2, 0.15005, 0.0),
    (0.0, np.pi / 2, 0.4318, 0.0),
    (0.0, -np.pi / 2, 0.0, 0.0),
    (0.0, 0.0, 0.0, 0.0),
]

UR5E_DH = [
    (0.0, np.pi / 2, 0.1625, 0.0),
    (-0.425, 0.0, 0.0, 0.0),
    (-0.3922, 0.0, 0.0, 0.0),
    (0.0, np.pi / 2, 0.1333, 0.0),
    (0.0, -np.pi / 2, 0.0997, 0.0),
    (0.0, 0.0, 0.0996, 0.0),
]
