"""KUKA KRL's configuration rules: status S and turn T (KSS 8 manual, "Status" and "Turn"),
the branch the controller takes for a written S and T, and the numbers written back."""

from __future__ import annotations

import math
import re

import numpy as np

from ...compensation.dialect_rules import ArmGeometry, DialectRules
from ...kinematics.conventions import euler_zyx_from_matrix, matrix_from_euler_zyx
from ..pose_dialects import PoseConvention, PoseTarget
from ..targets import Edit
from .reader import status_text, status_value

TWO_PI = 2 * math.pi


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
    config_edits=krl_config_edits, config_words=_krl_words,
    full_words=lambda geometry, q: f"S {krl_status(geometry, q)} T {krl_turn(q)}",
    frames_source="the controller's $config.dat", tool_names=lambda key: _numbered(key))


def _numbered(key: str) -> list[str]:
    """``TOOL_DATA[N]`` is also ``toolN`` in calib.json."""
    found = re.fullmatch(r"TOOL_DATA\[(\d+)\]", key, re.I)
    return [key] if found is None else [key, f"tool{int(found.group(1))}"]
