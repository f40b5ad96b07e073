"""Denavit-Hartenberg tables: the form in which robot makers publish a controller's model.

Standard (distal) D-H, as Universal Robots states its arms: link i is
``Rz(q_i + theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``, frame 0 is the robot base (z on axis 1),
frame n the flange. All values SI (m, rad), joints counted from 0 inside.

- :class:`DHTable` holds one table and turns it into a :class:`FixedChain` (its links are
  the constant parts ``Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``), the fast chain the
  compensation already evaluates;
- :data:`UR_NOMINAL` the published tables of the bundled UR arms;
- :func:`dh_from_chain` the exact D-H table of any 6R chain (a calibrated arm), its signs
  chosen like a reference table's (UR writes negative ``a``), and the part of the flange
  that D-H cannot hold;
- :func:`mdh_rows` the same table in the modified (proximal, Craig) convention.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import DataError
from .conventions import rot_x, rot_z
from .fixed_chain import FixedChain

HALF_PI = math.pi / 2


@dataclass(frozen=True)
class DHTable:
    """A standard D-H table: ``theta`` (joint zero offsets), ``d``, ``a``, ``alpha``, each
    (n,), rad and m."""

    theta: np.ndarray
    d: np.ndarray
    a: np.ndarray
    alpha: np.ndarray

    def __post_init__(self):
        arrays = [np.asarray(v, dtype=float).reshape(-1) for v in
                  (self.theta, self.d, self.a, self.alpha)]
        if len({len(v) for v in arrays}) != 1:
            raise DataError(f"D-H table: theta, d, a and alpha must have one value per joint, "
                            f"got {[len(v) for v in arrays]}")
        if not all(np.all(np.isfinite(v)) for v in arrays):
            raise DataError("D-H table: every value must be a finite number")
        for name, value in zip(("theta", "d", "a", "alpha"), arrays):
            object.__setattr__(self, name, value)

    @property
    def n_joints(self) -> int:
        return len(self.theta)

    def links(self) -> np.ndarray:
        """(n, 4, 4) the constant part of each row, ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``."""
        out = np.empty((self.n_joints, 4, 4))
        for i in range(self.n_joints):
            link = _rz(self.theta[i])
            link[:3, 3] = link[:3, :3] @ np.array([self.a[i], 0.0, self.d[i]])
            link[:3, :3] = link[:3, :3] @ rot_x(self.alpha[i])
            out[i] = link
        return out

    def chain(self) -> FixedChain:
        """The table as a :class:`FixedChain` (base = frame 0; 6 joints)."""
        if self.n_joints != 6:
            raise DataError(f"D-H table: a chain needs 6 joints, this table has {self.n_joints}")
        return FixedChain(first=np.eye(4), links=self.links())

    def flange(self, q: np.ndarray) -> np.ndarray:
        """Flange poses (m, 4, 4) in the base frame for joints q (m, 6), rad."""
        return self.chain().flange(np.atleast_2d(np.asarray(q, dtype=float)))

    def plus(self, theta, d, a, alpha) -> "DHTable":
        """This table with deltas added (UR's calibration.conf convention)."""
        return DHTable(self.theta + np.asarray(theta, float), self.d + np.asarray(d, float),
                       self.a + np.asarray(a, float), self.alpha + np.asarray(alpha, float))

    def minus(self, other: "DHTable") -> "DHTable":
        """The deltas (this - other), row by row."""
        return DHTable(self.theta - other.theta, self.d - other.d, self.a - other.a,
                       self.alpha - other.alpha)


def _rz(angle: float) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = rot_z(angle)
    return out


UR_NOMINAL: dict[str, DHTable] = {
    # Universal Robots, "DH parameters for calculations of kinematics and dynamics"
    # (universal-robots.com/articles/ur/application-installation/dh-parameters-for-
    # calculations-of-kinematics-and-dynamics/); the same numbers as robots/ur5e.urdf and
    # robots/ur10e.urdf (a test checks the chains agree).
    "ur5e": DHTable(theta=np.zeros(6), d=np.array([0.1625, 0, 0, 0.1333, 0.0997, 0.0996]),
                    a=np.array([0, -0.425, -0.3922, 0, 0, 0]),
                    alpha=np.array([HALF_PI, 0, 0, HALF_PI, -HALF_PI, 0])),
    "ur10e": DHTable(theta=np.zeros(6), d=np.array([0.1807, 0, 0, 0.17415, 0.11985, 0.11655]),
                     a=np.array([0, -0.6127, -0.57155, 0, 0, 0]),
                     alpha=np.array([HALF_PI, 0, 0, HALF_PI, -HALF_PI, 0])),
}
"""The published D-H tables of the bundled UR arms, by robot name."""


def ur_nominal(robot_name: str) -> DHTable:
    """The data-sheet D-H table of a bundled UR arm; :class:`DataError` for another robot."""
    table = UR_NOMINAL.get(robot_name.lower())
    if table is None:
        raise DataError(f"robot {robot_name}: UR calibration files describe Universal Robots "
                        f"arms (known: {', '.join(sorted(UR_NOMINAL))})")
    return table


@dataclass(frozen=True)
class DHFit:
    """The exact D-H table of a chain: ``table``, and what the last row cannot hold of the
    flange: ``flange_offset_m`` (the flange origin's distance off the plane that D-H allows,
    m) and ``flange_tilt_rad`` (the flange x axis's tilt out of the plane normal to axis 6)."""

    table: DHTable
    flange_offset_m: float
    flange_tilt_rad: float


def _line_frame(frame: np.ndarray, point: np.ndarray, direction: np.ndarray,
                hint_x: np.ndarray | None) -> tuple[tuple[float, float, float, float], np.ndarray]:
    """(theta, d, a, alpha) from D-H ``frame`` (z on axis i) to the axis (point,
    direction), and the new frame; its x is the common normal, signed like ``hint_x``."""
    origin, x0, z0 = frame[:3, 3], frame[:3, 0], frame[:3, 2]
    b = float(z0 @ direction)
    w = origin - point
    denom = 1.0 - b * b
    s = 0.0 if denom < 1e-15 else float((b * (direction @ w) - z0 @ w) / denom)
    foot0 = origin + s * z0
    foot1 = point + ((foot0 - point) @ direction) * direction
    normal = foot1 - foot0
    length = float(np.linalg.norm(normal))
    if length > 1e-12:
        x_new = normal / length
    else:
        cross = np.cross(z0, direction)
        x_new = cross / np.linalg.norm(cross) if np.linalg.norm(cross) > 1e-12 else x0
    if hint_x is not None and x_new @ hint_x < 0:
        x_new = -x_new
    a = float(normal @ x_new)
    theta = math.atan2(float(np.cross(x0, x_new) @ z0), float(x0 @ x_new))
    alpha = math.atan2(float(np.cross(z0, direction) @ x_new), float(z0 @ direction))
    new = np.eye(4)
    new[:3, 0], new[:3, 2] = x_new, direction
    new[:3, 1] = np.cross(direction, x_new)
    new[:3, 3] = foot1
    return (theta, s, a, alpha), new


def dh_from_chain(chain: FixedChain, reference: DHTable | None = None) -> DHFit:
    """The standard D-H table whose chain is ``chain`` (a 6R arm whose base z is axis 1 and
    whose axis 1 passes through the base origin): each row from the joint axes at zero.
    ``reference``: a table whose frames choose the sign of each common normal (UR's negative
    ``a``); without it every ``a`` is >= 0. Nearly parallel axes give large ``d`` (the
    common normal lies far away): exact, as UR's "linearised" tables are."""
    frames = _joint_frames(chain)
    if (frames[0][2, 2] < 1 - 1e-12
            or np.linalg.norm(frames[0][:2, 3]) > 1e-9):
        raise DataError("D-H table: axis 1 is not the base z axis through the base origin; "
                        "a D-H table cannot hold this base frame")
    hints = None if reference is None else _joint_frames(reference.chain(), flange=True)
    frame = np.eye(4)
    rows = []
    for i in range(5):
        hint = None if hints is None else hints[i + 1][:3, 0]
        row, frame = _line_frame(frame, frames[i + 1][:3, 3], frames[i + 1][:3, 2], hint)
        rows.append(row)
    flange = chain.flange(np.zeros((1, 6)))[0]
    row, offset, tilt = _last_row(frame, flange)
    rows.append(row)
    theta, d, a, alpha = (np.array(v) for v in zip(*rows))
    if reference is not None:   # zero offsets as the nearest turn to the reference's
        theta = reference.theta + (theta - reference.theta + math.pi) % (2 * math.pi) - math.pi
    return DHFit(DHTable(theta, d, a, alpha), offset, tilt)


def _last_row(frame: np.ndarray, flange: np.ndarray):
    """(theta, d, a, alpha) of the last row from D-H frame 5 (z on axis 6) to the flange,
    and what it cannot hold: the offset along the row's y (m) and the tilt of the flange x
    out of the plane normal to axis 6 (rad)."""
    z5, x5 = frame[:3, 2], frame[:3, 0]
    fx, fz = flange[:3, 0], flange[:3, 2]
    in_plane = fx - (fx @ z5) * z5
    tilt = math.asin(min(1.0, abs(float(fx @ z5))))
    x6 = in_plane / np.linalg.norm(in_plane)
    theta = math.atan2(float(np.cross(x5, x6) @ z5), float(x5 @ x6))
    offset = flange[:3, 3] - frame[:3, 3]
    d, a = float(offset @ z5), float(offset @ x6)
    y_off = abs(float(offset @ np.cross(z5, x6)))
    alpha = math.atan2(float(np.cross(z5, fz) @ x6), float(z5 @ fz))
    return (theta, d, a, alpha), y_off, tilt


def _joint_frames(chain: FixedChain, flange: bool = False) -> list[np.ndarray]:
    """Joint frames at zero (z on each axis), base frame; with ``flange`` the D-H frames of
    a D-H chain (frame k after link k) instead: [base, frame 1, ..., frame 6]."""
    if flange:
        out = [np.eye(4)]
        for link in chain.links:
            out.append(out[-1] @ link)
        return out
    out = [chain.first]
    for link in chain.links[:-1]:
        out.append(out[-1] @ link)
    return out


def mdh_rows(table: DHTable) -> tuple[np.ndarray, np.ndarray]:
    """The table in the modified (Craig) convention: rows (n, 4) of (alpha_{i-1}, a_{i-1},
    theta_i, d_i) for ``Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(q_i + theta_i) Tz(d_i)``, and the
    constant flange transform (4, 4) ``Tx(a_n) Rx(alpha_n)`` that follows the last joint.
    Exact: ``Tx(a) Rx(alpha)`` commute, so the two conventions group the same steps."""
    n = table.n_joints
    rows = np.zeros((n, 4))
    rows[1:, 0], rows[1:, 1] = table.alpha[:-1], table.a[:-1]
    rows[:, 2], rows[:, 3] = table.theta, table.d
    tail = np.eye(4)
    tail[0, 3] = table.a[-1]
    tail[:3, :3] = rot_x(table.alpha[-1])
    return rows, tail


def chain_difference_mm(a: FixedChain, b: FixedChain, q: np.ndarray) -> np.ndarray:
    """(m,) distance between the flange origins of two chains at joints q (m, 6), mm."""
    return np.linalg.norm(a.flange(q)[:, :3, 3] - b.flange(q)[:, :3, 3], axis=1) * 1e3


__all__ = ["DHTable", "DHFit", "UR_NOMINAL", "ur_nominal", "dh_from_chain", "mdh_rows",
           "chain_difference_mm"]
