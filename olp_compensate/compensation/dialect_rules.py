"""Configuration rules of the pose dialects: how a target's written configuration picks
the branch the nominal controller takes, and the configuration of solved joints.

A :class:`DialectRules` gives, for one dialect, its pose convention (units, angles) and two
functions on controller axes (rad):

- ``choose(geometry, target, branches, previous)``: which of the nominal closed form's
  branches (k, n) the controller takes for the target as written, or None with the reason;
- ``config(geometry, q, target)``: the configuration values to write for joints ``q``;
- ``written(target)``: the configuration values as written (for the report);
- ``config_edits(target, values)``: the edits writing ``values`` in the target's own style;
- ``config_words(values)``: the configuration as report text;
- ``is_identity(key)``: whether a frame reference names the flange or the robot base.

``choose`` may return a third element, a note for the report (for example that two
branches were nearly as near the previous joints).

:class:`ArmGeometry` holds what the rules measure on the nominal arm (the wrist point, the
arm plane), so each dialect states its configuration in its maker's own words.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..kinematics.conventions import euler_zyx_from_matrix, matrix_from_euler_zyx
from ..kinematics.model import build_model, joint_frames, joint_frames_batch
from ..kinematics.robot import Robot
from ..programs.krl import status_text, status_value
from ..programs.pose_dialects import PoseConvention, PoseTarget
from ..programs.targets import Edit

TWO_PI = 2 * math.pi


def _wrap(angle: float) -> float:
    return (angle + math.pi) % TWO_PI - math.pi


def _closest_point(p_a, d_a, p_b, d_b) -> np.ndarray:
    """The point midway between the closest points of two lines (point, unit direction)."""
    w = p_a - p_b
    b = d_a @ d_b
    d, e = d_a @ w, d_b @ w
    denom = 1.0 - b * b
    if denom < 1e-12:
        return p_a
    s = (b * e - d) / denom
    t = (e - b * d) / denom
    return 0.5 * ((p_a + s * d_a) + (p_b + t * d_b))


class ArmGeometry:
    """Configuration geometry of a 6-axis arm with a spherical wrist, on its nominal model.

    For controller axes ``q`` (rad): the wrist point (where axes 4 and 5 meet), its signed
    distance in front of axis 1 along the arm's forward direction, and the elbow angle
    ``psi`` (the wrist point about axis 3, from the stretched arm: 0 when the wrist point
    lies on the line from axis 2 through axis 3, growing with axis 3).
    """

    def __init__(self, robot: Robot):
        self.robot = robot
        self.model = build_model(robot)
        self._cache: dict[bytes, np.ndarray] = {}
        zero = self._frames(np.zeros(robot.n_joints))
        axis1 = zero[0]
        forward = self.wrist_point_frames(zero) - axis1[:3, 3]
        self._forward_sign = 1.0 if forward @ self._arm_direction(zero) >= 0 else -1.0

    def _frames(self, q_ctrl: np.ndarray) -> np.ndarray:
        q = np.asarray(q_ctrl, dtype=float)
        cached = self._cache.get(q.tobytes())
        if cached is not None:
            return cached
        q_urdf = self.robot.joints_from_controller(q[None])[0]
        return joint_frames(self.model, self.model.nominal, q_urdf)

    def prepare(self, q_ctrl: np.ndarray) -> None:
        """Compute the joint frames of many controller joint vectors ``q_ctrl`` (m, n) in one
        batch for the calls that follow (a program's nominal branches: each target's eight
        would otherwise be evaluated one by one, 14x slower); NaN rows are skipped."""
        q = np.asarray(q_ctrl, dtype=float).reshape(-1, self.robot.n_joints)
        q = q[np.all(np.isfinite(q), axis=1)]
        if len(self._cache) > 200_000:
            self._cache.clear()
        if not len(q):
            return
        frames = joint_frames_batch(self.model, self.model.nominal,
                                    self.robot.joints_from_controller(q))
        for row, f in zip(q, frames):
            self._cache[row.tobytes()] = f

    @staticmethod
    def wrist_point_frames(frames: np.ndarray) -> np.ndarray:
        return _closest_point(frames[3][:3, 3], frames[3][:3, 2], frames[4][:3, 3],
                              frames[4][:3, 2])

    @staticmethod
    def _arm_direction(frames: np.ndarray) -> np.ndarray:
        """Unit vector in the arm's plane, perpendicular to axis 1 (sign not yet fixed)."""
        d = np.cross(frames[1][:3, 2], frames[0][:3, 2])
        return d / np.linalg.norm(d)

    def in_front_of_axis1(self, q_ctrl: np.ndarray) -> float:
        """Signed distance (m) of the wrist point in front of axis 1 along the arm."""
        frames = self._frames(q_ctrl)
        w = self.wrist_point_frames(frames)
        return float((w - frames[0][:3, 3]) @ (self._forward_sign * self._arm_direction(frames)))

    def elbow_angle(self, q_ctrl: np.ndarray) -> float:
        """``psi`` (rad, wrapped to [-pi, pi)): the wrist point's angle about axis 3 from
        the stretched arm."""
        frames = self._frames(q_ctrl)
        z3 = frames[2][:3, 2]
        p2 = _closest_point(frames[1][:3, 3], frames[1][:3, 2], frames[2][:3, 3], z3)
        p3 = frames[2][:3, 3]
        w = self.wrist_point_frames(frames)
        u = (p3 - p2) - ((p3 - p2) @ z3) * z3
        v = (w - p3) - ((w - p3) @ z3) * z3
        return _wrap(math.atan2(np.cross(u, v) @ z3, u @ v))


