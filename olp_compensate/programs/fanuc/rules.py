"""FANUC TP configuration rules: ``CONFIG : 'N U T, t1, t2, t3'`` and the W, P, R angles.

Conventions and their sources:

- W, P, R (deg) turn about the fixed x, then y, then z axes: ``R = Rz(R) Ry(P) Rx(W)``,
  the matrix of KUKA's A, B, C with (A, B, C) = (R, P, W) (HandlingTool manual V9.40
  sec. 7.2.6: "W, P, R are rotations about X, Y, Z"; :mod:`..kinematics.conventions`).
- The letters (HandlingTool manual sec. 11.21.2, in public notes; the KAREL ``CONFIG``
  type ``CFG_FLIP, CFG_UP, CFG_FRONT``): F/N wrist flip or no-flip, U/D arm up or down,
  T/B arm front (top) or back. Measured on the nominal arm (:class:`.ArmGeometry`):
  *flip* when J5 >= 0 in FANUC's J5 sign (as SwRI's tesseract ``getRobotConfig`` for
  ROS-Industrial FANUC models, whose J5 is FANUC's; with J5 < 0 the usual tool-down
  point W = 180, P = 0 at J4 = 0 is 'N', as in the taught programs seen); *up* when the
  wrist point lies on the same side of the stretched arm (the line from J2 through J3)
  as at the zero pose (J2 arm vertical, J3 arm horizontal, clearly elbow up); *top*
  (front) when the wrist point lies in front of J1.
- The turn numbers (KAREL ``CFG_TURN_NO1..3``) are those of the axes of
  ``$SCR_GRP[g].$TURN_AXIS``, "normally J4 J5 J6": 0 for -179.99..179.99 deg, 1 for
  180..539.99, -1 for -539.99..-180. :func:`fanuc_rules` takes other axes
  (``turn_axes=(1, 4, 6)``) where a controller is set so.
- The controller's joints for a point: the branch of the nominal closed form with the
  written letters, each turn axis moved by whole turns into its written revolution; the
  other axes in (-180, 180].
"""

from __future__ import annotations

import math
import re

import numpy as np

from ...compensation.dialect_rules import ArmGeometry, DialectRules
from ...kinematics.conventions import euler_zyx_from_matrix, matrix_from_euler_zyx
from ..pose_dialects import PoseConvention, PoseTarget
from ..targets import Edit

TURN_AXES = (4, 5, 6)


def turn_number(angle_deg: float) -> int:
    """FANUC's turn number of an axis value (deg): 0 on (-180, 180), 1 on [180, 540)..."""
    return int(math.copysign(math.floor((abs(angle_deg) + 180.0) / 360.0), angle_deg))


def _in_turn(angle_rad: float, turn: int) -> float:
    """``angle_rad`` moved by whole turns into revolution ``turn`` (rad)."""
    base = math.degrees(math.remainder(angle_rad, 2 * math.pi))
    for k in (turn, turn - 1, turn + 1):
        value = base + 360.0 * k
        if turn_number(value) == turn:
            return math.radians(value)
    return math.radians(base + 360.0 * turn)


def _up_sign(geometry: ArmGeometry) -> float:
    cached = getattr(geometry, "_fanuc_up_sign", None)
    if cached is None:
        cached = 1.0 if geometry.elbow_angle(np.zeros(geometry.robot.n_joints)) >= 0 else -1.0
        geometry._fanuc_up_sign = cached
    return cached


def fanuc_letters(geometry: ArmGeometry, q: np.ndarray) -> tuple[str, str, str]:
    """('N'|'F', 'U'|'D', 'T'|'B') of controller axes ``q`` (rad); see the module notes."""
    flip = "F" if q[4] >= 0 else "N"
    up = "U" if geometry.elbow_angle(q) * _up_sign(geometry) >= 0 else "D"
    top = "T" if geometry.in_front_of_axis1(q) >= 0 else "B"
    return flip, up, top


def fanuc_written(target: PoseTarget) -> tuple:
    """(letters..., turns...) as written; () without CONFIG."""
    return tuple(n.text.upper() if k < 3 else int(n.text) for k, n in enumerate(target.config))


def _words(values: tuple) -> str:
    if not values:
        return ""
    return " ".join(values[:3]) + "".join(f", {v}" for v in values[3:])


def fanuc_rules(turn_axes: tuple[int, ...] = TURN_AXES) -> DialectRules:
    """FANUC TP rules with the turn numbers on ``turn_axes`` (1-based FANUC axes)."""
    axes = [a - 1 for a in turn_axes]

    def config(geometry: ArmGeometry, q: np.ndarray, target: PoseTarget) -> tuple:
        written = fanuc_written(target)
        if not written:
            return ()
        turns = tuple(turn_number(math.degrees(q[a])) for a in axes)
        return fanuc_letters(geometry, q) + turns[:len(written) - 3]

    def choose(geometry: ArmGeometry, target: PoseTarget, branches: np.ndarray, previous):
        written = fanuc_written(target)
        ranges = geometry.robot.controller_ranges
        candidates = []
        for q in branches:
            if not np.all(np.isfinite(q)):
                continue
            if written and fanuc_letters(geometry, q) != written[:3]:
                continue
            q = q.copy()
            for a, turn in zip(axes, written[3:]):
                q[a] = _in_turn(q[a], turn)
            candidates.append(q)
        if not candidates:
            return None, (f"no solution of the nominal arm has the configuration "
                          f"'{_words(written)}'" if written
                          else "the nominal arm does not reach the target")
        inside = [q for q in candidates
                  if np.all((q >= ranges[:, 0] - 1e-9) & (q <= ranges[:, 1] + 1e-9))]
        if not inside:
            return None, (f"the turn numbers of '{_words(written)}' put an axis outside its "
                          f"range")
        reference = np.zeros(len(inside[0])) if previous is None else previous
        best = min(inside, key=lambda q: float(np.sum((q - reference) ** 2)))
        return best, None

    def config_edits(target: PoseTarget, values: tuple) -> list[Edit]:
        return [Edit(n.start, n.end, str(v)) for n, v in zip(target.config, values)
                if (n.text.upper() if isinstance(v, str) else int(n.text)) != v]

    return DialectRules(
        name="fanuc_tp",
        convention=PoseConvention(
            position_scale=1e-3,
            rotation=lambda wpr: matrix_from_euler_zyx(*np.radians(np.asarray(wpr)[::-1])),
            angles=lambda rotation, ref: np.degrees(euler_zyx_from_matrix(
                rotation, np.radians(np.asarray(ref)[::-1])))[::-1],
            position_decimals=3, angle_decimals=3),
        choose=choose, config=config, written=fanuc_written, config_edits=config_edits,
        config_words=_words, is_identity=lambda key: key in ("UF0", "UT0"),
        full_words=lambda geometry, q: " ".join(fanuc_letters(geometry, q)),
        tool_names=_numbered)


def _numbered(key: str) -> list[str]:
    """``UTN`` is also ``toolN`` in calib.json."""
    found = re.fullmatch(r"UT(\d+)", key, re.I)
    return [key] if found is None else [key, f"tool{int(found.group(1))}"]


FANUC_TP = fanuc_rules()
