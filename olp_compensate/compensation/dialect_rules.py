"""Configuration rules of the pose dialects (each language's own in its folder,
``programs/<language>/rules.py``): how a target's written configuration picks
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

from ..kinematics.model import build_model, joint_frames, joint_frames_batch
from ..kinematics.robot import Robot
from ..programs.pose_dialects import PoseConvention, PoseTarget

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
    full_words: Callable[[ArmGeometry, np.ndarray], str] | None = None
    """The whole configuration of controller joints (rad) in the dialect's words, for a
    target that writes none (KRL ``S 2 T 35``); None: the joints in degrees."""
    joints_are_config: bool = False
    """Whether the configuration a target writes is the joints themselves (URScript's
    ``qnear``): the words of solved joints are then those joints."""
    frames_source: str = "the program nor the frames given"
    """Where the program's tool and base frames are looked for, for an unknown one's note."""
    tool_names: Callable[[str], list[str]] = lambda key: [key]
    """The names a calibrated tool may carry for a tool reference (KRL ``TOOL_DATA[3]``:
    also ``tool3``)."""