@dataclass(frozen=True)
class DialectRules:
    """One dialect's configuration rules (see the module docstring)."""

    name: str
    convention: PoseConvention
    choose: Callable
    config: Callable
    written: Callable[[PoseTarget], tuple]
    config_edits: Callable[[PoseTarget, tuple], list]
    config_words: Callable[[tuple], str]
    is_identity: Callable[[str], bool] = lambda key: key.endswith("[0]")
    """Whether a tool or base reference of the program names the flange or the robot base
    itself (KRL ``TOOL_DATA[0]``; VAL3 ``world[0]``, ``flange[0]``; FANUC ``UF0``)."""
    format_number: Callable | None = None
    """``(number, value, decimals, k) -> text`` replacing pose number ``k`` (0-5), where the
    dialect writes some numbers differently (VAL3: an attribute left out of the file is
    inserted as `` x="..."``); None: :func:`..programs.format_like` of the number's text."""


# ---- KUKA KRL ------------------------------------------------------------------------------

def krl_status(geometry: ArmGeometry, q: np.ndarray) -> int:
    """KUKA status S of controller axes ``q`` (rad), bits 0-2 (KSS 8 manual, "Status"):
    bit 0 set: the wrist point lies behind axis 1 (overhead area; x < 0 in the A1 frame);
    bit 1 set: A3 >= phi, phi the A3 of the stretched arm (wrist point on the line from A2
    through A3): the usual elbow-up arm; bit 2 set: A5 in [-180, 0) or [180, 360) deg."""
    s = 0
    if geometry.in_front_of_axis1(q) < 0:
        s |= 1
    if geometry.elbow_angle(q) >= 0:
        s |= 2
    a5 = q[4]
    if -math.pi <= a5 < 0 or math.pi <= a5 < TWO_PI:
        s |= 4
    return s


ZERO_AXIS_RAD = 1e-5
"""An axis this close to 0 (0.0006 deg, about what the written numbers resolve: 0.001 mm
at a metre, 0.0001 deg) has no sign of its own: either T bit holds for it."""


def krl_turn(q: np.ndarray, written: int | None = None) -> int:
    """KUKA turn T: bit i set when axis i+1 is negative; for an axis within
    :data:`ZERO_AXIS_RAD` of 0, the bit of ``written`` (clear without one)."""
    keep = 0 if written is None else written
    return sum(1 << i for i, v in enumerate(q[:6])
               if v < -ZERO_AXIS_RAD or (abs(v) <= ZERO_AXIS_RAD and keep >> i & 1))


def krl_written(target: PoseTarget) -> tuple[int, ...]:
    """(S, T) as written (as many as the target writes)."""
    return tuple(status_value(n) for n in target.config)


def _krl_numbers(target: PoseTarget):
    """(S, T) as written (None where absent)."""
    values = krl_written(target)
    s = values[0] if len(values) > 0 else None
    t = values[1] if len(values) > 1 else None
    return s, t


def krl_config_edits(target: PoseTarget, values: tuple[int, ...]) -> list[Edit]:
    """Edits writing S and T ``values`` in the forms the target wrote them."""
    return [Edit(n.start, n.end, status_text(n, v))
            for n, v in zip(target.config, values) if status_value(n) != v]


def krl_choose(geometry: ArmGeometry, target: PoseTarget, branches: np.ndarray, previous):
    """The branch KUKA's controller takes: the one whose status matches the written S, each
    axis turned by whole turns (inside its range) to the sign the written T asks; without S
    the branch nearest the previous joints (or zero). Returns (q (n,), None) or
    (None, reason)."""
    s, t = _krl_numbers(target)
    ranges = geometry.robot.controller_ranges
    candidates = []
    for q in branches:
        if not np.all(np.isfinite(q)):
            continue
        if s is not None and krl_status(geometry, q) != (s & 7):
            continue
        q = q.copy()
        if t is not None:
            for i in range(min(6, len(q))):
                want_negative = bool(t >> i & 1)
                if abs(q[i]) > ZERO_AXIS_RAD and (q[i] < 0) != want_negative:
                    shifted = q[i] + (-TWO_PI if q[i] >= 0 else TWO_PI)
                    if ranges[i, 0] <= shifted <= ranges[i, 1]:
                        q[i] = shifted
        candidates.append(q)
    if not candidates:
        return None, (f"no solution of the nominal arm has status S={s}" if s is not None
                      else "the nominal arm does not reach the target")
    reference = np.zeros(len(candidates[0])) if previous is None else previous
    best = min(candidates, key=lambda q: float(np.sum((q - reference) ** 2)))
    if t is not None and krl_turn(best, t) != (t & 63):
        return None, (f"the turn T={t} asks axis signs the pose cannot have on status "
                      f"S={s} inside the axis ranges")
    return best, None


def krl_config(geometry: ArmGeometry, q: np.ndarray, target: PoseTarget) -> tuple[int, ...]:
    """(S, T) of ``q`` for the numbers the target wrote (S keeps its bits above 2)."""
    s, t = _krl_numbers(target)
    values = []
    if s is not None:
        values.append((s & ~7) | krl_status(geometry, q))
    if t is not None:
        values.append(krl_turn(q, t))
    return tuple(values)


def _krl_words(values: tuple[int, ...]) -> str:
    names = ("S", "T")
    return " ".join(f"{n} {v}" for n, v in zip(names, values))


KRL = DialectRules(
    name="krl",
    convention=PoseConvention(
        position_scale=1e-3,
        rotation=lambda abc: matrix_from_euler_zyx(*np.radians(abc)),
        angles=lambda rotation, ref: np.degrees(euler_zyx_from_matrix(rotation, np.radians(ref))),
        position_decimals=3, angle_decimals=4),
    choose=krl_choose, config=krl_config, written=krl_written,
    config_edits=krl_config_edits, config_words=_krl_words)
